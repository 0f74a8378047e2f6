//! `run --processes N`: the program starts itself on N processes under the MPI launcher, so that a user
//! need not know `mpirun` (issue 46: both cores, or a workstation's many, in every phase, the solve
//! included). The processes run the same command line, `--processes N` included, and check that the
//! launcher gave them N.

use crate::solver_defaults::StepClass;
use std::ffi::OsString;
use std::os::unix::process::CommandExt;
use std::process::Command;

/// The environment variable that names another launcher than `mpirun` (e.g. `mpiexec`, `srun`).
pub const LAUNCHER_VARIABLE: &str = "MPIEXEC";

/// Environment variables that an MPI launcher sets in the processes it starts (Open MPI, MPICH/Hydra and
/// Intel MPI, PMIx, Slurm's `srun` job steps).
const UNDER_A_LAUNCHER: [&str; 4] = [
    "OMPI_COMM_WORLD_SIZE",
    "PMI_SIZE",
    "PMIX_RANK",
    "SLURM_STEP_ID",
];

/// Whether this process was started by an MPI launcher.
pub fn under_a_launcher() -> bool {
    UNDER_A_LAUNCHER
        .iter()
        .any(|v| std::env::var_os(v).is_some())
}

/// The number of processes the launcher started, where it says (Open MPI, MPICH/Hydra and Intel MPI,
/// Slurm's job steps).
pub fn launched_processes() -> Option<usize> {
    ["OMPI_COMM_WORLD_SIZE", "PMI_SIZE", "SLURM_STEP_NUM_TASKS"]
        .iter()
        .find_map(|v| std::env::var(v).ok()?.trim().parse().ok())
}

/// What `run --processes N` does in this process: `Ok(true)` start the launcher (not under one yet, N >
/// 1), `Ok(false)` run here (N = 1, or under a launcher that started N processes), `Err` a launcher that
/// started another number.
pub fn needs_launcher(processes: usize) -> Result<bool, String> {
    if !under_a_launcher() {
        return Ok(processes > 1);
    }
    match launched_processes() {
        Some(n) if n != processes => Err(format!(
            "--processes {processes}: the launcher started {n} processes; give the same number to \
             both, or only --processes (which starts the launcher itself)"
        )),
        _ => Ok(false),
    }
}

/// Points per process below which a plain `run` does not start a second process: the elastic
/// cantilever's 10 steps at 10,240 points took the same time on 2 processes as on one with threads, at
/// 40,960 points 0.75x (`docs/benchmarks.md`, "Both cores in the solve by default").
pub const POINTS_PER_PROCESS: f64 = 10_000.0;

/// What a plain `run` (no `--processes`, not under a launcher) knows when it chooses between threads and
/// processes: the class of its steps, the points and memory its plan needs, the memory available, the
/// cores.
#[derive(Debug, Clone, Copy)]
pub struct Machine {
    /// The class of the run's steps (`solver_defaults::StepClass::of` the plan's inertia ratio).
    pub class: StepClass,
    /// The material points the plan seeds.
    pub points: f64,
    /// The memory one process of the run needs (bytes).
    pub bytes: f64,
    /// The memory available (bytes), if known.
    pub available: Option<f64>,
    /// The cores this process may use.
    pub cores: usize,
}

/// How many processes a plain `run` starts itself on (issue 46 item 4: both cores busy in every phase,
/// the solve included, without the user knowing `mpirun`). Threads share the point loops, GMRES's
/// products and its ILU(0) (the inertia-dominated steps' solver), and there one process with threads is
/// the faster on two cores (the half-resolution CT at 4.3 m/s: two processes 1.16x slower). The
/// stiffness-dominated steps' multigrid and field split (BoomerAMG) are PETSc's, one core per process:
/// there processes are the faster (the half-resolution CT at 0.035 m/s 0.81x the time of threads, the
/// cantilever at 40,960 points 0.75x). So: one process per core for stiffness-dominated steps, at least
/// [`POINTS_PER_PROCESS`] points each, if their memory fits; one process otherwise (1 is "threads").
pub fn processes_for(m: Machine) -> usize {
    if !matches!(m.class, StepClass::StiffnessDominated { .. }) {
        return 1;
    }
    let by_points = (m.points / POINTS_PER_PROCESS).floor().max(1.0) as usize;
    let mut n = m.cores.min(by_points).max(1);
    if let Some(available) = m.available {
        while n > 1 && m.bytes * n as f64 > available {
            n -= 1;
        }
    }
    n
}

/// Whether the launcher (`$MPIEXEC` or `mpirun`) can be found: a path, or a name on `PATH`.
pub fn launcher_found() -> bool {
    let launcher = std::env::var_os(LAUNCHER_VARIABLE).unwrap_or_else(|| "mpirun".into());
    let path = std::path::Path::new(&launcher);
    if path.components().count() > 1 {
        return path.is_file();
    }
    std::env::var_os("PATH")
        .is_some_and(|dirs| std::env::split_paths(&dirs).any(|d| d.join(path).is_file()))
}

