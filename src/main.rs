//! `mpm-concrete`: the command-line program.
//!
//! Program arguments come first (clap); everything from the first single-dash option on (`-snes_monitor`,
//! `-ksp_type gmres`, `-pc_type hypre`, `-log_view`, `-help`, ...) goes to PETSc's options database.
//!
//! Exit codes: 0 success; 1 a run or command that failed while working (a step that does not converge, a
//! file that cannot be written); 2 input rejected before any work (command line, configuration, PETSc
//! options, output directory, checkpoint, memory), with one line that says what and why.

use anyhow::{Context, Result};
use clap::{Parser, Subcommand};
use mpm_concrete::app::smoke::{self, SmokeParams};
use mpm_concrete::app::study;
use mpm_concrete::checkpoint;
use mpm_concrete::config::{self, RunConfig};
use mpm_concrete::io::RunOutput;
use mpm_concrete::model::Setup;
use mpm_concrete::petsc::{self, Session, SessionGuard};
use mpm_concrete::preflight;
use mpm_concrete::rundir::{self, RunIdentity, RunRecord};
use mpm_concrete::scenario;
use mpm_concrete::solver::{Simulation, StepError};
use mpm_concrete::solver_defaults;
use std::path::{Path, PathBuf};

#[derive(Parser)]
#[command(
    name = "mpm-concrete",
    version,
    about = "Implicit MPM with a gradient-enhanced microplane damage model for concrete (units: mm, s, N, MPa, t)",
    after_help = "PETSc options follow the program's arguments, e.g.\n  mpm-concrete smoke -snes_monitor -ksp_type gmres -pc_type hypre\nUse -help after the arguments to list PETSc's options."
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run a simulation described by a TOML configuration (see configs/ and docs/configuration.md).
    Run {
        /// Configuration file.
        config: PathBuf,
        /// Override `run.steps`.
        #[arg(long)]
        steps: Option<usize>,
        /// Override the output directory.
        #[arg(long)]
        output: Option<PathBuf>,
        /// No progress bar (log lines instead).
        #[arg(long)]
        quiet: bool,
        /// Continue from the checkpoint in the output directory (written at every output step, on Ctrl-C
        /// and when a step fails for good). Only the `[run]` section (steps, output cadence, PETSc options)
        /// may differ from the checkpointed run.
        #[arg(long, conflicts_with = "overwrite")]
        resume: bool,
        /// Replace the results of another run in the output directory (removes the files the program
        /// writes there, nothing else) instead of refusing to start.
        #[arg(long)]
        overwrite: bool,
        /// Start even if the estimated memory need exceeds the memory available.
        #[arg(long)]
        allow_large: bool,
        /// Override a config value, `key=value` with a dotted key and a TOML value (repeatable), e.g.
        /// `--set shape.method=fem --set shape.kind=linear --set grid.cell_size=2.5`.
        #[arg(long = "set", value_name = "KEY=VALUE")]
        set: Vec<String>,
    },
    /// Solver-comparison study: runs a configuration for a few steps with several PETSc option sets (each in
    /// its own process) and writes a table (Markdown, CSV) and charts.
    Study {
        /// Configuration file.
        config: PathBuf,
        /// Steps per option set.
        #[arg(long, default_value_t = 10)]
        steps: usize,
        /// Option sets, one per line `name: -petsc -options` (default: MUMPS, SuperLU_dist, GMRES with ILU,
        /// BoomerAMG, GAMG, fieldsplit on (u, eta_bar), trust-region Newton).
        #[arg(long)]
        sets: Option<PathBuf>,
        /// Output directory (default runs/study-<config name>).
        #[arg(long)]
        output: Option<PathBuf>,
        /// Replace the results of an earlier study in the output directory.
        #[arg(long)]
        overwrite: bool,
    },
    /// Performance benchmark: the paper-size CT, the elastic cantilever at 40,960 and 163,840 points and
    /// the CT demo, each for a fixed number of steps in its own process, plus the microplane update's
    /// throughput; writes bench.json and bench.md (docs/benchmarks.md). PETSc options after the arguments
    /// go to every case.
    Bench {
        /// Only these cases (comma-separated names: ct-paper-4.3mps, cantilever-41k, cantilever-164k,
        /// ct-demo).
        #[arg(long, value_delimiter = ',')]
        cases: Vec<String>,
        /// Steps per case instead of each case's default.
        #[arg(long)]
        steps: Option<usize>,
        /// Output directory.
        #[arg(long, default_value = "runs/bench")]
        output: PathBuf,
    },
    /// Cross-check a finished run against reference CSV files (history columns or point values): prints
    /// relative errors; exit code 0 when all are within --tolerance, 1 when one exceeds it, 2 on bad
    /// input (docs/cross-check.md).
    Compare(mpm_concrete::app::compare::CompareArgs),
    /// Re-measure the crack metrics of a finished CT run from its snapshots with this version's criteria
    /// and rewrite its crack.json (prints the final state).
    Crack {
        /// Run directory (`config.toml`, `fields_*.h5`).
        run_dir: PathBuf,
    },
    /// Material-point driver: strain or mixed paths through one constitutive law (CSV + PNG); prints the
    /// implied uniaxial strengths. No PETSc involved.
    MaterialDriver(mpm_concrete::app::material_driver::DriverArgs),
    /// Solve a small nonlinear lattice problem (3 unknowns per node) with SNES: checks the PETSc set-up
    /// and the solver options given on the command line.
    Smoke {
        /// Nodes per side of the lattice.
        #[arg(long, default_value_t = 12)]
        n: usize,
        /// Downward load per node on the right edge.
        #[arg(long, default_value_t = 0.001)]
        load: f64,
        /// Print the full solution (global order) as JSON.
        #[arg(long)]
        print_solution: bool,
    },
}

