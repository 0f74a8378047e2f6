//! A run stopped after some steps and resumed from its checkpoint ends with exactly the same state and
//! history as an uninterrupted run (small gradient-enhanced CT specimen with damage).

use mpm_concrete::checkpoint;
use mpm_concrete::config::RunConfig;
use mpm_concrete::io::{RunOutput, SharedState};
use mpm_concrete::petsc::{self, Session, SessionGuard};
use mpm_concrete::rundir::RunIdentity;
use mpm_concrete::scenario;
use mpm_concrete::solver::{Simulation, StepReport};

const CONFIG: &str = r#"
[run]
name = "ct-restart"
steps = 36
[grid]
cell_size = 4.0
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

fn simulation(cfg: &RunConfig) -> Simulation {
    let mut setup = scenario::build(cfg).expect("model");
    setup.params.options_prefix = Some("ck_".into());
    Simulation::new(setup).expect("simulation")
}

fn advance(s: &SessionGuard, sim: &mut Simulation, out: &mut RunOutput, steps: usize) {
    for _ in 0..steps {
        let r = sim.advance(s).expect("step");
        out.record(r).expect("record");
    }
}

/// Step reports without their wall times (the only part that may differ).
fn physics(rows: &[StepReport]) -> Vec<StepReport> {
    rows.iter()
        .map(|r| StepReport {
            wall_setup: 0.0,
            wall_solve: 0.0,
            wall_assembly: 0.0,
            wall_total: 0.0,
            // Whether the PETSc objects were rebuilt is bookkeeping: a resumed run builds them anew.
            new_pattern: false,
            ..r.clone()
        })
        .collect()
}

#[test]
fn resumed_run_matches_the_uninterrupted_one_bit_for_bit() {
    check_restart(CONFIG, "mpm");
}

/// FEM mode carries the nodal velocity and acceleration from step to step: the checkpoint must too.
#[test]
fn resumed_fem_mode_run_matches_the_uninterrupted_one_bit_for_bit() {
    let fem = CONFIG.replace(
        "[grid]",
        "[shape]\nmethod = \"fem\"\nkind = \"linear\"\n[grid]",
    );
    check_restart(&fem, "fem");
}

/// Contact plates: the statuses of the contact nodes (the next step's first guess of the active set) are
/// part of the state.
#[test]
fn resumed_contact_run_matches_the_uninterrupted_one_bit_for_bit() {
    let contact = CONFIG.replace(
        "rise_time = 1.0e-5",
        "rise_time = 1.0e-5\nload_introduction = \"contact\"",
    );
    assert_ne!(contact, CONFIG);
    check_restart(&contact, "contact");
}

fn check_restart(config: &str, tag: &str) {
    let s = Session::get().expect("PETSc");
    petsc::apply_default_options(
        &s,
        "-ck_ksp_type preonly -ck_pc_type lu -ck_pc_factor_mat_solver_type mumps",
    )
    .expect("options");
    let cfg = RunConfig::from_str_named(config, "restart").expect("config");
    let base = std::env::temp_dir().join(format!("mpmc-restart-{tag}-{}", std::process::id()));
    let (dir_a, dir_b) = (base.join("a"), base.join("b"));

    let mut a = simulation(&cfg);
    let mut out_a = RunOutput::create(&dir_a, "a", config, &a.model, &a.state).expect("output");
    advance(&s, &mut a, &mut out_a, cfg.run.steps);

    let mut b = simulation(&cfg);
    let mut out_b = RunOutput::create(&dir_b, "b", config, &b.model, &b.state).expect("output");
    advance(&s, &mut b, &mut out_b, cfg.run.steps / 2);
    let identity = RunIdentity::new(config, "");
    let shared = SharedState::new(&s, &b.state).expect("rows");
    checkpoint::save(&dir_b, &shared, &out_b, &identity).expect("checkpoint");
    drop(shared);
    drop((b, out_b));

    let mut c = simulation(&cfg);
    let mut out_c = RunOutput::create(&dir_b, "b", config, &c.model, &c.state).expect("output");
    let header = checkpoint::load(&dir_b, &c.model, &mut c.state).expect("restore");
    assert_eq!(header.identity, identity);
    header.restore_records(&mut out_c).expect("records");
    assert_eq!(c.state.counters.step, cfg.run.steps / 2);
    advance(&s, &mut c, &mut out_c, cfg.run.steps - cfg.run.steps / 2);

    let (pa, pc) = (&a.state.particles, &c.state.particles);
    assert!(
        pa.damage.iter().any(|d| *d > 0.0),
        "the run should damage the specimen"
    );
    assert_eq!(pa.x, pc.x, "positions");
    assert_eq!(pa.v, pc.v, "velocities");
    assert_eq!(pa.f, pc.f, "deformation gradients");
    assert_eq!(pa.history, pc.history, "material history");
    assert_eq!(pa.damage, pc.damage, "damage");
    assert_eq!(a.state.counters, c.state.counters, "time, step, work");
    assert_eq!(physics(out_a.rows()), physics(out_c.rows()), "history rows");
    std::fs::remove_dir_all(&base).ok();
}
