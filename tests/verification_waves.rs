//! Implicit dynamics against closed forms (spec 02-benchmarks V3 and V6): a plane compression wave in
//! uniaxial strain and the first bending frequency of a plane-strain cantilever.
//!
//! Units: mm, s, N, MPa, t (density t/mm^3, velocity mm/s).

mod common;

use common::material;

use mpm_concrete::boundary::{Motion, NodeBox};
use mpm_concrete::geometry::{Geometry, Region, Seeding};
use mpm_concrete::grid::Grid;
use mpm_concrete::model::{Parameters, Setup, TimeIntegration};
use mpm_concrete::particles::Particles;
use mpm_concrete::petsc::{self, Session};
use mpm_concrete::shape::ShapeKind;
use mpm_concrete::solver::Simulation;
use nalgebra::Vector2;

const FAR: f64 = 1e6;

/// Concrete of Table 1 as a linear elastic solid: K = 18750 MPa, G = 15254 MPa, rho = 2.4e-9 t/mm^3.
const K: f64 = 18750.0;
const G: f64 = 15254.0;
const RHO: f64 = 2.4e-9;

/// V3 measured behind the front: relative errors of (v_x, sigma_xx, sigma_yy) against v0, -rho c_L v0
/// and (lambda/M) sigma_xx, averaged over the points with `0.25 L < x < c_L t - 0.25 L`.
fn plane_wave(kind: ShapeKind, cells: usize, courant: f64) -> [f64; 3] {
    let s = Session::get().expect("PETSc");
    petsc::apply_default_options(
        &s,
        "-v3_ksp_type preonly -v3_pc_type lu -v3_snes_rtol 1e-10 -v3_snes_atol 1e-8",
    )
    .expect("options");
    let (length, v0) = (200.0, 1000.0);
    let h = length / cells as f64;
    let m = K + 4.0 * G / 3.0;
    let lambda = K - 2.0 * G / 3.0;
    let c = (m / RHO).sqrt();
    let geometry = Geometry {
        include: vec![Region::Rect {
            min: [0.0, 0.0],
            max: [length, h],
        }],
        exclude: vec![],
    };
    let particles = Particles::seed(
        &geometry,
        &Seeding {
            h,
            points_per_cell: 2,
            density: RHO,
            body: 0,
        },
    )
    .expect("seed");
    let grid = Grid::covering(Vector2::new(0.0, 0.0), Vector2::new(length, h), h, 2).expect("grid");
    let dt = courant * h / c;
    let setup = Setup::of(
        Parameters {
            boxes: vec![
                NodeBox {
                    name: "rollers".into(),
                    min: Vector2::new(-FAR, -FAR),
                    max: Vector2::new(FAR, FAR),
                    motion: [Motion::Free, Motion::Velocity(0.0)],
                    rise_time: 0.0,
                },
                NodeBox {
                    name: "piston".into(),
                    min: Vector2::new(-FAR, -FAR),
                    max: Vector2::new(1e-9, FAR),
                    motion: [Motion::Velocity(v0), Motion::Velocity(0.0)],
                    rise_time: 0.0,
                },
            ],
            options_prefix: Some("v3_".into()),
            ..Parameters::new(
                grid,
                vec![material(&format!(
                    "model = \"linear_elastic\"\nbulk_modulus = {K}\nshear_modulus = {G}"
                ))],
                kind,
                TimeIntegration {
                    dt,
                    dt_min: dt,
                    ..TimeIntegration::default()
                },
            )
        },
        particles,
    );
    let mut sim = Simulation::new(setup).expect("simulation");
    // Run until the front has crossed three quarters of the strip.
    let steps = (0.75 * length / (c * dt)).round() as usize;
    for _ in 0..steps {
        let r = sim.advance(&s).expect("step");
        assert!(r.solve.converged());
    }
    let front = c * sim.state.counters.time;
    let p = &sim.state.particles;
    let window: Vec<usize> = (0..p.len())
        .filter(|&k| p.x[k].x > 0.25 * length && p.x[k].x < front - 0.25 * length)
        .collect();
    assert!(
        window.len() >= 8,
        "averaging window holds {} points",
        window.len()
    );
    let mean =
        |f: &dyn Fn(usize) -> f64| window.iter().map(|&k| f(k)).sum::<f64>() / window.len() as f64;
    let sxx_exact = -RHO * c * v0;
    let syy_exact = lambda / m * sxx_exact;
    [
        (mean(&|k| p.v[k].x) - v0).abs() / v0,
        (mean(&|k| p.stress[k][(0, 0)]) - sxx_exact).abs() / sxx_exact.abs(),
        (mean(&|k| p.stress[k][(1, 1)]) - syy_exact).abs() / syy_exact.abs(),
    ]
}