/// Input rejected before any work (exit code 2). An empty message means that another MPI rank reports it.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
struct BadInput(String);

/// A [`BadInput`] error.
fn bad(message: impl std::fmt::Display) -> anyhow::Error {
    BadInput(message.to_string()).into()
}

/// Splits the process arguments into the program's and PETSc's (from the first `-word` option on).
fn split_args(args: Vec<String>) -> (Vec<String>, Vec<String>) {
    let program = args
        .first()
        .cloned()
        .unwrap_or_else(|| "mpm-concrete".to_owned());
    let is_petsc = |a: &str| {
        let b = a.as_bytes();
        b.len() > 2 && b[0] == b'-' && b[1].is_ascii_alphabetic()
    };
    let split = args
        .iter()
        .skip(1)
        .position(|a| is_petsc(a))
        .map_or(args.len(), |i| i + 1);
    let mut petsc_args = vec![program];
    petsc_args.extend_from_slice(&args[split..]);
    (args[..split].to_vec(), petsc_args)
}

/// A program option (`--steps`) among the PETSc options would reach PETSc, not the program.
fn misplaced_program_option(petsc_args: &[String]) -> Option<String> {
    let first = petsc_args.get(1)?;
    let misplaced = petsc_args[1..]
        .iter()
        .find(|a| a.len() > 2 && a.starts_with("--"))?;
    Some(format!(
        "`{misplaced}` comes after the PETSc option `{first}`: the program's arguments (--steps, --output, \
         --set, ...) go before the first PETSc option"
    ))
}

fn main() -> std::process::ExitCode {
    // Under mpirun every process takes the same decisions: process 0 logs them, the others only warn.
    let rank = launcher_rank();
    tracing_subscriber::fmt()
        .with_writer(std::io::stderr)
        .with_target(false)
        .without_time()
        .with_max_level(if rank == 0 {
            tracing::Level::INFO
        } else {
            tracing::Level::WARN
        })
        .init();
    let (own, petsc_args) = split_args(std::env::args().collect());
    let cli = Cli::parse_from(&own);
    if let Some(message) = misplaced_program_option(&petsc_args) {
        eprintln!("error: {message}");
        return std::process::ExitCode::from(2);
    }
    if let Command::Compare(args) = &cli.command {
        return std::process::ExitCode::from(mpm_concrete::app::compare::run_cli(
            args,
            &petsc_args[1..],
        ));
    }
    // Under mpirun every process meets the same bad input and the same failed step: process 0 reports
    // them; the others report only what process 0 may not have met (errors other than bad input),
    // naming themselves.
    match run(cli, &own, &petsc_args) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => match e.chain().find_map(|c| c.downcast_ref::<BadInput>()) {
            Some(b) => {
                if !b.0.is_empty() && rank == 0 {
                    eprintln!("error: {e:#}");
                }
                std::process::ExitCode::from(2)
            }
            None => {
                match rank {
                    0 => eprintln!("error: {e:#}"),
                    r => eprintln!("error (process {r}): {e:#}"),
                }
                std::process::ExitCode::FAILURE
            }
        },
    }
}

/// This process's rank as the MPI launcher says (Open MPI, MPICH, Slurm); 0 outside a launcher.
fn launcher_rank() -> usize {
    ["OMPI_COMM_WORLD_RANK", "PMI_RANK", "SLURM_PROCID"]
        .iter()
        .find_map(|v| std::env::var(v).ok()?.trim().parse().ok())
        .unwrap_or(0)
}

/// Commands without PETSc accept no PETSc options (they would be silently ignored).
fn no_petsc_options(command: &str, hint: &str, petsc_args: &[String]) -> Result<()> {
    if petsc_args.len() > 1 {
        return Err(bad(format!(
            "{command} takes no PETSc options (got `{}`){hint}",
            petsc_args[1..].join(" ")
        )));
    }
    Ok(())
}

