//! The drivers of the commands that only check their arguments and call an application: `crack` (the
//! crack re-measurement of a finished run), `bench` and `study` (each case or option set in its own
//! process).

use super::{bad, bench, no_petsc_options, study};
use crate::config::RunConfig;
use crate::io::{self, OutputError};
use crate::preflight;
use crate::rundir;
use anyhow::{Context, Result};
use std::path::{Path, PathBuf};

/// `crack RUN_DIR`: re-measures the crack metrics of a finished CT run from its snapshots, rewrites its
/// crack.json and prints the states.
pub fn crack(run_dir: &Path, petsc_args: &[String]) -> Result<()> {
    no_petsc_options("crack", "", petsc_args)?;
    // The run's lock, held while crack.json is rewritten: a run still writing into the directory is
    // refused (its snapshots and crack.json are still changing).
    let _lock = if run_dir.is_dir() {
        let advice = |e: String| {
            bad(e.replace(
                "or give another --output",
                "then re-measure (crack rewrites crack.json)",
            ))
        };
        Some(rundir::lock(run_dir).map_err(advice)?)
    } else {
        None
    };
    // A directory that is no CT run (or no run at all) and a corrupt or unreadable snapshot are bad
    // input; a failed write of crack.json is not.
    let states = io::remeasure_cracks(run_dir).map_err(|e| match e {
        OutputError::Run { .. } | OutputError::Io { .. } => bad(e),
        other => other.into(),
    })?;
    for s in &states {
        println!(
            "t = {:8.1} us: {:<10} length {:6.1} mm, bands [{}] deg, band width {:.1} mm (max {:.1}), \
             zone width (d >= 0.5) {:.1} mm",
            s.time * 1e6,
            s.classification,
            s.length,
            s.band_angles(),
            s.band_width,
            s.band_width_max,
            s.zone_width
        );
    }
    Ok(())
}

/// `bench`: the benchmark `cases` (all when empty), each for `steps` steps (its default when None), with
/// the PETSc options of the command line, results in `output`.
pub fn bench(
    cases: &[String],
    steps: Option<usize>,
    output: &Path,
    petsc_args: &[String],
) -> Result<()> {
    let mut all = bench::default_cases();
    if !cases.is_empty() {
        let names: Vec<String> = all.iter().map(|c| c.name.clone()).collect();
        if let Some(unknown) = cases.iter().find(|c| !names.contains(c)) {
            return Err(bad(format!(
                "--cases: unknown case `{unknown}` (allowed: {})",
                names.join(", ")
            )));
        }
        all.retain(|c| cases.contains(&c.name));
    }
    if let Some(n) = steps {
        if n == 0 {
            return Err(bad("--steps must be at least 1"));
        }
        all.iter_mut().for_each(|c| c.steps = n);
    }
    if let Some(c) = all.iter().find(|c| !c.config.is_file()) {
        return Err(bad(format!(
            "bench: {} not found (the cases' configs are relative to the repository root: run \
             the command there)",
            c.config.display()
        )));
    }
    let options = petsc_args[1..].join(" ");
    preflight::check_petsc_options(&options).map_err(|e| bad(format!("command line: {e}")))?;
    let exe = std::env::current_exe().context("locating the mpm-concrete executable")?;
    let report = bench::run(&exe, &all, &options, output).map_err(anyhow::Error::msg)?;
    println!("{}", bench::markdown(&report));
    println!("results in {}", output.display());
    Ok(())
}

/// `study CONFIG`: the configuration for `steps` steps with each set of the file `sets` (PETSc options,
/// configuration overrides, program options; the default solver sets when None), results in `output`
/// (default `runs/study-<config name>`).
pub fn study(
    config: &Path,
    steps: usize,
    sets: Option<&Path>,
    output: Option<PathBuf>,
    overwrite: bool,
    petsc_args: &[String],
) -> Result<()> {
    no_petsc_options(
        "study",
        ": the options of each run go into a --sets file",
        petsc_args,
    )?;
    if steps == 0 {
        return Err(bad("--steps must be at least 1"));
    }
    RunConfig::from_file(config).map_err(bad)?;
    let sets = match sets {
        Some(p) => {
            let sets = study::read_sets(p).map_err(bad)?;
            // Every override of every set is checked before the first run starts.
            study::check_sets(config, &sets, p).map_err(bad)?;
            sets
        }
        None => study::default_sets(),
    };
    let dir = output.unwrap_or_else(|| study::default_dir(config));
    if dir.exists() && !dir.is_dir() {
        return Err(bad(format!(
            "{}: exists and is not a directory (give another --output)",
            dir.display()
        )));
    }
    if dir.join(study::REPORT).exists() && !overwrite {
        return Err(bad(format!(
            "{} holds an earlier study ({}): use --overwrite to replace it, or another --output",
            dir.display(),
            study::REPORT
        )));
    }
    // Every set's directory is checked before the first run: the study replaces no run it did not start.
    let replace = study::check_set_dirs(&dir, &sets, overwrite).map_err(bad)?;
    let exe = std::env::current_exe().context("locating the mpm-concrete executable")?;
    let results =
        study::run(&exe, config, steps, &sets, &dir, &replace).map_err(anyhow::Error::msg)?;
    let failed = results.iter().filter(|r| !r.completed).count();
    println!("{}", std::fs::read_to_string(dir.join(study::REPORT))?);
    if let Some(summary) = study::all_failed(&dir, &results) {
        anyhow::bail!(summary);
    }
    println!(
        "{} of {} sets completed; results in {}",
        results.len() - failed,
        results.len(),
        dir.display()
    );
    Ok(())
}
