//! Path following of quasi-static runs (issue 33, item 2; `docs/theory.md`, "Path following"): the
//! library bar of `src/bar.rs` (100 mm, one 2 mm cell high, lateral rollers, a weak centre zone of 10 mm
//! at section 0.9, Table 1's microplane material with the recommended gradient activity c_0 = 9 mm^2,
//! localizing R = 0.45), pulled quasi-statically at both ends under indirect displacement control: the
//! elongation of a 31 mm gauge centred on the weak zone grows by 0.5 um per step and the ends follow.
//!
//! Table 1's material is so brittle that the bar snaps back at the peak (`docs/theory.md`, "A
//! regularisation the grid resolves"): after the peak the ends move back while the gauge keeps opening, a
//! branch that no displacement-controlled static step can follow. The test follows it to separation and
//! checks it against the bar's semi-analytic branch: outside the gauge the bar stays elastic (full
//! section, uniaxial strain), so at every step `2 u_end - w = sigma (L - g) / M` with `M = K + 4G/3`; on the
//! snap-back the ends' motion is this elastic recovery minus the growth of the band's opening.
//!
//! Measured (2026-12-03, h = 2 mm): peak 30.24 MPa at w = 25.0 um (u_end = 39.16 um), the ends move back
//! to u_end = 20.33 um at w = 33.0 um (16 steps), the stress falls below 5 % of the peak at w = 47 um
//! (step 94; 4 to 6 Newton iterations per damaging step).

use mpm_concrete::bar::{BarPath, BarSpec, BarStep, bar_simulation};
use mpm_concrete::material::MicroplaneConfig;
use mpm_concrete::petsc::SessionGuard;

mod common;

/// Cell size (mm), gauge length (mm: the points at `L/2 -+ g/2` sit exactly there) and the gauge's
/// elongation per step (mm).
const H: f64 = 2.0;
const GAUGE: f64 = 31.0;
const INCREMENT: f64 = 5e-4;

fn session() -> SessionGuard {
    common::session(
        "-pf_ksp_type preonly -pf_pc_type lu -pf_pc_factor_mat_solver_type mumps \
         -pf_snes_rtol 1e-9 -pf_snes_atol 1e-9 -pf_snes_stol 0 -pf_snes_max_it 30",
    )
}

/// One converged step: the bar's values and the path's.
struct Row {
    bar: BarStep,
    opening: f64,
    lambda: f64,
}