fn run(cli: Cli, own_args: &[String], petsc_args: &[String]) -> Result<()> {
    match cli.command {
        Command::Crack { run_dir } => {
            no_petsc_options("crack", "", petsc_args)?;
            use mpm_concrete::io::OutputError;
            // A directory that is no CT run (or no run at all) is bad input; unreadable snapshots are not.
            let states = mpm_concrete::io::remeasure_cracks(&run_dir).map_err(|e| match e {
                OutputError::Run { .. } | OutputError::Io { .. } => bad(e),
                other => other.into(),
            })?;
            for s in &states {
                let bands: Vec<String> = s
                    .bands
                    .iter()
                    .map(|b| format!("{:.0}", b.angle_degrees))
                    .collect();
                println!(
                    "t = {:8.1} us: {:<10} length {:6.1} mm, bands [{}] deg, band width {:.1} mm (max {:.1})",
                    s.time * 1e6,
                    s.classification,
                    s.length,
                    bands.join(", "),
                    s.band_width,
                    s.band_width_max
                );
            }
            Ok(())
        }
        Command::MaterialDriver(args) => {
            no_petsc_options("material-driver", "", petsc_args)?;
            let summary = mpm_concrete::app::material_driver::run_driver(&args)?;
            println!("{summary}");
            Ok(())
        }
        Command::Bench {
            cases,
            steps,
            output,
        } => {
            let mut all = mpm_concrete::app::bench::default_cases();
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
            preflight::check_petsc_options(&options)
                .map_err(|e| bad(format!("command line: {e}")))?;
            let exe = std::env::current_exe().context("locating the mpm-concrete executable")?;
            let report = mpm_concrete::app::bench::run(&exe, &all, &options, &output)
                .map_err(anyhow::Error::msg)?;
            println!("{}", mpm_concrete::app::bench::markdown(&report));
            println!("results in {}", output.display());
            Ok(())
        }
        Command::Study {
            config,
            steps,
            sets,
            output,
            overwrite,
        } => {
            no_petsc_options(
                "study",
                ": the options of each run go into a --sets file",
                petsc_args,
            )?;
            if steps == 0 {
                return Err(bad("--steps must be at least 1"));
            }
            RunConfig::from_file(&config).map_err(bad)?;
            let sets = match sets {
                Some(p) => study::read_sets(&p).map_err(bad)?,
                None => study::default_sets(),
            };
            let dir = output.unwrap_or_else(|| study::default_dir(&config));
            if dir.join(study::REPORT).exists() && !overwrite {
                return Err(bad(format!(
                    "{} holds an earlier study ({}): use --overwrite to replace it, or another --output",
                    dir.display(),
                    study::REPORT
                )));
            }
            let exe = std::env::current_exe().context("locating the mpm-concrete executable")?;
            let results =
                study::run(&exe, &config, steps, &sets, &dir).map_err(anyhow::Error::msg)?;
            let failed = results.iter().filter(|r| !r.completed).count();
            println!("{}", std::fs::read_to_string(dir.join(study::REPORT))?);
            println!(
                "{} of {} option sets completed; results in {}",
                results.len() - failed,
                results.len(),
                dir.display()
            );
            Ok(())
        }
        // handled in main, without PETSc
        Command::Compare(_) => Ok(()),
        Command::Run {
            config,
            steps,
            output,
            quiet,
            resume,
            overwrite,
            allow_large,
            set,
        } => run_simulation(
            own_args,
            petsc_args,
            &config,
            RunFlags {
                steps,
                output,
                quiet,
                resume,
                overwrite,
                allow_large,
                set,
            },
        ),
        Command::Smoke {
            n,
            load,
            print_solution,
        } => {
            if n < 2 {
                return Err(bad(format!("--n must be at least 2 (got {n})")));
            }
            preflight::check_petsc_options(&petsc_args[1..].join(" "))
                .map_err(|e| bad(format!("command line: {e}")))?;
            let session = Session::initialize(petsc_args).context("starting PETSc")?;
            share_cores(&session);
            smoke_test(&session, n, load, print_solution)?;
            Session::finalize(session)?;
            Ok(())
        }
    }
}

fn smoke_test(session: &SessionGuard, n: usize, load: f64, print_solution: bool) -> Result<()> {
    petsc::apply_default_options(session, "-ksp_type preonly -pc_type lu")?;
    let p = SmokeParams {
        n,
        load,
        ..SmokeParams::default()
    };
    let r = smoke::solve(session, p, None).context("solving the lattice problem")?;
    let norm = r.solution.iter().map(|v| v * v).sum::<f64>().sqrt();
    if session.rank() == 0 {
        println!(
            "lattice {n}x{n} ({} unknowns) on {} process(es), solver {}",
            r.solution.len(),
            session.size(),
            r.solver
        );
        println!(
            "{}: {} Newton iterations, {} linear iterations, |x| = {norm:.12e}",
            r.info.reason_name, r.info.iterations, r.info.linear_iterations
        );
        if print_solution {
            println!("{}", serde_json::to_string(&r.solution)?);
        }
    }
    let unused = petsc::unused_options(session)?;
    if !unused.is_empty() {
        return Err(bad(format!(
            "unknown or unused PETSc option(s): {} (check the spelling; -help lists the options)",
            unused.join(" ")
        )));
    }
    if !r.info.converged() {
        anyhow::bail!(
            "the lattice problem did not converge: {}",
            r.info.reason_name
        );
    }
    Ok(())
}

use solver_defaults::FALLBACK_PREFIX;

/// PETSc error codes that mean the options asked for something impossible (wrong argument, out of
/// range, unsupported, incompatible, unknown type).
const PETSC_INPUT_ERRORS: [i32; 5] = [56, 62, 63, 75, 86];

/// Command-line flags of `run`.
struct RunFlags {
    steps: Option<usize>,
    output: Option<PathBuf>,
    quiet: bool,
    resume: bool,
    overwrite: bool,
    allow_large: bool,
    set: Vec<String>,
}

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
fn command_line(own: &[String], petsc: &[String]) -> String {
    own.iter()
        .chain(&petsc[1..])
        .map(|w| shell_quote(w))
        .collect::<Vec<_>>()
        .join(" ")
}

