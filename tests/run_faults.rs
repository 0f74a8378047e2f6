//! Runs survive what happens to real runs: the real binary on a tiny CT specimen (360 points) under the
//! faults of docs/bad-input.md, "While running":
//!
//! * a second run into a directory that a run is writing is refused, also with --overwrite or --resume,
//!   and under `mpirun` alike (exit code 2, one error line);
//! * Ctrl-C on several processes stops them all at the same step with a complete checkpoint of it, also
//!   when a step is too slow to end before the launcher kills them (it is abandoned);
//! * a write that fails (a file-size limit standing in for a full disk) leaves a resumable state and a
//!   run.json that says "failed";
//! * `crack` refuses corrupt snapshots, and snapshots that are not the run's own as written.
//!
//! Every child process runs under `timeout`, so a hang fails the test instead of blocking it.

mod binary;

use binary::{EXE, TINY, record, refused, scratch, stderr, succeeds};
use mpm_concrete::checkpoint;
use std::io::BufRead;
use std::path::Path;
use std::process::{Child, Command, Output, Stdio};
use std::sync::{RwLock, RwLockReadGuard, RwLockWriteGuard};

/// The tests of this file run side by side, except the slow-step Ctrl-C test, which needs the machine to
/// itself: Open MPI kills its processes 2 s after Ctrl-C, and the checkpoint must be written before that.
static MACHINE: RwLock<()> = RwLock::new(());

/// Held by a test that may share the machine with the others.
fn shared() -> RwLockReadGuard<'static, ()> {
    MACHINE.read().unwrap_or_else(|e| e.into_inner())
}

/// Held by a test that must run alone.
fn alone() -> RwLockWriteGuard<'static, ()> {
    MACHINE.write().unwrap_or_else(|e| e.into_inner())
}

/// `timeout 120 mpm-concrete ARGS` in `cwd`, not yet started.
fn command(cwd: &Path, args: &[&str]) -> Command {
    let mut c = Command::new("timeout");
    c.current_dir(cwd).args(["120", EXE]).args(args);
    c
}

/// Runs the program in `cwd` to its end.
fn run(cwd: &Path, args: &[&str]) -> Output {
    command(cwd, args).output().expect("start mpm-concrete")
}

/// The lines of a child's standard error.
type ErrLines = std::io::Lines<std::io::BufReader<std::process::ChildStderr>>;

/// Reads `child`'s standard error until a line starts with `prefix`; returns what it read and the rest.
fn wait_for_line(child: &mut Child, prefix: &str) -> (String, ErrLines) {
    let mut lines = std::io::BufReader::new(child.stderr.take().expect("piped stderr")).lines();
    let mut seen = String::new();
    while let Some(Ok(line)) = lines.next() {
        seen += &line;
        seen.push('\n');
        if line.starts_with(prefix) {
            return (seen, lines);
        }
    }
    panic!("no line starting with `{prefix}` in:\n{seen}");
}

/// A long run of the tiny specimen into `d` in `dir`, started and past its second step.
fn long_run(dir: &Path) -> (Child, ErrLines) {
    let mut child = command(
        dir,
        &[
            "run",
            "tiny.toml",
            "--quiet",
            "--output",
            "d",
            "--steps",
            "2000",
        ],
    )
    .stderr(Stdio::piped())
    .spawn()
    .expect("start mpm-concrete");
    let (_, rest) = wait_for_line(&mut child, "step 2:");
    (child, rest)
}

