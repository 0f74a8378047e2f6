//! A run's results can be trusted: the real binary on a tiny CT specimen (360 points, 1 us steps).
//!
//! * every class of bad input is refused before any work with exit code 2 and one `error:` line that names
//!   the file or option, the key and what is allowed, and nothing is written into the output directory;
//! * an output directory belongs to one run (`--overwrite` removes only the program's files);
//! * a checkpoint proves what it holds: a corrupt one is refused, as is resuming with other physics or
//!   with no steps left; a run that fails for good or is interrupted leaves a checkpoint of its last
//!   converged step and a resume command that works as printed;
//! * a run that ended before its requested end time says so.

mod binary;

use binary::{BLOCK, EXE, record, refused, run, scratch, stderr, succeeds};
use mpm_concrete::checkpoint;
use std::path::Path;
use std::process::{Command, Output, Stdio};

/// `mpm-concrete run tiny.toml --quiet --output d` in `cwd` with further arguments.
fn run_tiny(cwd: &Path, extra: &[&str]) -> Output {
    let mut args = vec!["run", "tiny.toml", "--quiet", "--output", "d"];
    args.extend_from_slice(extra);
    run(cwd, &args)
}

/// Names and contents of the files in `dir`.
fn snapshot(dir: &Path) -> Vec<(String, Vec<u8>)> {
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
fn bad_input_is_refused_before_anything_is_written() {
    let dir = scratch("safety", "bad", &[("block.toml", BLOCK)]);
    std::fs::write(dir.join("a_file"), "").unwrap();
    std::fs::write(
        dir.join("sets.txt"),
        "a: -pc_type lu\nb: -pc_type ilu\na: -pc_type jacobi\n",
    )
    .unwrap();
    let block = |name: &str, from: &str, to: &str| {
        let text = BLOCK.replace(from, to);
        assert_ne!(text, BLOCK, "{from}");
        std::fs::write(dir.join(name), text).unwrap();
    };
    block(
        "far-box.toml",
        "min = [-1.0, -0.1]\nmax = [11.0, 0.1]",
        "min = [-1.0, -60.0]\nmax = [11.0, -50.0]",
    );
    block(
        "no-material.toml",
        "material = { model = \"linear_elastic\", youngs_modulus = 30000.0, poisson_ratio = 0.2 }\n",
        "",
    );
    block("bad-kind.toml", "y = \"fixed\"", "y = \"fixd\"");
    let second = BLOCK[BLOCK.find("[[body]]").unwrap()..BLOCK.find("[[constraint]]").unwrap()]
        .replace("name = \"b\"", "name = \"c\"")
        .replace(
            "min = [0.0, 0.0], max = [10.0, 10.0]",
            "min = [5.0, 5.0], max = [15.0, 15.0]",
        );
    block(
        "overlap.toml",
        "[[constraint]]",
        &format!("{second}[[constraint]]"),
    );
    block(
        "rigid-no-geometry.toml",
        "[[constraint]]",
        "[[rigid_body]]\nname = \"r\"\ny = \"fixed\"\n\n[[constraint]]",
    );
    block(
        "nan-velocity.toml",
        "initial_velocity = [0.0, 0.0]",
        "initial_velocity = [nan, 0.0]",
    );
    // (program arguments after `run tiny.toml --quiet --output out`, PETSc options, what the error line
    // must name)
    type Case<'a> = (Vec<&'a str>, Vec<&'a str>, Vec<&'a str>);
    let cases: Vec<Case> = vec![
        (
            vec!["--set", "ct.rise_time=-1e-6"],
            vec![],
            vec![
                "tiny.toml",
                "ct.rise_time",
                "-0.000001",
                "a time in [0, 1000] s",
            ],
        ),
        (
            vec!["--set", "ct.rise_time=nan"],
            vec![],
            vec!["tiny.toml", "ct.rise_time", "NaN", "[0, 1000] s"],
        ),
        (
            vec!["--set", "ct.load_zone=[-100.0,-50.0]"],
            vec![],
            vec!["ct.load_zone", "0 <= a < b <= notch_length"],
        ),
        (
            vec!["--set", "ct.notch_tip=\"pointed\""],
            vec![],
            vec![
                "tiny.toml",
                "ct.notch_tip",
                "pointed",
                "\"flat\"",
                "\"round\"",
            ],
        ),
        (
            vec!["--set", "ct.load_introduction=\"inserts\""],
            vec![],
            vec!["tiny.toml", "ct.insert_thickness", "(missing)", "required"],
        ),
        (
            vec![
                "--set",
                "ct.load_introduction=\"inserts\"",
                "--set",
                "ct.insert_thickness=2.0",
            ],
            vec![],
            vec![
                "ct.insert_thickness",
                "2",
                "at least one cell (4 mm)",
                "notch_width - 2 (insert_thickness + plate_thickness) >= cell_size",
            ],
        ),
        (
            vec!["--set", "grid.cell_sise=2.0"],
            vec![],
            vec!["tiny.toml", "cell_sise"],
        ),
        (vec!["--steps", "0"], vec![], vec!["--steps", "at least 1"]),
        (
            vec![],
            vec!["-ksp_rtol", "-5"],
            vec!["command line", "-ksp_rtol -5", "[0, 1)"],
        ),
        (
            vec![],
            vec!["-snes_max_it", "-3"],
            vec!["command line", "-snes_max_it -3", "an integer >= 1"],
        ),
        (
            vec!["--set", "run.petsc_options=\"-fallback_snes_max_it 0\""],
            vec![],
            vec![
                "tiny.toml",
                "run.petsc_options",
                "-fallback_snes_max_it 0",
                ">= 1",
            ],
        ),
        (
            vec![],
            vec!["-snes_monitor", "--steps", "2"],
            vec!["`--steps` comes after the PETSc option `-snes_monitor`"],
        ),
        (
            vec!["--set", "grid.cell_size=0.01"],
            vec![],
            vec!["tiny.toml", "needs about", "available", "--allow-large"],
        ),
        (
            vec!["--resume"],
            vec![],
            vec!["checkpoint.h5", "no checkpoint"],
        ),
        (
            vec!["--allow-large", "--set", "extrusion.thickness=1e8"],
            vec![],
            vec![
                "material points",
                "more than the 4.295e9",
                "also with --allow-large",
            ],
        ),
        (
            vec![],
            vec!["-snes_monitr"],
            vec!["unknown or unused PETSc option", "-snes_monitr"],
        ),
        (
            vec![],
            vec!["-pc_type", "nonsense"],
            vec!["first step", "Unable to find requested PC type nonsense"],
        ),
    ];
    for (own, petsc, needles) in &cases {
        let mut args = vec!["run", "tiny.toml", "--quiet", "--output", "out"];
        args.extend(own);
        args.extend(petsc);
        let line = refused(&run(&dir, &args), needles);
        assert!(!dir.join("out").exists(), "{args:?} wrote out/: {line}");
    }
    // Inputs of the other commands and sections.
    let others: Vec<(Vec<&str>, Vec<&str>)> = vec![
        (
            vec!["run", "far-box.toml", "--output", "out"],
            vec!["field `constraint[0]`", "`base`", "holds no grid node"],
        ),
        (
            vec!["run", "nan-velocity.toml", "--output", "out"],
            vec!["body[0].initial_velocity", "finite"],
        ),
        (
            vec![
                "run",
                "block.toml",
                "--output",
                "out",
                "--set",
                "body[0].density=-1",
            ],
            vec!["body[0].density", "= -1", "a density in [1e-15, 1e-6]"],
        ),
        (
            vec![
                "run",
                "block.toml",
                "--output",
                "out",
                "--set",
                "body[2].density=1",
            ],
            vec![
                "--set body[2].density=1",
                "the file has 1 [[body]] (indices 0 to 0)",
            ],
        ),
        (
            vec![
                "run",
                "block.toml",
                "--output",
                "out",
                "--set",
                "shape.kind=\"bspline2\"",
                "--set",
                "grid.margin_cells=1",
            ],
            vec!["grid.margin_cells", "= 1", "at least 2", "bspline2"],
        ),
        (
            vec!["run", "no-material.toml", "--output", "out"],
            vec!["missing field `material`", "(in [[body]] 0 (name = \"b\"))"],
        ),
        (
            vec!["run", "bad-kind.toml", "--output", "out"],
            vec![
                "\"fixd\"",
                "\"free\", \"fixed\" or { velocity = v } (mm/s)",
                "[[constraint]] 0 (name = \"base\")",
            ],
        ),
        (
            vec!["run", "overlap.toml", "--output", "out"],
            vec![
                "body[1].geometry",
                "overlaps body[0] `b` at (5.500, 5.500) mm",
            ],
        ),
        (
            vec!["run", "rigid-no-geometry.toml", "--output", "out"],
            vec![
                "missing field `geometry`",
                "[[rigid_body]] 0 (name = \"r\")",
            ],
        ),
        (
            vec!["run", "tiny.toml", "--quiet", "--output", "/proc/mpmc/out"],
            vec![
                "/proc/mpmc/out: cannot create the output directory: No such file or directory (os \
                 error 2) (give another --output)",
            ],
        ),
        (
            vec!["material-driver", "--max-strain", "-0.01", "--out", "out"],
            vec!["max strain -0.01 must lie in (0, 1)"],
        ),
        (
            vec!["material-driver", "--strength-steps", "0", "--out", "out"],
            vec!["--strength-steps 0: a number of load steps in 1..=1000000"],
        ),
        (
            vec!["material-driver", "--name", "../evil", "--out", "out"],
            vec!["--name \"../evil\"", "without /"],
        ),
        (
            vec!["run", "tiny.toml", "--output", "a_file"],
            vec!["a_file", "not a directory"],
        ),
        (
            vec![
                "study",
                "tiny.toml",
                "--sets",
                "sets.txt",
                "--output",
                "out",
            ],
            vec!["sets.txt:3", "\"a\" is already used on line 1"],
        ),
        (
            vec!["study", "tiny.toml", "--output", "out", "-snes_monitor"],
            vec!["study takes no PETSc options", "-snes_monitor"],
        ),
        (
            vec!["material-driver", "--out", "out", "-snes_monitor"],
            vec!["material-driver takes no PETSc options", "-snes_monitor"],
        ),
    ];
    for (args, needles) in &others {
        let line = refused(&run(&dir, args), needles);
        assert!(!dir.join("out").exists(), "{args:?} wrote out/: {line}");
    }
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn an_output_directory_belongs_to_one_run() {
    let dir = scratch("safety", "own", &[("block.toml", BLOCK)]);
    succeeds(&run(
        &dir,
        &["run", "tiny.toml", "--quiet", "--output", "d"],
    ));
    let d = dir.join("d");
    std::fs::write(d.join("notes.txt"), "the user's own file").unwrap();
    let before = snapshot(&d);
    assert!(before.iter().any(|(n, _)| n == "fields_000004.h5"));
    // The same model again, and another model: both refused, nothing touched.
    let line = refused(
        &run(&dir, &["run", "tiny.toml", "--quiet", "--output", "d"]),
        &[
            "d holds the results of an earlier run of the same model",
            "--overwrite",
            "--resume",
        ],
    );
    assert!(line.contains("finished at step 4 of 4"), "{line}");
    refused(
        &run_tiny(&dir, &["--set", "ct.loading_rate=1000.0"]),
        &["d holds the results of another run"],
    );
    // --overwrite with a misspelled option: refused after the first step, the old run intact.
    refused(
        &run_tiny(&dir, &["--overwrite", "-snes_monitr"]),
        &["-snes_monitr"],
    );
    assert_eq!(
        snapshot(&d),
        before,
        "a refused run must not touch the directory"
    );
    // --overwrite replaces the program's files only: the stale fields of step 4 go, notes.txt stays.
    succeeds(&run_tiny(
        &dir,
        &[
            "--overwrite",
            "--steps",
            "2",
            "--set",
            "ct.loading_rate=1000.0",
        ],
    ));
    let after: Vec<String> = snapshot(&d).into_iter().map(|(n, _)| n).collect();
    assert!(after.contains(&"notes.txt".to_owned()), "{after:?}");
    assert!(after.contains(&"fields_000002.h5".to_owned()), "{after:?}");
    assert!(!after.contains(&"fields_000004.h5".to_owned()), "{after:?}");
    assert!(
        after
            .iter()
            .all(|n| n == "notes.txt" || mpm_concrete::rundir::is_program_file(n)),
        "every file a run writes is one --overwrite would remove: {after:?}"
    );
    let r = record(&d);
    assert_eq!((r.status.as_str(), r.steps_done), ("finished", 2));
    let copy = std::fs::read_to_string(d.join("config.toml")).unwrap();
    assert!(
        copy.contains("(with --set ct.loading_rate=1000.0 --set run.steps=2)")
            && copy.contains("loading_rate = 1000.0"),
        "the copied config includes the overrides:\n{copy}"
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// XORs `len` bytes of `file` from `offset`.
fn flip(file: &Path, offset: u64, len: usize) {
    let mut bytes = std::fs::read(file).unwrap();
    for b in &mut bytes[offset as usize..offset as usize + len] {
        *b ^= 0xff;
    }
    std::fs::write(file, bytes).unwrap();
}

/// File offset of a dataset's data.
fn data_offset(file: &Path, dataset: &str) -> u64 {
    let f = hdf5_metno::File::open(file).unwrap();
    f.dataset(dataset).unwrap().offset().expect("contiguous")
}

#[test]
fn a_corrupt_checkpoint_is_refused_and_changes_nothing() {
    let dir = scratch("safety", "corrupt", &[("block.toml", BLOCK)]);
    succeeds(&run_tiny(&dir, &["--steps", "2"]));
    let d = dir.join("d");
    let ck = d.join(checkpoint::FILE);
    let good = std::fs::read(&ck).unwrap();
    for (dataset, len) in [("stress", 200), ("meta", 8)] {
        std::fs::write(&ck, &good).unwrap();
        flip(&ck, data_offset(&ck, dataset) + 16, len);
        let before = snapshot(&d);
        refused(
            &run_tiny(&dir, &["--steps", "4", "--resume"]),
            &[
                "checkpoint.h5",
                "corrupt",
                &format!("`{dataset}` does not match its checksum"),
            ],
        );
        assert_eq!(snapshot(&d), before, "{dataset}: nothing may change");
    }
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn resume_refuses_other_physics_and_no_steps_left_and_accepts_run_control() {
    let dir = scratch("safety", "resume", &[("block.toml", BLOCK)]);
    succeeds(&run_tiny(&dir, &["--steps", "2"]));
    let d = dir.join("d");
    let before = snapshot(&d);
    let resume = |extra: &[&str]| {
        let mut args = vec!["run", "tiny.toml", "--quiet", "--output", "d", "--resume"];
        args.extend(extra);
        run(&dir, &args)
    };
    refused(
        &resume(&["--steps", "4", "--set", "ct.loading_rate=35"]),
        &[
            "other physics",
            "ct.loading_rate: 4300.0 in the checkpoint, 35.0 now",
            "[run] section",
        ],
    );
    refused(
        &resume(&["--steps", "4", "--set", "time.beta=0.3"]),
        &["time.beta: absent in the checkpoint, 0.3 now"],
    );
    refused(
        &resume(&["--steps", "2"]),
        &["at step 2", "asks for 2 steps", "nothing to do", "N > 2"],
    );
    assert_eq!(snapshot(&d), before);
    // Run control may change: more steps, another output cadence, other solver options.
    succeeds(&resume(&[
        "--steps",
        "3",
        "--set",
        "run.output_every=1",
        "-ksp_rtol",
        "1e-7",
    ]));
    let r = record(&d);
    assert_eq!(
        (r.status.as_str(), r.steps_done, r.resumed_from_step),
        ("finished", 3, Some(2))
    );
    assert!(d.join("fields_000003.h5").exists());
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_failed_run_keeps_a_checkpoint_of_its_last_converged_step() {
    let dir = scratch("safety", "failed", &[("block.toml", BLOCK)]);
    // Two Newton iterations with GMRES and one with the fallback are too few for step 2, and dt_min = dt
    // forbids halving: the run fails for good at step 2.
    let args = [
        "run",
        "tiny.toml",
        "--quiet",
        "--output",
        "d",
        "--set",
        "time.dt_min=1e-6",
        "--set",
        "run.output_every=0",
        "-snes_max_it",
        "2",
        "-fallback_snes_max_it",
        "1",
        // Every linear solve to -ksp_rtol: the Newton iterations this scenario counts on (a first
        // solve to 1e-3, the default, costs step 1 a third iteration on this tiny specimen).
        "-mpm_first_ksp_rtol",
        "0",
    ];
    let o = run(&dir, &args);
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(
        err.contains("step 2 at t = 1e-6 s did not converge"),
        "{err}"
    );
    let d = dir.join("d");
    let header = checkpoint::read_header(&d).expect("checkpoint");
    assert_eq!(
        header.counters.step, 1,
        "checkpoint of the last converged step"
    );
    assert!(d.join("fields_000001.h5").exists());
    let r = record(&d);
    assert_eq!((r.status.as_str(), r.steps_done), ("failed", 1));
    // The printed command resumes that run (and fails the same way with the same options).
    let hint = err
        .lines()
        .find_map(|l| l.split_once("to continue (e.g. with other solver options): "))
        .map(|(_, cmd)| cmd.to_owned())
        .expect("resume command");
    let o = Command::new("sh")
        .current_dir(&dir)
        .args(["-c", &hint])
        .output()
        .unwrap();
    let err = stderr(&o);
    assert!(err.contains("resuming at step 1"), "{hint}\n{err}");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn an_interrupted_run_prints_a_resume_command_that_works() {
    let dir = scratch("safety", "interrupt", &[("block.toml", BLOCK)]);
    let mut child = Command::new(EXE)
        .current_dir(&dir)
        .args([
            "run",
            "tiny.toml",
            "--quiet",
            "--output",
            "d",
            "--steps",
            "400",
            "--set",
            "run.output_every=1000",
            "-ksp_rtol",
            "1e-7",
        ])
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut lines = std::io::BufRead::lines(std::io::BufReader::new(child.stderr.take().unwrap()));
    let mut err = String::new();
    for line in lines.by_ref() {
        let line = line.unwrap();
        err += &line;
        err.push('\n');
        if line.starts_with("step 1:") {
            let kill = Command::new("kill")
                .args(["-INT", &child.id().to_string()])
                .status()
                .unwrap();
            assert!(kill.success());
            break;
        }
    }
    for line in lines {
        err += &line.unwrap();
        err.push('\n');
    }
    assert_eq!(child.wait().unwrap().code(), Some(1), "{err}");
    let hint = err
        .lines()
        .find_map(|l| l.split_once(": continue with "))
        .map(|(_, cmd)| cmd.to_owned())
        .unwrap_or_else(|| panic!("no resume command in:\n{err}"));
    assert!(
        hint.contains("--output d")
            && hint.contains("--steps 400")
            && hint.contains("-ksp_rtol 1e-7"),
        "{hint}"
    );
    let done = checkpoint::read_header(&dir.join("d"))
        .unwrap()
        .counters
        .step;
    assert!((1..400).contains(&done), "{done}");
    // Fewer steps to go: the hint with --steps 400 replaced keeps the test short.
    let hint = hint.replace("--steps 400", &format!("--steps {}", done + 2));
    let o = Command::new("sh")
        .current_dir(&dir)
        .args(["-c", &hint])
        .output()
        .unwrap();
    succeeds(&o);
    let r = record(&dir.join("d"));
    assert_eq!((r.status.as_str(), r.steps_done), ("finished", done + 2));
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_run_that_ended_early_says_so() {
    let dir = scratch("safety", "early", &[("block.toml", BLOCK)]);
    // Step 2 needs three Newton iterations: with two (GMRES), then one (fallback) to a relative residual
    // of 1e-3, it is halved until one iteration gets there (at dt/4), so the two steps end well before
    // 2 us.
    let o = run_tiny(
        &dir,
        &[
            "--steps",
            "2",
            "-snes_max_it",
            "2",
            "-fallback_snes_max_it",
            "1",
            "-fallback_snes_rtol",
            "1e-3",
            // Every linear solve to -ksp_rtol: the Newton iterations this scenario counts on.
            "-mpm_first_ksp_rtol",
            "0",
        ],
    );
    succeeds(&o);
    let stdout = String::from_utf8_lossy(&o.stdout);
    let note = "before its requested end time 2.0000 us (2 steps of 1.0000 us); 1 of 2 steps took a reduced time step";
    assert!(stdout.contains(note), "summary:\n{stdout}");
    assert!(stderr(&o).contains(note), "{}", stderr(&o));
    let history = std::fs::read_to_string(dir.join("d/history.csv")).unwrap();
    assert!(
        history
            .lines()
            .last()
            .unwrap()
            .starts_with("# the run ended at t = ")
    );
    assert!(history.contains(note));
    let r = record(&dir.join("d"));
    assert_eq!(r.reduced_steps, 1);
    assert!(r.time_reached < r.time_requested);
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn crack_remeasures_a_ct_run_from_its_snapshots_and_refuses_other_runs() {
    let dir = scratch("safety", "crack", &[("block.toml", BLOCK)]);
    succeeds(&run_tiny(&dir, &[]));
    let states = |d: &Path| -> Vec<serde_json::Value> {
        let text = std::fs::read_to_string(d.join("crack.json")).expect("crack.json");
        let v: serde_json::Value = serde_json::from_str(&text).expect("crack.json parses");
        v["states"].as_array().expect("states").clone()
    };
    let written = states(&dir.join("d"));
    // The crack length and band width over time are drawn beside crack.json, and drawn again by `crack`.
    for png in ["crack_length.png", "band_width.png"] {
        let bytes = std::fs::read(dir.join("d").join(png)).expect(png);
        assert!(bytes.starts_with(b"\x89PNG"), "{png} is a PNG");
        std::fs::remove_file(dir.join("d").join(png)).expect("remove");
    }
    std::fs::remove_file(dir.join("d/crack.json")).expect("remove crack.json");
    let o = run(&dir, &["crack", "d"]);
    succeeds(&o);
    let remeasured = states(&dir.join("d"));
    assert!(dir.join("d/crack_length.png").is_file() && dir.join("d/band_width.png").is_file());
    // Same criteria, same snapshots: the same states as the run wrote (one per snapshot).
    let snapshots = std::fs::read_dir(dir.join("d"))
        .expect("dir")
        .filter(|e| {
            let name = e
                .as_ref()
                .unwrap()
                .file_name()
                .to_string_lossy()
                .into_owned();
            name.starts_with("fields_") && name.ends_with(".h5")
        })
        .count();
    assert_eq!(remeasured.len(), snapshots);
    assert_eq!(written.len(), remeasured.len());
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
    assert_eq!(
        String::from_utf8_lossy(&o.stdout).lines().count(),
        snapshots,
        "one line per state"
    );
    // A run without a notch, and a directory that is no run, are refused with the file named.
    succeeds(&run(
        &dir,
        &["run", "block.toml", "--quiet", "--output", "b"],
    ));
    refused(&run(&dir, &["crack", "b"]), &["config.toml", "[ct]"]);
    refused(&run(&dir, &["crack", "nowhere"]), &["nowhere"]);
    std::fs::remove_dir_all(&dir).ok();
}

/// A numerical failure raised inside PETSc's solve (here SNES told to raise an error when it does not
/// converge, as MUMPS does when it fails on a nearly singular matrix) fails the attempt, not the run: the
/// step is retried with the fallback solver and reported. The fallback keeps its factors out of core
/// (MUMPS's statistics say so) and leaves none of their files in the output directory.
#[test]
fn a_petsc_error_inside_a_solve_fails_the_attempt_not_the_run() {
    let dir = scratch("safety", "petsc-error", &[("block.toml", BLOCK)]);
    let o = run_tiny(
        &dir,
        &[
            "-snes_max_it",
            "1",
            "-snes_error_if_not_converged",
            "-fallback_mat_mumps_icntl_4",
            "2",
        ],
    );
    succeeds(&o);
    let out_of_core = String::from_utf8_lossy(&o.stdout)
        .lines()
        .filter(|l| l.contains("ICNTL(22)"))
        .map(|l| l.split_whitespace().last().unwrap_or_default().to_owned())
        .collect::<Vec<_>>();
    assert!(
        !out_of_core.is_empty() && out_of_core.iter().all(|v| v == "1"),
        "MUMPS's out-of-core option: {out_of_core:?}"
    );
    let left: Vec<String> = std::fs::read_dir(dir.join("d"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with("mumps_"))
        .collect();
    assert!(left.is_empty(), "{left:?}");
    let err = stderr(&o);
    assert!(
        err.contains("PETSc error 91") && err.contains("retrying with the fallback solver"),
        "{err}"
    );
    let summary = String::from_utf8_lossy(&o.stdout).into_owned();
    let retried = summary
        .lines()
        .find(|l| l.starts_with("| steps |"))
        .unwrap_or_default()
        .to_owned();
    assert!(retried.contains("4 (4 retried"), "{summary}");
    assert_eq!(record(&dir.join("d")).steps_done, 4);
    std::fs::remove_dir_all(&dir).ok();
}

/// After a halved step the run keeps the reduced step until three steps in a row converged at their first
/// try, then doubles it (docs/theory.md, "The implicit MPM step"); Newton running out of iterations goes
/// straight to a smaller step, the fallback solver being for failures of the linear solver.
#[test]
fn a_reduced_step_grows_back_after_three_calm_steps() {
    let dir = scratch("safety", "grow", &[("block.toml", BLOCK)]);
    // Two Newton iterations are too few at the nominal step from step 2 on, enough at half of it.
    // Every linear solve to -ksp_rtol: the Newton iterations this scenario counts on.
    let o = run_tiny(
        &dir,
        &[
            "--steps",
            "12",
            "-snes_max_it",
            "2",
            "-mpm_first_ksp_rtol",
            "0",
        ],
    );
    succeeds(&o);
    let err = stderr(&o);
    assert!(!err.contains("fallback"), "{err}");
    let history = std::fs::read_to_string(dir.join("d/history.csv")).unwrap();
    let mut lines = history.lines().filter(|l| !l.starts_with('#'));
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let (c_dt, c_attempts) = (col("dt"), col("attempts"));
    let rows: Vec<(f64, usize)> = lines
        .map(|l| {
            let v: Vec<&str> = l.split(',').collect();
            (v[c_dt].parse().unwrap(), v[c_attempts].parse().unwrap())
        })
        .collect();
    // Each step starts at the step the rule gives from the steps before it: the last step's, doubled
    // after three first-try steps in a row while below the nominal step.
    let nominal = rows[0].0;
    let (mut calm, mut grown, mut retried) = (0, 0, 0);
    for pair in rows.windows(2) {
        let ((dt, attempts), (next_dt, next_attempts)) = (pair[0], pair[1]);
        calm = if attempts == 1 { calm + 1 } else { 0 };
        let mut start = dt;
        if dt < nominal && calm >= 3 {
            start = (2.0 * dt).min(nominal);
            calm = 0;
            grown += 1;
        }
        if next_attempts == 1 {
            assert_eq!(next_dt, start, "{rows:?}");
        } else {
            retried += 1;
            assert!(next_dt < start, "{rows:?}");
        }
    }
    assert!(retried > 0 && grown > 0, "{rows:?}");
    std::fs::remove_dir_all(&dir).ok();
}
