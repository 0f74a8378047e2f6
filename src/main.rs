//! `mpm-concrete`: the command-line program.
//!
//! Program arguments come first (clap); everything from the first single-dash option on (`-snes_monitor`,
//! `-ksp_type gmres`, `-pc_type hypre`, `-log_view`, `-help`, ...) goes to PETSc's options database.

use anyhow::{Context, Result};
use clap::{Parser, Subcommand};
use mpm_concrete::checkpoint;
use mpm_concrete::config::RunConfig;
use mpm_concrete::io::RunOutput;
use mpm_concrete::petsc::{self, Session, SessionGuard};
use mpm_concrete::scenario;
use mpm_concrete::smoke::{self, SmokeParams};
use mpm_concrete::solver::Simulation;
use mpm_concrete::solver_defaults;
use mpm_concrete::study;
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
        /// Continue from the checkpoint in the output directory (written at every output step and on Ctrl-C).
        #[arg(long)]
        resume: bool,
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
    Compare(mpm_concrete::compare::CompareArgs),
    /// Material-point driver: strain or mixed paths through one constitutive law (CSV + PNG); prints the
    /// implied uniaxial strengths. No PETSc involved.
    MaterialDriver(mpm_concrete::material::driver::DriverArgs),
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

fn main() -> std::process::ExitCode {
    tracing_subscriber::fmt()
        .with_writer(std::io::stderr)
        .with_target(false)
        .without_time()
        .init();
    let (own, petsc_args) = split_args(std::env::args().collect());
    let cli = Cli::parse_from(own);
    if let Command::Compare(args) = &cli.command {
        return std::process::ExitCode::from(mpm_concrete::compare::run_cli(
            args,
            &petsc_args[1..],
        ));
    }
    match run(cli, &petsc_args) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}

fn run(cli: Cli, petsc_args: &[String]) -> Result<()> {
    let command = match cli.command {
        Command::MaterialDriver(args) => {
            let summary = mpm_concrete::material::driver::run_driver(&args)?;
            println!("{summary}");
            return Ok(());
        }
        Command::Bench {
            cases,
            steps,
            output,
        } => {
            let mut all = mpm_concrete::bench::default_cases();
            if !cases.is_empty() {
                let names: Vec<String> = all.iter().map(|c| c.name.clone()).collect();
                if let Some(bad) = cases.iter().find(|c| !names.contains(c)) {
                    anyhow::bail!(
                        "--cases: unknown case `{bad}` (allowed: {})",
                        names.join(", ")
                    );
                }
                all.retain(|c| cases.contains(&c.name));
            }
            if let Some(n) = steps {
                anyhow::ensure!(n > 0, "--steps must be at least 1");
                all.iter_mut().for_each(|c| c.steps = n);
            }
            if let Some(c) = all.iter().find(|c| !c.config.is_file()) {
                anyhow::bail!(
                    "bench: {} not found (the cases' configs are relative to the repository root: run \
                     the command there)",
                    c.config.display()
                );
            }
            let exe = std::env::current_exe().context("locating the mpm-concrete executable")?;
            let report = mpm_concrete::bench::run(&exe, &all, &petsc_args[1..].join(" "), &output)
                .map_err(anyhow::Error::msg)?;
            println!("{}", mpm_concrete::bench::markdown(&report));
            println!("results in {}", output.display());
            return Ok(());
        }
        Command::Study {
            config,
            steps,
            sets,
            output,
        } => {
            anyhow::ensure!(steps > 0, "--steps must be at least 1");
            RunConfig::from_file(&config)?;
            let sets = match sets {
                Some(p) => study::read_sets(&p).map_err(anyhow::Error::msg)?,
                None => study::default_sets(),
            };
            let dir = output.unwrap_or_else(|| study::default_dir(&config));
            let exe = std::env::current_exe().context("locating the mpm-concrete executable")?;
            let results =
                study::run(&exe, &config, steps, &sets, &dir).map_err(anyhow::Error::msg)?;
            let failed = results.iter().filter(|r| !r.completed).count();
            println!("{}", std::fs::read_to_string(dir.join("study.md"))?);
            println!(
                "{} of {} option sets completed; results in {}",
                results.len() - failed,
                results.len(),
                dir.display()
            );
            return Ok(());
        }
        other => other,
    };
    let session = Session::initialize(petsc_args).context("starting PETSc")?;
    match command {
        Command::Run {
            config,
            steps,
            output,
            quiet,
            resume,
            set,
        } => run_simulation(
            &session,
            &config,
            RunFlags {
                steps,
                output,
                quiet,
                resume,
                set,
            },
        )?,
        // handled above, without PETSc
        Command::MaterialDriver(_)
        | Command::Study { .. }
        | Command::Bench { .. }
        | Command::Compare(_) => {}
        Command::Smoke {
            n,
            load,
            print_solution,
        } => {
            if n < 2 {
                anyhow::bail!("--n must be at least 2 (got {n})");
            }
            petsc::apply_default_options(&session, "-ksp_type preonly -pc_type lu")?;
            let p = SmokeParams {
                n,
                load,
                ..SmokeParams::default()
            };
            let r = smoke::solve(&session, p, None).context("solving the lattice problem")?;
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
            let unused = petsc::unused_options(&session)?;
            if !unused.is_empty() {
                anyhow::bail!(
                    "unknown or unused PETSc option(s): {} (check the spelling; -help lists the options)",
                    unused.join(" ")
                );
            }
            if !r.info.converged() {
                anyhow::bail!(
                    "the lattice problem did not converge: {}",
                    r.info.reason_name
                );
            }
        }
    }
    Session::finalize(session)?;
    Ok(())
}