#[test]
fn a_directory_that_a_run_is_writing_is_refused_to_a_second_run() {
    let _machine = shared();
    let dir = scratch("faults", "lock", &[]);
    let (mut first, rest) = long_run(&dir);
    let pid = first.id();
    let holder = record(&dir.join("d"))
        .holder
        .expect("a running run names its holder");
    // `timeout` runs the program as its child.
    assert_ne!(holder.pid, pid);
    let needles = [
        "d: another run is writing into this directory (process ".to_owned(),
        format!("process {} on {}", holder.pid, holder.host),
        "wait until it has ended".to_owned(),
    ];
    let needles: Vec<&str> = needles.iter().map(String::as_str).collect();
    for extra in [
        &[][..],
        &["--overwrite"],
        &["--resume", "--steps", "3000"],
        &["--set", "ct.loading_rate=35.0"],
    ] {
        let mut args = vec!["run", "tiny.toml", "--quiet", "--output", "d"];
        args.extend(extra);
        refused(&run(&dir, &args), &needles);
    }
    Command::new("kill")
        .args(["-INT", &holder.pid.to_string()])
        .status()
        .expect("kill");
    let rest: Vec<String> = rest.map_while(Result::ok).collect();
    assert_eq!(first.wait().expect("wait").code(), Some(1), "{rest:?}");
    let r = record(&dir.join("d"));
    assert_eq!(r.status, "interrupted");
    assert_eq!(r.holder, None, "a run that ended holds nothing");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn of_two_runs_started_together_into_one_directory_one_runs() {
    let _machine = shared();
    let dir = scratch("faults", "race", &[]);
    let start = |config: &str| {
        command(&dir, &["run", config, "--quiet", "--output", "d"])
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .expect("start mpm-concrete")
    };
    std::fs::write(dir.join("other.toml"), TINY.replace("4300.0", "1000.0")).unwrap();
    let (a, b) = (start("tiny.toml"), start("other.toml"));
    let (a, b) = (a.wait_with_output().unwrap(), b.wait_with_output().unwrap());
    let codes = [a.status.code(), b.status.code()];
    assert!(
        codes == [Some(0), Some(2)] || codes == [Some(2), Some(0)],
        "{codes:?}\n{}\n{}",
        stderr(&a),
        stderr(&b)
    );
    let (won, lost) = if codes[0] == Some(0) {
        (&a, &b)
    } else {
        (&b, &a)
    };
    succeeds(won);
    refused(lost, &["d"]);
    assert_eq!(record(&dir.join("d")).status, "finished");
    assert!(checkpoint::read_header(&dir.join("d")).is_ok());
    std::fs::remove_dir_all(&dir).ok();
}

/// Under `mpirun -n 2` a directory that another run holds is refused as on one process: exit code 2 and
/// one error line (process 0's), every time. Process 0 alone takes the lock; the other process, which
/// finds no other fault, learns of the refusal once PETSc has started, and both end alike (a refusal by
/// process 0 alone raced the other's start of MPI: exit code 1 in about one try of two). Five tries into
/// an empty directory, with and without --overwrite, then two where every process refuses the input
/// before PETSc starts (results, no checkpoint to resume) and process 0 names the lock first.
#[test]
fn a_held_directory_is_refused_alike_on_several_processes() {
    let _machine = shared();
    let dir = scratch("faults", "mpi-lock", &[]);
    let d = dir.join("d");
    std::fs::create_dir(&d).expect("d");
    let lock = mpm_concrete::rundir::lock(&d).expect("lock");
    let needles = [
        "d: another run is writing into this directory (a run that is starting",
        "wait until it has ended, or give another --output",
    ];
    let refused_once = |extra: &[&str]| {
        let mut args = vec!["run", "tiny.toml", "--quiet", "--output", "d"];
        args.extend(extra);
        let out = mpirun(&dir, &args).output().expect("mpirun");
        refused(&out, &needles);
        let err = stderr(&out);
        assert!(!err.contains("error (process"), "{extra:?}: {err}");
    };
    for i in 0..5 {
        refused_once(if i % 2 == 0 { &[] } else { &["--overwrite"] });
    }
    std::fs::write(d.join("history.csv"), "step\n").expect("history.csv");
    refused_once(&[]);
    refused_once(&["--resume", "--steps", "8"]);
    drop(lock);
    let left: Vec<String> = std::fs::read_dir(&d)
        .expect("d")
        .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
        .collect();
    assert_eq!(left, ["history.csv"], "nothing written");
    std::fs::remove_dir_all(&dir).ok();
}

/// The files of `dir` whose names end in `.tmp` or hold `.tmp-` (the temporaries of unfinished writes).
fn temporaries(dir: &Path) -> Vec<String> {
    std::fs::read_dir(dir)
        .expect("dir")
        .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".tmp") || n.contains(".tmp-"))
        .collect()
}

/// The parent process id and the process group of process `pid` (from /proc).
fn parent_and_group(pid: u32) -> (u32, u32) {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).expect("/proc/PID/stat");
    // After the command's name in parentheses: state, ppid, pgrp.
    let fields: Vec<&str> = stat
        .rsplit_once(')')
        .expect("stat")
        .1
        .split_whitespace()
        .collect();
    (fields[1].parse().unwrap(), fields[2].parse().unwrap())
}

