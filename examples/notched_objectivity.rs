//! Mesh objectivity of the gradient-enhanced finite-strain microplane model on a notched plain-concrete
//! specimen in tension (issue 6, item 5), quasi-static and at one dynamic rate.
//!
//! ```text
//! cargo run --release --example notched_objectivity          # the whole study into docs/img (12 min)
//! cargo run --release --example notched_objectivity -- --out /tmp/n --h 2,1 --rates qs --models local
//! ```
//!
//! Program arguments (all optional): `--out DIR` (default `docs/img`), `--h 2,1,0.5` (cell sizes, mm),
//! `--c 4` (gradient parameter of the `gradient` series, mm^2), `--c-table1 1` (c of the extra
//! quasi-static `table1` series; 0 = none), `--rates qs,dyn`, `--models gradient,local,table1`,
//! `--qs ELONGATION,STEPS` (default 0.04,125), `--dyn VELOCITY,RISE,DT,STEPS` (default
//! 200,1e-5,5e-7,300: 0.2 m/s rising over 10 us, 300 steps of 0.5 us). Everything from the first
//! single-dash word on goes to PETSc (e.g. `-nq_snes_monitor`; the runs use the options prefix `nq_`).
//!
//! Writes into the output directory: `notched-results.json` (every number quoted in
//! `docs/gradient-enhancement.md`, Sec. 6: peak force, elongation at the peak, dissipated energy at the
//! end, where a run stopped, Newton iterations, wall times, the comparison of the two finest meshes and
//! the step-by-step history of time, elongation, force, external work, stored and kinetic energy);
//! `notched-{qs,dyn}-{MODEL}-force.png` (reaction at the pulled grip against the elongation, one curve per
//! h), `notched-{qs,dyn}-{MODEL}-energy.png` (dissipated energy `D = W_ext - Psi - K` against the
//! elongation), `notched-{qs,dyn}-energy-vs-h.png` (D at the end of each run against h, one curve per
//! model) and `notched-{qs,dyn}-{MODEL}-damage-h{H}.png` (damage at the end), MODEL = `gradient`
//! (c = 4 mm^2), `local` (c = 0), `gradient-c1` (c = 1 mm^2, quasi-static only). Units: mm, s, N, MPa,
//! t; forces and energies per mm of thickness.
//!
//! Each case is built through the public configuration path: the example writes the TOML text of a
//! [`RunConfig`] (one `[[body]]` with the notched plate as `include`/`exclude` rectangles, two
//! `[[constraint]]` grips) and calls [`scenario::build`], then [`Simulation::advance`] step by step.
//!
//! Specimen: plate [0, 40] x [0, 20] mm, two symmetric edge notches x in [18, 22], y in [0, 6] and
//! [14, 20] (ligament 8 mm); every boundary is a multiple of 2 mm, so the three grids represent the same
//! geometry. Grips: every node with x <= 0 fixed (x and y), every node with x >= 40 moved in x and held
//! in y. Material: `microplane`, preset `paper_gamma0_1.25e-4` (tensile strength about 4.5 MPa) with the
//! gradient parameter `c` overridden. CPDI1, 2 x 2 points per cell, density 2.4e-9 t/mm^3. Solver:
//! Newton with line search, MUMPS LU; no fallback solver; a failed step is halved down to dt/64, and a
//! run that still fails stops there (recorded, not an error).

use mpm_concrete::config::RunConfig;
use mpm_concrete::petsc::{self, Session, SessionGuard};
use mpm_concrete::plot::{LinePlot, ScatterField};
use mpm_concrete::scenario;
use mpm_concrete::solver::{Simulation, StepError};
use serde_json::{Value, json};
use std::path::PathBuf;
use std::time::Instant;

type Result<T> = std::result::Result<T, Box<dyn std::error::Error>>;

/// Plate length and height (mm).
const LENGTH: f64 = 40.0;
const HEIGHT: f64 = 20.0;
/// Notches: x range and depth from each edge (mm).
const NOTCH_X: [f64; 2] = [18.0, 22.0];
const NOTCH_DEPTH: f64 = 6.0;
/// Density (t/mm^3).
const RHO: f64 = 2.4e-9;

