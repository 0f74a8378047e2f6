//! The `fit-material` command: microplane parameters from engineering data (E, nu, f_t, G_F, optionally
//! f_c, and the gradient length). The rules are in [`search`] and `docs/material.md`, "Parameters from
//! engineering data". Writes `<out>/material.toml` (the `[material]` section, also printed),
//! `<out>/tension.png` (the fitted local tension curve), `<out>/bar-dissipation.png` (the bar's
//! dissipation and end stress against its elongation) and `<out>/fit.json` (targets, achieved values,
//! errors, every evaluation of the search).
//!
//! Units: MPa, N/mm (= N mm/mm^2), mm, mm^2.

pub mod search;

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use serde_json::json;

use crate::app::bad;
use crate::material::driver::{PathKind, uniaxial_strengths};
use crate::material::{GradientActivity, MaterialConfig, MicroplaneConfig};
use crate::petsc::{self, Session};
use crate::plot::LinePlot;
use search::{Evaluation, FitSettings, Targets};

/// Command-line arguments of `fit-material`.
#[derive(clap::Args, Clone, Debug)]
pub struct FitArgs {
    /// Young's modulus E (MPa), > 0.
    #[arg(long = "youngs-modulus", allow_negative_numbers = true)]
    pub youngs_modulus: f64,
    /// Poisson's ratio nu, 0 <= nu < 0.5.
    #[arg(
        long = "poisson-ratio",
        allow_negative_numbers = true,
        default_value_t = 0.2
    )]
    pub poisson_ratio: f64,
    /// Uniaxial tensile strength f_t (MPa), 0 < f_t <= E/100.
    #[arg(long = "tensile-strength", allow_negative_numbers = true)]
    pub tensile_strength: f64,
    /// Fracture energy G_F (N/mm), > 0; a G_F more than ten times beyond what the 300 mm fitting bar
    /// can reach for E, f_t and c (below a tenth of f_t^2 L/(2E), above ten times the estimated largest,
    /// about 1.3 N/mm at E = 30000, f_t = 3, c = 9) is refused before any work.
    #[arg(long = "fracture-energy", allow_negative_numbers = true)]
    pub fracture_energy: f64,
    /// Uniaxial compressive strength f_c (MPa), > f_t; fitted through k_r (default: k_r = 14, Table 1).
    #[arg(long = "compressive-strength", allow_negative_numbers = true)]
    pub compressive_strength: Option<f64>,
    /// Gradient parameter c (mm^2), > 0 (default 9, the converged regularisation's c_0).
    #[arg(long, allow_negative_numbers = true, conflicts_with = "length")]
    pub c: Option<f64>,
    /// Gradient length l (mm), > 0, instead of c: c = l^2.
    #[arg(long, allow_negative_numbers = true)]
    pub length: Option<f64>,
    /// Cell size of the fitting bar (mm), in (0, 5]; at most sqrt(0.45 c)/2 for a converged G_F.
    #[arg(long, default_value_t = 1.0, allow_negative_numbers = true)]
    pub h: f64,
    /// Steps of each bar run.
    #[arg(long, default_value_t = 200)]
    pub bar_steps: usize,
    /// Steps of each driver run to the local strength.
    #[arg(long, default_value_t = 2000)]
    pub strength_steps: usize,
    /// Output directory.
    #[arg(long, default_value = "out/fit-material")]
    pub out: PathBuf,
}

/// `value` must be finite and satisfy `ok`, else a refusal naming `option` and `allowed`.
fn require(option: &str, value: f64, ok: bool, allowed: &str) -> Result<f64> {
    if value.is_finite() && ok {
        Ok(value)
    } else {
        Err(bad(format!("{option} {value}: allowed {allowed}")))
    }
}