/// Runs the resume command `hint` (printed for `--steps 2000`) for two more steps than `done`, in `dir`;
/// checks that it continued from step `done`.
fn resume_two_more(dir: &Path, hint: &str, done: usize) {
    let hint = hint.replace("--steps 2000", &format!("--steps {}", done + 2));
    let o = Command::new("timeout")
        .current_dir(dir)
        .args(["120", "sh", "-c", &hint])
        .output()
        .expect("sh");
    succeeds(&o);
    assert!(
        stderr(&o).contains(&format!("resuming at step {done} ")),
        "{}",
        stderr(&o)
    );
    let r = record(&dir.join("d"));
    assert_eq!(
        (r.status.as_str(), r.steps_done, r.resumed_from_step),
        ("finished", done + 2, Some(done))
    );
    let history = std::fs::read_to_string(dir.join("d/history.csv")).expect("history");
    let steps: Vec<usize> = history
        .lines()
        .filter_map(|l| l.split(',').next()?.parse().ok())
        .collect();
    assert_eq!(
        steps,
        (1..=done + 2).collect::<Vec<_>>(),
        "one row per step"
    );
    assert!(temporaries(&dir.join("d")).is_empty());
}

/// Ctrl-C on `mpirun -n 2` (SIGINT to its process group as a terminal sends it, or to mpirun alone; Open
/// MPI forwards it to the processes as SIGTERM): both processes stop after the same step, the checkpoint
/// of that step is complete, run.json says so, process 0 alone prints the resume command, which works
/// (and writes the snapshot of that step).
#[test]
fn ctrl_c_on_several_processes_stops_them_at_one_saved_step() {
    let _machine = shared();
    for target in ["group", "launcher"] {
        let dir = scratch("faults", &format!("mpi-int-{target}"), &[]);
        let mut child = Command::new("timeout")
            .current_dir(&dir)
            .args(["120", "setsid", "mpirun", "--oversubscribe", "-n", "2", EXE])
            .args([
                "run",
                "tiny.toml",
                "--quiet",
                "--output",
                "d",
                "--steps",
                "2000",
            ])
            .env("OMPI_ALLOW_RUN_AS_ROOT", "1")
            .env("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1")
            .stderr(Stdio::piped())
            .spawn()
            .expect("start timeout/setsid/mpirun (is Open MPI installed?)");
        let (mut err, rest) = wait_for_line(&mut child, "step 3:");
        // run.json names process 0; its parent is mpirun, the leader of its own process group.
        let rank0 = record(&dir.join("d")).holder.expect("holder").pid;
        let (mpirun, group) = parent_and_group(rank0);
        let whom = match target {
            "group" => format!("-{group}"),
            _ => mpirun.to_string(),
        };
        let kill = Command::new("kill")
            .args(["-INT", "--", &whom])
            .status()
            .expect("kill");
        assert!(kill.success());
        for line in rest.map_while(Result::ok) {
            err += &line;
            err.push('\n');
        }
        let code = child.wait().expect("wait").code();
        assert!(
            code != Some(0) && code != Some(124),
            "{target}: {code:?}\n{err}"
        );
        let errors: Vec<&str> = err.lines().filter(|l| l.starts_with("error")).collect();
        assert_eq!(errors.len(), 1, "{target}: process 0 alone reports:\n{err}");
        let (_, hint) = errors[0]
            .split_once(": continue with ")
            .unwrap_or_else(|| panic!("{target}: no resume command in:\n{err}"));
        let d = dir.join("d");
        let done = checkpoint::read_header(&d)
            .expect("checkpoint")
            .counters
            .step;
        let r = record(&d);
        assert_eq!(
            (r.status.as_str(), r.steps_done),
            ("interrupted", done),
            "{err}"
        );
        // The step after it ended or was abandoned, as the machine's load has it.
        let ended = format!("interrupted after step {done};");
        let abandoned = format!(
            "interrupted after step {done} (step {} was abandoned",
            done + 1
        );
        assert!(
            errors[0].contains(&ended) || errors[0].contains(&abandoned),
            "{err}"
        );
        assert!(temporaries(&d).is_empty(), "{:?}", temporaries(&d));
        resume_two_more(&dir, hint, done);
        // Left to the resumed run, which writes the snapshot of its first step.
        assert!(d.join(format!("fields_{done:06}.h5")).is_file());
        std::fs::remove_dir_all(&dir).ok();
    }
}

