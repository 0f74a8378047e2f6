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
    assert!(md.contains("| crack | branches | angles | widths | dissipated | peak reaction |"));
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn every_set_line_is_checked_before_the_first_run() {
    let cases: [(&str, &[&str]); 7] = [
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
        // A quoted value with a space is one word, checked as the run would get it.
        (
            "a: --set run.petsc_options=\"-ksp_rtol -5\"\n",
            &["sets.txt:1: set `a`", "run.petsc_options", "-ksp_rtol -5"],
        ),
        (
            "a: --set run.name=\"CT a -pc_type lu\n",
            &["sets.txt:1: set `a`", "unterminated \""],
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

/// A study in which every set fails ends with each set's reason and its directory, exit code 1, its
/// report written and no charts (nothing to draw).
#[test]
fn a_study_whose_every_set_fails_says_so_for_each_set() {
    let sets = "a: -snes_monitr\nb: -pc_typ lu\n";
    let dir = scratch("study", "all-fail", &[("sets.txt", sets)]);
    let o = study(&dir, &["--sets", "sets.txt", "--output", "out"]);
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(
        !err.contains("cannot plot") && !err.contains("panicked"),
        "{err}"
    );
    assert!(
        err.contains("error: every set of the study failed (2 of 2)"),
        "{err}"
    );
    for (set, option) in [("a", "-snes_monitr"), ("b", "-pc_typ")] {
        let line = err
            .lines()
            .find(|l| l.trim_start().starts_with(&format!("{set}: ")))
            .unwrap_or_else(|| panic!("no line of set {set}: {err}"));
        assert!(
            line.contains("unknown or unused PETSc option") && line.contains(option),
            "{line}"
        );
        assert!(line.contains(&format!("out/{set}")), "{line}");
    }
    assert!(dir.join("out/study.md").exists() && dir.join("out/study.csv").exists());
    assert!(!dir.join("out/study_newton.png").exists());
    std::fs::remove_dir_all(&dir).ok();
}

/// Names and contents of the files in `dir`.
fn files(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut files: Vec<(String, Vec<u8>)> = std::fs::read_dir(dir)
        .expect("dir")
        .map(|e| {
            let p = e.expect("entry").path();
            let name = p.file_name().unwrap().to_string_lossy().into_owned();
            (name, std::fs::read(&p).expect("read"))
        })
        .collect();
    files.sort();
    files
}

#[test]
fn a_study_replaces_no_run_it_did_not_start() {
    let sets = "a: -ksp_type preonly -pc_type lu\nb: --set ct.loading_rate=2000\n";
    let dir = scratch("study", "keep", &[("sets.txt", sets)]);
    // A finished run of another configuration where the study would put set `b`.
    let other = Command::new(EXE)
        .current_dir(&dir)
        .args([
            "run",
            "tiny.toml",
            "--quiet",
            "--steps",
            "2",
            "--output",
            "out/b",
        ])
        .args(["--set", "ct.loading_rate=1000"])
        .output()
        .expect("start mpm-concrete");
    succeeds(&other);
    let before = files(&dir.join("out/b"));
    let o = study(&dir, &["--sets", "sets.txt", "--output", "out"]);
    refused(
        &o,
        &[
            "out/b holds a run (config tiny.toml, finished at step 2 of 2)",
            "--overwrite",
        ],
    );
    assert_eq!(files(&dir.join("out/b")), before, "the run was changed");
    assert!(!dir.join("out/a").exists() && !dir.join("out/study.md").exists());

    // With --overwrite a directory that holds other files is refused, and left as it is, whatever the
    // order of the sets; so are results without a run record.
    std::fs::create_dir_all(dir.join("out/a")).expect("dir");
    std::fs::write(dir.join("out/a/notes.txt"), "mine").expect("notes");
    let o = study(
        &dir,
        &["--sets", "sets.txt", "--output", "out", "--overwrite"],
    );
    refused(
        &o,
        &["out/a: holds files that no run of this program writes (notes.txt)"],
    );
    std::fs::remove_file(dir.join("out/a/notes.txt")).expect("notes");
    std::fs::write(dir.join("out/a/history.csv"), "step\n").expect("history");
    let o = study(
        &dir,
        &["--sets", "sets.txt", "--output", "out", "--overwrite"],
    );
    refused(
        &o,
        &["out/a holds results (history.csv) without a run record"],
    );
    assert_eq!(files(&dir.join("out/b")), before, "the run was changed");
    assert!(!dir.join("out/study.md").exists());

    // With --overwrite the run in `b`, identified by its run.json, is replaced by the set's.
    std::fs::remove_file(dir.join("out/a/history.csv")).expect("history");
    let o = study(
        &dir,
        &["--sets", "sets.txt", "--output", "out", "--overwrite"],
    );
    succeeds(&o);
    let config = std::fs::read_to_string(dir.join("out/b/config.toml")).expect("config");
    assert!(config.contains("loading_rate = 2000"), "{config}");
    let csv = std::fs::read_to_string(dir.join("out/study.csv")).expect("study.csv");
    assert_eq!(
        csv.lines().filter(|l| l.contains(",true,")).count(),
        2,
        "{csv}"
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// `bench` writes each case into `<output>/<case>` with the study's rules: a case directory holding files
/// that no run of this program writes is refused before any case runs, and the files stay.
#[test]
fn bench_never_replaces_files_it_did_not_write() {
    let dir = scratch("study", "bench-foreign", &[]);
    let case = dir.join("out").join("ct-demo");
    std::fs::create_dir_all(&case).expect("case dir");
    std::fs::write(case.join("notes.txt"), "mine").expect("foreign file");
    let o = Command::new(EXE)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .args(["bench", "--cases", "ct-demo", "--steps", "1", "--output"])
        .arg(dir.join("out"))
        .output()
        .expect("start mpm-concrete");
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success(),
        "bench replaced a foreign directory:\n{err}"
    );
    assert!(
        err.contains("notes.txt") && err.contains("ct-demo") && !err.contains("panicked"),
        "{err}"
    );
    assert_eq!(
        std::fs::read_to_string(case.join("notes.txt")).unwrap(),
        "mine"
    );
    assert!(!dir.join("out").join("bench.json").exists());
}
