//! The process's arguments: the program's (clap) and PETSc's, which begin at the first single-dash option
//! (`-snes_monitor`, `-ksp_type gmres`, ...), and the process's rank as the MPI launcher tells it.

/// Splits the process arguments into the program's and PETSc's (from the first `-word` option on).
pub fn split_args(args: Vec<String>) -> (Vec<String>, Vec<String>) {
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
pub fn misplaced_program_option(petsc_args: &[String]) -> Option<String> {
    let first = petsc_args.get(1)?;
    let misplaced = petsc_args[1..]
        .iter()
        .find(|a| a.len() > 2 && a.starts_with("--"))?;
    Some(format!(
        "`{misplaced}` comes after the PETSc option `{first}`: the program's arguments (--steps, --output, \
         --set, ...) go before the first PETSc option"
    ))
}

/// This process's rank as the MPI launcher says (Open MPI, MPICH, Slurm); 0 outside a launcher.
pub fn launcher_rank() -> usize {
    ["OMPI_COMM_WORLD_RANK", "PMI_RANK", "SLURM_PROCID"]
        .iter()
        .find_map(|v| std::env::var(v).ok()?.trim().parse().ok())
        .unwrap_or(0)
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
}
