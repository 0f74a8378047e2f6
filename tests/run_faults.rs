//! Runs survive what happens to real runs: the real binary on a tiny CT specimen (360 points) under the
//! faults of docs/bad-input.md, "While running":
//!
//! * a second run into a directory that a run is writing is refused, also with --overwrite or --resume;
//! * Ctrl-C on several processes stops them all at the same step with a complete checkpoint of it;
//! * a write that fails (a file-size limit standing in for a full disk) leaves a resumable state and a
//!   run.json that says "failed";
//! * `crack` refuses corrupt snapshots.
//!
//! Every child process runs under `timeout`, so a hang fails the test instead of blocking it.

use mpm_concrete::checkpoint;
use mpm_concrete::rundir::RunRecord;
use std::io::BufRead;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};

const EXE: &str = env!("CARGO_BIN_EXE_mpm-concrete");

/// The CT specimen of tests/run_safety.rs: 360 points, 1 us steps, a few ms per step.
const TINY: &str = r#"
[run]
name = "tiny-ct"
steps = 4
output_every = 2

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

/// A fresh scratch directory holding `tiny.toml`.
fn scratch(tag: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("mpmc-faults-{}-{tag}", std::process::id()));
    std::fs::remove_dir_all(&dir).ok();
    std::fs::create_dir_all(&dir).expect("scratch dir");
    std::fs::write(dir.join("tiny.toml"), TINY).expect("config");
    dir
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

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn succeeds(o: &Output) {
    assert!(o.status.success(), "{}\n{}", o.status, stderr(o));
}

/// Exit code 2, one `error:` line holding every `needle`, no panic; returns the line.
fn refused(o: &Output, needles: &[&str]) -> String {
    let err = stderr(o);
    assert_eq!(o.status.code(), Some(2), "{err}");
    let lines: Vec<&str> = err.lines().filter(|l| l.starts_with("error:")).collect();
    assert_eq!(lines.len(), 1, "one error line expected:\n{err}");
    assert!(!err.contains("panicked"), "{err}");
    for n in needles {
        assert!(lines[0].contains(n), "`{n}` missing in: {}", lines[0]);
    }
    lines[0].to_owned()
}

fn record(dir: &Path) -> RunRecord {
    serde_json::from_str(&std::fs::read_to_string(dir.join("run.json")).expect("run.json"))
        .expect("run.json parses")
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
    let dir = scratch("lock");
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
    let dir = scratch("race");
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