/// Loading of a run.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Rate {
    /// Quasi-static: the end displacement in `steps` equal increments to `elongation` (mm).
    Static { elongation: f64, steps: usize },
    /// Dynamic: the end moves at `velocity` (mm/s), rising linearly over `rise` (s); `steps` of `dt` (s).
    Dynamic {
        velocity: f64,
        rise: f64,
        dt: f64,
        steps: usize,
    },
}

impl Rate {
    fn tag(&self) -> &'static str {
        match self {
            Rate::Static { .. } => "qs",
            Rate::Dynamic { .. } => "dyn",
        }
    }
    fn label(&self) -> String {
        match self {
            Rate::Static { .. } => "quasi-static".into(),
            Rate::Dynamic { velocity, .. } => format!("{} m/s", velocity / 1000.0),
        }
    }
}

/// The TOML text of one case.
fn config_text(h: f64, c: f64, rate: Rate) -> String {
    let (time, steps, velocity, rise) = match rate {
        Rate::Static { elongation, steps } => (
            "dt = 1.0\nquasi_static = true".to_owned(),
            steps,
            elongation / steps as f64,
            0.0,
        ),
        Rate::Dynamic {
            velocity,
            rise,
            dt,
            steps,
        } => (format!("dt = {dt:e}"), steps, velocity, rise),
    };
    let [n0, n1] = NOTCH_X;
    let d = NOTCH_DEPTH;
    let (top, far, eps) = (HEIGHT, 1.0e3, 1.0e-6);
    format!(
        r#"[run]
name = "notched-h{h}-c{c}-{tag}"
steps = {steps}

[time]
{time}

[grid]
cell_size = {h}

[shape]
kind = "cpdi1"
points_per_cell = 2

[[body]]
name = "notched plate"
density = {RHO:e}
geometry = {{ include = [{{ type = "rect", min = [0.0, 0.0], max = [{LENGTH}, {top}] }}], exclude = [
    {{ type = "rect", min = [{n0}, -1.0], max = [{n1}, {d}] }},
    {{ type = "rect", min = [{n0}, {n_top}], max = [{n1}, {above}] }},
] }}
material = {{ model = "microplane", preset = "paper_gamma0_1.25e-4", c = {c:?} }}

# Grips: every node at or beyond a face (CPDI corners of the end points cross it).
[[constraint]]
name = "fixed_end"
min = [-{far}, -{far}]
max = [{eps:e}, {far}]
x = "fixed"
y = "fixed"

[[constraint]]
name = "pulled_end"
min = [{pull:?}, -{far}]
max = [{far}, {far}]
x = {{ velocity = {velocity:e} }}
y = "fixed"
rise_time = {rise:e}
"#,
        tag = rate.tag(),
        n_top = top - d,
        above = top + 1.0,
        pull = LENGTH - eps,
    )
}

/// Result of one run.
struct RunResult {
    h: f64,
    c: f64,
    points: usize,
    unknowns: usize,
    /// (elongation, reaction at the pulled grip) per converged step (mm, N/mm).
    force: Vec<(f64, f64)>,
    /// (elongation, dissipated energy W_ext - Psi - K) per converged step (mm, N mm/mm).
    dissipated: Vec<(f64, f64)>,
    /// (time, elongation, force, W_ext, Psi, K) per step.
    history: Vec<[f64; 6]>,
    /// Elongation at which the run stopped early, and why.
    stopped: Option<(f64, String)>,
    newton: usize,
    retried_steps: usize,
    wall: f64,
    /// Wall time in set-up (shape functions, P2G), in residual/Jacobian evaluations, in PETSc (s).
    wall_parts: [f64; 3],
    /// Final positions and damage of the points (maps).
    x: Vec<[f64; 2]>,
    damage: Vec<f64>,
}

impl RunResult {
    fn peak(&self) -> (f64, f64) {
        self.force
            .iter()
            .copied()
            .fold((0.0, 0.0), |a, p| if p.1 > a.1 { p } else { a })
    }
    fn end(&self) -> (f64, f64) {
        self.dissipated.last().copied().unwrap_or((0.0, 0.0))
    }
    fn final_force(&self) -> f64 {
        self.force.last().map_or(0.0, |p| p.1)
    }
}

