//! What the tests of the real binary share (`run_safety.rs`, `run_faults.rs`, `hostile_input.rs`): the
//! executable, the tiny CT specimen, a held block, scratch directories and the checks of a success and of a refusal.
//!
//! Units: mm, s, N, MPa, t.

// Each test crate compiles this module and uses a part of it.
#![allow(dead_code)]

use mpm_concrete::rundir::RunRecord;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// The program under test.
pub const EXE: &str = env!("CARGO_BIN_EXE_mpm-concrete");

/// A block with a held base, for the sections the CT generator does not have.
pub const BLOCK: &str = r#"
[run]
name = "block"
steps = 2

[grid]
cell_size = 2.0

[[body]]
name = "b"
density = 2.4e-9
geometry = { include = [{ type = "rect", min = [0.0, 0.0], max = [10.0, 10.0] }] }
material = { model = "linear_elastic", youngs_modulus = 30000.0, poisson_ratio = 0.2 }
initial_velocity = [0.0, 0.0]

[[constraint]]
name = "base"
min = [-1.0, -0.1]
max = [11.0, 0.1]
y = "fixed"
"#;

/// Runs the program in `cwd`.
pub fn run(cwd: &Path, args: &[&str]) -> Output {
    Command::new(EXE)
        .current_dir(cwd)
        .args(args)
        .output()
        .expect("start mpm-concrete")
}

/// Runs the program in `cwd` with the environment variables `env`, killed after `limit` if it has not
/// ended by then (a read that blocks or never ends fails the test instead of hanging it).
pub fn run_within(
    cwd: &Path,
    args: &[&str],
    env: &[(&str, &str)],
    limit: std::time::Duration,
) -> Output {
    let mut child = Command::new(EXE)
        .current_dir(cwd)
        .args(args)
        .envs(env.iter().copied())
        .stdin(std::process::Stdio::null())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("start mpm-concrete");
    let start = std::time::Instant::now();
    while child.try_wait().expect("wait").is_none() {
        if start.elapsed() > limit {
            child.kill().ok();
            child.wait().ok();
            panic!("{args:?} ({env:?}) did not end within {limit:?}");
        }
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    child.wait_with_output().expect("output")
}

/// A CT specimen of 360 points (10 x 10 cells of 4 mm), 1 us steps, a few ms per step.
pub const TINY: &str = r#"
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

/// A fresh directory `mpmc-<suite>-<pid>-<tag>` under the temporary directory holding `tiny.toml` and the
/// further `(name, contents)` files.
pub fn scratch(suite: &str, tag: &str, files: &[(&str, &str)]) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("mpmc-{suite}-{}-{tag}", std::process::id()));
    std::fs::remove_dir_all(&dir).ok();
    std::fs::create_dir_all(&dir).expect("scratch dir");
    std::fs::write(dir.join("tiny.toml"), TINY).expect("config");
    for (name, text) in files {
        std::fs::write(dir.join(name), text).expect("config");
    }
    dir
}

/// The standard error of a finished run.
pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// The run succeeded (its output is shown otherwise).
pub fn succeeds(o: &Output) {
    assert!(
        o.status.success(),
        "{}\n{}{}",
        o.status,
        String::from_utf8_lossy(&o.stdout),
        stderr(o)
    );
}

/// Exit code 2, one `error:` line holding every `needle`, no panic; returns the line.
pub fn refused(o: &Output, needles: &[&str]) -> String {
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

/// The run record `dir/run.json`.
pub fn record(dir: &Path) -> RunRecord {
    serde_json::from_str(&std::fs::read_to_string(dir.join("run.json")).expect("run.json"))
        .expect("run.json parses")
}
