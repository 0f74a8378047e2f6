//! Implicit gradient enhancement: V4 against its closed form and mesh objectivity (spec 02-benchmarks V4,
//! issue 6 items 3-5).
//!
//! ```text
//! cargo run --release --example mesh_objectivity [-- <output dir, default docs/img>]
//! ```
//!
//! Writes `gradient-*.png` and `gradient-results.json` (all numbers quoted in
//! `docs/gradient-enhancement.md`). Units: mm, s, N, MPa, t; forces and energies per mm of thickness, and
//! "stress" = reaction at the pulled end / strip height (the stress in the full cross-section, MPa).
//!
//! 1. V4, perfect damage (alpha = 1, beta = 0), h = 2, 1, 0.5 mm, dL up to 0.05 mm: stress plateau,
//!    damage-zone width and eta_bar profile against the closed form of
//!    [`mpm_concrete::material::isotropic::peerlings`] (area-weighted flux, kappa = 0.9, and the spec's
//!    kappa = 1).
//! 2. The same bar (h = 1 mm) solved with `-pc_type fieldsplit` (GMRES, LU on the `u` and `eta_bar`
//!    blocks) instead of monolithic LU: same answer.
//! 3. Exponential softening (alpha = 0.98, beta = 650) on h = 2, 1, 0.5, 0.25 mm with c = 1 mm^2 and c = 0
//!    (local): stress-elongation curves and dissipated energy `D = W_ext - Psi` (N mm per mm^2 of
//!    section). A 0.1 % triangular deepening of the weak zone towards the centre selects the localisation
//!    point; without it the local model softens homogeneously over the whole weak zone (its points are
//!    identical in exact arithmetic), which hides its mesh dependence.

use mpm_concrete::boundary::{Motion, NodeBox};
use mpm_concrete::geometry::{Geometry, Region, Seeding};
use mpm_concrete::grid::Grid;
use mpm_concrete::material::MaterialConfig;
use mpm_concrete::material::isotropic::peerlings::Bar;
use mpm_concrete::model::{Parameters, Setup, TimeIntegration};
use mpm_concrete::particles::Particles;
use mpm_concrete::petsc::{self, Session, SessionGuard};
use mpm_concrete::plot::LinePlot;
use mpm_concrete::shape::ShapeKind;
use mpm_concrete::solver::{Simulation, StepError};
use nalgebra::Vector2;
use serde_json::{Value, json};
use std::path::{Path, PathBuf};
use std::time::Instant;

type Result<T> = std::result::Result<T, Box<dyn std::error::Error>>;

/// E (MPa), gamma_0, L and W (mm), density (t/mm^3; irrelevant quasi-statically).
const E: f64 = 20000.0;
const GAMMA_0: f64 = 1e-4;
const L: f64 = 100.0;
const W: f64 = 10.0;
const RHO: f64 = 2.4e-9;

/// One quasi-static bar run.
struct BarCase {
    /// Cell size (mm).
    h: f64,
    /// Gradient parameter (mm^2); 0 = local.
    c: f64,
    alpha: f64,
    beta: f64,
    /// Extra relative deepening of the weak zone at the centre (triangular over W).
    imperfection: f64,
    /// Final elongation (mm) and number of equal load steps.
    dl: f64,
    steps: usize,
    /// `kinematics` of the material: `"small"` or `"finite"`.
    kinematics: &'static str,
    /// SNES options prefix.
    prefix: &'static str,
}

/// History and final state of a run.
struct BarResult {
    /// (dL, stress) per converged step (mm, MPa).
    curve: Vec<(f64, f64)>,
    /// (dL, dissipated energy per mm^2 of section) per converged step (mm, N mm/mm^2).
    dissipated: Vec<(f64, f64)>,
    /// Initial x of the points (mm), final eta_bar and damage.
    x0: Vec<f64>,
    eta_bar: Vec<f64>,
    damage: Vec<f64>,
    /// Elongation at which a step failed (the run stops there), if any.
    failed_at: Option<f64>,
    /// Newton iterations summed over the steps, wall time (s).
    iterations: usize,
    wall: f64,
}

