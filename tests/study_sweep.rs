//! `study` as a sweep over configuration overrides, on the real binary and the tiny CT (360 points):
//! the sets' overrides and step counts reach their runs, the table holds the crack and reaction columns,
//! and every bad line of a sets file is refused before any run starts (exit code 2, the file, the line,
//! the set and the key named, nothing written).

mod binary;

use binary::{EXE, refused, scratch, succeeds};
use std::path::Path;
use std::process::{Command, Output};

/// `mpm-concrete study tiny.toml ...` in `dir`.
fn study(dir: &Path, extra: &[&str]) -> Output {
    Command::new(EXE)
        .current_dir(dir)
        .args(["study", "tiny.toml", "--steps", "2"])
        .args(extra)
        .output()
        .expect("start mpm-concrete")
}

#[test]
fn a_sweep_over_overrides_runs_each_set_with_its_overrides_into_one_table() {
    let sets = "# a sweep\n\
                slow: --set ct.loading_rate=2000 --steps 3\n\
                fast: --set=ct.loading_rate=4300 -ksp_type preonly -pc_type lu\n";
    let dir = scratch("study", "sweep", &[("sets.txt", sets)]);
    let o = study(&dir, &["--sets", "sets.txt", "--output", "out"]);
    succeeds(&o);
    let out = dir.join("out");
    let config = |set: &str| std::fs::read_to_string(out.join(set).join("config.toml")).unwrap();
    assert!(config("slow").contains("loading_rate = 2000"));
    assert!(config("fast").contains("loading_rate = 4300"));
    let rows = |set: &str| {
        let h = std::fs::read_to_string(out.join(set).join("history.csv")).unwrap();
        h.lines().filter(|l| !l.starts_with('#')).count() - 1
    };
    assert_eq!((rows("slow"), rows("fast")), (3, 2));
    let csv = std::fs::read_to_string(out.join("study.csv")).expect("study.csv");
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    for column in [
        "crack_length_mm",
        "branches",
        "dissipated_tension",
        "peak_reaction",
        "overrides",
    ] {
        assert!(header.contains(&column), "{column} missing in {header:?}");
    }
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    assert_eq!(rows.len(), 2);
    for row in &rows {
        assert_eq!(row[col("converged")], "true", "{row:?}");
        let peak: f64 = row[col("peak_reaction")].parse().expect("a peak reaction");
        assert!(peak > 0.0 && peak.is_finite(), "{row:?}");
        assert!(
            row[col("crack_length_mm")].parse::<f64>().is_ok(),
            "{row:?}"
        );
    }
    // The faster plate pushes harder.
    let peak = |r: &Vec<&str>| r[col("peak_reaction")].parse::<f64>().unwrap();
    assert!(peak(&rows[1]) > peak(&rows[0]), "{rows:?}");
    let md = std::fs::read_to_string(out.join("study.md")).expect("study.md");
    assert!(
        md.contains("- `slow`: `--set ct.loading_rate=2000`"),
        "{md}"
    );
    assert!(md.contains("| crack | branches | angles | dissipated | peak reaction |"));
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn every_set_line_is_checked_before_the_first_run() {
    let cases: [(&str, &[&str]); 5] = [
        (
            "ok: --set ct.loading_rate=2000\nh1: --set grid.cell_siz=1\n",
            &["sets.txt:2: set `h1`", "cell_siz"],
        ),
        (
            "ok: --set grid.cell_size=4\nneg: --set grid.cell_size=-1\n",
            &["sets.txt:2: set `neg`", "grid.cell_size", "-1"],
        ),
        (
            "a: --set ct.material.erosion_damage=x\n",
            &["sets.txt:1: set `a`", "erosion_damage"],
        ),
        ("a: --steps 0\n", &["sets.txt:1: set `a`", "--steps 0"]),
        (
            "a: --output elsewhere -pc_type lu\n",
            &[
                "sets.txt:1: set `a`",
                "`--output` is no option of a set line",
            ],
        ),
    ];
    for (i, (sets, needles)) in cases.iter().enumerate() {
        let dir = scratch("study", &format!("refusal{i}"), &[("sets.txt", sets)]);
        let o = study(&dir, &["--sets", "sets.txt", "--output", "out"]);
        let line = refused(&o, needles);
        assert!(!dir.join("out").exists(), "{sets}: wrote out/: {line}");
        std::fs::remove_dir_all(&dir).ok();
    }
    let dir = scratch("study", "output-file", &[("notes.txt", "mine")]);
    let o = study(&dir, &["--output", "notes.txt"]);
    refused(&o, &["notes.txt", "exists and is not a directory"]);
    assert_eq!(
        std::fs::read_to_string(dir.join("notes.txt")).unwrap(),
        "mine"
    );
    std::fs::remove_dir_all(&dir).ok();
}