/// Checks the arguments (exit 2 naming the option and its range) and returns the targets.
pub fn targets(a: &FitArgs) -> Result<(Targets, FitSettings)> {
    let e = require(
        "--youngs-modulus",
        a.youngs_modulus,
        a.youngs_modulus > 0.0,
        "E > 0 MPa",
    )?;
    let nu = a.poisson_ratio;
    let nu = require(
        "--poisson-ratio",
        nu,
        (0.0..0.5).contains(&nu),
        "0 <= nu < 0.5",
    )?;
    let ft = a.tensile_strength;
    let ft = require(
        "--tensile-strength",
        ft,
        ft > 0.0 && ft <= 0.01 * e,
        &format!(
            "0 < f_t <= E/100 = {} MPa (peak strains above 1 % are beyond the fitted model's small-strain scaling)",
            0.01 * e
        ),
    )?;
    let gf = a.fracture_energy;
    let gf = require("--fracture-energy", gf, gf > 0.0, "G_F > 0 N/mm")?;
    let fc = match a.compressive_strength {
        Some(fc) => Some(require(
            "--compressive-strength",
            fc,
            fc > ft,
            &format!("f_c > f_t = {ft} MPa"),
        )?),
        None => None,
    };
    let c = match (a.c, a.length) {
        (Some(c), _) => require("--c", c, c > 0.0, "c > 0 mm^2")?,
        (None, Some(l)) => require("--length", l, l > 0.0, "l > 0 mm (c = l^2)")?.powi(2),
        (None, None) => 9.0,
    };
    let h = require("--h", a.h, a.h > 0.0 && a.h <= 5.0, "0 < h <= 5 mm")?;
    // A G_F far outside what the fitting bar can reach is refused before any bar run.
    let (lo, hi) = search::plausible_fracture_energy(e, ft, c);
    require(
        "--fracture-energy",
        gf,
        (lo..=hi).contains(&gf),
        &format!(
            "{lo:.3e} <= G_F <= {hi:.3e} N/mm for E = {e} MPa, f_t = {ft} MPa, c = {c} mm^2 (a tenth of \
             f_t^2 L/(2E), below which the {} mm fitting bar snaps back, to ten times the estimated \
             largest G_F of its most ductile band, which falls as 1/c: a smaller --c reaches a larger G_F)",
            search::BAR_LENGTH
        ),
    )?;
    for (option, n) in [
        ("--bar-steps", a.bar_steps),
        ("--strength-steps", a.strength_steps),
    ] {
        if !(20..=1_000_000).contains(&n) {
            return Err(bad(format!("{option} {n}: allowed 20..=1000000 steps")));
        }
    }
    if a.out.exists() && !a.out.is_dir() {
        return Err(bad(format!(
            "--out {}: allowed a directory (it exists and is not one)",
            a.out.display()
        )));
    }
    let t = Targets {
        youngs_modulus: e,
        poisson_ratio: nu,
        tensile_strength: ft,
        fracture_energy: gf,
        compressive_strength: fc,
        c,
    };
    let settings = FitSettings {
        strength_steps: a.strength_steps,
        h,
        bar_steps: a.bar_steps,
    };
    Ok((t, settings))
}

/// The `[material]` section of a fitted microplane config (every parameter explicit).
pub fn toml_snippet(cfg: &MicroplaneConfig) -> Result<String> {
    let p = cfg.resolve()?;
    let activity = match p.gradient_activity {
        GradientActivity::Constant => "{ kind = \"constant\" }".to_string(),
        other => anyhow::bail!("unexpected activity {other:?}"),
    };
    Ok(format!(
        "[material]\nmodel = \"microplane\"\nbulk_modulus = {:e}\nshear_modulus = {:e}\n\
         poisson_ratio = {:?}\ngamma_0 = {:e}\nk_r = {:e}\nalpha = {:?}\nbeta = {:e}\nc = {:e}\n\
         gradient_activity = {activity}\n",
        p.bulk_modulus, p.shear_modulus, p.poisson_ratio, p.gamma_0, p.k_r, p.alpha, p.beta, p.c
    ))
}

/// The values a fitted section achieves, measured anew: the local strengths by the material driver on
/// the section read back from `snippet`, `G_F` from the search's final bar.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Achieved {
    /// Tensile strength (MPa).
    pub tensile_strength: f64,
    /// Compressive strength (MPa).
    pub compressive_strength: f64,
    /// Fracture energy (N/mm).
    pub fracture_energy: f64,
}

/// Reads the snippet back and measures its strengths with the driver (`steps` per run).
pub fn achieved(snippet: &str, fracture_energy: f64, steps: usize) -> Result<Achieved> {
    let table: toml::Table = toml::from_str(snippet)?;
    let section: MaterialConfig = table
        .get("material")
        .context("no [material] table")?
        .clone()
        .try_into()?;
    let local = match section {
        MaterialConfig::Microplane(m) => MaterialConfig::Microplane(MicroplaneConfig {
            c: Some(0.0),
            gradient_activity: None,
            ..m
        }),
        _ => anyhow::bail!("not a microplane section"),
    };
    let s = uniaxial_strengths(&local.build()?, steps)?.context("no strengths")?;
    Ok(Achieved {
        tensile_strength: s.tensile,
        compressive_strength: s.compressive,
        fracture_energy,
    })
}