/// The command that resumes a run started with `own` + `petsc`: the same arguments with `--resume`
/// instead of `--overwrite` and with the output directory spelled out.
fn resume_command(own: &[String], petsc: &[String], dir: &Path) -> String {
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

/// Why a new run may not write into `dir`.
fn refusal(dir: &Path, contents: &rundir::Contents, identity: &RunIdentity) -> String {
    let what = match &contents.record {
        Some(r) => format!(
            "the results of {} (config {}, {} at step {} of {})",
            if r.identity.physics == identity.physics {
                "an earlier run of the same model"
            } else {
                "another run"
            },
            r.config_file,
            r.status,
            r.steps_done,
            r.steps_requested
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
    format!(
        "{} holds {what}: use --overwrite to replace them, --resume to continue that run, or another --output",
        dir.display()
    )
}

/// Checks that the checkpoint in `dir` can be resumed by a run of `identity` with `steps` steps.
fn check_resume(dir: &Path, identity: &RunIdentity, steps: usize) -> Result<checkpoint::Header> {
    let header = checkpoint::read_header(dir).map_err(bad)?;
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

/// Steps (their time steps `taken`) that took less than the nominal time step `dt`.
fn reduced_steps(taken: &[f64], dt: f64) -> usize {
    taken.iter().filter(|&&t| t < dt * (1.0 - 1e-9)).count()
}

/// A sentence when a run whose steps took `taken` reached less than its requested end time (steps x dt)
/// or took reduced steps.
fn time_note(taken: &[f64], time: f64, steps: usize, dt: f64) -> Option<String> {
    let end = steps as f64 * dt;
    let reduced = reduced_steps(taken, dt);
    if time >= end * (1.0 - 1e-9) && reduced == 0 {
        return None;
    }
    let smallest = taken.iter().copied().fold(f64::INFINITY, f64::min);
    let mut note = format!(
        "the run ended at t = {:.4} us, before its requested end time {:.4} us ({steps} steps of {:.4} us)",
        time * 1e6,
        end * 1e6,
        dt * 1e6
    );
    if reduced > 0 {
        note += &format!(
            "; {reduced} of {} steps took a reduced time step (down to {:.4} us)",
            taken.len(),
            smallest * 1e6
        );
    }
    Some(note)
}

/// Appends `# note` to the run's history.csv, if it has one (the next rewrite of the history, by a resumed
/// run, drops it).
fn append_history_note(dir: &Path, note: &str) -> Result<()> {
    use std::io::Write as _;
    let path = dir.join(mpm_concrete::schema::file::HISTORY);
    if !path.exists() {
        return Ok(());
    }
    let mut f = std::fs::OpenOptions::new()
        .append(true)
        .open(&path)
        .with_context(|| format!("{}: appending a note", path.display()))?;
    writeln!(f, "# {note}").with_context(|| format!("{}: appending a note", path.display()))
}

/// Writes the point fields, the force plots and the checkpoint of the current state.
/// Writes the point fields, the force plots and the checkpoint of the current state (with the points
/// shared out over processes, process 0 gathers them first). Collective.
fn save_state<const D: usize>(
    session: &SessionGuard,
    out: &mut RunOutput,
    sim: &Simulation<D>,
    dir: &Path,
    identity: &RunIdentity,
) -> Result<()> {
    let Some(state) = mpm_concrete::partition::whole_state(session, &sim.state)
        .context("gathering the points on process 0")?
    else {
        return Ok(());
    };
    out.snapshot(&state)?;
    out.force_plots()?;
    if out.writes() {
        checkpoint::save(dir, &state, out, identity)?;
    }
    Ok(())
}

/// Processes of this run on this node, as the launcher says (Open MPI, MPICH, Slurm); None outside one.
fn processes_per_node() -> Option<usize> {
    [
        "OMPI_COMM_WORLD_LOCAL_SIZE",
        "MPI_LOCALNRANKS",
        "SLURM_NTASKS_PER_NODE",
    ]
    .iter()
    .find_map(|v| std::env::var(v).ok()?.trim().parse().ok())
    .filter(|&n: &usize| n > 0)
}

/// The number of processors the node has online (Linux), to tell a process bound to some cores from one
/// that may use all.
fn online_cpus() -> Option<usize> {
    let text = std::fs::read_to_string("/sys/devices/system/cpu/online").ok()?;
    text.trim()
        .split(',')
        .map(|range| {
            let mut ends = range.split('-');
            let lo: usize = ends.next()?.parse().ok()?;
            let hi: usize = match ends.next() {
                Some(hi) => hi.parse().ok()?,
                None => lo,
            };
            Some(hi + 1 - lo)
        })
        .sum()
}

/// Threads of the point loops when several processes run: a process bound to some of the node's cores
/// (by mpirun or srun) uses those; an unbound one its share of the node's cores among the processes on
/// the node. `RAYON_NUM_THREADS` overrides both.
fn share_cores(session: &SessionGuard) {
    if session.size() == 1 || std::env::var_os("RAYON_NUM_THREADS").is_some() {
        return;
    }
    let mine = std::thread::available_parallelism().map_or(1, |n| n.get());
    let threads = if mine < online_cpus().unwrap_or(mine) {
        mine
    } else {
        mine / processes_per_node().unwrap_or(session.size())
    };
    // Fails only if the pool already exists; it then keeps its size.
    let _ = rayon::ThreadPoolBuilder::new()
        .num_threads(threads.max(1))
        .build_global();
}

fn run_simulation(
    own_args: &[String],
    petsc_args: &[String],
    path: &Path,
    flags: RunFlags,
) -> Result<()> {
    let file = path.display().to_string();
    // Everything that can be checked is checked before anything is written: the configuration with its
    // overrides (--steps is run.steps), the PETSc option values, the output directory or the checkpoint
    // to resume, the memory, the number of processes, the model, and (by the first step) the PETSc set-up.
    if flags.steps == Some(0) {
        return Err(bad("--steps must be at least 1"));
    }
    let mut overrides = flags.set.clone();
    if let Some(n) = flags.steps {
        overrides.push(format!("run.steps={n}"));
    }
    let (cfg, effective) = RunConfig::load(path, &overrides).map_err(bad)?;
    preflight::check_petsc_options(&cfg.run.petsc_options)
        .map_err(|e| bad(format!("{file}: run.petsc_options: {e}")))?;
    let command_options = petsc_args[1..].join(" ");
    preflight::check_petsc_options(&command_options)
        .map_err(|e| bad(format!("command line: {e}")))?;
    let dir = flags.output.clone().unwrap_or_else(|| cfg.output_dir());
    let petsc_options = format!("{} {command_options}", cfg.run.petsc_options)
        .trim()
        .to_owned();
    let identity = RunIdentity::new(&effective, &petsc_options);
    let contents = rundir::inspect(&dir).map_err(bad)?;
    let resume_from = if flags.resume {
        Some(check_resume(&dir, &identity, cfg.run.steps)?)
    } else {
        if !contents.results.is_empty() && !flags.overwrite {
            return Err(bad(refusal(&dir, &contents, &identity)));
        }
        None
    };
    // Every process builds the whole model before it keeps its share of the points, and process 0
    // gathers all points for the output: each process on this node may peak near a serial run's memory
    // (paper-size CT: 731 MB per process on 2 against 649 MB on one).
    let mut need = preflight::memory_need(&cfg);
    need.bytes *= processes_per_node().unwrap_or(1) as f64;
    if let Some(limit) = preflight::memory_limit()
        && need.bytes > limit.bytes
        && !flags.allow_large
    {
        return Err(bad(format!(
            "{}: the run needs about {} of memory ({:.3e} material points, {:.3e} grid nodes), more \
             than the {} available ({}): use a larger grid.cell_size or fewer shape.points_per_cell, or \
             --allow-large to start anyway",
            config::source_label(&file, &overrides),
            preflight::human_bytes(need.bytes),
            need.points,
            need.nodes,
            preflight::human_bytes(limit.bytes),
            limit.source
        )));
    }

    let session = Session::initialize(petsc_args).context("starting PETSc")?;
    share_cores(&session);
    let prepared = Prepared {
        cfg,
        overrides,
        effective,
        identity,
        dir,
        resume_from,
    };
    // A plane set-up, or the plate it is extruded to ([extrusion]): the same run in 2D or 3D.
    match prepared.cfg.extrusion.as_ref().map(|e| e.thickness) {
        None => simulate::<2>(&session, own_args, petsc_args, path, &flags, prepared, &Ok)?,
        Some(thickness) => simulate::<3>(
            &session,
            own_args,
            petsc_args,
            path,
            &flags,
            prepared,
            &|plane: Setup| {
                plane
                    .extrude(thickness)
                    .map_err(|e| format!("[extrusion]: {e}"))
            },
        )?,
    }
    Session::finalize(session)?;
    Ok(())
}

/// A run that passed the checks that need no PETSc.
struct Prepared {
    cfg: RunConfig,
    /// `--set` overrides, `--steps` as `run.steps=N`.
    overrides: Vec<String>,
    effective: String,
    identity: RunIdentity,
    dir: PathBuf,
    resume_from: Option<checkpoint::Header>,
}

/// The run of a prepared configuration: `lift` turns the plane set-up the configuration describes into
/// the one of `D` dimensions that runs (2D: itself; 3D: its extrusion).
fn simulate<const D: usize>(
    session: &SessionGuard,
    own_args: &[String],
    petsc_args: &[String],
    path: &Path,
    flags: &RunFlags,
    prepared: Prepared,
    lift: &dyn Fn(Setup) -> Result<Setup<D>, String>,
) -> Result<()> {
    let Prepared {
        cfg,
        overrides,
        effective,
        identity,
        dir,
        resume_from,
    } = prepared;
    let file = path.display().to_string();
    petsc::apply_default_options(session, &cfg.run.petsc_options)
        .map_err(|e| bad(format!("{file}: run.petsc_options: {e}")))?;
    let plane = || scenario::build(&cfg).map_err(|e| bad(format!("{file}: {e}")));
    let model = || lift(plane()?).map_err(|e| bad(format!("{file}: {e}")));
    let mut setup = plane()?;
    // The solver defaults follow the kind of step (docs/solvers.md); those a user's solver choice makes
    // irrelevant (e.g. the MUMPS option under -pc_type hypre) must not be reported as unused.
    let (_, defaults) = solver_defaults::apply(session, &mut setup, D)?;
    let setup = lift(setup).map_err(|e| bad(format!("{file}: {e}")))?;
    let mut sim = Simulation::new(setup).map_err(|e| bad(format!("{file}: {e}")))?;
    // On several processes every one holds the whole model and its own share of the points (from the
    // first step on), the unknowns and PETSc's solvers are distributed (docs/theory.md, "Processes");
    // process 0 gathers the points and alone writes.
    let root = session.rank() == 0;
    if resume_from.is_some() {
        checkpoint::load(&dir, &sim.model, &mut sim.state).map_err(bad)?;
        if root {
            eprintln!(
                "resuming at step {} (t = {:e} s)",
                sim.state.step, sim.state.time
            );
        }
    }
    // Ctrl-C: finish the current step, write a checkpoint and the outputs, and stop.
    let interrupted = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    {
        let flag = interrupted.clone();
        ctrlc::set_handler(move || flag.store(true, std::sync::atomic::Ordering::SeqCst))
            .context("installing the Ctrl-C handler")?;
    }
    let np = sim.state.particles.len();
    let grid = &sim.model.grid;
    if root {
        let cells: Vec<String> = grid.cells().iter().map(usize::to_string).collect();
        eprintln!(
            "{}: {np} material points, grid {} cells of {} mm{}, {} steps of {:e} s, {} unknowns per node, {}output in {}",
            cfg.run.name,
            cells.join("x"),
            grid.cell_size(),
            match &cfg.extrusion {
                Some(e) => format!(", a {} mm plate (3D)", e.thickness),
                None => String::new(),
            },
            cfg.run.steps,
            cfg.time.dt,
            sim.model.layout().per_node(),
            match session.size() {
                1 => String::new(),
                n => format!("{n} processes, "),
            },
            dir.display()
        );
    }
    let bar = if flags.quiet || !root {
        indicatif::ProgressBar::hidden()
    } else {
        indicatif::ProgressBar::new(cfg.run.steps as u64)
    };
    bar.set_style(
        indicatif::ProgressStyle::with_template(
            "{bar:30} {pos}/{len} steps  {msg}  [{elapsed_precise} < {eta_precise}]",
        )
        .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    bar.set_position(sim.state.step as u64);
    let started = std::time::Instant::now();
    // A PETSc logging stage for the time loop, so -log_view separates it from the set-up.
    let _stage = session.push_stage(session.register_stage("MPM time steps")?)?;

    // The first step sets up PETSc's solvers, which read (and so validate) the options: until it has
    // passed, nothing is written.
    let mut step = sim.advance(session);
    match &step {
        Ok(_) => {
            let mut unused = petsc::unused_options(session)?;
            unused.retain(|o| {
                !defaults.contains(o) && !o.starts_with(&format!("-{FALLBACK_PREFIX}"))
            });
            if !unused.is_empty() {
                bar.abandon();
                return Err(bad(format!(
                    "unknown or unused PETSc option(s): {} (check the spelling; -help lists the options); \
                     nothing was written",
                    unused.join(" ")
                )));
            }
        }
        Err(StepError::Petsc(e)) => {
            bar.abandon();
            let message = format!("the first step failed in PETSc: {e}; nothing was written");
            return Err(if PETSC_INPUT_ERRORS.contains(&e.code) {
                bad(message)
            } else {
                anyhow::anyhow!(message)
            });
        }
        Err(e @ StepError::Setup(_)) => {
            bar.abandon();
            return Err(bad(format!("{file}: {e}; nothing was written")));
        }
        Err(_) => {}
    }

    // The output: the directory now belongs to this run.
    if flags.overwrite && root {
        let removed = rundir::remove_program_files(&dir).map_err(anyhow::Error::msg)?;
        if removed > 0 {
            eprintln!(
                "--overwrite: removed {removed} files of the earlier run from {}",
                dir.display()
            );
        }
    }
    let config_copy = format!(
        "# The effective configuration of the run in this directory: {}.\n\
         # Canonical form (sorted keys; the file's comments are not kept).\n\n{effective}",
        config::source_label(&file, &overrides)
    );
    // The output's reference state (initial positions, the step-0 fields) is the model as built, on the
    // process that writes (the others keep the records only).
    let initial = if root {
        Some(mpm_concrete::model::Model::new(model()?).map_err(|e| bad(format!("{file}: {e}")))?)
    } else {
        None
    };
    let mut out = match &initial {
        Some((initial_model, initial)) => {
            RunOutput::create(&dir, &cfg.run.name, &config_copy, initial_model, initial)?
        }
        None => RunOutput::mirror(&dir, &cfg.run.name, &config_copy, cfg.grid.cell_size),
    };
    if let Some(z) = cfg.extrusion.as_ref().and_then(|e| e.section_z) {
        out.set_section(z);
    }
    if let Some(ct) = &cfg.ct {
        out.track_crack(
            nalgebra::Vector2::new(ct.notch_length, 0.5 * ct.height),
            mpm_concrete::crack::CrackCriteria::for_notch(ct.notch_width, cfg.grid.cell_size),
        );
    }
    let mut record = RunRecord {
        identity: identity.clone(),
        command: command_line(own_args, petsc_args),
        config_file: file.clone(),
        overrides: overrides.clone(),
        started_unix: std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_secs()),
        resumed_from_step: resume_from.as_ref().map(|h| h.counters.step),
        status: "running".into(),
        steps_done: sim.state.step,
        steps_requested: cfg.run.steps,
        time_reached: sim.state.time,
        time_requested: cfg.run.steps as f64 * cfg.time.dt,
        reduced_steps: 0,
        note: None,
    };
    if root {
        record.write(&dir)?;
    }
    match (&resume_from, &initial) {
        (Some(header), _) => header
            .restore_records(&mut out)
            .context("restoring the output's records from the checkpoint")?,
        (None, Some((_, initial))) => out.snapshot(initial)?,
        (None, None) => {}
    }
    drop(initial);

    let hint = resume_command(own_args, petsc_args, &dir);
    let finish = |record: &mut RunRecord,
                  out: &RunOutput,
                  sim: &Simulation<D>,
                  status: &str,
                  why: Option<String>|
     -> Result<Option<String>> {
        let taken: Vec<f64> = out.rows().iter().map(|r| r.dt).collect();
        let note = time_note(&taken, sim.state.time, cfg.run.steps, cfg.time.dt);
        record.status = status.into();
        record.steps_done = sim.state.step;
        record.time_reached = sim.state.time;
        record.reduced_steps = reduced_steps(&taken, cfg.time.dt);
        record.note = match (&why, &note) {
            (Some(w), Some(n)) => Some(format!("{w}; {n}")),
            (w, n) => w.clone().or(n.clone()),
        };
        if root {
            if let Some(n) = &record.note {
                append_history_note(&dir, n)?;
            }
            record.write(&dir)?;
        }
        Ok(note)
    };
    loop {
        let report = match step {
            Ok(r) => r,
            Err(e) => {
                bar.abandon();
                save_state(session, &mut out, &sim, &dir, &identity)?;
                let why = format!(
                    "step {} failed: {}",
                    sim.state.step + 1,
                    e.to_string().trim()
                );
                finish(&mut record, &out, &sim, "failed", Some(why))?;
                anyhow::bail!(
                    "{}; the last converged state (step {}, t = {:e} s) is saved in {} with a checkpoint; \
                     to continue (e.g. with other solver options): {hint}",
                    e.to_string().trim(),
                    sim.state.step,
                    sim.state.time,
                    dir.display()
                );
            }
        };
        let msg = format!(
            "t = {:.2} us, Newton {}, KSP {}, {}",
            report.time * 1e6,
            report.solve.iterations,
            report.solve.linear_iterations,
            report.solve.reason_name
        );
        if flags.quiet && root {
            eprintln!("step {}: {msg}, {:.2} s", report.step, report.wall_total);
        }
        bar.set_message(msg);
        bar.inc(1);
        out.record(report)?;
        let every = cfg.run.output_every;
        // Every process stops after the same step (a signal may reach them at different steps).
        let stop = session.any(interrupted.load(std::sync::atomic::Ordering::SeqCst));
        if (every > 0 && sim.state.step % every == 0) || sim.state.step == cfg.run.steps || stop {
            save_state(session, &mut out, &sim, &dir, &identity)?;
            // run.json follows the checkpoint, so a run killed outright shows how far it got.
            record.steps_done = sim.state.step;
            record.time_reached = sim.state.time;
            if root {
                record.write(&dir)?;
            }
        }
        if stop && sim.state.step < cfg.run.steps {
            bar.abandon();
            finish(
                &mut record,
                &out,
                &sim,
                "interrupted",
                Some(format!("interrupted after step {}", sim.state.step)),
            )?;
            anyhow::bail!(
                "interrupted after step {}; the state is saved in {}: continue with {hint}",
                sim.state.step,
                dir.display()
            );
        }
        if sim.state.step >= cfg.run.steps {
            break;
        }
        step = sim.advance(session);
    }
    bar.finish();
    let note = finish(&mut record, &out, &sim, "finished", None)?;
    if !root {
        return Ok(());
    }
    summary(&out, started.elapsed().as_secs_f64(), note.as_deref());
    if let Some(n) = note {
        eprintln!("warning: {n}");
    }
    let unused_fallback: Vec<String> = petsc::unused_options(session)?
        .into_iter()
        .filter(|o| o.starts_with(&format!("-{FALLBACK_PREFIX}")) && !defaults.contains(o))
        .collect();
    if !unused_fallback.is_empty() {
        eprintln!(
            "note: {} never used: the fallback solver did not run, or the option is misspelled",
            unused_fallback.join(" ")
        );
    }
    Ok(())
}

/// Final table: steps, time reached, iterations, times, memory, reactions; `note` says that the run ended
/// before its requested end time.
fn summary(out: &RunOutput, wall: f64, note: Option<&str>) {
    let rows = out.rows();
    let newton: usize = rows.iter().map(|r| r.solve.iterations).sum();
    let linear: usize = rows.iter().map(|r| r.solve.linear_iterations).sum();
    let retries: usize = rows.iter().map(|r| r.attempts - 1).sum();
    let assembly: f64 = rows.iter().map(|r| r.wall_assembly).sum();
    let solve: f64 = rows.iter().map(|r| r.wall_solve - r.wall_assembly).sum();
    let setup: f64 = rows.iter().map(|r| r.wall_setup).sum();
    let peak = peak_rss_mb();
    println!("\n| quantity | value |\n|---|---|");
    println!(
        "| steps | {} ({} retried with the fallback solver or a smaller dt) |",
        rows.len(),
        retries
    );
    let time = rows.last().map_or(0.0, |r| r.time);
    match note {
        Some(n) => println!("| time reached | **{:.4} us**: {n} |", time * 1e6),
        None => println!(
            "| time reached | {:.4} us, the requested end time |",
            time * 1e6
        ),
    }
    println!(
        "| Newton iterations | {newton} ({:.2} per step) |",
        newton as f64 / rows.len().max(1) as f64
    );
    println!("| linear iterations | {linear} |");
    let contact: usize = rows.iter().map(|r| r.contact_solves).sum();
    if contact > rows.len() {
        println!(
            "| contact solves | {contact} ({:.2} per step: SNES solves while the contact active sets and \
             pin rotations settled) |",
            contact as f64 / rows.len().max(1) as f64
        );
    }
    let ghosts: usize = rows.iter().map(|r| r.ghosts).sum();
    if ghosts > 0 {
        let migrated: usize = rows.iter().map(|r| r.migrated).sum();
        println!(
            "| points between processes | {migrated} moved to another process; {:.0} ghost copies per step |",
            ghosts as f64 / rows.len().max(1) as f64
        );
    }
    // The steps' times cover the whole run, also the part before a resume; `wall` is this process's.
    let steps_wall: f64 = rows.iter().map(|r| r.wall_total).sum();
    println!(
        "| wall time | {steps_wall:.1} s in the steps (set-up {setup:.1} s, assembly {assembly:.1} s, PETSc solve \
         {solve:.1} s); {wall:.1} s in this process |"
    );
    println!("| peak memory | {peak:.0} MB |");
    if let Some(last) = rows.last() {
        for (name, f) in &last.reactions {
            let components: Vec<String> = f.iter().map(|v| format!("{v:.4e}")).collect();
            // A 3D run's reactions are of the whole plate, a 2D run's per mm of thickness.
            let units = if f.len() == 3 { "N" } else { "N/mm" };
            println!(
                "| final reaction `{name}` | ({}) {units} |",
                components.join(", ")
            );
        }
    }
    if let Some(c) = out.cracks().last() {
        let angles: Vec<String> = c
            .bands
            .iter()
            .map(|b| format!("{:.0} deg", b.angle_degrees))
            .collect();
        println!(
            "| crack | {} (length {:.1} mm, bands at {}; criteria in crack.json) |",
            c.classification,
            c.length,
            if angles.is_empty() {
                "-".to_owned()
            } else {
                angles.join(", ")
            }
        );
    }
    println!("| output | {} |", out.dir().display());
}

/// Peak resident set size of this process (MB), from /proc.
fn peak_rss_mb() -> f64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines().find(|l| l.starts_with("VmHWM:")).and_then(|l| {
                l.split_whitespace()
                    .nth(1)
                    .and_then(|v| v.parse::<f64>().ok())
            })
        })
        .map_or(f64::NAN, |kb| kb / 1024.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn petsc_options_start_at_the_first_single_dash_word() {
        let args: Vec<String> = [
            "prog",
            "smoke",
            "--n",
            "4",
            "-snes_monitor",
            "-ksp_type",
            "gmres",
        ]
        .iter()
        .map(|s| s.to_string())
        .collect();
        let (own, petsc) = split_args(args);
        assert_eq!(own, ["prog", "smoke", "--n", "4"]);
        assert_eq!(petsc, ["prog", "-snes_monitor", "-ksp_type", "gmres"]);
    }

    fn words(s: &[&str]) -> Vec<String> {
        s.iter().map(|w| w.to_string()).collect()
    }

    #[test]
    fn a_program_option_after_the_petsc_options_is_reported() {
        let (_, petsc) = split_args(words(&[
            "prog",
            "run",
            "c.toml",
            "-snes_monitor",
            "--steps",
            "20",
        ]));
        let e = misplaced_program_option(&petsc).expect("misplaced");
        assert!(
            e.contains("`--steps`") && e.contains("`-snes_monitor`"),
            "{e}"
        );
        let (_, petsc) = split_args(words(&[
            "prog",
            "run",
            "c.toml",
            "--steps",
            "2",
            "-ksp_rtol",
            "-1",
        ]));
        assert_eq!(misplaced_program_option(&petsc), None);
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

    #[test]
    fn the_time_note_tells_an_early_end_and_reduced_steps() {
        let full = [1e-6; 4];
        assert_eq!(time_note(&full, 4e-6, 4, 1e-6), None);
        let halved = [1e-6, 0.5e-6, 0.25e-6, 0.5e-6];
        let note = time_note(&halved, 2.25e-6, 4, 1e-6).expect("note");
        assert!(
            note.contains("t = 2.2500 us, before its requested end time 4.0000 us")
                && note.contains("3 of 4 steps took a reduced time step (down to 0.2500 us)"),
            "{note}"
        );
        assert!(time_note(&full[..2], 2e-6, 4, 1e-6).is_some());
    }
}
