//! A regularisation the grid resolves (issue 31, item 1): the finite-strain microplane model of Table 1
//! (preset `paper`) in a bar pulled in tension, on h = 2, 1, 0.5 and 0.25 mm, for several gradient-activity
//! settings: band width and dissipated energy against the cell size.
//!
//! ```text
//! cargo run --release --example regularisation_bar                  # the whole study into docs/img
//! cargo run --release --example regularisation_bar -- --out /tmp/r --h 1,0.5 \
//!     --case 'try|4|{ kind = "localizing", residual = 0.25, decay = 0.0 }'
//! ```
//!
//! Program arguments (all optional): `--out DIR` (default `docs/img`), `--h 2,1,0.5,0.25` (cell sizes, mm),
//! `--dl 0.15` (final elongation of each end, mm), `--length 100` (mm), `--section 0.9` (weak-zone section
//! factor), `--speed 1800` (mm/s), `--dt 2.5e-7` (s), `--case 'LABEL|C0|ACTIVITY'` (repeatable; replaces
//! the default cases; `C0` in mm^2, `ACTIVITY` the TOML inline table of `gradient_activity`). Everything
//! from the first single-dash word on goes to PETSc (the runs use the options prefix `rb_`).
//!
//! Writes into the output directory `regularisation-results.json` (every number quoted in
//! `docs/theory.md`, "A regularisation the grid resolves": per case and h the strength, the band widths,
//! the dissipated energy at the end and at the marks, the comparison of successive grids, the final
//! damage profile and the stress and energy histories) and per case `regularisation-{LABEL}-stress.png`
//! (reaction stress at the right end against its elongation, one curve per h), `-energy.png`
//! (dissipated energy against elongation) and `-damage.png` (final damage profile).
//!
//! Set-up: bar `0 <= x <= L = 100 mm`, a strip one cell high (plane strain, per mm of thickness),
//! lateral rollers (`u_y = 0` at every node: uniaxial strain), both ends pulled apart at 1.8 m/s (every
//! node at `x <= 0` and at `x >= L`, rising over 10 us; Newmark, dt = 0.25 us). Two tensile waves of
//! `rho c v` = 17.5 MPa (half the strength) meet in the centre and break it (the classic 1D softening
//! wave problem of Bazant & Belytschko 1985, where a local model dissipates nothing in the limit). The
//! centre zone `|x - L/2| < W/2 = 5 mm` has its section reduced to 0.9, deepened by 0.1 % towards the
//! centre (scaled `V_p`, `m_p`); points farther than 20 mm from the centre have twice Table 1's
//! `gamma_0` (same moduli and `c`), so the ringing halves never damage at the grips. CPDI1, 2 x 2
//! points per cell, density 2.4e-9 t/mm^3, MUMPS LU. Units: mm, s, N, MPa, t; the dissipated energy is
//! `D = (W_ext - Psi - K)/A` per mm^2 of the full section (N mm/mm^2). **Strength**: the largest axial
//! Cauchy stress of a weak-zone point before the first point reaches d = 0.9.
//!
//! **Band width** (stated definition): the distance between the outermost crossings of the damage level
//! 0.5 by the point damage profile (the microplane output damage, `1 - Psi/Psi_0`), linearly
//! interpolated between neighbouring points; since the band's centre reaches d close to 1, this is the
//! full width at half maximum of the damage profile.

use mpm_concrete::bar::{BarSpec, bar_simulation, damage_profile, pull};
use mpm_concrete::crack::band_width_1d;
use mpm_concrete::material::MicroplaneConfig;
use mpm_concrete::petsc::{self, Session, SessionGuard};
use mpm_concrete::plot::LinePlot;
use mpm_concrete::solver::{Simulation, StepError};
use serde_json::{Value, json};
use std::path::PathBuf;

type Result<T> = std::result::Result<T, Box<dyn std::error::Error>>;

/// Elongations at which the band width and the energy are recorded (mm).
const MARKS: [f64; 3] = [0.05, 0.1, 0.15];

/// One gradient-activity setting.
#[derive(Clone, Debug)]
struct Case {
    label: String,
    /// `c_0` (mm^2).
    c0: f64,
    /// TOML inline table of `gradient_activity`.
    activity: String,
}

