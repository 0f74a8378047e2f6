//! Every file the program reads as input is a regular file below the limit of its kind, checked before it
//! is read: on the real binary, a FIFO (the read would block for ever), `/dev/zero` (an endless read that
//! exhausts the memory), a directory and a huge file given as a configuration, a study's `--sets` file, a
//! PETSc `-options_file` (on the command line, in `PETSC_OPTIONS` and in a set line), a run's `run.json`
//! and the `config.toml`, `crack.json` and snapshots `crack RUN` reads are refused within seconds with
//! exit code 2 and one line that names the file and the limit.
//!
//! Units: mm, s, N, MPa, t.

mod binary;

use binary::{refused, run, run_within, scratch, succeeds};
use std::path::Path;
use std::process::Command;
use std::time::Duration;

/// A refused input must be refused at once; a read of a FIFO or of `/dev/zero` would never end.
const LIMIT: Duration = Duration::from_secs(20);

/// The limit as the errors state it.
const STATED: &str = "an input must be a regular file of at most 64 MiB (67108864 bytes)";

/// A refusal: the arguments, the environment, what the error line names.
type Case<'a> = (Vec<&'a str>, Vec<(&'a str, &'a str)>, Vec<&'a str>);

/// Makes the FIFO `path`.
fn mkfifo(path: &Path) {
    let made = Command::new("mkfifo").arg(path).status();
    assert!(made.is_ok_and(|s| s.success()), "mkfifo {}", path.display());
}

/// Refused within [`LIMIT`] with exit code 2 and one line holding every needle.
fn refused_at_once(dir: &Path, args: &[&str], env: &[(&str, &str)], needles: &[&str]) -> String {
    refused(&run_within(dir, args, env, LIMIT), needles)
}

#[test]
fn configurations_sets_and_options_files_that_are_no_regular_files_are_refused_at_once() {
    let dir = scratch("input", "files", &[("sets.txt", "lu: -pc_type lu\n")]);
    mkfifo(&dir.join("fifo"));
    std::fs::create_dir(dir.join("folder")).expect("dir");
    std::fs::File::create(dir.join("huge.toml"))
        .and_then(|f| f.set_len((64 << 20) + 1))
        .expect("a sparse file");
    let fifo = "fifo: is a FIFO (named pipe), not a regular file";
    let zero = "/dev/zero: is a character device, not a regular file";
    let cases: Vec<Case> = vec![
        (
            vec!["run", "fifo", "--output", "out"],
            vec![],
            vec![fifo, STATED],
        ),
        (
            vec!["run", "/dev/zero", "--output", "out"],
            vec![],
            vec![zero, STATED],
        ),
        (
            vec!["run", "folder", "--output", "out"],
            vec![],
            vec!["folder: is a directory, not a regular file", STATED],
        ),
        (
            vec!["run", "huge.toml", "--output", "out"],
            vec![],
            vec!["huge.toml: is 64.0 MiB (67108865 bytes)", STATED],
        ),
        (
            vec!["study", "/dev/zero", "--output", "out"],
            vec![],
            vec![zero, STATED],
        ),
        (
            vec![
                "study",
                "tiny.toml",
                "--sets",
                "/dev/zero",
                "--output",
                "out",
            ],
            vec![],
            vec![zero, STATED],
        ),
        (
            vec!["study", "tiny.toml", "--sets", "fifo", "--output", "out"],
            vec![],
            vec![fifo, STATED],
        ),
        (
            vec![
                "run",
                "tiny.toml",
                "--output",
                "out",
                "-options_file",
                "/dev/zero",
            ],
            vec![],
            vec![
                "command line: PETSc option -options_file /dev/zero: is a character device",
                STATED,
            ],
        ),
        (
            vec![
                "run",
                "tiny.toml",
                "--output",
                "out",
                "-ksp_type",
                "gmres",
                "-options_file",
                "fifo",
            ],
            vec![],
            vec![
                "command line: PETSc option -options_file fifo: is a FIFO",
                STATED,
            ],
        ),
        (
            vec!["smoke", "-options_file", "fifo"],
            vec![],
            vec!["PETSc option -options_file fifo: is a FIFO", STATED],
        ),
        (
            vec![
                "run",
                "tiny.toml",
                "--output",
                "out",
                "-options_file",
                "missing.opts",
            ],
            vec![],
            vec!["PETSc option -options_file missing.opts: cannot read: no such file"],
        ),
        (
            vec!["run", "tiny.toml", "--output", "out"],
            vec![("PETSC_OPTIONS", "-options_file fifo")],
            vec!["environment variable PETSC_OPTIONS: PETSc option -options_file fifo: is a FIFO"],
        ),
    ];
    for (args, env, needles) in &cases {
        let line = refused_at_once(&dir, args, env, needles);
        assert!(!dir.join("out").exists(), "{args:?} wrote out/: {line}");
    }
    // An options file in a study's set line is checked with the set lines, before any run.
    std::fs::write(
        dir.join("sets.txt"),
        "lu: -pc_type lu\nf: -options_file fifo\n",
    )
    .expect("sets");
    refused_at_once(
        &dir,
        &[
            "study",
            "tiny.toml",
            "--sets",
            "sets.txt",
            "--output",
            "out",
        ],
        &[],
        &[
            "sets.txt:2: PETSc option -options_file fifo: is a FIFO",
            STATED,
        ],
    );
    assert!(!dir.join("out").exists());
    // A small regular options file is read by PETSc as before.
    std::fs::write(dir.join("solver.opts"), "-ksp_type preonly\n-pc_type lu\n").expect("options");
    succeeds(&run_within(
        &dir,
        &["smoke", "--n", "4", "-options_file", "solver.opts"],
        &[],
        LIMIT,
    ));
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn the_files_of_a_run_directory_that_are_no_regular_files_are_refused_at_once() {
    let dir = scratch("input", "rundir", &[]);
    succeeds(&run(
        &dir,
        &["run", "tiny.toml", "--quiet", "--output", "d"],
    ));
    let d = dir.join("d");
    let keep = |name: &str| std::fs::rename(d.join(name), dir.join(name)).expect("keep");
    let back = |name: &str| {
        std::fs::remove_file(d.join(name)).ok();
        std::fs::rename(dir.join(name), d.join(name)).expect("restore");
    };
    let zero = |name: &str| std::os::unix::fs::symlink("/dev/zero", d.join(name)).expect("symlink");
    let crack = ["crack", "d"];
    let rerun = [
        "run",
        "tiny.toml",
        "--quiet",
        "--output",
        "d",
        "--overwrite",
    ];
    // (file, replaced by a FIFO or by /dev/zero, the command that reads it)
    let cases: [(&str, bool, &[&str]); 6] = [
        ("config.toml", true, &crack),
        ("config.toml", false, &crack),
        ("crack.json", true, &crack),
        ("crack.json", false, &crack),
        ("fields_000002.h5", true, &crack),
        ("run.json", false, &rerun),
    ];
    for (name, fifo, args) in cases {
        keep(name);
        if fifo {
            mkfifo(&d.join(name));
        } else {
            zero(name);
        }
        let kind = if fifo {
            "is a FIFO (named pipe)"
        } else {
            "is a character device"
        };
        let line = refused_at_once(
            &dir,
            args,
            &[],
            &[&format!("d/{name}: {kind}, not a regular file")],
        );
        assert!(
            line.contains("at most 64 MiB") || line.contains("at most 64 GiB"),
            "{line}"
        );
        back(name);
    }
    // The run directory is intact: crack re-measures it.
    succeeds(&run_within(&dir, &crack, &[], LIMIT));
    std::fs::remove_dir_all(&dir).ok();
}