#[test]
fn bar_is_followed_through_its_snap_back_to_separation() {
    let s = session();
    let material: MicroplaneConfig = toml::from_str(
        "preset = \"paper\"\nc = 9.0\n\
         gradient_activity = { kind = \"localizing\", residual = 0.45, decay = 0.0 }\n",
    )
    .expect("material");
    let spec = BarSpec {
        speed: 5e-3,
        rise: 0.0,
        dt: 1.0,
        quasi_static: true,
        options_prefix: "pf_".into(),
        path: Some(BarPath {
            gauge: GAUGE,
            increment: INCREMENT,
        }),
        ..BarSpec::regularisation()
    };
    let mut sim = bar_simulation(&spec, H, &material).expect("simulation");
    let e = sim.model.params.materials[0].elastic_moduli();
    let m = e.bulk + 4.0 * e.shear / 3.0;
    let mut rows: Vec<Row> = Vec::new();
    let mut peak = 0.0f64;
    for _ in 0..400 {
        let r = sim
            .advance(&s)
            .unwrap_or_else(|e| panic!("step failed: {e}"));
        let p = r.path.expect("a path point in every step");
        let bar = BarStep::of(&r, H);
        peak = peak.max(bar.stress);
        rows.push(Row {
            bar,
            opening: p.opening,
            lambda: p.lambda,
        });
        if bar.stress < 0.05 * peak {
            break;
        }
    }
    let last = rows.last().expect("steps");
    assert!(
        last.bar.stress < 0.05 * peak,
        "not separated after {} steps: {:.3} MPa of a {peak:.3} MPa peak",
        rows.len(),
        last.bar.stress
    );
    // The control: the gauge opens by the increment in every step; lambda is the ends' motion / speed.
    for (k, r) in rows.iter().enumerate() {
        let w = (k + 1) as f64 * INCREMENT;
        assert!(
            (r.opening - w).abs() < 1e-9,
            "step {}: w = {:e}, not {w:e}",
            k + 1,
            r.opening
        );
        assert!((r.lambda * spec.speed - r.bar.end_displacement).abs() < 1e-12);
    }
    // The snap-back: after the peak the ends move back while the gauge opens.
    let ipeak = (0..rows.len())
        .max_by(|&a, &b| rows[a].bar.stress.total_cmp(&rows[b].bar.stress))
        .expect("peak");
    let u = |k: usize| rows[k].bar.end_displacement;
    let umax = u(ipeak);
    let imin = (ipeak..rows.len())
        .min_by(|&a, &b| u(a).total_cmp(&u(b)))
        .expect("minimum");
    eprintln!(
        "peak {peak:.3} MPa at w = {:.4e} mm (step {}), u_end {umax:.5e} -> {:.5e} mm at w = {:.4e} \
         mm (step {}), separated at w = {:.4e} mm (step {}, {:.3} MPa)",
        rows[ipeak].opening,
        ipeak + 1,
        u(imin),
        rows[imin].opening,
        imin + 1,
        last.opening,
        rows.len(),
        last.bar.stress
    );
    assert!(
        (25.0..34.0).contains(&peak),
        "peak {peak} MPa: 0.9 f_t is 30.2"
    );
    assert!(
        u(imin) < 0.6 * umax && imin >= ipeak + 5,
        "no snap-back: u_end {umax:e} -> {:e} mm over steps {} to {}",
        u(imin),
        ipeak + 1,
        imin + 1
    );
    assert!(
        (ipeak + 2..=imin).all(|k| u(k) < u(k - 1)),
        "the ends do not move back monotonically on the snap-back"
    );
    // The semi-analytic branch: the bar outside the gauge is elastic.
    let worst = rows
        .iter()
        .map(|r| {
            let elastic = r.bar.stress * (spec.length - GAUGE) / m;
            (2.0 * r.bar.end_displacement - r.opening - elastic).abs()
        })
        .fold(0.0, f64::max);
    eprintln!("largest |2 u_end - w - sigma (L - g)/M| = {worst:.3e} mm");
    for (k, r) in rows.iter().enumerate() {
        let elastic = r.bar.stress * (spec.length - GAUGE) / m;
        let err = 2.0 * r.bar.end_displacement - r.opening - elastic;
        assert!(
            err.abs() < 2e-3 * 2.0 * umax,
            "step {}: 2 u_end - w = {:.6e} mm, sigma (L - g) / M = {elastic:.6e} mm",
            k + 1,
            2.0 * r.bar.end_displacement - r.opening
        );
    }
}

/// A 10 x 4 mm block of a St Venant-Kirchhoff solid on 1 mm cells, held at x = 0 and pulled at x = 10
/// with a velocity of 1e-3 mm/s, under path following of the elongation between the points nearest
/// `from` and `to`; `extra` is appended to the text.
fn block(extra: &str) -> String {
    format!(
        r#"
[run]
name = "path-block"
steps = 3
[time]
dt = 1.0
quasi_static = true
[grid]
cell_size = 1.0
[[body]]
name = "block"
density = 1e-9
geometry = {{ include = [{{ type = "rect", min = [0.0, 0.0], max = [10.0, 4.0] }}] }}
material = {{ model = "svk", youngs_modulus = 1000.0, poisson_ratio = 0.2 }}
[[constraint]]
name = "held"
min = [-1.0, -1.0]
max = [0.0, 5.0]
x = "fixed"
y = "fixed"
[[constraint]]
name = "pulled"
min = [10.0, -1.0]
max = [11.0, 5.0]
x = {{ velocity = 1e-3 }}
{extra}
"#
    )
}

const PATH: &str = "[path]\nfrom = [2.0, 2.0]\nto = [8.0, 2.0]\nincrement = 2e-3\n";

#[test]
fn a_configured_path_controls_an_mpm_run() {
    let s = session();
    let setup = common::config_setup(&block(PATH), "block.toml", "pf_");
    let mut sim = mpm_concrete::solver::Simulation::new(setup).expect("simulation");
    let mut ratio = 0.0;
    for step in 1..=3 {
        let r = sim.advance(&s).expect("step");
        let p = r.path.expect("path point");
        assert!((p.opening - 2e-3 * step as f64).abs() < 1e-12, "{p:?}");
        // Elastic and nearly homogeneous: the end moves by about 10 / 6 of the gauge's opening (1.65 on
        // this grid), by the same amount in every step (to finite-strain terms).
        let u = r.displacements[1].1[0];
        assert!((u - p.lambda * 1e-3).abs() < 1e-15);
        assert!(
            (u / p.opening - 10.0 / 6.0).abs() < 2e-2,
            "u {u:e}, w {:e}",
            p.opening
        );
        if step > 1 {
            assert!((p.ratio - ratio).abs() < 1e-4 * ratio.abs(), "{p:?}");
        }
        ratio = p.ratio;
    }
}

