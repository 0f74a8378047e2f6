//! The applications built on the library, one module per command of `mpm-concrete`: the simulation run
//! (`run`), cross-checks against reference solutions (`compare`), solver-comparison studies (`study`), the
//! benchmark command (`bench`), the crack re-measurement and the drivers of the other commands
//! (`commands`), the material-point driver (`material_driver`), the fit of microplane parameters to engineering
//! data (`fit_material`) and the PETSc lattice smoke problem
//! (`smoke`). The library below them (material, solver, io, ...) imports none of them; the command-line
//! parser (main.rs) only parses and calls them.

pub mod args;
pub mod bench;
pub mod commands;
pub mod compare;
pub mod fit_material;
pub mod launch;
pub mod material_driver;
pub mod run;
pub mod smoke;
pub mod study;

use crate::petsc::SessionGuard;

/// Input rejected before any work (exit code 2). An empty message means that another MPI rank reports it.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct BadInput(pub String);

/// A failure of another process, which reports it (e.g. process 0's failed write, or the interruption
/// that process 0 reports): the other processes end with exit code 1 without repeating it.
#[derive(Debug, thiserror::Error)]
#[error("another process failed (it reports why)")]
pub struct FailedElsewhere;

/// The one line that reports `e`: its message and its causes, each cause left out whose text the line
/// already holds (many errors name their cause in their own message, e.g. `f: File too large`).
pub fn error_line(e: &anyhow::Error) -> String {
    let mut line = String::new();
    for cause in e.chain() {
        let text = cause.to_string();
        if line.is_empty() {
            line = text;
        } else if !line.contains(&text) {
            line = format!("{line}: {text}");
        }
    }
    line
}

/// A [`BadInput`] error.
pub fn bad(message: impl std::fmt::Display) -> anyhow::Error {
    BadInput(message.to_string()).into()
}

/// Commands without PETSc accept no PETSc options (they would be silently ignored); `petsc_args` starts
/// with the program name.
pub fn no_petsc_options(command: &str, hint: &str, petsc_args: &[String]) -> anyhow::Result<()> {
    if petsc_args.len() > 1 {
        return Err(bad(format!(
            "{command} takes no PETSc options (got `{}`){hint}",
            petsc_args[1..].join(" ")
        )));
    }
    Ok(())
}

/// Processes of this run on this node, as the launcher says (Open MPI, MPICH, Slurm); None outside one.
pub fn processes_per_node() -> Option<usize> {
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
pub fn share_cores(session: &SessionGuard) {
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_error_line_names_each_cause_once() {
        let io = std::io::Error::from_raw_os_error(27);
        let output = crate::io::OutputError::Io {
            path: "d/fields.xdmf".into(),
            source: io,
        };
        let e = anyhow::Error::from(output).context("writing the output");
        assert_eq!(
            error_line(&e),
            "writing the output: d/fields.xdmf: File too large (os error 27)"
        );
    }
}
