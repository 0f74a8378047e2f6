//! `mpm-concrete`: the command-line program.
//!
//! Program arguments come first (clap); everything from the first single-dash option on (`-snes_monitor`,
//! `-ksp_type gmres`, `-pc_type hypre`, `-log_view`, `-help`, ...) goes to PETSc's options database.
//!
//! Exit codes: 0 success; 1 a run or command that failed while working (a step that does not converge, a
//! file that cannot be written); 2 input rejected before any work (command line, configuration, PETSc
//! options, output directory, checkpoint, memory), with one line that says what and why.

use anyhow::Result;
use clap::{CommandFactory, Parser, Subcommand};
use mpm_concrete::app::args::{launcher_rank, misplaced_program_option, split_args};
use mpm_concrete::app::run::{self, RunFlags};
use mpm_concrete::app::{
    BadInput, FailedElsewhere, bad, commands, compare, error_line, fit_material, launch,
    material_driver, no_petsc_options, smoke,
};
use mpm_concrete::preflight;
use std::path::PathBuf;

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
    Run(RunFlags),
    /// Solver-comparison study: runs a configuration for a few steps with several PETSc option sets (each in
    /// its own process) and writes a table (Markdown, CSV) and charts. A failed set is reported in the
    /// table; if every set fails the study ends with each set's reason and exit code 1.
    Study {
        /// Configuration file.
        config: PathBuf,
        /// Steps per option set.
        #[arg(long, default_value_t = 10)]
        steps: usize,
        /// Option sets, one per line `name: [--set KEY=VALUE ...] [--steps N] [--allow-large] -petsc
        /// -options`, words split as a shell does (quote a value with spaces: --set run.name="CT a"), every
        /// line checked before the first run (default: MUMPS, SuperLU_dist, GMRES with ILU, BoomerAMG, GAMG,
        /// fieldsplit on (u, eta_bar), trust-region Newton).
        #[arg(long)]
        sets: Option<PathBuf>,
        /// Output directory (default runs/study-<config name>).
        #[arg(long)]
        output: Option<PathBuf>,
        /// Replace an earlier study in the output directory: its report and the runs in the sets'
        /// directories (each identified as a run of this program by its run.json; a directory holding
        /// other files is refused, never cleared). Without it a set directory holding a run is refused.
        #[arg(long)]
        overwrite: bool,
    },
    /// Performance benchmark: the paper-size CT, the elastic cantilever at 40,960 and 163,840 points and
    /// the CT demo (both CTs with the paper's constant c = 1 mm^2, the setting of the recorded timings),
    /// each for a fixed number of steps in its own process, plus the microplane update's
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
    Compare(compare::CompareArgs),
    /// Re-measure the crack metrics of a finished CT run from its snapshots with this version's criteria
    /// and rewrite its crack.json (prints the final state).
    Crack {
        /// Run directory (`config.toml`, `fields_*.h5`).
        run_dir: PathBuf,
    },
    /// Material-point driver: strain or mixed paths through one constitutive law (CSV + PNG); prints the
    /// implied uniaxial strengths. No PETSc involved.
    MaterialDriver(material_driver::DriverArgs),
    /// Fit microplane parameters to E, nu, f_t, G_F (optionally f_c) and a gradient length: f_t by the
    /// material driver, G_F by a quasi-static regularised bar; prints the [material] section and writes
    /// it with plots (docs/material.md, "Parameters from engineering data"). Takes no PETSc options (the
    /// bar is always solved by Newton with MUMPS LU).
    FitMaterial(fit_material::FitArgs),
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

/// How long a process other than process 0 waits before it ends on bad input, so that process 0's error
/// line is printed before the launcher stops the processes (s).
const REPORT_GRACE: std::time::Duration = std::time::Duration::from_secs(1);

/// How long a process other than process 0 waits before it ends on a failure that process 0 reports (a
/// failed step, an interruption): the launcher aborts the job as soon as one process ends with an error,
/// and process 0 prints its line (the resume command) only once it has left the run. Shorter than
/// `REPORT_GRACE`: after a Ctrl-C, Open MPI's mpirun kills the processes 1 s after their SIGTERM, and a
/// process that saved its checkpoint must end before that.
const FAILURE_GRACE: std::time::Duration = std::time::Duration::from_millis(200);

