//! The run's directory between invocations: why a new run may not write into it, whether its checkpoint
//! can be resumed, and the command that resumes it.

use crate::app::bad;
use crate::checkpoint;
use crate::input::InputProblem;
use crate::rundir::{self, RunIdentity};
use anyhow::Result;
use std::path::Path;

/// Quotes `word` for a POSIX shell when it needs it.
fn shell_quote(word: &str) -> String {
    let plain = |c: char| c.is_ascii_alphanumeric() || "_-./=:,+@%".contains(c);
    if !word.is_empty() && word.chars().all(plain) {
        word.to_owned()
    } else {
        format!("'{}'", word.replace('\'', "'\\''"))
    }
}

/// The command line as given, quoted for a shell.
pub(super) fn command_line(own: &[String], petsc: &[String]) -> String {
    own.iter()
        .chain(&petsc[1..])
        .map(|w| shell_quote(w))
        .collect::<Vec<_>>()
        .join(" ")
}

/// The command that resumes a run started with `own` + `petsc`: the same arguments with `--resume`
/// instead of `--overwrite` and with the output directory spelled out.
pub(super) fn resume_command(own: &[String], petsc: &[String], dir: &Path) -> String {
    let mut words: Vec<String> = own
        .iter()
        .filter(|a| *a != "--overwrite")
        .cloned()
        .collect();
    if !own
        .iter()
        .any(|a| a == "--output" || a.starts_with("--output="))
    {
        words.push("--output".into());
        words.push(dir.display().to_string());
    }
    if !own.iter().any(|a| a == "--resume") {
        words.push("--resume".into());
    }
    let mut all = vec![words.remove(0)];
    all.extend(words);
    command_line(&all, petsc)
}

/// Why a new run may not write into `dir` (which no other run holds: a run whose record still says
/// `running` ended without closing it, killed or crashed).
pub(super) fn refusal(dir: &Path, contents: &rundir::Contents, identity: &RunIdentity) -> String {
    let what = match &contents.record {
        Some(r) => format!(
            "the results of {} (config {}, {})",
            if r.identity.physics == identity.physics {
                "an earlier run of the same model"
            } else {
                "another run"
            },
            r.config_file,
            match r.status.as_str() {
                "running" => format!(
                    "ended without closing its record (killed?) after step {} of {}",
                    r.steps_done, r.steps_requested
                ),
                status => format!("{status} at step {} of {}", r.steps_done, r.steps_requested),
            }
        ),
        None => {
            let n = contents.results.len();
            format!(
                "the results of another run ({}{})",
                contents.results[..n.min(3)].join(", "),
                if n > 3 {
                    format!(" and {} more files", n - 3)
                } else {
                    String::new()
                }
            )
        }
    };
    let resume = if contents.results.iter().any(|f| f == checkpoint::FILE) {
        ", --resume to continue that run"
    } else {
        " (it left no checkpoint to resume)"
    };
    format!(
        "{} holds {what}: use --overwrite to replace them{resume}, or another --output",
        dir.display()
    )
}

/// Checks that the checkpoint in `dir` can be resumed by a run of `identity` with `steps` steps.
pub(super) fn check_resume(
    dir: &Path,
    identity: &RunIdentity,
    steps: usize,
) -> Result<checkpoint::Header> {
    let header = checkpoint::read_header(dir).map_err(bad)?;
    check_record(dir)?;
    let file = dir.join(checkpoint::FILE);
    let changes = header.identity.physics_changes(identity);
    if !changes.is_empty() {
        return Err(bad(format!(
            "{}: the checkpoint was written with other physics ({}); --resume may change only the [run] \
             section (steps, output_every, output_dir, name, petsc_options): start a new run instead",
            file.display(),
            changes.join("; ")
        )));
    }
    let done = header.counters.step;
    if steps <= done {
        return Err(bad(format!(
            "{}: the checkpoint is at step {done} and the run asks for {steps} steps, so there is nothing to \
             do: give --steps N with N > {done} to continue",
            file.display()
        )));
    }
    if header.identity.version != identity.version {
        eprintln!(
            "note: the checkpoint was written by version {}, this is {}",
            header.identity.version, identity.version
        );
    }
    if header.identity.petsc_options != identity.petsc_options {
        let shown = |o: &str| {
            if o.is_empty() {
                "none".to_owned()
            } else {
                format!("`{o}`")
            }
        };
        eprintln!(
            "note: PETSc options {} at the checkpoint, {} now",
            shown(&header.identity.petsc_options),
            shown(&identity.petsc_options)
        );
    }
    Ok(header)
}

/// The run record `dir/run.json` of a run to resume is advisory: the run continues from the checkpoint,
/// which its checksums verify, and writes a new record. A record that is no run record (or cannot be
/// read) is noted and ignored; one that is not a regular file below the limit of inputs would block the
/// read or make the rewrite fail after the work, so it is refused.
fn check_record(dir: &Path) -> Result<()> {
    let path = dir.join(crate::rundir::RUN_FILE);
    let parsed = match crate::input::read_text_input(&path) {
        Ok(text) => {
            serde_json::from_str::<crate::rundir::RunRecord>(&text).map_err(|e| e.to_string())
        }
        Err(e) if e.is_missing() => return Ok(()),
        Err(e) if matches!(e.problem, InputProblem::Unreadable(_)) => Err(e.reason()),
        Err(e) => {
            return Err(bad(format!(
                "{e}: the run record a resumed run rewrites (remove it)"
            )));
        }
    };
    if let Err(e) = parsed {
        eprintln!(
            "note: {}: not a run record ({e}); ignored: the run continues from the checkpoint, \
             which its checksums verify, and writes a new run.json",
            path.display()
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn words(s: &[&str]) -> Vec<String> {
        s.iter().map(|w| w.to_string()).collect()
    }

    #[test]
    fn the_resume_command_repeats_the_invocation_with_resume_and_the_output() {
        let own = words(&[
            "target/release/mpm-concrete",
            "run",
            "configs/ct-demo.toml",
            "--steps",
            "20",
            "--overwrite",
            "--set",
            "ct.material={ model = \"microplane\", preset = \"paper\" }",
        ]);
        let petsc = words(&["prog", "-ksp_type", "gmres"]);
        assert_eq!(
            resume_command(&own, &petsc, Path::new("runs/ct demo")),
            "target/release/mpm-concrete run configs/ct-demo.toml --steps 20 --set \
             'ct.material={ model = \"microplane\", preset = \"paper\" }' --output 'runs/ct demo' --resume \
             -ksp_type gmres"
        );
        let own = words(&["mpm-concrete", "run", "c.toml", "--output", "d", "--resume"]);
        assert_eq!(
            resume_command(&own, &words(&["p"]), Path::new("d")),
            "mpm-concrete run c.toml --output d --resume"
        );
        assert_eq!(shell_quote("it's"), "'it'\\''s'");
    }
}