fn run_case(s: &SessionGuard, h: f64, c: f64, rate: Rate) -> Result<RunResult> {
    let text = config_text(h, c, rate);
    let name = format!("notched h = {h}, c = {c}, {}", rate.label());
    let cfg = RunConfig::from_str_named(&text, &name)?;
    let mut setup = scenario::build(&cfg)?;
    setup.params.options_prefix = Some("nq_".into());
    setup.params.fallback_prefix = None;
    let mut sim = Simulation::new(setup)?;
    let points = sim.state.particles.len();
    let pulled = |names: &[(String, Vec<f64>)]| names.iter().position(|n| n.0 == "pulled_end");
    let t0 = Instant::now();
    let mut r = RunResult {
        h,
        c,
        points,
        unknowns: 0,
        force: vec![(0.0, 0.0)],
        dissipated: vec![(0.0, 0.0)],
        history: vec![[0.0; 6]],
        stopped: None,
        newton: 0,
        retried_steps: 0,
        wall: 0.0,
        wall_parts: [0.0; 3],
        x: vec![],
        damage: vec![],
    };
    let steps = cfg.run.steps;
    let end_time = steps as f64 * cfg.time.dt;
    while sim.state.counters.time < end_time * (1.0 - 1e-9) {
        match sim.advance(s) {
            Ok(rep) => {
                let k = pulled(&rep.reactions).ok_or("no pulled_end reaction")?;
                let u = rep.displacements[k].1[0];
                let f = rep.reactions[k].1[0];
                let d = rep.external_work - rep.stored_energy - rep.kinetic_energy;
                r.force.push((u, f));
                r.dissipated.push((u, d));
                r.history.push([
                    rep.time,
                    u,
                    f,
                    rep.external_work,
                    rep.stored_energy,
                    rep.kinetic_energy,
                ]);
                r.newton += rep.solve.iterations;
                r.retried_steps += usize::from(rep.attempts > 1);
                r.unknowns = r.unknowns.max(rep.unknowns);
                r.wall_parts[0] += rep.wall_setup;
                r.wall_parts[1] += rep.wall_assembly;
                r.wall_parts[2] += rep.wall_solve - rep.wall_assembly;
            }
            Err(e) => {
                let u = r.force.last().map_or(0.0, |p| p.0);
                let why = match &e {
                    StepError::Diverged { reason, .. } => format!("Newton failed: {reason}"),
                    other => other.to_string(),
                };
                eprintln!("{name}: stopped at elongation {u:.5} mm: {why}");
                r.stopped = Some((u, why));
                break;
            }
        }
    }
    r.wall = t0.elapsed().as_secs_f64();
    let p = &sim.state.particles;
    r.x = p.x.iter().map(|x| [x.x, x.y]).collect();
    r.damage = p.damage.clone();
    let (up, fp) = r.peak();
    let (ue, de) = r.end();
    println!(
        "{name}: {points} points, {} unknowns, peak {fp:.3} N/mm at {up:.5} mm, end {ue:.5} mm: F = {:.3} N/mm, \
         D = {de:.5} N mm/mm, {} Newton iterations, {} retried steps, {:.1} s (set-up {:.1}, assembly {:.1}, \
         PETSc {:.1}){}",
        r.unknowns,
        r.final_force(),
        r.newton,
        r.retried_steps,
        r.wall,
        r.wall_parts[0],
        r.wall_parts[1],
        r.wall_parts[2],
        r.stopped
            .as_ref()
            .map_or(String::new(), |s| format!(", STOPPED at {:.5} mm", s.0))
    );
    Ok(r)
}

/// Linear interpolation of a curve sorted by x (None outside its range).
fn interpolate(curve: &[(f64, f64)], x: f64) -> Option<f64> {
    let k = curve.windows(2).position(|w| w[0].0 <= x && x <= w[1].0)?;
    let (a, b) = (curve[k], curve[k + 1]);
    if b.0 == a.0 {
        return Some(b.1);
    }
    Some(a.1 + (x - a.0) / (b.0 - a.0) * (b.1 - a.1))
}