/// Seconds Open MPI's `mpirun` waits after Ctrl-C before it sends the processes SIGTERM, and again before
/// SIGKILL (its default 1 s): time for the processes to write the checkpoint of the last finished step,
/// which a large run may need more than a second for.
const SIGKILL_TIMEOUT: &str = "10";

/// The launcher's command for `processes` processes of this program with the same arguments `args`
/// (the program's and PETSc's, without the program's name): `$MPIEXEC` or `mpirun`, `-n N`, this
/// executable. For Open MPI the environment allows a run as root and more processes than cores (a
/// container's user is often root; oversubscription only slows a run that asks for it) and gives the
/// processes [`SIGKILL_TIMEOUT`] s after Ctrl-C to save the run.
pub fn command(processes: usize, args: &[OsString]) -> std::io::Result<Command> {
    let launcher = std::env::var_os(LAUNCHER_VARIABLE).unwrap_or_else(|| "mpirun".into());
    let mut cmd = Command::new(launcher);
    cmd.arg("-n")
        .arg(processes.to_string())
        .arg(std::env::current_exe()?)
        .args(args);
    for (name, value) in [
        ("OMPI_ALLOW_RUN_AS_ROOT", "1"),
        ("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1"),
        ("OMPI_MCA_rmaps_base_oversubscribe", "1"),
        ("OMPI_MCA_odls_base_sigkill_timeout", SIGKILL_TIMEOUT),
    ] {
        if std::env::var_os(name).is_none() {
            cmd.env(name, value);
        }
    }
    Ok(cmd)
}

/// Replaces this process by the launcher of `processes` processes of the same command line (Ctrl-C then
/// reaches the launcher, which passes it on, as under a plain `mpirun`). Returns only on failure, with a
/// line that says what to do.
pub fn relaunch(processes: usize) -> String {
    let args: Vec<OsString> = std::env::args_os().skip(1).collect();
    let error = match command(processes, &args) {
        Ok(mut cmd) => cmd.exec(),
        Err(e) => e,
    };
    let launcher = std::env::var(LAUNCHER_VARIABLE).unwrap_or_else(|_| "mpirun".into());
    format!(
        "{processes} processes: cannot start `{launcher}` ({error}): install Open MPI \
         (scripts/install-deps.sh) or name the launcher in {LAUNCHER_VARIABLE}"
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn machine(ratio: f64, points: f64, cores: usize) -> Machine {
        Machine {
            class: StepClass::of(Some(ratio)),
            points,
            bytes: 5e8,
            available: Some(8e9),
            cores,
        }
    }

    #[test]
    fn stiffness_dominated_steps_run_on_a_process_per_core_inertia_dominated_on_threads() {
        // The CT at 0.035 m/s (r = 0.0098) and at 4.3 m/s (r = 0.25), 155,600 points.
        assert_eq!(processes_for(machine(0.0098, 155_600.0, 2)), 2);
        assert_eq!(processes_for(machine(0.0098, 155_600.0, 64)), 15);
        assert_eq!(processes_for(machine(0.25, 155_600.0, 2)), 1);
        assert_eq!(processes_for(machine(0.0098, 155_600.0, 1)), 1);
        let quasi_static = Machine {
            class: StepClass::of(None),
            ..machine(0.0, 155_600.0, 2)
        };
        assert_eq!(processes_for(quasi_static), 1);
        // Too few points for two: the cantilever at 10,240 points.
        assert_eq!(processes_for(machine(1e-4, 10_240.0, 2)), 1);
        assert_eq!(processes_for(machine(1e-4, 40_960.0, 8)), 4);
    }

    #[test]
    fn no_more_processes_than_the_memory_holds() {
        let m = Machine {
            bytes: 3e9,
            ..machine(0.0098, 155_600.0, 8)
        };
        assert_eq!(processes_for(m), 2);
        let m = Machine {
            bytes: 9e9,
            ..machine(0.0098, 155_600.0, 8)
        };
        assert_eq!(processes_for(m), 1);
    }

    #[test]
    fn the_launcher_runs_this_program_with_the_same_arguments() {
        let args: Vec<OsString> = ["run", "c.toml", "--processes", "2", "-snes_monitor"]
            .iter()
            .map(OsString::from)
            .collect();
        let cmd = command(2, &args).expect("command");
        let words: Vec<String> = cmd
            .get_args()
            .map(|a| a.to_string_lossy().into_owned())
            .collect();
        assert_eq!(&words[..2], ["-n", "2"]);
        let exe = std::env::current_exe().expect("exe");
        assert_eq!(words[2], exe.to_string_lossy());
        assert_eq!(
            &words[3..],
            ["run", "c.toml", "--processes", "2", "-snes_monitor"]
        );
    }
}
