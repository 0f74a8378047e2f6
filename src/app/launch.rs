//! `run --processes N`: the program starts itself on N processes under the MPI launcher, so that a user
//! need not know `mpirun` (issue 46: both cores, or a workstation's many, in every phase, the solve
//! included). The processes run the same command line, `--processes N` included, and check that the
//! launcher gave them N.

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

/// The launcher's command for `processes` processes of this program with the same arguments `args`
/// (the program's and PETSc's, without the program's name): `$MPIEXEC` or `mpirun`, `-n N`, this
/// executable. For Open MPI the environment allows a run as root and more processes than cores (a
/// container's user is often root; oversubscription only slows a run that asks for it).
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
        "--processes {processes}: cannot start `{launcher}` ({error}): install Open MPI \
         (scripts/install-deps.sh) or name the launcher in {LAUNCHER_VARIABLE}"
    )
}

#[cfg(test)]
mod tests {
    use super::*;

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
