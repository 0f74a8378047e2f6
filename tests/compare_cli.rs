//! `mpm-concrete compare` end to end: a tiny quasi-static run (a linear-elastic block stretched
//! homogeneously, so its displacement is linear in the reference position), then references built from
//! its own history and from the analytic field pass, a perturbed one fails (exit 1) and bad input exits 2
//! with a message naming the file.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::OnceLock;

const EXE: &str = env!("CARGO_BIN_EXE_mpm-concrete");

/// Stretch rate (1/s): the nodes at x = 20 and x = 22 move with `RATE x`, the left face is held, so every
/// step maps x -> (1 + RATE dt) x and ux(X) = ((1 + RATE dt)^n - 1) X exactly (Poisson's ratio 0: no
/// lateral stress, uy = 0).
const RATE: f64 = 0.25;
const DT: f64 = 1.0e-3;
const STEPS: i32 = 4;
const E: f64 = 30000.0;

const CONFIG: &str = r#"
[run]
name = "compare-stretch"
steps = 4
output_every = 1
petsc_options = "-ksp_type preonly -pc_type lu"

[time]
dt = 1.0e-3
quasi_static = true

[grid]
cell_size = 2.0

[shape]
kind = "cpdi1"
points_per_cell = 2

[[body]]
name = "block"
density = 2.4e-9
geometry = { include = [{ type = "rect", min = [0.0, 0.0], max = [20.0, 10.0] }] }
material = { model = "linear_elastic", youngs_modulus = 30000.0, poisson_ratio = 0.0 }

[[constraint]]
name = "held"
min = [-0.1, -1.0]
max = [0.1, 11.0]
x = "fixed"
y = "fixed"

[[constraint]]
name = "pulled"
min = [19.9, -1.0]
max = [20.1, 11.0]
x = { velocity = 5.0 }

[[constraint]]
name = "outer"
min = [21.9, -1.0]
max = [22.1, 11.0]
x = { velocity = 5.5 }
"#;

fn base() -> PathBuf {
    std::env::temp_dir().join(format!("mpmc-compare-{}", std::process::id()))
}

/// Runs the simulation once (shared by the tests) and returns its output directory.
fn run_dir() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let base = base();
        std::fs::create_dir_all(&base).expect("temp dir");
        let cfg = base.join("stretch.toml");
        std::fs::write(&cfg, CONFIG).expect("config");
        let out = base.join("run");
        let o = Command::new(EXE)
            .arg("run")
            .arg(&cfg)
            .arg("--output")
            .arg(&out)
            .arg("--quiet")
            .output()
            .expect("running mpm-concrete");
        assert!(
            o.status.success(),
            "run failed: {}",
            String::from_utf8_lossy(&o.stderr)
        );
        out
    })
}

fn write(name: &str, text: &str) -> PathBuf {
    let p = base().join(name);
    std::fs::write(&p, text).expect("reference file");
    p
}

fn compare(args: &[&str]) -> Output {
    Command::new(EXE)
        .arg("compare")
        .args(args)
        .output()
        .expect("running mpm-concrete compare")
}

fn code(o: &Output) -> i32 {
    o.status.code().expect("exit code")
}

fn text(o: &Output) -> String {
    format!(
        "stdout:\n{}\nstderr:\n{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

/// The run's history.csv: header and rows.
fn history() -> (Vec<String>, Vec<Vec<String>>) {
    let s = std::fs::read_to_string(run_dir().join("history.csv")).expect("history.csv");
    let mut lines = s.lines().filter(|l| !l.starts_with('#'));
    let header = lines
        .next()
        .expect("header")
        .split(',')
        .map(str::to_owned)
        .collect();
    let rows = lines
        .map(|l| l.split(',').map(str::to_owned).collect())
        .collect();
    (header, rows)
}

/// A history reference of `columns`, from the run's own history.csv; `edit` may change a value
/// (row, column index, value).
fn self_reference(columns: &[&str], edit: impl Fn(usize, usize, f64) -> f64) -> String {
    let (header, rows) = history();
    let idx: Vec<usize> = ["time"]
        .iter()
        .chain(columns)
        .map(|c| header.iter().position(|h| h == c).expect("column"))
        .collect();
    let mut s = format!(
        "# built from the run's own history\ntime,{}\n",
        columns.join(",")
    );
    for (r, row) in rows.iter().enumerate() {
        let mut fields = vec![row[idx[0]].clone()];
        for (c, &i) in idx[1..].iter().enumerate() {
            let v: f64 = row[i].parse().expect("number");
            let w = edit(r, c, v);
            fields.push(if w == v {
                row[i].clone()
            } else {
                format!("{w:e}")
            });
        }
        s.push_str(&fields.join(","));
        s.push('\n');
    }
    s
}

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).expect("json")).expect("valid json")
}