fn run_bar(s: &SessionGuard, case: &BarCase) -> Result<BarResult> {
    let h = case.h;
    let geometry = Geometry {
        include: vec![Region::Rect {
            min: [0.0, 0.0],
            max: [L, h],
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
    )?;
    for p in 0..particles.len() {
        let r = (particles.x[p].x - 0.5 * L).abs() / (0.5 * W);
        if r < 1.0 {
            let scale = 0.9 * (1.0 - case.imperfection * (1.0 - r));
            particles.vol0[p] *= scale;
            particles.vol[p] *= scale;
            particles.mass[p] *= scale;
        }
    }
    let x0: Vec<f64> = particles.x.iter().map(|x| x.x).collect();
    let cfg: MaterialConfig = toml::from_str(&format!(
        "model = \"isotropic_damage\"\nyoungs_modulus = {E}\npoisson_ratio = 0.0\ngamma_0 = {GAMMA_0}\n\
         alpha = {}\nbeta = {}\nc = {}\nequivalent_strain = \"axial\"\nkinematics = \"{}\"\n",
        case.alpha, case.beta, case.c, case.kinematics
    ))?;
    let far = 1e3;
    let bx = |name: &str, min: [f64; 2], max: [f64; 2], motion| NodeBox {
        name: name.into(),
        min: Vector2::from(min),
        max: Vector2::from(max),
        motion,
        rise_time: 0.0,
    };
    let time = TimeIntegration {
        quasi_static: true,
        ..TimeIntegration::with_dt(1.0)
    };
    let grid = Grid::covering(Vector2::zeros(), Vector2::new(L, h), h, 2)?;
    let setup = Setup::of(
        Parameters {
            // Grips: every node at x >= L moves with the end, every node at x <= 0 is fixed. A grip that holds
            // only the nodes on x = L leaves the node beyond it free, with the small mass of the end points'
            // CPDI corners that have crossed x = L: it relaxes the last column of points to zero stress
            // (F = I) and doubles the strain of the column before it.
            boxes: vec![
                bx(
                    "pulled end",
                    [L - 1e-6, -far],
                    [far, far],
                    [Motion::Velocity(case.dl / case.steps as f64), Motion::Free],
                ),
                bx(
                    "fixed end",
                    [-far, -far],
                    [1e-6, far],
                    [Motion::Velocity(0.0), Motion::Free],
                ),
                bx(
                    "rollers",
                    [-far, -far],
                    [far, far],
                    [Motion::Free, Motion::Velocity(0.0)],
                ),
            ],
            options_prefix: Some(case.prefix.into()),
            ..Parameters::new(grid, vec![cfg.build()?], ShapeKind::Cpdi1, time)
        },
        particles,
    );
    let mut sim = Simulation::new(setup)?;
    let t0 = Instant::now();
    let (mut curve, mut dissipated) = (vec![(0.0, 0.0)], vec![(0.0, 0.0)]);
    let (mut failed_at, mut iterations) = (None, 0);
    while sim.state.counters.time < case.steps as f64 - 1e-9 {
        match sim.advance(s) {
            Ok(r) => {
                let dl = r.displacements[0].1[0];
                curve.push((dl, r.reactions[0].1[0] / h));
                dissipated.push((dl, (r.external_work - r.stored_energy) / h));
                iterations += r.solve.iterations;
            }
            Err(StepError::Diverged { time, reason, .. }) => {
                eprintln!("h = {h}, c = {}: stopped at t = {time}: {reason}", case.c);
                failed_at = Some(time / case.steps as f64 * case.dl);
                break;
            }
            Err(e) => return Err(e.into()),
        }
    }
    let p = &sim.state.particles;
    Ok(BarResult {
        curve,
        dissipated,
        x0,
        eta_bar: p.eta_bar.clone(),
        damage: p.damage.clone(),
        failed_at,
        iterations,
        wall: t0.elapsed().as_secs_f64(),
    })
}

/// Points of one row (y below h/2), sorted by x: (x - L/2, value).
fn profile(r: &BarResult, values: &[f64]) -> Vec<(f64, f64)> {
    let mut pts: Vec<(f64, f64)> =
        r.x0.iter()
            .zip(values)
            .map(|(x, v)| (x - 0.5 * L, *v))
            .collect();
    pts.sort_by(|a, b| a.0.total_cmp(&b.0));
    pts.dedup_by(|a, b| (a.0 - b.0).abs() < 1e-9);
    pts
}

/// Largest difference of eta_bar between mirror points `x` and `-x` (about the centre), relative to its
/// maximum: the solution of the symmetric bar should be symmetric.
fn asymmetry(r: &BarResult) -> f64 {
    let pts = profile(r, &r.eta_bar);
    let n = pts.len();
    let max = pts.iter().map(|p| p.1).fold(0.0, f64::max);
    (0..n / 2)
        .map(|k| (pts[k].1 - pts[n - 1 - k].1).abs())
        .fold(0.0, f64::max)
        / max
}

/// Width of the zone where eta_bar > gamma_0 (mm), from linearly interpolated crossings.
fn damage_zone_width(r: &BarResult) -> f64 {
    let pts = profile(r, &r.eta_bar);
    let c: Vec<f64> = pts
        .windows(2)
        .filter(|w| (w[0].1 - GAMMA_0).signum() != (w[1].1 - GAMMA_0).signum())
        .map(|w| w[0].0 + (GAMMA_0 - w[0].1) / (w[1].1 - w[0].1) * (w[1].0 - w[0].0))
        .collect();
    match c.as_slice() {
        [a, .., b] => b - a,
        _ => f64::NAN,
    }
}

/// Normalised L2 error of eta_bar over the points against `exact(x - L/2)`.
fn l2_error(r: &BarResult, exact: impl Fn(f64) -> f64) -> f64 {
    let (mut num, mut den) = (0.0, 0.0);
    for (x, e) in r.x0.iter().zip(&r.eta_bar) {
        let ex = exact(x - 0.5 * L);
        num += (e - ex).powi(2);
        den += ex * ex;
    }
    (num / den).sqrt()
}

/// Cell sizes of the objectivity study (mm).
const MESHES: [f64; 4] = [2.0, 1.0, 0.5, 0.25];

/// Part 1 and 2: V4 against the closed form, and fieldsplit against LU.
fn v4(s: &SessionGuard, out: &Path) -> Result<Value> {
    let dl = 0.05;
    let weighted = Bar::spec(0.9)
        .solve(dl)
        .ok_or("closed form (kappa = 0.9)")?;
    let spec = Bar::spec(1.0).solve(dl).ok_or("closed form (kappa = 1)")?;
    let mut runs = Vec::new();
    let mut profile_plot = LinePlot::new(
        format!("V4 at dL = {dl} mm: nonlocal equivalent strain"),
        "x - L/2 [mm]",
        "eta_bar [-]",
    );
    let mut stress_plot = LinePlot::new(
        "V4: stress in the full section",
        "elongation dL [mm]",
        "sigma / (E gamma_0) [-]",
    );
    let mut h1 = None;
    let cases = [
        (2.0, "small"),
        (1.0, "small"),
        (0.5, "small"),
        (0.25, "small"),
        (0.5, "finite"),
    ];
    for (h, kinematics) in cases {
        let case = BarCase {
            h,
            c: 1.0,
            alpha: 1.0,
            beta: 0.0,
            imperfection: 0.0,
            dl,
            steps: 50,
            kinematics,
            prefix: "lu_",
        };
        let r = run_bar(s, &case)?;
        let ratio = r.curve.last().map_or(f64::NAN, |c| c.1) / (E * GAMMA_0);
        let w = damage_zone_width(&r);
        let err = l2_error(&r, |x| weighted.eta_bar(x));
        let err_spec = l2_error(&r, |x| spec.eta_bar(x));
        println!(
            "V4 h = {h} ({kinematics}): sigma/(E gamma_0) = {ratio:.5}, w = {w:.3} mm, eta_bar L2 error {err:.4} \
             (spec closed form: {err_spec:.4}), {} Newton iterations, {:.1} s",
            r.iterations, r.wall
        );
        runs.push(json!({
            "h": h, "kinematics": kinematics, "stress_ratio": ratio, "w": w, "eta_bar_l2_error": err,
            "eta_bar_l2_error_vs_spec": err_spec, "newton_iterations": r.iterations, "wall_s": r.wall,
        }));
        profile_plot = profile_plot.with_series(
            format!("MPM h = {h} mm, {kinematics}"),
            profile(&r, &r.eta_bar),
        );
        stress_plot = stress_plot.with_series(
            format!("MPM h = {h} mm, {kinematics}"),
            r.curve
                .iter()
                .map(|&(d, sg)| (d, sg / (E * GAMMA_0)))
                .collect(),
        );
        if h == 1.0 && kinematics == "small" {
            h1 = Some(r);
        }
    }
    let xs: Vec<f64> = (0..=1000).map(|k| -50.0 + 0.1 * k as f64).collect();
    profile_plot = profile_plot
        .with_series(
            "closed form, A eta_bar' continuous (kappa = 0.9)",
            xs.iter().map(|&x| (x, weighted.eta_bar(x))).collect(),
        )
        .with_series(
            "closed form of the spec (kappa = 1)",
            xs.iter().map(|&x| (x, spec.eta_bar(x))).collect(),
        );
    profile_plot.save_png(out.join("gradient-v4-profile.png"))?;
    let exact_curve = |kappa: f64| -> Vec<(f64, f64)> {
        (1..=100)
            .filter_map(|k| Bar::spec(kappa).solve(0.0005 * k as f64))
            .map(|sol| (sol.elongation, sol.stress_ratio()))
            .collect()
    };
    stress_plot = stress_plot
        .with_series("closed form (kappa = 0.9)", exact_curve(0.9))
        .with_series("closed form (kappa = 1)", exact_curve(1.0));
    stress_plot.save_png(out.join("gradient-v4-stress.png"))?;

    // Fieldsplit against LU on h = 1 mm.
    let lu = h1.ok_or("h = 1 run")?;
    let fs = run_bar(
        s,
        &BarCase {
            h: 1.0,
            c: 1.0,
            alpha: 1.0,
            beta: 0.0,
            imperfection: 0.0,
            dl,
            steps: 50,
            kinematics: "small",
            prefix: "fs_",
        },
    )?;
    let d_stress = lu
        .curve
        .iter()
        .zip(&fs.curve)
        .map(|(a, b)| (a.1 - b.1).abs())
        .fold(0.0, f64::max)
        / (E * GAMMA_0);
    let d_eb = lu
        .eta_bar
        .iter()
        .zip(&fs.eta_bar)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max)
        / lu.eta_bar.iter().copied().fold(0.0, f64::max);
    for (name, r) in [("LU", &lu), ("fieldsplit", &fs)] {
        println!(
            "{name}: asymmetry max |eta_bar(x) - eta_bar(-x)| / max eta_bar = {:.2e}",
            asymmetry(r)
        );
    }
    println!(
        "final stress ratio LU {:.6}, fieldsplit {:.6}; w LU {:.3}, fieldsplit {:.3} mm",
        lu.curve.last().map_or(f64::NAN, |c| c.1) / (E * GAMMA_0),
        fs.curve.last().map_or(f64::NAN, |c| c.1) / (E * GAMMA_0),
        damage_zone_width(&lu),
        damage_zone_width(&fs)
    );
    println!(
        "fieldsplit vs LU (h = 1): max |d sigma|/(E gamma_0) = {d_stress:.2e}, max |d eta_bar|/max eta_bar = {d_eb:.2e}; \
         Newton iterations {} vs {}, wall {:.1} s vs {:.1} s",
        fs.iterations, lu.iterations, fs.wall, lu.wall
    );
    Ok(json!({
        "dl": dl,
        "closed_form_kappa_0.9": { "stress_ratio": weighted.stress_ratio(), "b": weighted.b, "g": weighted.g, "w": weighted.w, "eta_bar_0": weighted.eta_bar(0.0) },
        "closed_form_spec": { "stress_ratio": spec.stress_ratio(), "b": spec.b, "g": spec.g, "w": spec.w, "eta_bar_0": spec.eta_bar(0.0) },
        "runs": runs,
        "fieldsplit_vs_lu": { "h": 1.0, "max_stress_difference_over_E_gamma0": d_stress, "max_eta_bar_difference_relative": d_eb,
            "newton_iterations_fieldsplit": fs.iterations, "newton_iterations_lu": lu.iterations,
            "wall_fieldsplit_s": fs.wall, "wall_lu_s": lu.wall },
    }))
}

/// Part 3: exponential softening, gradient vs local, on three meshes.
fn objectivity(s: &SessionGuard, out: &Path) -> Result<Value> {
    let mut summary = Vec::new();
    // Small load steps for the local model, to trace its path up to the snap-back after the peak (with
    // 200 steps Newton jumps across it on some meshes and fails on others).
    for (c, label, dl, steps) in [
        (1.0, "gradient c = 1 mm^2", 0.2, 200),
        (0.0, "local c = 0", 0.05, 4000),
    ] {
        let mut stress_plot = LinePlot::new(
            format!("alpha = 0.98, beta = 650, {label}: stress-elongation"),
            "elongation dL [mm]",
            "sigma [MPa]",
        );
        let mut energy_plot = LinePlot::new(
            format!("alpha = 0.98, beta = 650, {label}: dissipated energy"),
            "elongation dL [mm]",
            "D = (W_ext - Psi)/A [N mm/mm^2]",
        );
        let mut damage_plot = LinePlot::new(
            format!("alpha = 0.98, beta = 650, {label}: damage at the end of the run"),
            "x - L/2 [mm]",
            "d [-]",
        );
        let mut results = Vec::new();
        for h in MESHES {
            let r = run_bar(
                s,
                &BarCase {
                    h,
                    c,
                    alpha: 0.98,
                    beta: 650.0,
                    imperfection: 1e-3,
                    dl,
                    steps,
                    kinematics: "small",
                    prefix: "lu_",
                },
            )?;
            let peak = r.curve.iter().map(|p| p.1).fold(0.0, f64::max);
            let d_end = r.dissipated.last().map_or(f64::NAN, |p| p.1);
            let damaged = profile(&r, &r.damage)
                .windows(2)
                .filter(|w| w[0].1 > 0.5 || w[1].1 > 0.5)
                .map(|w| w[1].0 - w[0].0)
                .sum::<f64>();
            println!(
                "{label}, h = {h}: peak {peak:.4} MPa, D(end) = {d_end:.5e} N mm/mm^2, zone with d > 0.5: {damaged:.2} mm, \
                 failed at {:?}, {} Newton iterations, {:.1} s",
                r.failed_at, r.iterations, r.wall
            );
            stress_plot = stress_plot.with_series(format!("h = {h} mm"), r.curve.clone());
            energy_plot = energy_plot.with_series(format!("h = {h} mm"), r.dissipated.clone());
            damage_plot = damage_plot.with_series(format!("h = {h} mm"), profile(&r, &r.damage));
            results.push((h, r, peak, d_end, damaged));
        }
        let tag = if c > 0.0 { "gradient" } else { "local" };
        stress_plot.save_png(out.join(format!("gradient-objectivity-{tag}-stress.png")))?;
        energy_plot.save_png(out.join(format!("gradient-objectivity-{tag}-energy.png")))?;
        damage_plot.save_png(out.join(format!("gradient-objectivity-{tag}-damage.png")))?;
        // Difference of the two finest meshes: energy at the end, and the curves step by step.
        let (a, b) = (&results[2], &results[3]);
        let energy_diff = (a.3 - b.3).abs() / b.3;
        let curve_diff =
            a.1.curve
                .iter()
                .zip(&b.1.curve)
                .map(|(p, q)| (p.1 - q.1).abs())
                .fold(0.0, f64::max)
                / b.2;
        println!(
            "{label}: h = 0.5 vs 0.25: dissipated energy differs by {:.2} %, stress curves by up to {:.2} % of the peak",
            100.0 * energy_diff,
            100.0 * curve_diff
        );
        summary.push(json!({
            "model": tag, "c": c, "dl": dl, "steps": steps,
            "runs": results.iter().map(|(h, r, peak, d, zone)| json!({
                "h": h, "peak_stress": peak, "dissipated_energy_end": d, "zone_d_gt_0.5": zone,
                "failed_at_dl": r.failed_at, "newton_iterations": r.iterations, "wall_s": r.wall,
            })).collect::<Vec<_>>(),
            "energy_difference_h0.5_h0.25": energy_diff,
            "max_stress_difference_h0.5_h0.25_over_peak": curve_diff,
        }));
    }
    Ok(Value::Array(summary))
}

fn main() -> Result<()> {
    let out = PathBuf::from(std::env::args().nth(1).unwrap_or_else(|| "docs/img".into()));
    std::fs::create_dir_all(&out)?;
    let s = Session::get()?;
    let tol = "snes_rtol 1e-9 -{p}snes_atol 1e-9 -{p}snes_stol 0 -{p}snes_max_it 50";
    petsc::apply_default_options(
        &s,
        &format!(
            "-lu_ksp_type preonly -lu_pc_type lu -lu_pc_factor_mat_solver_type mumps -lu_{}",
            tol.replace("{p}", "lu_")
        ),
    )?;
    petsc::apply_default_options(
        &s,
        &format!(
            "-fs_ksp_type gmres -fs_ksp_rtol 1e-12 -fs_pc_type fieldsplit -fs_fieldsplit_u_pc_type lu \
             -fs_fieldsplit_eta_bar_pc_type lu -fs_{}",
            tol.replace("{p}", "fs_")
        ),
    )?;
    let v4 = v4(&s, &out)?;
    let obj = objectivity(&s, &out)?;
    let json = json!({ "units": "mm, s, N, MPa, t; stress = reaction / strip height", "v4": v4, "objectivity": obj });
    std::fs::write(
        out.join("gradient-results.json"),
        serde_json::to_string_pretty(&json)?,
    )?;
    Ok(())
}