/// PETSc options that make a step of the fine tiny CT slow in many short Krylov iterations (each checks
/// the interrupt): point Jacobi and GMRES to a relative 1e-12, about 300 iterations a Newton iteration
/// (within the 1,000 allowed on one process as on two; GMRES(10) needs more on one), and Newton to
/// 1e-8. Steps 1, 2 and 3 then take about 1.7, 1.7 and 2.7 s on 2 processes of a 2-core machine in the
/// test profile. With block Jacobi's ILU instead (134 iterations) step 3 took 1.25-1.54 s, and the
/// SIGTERM that mpirun sends 1 s after Ctrl-C could land in the step's last residual evaluation, after its
/// last check of the interrupt: the step was then kept, not abandoned. Every Newton iteration's solve to
/// that 1e-12 (`-mpm_first_ksp_rtol 0`): with the default first solve to 1e-3 step 3 took 1.47 s and was
/// kept.
const SLOW_STEP: [&str; 8] = [
    "-pc_type",
    "jacobi",
    "-ksp_rtol",
    "1e-12",
    "-snes_rtol",
    "1e-8",
    "-mpm_first_ksp_rtol",
    "0",
];

/// The overrides that make the tiny specimen's steps slow: 0.25 mm cells (92,160 points).
const FINE: [&str; 4] = [
    "--set",
    "grid.cell_size=0.25",
    "--set",
    "run.output_every=1000",
];

/// `timeout 120 setsid mpirun -n 2 mpm-concrete ARGS` in `dir` (mpirun the leader of its own process
/// group, as in a terminal), not yet started.
fn mpirun(dir: &Path, args: &[&str]) -> Command {
    let mut c = Command::new("timeout");
    c.current_dir(dir)
        .args(["120", "setsid", "mpirun", "--oversubscribe", "-n", "2", EXE])
        .args(args)
        .env("OMPI_ALLOW_RUN_AS_ROOT", "1")
        .env("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1");
    c
}

/// The rows of `dir/history.csv` by column name (comment lines left out).
fn history_rows(dir: &Path) -> Vec<Vec<(String, String)>> {
    let text = std::fs::read_to_string(dir.join("history.csv")).expect("history");
    let mut lines = text.lines().filter(|l| !l.starts_with('#'));
    let header: Vec<&str> = lines.next().expect("header").split(',').collect();
    lines
        .map(|l| {
            let names = header.iter().map(|h| h.to_string());
            names.zip(l.split(',').map(str::to_owned)).collect()
        })
        .collect()
}

