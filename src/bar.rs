//! The 1D regularisation bar (`docs/theory.md`, "A regularisation the grid resolves"): a strip one cell
//! high of a microplane material, lateral rollers (uniaxial strain), both ends pulled apart, a weak centre
//! zone where the band forms. Used by `examples/regularisation_bar.rs`, `tests/regularisation_bar.rs`
//! (dynamic: two tensile waves meet in the centre) and the `fit-material` command (quasi-static: the
//! dissipation per unit section to separation, the fracture energy `G_F` of the regularised model).
//!
//! Units: mm, s, N, MPa, t. Bar `0 <= x <= L`, plane strain, per mm of thickness. The weak zone
//! `|x - L/2| < W/2` has its section (volume and mass of its points) scaled by `section`, deepened by
//! 0.1 % towards the centre; points farther than `strong_beyond` from the centre get `strong_factor`
//! times the threshold `gamma_0` (same moduli and `c`), so that in a dynamic run the ringing halves do
//! not damage at the grips. CPDI1, 2 x 2 points per cell.

use anyhow::Result;
use nalgebra::Vector2;

use crate::boundary::{Motion, NodeBox};
use crate::geometry::{Geometry, Region, Seeding};
use crate::grid::Grid;
use crate::material::{MaterialConfig, MicroplaneConfig};
use crate::model::PathControl;
use crate::model::{Parameters, Setup, TimeIntegration};
use crate::particles::Particles;
use crate::petsc::SessionGuard;
use crate::shape::ShapeKind;
use crate::solver::{Simulation, StepError, StepReport};

/// Geometry, loading and time stepping of the bar.
#[derive(Clone, Debug, PartialEq)]
pub struct BarSpec {
    /// Bar length `L` (mm).
    pub length: f64,
    /// Width `W` of the weak centre zone (mm).
    pub weak_zone: f64,
    /// Section factor of the weak zone (-), in (0, 1].
    pub section: f64,
    /// Points farther than this from the centre get the stronger threshold (mm).
    pub strong_beyond: f64,
    /// Threshold factor of the strong parts (-), >= 1 (1: the whole bar is one material).
    pub strong_factor: f64,
    /// Speed of each end (mm/s; quasi-statically the elongation per end per unit of time).
    pub speed: f64,
    /// Rise time of the end speed (s).
    pub rise: f64,
    /// Time step (s).
    pub dt: f64,
    /// Density (t/mm^3).
    pub density: f64,
    /// Static equilibrium each step instead of Newmark.
    pub quasi_static: bool,
    /// PETSc options prefix of the runs (e.g. `rb_`).
    pub options_prefix: String,
    /// Path following (quasi-static only): the opening of a gauge across the weak zone controls the
    /// steps, the ends' motion follows; `None`: the ends move at `speed`.
    pub path: Option<BarPath>,
}

/// Indirect displacement control of the bar: the elongation of a gauge centred on the weak zone, at
/// mid-height of the strip, grows by `increment` per step; each end moves by `speed dt` times the
/// step's load ratio (negative on a snap-back).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BarPath {
    /// Gauge length (mm): the points nearest `L/2 -+ gauge/2` are measured.
    pub gauge: f64,
    /// Elongation of the gauge per step (mm).
    pub increment: f64,
}

impl BarSpec {
    /// The dynamic bar of the regularisation study: 100 mm, weak zone 10 mm at section 0.9, strong beyond
    /// 20 mm with twice `gamma_0`, ends at 1.8 m/s rising over 10 us, dt = 0.25 us, density 2.4e-9.
    pub fn regularisation() -> Self {
        Self {
            length: 100.0,
            weak_zone: 10.0,
            section: 0.9,
            strong_beyond: 20.0,
            strong_factor: 2.0,
            speed: 1800.0,
            rise: 1e-5,
            dt: 2.5e-7,
            density: 2.4e-9,
            quasi_static: false,
            options_prefix: "rb_".into(),
            path: None,
        }
    }
}

/// One converged step of a bar run.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BarStep {
    /// Displacement of the right end (mm); the bar's elongation is twice this.
    pub end_displacement: f64,
    /// Axial reaction stress at the right end, per mm^2 of the full section (MPa).
    pub stress: f64,
    /// Dissipated energy `D = (W_ext - Psi - K)/A` per mm^2 of the full section (N mm/mm^2).
    pub dissipated: f64,
}

impl BarStep {
    /// The step's values from the solver's report (cell size `h`, the section per mm of thickness).
    pub fn of(r: &StepReport, h: f64) -> Self {
        Self {
            end_displacement: r.displacements[0].1[0],
            stress: r.reactions[0].1[0] / h,
            dissipated: (r.external_work - r.stored_energy - r.kinetic_energy) / h,
        }
    }
}