/// Writes the plots of the fit into `out`.
fn plots(out: &Path, best: &Evaluation, steps: usize) -> Result<()> {
    let (_, curve) = search::strength(&best.config, PathKind::UniaxialTension, steps)?;
    LinePlot::new(
        "fitted local model, uniaxial tension",
        "nominal strain F11 - 1 [-]",
        "P11 [MPa]",
    )
    .with_series(
        "P11",
        curve.iter().map(|p| (p.control, p.p[(0, 0)])).collect(),
    )
    .save_png(out.join("tension.png"))?;
    let elongation = |d: f64| 2.0 * d;
    LinePlot::new(
        "fitting bar (quasi-static, uniaxial strain)",
        "bar elongation [mm]",
        "D [N/mm] and end stress / 10 [MPa]",
    )
    .with_series(
        "dissipated energy D",
        best.bar
            .steps
            .iter()
            .map(|s| (elongation(s.end_displacement), s.dissipated))
            .collect(),
    )
    .with_series(
        "end stress / 10",
        best.bar
            .steps
            .iter()
            .map(|s| (elongation(s.end_displacement), 0.1 * s.stress))
            .collect(),
    )
    .save_png(out.join("bar-dissipation.png"))?;
    Ok(())
}

/// Relative error `a/b - 1`.
fn rel(a: f64, b: f64) -> f64 {
    a / b - 1.0
}

/// Runs the command: checks, fits, measures, writes and prints.
pub fn run(args: &FitArgs, petsc_args: &[String]) -> Result<()> {
    super::no_petsc_options(
        "fit-material",
        ": its fitting bar is always solved by Newton with MUMPS LU at fixed tolerances",
        petsc_args,
    )?;
    let (t, settings) = targets(args)?;
    let s = Session::initialize(petsc_args).context("starting PETSc")?;
    petsc::apply_default_options(
        &s,
        "-fit_ksp_type preonly -fit_pc_type lu -fit_pc_factor_mat_solver_type mumps \
         -fit_snes_rtol 1e-10 -fit_snes_atol 1e-10 -fit_snes_stol 0 -fit_snes_max_it 40",
    )?;
    let mut log = Vec::new();
    let best = search::fit(&s, &t, &settings, |e| {
        eprintln!(
            "  x = alpha beta gamma_0 = {:.4}: G_F = {:.5} N/mm{}",
            e.x,
            e.bar.fracture_energy,
            if e.bar.separated {
                ""
            } else {
                " (not separated)"
            }
        );
        log.push(json!({"x": e.x, "fracture_energy": e.bar.fracture_energy, "separated": e.bar.separated}));
    })?;
    let snippet = toml_snippet(&best.config)?;
    let got = achieved(&snippet, best.bar.fracture_energy, settings.strength_steps)?;
    let out = &args.out;
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    std::fs::write(out.join("material.toml"), &snippet)?;
    plots(out, &best, settings.strength_steps)?;
    let p = best.config.resolve()?;
    let fc_err = t
        .compressive_strength
        .map(|fc| rel(got.compressive_strength, fc));
    let doc = json!({
        "units": "MPa, N/mm, mm, mm^2",
        "targets": {"youngs_modulus": t.youngs_modulus, "poisson_ratio": t.poisson_ratio,
            "tensile_strength": t.tensile_strength, "fracture_energy": t.fracture_energy,
            "compressive_strength": t.compressive_strength, "c": t.c},
        "achieved": {"tensile_strength": got.tensile_strength, "compressive_strength": got.compressive_strength,
            "fracture_energy": got.fracture_energy},
        "relative_errors": {"tensile_strength": rel(got.tensile_strength, t.tensile_strength),
            "fracture_energy": rel(got.fracture_energy, t.fracture_energy), "compressive_strength": fc_err},
        "onset_half_wavelength": p.onset_half_wavelength(),
        "bar": {"h": settings.h, "length": search::BAR_LENGTH, "steps": settings.bar_steps},
        "evaluations": log,
    });
    std::fs::write(
        out.join("fit.json"),
        serde_json::to_string_pretty(&doc)? + "\n",
    )?;
    println!("{snippet}");
    println!(
        "# f_t {:.4} MPa ({:+.2} %), G_F {:.5} N/mm ({:+.2} %), f_c {:.3} MPa{}; onset half-wavelength {:.2} mm",
        got.tensile_strength,
        100.0 * rel(got.tensile_strength, t.tensile_strength),
        got.fracture_energy,
        100.0 * rel(got.fracture_energy, t.fracture_energy),
        got.compressive_strength,
        fc_err.map_or(String::new(), |e| format!(" ({:+.2} %)", 100.0 * e)),
        p.onset_half_wavelength()
    );
    println!(
        "# written: {}/{{material.toml, tension.png, bar-dissipation.png, fit.json}}",
        out.display()
    );
    Ok(())
}