#[test]
fn history_reference_from_the_run_itself_passes_with_zero_error() {
    let dir = run_dir();
    let cols = ["pulled_fx", "held_fx", "pulled_ux", "stored_energy"];
    let r = write("self.csv", &self_reference(&cols, |_, _, v| v));
    // pulled_ux = 5 mm/s t is linear in time: reference values between the steps test the interpolation.
    let mid = write(
        "mid.csv",
        "time,pulled_ux\n# between steps\n1.5e-3,7.5e-3\n3.25e-3,1.625e-2\n",
    );
    // A single row at the run's last time.
    let (header, rows) = history();
    let fx = header.iter().position(|h| h == "held_fx").expect("held_fx");
    let last = rows.last().expect("rows");
    let single = write(
        "single.csv",
        &format!("time,held_fx\n{},{}\n", last[1], last[fx]),
    );
    let out = base().join("history.json");
    let o = compare(&[
        dir.to_str().expect("utf-8"),
        r.to_str().expect("utf-8"),
        mid.to_str().expect("utf-8"),
        single.to_str().expect("utf-8"),
        "--json",
        out.to_str().expect("utf-8"),
    ]);
    assert_eq!(code(&o), 0, "{}", text(&o));
    assert!(text(&o).contains("PASSED"), "{}", text(&o));
    let j = json(&out);
    assert_eq!(j["passed"], true);
    let refs = j["references"].as_array().expect("references");
    assert_eq!(refs.len(), 3);
    for r in refs {
        assert_eq!(r["kind"], "history");
        for c in r["columns"].as_array().expect("columns") {
            let (l2, max) = (
                c["rel_l2"].as_f64().unwrap(),
                c["rel_max"].as_f64().unwrap(),
            );
            assert!(l2 <= 1e-9 && max <= 1e-9, "{c}");
        }
    }
    // The reaction of the held face peaks (in magnitude) at the last step: sigma_xx H.
    let held = &refs[0]["columns"][1];
    let strain = (1.0 + RATE * DT).powi(STEPS) - 1.0;
    let peak = held["peak_run"]["value"].as_f64().unwrap();
    assert!(
        (peak + E * strain * 10.0).abs() < 1e-6 * E * strain * 10.0,
        "{held}"
    );
    assert!((held["peak_reference"]["time"].as_f64().unwrap() - 4e-3).abs() < 1e-12);
}

#[test]
fn a_value_perturbed_by_ten_percent_fails() {
    let dir = run_dir();
    let n = history().1.len();
    // The largest reaction (last row) 10 % too high.
    let r = write(
        "perturbed.csv",
        &self_reference(&["pulled_fx", "held_fx"], |row, c, v| {
            if row == n - 1 && c == 0 { 1.1 * v } else { v }
        }),
    );
    let out = base().join("perturbed.json");
    let o = compare(&[
        dir.to_str().unwrap(),
        r.to_str().unwrap(),
        "--tolerance",
        "0.05",
        "--json",
        out.to_str().unwrap(),
    ]);
    assert_eq!(code(&o), 1, "{}", text(&o));
    let t = text(&o);
    assert!(
        t.contains("FAILED") && t.contains("column `pulled_fx`"),
        "{t}"
    );
    assert!(!t.contains("column `held_fx`: relative"), "{t}");
    let j = json(&out);
    assert_eq!(j["passed"], false);
    let c = &j["references"][0]["columns"][0];
    // The perturbed value is the largest: relative max error 0.1 / 1.1.
    let max = c["rel_max"].as_f64().unwrap();
    assert!((max - 0.1 / 1.1).abs() < 1e-6, "{c}");
    assert_eq!(j["references"][0]["columns"][1]["passed"], true);
}

