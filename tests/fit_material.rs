//! `fit-material` (docs/material.md, "Parameters from engineering data"): bad engineering data is refused
//! by the real binary before any work (exit 2, one line naming the option and the allowed range), and the
//! documented example's fitted parameters reach f_t (driver, read back from the snippet) within 2 % and
//! G_F (the quasi-static fitting bar, h = 2 mm) within 5 %; and the full fit through the binary (f_t = 3 MPa,
//! G_F = 0.1 N/mm on the h = 2 mm bar) is checked by an independent `material-driver` run on the written
//! `material.toml` (f_t within 2 %) and by its reported G_F (within 5 %).
//!
//! Units: MPa, N/mm, mm, mm^2.

mod binary;

use binary::{EXE, refused, scratch};
use mpm_concrete::app::fit_material::search::{self, Targets};
use mpm_concrete::app::fit_material::{achieved, toml_snippet};
use mpm_concrete::petsc::{self, Session};
use std::process::Command;

/// `mpm-concrete fit-material ARGS` in a scratch directory.
fn fit(tag: &str, args: &[&str]) -> (std::path::PathBuf, std::process::Output) {
    let dir = scratch("fit", tag, &[]);
    let out = Command::new(EXE)
        .current_dir(&dir)
        .arg("fit-material")
        .args(args)
        .output()
        .expect("start mpm-concrete");
    (dir, out)
}

const GOOD: [&str; 6] = [
    "--youngs-modulus",
    "30000",
    "--tensile-strength",
    "3",
    "--fracture-energy",
    "0.1",
];

/// `GOOD` with `option` set to `value` (replaced if present, else appended).
fn with(option: &str, value: &str) -> Vec<String> {
    let mut args: Vec<String> = GOOD.iter().map(|s| s.to_string()).collect();
    match args.iter().position(|a| a == option) {
        Some(i) => args[i + 1] = value.to_string(),
        None => args.extend([option.to_string(), value.to_string()]),
    }
    args
}

#[test]
fn bad_engineering_data_is_refused_naming_the_option_and_its_range() {
    let cases: [(&str, &str, &[&str]); 11] = [
        ("--youngs-modulus", "-30000", &["--youngs-modulus", "E > 0"]),
        ("--youngs-modulus", "NaN", &["--youngs-modulus", "E > 0"]),
        (
            "--poisson-ratio",
            "0.5",
            &["--poisson-ratio", "0 <= nu < 0.5"],
        ),
        (
            "--tensile-strength",
            "400",
            &["--tensile-strength", "E/100"],
        ),
        (
            "--tensile-strength",
            "-3",
            &["--tensile-strength", "0 < f_t"],
        ),
        ("--fracture-energy", "0", &["--fracture-energy", "G_F > 0"]),
        (
            "--compressive-strength",
            "2",
            &["--compressive-strength", "f_c > f_t"],
        ),
        ("--length", "-3", &["--length", "l > 0"]),
        ("--h", "inf", &["--h", "0 < h <= 5"]),
        // Far beyond what the fitting bar reaches: refused at once, the range with its unit.
        (
            "--fracture-energy",
            "1e9",
            &[
                "--fracture-energy",
                "<= G_F <= 1.309e0 N/mm",
                "a smaller --c",
            ],
        ),
        (
            "--fracture-energy",
            "1e-9",
            &["--fracture-energy", "4.500e-3 <= G_F", "N/mm", "snaps back"],
        ),
    ];
    for (k, (option, value, needles)) in cases.into_iter().enumerate() {
        let args = with(option, value);
        let start = std::time::Instant::now();
        let (dir, out) = fit(
            &format!("bad{k}"),
            &args.iter().map(String::as_str).collect::<Vec<_>>(),
        );
        refused(&out, needles);
        assert!(!dir.join("out").exists(), "{option}: nothing written");
        // Before any bar run (one takes seconds).
        assert!(
            start.elapsed().as_secs_f64() < 5.0,
            "{option} {value}: {:?}",
            start.elapsed()
        );
        std::fs::remove_dir_all(&dir).ok();
    }
}

