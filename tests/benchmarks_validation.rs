//! The benchmark configurations of `docs/validation.md` (`configs/benchmarks/`), checked cheaply: each
//! loads and passes the memory preflight at its full size, its concrete is exactly the section that
//! `fit-material` wrote next to it, and its first (elastic) load step on a coarse grid gives a stiffness
//! that agrees with the FEM mode of the same configuration (bilinear elements on the same grid) and, for
//! the beams, lies between the beam-theory stiffnesses of the beam without a notch and of a beam as deep
//! as the ligament; the offset-notched beam's elastic load-CMOD slope is checked against the experiment's.
//!
//! The full runs (minutes) are in `docs/validation.md`; these tests take seconds. Units: mm, s, N, MPa.

use mpm_concrete::config::RunConfig;
use mpm_concrete::preflight;
use mpm_concrete::scenario;
use std::path::{Path, PathBuf};
use std::process::Command;

fn config_path(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("configs/benchmarks")
        .join(name)
}

/// Loads the benchmark, checks its size as planned (points, memory well below a laptop's) and returns the
/// number of material points.
fn preflight_points(name: &str) -> f64 {
    let cfg = RunConfig::from_file(&config_path(name)).expect("the benchmark loads");
    let plan = scenario::plan(&cfg).expect("plan");
    let need = preflight::memory_need(&plan).expect("memory estimate");
    assert!(
        need.bytes < 1.0e9,
        "{name}: the preflight estimates {} (a benchmark must run on a laptop)",
        preflight::human_bytes(need.bytes)
    );
    need.points
}

/// The `[[body]]` material of the benchmark must be the `[material]` section of its fitted file.
fn assert_fitted_material(config: &str, material_file: &str) {
    let read = |f: &str| -> toml::Table {
        toml::from_str(&std::fs::read_to_string(config_path(f)).expect("read")).expect("toml")
    };
    let cfg = read(config);
    let body = &cfg["body"].as_array().expect("[[body]]")[0];
    let fitted = read(material_file);
    assert_eq!(
        body["material"].as_table().expect("material table"),
        fitted["material"].as_table().expect("[material]"),
        "{config}: the concrete differs from {material_file} (re-fit or copy the section)"
    );
}