fn main() -> std::process::ExitCode {
    // Under mpirun every process takes the same decisions and meets the same warnings: process 0 logs and
    // warns, the others report only errors.
    let rank = launcher_rank();
    tracing_subscriber::fmt()
        .with_writer(std::io::stderr)
        .with_target(false)
        .without_time()
        .with_max_level(if rank == 0 {
            tracing::Level::INFO
        } else {
            tracing::Level::ERROR
        })
        .init();
    let (own, petsc_args) = split_args(std::env::args().collect());
    let cli = match Cli::try_parse_from(&own) {
        Ok(cli) => cli,
        Err(e) => return usage_error(e, &own),
    };
    if let Some(message) = misplaced_program_option(&petsc_args) {
        eprintln!("error: {message}");
        return std::process::ExitCode::from(2);
    }
    if let Command::Run(RunFlags {
        processes: Some(n), ..
    }) = &cli.command
    {
        match launch::needs_launcher(*n as usize) {
            Ok(false) => {}
            Ok(true) => {
                eprintln!("error: {}", launch::relaunch(*n as usize));
                return std::process::ExitCode::from(2);
            }
            Err(message) => {
                if rank == 0 {
                    eprintln!("error: {message}");
                }
                return std::process::ExitCode::from(2);
            }
        }
    }
    // A plain run whose solve is PETSc's on one core per process starts itself on a process per core
    // (`launch::processes_for`); `--processes N` or RAYON_NUM_THREADS chooses otherwise.
    if let Command::Run(
        flags @ RunFlags {
            processes: None, ..
        },
    ) = &cli.command
        && !launch::under_a_launcher()
        && let Some((n, ratio)) = run::automatic_processes(flags, &petsc_args[1..])
    {
        tracing::info!(
            "stiffness-dominated steps (r = {ratio:.2e}): their solver (multigrid or field split) is \
             PETSc's, one core per process, so this run starts itself on {n} processes (`--processes \
             1`: one process with threads)"
        );
        let failure = launch::relaunch(n);
        tracing::warn!("{failure}; this run goes on with one process and threads");
    }
    if let Command::Compare(args) = &cli.command {
        return std::process::ExitCode::from(compare::run_cli(args, &petsc_args[1..]));
    }
    // Under mpirun every process meets the same bad input and the same failed step: process 0 reports
    // them; the others report only what process 0 may not have met (errors other than bad input and
    // the failures process 0 reports, such as its failed writes or an interruption), naming themselves.
    match run(cli, &own, &petsc_args) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => match e.chain().find_map(|c| c.downcast_ref::<BadInput>()) {
            Some(b) => {
                if rank == 0 {
                    if !b.0.is_empty() {
                        eprintln!("error: {}", error_line(&e));
                    }
                } else {
                    // Process 0 reports bad input: the others give it time to print before the launcher,
                    // seeing one of them end, stops the rest.
                    std::thread::sleep(REPORT_GRACE);
                }
                std::process::ExitCode::from(2)
            }
            None => {
                let elsewhere = e.chain().any(|c| c.is::<FailedElsewhere>());
                match rank {
                    0 => eprintln!("error: {}", error_line(&e)),
                    _ if elsewhere => std::thread::sleep(FAILURE_GRACE),
                    r => eprintln!("error (process {r}): {}", error_line(&e)),
                }
                std::process::ExitCode::FAILURE
            }
        },
    }
}

/// A command-line usage error in two lines, the error (with clap's continuation lines, such as the
/// possible values or a tip, joined onto it) and where the help is, exit code 2; help and version requests
/// are printed as clap prints them.
fn usage_error(e: clap::Error, own: &[String]) -> std::process::ExitCode {
    use clap::error::ErrorKind;
    if matches!(
        e.kind(),
        ErrorKind::DisplayHelp
            | ErrorKind::DisplayVersion
            | ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand
    ) {
        e.exit();
    }
    let text = e.render().to_string();
    let mut lines = text.lines().map(str::trim);
    let mut message = lines.next().unwrap_or("error: bad command line").to_owned();
    for more in lines
        .filter(|l| !l.is_empty())
        .take_while(|l| !l.starts_with("Usage:") && !l.starts_with("For more information"))
    {
        message = format!("{message} {more}");
    }
    let cli = Cli::command();
    let sub = own
        .iter()
        .skip(1)
        .find(|a| cli.get_subcommands().any(|c| c.get_name() == a.as_str()));
    let program = cli.get_name().to_owned();
    eprintln!("{message}");
    match sub {
        Some(sub) => eprintln!("For more information, try '{program} {sub} --help'."),
        None => eprintln!("For more information, try '{program} --help'."),
    }
    std::process::ExitCode::from(2)
}

/// Runs the command `cli` names; `own_args` are the program's arguments, `petsc_args` PETSc's (starting with
/// the program name).
fn run(cli: Cli, own_args: &[String], petsc_args: &[String]) -> Result<()> {
    // PETSc reads the options files of its arguments and of PETSC_OPTIONS when it starts: each is checked
    // first (a FIFO would block PETSc's start, /dev/zero exhaust the memory).
    preflight::check_options_files(petsc_args[1..].iter().map(String::as_str))
        .map_err(|e| bad(format!("command line: {e}")))?;
    if let Ok(env) = std::env::var("PETSC_OPTIONS") {
        preflight::check_options_files(env.split_whitespace())
            .map_err(|e| bad(format!("environment variable PETSC_OPTIONS: {e}")))?;
    }
    match cli.command {
        Command::Crack { run_dir } => commands::crack(&run_dir, petsc_args),
        Command::MaterialDriver(args) => {
            no_petsc_options("material-driver", "", petsc_args)?;
            let summary = material_driver::run_driver(&args)
                .map_err(|e| if e.is_bad_input() { bad(e) } else { e.into() })?;
            println!("{summary}");
            Ok(())
        }
        Command::FitMaterial(args) => fit_material::run(&args, petsc_args),
        Command::Bench {
            cases,
            steps,
            output,
        } => commands::bench(&cases, steps, &output, petsc_args),
        Command::Study {
            config,
            steps,
            sets,
            output,
            overwrite,
        } => commands::study(
            &config,
            steps,
            sets.as_deref(),
            output,
            overwrite,
            petsc_args,
        ),
        // handled in main, without PETSc
        Command::Compare(_) => Ok(()),
        Command::Run(flags) => run::run(own_args, petsc_args, flags),
        Command::Smoke {
            n,
            load,
            print_solution,
        } => smoke::command(petsc_args, n, load, print_solution),
    }
}