/// PETSc options would be ignored (the fitting bar's solver is fixed): refused before any work.
#[test]
fn petsc_options_are_refused_before_any_work() {
    let mut args: Vec<&str> = GOOD.to_vec();
    args.extend(["-snes_monitor", "-ksp_type", "gmres"]);
    let (dir, out) = fit("petsc", &args);
    refused(
        &out,
        &[
            "fit-material takes no PETSc options",
            "-snes_monitor -ksp_type gmres",
            "MUMPS LU",
        ],
    );
    assert!(!dir.join("out").exists(), "nothing written");
    std::fs::remove_dir_all(&dir).ok();
}

/// The targets of the documented example.
fn example() -> Targets {
    Targets {
        youngs_modulus: 30000.0,
        poisson_ratio: 0.2,
        tensile_strength: 3.0,
        fracture_energy: 0.1,
        compressive_strength: None,
        c: 9.0,
    }
}

/// The example's fitted section (docs/material.md, "Parameters from engineering data").
const FITTED: &str = "[material]
model = \"microplane\"
bulk_modulus = 1.6666666666666668e4
shear_modulus = 1.25e4
poisson_ratio = 0.2
gamma_0 = 1.0007947881923046e-4
k_r = 1.4e1
alpha = 0.98
beta = 2.0988208964415847e2
c = 9e0
gradient_activity = { kind = \"constant\" }
";

#[test]
fn the_fitted_example_dissipates_its_fracture_energy_on_the_bar() {
    let t = example();
    let section: toml::Table = toml::from_str(FITTED).unwrap();
    let cfg = match section["material"].clone().try_into().unwrap() {
        mpm_concrete::material::MaterialConfig::Microplane(m) => m,
        other => panic!("{other:?}"),
    };
    assert_eq!(
        toml_snippet(&cfg).unwrap(),
        FITTED,
        "the snippet reads back unchanged"
    );
    // f_t by the driver's own strength measurement (independent of the fit's scaling loop).
    let got = achieved(FITTED, f64::NAN, 2000).unwrap();
    assert!((got.tensile_strength / 3.0 - 1.0).abs() < 0.02, "{got:?}");
    let s = Session::get().expect("PETSc");
    petsc::apply_default_options(
        &s,
        "-fit_ksp_type preonly -fit_pc_type lu -fit_pc_factor_mat_solver_type mumps \
         -fit_snes_rtol 1e-10 -fit_snes_atol 1e-10 -fit_snes_stol 0 -fit_snes_max_it 40",
    )
    .unwrap();
    let bar =
        search::bar_fracture_energy(&s, &cfg, 2.0, search::end_displacement(&t), 200).unwrap();
    eprintln!(
        "G_F {:.5} N/mm, peak {:.4} MPa, {} steps, separated {}",
        bar.fracture_energy,
        bar.peak_stress,
        bar.steps.len(),
        bar.separated
    );
    assert!(bar.separated, "the end stress fell below 5 % of its peak");
    assert!(
        (bar.fracture_energy / 0.1 - 1.0).abs() < 0.05,
        "G_F {}",
        bar.fracture_energy
    );
}

/// The full fit through the binary, checked independently: `material-driver --config material.toml`
/// prints the tensile strength.
#[test]
fn full_fit_to_3_mpa_and_0_1_n_per_mm_is_within_tolerance() {
    let (dir, out) = fit(
        "full",
        &with("--h", "2")
            .iter()
            .map(String::as_str)
            .collect::<Vec<_>>(),
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let json: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(dir.join("out/fit-material/fit.json")).unwrap(),
    )
    .unwrap();
    let gf = json["achieved"]["fracture_energy"].as_f64().unwrap();
    assert!((gf / 0.1 - 1.0).abs() < 0.05, "G_F {gf}");
    let driver = Command::new(EXE)
        .current_dir(&dir)
        .args([
            "material-driver",
            "--config",
            "out/fit-material/material.toml",
            "--out",
            "drv",
        ])
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&driver.stdout).into_owned();
    let ft: f64 = text
        .split("tensile ")
        .nth(1)
        .and_then(|r| r.split(' ').next())
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("{text}"));
    assert!((ft / 3.0 - 1.0).abs() < 0.02, "f_t {ft}");
    std::fs::remove_dir_all(&dir).ok();
}