/// Concrete, v0 = 1 m/s: c_L = 4.036e6 mm/s, sigma_xx = -9.686 MPa, sigma_yy = -2.126 MPa behind the
/// front. Strip 200 mm, h = 2 mm, 2 x 2 points per cell, Courant number 1. Measured errors of
/// (v, sigma_xx, sigma_yy): linear 0.14/0.15/0.18 %, cpdi1 0.11/0.11/0.14 %; the trailing oscillations of
/// the trapezoidal rule average out over the window. A wrong wave speed (E = 36 GPa instead of
/// M = 39.1 GPa) moves sigma_xx by 4 %; without the lateral rollers sigma_yy would relax towards 0.
#[test]
fn v3_plane_wave_behind_the_front() {
    for kind in [ShapeKind::Linear, ShapeKind::Cpdi1] {
        let err = plane_wave(kind, 100, 1.0);
        eprintln!(
            "V3 {}: errors v {:.4}, sigma_xx {:.4}, sigma_yy {:.4}",
            kind.name(),
            err[0],
            err[1],
            err[2]
        );
        assert!(
            err.iter().all(|e| *e < 0.03),
            "{}: relative errors (v, sxx, syy) {err:?}",
            kind.name()
        );
    }
}

/// V6: plane-strain cantilever L = 1000 mm, H = 100 mm (L/H = 10), clamped at x = 0, concrete-like
/// E = 30000 MPa, nu = 0.2, rho = 2.4e-9 t/mm^3, started with the velocity of the first Euler-Bernoulli
/// mode (tip 10 mm/s, amplitude about 0.03 mm). Returns (measured, Euler-Bernoulli) first angular
/// frequency (rad/s), measured from the zero crossings of the tip-point deflection.
fn cantilever(
    kind: ShapeKind,
    cells_through: usize,
    steps_per_period: usize,
    periods: f64,
) -> (f64, f64) {
    let s = Session::get().expect("PETSc");
    petsc::apply_default_options(
        &s,
        "-v6_ksp_type preonly -v6_pc_type lu -v6_snes_rtol 1e-10 -v6_snes_atol 1e-7",
    )
    .expect("options");
    let (length, height, e, nu): (f64, f64, f64, f64) = (1000.0, 100.0, 30000.0, 0.2);
    let h = height / cells_through as f64;
    let e_plane = e / (1.0 - nu * nu);
    let inertia = height.powi(3) / 12.0;
    let bl = 1.875_104_068_711_961_f64;
    let w_exact = bl * bl * (e_plane * inertia / (RHO * height * length.powi(4))).sqrt();
    let geometry = Geometry {
        include: vec![Region::Rect {
            min: [0.0, 0.0],
            max: [length, height],
        }],
        exclude: vec![],
    };
    let mut particles = Particles::seed(
        &geometry,
        &Seeding {
            h,
            points_per_cell: 2,
            density: RHO,
            body: 0,
        },
    )
    .expect("seed");
    // First mode shape, normalised to 1 at the tip.
    let sigma = (bl.cosh() + bl.cos()) / (bl.sinh() + bl.sin());
    let mode = |x: f64| {
        let b = bl * x / length;
        (b.cosh() - b.cos() - sigma * (b.sinh() - b.sin()))
            / (bl.cosh() - bl.cos() - sigma * (bl.sinh() - bl.sin()))
    };
    let v_tip = 10.0;
    for k in 0..particles.len() {
        particles.v[k] = Vector2::new(0.0, v_tip * mode(particles.x[k].x));
    }
    let tip = (0..particles.len())
        .min_by(|&a, &b| {
            let d = |k: usize| (particles.x[k] - Vector2::new(length, 0.5 * height)).norm();
            d(a).total_cmp(&d(b))
        })
        .expect("points");
    let y_tip0 = particles.x[tip].y;
    let grid =
        Grid::covering(Vector2::new(0.0, 0.0), Vector2::new(length, height), h, 2).expect("grid");
    let period = 2.0 * std::f64::consts::PI / w_exact;
    let dt = period / steps_per_period as f64;
    let setup = Setup::of(
        Parameters {
            boxes: vec![NodeBox {
                name: "clamp".into(),
                min: Vector2::new(-FAR, -FAR),
                max: Vector2::new(1e-9, FAR),
                motion: [Motion::Velocity(0.0), Motion::Velocity(0.0)],
                rise_time: 0.0,
            }],
            options_prefix: Some("v6_".into()),
            ..Parameters::new(
                grid,
                vec![material(&format!(
                    "model = \"linear_elastic\"\nyoungs_modulus = {e}\npoisson_ratio = {nu}"
                ))],
                kind,
                TimeIntegration {
                    dt,
                    dt_min: dt,
                    ..TimeIntegration::default()
                },
            )
        },
        particles,
    );
    let mut sim = Simulation::new(setup).expect("simulation");
    let (mut t_prev, mut u_prev) = (0.0, 0.0);
    let mut crossings = Vec::new();
    for _ in 0..(periods * steps_per_period as f64).ceil() as usize {
        let r = sim.advance(&s).expect("step");
        assert!(r.solve.converged());
        let u = sim.state.particles.x[tip].y - y_tip0;
        // Zero crossings of the deflection (it starts at 0 moving up: T/2, T, 3T/2, ...), interpolated.
        if (u_prev > 0.0 && u <= 0.0) || (u_prev < 0.0 && u >= 0.0) {
            crossings.push(t_prev + (sim.state.counters.time - t_prev) * u_prev / (u_prev - u));
        }
        t_prev = sim.state.counters.time;
        u_prev = u;
    }
    assert!(
        crossings.len() >= 2,
        "only {} zero crossings of the tip deflection",
        crossings.len()
    );
    let half_periods = (crossings.len() - 1) as f64;
    let measured_period = 2.0 * (crossings[crossings.len() - 1] - crossings[0]) / half_periods;
    (2.0 * std::f64::consts::PI / measured_period, w_exact)
}