#[test]
fn point_reference_of_the_linear_displacement_is_reproduced() {
    let dir = run_dir();
    let strain = (1.0 + RATE * DT).powi(STEPS) - 1.0;
    let mut s =
        String::from("# ux = strain X at the last step, at corners (extrapolated) and inside\n");
    s.push_str("time,x,y,quantity,value\n");
    let points = [
        (0.0, 0.0),
        (20.0, 0.0),
        (20.0, 10.0),
        (0.0, 10.0),
        (7.3, 4.1),
        (13.0, 2.0),
        (19.5, 9.9),
        (10.0, 5.0),
    ];
    for (x, y) in points {
        s.push_str(&format!("4e-3,{x},{y},ux,{:e}\n", strain * x));
    }
    for (x, y) in points {
        s.push_str(&format!("4e-3,{x},{y},sigma_xx,{:e}\n", E * strain));
    }
    // After the first step, from the snapshot fields_000001.h5.
    let strain1 = RATE * DT;
    for (x, y) in points {
        s.push_str(&format!("1e-3,{x},{y},ux,{:e}\n", strain1 * x));
    }
    let r = write("points.csv", &s);
    let out = base().join("points.json");
    let o = compare(&[
        dir.to_str().unwrap(),
        r.to_str().unwrap(),
        "--tolerance",
        "1e-8",
        "--json",
        out.to_str().unwrap(),
    ]);
    assert_eq!(code(&o), 0, "{}", text(&o));
    let j = json(&out);
    let groups = j["references"][0]["groups"].as_array().expect("groups");
    assert_eq!(groups.len(), 3);
    let names: Vec<(&str, &str)> = groups
        .iter()
        .map(|g| {
            (
                g["quantity"].as_str().unwrap(),
                g["snapshot"].as_str().unwrap(),
            )
        })
        .collect();
    assert_eq!(
        names,
        [
            ("ux", "fields_000004.h5"),
            ("sigma_xx", "fields_000004.h5"),
            ("ux", "fields_000001.h5")
        ]
    );
    for g in groups {
        assert!(g["rel_max"].as_f64().unwrap() <= 1e-8, "{g}");
        assert_eq!(g["points"].as_array().unwrap().len(), points.len());
    }
    // The current positions are not the reference configuration: evaluated there, ux would be off by
    // the strain (relative); a reference in current coordinates fails.
    let mut wrong = String::from("time,x,y,quantity,value\n");
    for (x, y) in points {
        wrong.push_str(&format!(
            "4e-3,{},{y},ux,{:e}\n",
            x * (1.0 + strain),
            strain * x
        ));
    }
    let w = write("current.csv", &wrong);
    let o = compare(&[
        dir.to_str().unwrap(),
        w.to_str().unwrap(),
        "--tolerance",
        "1e-6",
    ]);
    assert_eq!(code(&o), 1, "{}", text(&o));
}

#[test]
fn bad_input_exits_2_with_a_message_naming_the_file() {
    let dir = run_dir();
    let d = dir.to_str().unwrap();
    let cases = [
        (
            write("bad_column.csv", "time,pulled_fz\n1e-3,1\n"),
            "bad_column.csv:1: column `pulled_fz` is not in",
        ),
        (
            write(
                "bad_quantity.csv",
                "# c\ntime,x,y,quantity,value\n4e-3,1,1,strain,0\n",
            ),
            "bad_quantity.csv:3: quantity `strain` is unknown; allowed: ux, uy",
        ),
        (
            write("bad_row.csv", "time,held_fx\n1e-3,1\n2e-3\n"),
            "bad_row.csv:3: 1 fields, the header has 2",
        ),
        (
            write("bad_number.csv", "time,held_fx\n1e-3,one\n"),
            "bad_number.csv:2: `held_fx` = `one` is not a finite number",
        ),
        (
            write("bad_header.csv", "t,x\n1,2\n"),
            "bad_header.csv:1: header `t,x`: expected",
        ),
        (
            write("bad_time.csv", "time,held_fx\n0.5,1\n"),
            "bad_time.csv:2: time 0.5 s is outside the run's history",
        ),
        (
            write(
                "bad_snapshot.csv",
                "time,x,y,quantity,value\n3.5e-3,1,1,ux,0\n",
            ),
            "bad_snapshot.csv:2: time 0.0035 s: no snapshot within",
        ),
        (
            write("bad_point.csv", "time,x,y,quantity,value\n4e-3,60,5,ux,0\n"),
            "bad_point.csv:2: point (60, 5) mm lies",
        ),
        (base().join("missing.csv"), "missing.csv: cannot read"),
    ];
    for (file, message) in &cases {
        let o = compare(&[d, file.to_str().unwrap()]);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(code(&o), 2, "{}: {}", file.display(), text(&o));
        assert!(err.contains(message), "expected `{message}` in: {err}");
        assert!(!err.contains("panicked"), "{err}");
        assert_eq!(err.trim().lines().count(), 1, "one line: {err}");
    }
    // A missing run directory.
    let ok = write("ok.csv", "time,held_fx\n1e-3,-75\n");
    let o = compare(&["/nonexistent/run", ok.to_str().unwrap()]);
    assert_eq!(code(&o), 2, "{}", text(&o));
    assert!(
        text(&o).contains("/nonexistent/run: not a directory"),
        "{}",
        text(&o)
    );
}