/// The bar's points on cells of size `h` (mm): section-scaled weak zone, strong parts as body 1.
pub fn bar_points(spec: &BarSpec, h: f64) -> Result<Particles> {
    let geometry = Geometry {
        include: vec![Region::Rect {
            min: [0.0, 0.0],
            max: [spec.length, h],
        }],
        exclude: vec![],
    };
    let seeding = Seeding {
        h,
        points_per_cell: 2,
        density: spec.density,
        body: 0,
    };
    let mut particles = Particles::seed(&geometry, &seeding)?;
    let centre = 0.5 * spec.length;
    for p in 0..particles.len() {
        let r = (particles.x[p].x - centre).abs() / (0.5 * spec.weak_zone);
        if r < 1.0 {
            let scale = spec.section * (1.0 - 1e-3 * (1.0 - r));
            particles.vol0[p] *= scale;
            particles.vol[p] *= scale;
            particles.mass[p] *= scale;
        }
        if (particles.x[p].x - centre).abs() > spec.strong_beyond {
            particles.body[p] = 1;
        }
    }
    Ok(particles)
}

/// The simulation of the bar with cell size `h` (mm) and the microplane material `material` (the strong
/// parts: the same with `strong_factor` times its `gamma_0`).
pub fn bar_simulation(spec: &BarSpec, h: f64, material: &MicroplaneConfig) -> Result<Simulation> {
    let particles = bar_points(spec, h)?;
    let l = spec.length;
    let weak = MaterialConfig::Microplane(material.clone());
    let strong = MaterialConfig::Microplane(MicroplaneConfig {
        gamma_0: Some(spec.strong_factor * material.resolve()?.gamma_0),
        ..material.clone()
    });
    let far = 1e3;
    let bx = |name: &str, min: [f64; 2], max: [f64; 2], motion| NodeBox {
        name: name.into(),
        min: Vector2::from(min),
        max: Vector2::from(max),
        motion,
        rise_time: spec.rise,
    };
    let grid = Grid::covering(
        Vector2::zeros(),
        Vector2::new(l, h),
        h,
        (1.0 / h).ceil() as usize + 2,
    )?;
    let time = TimeIntegration {
        quasi_static: spec.quasi_static,
        ..TimeIntegration::with_dt(spec.dt)
    };
    let params = Parameters {
        boxes: vec![
            bx(
                "right end",
                [l - 1e-6, -far],
                [far, far],
                [Motion::Velocity(spec.speed), Motion::Free],
            ),
            bx(
                "left end",
                [-far, -far],
                [1e-6, far],
                [Motion::Velocity(-spec.speed), Motion::Free],
            ),
            bx(
                "rollers",
                [-far, -far],
                [far, far],
                [Motion::Free, Motion::Velocity(0.0)],
            ),
        ],
        options_prefix: Some(spec.options_prefix.clone()),
        path: spec.path.map(|p| PathControl {
            from: Vector2::new(0.5 * (l - p.gauge), 0.5 * h),
            to: Vector2::new(0.5 * (l + p.gauge), 0.5 * h),
            direction: Vector2::x(),
            increment: p.increment,
        }),
        ..Parameters::new(
            grid,
            vec![weak.build()?, strong.build()?],
            ShapeKind::Cpdi1,
            time,
        )
    };
    Ok(Simulation::new(Setup::of(params, particles))?)
}

/// Steps `sim` (cell size `h`, mm) until its right end has moved `dl` (mm) or `on_step` returns false;
/// `on_step` sees the simulation and the step's values after each converged step. A failed step ends the
/// run with its error.
pub fn pull(
    s: &SessionGuard,
    sim: &mut Simulation,
    h: f64,
    dl: f64,
    mut on_step: impl FnMut(&Simulation, &BarStep) -> bool,
) -> std::result::Result<(), StepError> {
    let mut d = 0.0;
    while d < dl - 1e-9 {
        let r = sim.advance(s)?;
        let step = BarStep::of(&r, h);
        d = step.end_displacement;
        if !on_step(sim, &step) {
            break;
        }
    }
    Ok(())
}

/// The damage profile `(x - centre, d)` of the points whose initial `x` coordinates are `x0`, sorted by
/// `x` with duplicates (the points above each other in the strip) removed.
pub fn damage_profile(sim: &Simulation, x0: &[f64], centre: f64) -> Vec<(f64, f64)> {
    let mut pts: Vec<(f64, f64)> = x0
        .iter()
        .zip(&sim.state.particles.damage)
        .map(|(x, d)| (*x - centre, *d))
        .collect();
    pts.sort_by(|a, b| a.0.total_cmp(&b.0));
    pts.dedup_by(|a, b| (a.0 - b.0).abs() < 1e-9);
    pts
}