/// The deviation from Euler-Bernoulli has three parts: shear and rotary inertia (Timoshenko, about -0.6 %
/// at L/H = 10), the period elongation of the trapezoidal rule (-(w dt)^2/12 = -0.3 % at 32 steps per
/// period) and the spatial discretisation. Measured with cpdi1 (2 x 2 points per cell): -0.05 %, -0.72 %,
/// -0.90 % with 2, 4, 8 cells through the depth (linear and cpdi2 the same, gimp -0.32/-0.76/-0.91 %),
/// i.e. converging to the -0.9 % of the first two effects. The 2 % bound fails for a plane-stress modulus
/// (-2 %, total -2.7 %), a wrong mass or a clamp that lets the root rotate.
#[test]
fn v6_cantilever_first_frequency() {
    let (w, w_exact) = cantilever(ShapeKind::Cpdi1, 4, 32, 1.6);
    let dev = w / w_exact - 1.0;
    eprintln!(
        "V6 cpdi1, 4 cells through the depth: w1 = {w:.2} rad/s, Euler-Bernoulli {w_exact:.2}, deviation {dev:+.4}"
    );
    assert!(
        dev.abs() < 0.02,
        "first frequency {w:.2} rad/s vs {w_exact:.2} (deviation {dev:+.4})"
    );
}