/// Command-line flags of `run`.
struct RunFlags {
    steps: Option<usize>,
    output: Option<PathBuf>,
    quiet: bool,
    resume: bool,
    set: Vec<String>,
}

fn run_simulation(session: &SessionGuard, path: &std::path::Path, flags: RunFlags) -> Result<()> {
    let RunFlags {
        steps,
        output,
        quiet,
        resume,
        set,
    } = flags;
    let mut cfg = RunConfig::from_file_with(path, &set)?;
    if let Some(n) = steps {
        anyhow::ensure!(n > 0, "--steps must be at least 1");
        cfg.run.steps = n;
    }
    petsc::apply_default_options(session, &cfg.run.petsc_options)
        .with_context(|| format!("{}: run.petsc_options", path.display()))?;
    let mut setup =
        scenario::build(&cfg).with_context(|| format!("{}: building the model", path.display()))?;
    // The solver defaults follow the kind of step (docs/solvers.md).
    let (_, defaults) = solver_defaults::apply(session, &setup)?;
    setup.fallback_prefix = Some("fallback_".into());
    let mut sim = Simulation::new(setup)?;
    let dir = output.unwrap_or_else(|| cfg.output_dir());
    let text = std::fs::read_to_string(path)?;
    let mut out = RunOutput::create(&dir, &cfg.run.name, &text, &sim)?;
    if let Some(ct) = &cfg.ct {
        out.track_crack(
            nalgebra::Vector2::new(ct.notch_length, 0.5 * ct.height),
            Default::default(),
        );
    }
    if resume {
        checkpoint::load(&dir, &mut sim, &mut out)
            .with_context(|| format!("resuming from {}", dir.join(checkpoint::FILE).display()))?;
        eprintln!("resumed at step {} (t = {:e} s)", sim.step, sim.time);
    }
    // Ctrl-C: finish the current step, write a checkpoint and the outputs, and stop.
    let interrupted = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    {
        let flag = interrupted.clone();
        ctrlc::set_handler(move || flag.store(true, std::sync::atomic::Ordering::SeqCst))
            .context("installing the Ctrl-C handler")?;
    }
    let np = sim.setup.particles.len();
    let grid = &sim.setup.grid;
    eprintln!(
        "{}: {np} material points, grid {}x{} cells of {} mm, {} steps of {:e} s, {} unknowns per node, output in {}",
        cfg.run.name,
        grid.nx(),
        grid.ny(),
        grid.cell_size(),
        cfg.run.steps,
        cfg.time.dt,
        sim.fields(),
        dir.display()
    );
    let bar = if quiet {
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
    let started = std::time::Instant::now();
    let mut unused_checked = false;
    // A PETSc logging stage for the time loop, so -log_view separates it from the set-up.
    let _stage = session.push_stage(session.register_stage("MPM time steps")?)?;
    bar.set_position(sim.step as u64);
    if !resume {
        out.snapshot(&sim)?;
    }
    while sim.step < cfg.run.steps {
        let report = match sim.advance(session) {
            Ok(r) => r,
            Err(e) => {
                bar.abandon();
                out.snapshot(&sim)?;
                out.force_plots()?;
                return Err(anyhow::Error::new(e).context(format!(
                    "run stopped; the last converged state (step {}) is saved in {}",
                    sim.step,
                    dir.display()
                )));
            }
        };
        if !unused_checked {
            let mut unused = petsc::unused_options(session)?;
            unused.retain(|o| !defaults.contains(o));
            anyhow::ensure!(
                unused.is_empty(),
                "unknown or unused PETSc option(s): {} (check the spelling; -help lists the options)",
                unused.join(" ")
            );
            unused_checked = true;
        }
        let msg = format!(
            "t = {:.2} us, Newton {}, KSP {}, {}",
            report.time * 1e6,
            report.solve.iterations,
            report.solve.linear_iterations,
            report.solve.reason_name
        );
        if quiet {
            eprintln!("step {}: {msg}, {:.2} s", report.step, report.wall_total);
        }
        bar.set_message(msg);
        bar.inc(1);
        out.record(report)?;
        let every = cfg.run.output_every;
        let stop = interrupted.load(std::sync::atomic::Ordering::SeqCst);
        if (every > 0 && sim.step % every == 0) || sim.step == cfg.run.steps || stop {
            out.snapshot(&sim)?;
            out.force_plots()?;
            checkpoint::save(&dir, &sim, &out)?;
        }
        if stop {
            bar.abandon();
            anyhow::bail!(
                "interrupted after step {}; the state is saved in {}: continue with `mpm-concrete run {} --resume`",
                sim.step,
                dir.display(),
                path.display()
            );
        }
    }
    bar.finish();
    summary(&out, started.elapsed().as_secs_f64());
    Ok(())
}

/// Final table: steps, iterations, times, memory, reactions.
fn summary(out: &RunOutput, wall: f64) {
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
    println!(
        "| Newton iterations | {newton} ({:.2} per step) |",
        newton as f64 / rows.len().max(1) as f64
    );
    println!("| linear iterations | {linear} |");
    println!(
        "| wall time | {wall:.1} s (set-up {setup:.1} s, assembly {assembly:.1} s, PETSc solve {solve:.1} s) |"
    );
    println!("| peak memory | {peak:.0} MB |");
    if let Some(last) = rows.last() {
        for (name, f) in &last.reactions {
            println!(
                "| final reaction `{name}` | ({:.4e}, {:.4e}) N/mm |",
                f[0], f[1]
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
    use super::split_args;

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
}
