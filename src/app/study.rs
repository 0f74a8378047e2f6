//! Solver-comparison study: one configuration, several PETSc option sets, one table.
//!
//! Every option set runs as its own `mpm-concrete run` process (so a failing set is reported, not fatal,
//! and its peak memory is its own) with `-log_view` written beside its results; the study reads each run's
//! `history.csv` and summary and writes `study.md`, `study.csv` and `study_*.png` (Newton iterations and wall
//! time per step for every set).

use crate::io::write_atomic;
use crate::plot::{LinePlot, Series};
use crate::schema::{file, history};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::Command;

/// The study's report in its output directory.
pub const REPORT: &str = "study.md";

/// A named PETSc option set.
#[derive(Debug, Clone, PartialEq)]
pub struct OptionSet {
    /// Short name (directory and table row).
    pub name: String,
    /// PETSc options, e.g. `-ksp_type gmres -pc_type hypre`.
    pub options: String,
}

/// The sets compared when none are given: direct solvers, Krylov with algebraic multigrid, ILU and the
/// (u, eta_bar) field split, and a trust-region Newton.
pub fn default_sets() -> Vec<OptionSet> {
    let set = |name: &str, options: &str| OptionSet {
        name: name.into(),
        options: options.into(),
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

/// Reads option sets from a text file: one set per line, `name: options`; `#` starts a comment. Names must
/// be unique (each names a directory) and the values of common options are checked
/// ([`crate::preflight::check_petsc_options`]).
pub fn read_sets(path: &Path) -> Result<Vec<OptionSet>, String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let mut sets: Vec<(usize, OptionSet)> = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let line = line.split('#').next().unwrap_or("").trim();
        if line.is_empty() {
            continue;
        }
        let (name, options) = line.split_once(':').ok_or_else(|| {
            format!(
                "{}:{}: expected `name: -petsc -options`",
                path.display(),
                i + 1
            )
        })?;
        let name = name.trim();
        if name.is_empty()
            || !name
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_')
        {
            return Err(format!(
                "{}:{}: set name {name:?} must be letters, digits, - or _",
                path.display(),
                i + 1
            ));
        }
        if let Some((line, _)) = sets.iter().find(|(_, s)| s.name == name) {
            return Err(format!(
                "{}:{}: set name {name:?} is already used on line {line} (each set writes into the directory of its name)",
                path.display(),
                i + 1
            ));
        }
        crate::preflight::check_petsc_options(options)
            .map_err(|e| format!("{}:{}: {e}", path.display(), i + 1))?;
        sets.push((
            i + 1,
            OptionSet {
                name: name.into(),
                options: options.trim().into(),
            },
        ));
    }
    if sets.is_empty() {
        return Err(format!("{}: no option sets", path.display()));
    }
    Ok(sets.into_iter().map(|(_, s)| s).collect())
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
}

/// Runs every set for `steps` steps of `config`, results under `dir/<set name>` (replacing an earlier
/// study's there).
pub fn run(
    exe: &Path,
    config: &Path,
    steps: usize,
    sets: &[OptionSet],
    dir: &Path,
) -> Result<Vec<SetResult>, String> {
    std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let mut results = Vec::new();
    for set in sets {
        eprintln!("study: {} ({})", set.name, set.options);
        results.push(run_one(exe, config, steps, set, &dir.join(&set.name))?);
    }
    write_report(dir, config, steps, &results)?;
    Ok(results)
}