#[test]
fn bad_path_tables_are_refused_naming_the_key() {
    use mpm_concrete::config::RunConfig;
    let refused = |text: String, key: &str, says: &str| {
        let e = match RunConfig::from_str_named(&text, "block.toml") {
            Err(e) => e.to_string(),
            Ok(cfg) => {
                let setup = mpm_concrete::scenario::build(&cfg).expect("set-up");
                match mpm_concrete::solver::Simulation::new(setup) {
                    Err(e) => e.to_string(),
                    Ok(_) => panic!("accepted: {text}"),
                }
            }
        };
        assert!(
            e.contains(key) && e.contains(says) && !e.contains('\n'),
            "{key}: {e}"
        );
    };
    let dynamic = block(PATH).replace("quasi_static = true", "quasi_static = false");
    refused(dynamic, "time.quasi_static", "[path]");
    refused(block(&PATH.replace("2e-3", "0.0")), "path.increment", "> 0");
    let same = "[path]\nfrom = [2.0, 2.0]\nto = [2.0, 2.0]\nincrement = 1e-3\n";
    refused(block(same), "path.direction", "nonzero");
    let one_point = "[path]\nfrom = [2.25, 2.25]\nto = [2.3, 2.25]\nincrement = 1e-3\n";
    refused(block(one_point), "path", "nearest material points differ");
    let off = "[path]\nfrom = [2.0, 2.0]\nto = [500.0, 2.0]\nincrement = 1e-3\n";
    refused(block(off), "path.to", "within one cell");
    let rise = block(PATH).replace(
        "x = { velocity = 1e-3 }",
        "x = { velocity = 1e-3 }\nrise_time = 1.0",
    );
    refused(rise, "path", "rise_time = 0");
    let still = block(PATH).replace("x = { velocity = 1e-3 }", "x = \"fixed\"");
    refused(still, "path", "nonzero velocity");
    let load = "[[load]]\nname = \"f\"\nfrom = [10.0, 0.0]\nto = [10.0, 4.0]\nforce = [1.0, 0.0]\n";
    refused(block(&format!("{PATH}{load}")), "path", "no [[load]]");
}

/// The notched beam of `configs/tpb-path.toml` (CMOD control, 1 um per step) with the run's default
/// solver options: at CMOD 15 um the plain bordered Newton leaves the material's domain (an inverted
/// point after 16 iterations; before the line search the step was retried at half the increment). The
/// retry of the attempt with the line search converges it at the full increment: every one of the first
/// 15 steps takes one attempt, the CMOD is 1 um per step, and only step 15's residual history holds
/// both Newton runs: the retry starts from the same guess, so its first norm repeats the first one
/// exactly.
#[test]
fn a_notched_beam_step_the_plain_newton_fails_converges_at_the_full_increment() {
    let s = common::session(
        "-tp_ksp_type preonly -tp_pc_type lu -tp_pc_factor_mat_solver_type mumps \
         -tp_snes_rtol 1e-8 -tp_snes_atol 1e-8 -tp_snes_max_it 25",
    );
    let text = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/configs/tpb-path.toml"
    ))
    .expect("configs/tpb-path.toml");
    let setup = common::config_setup(&text, "tpb-path.toml", "tp_");
    let mut sim = mpm_concrete::solver::Simulation::new(setup).expect("simulation");
    let mut rescued = Vec::new();
    for step in 1..=15 {
        let r = sim.advance(&s).expect("step");
        let p = r.path.expect("path point");
        assert_eq!(r.attempts, 1, "step {step} was retried: {:?}", r.solve);
        assert!((p.opening - 1e-3 * step as f64).abs() < 1e-12, "{p:?}");
        let norms = &r.solve.residual_norms;
        if norms[1..].contains(&norms[0]) {
            rescued.push(step);
        }
    }
    assert_eq!(rescued, [15], "steps whose plain Newton failed");
}