/// Comparison of the two finest runs (`coarse`, `fine`).
fn compare(coarse: &RunResult, fine: &RunResult) -> Value {
    let (_, pc) = coarse.peak();
    let (_, pf) = fine.peak();
    let (uc, dc) = coarse.end();
    let (uf, df) = fine.end();
    // Largest force difference over the common elongation range, relative to the fine peak.
    let common = uc.min(uf);
    let curve = fine
        .force
        .iter()
        .filter(|p| p.0 <= common)
        .filter_map(|p| interpolate(&coarse.force, p.0).map(|q| (q - p.1).abs()))
        .fold(0.0, f64::max)
        / pf;
    // Dissipated energy at the common end elongation.
    let d_common = match (
        interpolate(&coarse.dissipated, common),
        interpolate(&fine.dissipated, common),
    ) {
        (Some(a), Some(b)) if b != 0.0 => (a - b).abs() / b.abs(),
        _ => f64::NAN,
    };
    json!({
        "h": [coarse.h, fine.h],
        "peak_force_difference": (pc - pf).abs() / pf,
        "dissipated_energy_end_difference": (dc - df).abs() / df.abs(),
        "end_elongations": [uc, uf],
        "common_elongation": common,
        "dissipated_energy_difference_at_common_elongation": d_common,
        "max_force_difference_over_peak": curve,
    })
}

fn damage_map(r: &RunResult, title: String, path: PathBuf) -> Result<()> {
    ScatterField {
        title,
        x: r.x.iter().map(|x| x[0]).collect(),
        y: r.x.iter().map(|x| x[1]).collect(),
        value: r.damage.clone(),
        value_label: "damage [-]".into(),
        range: Some((0.0, 1.0)),
        point_size: 0.5 * r.h,
    }
    .save_png(path)?;
    Ok(())
}

/// A material variant of the study.
#[derive(Clone, Debug, PartialEq)]
struct Model {
    /// File-name tag: `gradient`, `local`, `gradient-c1`.
    tag: String,
    /// Gradient parameter (mm^2); 0 = local.
    c: f64,
    /// Run only the quasi-static loading.
    static_only: bool,
}

impl Model {
    fn label(&self) -> String {
        if self.c > 0.0 {
            format!("gradient c = {} mm^2", self.c)
        } else {
            "local c = 0".into()
        }
    }
}

struct Options {
    out: PathBuf,
    meshes: Vec<f64>,
    rates: Vec<Rate>,
    models: Vec<Model>,
}

/// Default loadings: quasi-static to 0.04 mm in 125 steps of 0.00032 mm; dynamic at 0.2 m/s (rising over
/// 10 us), 300 steps of 0.5 us (elongation 0.029 mm at 150 us).
const QS: Rate = Rate::Static {
    elongation: 0.04,
    steps: 125,
};
const DYN: Rate = Rate::Dynamic {
    velocity: 200.0,
    rise: 1.0e-5,
    dt: 5.0e-7,
    steps: 300,
};

