//! `mpm-concrete run` on a configuration with `[extrusion]`: the plane CT set-up as a plate, run in 3D
//! through the same command as a plane run, with the same output (history with three components per
//! reaction, 3D point fields, crack metrics and damage maps of a section layer) and checkpoints that
//! resume bit for bit.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

const EXE: &str = env!("CARGO_BIN_EXE_mpm-concrete");

/// A small CT specimen (10 x 10 cells of 4 mm), loaded fast enough to damage from about step 10 on.
const PLANE: &str = r#"
[run]
name = "tiny-plate"
steps = 20
output_every = 4

[grid]
cell_size = 4.0

[ct]
width = 40.0
height = 40.0
notch_length = 20.0
notch_width = 8.0
load_zone = [0.0, 8.0]
loading_rate = 4300.0
rise_time = 2.0e-6
material = { model = "microplane", preset = "paper" }
"#;

/// Thickness of the plate (mm): two cells, four layers of points.
const THICKNESS: f64 = 8.0;

fn scratch(tag: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("mpmc-plate-{}-{tag}", std::process::id()));
    std::fs::remove_dir_all(&dir).ok();
    std::fs::create_dir_all(&dir).expect("scratch dir");
    std::fs::write(dir.join("plane.toml"), PLANE).expect("config");
    std::fs::write(
        dir.join("plate.toml"),
        format!("{PLANE}\n[extrusion]\nthickness = {THICKNESS}\n"),
    )
    .expect("config");
    dir
}

fn run(cwd: &Path, args: &[&str]) -> Output {
    Command::new(EXE)
        .current_dir(cwd)
        .args(args)
        .output()
        .expect("start mpm-concrete")
}

fn succeeds(o: &Output) -> String {
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(
        o.status.success(),
        "{}\n{}{err}",
        o.status,
        String::from_utf8_lossy(&o.stdout)
    );
    err
}

/// The columns and rows of a `history.csv` (comment lines skipped).
fn history(dir: &Path) -> (Vec<String>, Vec<Vec<String>>) {
    let text = std::fs::read_to_string(dir.join("history.csv")).expect("history.csv");
    let mut lines = text.lines().filter(|l| !l.starts_with('#'));
    let columns = lines
        .next()
        .expect("header")
        .split(',')
        .map(String::from)
        .collect();
    let rows = lines
        .map(|l| l.split(',').map(String::from).collect())
        .collect();
    (columns, rows)
}

fn column(h: &(Vec<String>, Vec<Vec<String>>), name: &str) -> Vec<f64> {
    let k =
        h.0.iter()
            .position(|c| c == name)
            .unwrap_or_else(|| panic!("no column {name} in {:?}", h.0));
    h.1.iter()
        .map(|r| r[k].parse().expect("a number"))
        .collect()
}