/// History and final state of one run.
struct BarRun {
    /// (dL, stress) per step (mm, MPa).
    curve: Vec<(f64, f64)>,
    /// (dL, dissipated energy) per step (mm, N mm/mm^2).
    dissipated: Vec<(f64, f64)>,
    /// (dL, band width, D) at the marks reached.
    marks: Vec<(f64, f64, f64)>,
    /// Final damage profile (x - L/2, d), sorted.
    damage: Vec<(f64, f64)>,
    /// The largest axial stress of the weak zone's points before the first point reached d = 0.9 (MPa).
    peak: Option<f64>,
    /// A point has reached d = 0.9.
    broken: bool,
    /// Elongation at which a step failed for good, if any.
    failed_at: Option<f64>,
}

impl BarRun {
    /// The strength: the largest axial stress in the weak zone before it broke (MPa).
    fn peak(&self) -> f64 {
        self.peak.unwrap_or(f64::NAN)
    }
    fn end(&self) -> (f64, f64) {
        *self.dissipated.last().unwrap_or(&(0.0, 0.0))
    }
}

/// Table 1 (preset `paper`) with the case's `c_0` and activity.
fn material(case: &Case) -> Result<MicroplaneConfig> {
    Ok(toml::from_str(&format!(
        "preset = \"paper\"\nc = {}\ngradient_activity = {}\n",
        case.c0, case.activity
    ))?)
}

/// Updates the strength: the largest axial Cauchy stress of a point of the weak zone until the first
/// point reaches d = 0.9 (MPa).
fn track_strength(sim: &Simulation, x0: &[f64], centre: f64, w: f64, run: &mut BarRun) {
    let p = &sim.state.particles;
    if run.broken {
        return;
    }
    run.broken = p.damage.iter().any(|&v| v >= 0.9);
    let sigma = x0
        .iter()
        .zip(&p.stress)
        .filter(|(x, _)| (**x - centre).abs() < 0.5 * w)
        .map(|(_, s)| s[(0, 0)])
        .fold(f64::NEG_INFINITY, f64::max);
    run.peak = Some(run.peak.map_or(sigma, |v| v.max(sigma)));
}

/// Pulls the bar of cell size `h` to the elongation `dl` (mm).
fn run_bar(s: &SessionGuard, bar: &BarSpec, h: f64, dl: f64, case: &Case) -> Result<BarRun> {
    let mut sim = bar_simulation(bar, h, &material(case)?)?;
    let centre = 0.5 * bar.length;
    let x0: Vec<f64> = sim.state.particles.x.iter().map(|x| x.x).collect();
    let mut run = BarRun {
        curve: vec![(0.0, 0.0)],
        dissipated: vec![(0.0, 0.0)],
        marks: Vec::new(),
        damage: Vec::new(),
        peak: None,
        broken: false,
        failed_at: None,
    };
    let result = pull(s, &mut sim, h, dl, |sim, step| {
        let d = step.end_displacement;
        run.curve.push((d, step.stress));
        run.dissipated.push((d, step.dissipated));
        if run.marks.len() < MARKS.len() && d >= MARKS[run.marks.len()] - 1e-12 {
            let w = band_width_1d(&damage_profile(sim, &x0, centre), 0.5);
            run.marks.push((d, w, step.dissipated));
        }
        track_strength(sim, &x0, centre, bar.weak_zone, &mut run);
        true
    });
    match result {
        Ok(()) => {}
        Err(StepError::Diverged { time, reason, .. }) => {
            eprintln!("{} h = {h}: stopped at t = {time}: {reason}", case.label);
            run.failed_at = Some(run.end().0);
        }
        Err(e) => return Err(e.into()),
    }
    run.damage = damage_profile(&sim, &x0, centre);
    Ok(run)
}

/// Relative difference `|a - b| / |b|`.
fn rel(a: f64, b: f64) -> f64 {
    (a - b).abs() / b.abs().max(1e-300)
}

fn round6(x: f64) -> f64 {
    if x == 0.0 || !x.is_finite() {
        return x;
    }
    let scale = 10f64.powi(5 - x.abs().log10().floor() as i32);
    (x * scale).round() / scale
}

