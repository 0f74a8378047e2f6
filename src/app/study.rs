//! Studies: one configuration run with several sets, each of PETSc options, configuration overrides
//! (`--set key=value`) and program options (`--steps`, `--allow-large`), one table: a solver comparison,
//! or a sweep over cell sizes, grid rotations, erosion thresholds.
//!
//! Every set runs as its own `mpm-concrete run` process (so a failing set is reported, not fatal,
//! and its peak memory is its own) with `-log_view` written beside its results; the study reads each run's
//! `history.csv`, `crack.json` and summary and writes `study.md`, `study.csv` and `study_*.png` (Newton
//! iterations and wall time per step for every set).

use crate::crack::CrackState;
use crate::io::write_atomic;
use crate::plot::{LinePlot, Series};
use crate::rundir;
use crate::schema::{file, history};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::Command;

/// The study's report in its output directory.
pub const REPORT: &str = "study.md";

/// A named set of a study: PETSc options, configuration overrides and program options of its run.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct OptionSet {
    /// Short name (directory and table row).
    pub name: String,
    /// PETSc options, e.g. `-ksp_type gmres -pc_type hypre`.
    pub options: String,
    /// Configuration overrides `key=value` (`--set` of `run`), e.g. `grid.cell_size=1`.
    pub overrides: Vec<String>,
    /// Steps of this set's run (`--steps`); `None`: the study's.
    pub steps: Option<usize>,
    /// Start the run even above the memory estimate (`--allow-large`).
    pub allow_large: bool,
    /// Line of the sets file (0 for the default sets), for the errors of the checks.
    pub line: usize,
}

/// The sets compared when none are given: direct solvers, Krylov with algebraic multigrid, ILU and the
/// (u, eta_bar) field split, and a trust-region Newton.
pub fn default_sets() -> Vec<OptionSet> {
    let set = |name: &str, options: &str| OptionSet {
        name: name.into(),
        options: options.into(),
        ..OptionSet::default()
    };
    vec![
        set(
            "mumps",
            "-ksp_type preonly -pc_type lu -pc_factor_mat_solver_type mumps",
        ),
        set(
            "superlu_dist",
            "-ksp_type preonly -pc_type lu -pc_factor_mat_solver_type superlu_dist",
        ),
        set(
            "gmres-ilu",
            "-ksp_type gmres -ksp_rtol 1e-6 -pc_type bjacobi -sub_pc_type ilu",
        ),
        set(
            "gmres-hypre",
            "-ksp_type gmres -ksp_rtol 1e-6 -pc_type hypre -pc_hypre_type boomeramg",
        ),
        set("gmres-gamg", "-ksp_type gmres -ksp_rtol 1e-6 -pc_type gamg"),
        set(
            "gmres-mg",
            "-ksp_type gmres -ksp_rtol 1e-6 -pc_type mg -mg_levels_ksp_type richardson \
             -mg_levels_ksp_max_it 1 -mg_levels_pc_type sor",
        ),
        set(
            "fieldsplit",
            "-ksp_type gmres -ksp_rtol 1e-6 -pc_type fieldsplit -pc_fieldsplit_type multiplicative \
             -fieldsplit_u_pc_type bjacobi -fieldsplit_u_sub_pc_type ilu -fieldsplit_eta_bar_pc_type bjacobi \
             -fieldsplit_eta_bar_sub_pc_type ilu",
        ),
        set(
            "newtontr-ilu",
            "-snes_type newtontr -ksp_type gmres -ksp_rtol 1e-6 -pc_type bjacobi -sub_pc_type ilu",
        ),
    ]
}

/// The program options a set line may carry before its PETSc options.
const SET_PROGRAM_OPTIONS: &str = "--set KEY=VALUE, --steps N, --allow-large";

/// Reads the sets of a study from a text file: one set per line, `name: [program options] [PETSc
/// options]`, the program options `--set KEY=VALUE` (repeatable), `--steps N` and `--allow-large` before
/// the first PETSc option (one dash); `#` starts a comment. Names must be unique (each names a directory)
/// and the values of common PETSc options are checked ([`crate::preflight::check_petsc_options`]); the
/// overrides are checked against a configuration by [`check_sets`].
pub fn read_sets(path: &Path) -> Result<Vec<OptionSet>, String> {
    let text = crate::input::read_text_input(path).map_err(|e| e.to_string())?;
    let mut sets: Vec<OptionSet> = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let at = format!("{}:{}", path.display(), i + 1);
        let line = line[..comment_start(line)].trim();
        if line.is_empty() {
            continue;
        }
        let (name, rest) = line.split_once(':').ok_or_else(|| {
            format!("{at}: expected `name: [--set key=value ...] -petsc -options`")
        })?;
        let name = name.trim();
        if name.is_empty()
            || !name
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_')
        {
            return Err(format!(
                "{at}: set name {name:?} must be letters, digits, - or _"
            ));
        }
        if let Some(s) = sets.iter().find(|s| s.name == name) {
            return Err(format!(
                "{at}: set name {name:?} is already used on line {} (each set writes into the directory of its name)",
                s.line
            ));
        }
        let mut set = words(rest)
            .and_then(|w| parse_set_line(&w))
            .map_err(|e| format!("{at}: set `{name}`: {e}"))?;
        crate::preflight::check_petsc_options(&set.options).map_err(|e| format!("{at}: {e}"))?;
        crate::preflight::check_options_files(set.options.split_whitespace())
            .map_err(|e| format!("{at}: {e}"))?;
        set.name = name.into();
        set.line = i + 1;
        sets.push(set);
    }
    if sets.is_empty() {
        return Err(format!("{}: no option sets", path.display()));
    }
    Ok(sets)
}

