//! A small dynamic compact tension run (half-size plate, 4 mm cells, Table 1's parameters, gradient
//! enhanced): damage must start at the notch tip, not elsewhere, and the opening force must be positive
//! and finite at every step.

use mpm_concrete::config::RunConfig;
use mpm_concrete::petsc::{self, Session};
use mpm_concrete::scenario;
use mpm_concrete::solver::Simulation;

const CONFIG: &str = r#"
[run]
name = "ct-small"
steps = 80
[time]
dt = 1.0e-6
[grid]
cell_size = 4.0
[shape]
kind = "cpdi1"
points_per_cell = 2
[ct]
width = 100.0
height = 100.0
notch_length = 56.0
notch_width = 8.0
load_zone = [0.0, 16.0]
loading_rate = 4300.0
rise_time = 1.0e-5
material = { model = "microplane", preset = "paper" }
"#;

#[test]
fn damage_starts_at_the_notch_tip_and_the_opening_force_is_positive() {
    let s = Session::get().expect("PETSc");
    petsc::apply_default_options(&s, "-ct_ksp_type preonly -ct_pc_type lu -ct_pc_factor_mat_solver_type mumps -ct_snes_rtol 1e-8 -ct_snes_atol 1e-8")
        .expect("options");
    let cfg = RunConfig::from_str_named(CONFIG, "ct-small").expect("config");
    let mut setup = scenario::build(&cfg).expect("model");
    setup.options_prefix = Some("ct_".into());
    let mut sim = Simulation::new(setup).expect("simulation");
    assert_eq!(
        sim.fields(),
        3,
        "gradient-enhanced: (u_x, u_y, eta_bar) per node"
    );
    let tip = nalgebra::Vector2::new(56.0, 50.0);
    let mut first_damage = None;
    for _ in 0..cfg.run.steps {
        let r = sim.advance(&s).expect("step converges");
        let (name, f) = &r.reactions[0];
        assert_eq!(name, "loading_plate");
        // The plate pulls the lower face down: the force it exerts on the specimen is -y.
        let opening = -f[1];
        assert!(
            opening.is_finite() && opening > 0.0,
            "step {}: opening force {opening}",
            r.step
        );
        let p = &sim.setup.particles;
        let damaged: Vec<usize> = (0..p.len()).filter(|&i| p.damage[i] > 0.05).collect();
        if !damaged.is_empty() {
            first_damage = Some((r.step, damaged));
            break;
        }
    }
    let (step, damaged) = first_damage.expect("damage within 80 us");
    eprintln!("first damage at step {step}: {} points", damaged.len());
    let p = &sim.setup.particles;
    for i in damaged {
        let d = (p.x[i] - tip).norm();
        assert!(
            d < 8.0,
            "step {step}: damaged point at {:?}, {d:.1} mm from the notch tip",
            p.x[i]
        );
    }
}