/// The JSON record of one run.
fn run_json(h: f64, r: &BarRun) -> Value {
    let thin = |c: &[(f64, f64)]| -> Vec<[f64; 2]> {
        let every = (c.len() / 60).max(1);
        c.iter()
            .step_by(every)
            .map(|p| [round6(p.0), round6(p.1)])
            .collect()
    };
    json!({
        "h": h,
        "peak_stress": round6(r.peak()),
        "final_elongation": round6(r.end().0),
        "dissipated_end": round6(r.end().1),
        "band_width_end": round6(band_width_1d(&r.damage, 0.5)),
        "band_width_d0.9_end": round6(band_width_1d(&r.damage, 0.9)),
        "band_width_in_cells_end": round6(band_width_1d(&r.damage, 0.5) / h),
        "marks": r.marks.iter().map(|m| json!({"elongation": round6(m.0), "band_width": round6(m.1),
            "dissipated": round6(m.2)})).collect::<Vec<_>>(),
        "failed_at": r.failed_at,
        "stress_curve": thin(&r.curve),
        "dissipated_curve": thin(&r.dissipated),
        "damage_profile": thin(&r.damage.iter().copied().filter(|p| p.0.abs() <= 20.0).collect::<Vec<_>>()),
    })
}

/// Successive-grid differences of band width and energy at the end (fractions).
fn comparisons(runs: &[(f64, BarRun)]) -> Vec<Value> {
    runs.windows(2)
        .map(|w| {
            let ((hc, c), (hf, f)) = (&w[0], &w[1]);
            let (wc, wf) = (band_width_1d(&c.damage, 0.5), band_width_1d(&f.damage, 0.5));
            json!({"h_coarse": hc, "h_fine": hf,
                "band_width": round6(rel(wc, wf)), "dissipated": round6(rel(c.end().1, f.end().1)),
                "peak_stress": round6(rel(c.peak(), f.peak()))})
        })
        .collect()
}

/// Runs one case on every grid, writes its plots and returns its JSON record.
fn study_case(s: &SessionGuard, o: &Options, case: &Case) -> Result<Value> {
    let out = &o.out;
    let mut runs = Vec::new();
    for &h in &o.hs {
        let r = run_bar(s, &o.bar, h, o.dl, case)?;
        eprintln!(
            "{} h = {h}: peak {:.3} MPa, band (d >= 0.5) {:.3} mm = {:.1} cells, D = {:.5} N mm/mm^2 at dL = {:.3}, marks {:?}",
            case.label,
            r.peak(),
            band_width_1d(&r.damage, 0.5),
            band_width_1d(&r.damage, 0.5) / h,
            r.end().1,
            r.end().0,
            r.marks
        );
        runs.push((h, r));
    }
    let title = format!("c0 = {} mm^2, {}", case.c0, case.activity);
    let mut stress = LinePlot::new(
        format!("{title}: stress"),
        "elongation dL [mm]",
        "sigma [MPa]",
    );
    let mut energy = LinePlot::new(
        format!("{title}: dissipated energy"),
        "elongation dL [mm]",
        "D [N mm/mm^2]",
    );
    let mut damage = LinePlot::new(format!("{title}: final damage"), "x - L/2 [mm]", "d [-]");
    for (h, r) in &runs {
        let name = format!("h = {h} mm");
        stress = stress.with_series(name.clone(), r.curve.clone());
        energy = energy.with_series(name.clone(), r.dissipated.clone());
        let centre: Vec<(f64, f64)> = r
            .damage
            .iter()
            .copied()
            .filter(|p| p.0.abs() <= 15.0)
            .collect();
        damage = damage.with_series(name, centre);
    }
    let tag = &case.label;
    stress.save_png(out.join(format!("regularisation-{tag}-stress.png")))?;
    energy.save_png(out.join(format!("regularisation-{tag}-energy.png")))?;
    damage.save_png(out.join(format!("regularisation-{tag}-damage.png")))?;
    Ok(json!({
        "label": case.label, "c0": case.c0, "gradient_activity": case.activity,
        "runs": runs.iter().map(|(h, r)| run_json(*h, r)).collect::<Vec<_>>(),
        "successive_grids": comparisons(&runs),
    }))
}

/// Command-line options.
struct Options {
    out: PathBuf,
    bar: BarSpec,
    hs: Vec<f64>,
    dl: f64,
    cases: Vec<Case>,
    petsc: String,
}