/// Program arguments: `--out DIR`, `--h 2,1,0.5`, `--c 4` (gradient runs), `--c-table1 1` (an extra
/// quasi-static gradient series with Table 1's c; 0 = none), `--rates qs,dyn`, `--models
/// gradient,local,table1`, `--qs elongation,steps`, `--dyn velocity,rise,dt,steps`.
fn parse(args: &[String]) -> Result<Options> {
    let list = |v: &str| -> Result<Vec<f64>> {
        Ok(v.split(',')
            .map(str::parse)
            .collect::<std::result::Result<_, _>>()?)
    };
    let (mut out, mut meshes) = (PathBuf::from("docs/img"), vec![2.0, 1.0, 0.5]);
    let (mut c, mut c_table1) = (4.0, 1.0);
    let (mut qs, mut dynamic) = (QS, DYN);
    let mut rates = vec!["qs".to_owned(), "dyn".to_owned()];
    let mut models = vec![
        "gradient".to_owned(),
        "local".to_owned(),
        "table1".to_owned(),
    ];
    let mut it = args.iter();
    while let Some(a) = it.next() {
        let v = it.next().ok_or(format!("{a} needs a value"))?;
        let csv = || v.split(',').map(str::to_owned).collect::<Vec<_>>();
        match a.as_str() {
            "--out" => out = PathBuf::from(v),
            "--h" => meshes = list(v)?,
            "--c" => c = v.parse()?,
            "--c-table1" => c_table1 = v.parse()?,
            "--rates" => rates = csv(),
            "--models" => models = csv(),
            "--qs" => match list(v)?.as_slice() {
                &[elongation, steps] => {
                    qs = Rate::Static {
                        elongation,
                        steps: steps as usize,
                    }
                }
                _ => return Err("--qs elongation,steps".into()),
            },
            "--dyn" => match list(v)?.as_slice() {
                &[velocity, rise, dt, steps] => {
                    dynamic = Rate::Dynamic {
                        velocity,
                        rise,
                        dt,
                        steps: steps as usize,
                    }
                }
                _ => return Err("--dyn velocity,rise,dt,steps".into()),
            },
            other => return Err(format!("unknown argument {other}").into()),
        }
    }
    let rates = rates
        .iter()
        .map(|r| match r.as_str() {
            "qs" => Ok(qs),
            "dyn" => Ok(dynamic),
            _ => Err(format!("unknown rate {r} (qs, dyn)")),
        })
        .collect::<std::result::Result<_, _>>()?;
    let mut list_models = Vec::new();
    for m in &models {
        let model = |tag: String, c: f64, static_only: bool| Model {
            tag,
            c,
            static_only,
        };
        match m.as_str() {
            "gradient" => list_models.push(model("gradient".into(), c, false)),
            "local" => list_models.push(model("local".into(), 0.0, false)),
            "table1" if c_table1 > 0.0 && c_table1 != c => {
                list_models.push(model(format!("gradient-c{c_table1}"), c_table1, true))
            }
            "table1" => {}
            _ => return Err(format!("unknown model {m} (gradient, local, table1)").into()),
        }
    }
    Ok(Options {
        out,
        meshes,
        rates,
        models: list_models,
    })
}