/// Where the comment of a set line starts: its first `#` outside quotes (the line's length without one).
fn comment_start(line: &str) -> usize {
    let mut quote = None;
    let mut escaped = false;
    for (i, c) in line.char_indices() {
        match (quote, c) {
            _ if escaped => escaped = false,
            (Some('"'), '\\') => escaped = true,
            (Some(q), c) if c == q => quote = None,
            (None, '"' | '\'') => quote = Some(c),
            (None, '#') => return i,
            _ => {}
        }
    }
    line.len()
}

/// The words of a set line as a shell splits them, so that the checks and the runs see the same values:
/// whitespace separates words, `'...'` and `"..."` quote (inside double quotes `\"` and `\\` stand for `"`
/// and `\`), e.g. `--set run.name="CT a"` gives `--set` and `run.name=CT a`.
fn words(text: &str) -> Result<Vec<String>, String> {
    let mut words = Vec::new();
    let mut word: Option<String> = None;
    let mut chars = text.chars();
    while let Some(c) = chars.next() {
        match c {
            c if c.is_whitespace() => words.extend(word.take()),
            '\'' | '"' => {
                let w = word.get_or_insert_with(String::new);
                loop {
                    match chars.next() {
                        Some(q) if q == c => break,
                        Some('\\') if c == '"' => match chars.next() {
                            Some(e @ ('"' | '\\')) => w.push(e),
                            Some(e) => w.extend(['\\', e]),
                            None => w.push('\\'),
                        },
                        Some(other) => w.push(other),
                        None => {
                            return Err(format!(
                                "unterminated {c}: a quoted value ends with its quote on the same line"
                            ));
                        }
                    }
                }
            }
            c => word.get_or_insert_with(String::new).push(c),
        }
    }
    words.extend(word);
    Ok(words)
}

/// The options of a set line after its name, as [`words`]: program options, then PETSc options
/// (everything from the first word with one dash on; each a single word without spaces, as they are
/// passed on to the run).
fn parse_set_line(words: &[String]) -> Result<OptionSet, String> {
    let mut set = OptionSet::default();
    let mut tokens = words.iter().map(String::as_str).peekable();
    while let Some(&token) = tokens.peek() {
        if token.starts_with('-') && !token.starts_with("--") {
            break;
        }
        tokens.next();
        let mut value = |option: &str| {
            tokens
                .next()
                .ok_or_else(|| format!("{option} needs a value ({SET_PROGRAM_OPTIONS})"))
        };
        match token.split_once('=') {
            Some(("--set", kv)) => set.overrides.push(kv.to_owned()),
            _ if token == "--set" => set.overrides.push(value("--set")?.to_owned()),
            _ if token == "--steps" => {
                let n = value("--steps")?;
                set.steps = Some(
                    n.parse()
                        .ok()
                        .filter(|&n: &usize| n >= 1)
                        .ok_or_else(|| format!("--steps {n}: a number of steps >= 1"))?,
                );
            }
            _ if token == "--allow-large" => set.allow_large = true,
            _ => {
                return Err(format!(
                    "`{token}` is no option of a set line (allowed: {SET_PROGRAM_OPTIONS}, then PETSc \
                     options with one dash)"
                ));
            }
        }
    }
    if let Some(bad) = set.overrides.iter().find(|o| !o.contains('=')) {
        return Err(format!(
            "--set {}: expected key=value (e.g. grid.cell_size=2.5)",
            crate::input::echoed(bad)
        ));
    }
    let options: Vec<&str> = tokens.collect();
    if let Some(bad) = options
        .iter()
        .find(|o| o.is_empty() || o.contains(char::is_whitespace))
    {
        return Err(format!(
            "PETSc option word {bad:?} is empty or holds a space: the PETSc options of a set line are \
             single words (quotes are for the values of --set)"
        ));
    }
    set.options = options.join(" ");
    Ok(set)
}