/// The default cases: the CT configs' localizing setting, the paper's constant `c`, an intermediate
/// setting and the recommended one.
fn default_cases() -> Vec<Case> {
    let case = |label: &str, c0: f64, activity: &str| Case {
        label: label.into(),
        c0,
        activity: activity.into(),
    };
    vec![
        case(
            "old",
            1.0,
            "{ kind = \"localizing\", residual = 0.01, decay = 0.0 }",
        ),
        case("paper", 1.0, "{ kind = \"constant\" }"),
        case(
            "c4-r0.25",
            4.0,
            "{ kind = \"localizing\", residual = 0.25, decay = 0.0 }",
        ),
        case(
            "chosen",
            9.0,
            "{ kind = \"localizing\", residual = 0.45, decay = 0.0 }",
        ),
    ]
}

fn parse_case(text: &str) -> Result<Case> {
    let parts: Vec<&str> = text.splitn(3, '|').collect();
    let [label, c0, activity] = parts.as_slice() else {
        return Err(format!("--case: expected LABEL|C0|ACTIVITY, got `{text}`").into());
    };
    Ok(Case {
        label: label.to_string(),
        c0: c0
            .parse()
            .map_err(|_| format!("--case: C0 `{c0}` is not a number"))?,
        activity: activity.to_string(),
    })
}

fn parse(args: &[String]) -> Result<Options> {
    let mut o = Options {
        out: PathBuf::from("docs/img"),
        bar: BarSpec::regularisation(),
        hs: vec![2.0, 1.0, 0.5, 0.25],
        dl: 0.15,
        cases: Vec::new(),
        petsc: String::new(),
    };
    let mut i = 0;
    while i < args.len() {
        let a = args[i].as_str();
        if a.starts_with('-') && !a.starts_with("--") {
            o.petsc = args[i..].join(" ");
            break;
        }
        let v = args
            .get(i + 1)
            .ok_or_else(|| format!("{a}: missing value"))?;
        match a {
            "--out" => o.out = PathBuf::from(v),
            "--h" => {
                o.hs = v
                    .split(',')
                    .map(|t| {
                        t.parse::<f64>()
                            .map_err(|_| format!("--h: `{t}` is not a number"))
                    })
                    .collect::<std::result::Result<_, _>>()?
            }
            "--dl" => {
                o.dl = v
                    .parse()
                    .map_err(|_| format!("--dl: `{v}` is not a number"))?
            }
            "--length" => o.bar.length = v.parse().map_err(|_| format!("--length: `{v}`"))?,
            "--section" => o.bar.section = v.parse().map_err(|_| format!("--section: `{v}`"))?,
            "--speed" => o.bar.speed = v.parse().map_err(|_| format!("--speed: `{v}`"))?,
            "--dt" => o.bar.dt = v.parse().map_err(|_| format!("--dt: `{v}`"))?,
            "--case" => o.cases.push(parse_case(v)?),
            _ => return Err(format!("unknown argument `{a}` (--out, --h, --dl, --case)").into()),
        }
        i += 2;
    }
    if o.cases.is_empty() {
        o.cases = default_cases();
    }
    Ok(o)
}

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let o = parse(&args)?;
    std::fs::create_dir_all(&o.out)?;
    let s = Session::get()?;
    petsc::apply_default_options(
        &s,
        &format!(
            "-rb_ksp_type preonly -rb_pc_type lu -rb_pc_factor_mat_solver_type mumps \
             -rb_snes_rtol 1e-10 -rb_snes_atol 1e-10 -rb_snes_stol 0 -rb_snes_max_it 40 {}",
            o.petsc
        ),
    )?;
    let mut cases = Vec::new();
    for case in &o.cases {
        cases.push(study_case(&s, &o, case)?);
    }
    let doc = json!({
        "units": "mm, s, N, MPa, t; D per mm^2 of the full section",
        "bar": {"length": o.bar.length, "weak_zone": o.bar.weak_zone, "section_factor": o.bar.section, "speed": o.bar.speed, "rise_time": o.bar.rise,
                "dt": o.bar.dt, "density": o.bar.density, "material": "microplane, preset paper (Table 1)",
                "band_width": "distance between the outermost crossings of d = 0.5 by the point damage profile"},
        "final_elongation": o.dl,
        "cases": cases,
    });
    let path = o.out.join("regularisation-results.json");
    std::fs::write(&path, serde_json::to_string_pretty(&doc)? + "\n")?;
    eprintln!("wrote {}", path.display());
    Ok(())
}