#[test]
fn a_configuration_with_extrusion_runs_in_3d_and_resumes_bit_for_bit() {
    let dir = scratch("run");
    let err = succeeds(&run(
        &dir,
        &["run", "plate.toml", "--quiet", "--output", "whole"],
    ));
    assert!(err.contains("a 8 mm plate (3D)"), "{err}");
    let whole = history(&dir.join("whole"));
    assert_eq!(whole.1.len(), 20);
    // Three components per reaction, and the units of a plate.
    for c in ["loading_plate_uz", "loading_plate_fz", "support_plate_fz"] {
        assert!(whole.0.iter().any(|n| n == c), "{c} in {:?}", whole.0);
    }
    let text = std::fs::read_to_string(dir.join("whole/history.csv")).expect("history");
    assert!(text.starts_with("# units:") && text.contains("force N (3D"));

    // The plane run of the same file: before damage, the plate's force per mm of thickness is the plane
    // one's, between plane strain and plane stress (nu = 0.2: a few per cent apart), not a factor off.
    succeeds(&run(
        &dir,
        &["run", "plane.toml", "--quiet", "--output", "plane"],
    ));
    let plane = history(&dir.join("plane"));
    let f3 = column(&whole, "loading_plate_fy");
    let f2 = column(&plane, "loading_plate_fy");
    for (step, (a, b)) in f3.iter().zip(&f2).enumerate().take(8).skip(1) {
        let per_mm = a / THICKNESS;
        assert!(
            b.abs() > 1.0 && (per_mm - b).abs() < 0.1 * b.abs(),
            "step {}: plate {per_mm} N/mm, plane {b} N/mm",
            step + 1
        );
    }

    // Stopped after 10 steps and resumed: the same history, bit for bit, but for the wall times.
    succeeds(&run(
        &dir,
        &[
            "run",
            "plate.toml",
            "--quiet",
            "--output",
            "split",
            "--steps",
            "10",
        ],
    ));
    let err = succeeds(&run(
        &dir,
        &[
            "run",
            "plate.toml",
            "--quiet",
            "--output",
            "split",
            "--resume",
        ],
    ));
    assert!(err.contains("resuming at step 10"), "{err}");
    let split = history(&dir.join("split"));
    assert_eq!(split.0, whole.0);
    assert_eq!(split.1.len(), whole.1.len());
    for (name_k, name) in whole.0.iter().enumerate() {
        if name.starts_with("wall_") || name == "new_pattern" {
            continue;
        }
        for (a, b) in whole.1.iter().zip(&split.1) {
            assert_eq!(a[name_k], b[name_k], "column {name}, step {}", a[0]);
        }
    }

    // 3D point fields: positions through the thickness, every point in every snapshot.
    let f = hdf5_metno::File::open(dir.join("whole/fields_000020.h5")).expect("fields");
    let position: Vec<f64> = f
        .dataset("position")
        .and_then(|d| d.read_raw())
        .expect("position");
    let damage: Vec<f64> = f
        .dataset("damage")
        .and_then(|d| d.read_raw())
        .expect("damage");
    assert_eq!(position.len(), 3 * damage.len());
    let z: Vec<f64> = position.chunks_exact(3).map(|x| x[2]).collect();
    let (lo, hi) = z
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
            (a.min(v), b.max(v))
        });
    assert!(
        lo > 0.0 && lo < 2.0 && hi > 6.0 && hi < THICKNESS,
        "z in [{lo}, {hi}]"
    );
    for name in ["sigma_xz", "sigma_yz"] {
        assert!(f.dataset(name).is_ok(), "{name} written");
    }
    let xdmf = std::fs::read_to_string(dir.join("whole/fields.xdmf")).expect("xdmf");
    assert_eq!(
        xdmf.matches("<Grid Name=\"step_").count(),
        6,
        "steps 0, 4, .., 20"
    );
    let png = std::fs::read(dir.join("whole/damage_000020.png")).expect("damage map");
    assert!(png.starts_with(b"\x89PNG"));

    // The crack metrics of the section layer: `crack` measures the same from the snapshots.
    let states = |d: &Path| -> Vec<serde_json::Value> {
        let text = std::fs::read_to_string(d.join("crack.json")).expect("crack.json");
        let v: serde_json::Value = serde_json::from_str(&text).expect("crack.json parses");
        assert!(
            v["units"]
                .as_str()
                .is_some_and(|u| u.contains("whole plate"))
        );
        v["states"].as_array().expect("states").clone()
    };
    let written = states(&dir.join("whole"));
    assert_eq!(written.len(), 6);
    // A crack has started from the notch; the plate has dissipated energy.
    let last = written.last().expect("a state");
    let length = last["length"].as_f64().expect("length");
    assert!(length > 2.0 && length < 20.0, "crack length {length} mm");
    assert!(
        last["dissipated"][0].as_f64().is_some_and(|d| d > 1.0),
        "{last}"
    );
    succeeds(&run(&dir, &["crack", "whole"]));
    let remeasured = states(&dir.join("whole"));
    assert_eq!(remeasured.len(), written.len());
    for (a, b) in written.iter().zip(&remeasured) {
        for key in [
            "time",
            "classification",
            "length",
            "band_width",
            "nonlocal_points",
        ] {
            assert_eq!(a[key], b[key], "{key}: {a} vs {b}");
        }
    }
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_bad_extrusion_is_refused_naming_the_field() {
    let dir = scratch("bad");
    for (set, needle) in [
        ("extrusion.thickness=6.0", "multiple of grid.cell_size"),
        ("extrusion.thickness=-8.0", "thickness > 0"),
        ("extrusion.section_z=9.0", "within the plate"),
        ("extrusion.depth=2.0", "unknown field `depth`"),
    ] {
        let o = run(
            &dir,
            &[
                "run",
                "plate.toml",
                "--quiet",
                "--output",
                "x",
                "--set",
                set,
            ],
        );
        let err = String::from_utf8_lossy(&o.stderr).into_owned();
        assert_eq!(o.status.code(), Some(2), "{set}: {err}");
        assert!(
            err.contains("plate.toml") && err.contains(needle),
            "{set}: {err}"
        );
        assert!(!err.contains("panicked"), "{err}");
        assert!(!dir.join("x").exists(), "{set}: nothing written");
    }
    std::fs::remove_dir_all(&dir).ok();
}