/// Checks every set's overrides on `config` before any run starts: each key exists, each value parses
/// and passes the configuration's checks, and the PETSc options the overrides set (`run.petsc_options`)
/// are valid; the error names the sets file `sets_file`, the set's line, the set and the key.
pub fn check_sets(config: &Path, sets: &[OptionSet], sets_file: &Path) -> Result<(), String> {
    for set in sets.iter().filter(|s| !s.overrides.is_empty()) {
        let at = format!("{}:{}: set `{}`", sets_file.display(), set.line, set.name);
        let (cfg, _) = crate::config::RunConfig::load(config, &set.overrides)
            .map_err(|e| format!("{at}: {e}"))?;
        crate::preflight::check_petsc_options(&cfg.run.petsc_options)
            .map_err(|e| format!("{at}: {}", e.at_key("run.petsc_options")))?;
    }
    Ok(())
}

/// Result of one option set.
#[derive(Debug, Clone)]
pub struct SetResult {
    /// The set.
    pub set: OptionSet,
    /// Completed steps.
    pub steps: usize,
    /// True if every requested step converged.
    pub completed: bool,
    /// Newton iterations per step.
    pub newton: Vec<f64>,
    /// Linear iterations per Newton iteration (mean).
    pub linear_per_newton: f64,
    /// Wall time per step (s).
    pub wall: Vec<f64>,
    /// Set-up, assembly and PETSc solve time summed over the steps (s).
    pub setup: f64,
    /// Assembly time (s).
    pub assembly: f64,
    /// PETSc solve time (s).
    pub solve: f64,
    /// Total wall time of the process (s).
    pub total: f64,
    /// Peak resident memory (MB) as reported by the run.
    pub peak_mb: f64,
    /// Steps retried with a smaller time step.
    pub retries: usize,
    /// Mean number of unknowns per step.
    pub unknowns: f64,
    /// Steps whose Jacobian pattern changed (PETSc objects built anew).
    pub new_patterns: usize,
    /// Error message of a failed run.
    pub error: Option<String>,
    /// The last crack state of `crack.json` (CT runs): length, bands, dissipated energy.
    pub crack: Option<CrackState>,
    /// The largest reaction force magnitude `|F|` over the steps and the sets of `history.csv` (N per mm
    /// thickness in 2D, N in 3D; specimen frame) and the set it acts on.
    pub peak_reaction: Option<(String, f64)>,
}

/// Runs every set for `steps` steps of `config`, results under `dir/<set name>`; `replace[i]` says that set
/// `i`'s directory holds an earlier run that its run replaces ([`check_set_dirs`]).
pub fn run(
    exe: &Path,
    config: &Path,
    steps: usize,
    sets: &[OptionSet],
    dir: &Path,
    replace: &[bool],
) -> Result<Vec<SetResult>, String> {
    std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let mut results = Vec::new();
    for (set, &replace) in sets.iter().zip(replace) {
        let overrides: Vec<String> = set.overrides.iter().map(|o| format!("--set {o}")).collect();
        eprintln!(
            "study: {} ({} {})",
            set.name,
            overrides.join(" "),
            set.options
        );
        let out = dir.join(&set.name);
        if replace {
            eprintln!(
                "study: --overwrite: the run of `{}` replaces the earlier run in {}",
                set.name,
                out.display()
            );
        }
        results.push(run_one(exe, config, steps, set, &out, replace)?);
    }
    write_report(dir, config, steps, &results)?;
    Ok(results)
}

/// The files a study writes into a set's directory besides the run's own
/// ([`rundir::is_program_file`]): PETSc's profile.
const STUDY_FILES: [&str; 1] = ["log_view.txt"];

/// Checks the directory `dir/<set name>` of every set before the first run, so that a study never
/// replaces a run it did not start: a directory that another run is writing into, that holds files no
/// run of this program writes, or that holds a run while `overwrite` is false is refused (the error
/// names the directory and what to do); with `overwrite`, a run is replaced only when its run record
/// (`run.json`) identifies it as a run of this program. Returns, per set, whether its run replaces an
/// earlier run (`run --overwrite`, which removes only the program's files).
pub fn check_set_dirs(
    dir: &Path,
    sets: &[OptionSet],
    overwrite: bool,
) -> Result<Vec<bool>, String> {
    sets.iter()
        .map(|set| check_set_dir(&dir.join(&set.name), overwrite))
        .collect()
}

