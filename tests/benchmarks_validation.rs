//! The benchmark configurations of `docs/validation.md` (`configs/benchmarks/`), checked cheaply: each
//! loads and passes the memory preflight at its full size, its concrete is exactly the section that
//! `fit-material` wrote next to it, and its first (elastic) load step on a coarse grid gives a stiffness
//! that agrees with the FEM mode of the same configuration (bilinear elements on the same grid) and, for
//! the beam, lies between the beam-theory stiffnesses of the beam without a notch and of a beam as deep
//! as the ligament.
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
/// returns the load set's (displacement, reaction) in y after the last step (mm, N per mm thickness).
fn first_steps(name: &str, method: &str, h: f64, steps: usize) -> (f64, f64) {
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
    (col("load_uy"), col("load_fy"))
}

/// MPM against FEM on the same grid: the stiffness of the first step (N/mm per mm thickness).
fn mpm_and_fem_stiffness(name: &str, h: f64) -> (f64, f64) {
    let [mpm, fem] = ["mpm", "fem"].map(|m| {
        let (u, f) = first_steps(name, m, h, 1);
        assert!(u != 0.0, "{name} {m}: the load point did not move");
        f / u
    });
    println!("{name}, h = {h} mm: first-step stiffness MPM {mpm:.2}, FEM {fem:.2} N/mm per mm");
    (mpm, fem)
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
    // Timoshenko beam on span L under a central load, plane strain, depth d: the beam without a notch
    // (d = 200) is stiffer than the notched one, a beam as deep as the ligament (d = 100) softer.
    let (e, nu, span): (f64, f64, f64) = (30_000.0, 0.2, 2000.0);
    let (e_ps, g) = (e / (1.0 - nu * nu), e / (2.0 * (1.0 + nu)));
    let beam = |d: f64| -> f64 {
        let compliance =
            span.powi(3) / (48.0 * e_ps * d.powi(3) / 12.0) + span / (4.0 * 5.0 / 6.0 * g * d);
        1.0 / compliance
    };
    let (soft, stiff) = (beam(100.0), beam(200.0));
    println!("beam stiffness {k:.2} N/mm per mm, bounds [{soft:.2}, {stiff:.2}]");
    assert!(
        soft < k && k < stiff,
        "beam stiffness {k:.2} N/mm per mm outside the beam-theory bounds [{soft:.2}, {stiff:.2}]"
    );
}