/// `x` rounded to 6 significant digits (keeps the JSON short).
fn round6(x: f64) -> f64 {
    format!("{x:.5e}").parse().unwrap_or(x)
}

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let is_petsc = |a: &str| {
        let b = a.as_bytes();
        b.len() > 2 && b[0] == b'-' && b[1].is_ascii_alphabetic()
    };
    let split = args
        .iter()
        .skip(1)
        .position(|a| is_petsc(a))
        .map_or(args.len(), |i| i + 1);
    let mut petsc_args = vec![args[0].clone()];
    petsc_args.extend_from_slice(&args[split..]);
    let o = parse(&args[1..split])?;
    std::fs::create_dir_all(&o.out)?;
    let s = Session::initialize(&petsc_args)?;
    petsc::apply_default_options(
        &s,
        "-nq_ksp_type preonly -nq_pc_type lu -nq_pc_factor_mat_solver_type mumps \
         -nq_snes_rtol 1e-8 -nq_snes_atol 1e-8 -nq_snes_max_it 25",
    )?;
    let started = Instant::now();
    let mut summary = Vec::new();
    for rate in &o.rates {
        let mut energy_vs_h = LinePlot::new(
            format!(
                "notched specimen, {}: dissipated energy at the end of the run",
                rate.label()
            ),
            "cell size h [mm]",
            "D = W_ext - Psi - K at the end [N mm/mm]",
        );
        let mut models = Vec::new();
        let dynamic = matches!(rate, Rate::Dynamic { .. });
        for model in o.models.iter().filter(|m| !(dynamic && m.static_only)) {
            let (c, label) = (model.c, model.label());
            let mut force_plot = LinePlot::new(
                format!("notched specimen, {}, {label}", rate.label()),
                "elongation [mm]",
                "reaction at the pulled grip [N/mm]",
            );
            let mut energy_plot = LinePlot::new(
                format!("notched specimen, {}, {label}", rate.label()),
                "elongation [mm]",
                "dissipated energy W_ext - Psi - K [N mm/mm]",
            );
            let mut runs = Vec::new();
            for &h in &o.meshes {
                let r = run_case(&s, h, c, *rate)?;
                let legend = match &r.stopped {
                    Some((u, _)) => format!("h = {h} mm (stopped at {u:.4} mm)"),
                    None => format!("h = {h} mm"),
                };
                force_plot = force_plot.with_series(legend.clone(), r.force.clone());
                energy_plot = energy_plot.with_series(legend, r.dissipated.clone());
                runs.push(r);
            }
            let tag = format!("notched-{}-{}", rate.tag(), model.tag);
            force_plot.save_png(o.out.join(format!("{tag}-force.png")))?;
            energy_plot.save_png(o.out.join(format!("{tag}-energy.png")))?;
            // Runs that stopped early are compared at different elongations: say where.
            let stops: Vec<String> = runs
                .iter()
                .filter_map(|r| {
                    r.stopped
                        .as_ref()
                        .map(|s| format!("h = {}: {:.4}", r.h, s.0))
                })
                .collect();
            let legend = if stops.is_empty() {
                label.clone()
            } else {
                format!("{label} (stopped at {} mm)", stops.join(", "))
            };
            energy_vs_h =
                energy_vs_h.with_series(legend, runs.iter().map(|r| (r.h, r.end().1)).collect());
            for r in &runs {
                damage_map(
                    r,
                    format!(
                        "damage, {}, {label}, h = {} mm, elongation {:.4} mm",
                        rate.label(),
                        r.h,
                        r.end().0
                    ),
                    o.out.join(format!("{tag}-damage-h{}.png", r.h)),
                )?;
            }
            let comparison = (runs.len() >= 2).then(|| {
                let n = runs.len();
                compare(&runs[n - 2], &runs[n - 1])
            });
            if let Some(cmp) = &comparison {
                println!("{}, {label}: finest two: {cmp}", rate.label());
            }
            models.push(json!({
                "model": model.tag,
                "c": c,
                "runs": runs.iter().map(|r| {
                    let (up, fp) = r.peak();
                    let (ue, de) = r.end();
                    let history: Vec<Vec<f64>> =
                        r.history.iter().map(|row| row.iter().map(|v| round6(*v)).collect()).collect();
                    json!({
                        "h": r.h, "c": r.c, "points": r.points, "unknowns": r.unknowns,
                        "peak_force": fp, "elongation_at_peak": up,
                        "end_elongation": ue, "dissipated_energy_end": de, "force_end": r.final_force(),
                        "stopped": r.stopped.as_ref().map(|(u, why)| json!({"elongation": u, "reason": why})),
                        "newton_iterations": r.newton, "retried_steps": r.retried_steps, "wall_s": r.wall,
                        "wall_setup_assembly_petsc_s": r.wall_parts,
                        "history_columns": ["time", "elongation", "force", "external_work", "stored_energy", "kinetic_energy"],
                        "history": history,
                    })
                }).collect::<Vec<_>>(),
                "finest_two": comparison,
            }));
        }
        energy_vs_h.save_png(
            o.out
                .join(format!("notched-{}-energy-vs-h.png", rate.tag())),
        )?;
        let loading = match *rate {
            Rate::Static { elongation, steps } => {
                json!({"type": "quasi_static", "elongation": elongation, "steps": steps})
            }
            Rate::Dynamic {
                velocity,
                rise,
                dt,
                steps,
            } => {
                json!({"type": "dynamic", "velocity": velocity, "rise_time": rise, "dt": dt, "steps": steps,
                         "density": RHO})
            }
        };
        summary.push(json!({ "rate": rate.tag(), "loading": loading, "models": models }));
    }
    let total = started.elapsed().as_secs_f64();
    println!("total wall time {total:.0} s");
    let json = json!({
        "units": "mm, s, N, MPa, t; forces and energies per mm of thickness",
        "command": args.join(" "),
        "specimen": {
            "plate": [LENGTH, HEIGHT], "notch_x": NOTCH_X, "notch_depth": NOTCH_DEPTH,
            "ligament": HEIGHT - 2.0 * NOTCH_DEPTH,
            "material": "microplane, preset paper_gamma0_1.25e-4", "shape": "cpdi1, 2 x 2 points per cell",
            "grips": "x <= 0 fixed in x and y; x >= 40 moved in x, fixed in y",
            "solver": "Newton line search, MUMPS LU (-nq_ prefix)",
        },
        "meshes": o.meshes,
        "total_wall_s": total,
        "studies": summary,
    });
    std::fs::write(
        o.out.join("notched-results.json"),
        serde_json::to_string_pretty(&json)?,
    )?;
    Session::finalize(s)?;
    Ok(())
}
