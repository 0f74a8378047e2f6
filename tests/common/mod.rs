//! Set-ups shared by the integration tests: a material from its TOML section, the PETSc session with a
//! test's solver options, a set-up from a configuration text, and the one-cell-wide elastic column of V2
//! (quasi-static self-weight, `verification_static.rs`) and of the suddenly loaded column
//! (`verification_dynamics.rs`).
//!
//! Units: mm, s, N, MPa, t (density t/mm^3, gravity mm/s^2).

// Each test crate compiles this module and uses a part of it.
#![allow(dead_code)]

use mpm_concrete::boundary::{Motion, NodeBox};
use mpm_concrete::config::RunConfig;
use mpm_concrete::geometry::{Geometry, Region, Seeding};
use mpm_concrete::grid::Grid;
use mpm_concrete::material::{Material, MaterialConfig};
use mpm_concrete::model::{Method, Parameters, Setup, TimeIntegration};
use mpm_concrete::particles::Particles;
use mpm_concrete::petsc::{self, Session, SessionGuard};
use mpm_concrete::scenario;
use mpm_concrete::shape::ShapeKind;
use nalgebra::Vector2;

/// A constitutive law from its TOML section.
pub fn material(toml_text: &str) -> Material {
    MaterialConfig::build_toml(toml_text).expect("valid material")
}

/// The PETSc session with the solver `options` (a PETSc options string, usually under the test's own
/// prefix) added to the options database; options already set win.
pub fn session(options: &str) -> SessionGuard {
    let s = Session::get().expect("PETSc");
    petsc::apply_default_options(&s, options).expect("options");
    s
}

/// The plane set-up of the configuration `toml` (named `file` in errors), its solver options under
/// `prefix`.
pub fn config_setup(toml: &str, file: &str, prefix: &str) -> Setup {
    let cfg = RunConfig::from_str_named(toml, file).expect("config");
    let mut setup = scenario::build(&cfg).expect("model");
    setup.params.options_prefix = Some(prefix.into());
    setup
}

/// Height, Young's modulus, density and gravity of a column (nu = 0).
pub struct Column {
    pub height: f64,
    pub e: f64,
    pub rho: f64,
    pub g: f64,
}

impl Column {
    /// The column one cell wide and `cells` cells high, 2 x 2 points per cell (Gauss points in FEM mode),
    /// law `law` (E, nu = 0), rollers on the sides (x fixed at every node, for nu = 0 the same as side
    /// rollers), a clamped base (all nodes with y <= 0) and gravity `-g` in y applied at once
    /// (`body_force_ramp` = 0); SNES options under `prefix`.
    pub fn setup(
        &self,
        law: &str,
        kind: ShapeKind,
        method: Method,
        cells: usize,
        time: TimeIntegration,
        prefix: &str,
    ) -> Setup {
        let h = self.height / cells as f64;
        let geometry = Geometry {
            include: vec![Region::Rect {
                min: [0.0, 0.0],
                max: [h, self.height],
            }],
            exclude: vec![],
        };
        let seed = match method {
            Method::Mpm => Particles::seed,
            Method::Fem => Particles::seed_gauss,
        };
        let particles = seed(
            &geometry,
            &Seeding {
                h,
                points_per_cell: 2,
                density: self.rho,
                body: 0,
            },
        )
        .expect("seed");
        let grid = Grid::covering(Vector2::new(0.0, 0.0), Vector2::new(h, self.height), h, 2)
            .expect("grid");
        let far = 1e6;
        Setup::of(
            Parameters {
                body_force: Vector2::new(0.0, -self.g),
                boxes: vec![
                    NodeBox {
                        name: "side rollers".into(),
                        min: Vector2::new(-far, -far),
                        max: Vector2::new(far, far),
                        motion: [Motion::Velocity(0.0), Motion::Free],
                        rise_time: 0.0,
                    },
                    NodeBox {
                        name: "base".into(),
                        min: Vector2::new(-far, -far),
                        max: Vector2::new(far, 0.0),
                        motion: [Motion::Velocity(0.0), Motion::Velocity(0.0)],
                        rise_time: 0.0,
                    },
                ],
                options_prefix: Some(prefix.into()),
                method,
                ..Parameters::new(
                    grid,
                    vec![material(&format!(
                        "model = \"{law}\"\nyoungs_modulus = {}\npoisson_ratio = 0.0",
                        self.e
                    ))],
                    kind,
                    time,
                )
            },
            particles,
        )
    }
}