/// Runs the first `steps` steps of the benchmark on cells of `h` mm with `method` ("mpm" or "fem") and
/// returns the `history.csv` values of `columns` after the last step (mm, N per mm thickness).
fn first_steps(name: &str, method: &str, h: f64, steps: usize, columns: &[&str]) -> Vec<f64> {
    let dir = std::env::temp_dir().join(format!(
        "mpmc-benchmark-{}-{name}-{method}-{h}",
        std::process::id()
    ));
    let kind = if method == "fem" { "linear" } else { "cpdi1" };
    let out = Command::new(env!("CARGO_BIN_EXE_mpm-concrete"))
        .arg("run")
        .arg(config_path(name))
        .args(["--quiet", "--overwrite", "--steps", &steps.to_string()])
        .arg("--output")
        .arg(&dir)
        .args(["--set", &format!("shape.method={method}")])
        .args(["--set", &format!("shape.kind={kind}")])
        .args(["--set", &format!("grid.cell_size={h}")])
        .args(["--set", "run.output_every=1000"])
        .output()
        .expect("running mpm-concrete");
    assert!(
        out.status.success(),
        "{name} {method} h = {h}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = std::fs::read_to_string(dir.join("history.csv")).expect("history.csv");
    std::fs::remove_dir_all(&dir).ok();
    let mut rows = text.lines().filter(|l| !l.starts_with('#'));
    let header: Vec<&str> = rows.next().expect("header").split(',').collect();
    let last: Vec<&str> = rows.next_back().expect("a step").split(',').collect();
    let col = |c: &str| -> f64 {
        let k = header.iter().position(|h| *h == c).expect("column");
        last[k].parse().expect("number")
    };
    columns.iter().map(|c| col(c)).collect()
}

/// MPM against FEM on the same grid: the stiffness of the first step (N/mm per mm thickness).
fn mpm_and_fem_stiffness(name: &str, h: f64) -> (f64, f64) {
    let [mpm, fem] = ["mpm", "fem"].map(|m| {
        let row = first_steps(name, m, h, 1, &["load_uy", "load_fy"]);
        let (u, f) = (row[0], row[1]);
        assert!(u != 0.0, "{name} {m}: the load point did not move");
        f / u
    });
    println!("{name}, h = {h} mm: first-step stiffness MPM {mpm:.2}, FEM {fem:.2} N/mm per mm");
    (mpm, fem)
}

/// Stiffness (N/mm per mm thickness) of a simply supported Timoshenko beam of depth `d` (mm) on `span`
/// (mm) under a central load, plane strain (`E/(1 - nu^2)`, shear factor 5/6), `e` in MPa.
fn timoshenko_stiffness(e: f64, nu: f64, span: f64, d: f64) -> f64 {
    let (e_ps, g) = (e / (1.0 - nu * nu), e / (2.0 * (1.0 + nu)));
    let compliance =
        span.powi(3) / (48.0 * e_ps * d.powi(3) / 12.0) + span / (4.0 * 5.0 / 6.0 * g * d);
    1.0 / compliance
}

#[test]
fn l_panel_loads_is_fitted_and_is_as_stiff_as_its_fem_twin() {
    assert_eq!(preflight_points("l-panel.toml"), 30_000.0);
    assert_fitted_material("l-panel.toml", "l-panel-material.toml");
    let (mpm, fem) = mpm_and_fem_stiffness("l-panel.toml", 25.0);
    // The load pushes up: a positive reaction for a positive displacement.
    assert!(mpm > 0.0 && fem > 0.0);
    // Measured: MPM 0.8 % softer than FEM at h = 25 mm (CPDI1 against bilinear elements).
    assert!(
        (mpm / fem - 1.0).abs() < 0.05,
        "MPM {mpm:.2} vs FEM {fem:.2} N/mm per mm: more than 5 % apart"
    );
}

#[test]
fn three_point_beam_loads_is_fitted_and_lies_between_beam_bounds() {
    assert_eq!(preflight_points("petersson-3pb.toml"), 32_000.0);
    assert_fitted_material("petersson-3pb.toml", "petersson-3pb-material.toml");
    let (mpm, fem) = mpm_and_fem_stiffness("petersson-3pb.toml", 20.0);
    // Measured: MPM 1.3 % softer than FEM at h = 20 mm; the beam 65.1 N/mm per mm in [15.5, 121.4].
    // The load pushes down: a negative reaction for a negative displacement.
    assert!(mpm > 0.0 && fem > 0.0);
    assert!(
        (mpm / fem - 1.0).abs() < 0.05,
        "MPM {mpm:.2} vs FEM {fem:.2} N/mm per mm: more than 5 % apart"
    );
    // The half beam carries half the load P for the same deflection: k = P/w = 2 f/u (per mm thickness).
    let k = 2.0 * mpm;
    // The beam without a notch (d = 200) is stiffer than the notched one, a beam as deep as the ligament
    // (d = 100) softer.
    let beam = |d: f64| timoshenko_stiffness(30_000.0, 0.2, 2000.0, d);
    let (soft, stiff) = (beam(100.0), beam(200.0));
    println!("beam stiffness {k:.2} N/mm per mm, bounds [{soft:.2}, {stiff:.2}]");
    assert!(
        soft < k && k < stiff,
        "beam stiffness {k:.2} N/mm per mm outside the beam-theory bounds [{soft:.2}, {stiff:.2}]"
    );
}

#[test]
fn offset_notched_beam_loads_is_fitted_and_matches_the_elastic_slopes() {
    let name = "offset-notch-3pb.toml";
    // 100 x 32 cells of 2.5 mm with 2 x 2 points, less the notch's 2 x 8 cells.
    assert_eq!(preflight_points(name), 12_736.0);
    assert_fitted_material(name, "offset-notch-3pb-material.toml");
    // The first step opens the crack mouth by the path increment, 0.001 mm, at the full size: the 5 mm
    // notch is two cells, so MPM and FEM (which drops the notch's cells) model the same notch.
    let cols = ["load_uy", "load_fy", "path_opening"];
    let [mpm, fem] = ["mpm", "fem"].map(|m| first_steps(name, m, 2.5, 1, &cols));
    for row in [&mpm, &fem] {
        // Pushed down: the load point moves down and the reaction points up in the set's sign.
        assert!(
            row[0] < 0.0 && row[1] < 0.0,
            "the load point did not move down: {row:?}"
        );
        assert!(
            (row[2] - 1.0e-3).abs() < 1.0e-9,
            "CMOD {} after one step",
            row[2]
        );
    }
    let (k_mpm, k_fem) = (mpm[1] / mpm[0], fem[1] / fem[0]);
    println!("{name}: first-step stiffness MPM {k_mpm:.1}, FEM {k_fem:.1} N/mm per mm");
    assert!(
        (k_mpm / k_fem - 1.0).abs() < 0.05,
        "MPM {k_mpm:.1} vs FEM {k_fem:.1} N/mm per mm: more than 5 % apart"
    );
    // Between the Timoshenko beams without a notch (d = 80 mm) and as deep as the ligament (60 mm).
    let beam = |d: f64| timoshenko_stiffness(33_800.0, 0.2, 200.0, d);
    let (soft, stiff) = (beam(60.0), beam(80.0));
    println!("beam stiffness {k_mpm:.1} N/mm per mm, bounds [{soft:.1}, {stiff:.1}]");
    assert!(
        soft < k_mpm && k_mpm < stiff,
        "stiffness {k_mpm:.1} N/mm per mm outside the beam-theory bounds [{soft:.1}, {stiff:.1}]"
    );
    // The elastic load-CMOD slope of the whole 50 mm beam against the experiment's: the tangent of both
    // bounding curves of the measured band between CMOD 0.005 and 0.0075 mm is 498-510 kN/mm
    // (docs/validation.md, "Offset-notched beam"); plane strain is a few per cent stiffer.
    let slope = -50.0 * mpm[1] / mpm[2] / 1000.0;
    println!("load-CMOD slope {slope:.1} kN/mm (experiment 498-510)");
    assert!(
        (0.95 * 498.0..1.10 * 510.0).contains(&slope),
        "elastic load-CMOD slope {slope:.1} kN/mm, experiment 498-510 kN/mm"
    );
}