/// The check of [`check_set_dirs`] for one run directory `out` (a study's set, a benchmark's case):
/// whether a run started there replaces an earlier run, or why it may not.
pub fn check_set_dir(out: &Path, overwrite: bool) -> Result<bool, String> {
    // A file in the way and a run.json that is no regular file are refused here.
    let contents = rundir::inspect(out)?;
    if !out.is_dir() {
        return Ok(false);
    }
    // A run writing into the directory now is refused, also with --overwrite.
    drop(rundir::lock(out)?);
    let mut foreign = Vec::new();
    for entry in std::fs::read_dir(out).map_err(|e| format!("{}: {e}", out.display()))? {
        let entry = entry.map_err(|e| format!("{}: {e}", out.display()))?;
        let name = entry.file_name().to_string_lossy().into_owned();
        let ours = rundir::is_program_file(&name) || STUDY_FILES.contains(&name.as_str());
        if !ours || !entry.path().is_file() {
            foreign.push(name);
        }
    }
    foreign.sort();
    let listed = |names: &[String]| {
        let more = names.len().saturating_sub(3);
        let shown = names[..names.len().min(3)].join(", ");
        if more > 0 {
            format!("{shown} and {more} more")
        } else {
            shown
        }
    };
    if !foreign.is_empty() {
        return Err(format!(
            "{}: holds files that no run of this program writes ({}): each set of a study (each case of \
             a benchmark) runs in its own directory, and only run directories are replaced: move them, \
             or give another --output",
            out.display(),
            listed(&foreign)
        ));
    }
    if contents.results.is_empty() {
        return Ok(false);
    }
    match (&contents.record, overwrite) {
        (Some(r), false) => {
            let (done, of) = (r.steps_done, r.steps_requested);
            let state = match r.status.as_str() {
                // No run holds the directory (its lock is free): the run was killed.
                "running" => {
                    format!("ended without closing its record (killed?) after step {done} of {of}")
                }
                status => format!("{status} at step {done} of {of}"),
            };
            Err(format!(
                "{} holds a run (config {}, {state}): give the study --overwrite to replace the runs in \
                 its sets' directories, or another --output",
                out.display(),
                r.config_file,
            ))
        }
        (None, _) => Err(format!(
            "{} holds results ({}) without a run record (run.json) that identifies the run: they are \
             not replaced, also with --overwrite: move them, or give another --output",
            out.display(),
            listed(&contents.results)
        )),
        (Some(_), true) => Ok(true),
    }
}

/// Runs `config` for `steps` steps with the option set as its own `mpm-concrete run` process, results
/// and PETSc's `-log_view` profile (`log_view.txt`) in `out` (with `replace`, the run replaces an earlier
/// run there: `run --overwrite`; without, the run refuses a directory that holds one); reads back its
/// history and summary.
pub fn run_one(
    exe: &Path,
    config: &Path,
    steps: usize,
    set: &OptionSet,
    out: &Path,
    replace: bool,
) -> Result<SetResult, String> {
    let log = out.join("log_view.txt");
    std::fs::create_dir_all(out).map_err(|e| format!("{}: {e}", out.display()))?;
    let steps = set.steps.unwrap_or(steps);
    let start = std::time::Instant::now();
    let output = Command::new(exe)
        .arg("run")
        .arg(config)
        .args(["--steps", &steps.to_string(), "--quiet"])
        .args(replace.then_some("--overwrite"))
        .arg("--output")
        .arg(out)
        .args(set.overrides.iter().flat_map(|o| ["--set", o.as_str()]))
        .args(set.allow_large.then_some("--allow-large"))
        // One process with threads, as every set before automatic processes: the sets compare solvers
        // on the same footing.
        .args(["--processes", "1"])
        .args(set.options.split_whitespace())
        .arg("-log_view")
        .arg(format!(":{}", log.display()))
        .output()
        .map_err(|e| format!("cannot start {}: {e}", exe.display()))?;
    let total = start.elapsed().as_secs_f64();
    let stdout = String::from_utf8_lossy(&output.stdout);
    let stderr = String::from_utf8_lossy(&output.stderr);
    let error = (!output.status.success()).then(|| {
        stderr
            .lines()
            .rev()
            .find(|l| l.starts_with("error"))
            .map_or_else(|| format!("failed ({})", output.status), str::to_owned)
    });
    let mut result = read_result(set, &out.join(file::HISTORY), &stdout, total, steps, error);
    result.crack = last_crack_state(&out.join(file::CRACK));
    Ok(result)
}

/// The last state of a run's `crack.json`; `None` without one (no CT) or if it cannot be read.
fn last_crack_state(path: &Path) -> Option<CrackState> {
    let text = crate::input::read_text_input(path).ok()?;
    let mut json: serde_json::Value = serde_json::from_str(&text).ok()?;
    let states: Vec<CrackState> = serde_json::from_value(json["states"].take()).ok()?;
    states.into_iter().last()
}

