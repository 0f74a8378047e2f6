//! `[ct] symmetric = true` loads both notch faces mirror-identically: the damage field of a small
//! symmetric CT run is mirror-symmetric about the notch axis (y = height / 2) to round-off.

use mpm_concrete::config::RunConfig;
use mpm_concrete::petsc::{self, Session};
use mpm_concrete::scenario;
use mpm_concrete::solver::Simulation;

/// Half-size plate with its notch faces on grid lines (4 mm cells), Table 1's parameters.
fn config(load_introduction: &str) -> String {
    format!(
        r#"
[run]
name = "ct-symmetric"
steps = 1
[time]
dt = 1.0e-6
[grid]
cell_size = 4.0
[shape]
kind = "cpdi1"
points_per_cell = 2
[ct]
width = 96.0
height = 96.0
notch_length = 52.0
notch_width = 8.0
load_zone = [0.0, 16.0]
loading_rate = 8600.0
rise_time = 1.0e-5
symmetric = true
load_introduction = "{load_introduction}"
material = {{ model = "microplane", preset = "paper" }}
"#
    )
}

/// Runs `steps` steps and returns the largest damage and the largest difference of damage (and of
/// the mirrored displacement, mm) between mirror points.
fn mirror_error(load_introduction: &str, steps: usize) -> (f64, f64, f64) {
    let s = Session::get().expect("PETSc");
    petsc::apply_default_options(
        &s,
        "-sym_ksp_type preonly -sym_pc_type lu -sym_pc_factor_mat_solver_type mumps -sym_snes_rtol 1e-10 -sym_snes_atol 1e-10",
    )
    .expect("options");
    let cfg = RunConfig::from_str_named(&config(load_introduction), "sym").expect("config");
    let mut setup = scenario::build(&cfg).expect("model");
    setup.params.options_prefix = Some("sym_".into());
    let x0 = setup.particles.x.clone();
    let mut sim = Simulation::new(setup).expect("simulation");
    for _ in 0..steps {
        sim.advance(&s).expect("step converges");
    }
    let p = &sim.state.particles;
    let h = 96.0;
    let key = |x: nalgebra::Vector2<f64>| ((x.x * 8.0).round() as i64, (x.y * 8.0).round() as i64);
    let index: std::collections::HashMap<_, _> =
        x0.iter().enumerate().map(|(i, x)| (key(*x), i)).collect();
    let (mut dmax, mut derr, mut uerr) = (0.0_f64, 0.0_f64, 0.0_f64);
    for (i, x) in x0.iter().enumerate() {
        let j = index[&key(nalgebra::Vector2::new(x.x, h - x.y))];
        dmax = dmax.max(p.damage[i]);
        derr = derr.max((p.damage[i] - p.damage[j]).abs());
        let (ui, uj) = (p.x[i] - x0[i], p.x[j] - x0[j]);
        uerr = uerr.max((ui.x - uj.x).abs()).max((ui.y + uj.y).abs());
    }
    (dmax, derr, uerr)
}

/// Runs the symmetric CT with `load` for 40 steps and asserts a damaged, mirror-symmetric result.
fn assert_mirror_symmetric(load: &str) {
    let (dmax, derr, uerr) = mirror_error(load, 40);
    eprintln!(
        "{load}: max damage {dmax:.4}, mirror error damage {derr:.3e}, displacement {uerr:.3e} mm"
    );
    assert!(
        dmax > 0.05,
        "the run must damage the specimen: max damage {dmax}"
    );
    assert!(derr < 1e-9, "damage not mirror-symmetric: {derr:e}");
    assert!(
        uerr < 1e-9,
        "displacement not mirror-symmetric: {uerr:e} mm"
    );
}

#[test]
fn symmetric_ct_with_contact_plates_is_mirror_symmetric() {
    assert_mirror_symmetric("contact");
}

#[test]
fn symmetric_ct_with_glued_plates_is_mirror_symmetric() {
    assert_mirror_symmetric("glued");
}