/// Ctrl-C on `mpirun -n 2` (to mpirun alone: the processes get SIGTERM 1 s later and SIGKILL 1 s after
/// that) while a step of about 3 s runs: the processes abandon it at once, together, and save the last
/// finished step before the SIGKILL; run.json says `interrupted` at that step and that the next was
/// abandoned; the printed command resumes from it, and the resumed run matches an uninterrupted one.
/// The step is made slow with many short Krylov iterations ([`SLOW_STEP`]; each iteration checks the
/// interrupt): faster steps in a debug build may end within the second mpirun waits before its SIGTERM,
/// and the test then finds no abandoned step.
#[test]
fn ctrl_c_on_several_processes_abandons_a_slow_step_and_saves_the_last_one() {
    let _machine = alone();
    let dir = scratch("faults", "mpi-abandon", &[]);
    let mut args = vec![
        "run",
        "tiny.toml",
        "--quiet",
        "--output",
        "d",
        "--steps",
        "2000",
    ];
    args.extend(FINE);
    args.extend(SLOW_STEP);
    let mut child = mpirun(&dir, &args)
        .stderr(Stdio::piped())
        .spawn()
        .expect("start timeout/setsid/mpirun (is Open MPI installed?)");
    let (mut err, rest) = wait_for_line(&mut child, "step 2:");
    // Into step 3, past the end of step 2's records.
    std::thread::sleep(std::time::Duration::from_millis(300));
    let rank0 = record(&dir.join("d")).holder.expect("holder").pid;
    let (launcher, _) = parent_and_group(rank0);
    let signalled = std::time::Instant::now();
    let kill = Command::new("kill")
        .args(["-INT", &launcher.to_string()])
        .status()
        .expect("kill");
    assert!(kill.success());
    for line in rest.map_while(Result::ok) {
        err += &line;
        err.push('\n');
    }
    let code = child.wait().expect("wait").code();
    let took = signalled.elapsed();
    eprintln!("mpirun ended {took:?} after Ctrl-C");
    assert!(code != Some(0) && code != Some(124), "{code:?}\n{err}");
    assert!(!err.contains("signal 9"), "killed:\n{err}");
    let d = dir.join("d");
    let done = checkpoint::read_header(&d)
        .expect("checkpoint")
        .counters
        .step;
    assert!(done >= 2, "{done}\n{err}");
    let errors: Vec<&str> = err.lines().filter(|l| l.starts_with("error")).collect();
    assert_eq!(errors.len(), 1, "process 0 alone reports:\n{err}");
    let abandoned = format!(
        "interrupted after step {done} (step {} was abandoned unfinished)",
        done + 1
    );
    assert!(errors[0].contains(&abandoned), "{err}");
    let r = record(&d);
    assert_eq!(
        (r.status.as_str(), r.steps_done),
        ("interrupted", done),
        "{err}"
    );
    assert!(r.note.unwrap_or_default().contains(&abandoned));
    assert!(temporaries(&d).is_empty(), "{:?}", temporaries(&d));
    let (_, hint) = errors[0]
        .split_once(": continue with ")
        .expect("resume command");
    let hint = hint.replace("--steps 2000", &format!("--steps {}", done + 1));
    let o = Command::new("timeout")
        .current_dir(&dir)
        .args(["120", "sh", "-c", &hint])
        .output()
        .expect("sh");
    succeeds(&o);
    assert!(
        stderr(&o).contains(&format!("resuming at step {done} ")),
        "{}",
        stderr(&o)
    );
    let r = record(&d);
    assert_eq!(
        (r.status.as_str(), r.steps_done, r.resumed_from_step),
        ("finished", done + 1, Some(done))
    );
    assert!(d.join(format!("fields_{done:06}.h5")).is_file());
    // The same steps uninterrupted.
    let steps = (done + 1).to_string();
    let mut args = vec![
        "run",
        "tiny.toml",
        "--quiet",
        "--output",
        "ref",
        "--steps",
        &steps,
    ];
    args.extend(FINE);
    args.extend(SLOW_STEP);
    succeeds(&mpirun(&dir, &args).output().expect("mpirun"));
    let (resumed, uninterrupted) = (history_rows(&d), history_rows(&dir.join("ref")));
    assert_eq!(resumed.len(), uninterrupted.len());
    // The resumed run builds PETSc's objects and shares out the points anew, so GMRES (relative
    // tolerance 1e-6) stops at other iterates: the solver's statistics differ, the results agree to
    // the solvers' tolerances (bound: 1e-6 of each column's largest value).
    let solver = [
        "newton_its",
        "linear_its",
        "reason",
        "residual_initial",
        "residual_final",
        "contact_solves",
        "new_pattern",
    ];
    let compared = |name: &str| {
        !(name.starts_with("wall_") || name.starts_with("bytes_") || solver.contains(&name))
    };
    // Forces are measured against the largest of them (a support's tangential force is round-off).
    let force = |name: &str| ["_fx", "_fy", "_fz"].iter().any(|c| name.ends_with(c));
    let largest_force = uninterrupted
        .iter()
        .flatten()
        .filter(|(name, _)| force(name))
        .filter_map(|(_, v)| v.parse::<f64>().ok())
        .fold(0.0_f64, |m, x| m.max(x.abs()));
    for (k, (name, _)) in uninterrupted[0].iter().enumerate() {
        if !compared(name) {
            continue;
        }
        let (a, b): (Vec<&str>, Vec<&str>) = resumed
            .iter()
            .zip(&uninterrupted)
            .map(|(a, b)| (a[k].1.as_str(), b[k].1.as_str()))
            .unzip();
        let numbers = |v: &[&str]| {
            v.iter()
                .map(|x| x.parse::<f64>())
                .collect::<Result<Vec<_>, _>>()
        };
        match (numbers(&a), numbers(&b)) {
            (Ok(a), Ok(b)) => {
                let mut scale = b.iter().fold(0.0_f64, |m, x| m.max(x.abs()));
                if force(name) {
                    scale = largest_force;
                }
                let diff = a
                    .iter()
                    .zip(&b)
                    .fold(0.0_f64, |m, (x, y)| m.max((x - y).abs()));
                assert!(
                    diff <= 1e-6 * scale,
                    "{name}: {a:?} resumed, {b:?} uninterrupted"
                );
            }
            _ => assert_eq!(a, b, "{name}"),
        }
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// `mpm-concrete ARGS` in `dir` under `timeout`, with writes limited to files of `kib` KiB (SIGXFSZ
/// ignored, so a write beyond it fails with EFBIG, as on a full disk). Open MPI's start-up keeps its
/// shared memory in files, which the limit would stop: `PMIX_MCA_gds=hash` keeps it in memory.
fn run_limited(dir: &Path, kib: usize, args: &str) -> Output {
    let script = format!("trap '' XFSZ; ulimit -f {kib}; exec {EXE} {args}");
    Command::new("timeout")
        .current_dir(dir)
        .args(["120", "bash", "-c", &script])
        .env("PMIX_MCA_gds", "hash")
        .output()
        .expect("timeout/bash")
}

/// A write that fails after the checkpoint of its step (here the index of the point fields grows beyond the
/// limit) leaves that checkpoint, run.json says `failed` at the real step, the message names the file
/// and the cause once, and the printed command resumes (writing the step's fields again if they are
/// missing); a failure before any checkpoint says so, and the refusal of a new run does not offer
/// --resume.
#[test]
fn a_failed_write_leaves_a_resumable_state_and_a_failed_record() {
    let _machine = shared();
    let dir = scratch("faults", "full", &[]);
    // The checkpoint grows by about 1.5 kB per step (its step records), the fields' index by 3.3 kB per
    // snapshot: with one snapshot per step the index passes 600 KiB well before the checkpoint does (at
    // 400 KiB the two met near step 125 once the energy books' records grew).
    let o = run_limited(
        &dir,
        600,
        "run tiny.toml --quiet --output d --steps 2000 --set run.output_every=1",
    );
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{err}");
    let line = err
        .lines()
        .find(|l| l.starts_with("error:"))
        .expect("error line");
    assert_eq!(line.matches("File too large").count(), 1, "{line}");
    assert!(line.contains("d/fields.xdmf"), "{line}");
    let d = dir.join("d");
    let done = checkpoint::read_header(&d)
        .expect("checkpoint")
        .counters
        .step;
    assert!(done > 10, "{done}");
    let r = record(&d);
    assert_eq!((r.status.as_str(), r.steps_done), ("failed", done), "{err}");
    assert!(r.note.unwrap_or_default().contains("fields.xdmf"));
    assert!(temporaries(&d).is_empty(), "{:?}", temporaries(&d));
    refused(
        &run(&dir, &["run", "tiny.toml", "--quiet", "--output", "d"]),
        &[
            &format!("failed at step {done} of 2000"),
            "--resume to continue",
        ],
    );
    // As if the fields file of that step had failed: the resumed run writes it again.
    let fields = d.join(format!("fields_{done:06}.h5"));
    std::fs::remove_file(&fields).expect("fields of the last step");
    let (_, hint) = line
        .split_once("(e.g. space freed): ")
        .expect("resume command");
    resume_two_more(&dir, hint, done);
    assert!(fields.is_file());

    // Before the first checkpoint: nothing to resume, and no offer to.
    let o = run_limited(&dir, 100, "run tiny.toml --quiet --output e --steps 10");
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(
        err.contains(
            "checkpoint.h5: HDF5: writing failed: File too large; no checkpoint was written"
        ),
        "{err}"
    );
    let e = dir.join("e");
    assert!(!e.join("checkpoint.h5").exists() && temporaries(&e).is_empty());
    assert_eq!(record(&e).status, "failed");
    refused(
        &run(&dir, &["run", "tiny.toml", "--quiet", "--output", "e"]),
        &["failed at step 1 of 10", "it left no checkpoint to resume"],
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// Sets point 0 of the dataset `name` of the snapshot `file` to `value`.
fn corrupt_point(file: &Path, name: &str, value: f64) {
    let f = hdf5_metno::File::open_rw(file).expect("open the snapshot");
    let ds = f.dataset(name).expect("dataset");
    let mut values: Vec<f64> = ds.read_raw().expect("read");
    values[0] = value;
    ds.write_raw(&values).expect("write");
}

/// `crack RUN` verifies the snapshots it reads as a checkpoint is verified: a non-finite value or a damage
/// outside [0, 1] is refused, naming the file and the dataset, and crack.json is not rewritten.
#[test]
fn crack_refuses_corrupt_snapshots_and_keeps_crack_json() {
    let _machine = shared();
    let dir = scratch("faults", "crack-corrupt", &[]);
    succeeds(&run(
        &dir,
        &["run", "tiny.toml", "--quiet", "--output", "d"],
    ));
    let d = dir.join("d");
    let snapshot = d.join("fields_000002.h5");
    let good = std::fs::read(&snapshot).expect("snapshot");
    let crack_json = std::fs::read(d.join("crack.json")).expect("crack.json");
    for (name, value, shown) in [
        ("damage", f64::NAN, "holds NaN at point 0"),
        ("damage", 1.0 + 1e-9, "(allowed: values in [0, 1])"),
        ("damage", -0.5, "holds -0.5 at point 0"),
        (
            "position",
            f64::INFINITY,
            "holds inf at point 0 (allowed: finite values)",
        ),
        ("nonlocal_damage", f64::NAN, "`nonlocal_damage` holds NaN"),
    ] {
        std::fs::write(&snapshot, &good).expect("restore");
        corrupt_point(&snapshot, name, value);
        refused(
            &run(&dir, &["crack", "d"]),
            &[
                "d/fields_000002.h5",
                &format!("dataset `{name}`"),
                shown,
                "corrupt",
            ],
        );
        assert_eq!(
            std::fs::read(d.join("crack.json")).expect("crack.json"),
            crack_json
        );
    }
    std::fs::write(&snapshot, &good).expect("restore");
    succeeds(&run(&dir, &["crack", "d"]));
    std::fs::remove_dir_all(&dir).ok();
}

/// Sets every value of the dataset `name` of the snapshot `file` to `value` plus `shift`.
fn rewrite(file: &Path, name: &str, value: Option<f64>, shift: f64) {
    let f = hdf5_metno::File::open_rw(file).expect("open the snapshot");
    let ds = f.dataset(name).expect("dataset");
    let values: Vec<f64> = ds.read_raw().expect("read");
    let values: Vec<f64> = values.iter().map(|v| value.unwrap_or(*v) + shift).collect();
    ds.write_raw(&values).expect("write");
}

/// `crack RUN` refuses, naming the file, a snapshot that is in range but not the run's own as written: its
/// damage or positions rewritten, one of another run, one copied under another step's name, and a snapshot
/// run.json lists that is missing; crack.json is not rewritten. The untouched run passes, and so does a run
/// resumed with more steps and a run written before snapshots carried their identity (no attributes, no
/// list in run.json).
#[test]
fn crack_refuses_snapshots_that_are_not_the_runs_own() {
    let _machine = shared();
    let dir = scratch("faults", "crack-identity", &[]);
    succeeds(&run(
        &dir,
        &["run", "tiny.toml", "--quiet", "--output", "d"],
    ));
    let other = [
        "run",
        "tiny.toml",
        "--quiet",
        "--output",
        "e",
        "--steps",
        "6",
    ];
    succeeds(&run(&dir, &other));
    let d = dir.join("d");
    let listed = record(&d).snapshots.expect("run.json lists the snapshots");
    let steps: Vec<(&str, usize)> = listed.iter().map(|s| (s.file.as_str(), s.step)).collect();
    assert_eq!(
        steps,
        [
            ("fields_000000.h5", 0),
            ("fields_000002.h5", 2),
            ("fields_000004.h5", 4)
        ]
    );
    assert!(
        listed
            .iter()
            .all(|s| s.run.is_some() && s.checksum.is_some())
    );
    succeeds(&run(&dir, &["crack", "d"]));
    let crack_json = std::fs::read(d.join("crack.json")).expect("crack.json");
    let snapshot = d.join("fields_000002.h5");
    let good = std::fs::read(&snapshot).expect("snapshot");
    let changed = "its point fields changed after writing";
    let faults: [(&str, &dyn Fn(), &str); 5] = [
        (
            "damage 1",
            &|| rewrite(&snapshot, "damage", Some(1.0), 0.0),
            changed,
        ),
        // (The tiny run has no damage yet: setting it to 0 would change nothing.)
        (
            "damage 0.5",
            &|| rewrite(&snapshot, "damage", Some(0.5), 0.0),
            changed,
        ),
        (
            "shifted",
            &|| rewrite(&snapshot, "position", None, 1e6),
            changed,
        ),
        (
            "another run's",
            &|| {
                std::fs::copy(dir.join("e/fields_000002.h5"), &snapshot).expect("copy");
            },
            "written by another run",
        ),
        (
            "another step's",
            &|| {
                std::fs::copy(d.join("fields_000004.h5"), &snapshot).expect("copy");
            },
            "holds step 4, its name says step 2",
        ),
    ];
    for (what, fault, shown) in faults {
        std::fs::write(&snapshot, &good).expect("restore");
        fault();
        let line = refused(&run(&dir, &["crack", "d"]), &["d/fields_000002.h5", shown]);
        assert!(line.contains("not this run's snapshot"), "{what}: {line}");
        assert_eq!(
            std::fs::read(d.join("crack.json")).expect("crack.json"),
            crack_json
        );
    }
    std::fs::write(&snapshot, &good).expect("restore");
    let last = d.join("fields_000004.h5");
    let kept = std::fs::read(&last).expect("last snapshot");
    std::fs::remove_file(&last).expect("delete the last snapshot");
    refused(
        &run(&dir, &["crack", "d"]),
        &[
            "d/fields_000004.h5",
            "missing: run.json lists it as the snapshot of step 4",
        ],
    );
    std::fs::write(&last, kept).expect("restore");
    succeeds(&run(&dir, &["crack", "d"]));
    // A resumed run with more steps is another run identity: the snapshots written before the resumption
    // are listed with the identity of the run that wrote them, and pass.
    let resumed = [
        "run",
        "tiny.toml",
        "--quiet",
        "--output",
        "d",
        "--resume",
        "--steps",
        "6",
    ];
    succeeds(&run(&dir, &resumed));
    let runs: Vec<Option<String>> = record(&d)
        .snapshots
        .expect("list")
        .into_iter()
        .map(|s| s.run)
        .collect();
    assert_eq!(runs.len(), 4);
    assert!(runs[0] == runs[2] && runs[2] != runs[3], "{runs:?}");
    succeeds(&run(&dir, &["crack", "d"]));
    // A run of an earlier version: no list in run.json, no identity in the snapshots.
    let mut old = record(&d);
    let written = old.snapshots.take().expect("list");
    std::fs::write(
        d.join("run.json"),
        serde_json::to_string(&old).expect("json"),
    )
    .expect("write");
    for s in written {
        let f = hdf5_metno::File::open_rw(d.join(&s.file)).expect("open the snapshot");
        f.delete_attr("run_id").expect("delete run_id");
        f.delete_attr("fields_crc32").expect("delete fields_crc32");
    }
    succeeds(&run(&dir, &["crack", "d"]));
    std::fs::remove_dir_all(&dir).ok();
}

/// A block and a rigid body 500 mm away: the grid grows from 11 x 11 to 258 x 258 cells.
const FAR: &str = r#"
[run]
name = "far"
steps = 1

[grid]
cell_size = 2.0

[[body]]
name = "b"
density = 2.4e-9
geometry = { include = [{ type = "rect", min = [0.0, 0.0], max = [10.0, 10.0] }] }
material = { model = "linear_elastic", youngs_modulus = 30000.0, poisson_ratio = 0.2 }

[[rigid_body]]
name = "far"
geometry = { include = [{ type = "rect", min = [500.0, 500.0], max = [504.0, 504.0] }] }
y = "fixed"
"#;

/// A rigid body far from the bodies that grows the grid is warned about, with the grid's size with and
/// without it, and under mpirun once (by process 0).
#[test]
fn a_far_rigid_body_is_warned_about_once() {
    let _machine = shared();
    let dir = scratch("faults", "far", &[]);
    std::fs::write(dir.join("far.toml"), FAR).expect("config");
    let warning =
        "the grid is 258x258 cells, the bodies alone need 11x11: a [[rigid_body]] lies far";
    let o = run(&dir, &["run", "far.toml", "--quiet", "--output", "d"]);
    succeeds(&o);
    assert_eq!(stderr(&o).matches(warning).count(), 1, "{}", stderr(&o));
    let o = Command::new("timeout")
        .current_dir(&dir)
        .args(["120", "mpirun", "--oversubscribe", "-n", "2", EXE])
        .args(["run", "far.toml", "--quiet", "--output", "e"])
        .env("OMPI_ALLOW_RUN_AS_ROOT", "1")
        .env("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1")
        .output()
        .expect("start timeout/mpirun (is Open MPI installed?)");
    succeeds(&o);
    assert_eq!(stderr(&o).matches(warning).count(), 1, "{}", stderr(&o));
    std::fs::remove_dir_all(&dir).ok();
}