/// The largest reaction magnitude over the rows `f` of `history.csv` whose columns are `header`: each
/// set's force components `<set>_fx`, `<set>_fy` (and `<set>_fz`), and the set.
fn peak_reaction<'h>(header: &[&'h str], rows: &[Vec<f64>]) -> Option<(&'h str, f64)> {
    let mut sets: Vec<(&str, Vec<usize>)> = Vec::new();
    for (i, h) in header.iter().enumerate() {
        let Some(set) = ["_fx", "_fy", "_fz"].iter().find_map(|c| h.strip_suffix(c)) else {
            continue;
        };
        match sets.iter_mut().find(|(s, _)| *s == set) {
            Some((_, columns)) => columns.push(i),
            None => sets.push((set, vec![i])),
        }
    }
    let mut peak: Option<(&str, f64)> = None;
    for row in rows {
        for (set, columns) in &sets {
            let f = columns.iter().map(|&i| row[i] * row[i]).sum::<f64>().sqrt();
            if f.is_finite() && peak.is_none_or(|(_, p)| f > p) {
                peak = Some((set, f));
            }
        }
    }
    peak
}

/// The figures of a set's run from its `history.csv` at `csv` and the summary on its `stdout`.
fn read_result(
    set: &OptionSet,
    csv: &Path,
    stdout: &str,
    total: f64,
    steps: usize,
    error: Option<String>,
) -> SetResult {
    let mut r = SetResult {
        set: set.clone(),
        steps: 0,
        completed: false,
        newton: Vec::new(),
        linear_per_newton: f64::NAN,
        wall: Vec::new(),
        setup: 0.0,
        assembly: 0.0,
        solve: 0.0,
        total,
        peak_mb: f64::NAN,
        retries: 0,
        unknowns: f64::NAN,
        new_patterns: 0,
        error,
        crack: None,
        peak_reaction: None,
    };
    let text = crate::input::read_text_input(csv).unwrap_or_default();
    let mut lines = text.lines().filter(|l| !l.starts_with('#'));
    let header: Vec<&str> = lines
        .next()
        .map(|h| h.split(',').collect())
        .unwrap_or_default();
    let rows: Vec<Vec<f64>> = lines
        .map(|line| {
            let f: Vec<&str> = line.split(',').collect();
            (0..header.len())
                .map(|i| f.get(i).and_then(|v| v.parse().ok()).unwrap_or(f64::NAN))
                .collect()
        })
        .collect();
    let col = |name: &str| header.iter().position(|h| *h == name);
    let (mut newton_sum, mut linear_sum, mut unknowns_sum) = (0.0, 0.0, 0.0);
    for row in &rows {
        let num = |name: &str| col(name).map_or(f64::NAN, |i| row[i]);
        r.steps += 1;
        r.newton.push(num(history::NEWTON_ITS));
        newton_sum += num(history::NEWTON_ITS);
        linear_sum += num(history::LINEAR_ITS);
        r.wall.push(num(history::WALL_TOTAL));
        r.setup += num(history::WALL_SETUP);
        r.assembly += num(history::WALL_ASSEMBLY);
        r.solve += num(history::WALL_SOLVE) - num(history::WALL_ASSEMBLY);
        r.retries += (num(history::ATTEMPTS) as usize).saturating_sub(1);
        unknowns_sum += num(history::UNKNOWNS);
        r.new_patterns += usize::from(num(history::NEW_PATTERN) == 1.0);
    }
    r.peak_reaction = peak_reaction(&header, &rows).map(|(set, f)| (set.to_owned(), f));
    r.unknowns = unknowns_sum / r.steps.max(1) as f64;
    r.linear_per_newton = if newton_sum > 0.0 {
        linear_sum / newton_sum
    } else {
        f64::NAN
    };
    r.completed = r.error.is_none() && r.steps == steps;
    r.peak_mb = stdout
        .lines()
        .find(|l| l.starts_with("| peak memory |"))
        .and_then(|l| l.split('|').nth(2))
        .and_then(|v| v.split_whitespace().next())
        .and_then(|v| v.parse().ok())
        .unwrap_or(f64::NAN);
    r
}

/// Writes the study's report (Markdown), `study.csv` and the per-step plots into `dir`.
fn write_report(
    dir: &Path,
    config: &Path,
    steps: usize,
    results: &[SetResult],
) -> Result<(), String> {
    let (md, csv) = report_tables(config, steps, results);
    let io = |e: crate::io::OutputError| e.to_string();
    write_atomic(&dir.join(REPORT), md.as_bytes()).map_err(io)?;
    write_atomic(&dir.join("study.csv"), csv.as_bytes()).map_err(io)?;
    write_plots(dir, results)
}