/// Runs `config` for `steps` steps with the option set as its own `mpm-concrete run` process, results
/// and PETSc's `-log_view` profile (`log_view.txt`) in `out` (replacing an earlier run's there); reads
/// back its history and summary.
pub fn run_one(
    exe: &Path,
    config: &Path,
    steps: usize,
    set: &OptionSet,
    out: &Path,
) -> Result<SetResult, String> {
    let log = out.join("log_view.txt");
    std::fs::create_dir_all(out).map_err(|e| format!("{}: {e}", out.display()))?;
    let start = std::time::Instant::now();
    let output = Command::new(exe)
        .arg("run")
        .arg(config)
        .args([
            "--steps",
            &steps.to_string(),
            "--quiet",
            "--overwrite",
            "--output",
        ])
        .arg(out)
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
            .unwrap_or("failed")
            .to_owned()
    });
    Ok(read_result(
        set,
        &out.join(file::HISTORY),
        &stdout,
        total,
        steps,
        error,
    ))
}

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
    };
    let text = std::fs::read_to_string(csv).unwrap_or_default();
    let mut lines = text.lines().filter(|l| !l.starts_with('#'));
    let header: Vec<&str> = lines
        .next()
        .map(|h| h.split(',').collect())
        .unwrap_or_default();
    let col = |name: &str| header.iter().position(|h| *h == name);
    let (mut newton_sum, mut linear_sum, mut unknowns_sum) = (0.0, 0.0, 0.0);
    for line in lines {
        let f: Vec<&str> = line.split(',').collect();
        let num = |name: &str| {
            col(name)
                .and_then(|i| f.get(i))
                .and_then(|v| v.parse::<f64>().ok())
                .unwrap_or(f64::NAN)
        };
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

/// The report's Markdown (a table of the sets and their options) and the same figures as CSV.
fn report_tables(config: &Path, steps: usize, results: &[SetResult]) -> (String, String) {
    let mut md = format!(
        "# Solver study: `{}`, {steps} steps\n\nWall times in s, memory in MB (peak resident set of the run's process). \
         PETSc's profile of each set: `<set>/log_view.txt`.\n\n",
        config.display()
    );
    md.push_str("| set | converged | steps | Newton/step | KSP/Newton | set-up | assembly | PETSc solve | total | peak MB | retries |\n");
    md.push_str("|---|---|---|---|---|---|---|---|---|---|---|\n");
    let mut csv = String::from(
        "set,converged,steps,newton_per_step,ksp_per_newton,setup_s,assembly_s,solve_s,total_s,peak_mb,retries,options,error\n",
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
        let _ = writeln!(md, " {retries} |");
        let error = r.error.clone().unwrap_or_default().replace('"', "'");
        let _ = writeln!(csv, ",{retries},\"{}\",\"{error}\"", r.set.options);
    }
    md.push_str("\nOption sets:\n\n");
    for r in results {
        let _ = writeln!(
            md,
            "- `{}`: `{}`{}",
            r.set.name,
            r.set.options,
            r.error
                .as_ref()
                .map(|e| format!(" — failed: {e}"))
                .unwrap_or_default()
        );
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
                options: "-pc_type ilu".into()
            }
        );
        std::fs::write(&p, "a: -pc_type lu\nb: -pc_type ilu\na: -pc_type jacobi\n").expect("write");
        let e = read_sets(&p).unwrap_err();
        assert!(
            e.contains("sets.txt:3") && e.contains("\"a\" is already used on line 1"),
            "{e}"
        );
        std::fs::write(&p, "a: -ksp_type gmres -ksp_rtol -5\n").expect("write");
        let e = read_sets(&p).unwrap_err();
        assert!(
            e.contains("sets.txt:1") && e.contains("-ksp_rtol -5"),
            "{e}"
        );
        std::fs::write(&p, "no colon here\n").expect("write");
        let e = read_sets(&p).unwrap_err();
        assert!(
            e.contains("sets.txt:1") && e.contains("name: -petsc"),
            "{e}"
        );
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn report_rows_have_fixed_decimals() {
        let row = |name: &str, steps: usize, error: Option<&str>| SetResult {
            set: OptionSet {
                name: name.into(),
                options: "-pc_type lu".into(),
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
        };
        let results = [row("lu", 2, None), row("ilu", 0, Some("diverged \"x\""))];
        let (md, csv) = report_tables(Path::new("c.toml"), 2, &results);
        assert!(md.contains(
            "| lu | yes | 2 | 3.50 | 2.3 | 0.12 | 0.33 | 2.50 | 4.00 | 106 | 1 |\n\
             | ilu | **no** | 0 | NaN | 2.3 | 0.12 | 0.33 | 2.50 | 4.00 | 106 | 1 |\n"
        ));
        assert!(csv.ends_with(
            "lu,true,2,3.5000,2.3450,0.1250,0.3333,2.5000,4.0000,106.1,1,\"-pc_type lu\",\"\"\n\
             ilu,false,0,NaN,2.3450,0.1250,0.3333,2.5000,4.0000,106.1,1,\"-pc_type lu\",\"diverged 'x'\"\n"
        ));
    }
}
