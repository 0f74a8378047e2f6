//! `mpm-concrete`: the command-line program.
//!
//! Program arguments come first (clap); everything from the first single-dash option on (`-snes_monitor`,
//! `-ksp_type gmres`, `-pc_type hypre`, `-log_view`, `-help`, ...) goes to PETSc's options database.

use anyhow::{Context, Result};
use clap::{Parser, Subcommand};
use mpm_concrete::petsc::{self, Session};
use mpm_concrete::smoke::{self, SmokeParams};

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
    let (own, petsc_args) = split_args(std::env::args().collect());
    let cli = Cli::parse_from(own);
    match run(cli, &petsc_args) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}

fn run(cli: Cli, petsc_args: &[String]) -> Result<()> {
    let session = Session::initialize(petsc_args).context("starting PETSc")?;
    match cli.command {
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