/// The report's Markdown (a table of the sets, their options and results) and the same figures as CSV.
fn report_tables(config: &Path, steps: usize, results: &[SetResult]) -> (String, String) {
    let mut md = format!(
        "# Study: `{}`, {steps} steps\n\nWall times in s, memory in MB (peak resident set of the run's process). \
         Crack length (mm), branches and band angles (deg against the notch axis) of the last crack state \
         in `crack.json`, the median widths across the bands of the zones with damage d >= 0.9 and d >= 0.5 \
         (mm), the energy the damage dissipated under tension / compression and the largest \
         reaction |F| of the run (N per mm thickness; N in 3D), all in the specimen's frame (also with \
         `grid.rotation`). PETSc's profile of each set: `<set>/log_view.txt`.\n\n",
        config.display()
    );
    md.push_str("| set | converged | steps | Newton/step | KSP/Newton | set-up | assembly | PETSc solve | total | peak MB | retries | crack | branches | angles | widths | dissipated | peak reaction |\n");
    md.push_str("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
    let mut csv = String::from(
        "set,converged,steps,newton_per_step,ksp_per_newton,setup_s,assembly_s,solve_s,total_s,peak_mb,retries,\
         crack_length_mm,branches,band_angles_deg,classification,band_width_mm,zone_width_mm,\
         dissipated_tension,dissipated_compression,\
         peak_reaction,peak_reaction_set,overrides,options,error\n",
    );
    for r in results {
        let newton = if r.steps > 0 {
            r.newton.iter().sum::<f64>() / r.steps as f64
        } else {
            f64::NAN
        };
        // The figures with their decimals in the report and in the CSV: Newton/step, KSP/Newton, the
        // set-up, assembly, solve and total times (s) and the peak memory (MB).
        let figures = [
            (newton, 2, 4),
            (r.linear_per_newton, 1, 4),
            (r.setup, 2, 4),
            (r.assembly, 2, 4),
            (r.solve, 2, 4),
            (r.total, 2, 4),
            (r.peak_mb, 0, 1),
        ];
        let (name, steps, retries) = (&r.set.name, r.steps, r.retries);
        let converged = if r.completed { "yes" } else { "**no**" };
        let _ = write!(md, "| {name} | {converged} | {steps} |");
        let _ = write!(csv, "{name},{},{steps}", r.completed);
        for (v, md_decimals, csv_decimals) in figures {
            let _ = write!(md, " {v:.md_decimals$} |");
            let _ = write!(csv, ",{v:.csv_decimals$}");
        }
        let _ = write!(md, " {retries} |");
        let _ = write!(csv, ",{retries}");
        let (md_results, csv_results) = result_cells(r);
        let _ = writeln!(md, "{md_results}");
        let error = r.error.clone().unwrap_or_default().replace('"', "'");
        let _ = writeln!(
            csv,
            "{csv_results},\"{}\",\"{}\",\"{error}\"",
            r.set.overrides.join(" "),
            r.set.options
        );
    }
    md.push_str("\nSets:\n\n");
    for r in results {
        let overrides: Vec<String> = r
            .set
            .overrides
            .iter()
            .map(|o| format!("--set {o}"))
            .collect();
        let options = [overrides.join(" "), r.set.options.clone()].join(" ");
        let _ = writeln!(
            md,
            "- `{}`: `{}`{}",
            r.set.name,
            options.trim(),
            r.error
                .as_ref()
                .map(|e| format!(" — failed: {e}"))
                .unwrap_or_default()
        );
    }
    (md, csv)
}

/// The result cells of a set's row in the Markdown table (crack length, branches, band angles, dissipated
/// energy, peak reaction; `-` where the run has none) and in the CSV (from a leading comma to the peak
/// reaction's set).
fn result_cells(r: &SetResult) -> (String, String) {
    let (mut md, mut csv) = (String::new(), String::new());
    match &r.crack {
        Some(c) => {
            let angles: Vec<String> = c
                .bands
                .iter()
                .map(|b| format!("{:.0}", b.angle_degrees))
                .collect();
            let [t, k] = c.dissipated;
            let _ = write!(
                md,
                " {:.1} | {} | {} | {:.1} / {:.1} | {t:.2} / {k:.2} |",
                c.length,
                c.bands.len(),
                angles.join(", "),
                c.band_width,
                c.zone_width
            );
            let precise: Vec<String> = c
                .bands
                .iter()
                .map(|b| format!("{:.2}", b.angle_degrees))
                .collect();
            let _ = write!(
                csv,
                ",{:.3},{},\"{}\",{},{:.3},{:.3},{t:.6e},{k:.6e}",
                c.length,
                c.bands.len(),
                precise.join(" "),
                c.classification,
                c.band_width,
                c.zone_width
            );
        }
        None => {
            md.push_str(" - | - | - | - | - |");
            csv.push_str(",,,,,,,,");
        }
    }
    match &r.peak_reaction {
        Some((set, f)) => {
            let _ = write!(md, " {f:.2} ({set}) |");
            let _ = write!(csv, ",{f:.6e},{set}");
        }
        None => {
            md.push_str(" - |");
            csv.push_str(",,");
        }
    }
    (md, csv)
}

/// Newton iterations and wall time per step of every set that ran, as line plots in `dir`.
fn write_plots(dir: &Path, results: &[SetResult]) -> Result<(), String> {
    let series = |f: &dyn Fn(&SetResult) -> &Vec<f64>| -> Vec<Series> {
        results
            .iter()
            .filter(|r| r.steps > 0)
            .map(|r| Series {
                name: r.set.name.clone(),
                points: f(r)
                    .iter()
                    .enumerate()
                    .map(|(i, v)| ((i + 1) as f64, *v))
                    .collect(),
            })
            .collect()
    };
    let plots = [
        (
            "study_newton.png",
            "Newton iterations per step",
            series(&|r| &r.newton),
        ),
        (
            "study_wall.png",
            "wall time per step [s]",
            series(&|r| &r.wall),
        ),
    ];
    for (file, label, s) in plots {
        // No set ran a step: nothing to draw (the report says why each set failed).
        if s.is_empty() {
            continue;
        }
        let plot = LinePlot {
            title: format!("solver study: {label}"),
            x_label: "step".into(),
            y_label: label.into(),
            series: s,
        };
        plot.save_png(dir.join(file)).map_err(|e| e.to_string())?;
    }
    Ok(())
}

/// The summary of a study in which no set completed (`None` if one did): each set's reason and
/// directory, for an error that ends the study.
pub fn all_failed(dir: &Path, results: &[SetResult]) -> Option<String> {
    if results.is_empty() || results.iter().any(|r| r.completed) {
        return None;
    }
    let mut text = format!(
        "every set of the study failed ({} of {}); the report is {}:",
        results.len(),
        results.len(),
        dir.join(REPORT).display()
    );
    for r in results {
        let reason = r.error.as_deref().unwrap_or("stopped before its last step");
        let reason = reason.strip_prefix("error: ").unwrap_or(reason);
        let _ = write!(
            text,
            "\n  {}: {} step(s) done, {reason} (run in {})",
            r.set.name,
            r.steps,
            dir.join(&r.set.name).display()
        );
    }
    Some(text)
}

/// Default output directory of a study of `config`.
pub fn default_dir(config: &Path) -> PathBuf {
    let stem = config
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "config".into());
    PathBuf::from("runs").join(format!("study-{stem}"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn option_set_files_are_parsed_with_clear_errors() {
        let dir = std::env::temp_dir().join(format!("mpmc-sets-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("dir");
        let p = dir.join("sets.txt");
        std::fs::write(
            &p,
            "# comment\nlu: -pc_type lu\n\nilu: -pc_type ilu # trailing\n",
        )
        .expect("write");
        let sets = read_sets(&p).expect("valid");
        assert_eq!(sets.len(), 2);
        assert_eq!(
            sets[1],
            OptionSet {
                name: "ilu".into(),
                options: "-pc_type ilu".into(),
                line: 4,
                ..OptionSet::default()
            }
        );
        std::fs::write(
            &p,
            "h1: --set grid.cell_size=1 --set=ct.notch_width=1 --steps 3 --allow-large -pc_type lu\n",
        )
        .expect("write");
        let sets = read_sets(&p).expect("valid");
        assert_eq!(
            sets[0],
            OptionSet {
                name: "h1".into(),
                options: "-pc_type lu".into(),
                overrides: vec!["grid.cell_size=1".into(), "ct.notch_width=1".into()],
                steps: Some(3),
                allow_large: true,
                line: 1,
            }
        );
        // Quoted values are one word each, as a shell gives them to the run; a `#` inside quotes is no
        // comment.
        std::fs::write(
            &p,
            "q: --set run.name=\"CT a#1\" --set 'ct.notch=\"round\"' -pc_type lu # c\n",
        )
        .expect("write");
        let sets = read_sets(&p).expect("valid");
        assert_eq!(
            sets[0].overrides,
            vec!["run.name=CT a#1".to_string(), "ct.notch=\"round\"".into()]
        );
        assert_eq!(sets[0].options, "-pc_type lu");
        // (file, where the error points, what it says)
        let set_a = "sets.txt:1: set `a`";
        for (text, at, needle) in [
            (
                "a: --sets x=1\n",
                set_a,
                "`--sets` is no option of a set line",
            ),
            ("a: --set\n", set_a, "--set needs a value"),
            (
                "a: --set grid.cell_size\n",
                set_a,
                "--set grid.cell_size: expected key=value",
            ),
            ("a: --steps 0\n", set_a, "--steps 0: a number of steps >= 1"),
            (
                "a: grid.cell_size=1\n",
                set_a,
                "`grid.cell_size=1` is no option",
            ),
            (
                "a: -pc_type lu\nb: -pc_type ilu\na: -pc_type jacobi\n",
                "sets.txt:3",
                "\"a\" is already used on line 1",
            ),
            (
                "a: -ksp_type gmres -ksp_rtol -5\n",
                "sets.txt:1",
                "-ksp_rtol -5",
            ),
            (
                "a: --set run.name='x -pc_type lu\n",
                set_a,
                "unterminated '",
            ),
            (
                "a: -pc_type \"l u\"\n",
                set_a,
                "PETSc option word \"l u\" is empty or holds a space",
            ),
            (
                "no colon here\n",
                "sets.txt:1",
                "name: [--set key=value ...] -petsc",
            ),
        ] {
            std::fs::write(&p, text).expect("write");
            let e = read_sets(&p).unwrap_err();
            assert!(e.contains(at) && e.contains(needle), "{e}");
        }
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn report_rows_have_fixed_decimals() {
        let row = |name: &str, steps: usize, error: Option<&str>| SetResult {
            set: OptionSet {
                name: name.into(),
                options: "-pc_type lu".into(),
                ..OptionSet::default()
            },
            steps,
            completed: error.is_none(),
            newton: vec![3.0, 4.0],
            linear_per_newton: 2.345,
            wall: vec![0.1, 0.2],
            setup: 0.125,
            assembly: 1.0 / 3.0,
            solve: 2.5,
            total: 4.0,
            peak_mb: 106.06,
            retries: 1,
            unknowns: 100.0,
            new_patterns: 0,
            error: error.map(str::to_string),
            crack: None,
            peak_reaction: None,
        };
        let mut lu = row("lu", 2, None);
        lu.set.overrides = vec!["grid.rotation=15".into()];
        let state = serde_json::json!({
            "time": 3e-4, "length": 101.84, "tip": [150.0, 7.0],
            "bands": [{ "angle_degrees": -94.04, "points": 3 }, { "angle_degrees": -68.0, "points": 3 }],
            "classification": "branching", "crossings": [], "band_width": 4.0, "band_width_max": 6.0,
            "zone_width": 9.25, "dissipated": [88.834, 3.41]
        });
        lu.crack = Some(serde_json::from_value(state).expect("a crack state"));
        lu.peak_reaction = Some(("loading_plate".into(), 2276.0751));
        let results = [lu, row("ilu", 0, Some("diverged \"x\""))];
        let (md, csv) = report_tables(Path::new("c.toml"), 2, &results);
        assert!(
            md.contains(
                "| lu | yes | 2 | 3.50 | 2.3 | 0.12 | 0.33 | 2.50 | 4.00 | 106 | 1 | 101.8 | 2 | -94, -68 | 4.0 / 9.2 | 88.83 / 3.41 | 2276.08 (loading_plate) |\n\
                 | ilu | **no** | 0 | NaN | 2.3 | 0.12 | 0.33 | 2.50 | 4.00 | 106 | 1 | - | - | - | - | - | - |\n"
            ),
            "{md}"
        );
        assert!(
            md.contains("- `lu`: `--set grid.rotation=15 -pc_type lu`"),
            "{md}"
        );
        assert!(
            csv.ends_with(
                "lu,true,2,3.5000,2.3450,0.1250,0.3333,2.5000,4.0000,106.1,1,101.840,2,\"-94.04 -68.00\",branching,4.000,9.250,\
                 8.883400e1,3.410000e0,2.276075e3,loading_plate,\"grid.rotation=15\",\"-pc_type lu\",\"\"\n\
                 ilu,false,0,NaN,2.3450,0.1250,0.3333,2.5000,4.0000,106.1,1,,,,,,,,,,,\"\",\"-pc_type lu\",\"diverged 'x'\"\n"
            ),
            "{csv}"
        );
    }

    #[test]
    fn the_peak_reaction_is_the_largest_force_magnitude_of_any_set() {
        let header = ["step", "a_ux", "a_fx", "a_fy", "b_fx", "b_fy", "b_uy"];
        let rows = vec![
            vec![1.0, 0.0, 3.0, 4.0, 1.0, 1.0, 9e9],
            vec![2.0, 0.0, 0.0, 1.0, -6.0, 0.0, 9e9],
            vec![3.0, 0.0, f64::NAN, 1.0, 0.0, 0.0, 9e9],
        ];
        assert_eq!(peak_reaction(&header, &rows), Some(("b", 6.0)));
        assert_eq!(peak_reaction(&header[..2], &rows), None);
    }
}
