//! The PETSc layer end to end on the lattice problem of `mpm_concrete::smoke`: several SNES/KSP/PC
//! combinations chosen through the options database reach the same solution with quadratic Newton
//! convergence; the assembled Jacobian matches finite differences; bad options give clear errors.

use mpm_concrete::petsc::{self, Session};
use mpm_concrete::smoke::{self, SmokeParams};

/// Sets `options` under `prefix` and solves; returns the result.
fn solve_with(prefix: &str, options: &str) -> smoke::SmokeResult {
    let s = Session::get().expect("PETSc session");
    let prefixed: String = options
        .split_whitespace()
        .map(|t| match t.strip_prefix('-') {
            Some(name) => format!("-{prefix}{name}"),
            None => t.to_owned(),
        })
        .collect::<Vec<_>>()
        .join(" ");
    petsc::apply_default_options(&s, &prefixed).expect("options");
    smoke::solve(&s, params(), Some(prefix)).unwrap_or_else(|e| panic!("{prefix}: {e}"))
}

fn params() -> SmokeParams {
    SmokeParams {
        n: 10,
        load: 0.001,
        ..SmokeParams::default()
    }
}

/// Newton converges quadratically: once the residual is below 1e-2 of the initial one, each iterate
/// squares it up to a modest constant (r_{k+1}/r0 <= 50 (r_k/r0)^2) — a linearly converging method with
/// rate 0.1 fails this at the last iterations.
fn assert_quadratic(name: &str, norms: &[f64]) {
    assert!(
        norms.len() >= 3,
        "{name}: too few iterations to judge: {norms:?}"
    );
    let r0 = norms[0];
    let e: Vec<f64> = norms.iter().map(|r| r / r0).collect();
    for w in e.windows(2) {
        if w[0] < 1e-2 && w[1] > 1e-13 {
            assert!(w[1] <= 50.0 * w[0] * w[0], "{name}: not quadratic: {e:?}");
        }
    }
    assert!(
        e.last().copied().unwrap_or(1.0) < 1e-10,
        "{name}: did not converge: {e:?}"
    );
}

const COMMON: &str = "-snes_rtol 1e-14 -snes_atol 1e-13 -snes_stol 0 -snes_max_it 30";

#[test]
fn solvers_agree_and_converge_quadratically() {
    let cases = [
        ("lu_", "-ksp_type preonly -pc_type lu"),
        (
            "mumps_",
            "-ksp_type preonly -pc_type lu -pc_factor_mat_solver_type mumps",
        ),
        (
            "hypre_",
            "-ksp_type gmres -ksp_rtol 1e-12 -ksp_max_it 500 -pc_type hypre -pc_hypre_type boomeramg",
        ),
        (
            "ilu_",
            "-ksp_type gmres -ksp_rtol 1e-12 -ksp_max_it 500 -pc_type bjacobi -sub_pc_type ilu",
        ),
    ];
    let mut reference: Option<Vec<f64>> = None;
    for (prefix, opts) in cases {
        let r = solve_with(prefix, &format!("{COMMON} {opts}"));
        assert!(
            r.info.converged(),
            "{prefix}: {} after {} its: {:?}",
            r.info.reason_name,
            r.info.iterations,
            r.info.residual_norms
        );
        assert_quadratic(prefix, &r.info.residual_norms);
        let max = r.solution.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        assert!(max > 1e-2, "{prefix}: trivial solution");
        match &reference {
            None => reference = Some(r.solution),
            Some(x) => {
                let diff = x
                    .iter()
                    .zip(&r.solution)
                    .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
                assert!(diff < 1e-9 * max, "{prefix}: differs from LU by {diff:e}");
            }
        }
        assert!(
            r.solver
                .contains(opts.split_whitespace().nth(1).unwrap_or("")),
            "{}",
            r.solver
        );
    }
}

#[test]
fn jacobian_matches_finite_differences() {
    let s = Session::get().expect("PETSc session");
    let p = SmokeParams { n: 4, ..params() };
    let n = 3 * p.n * p.n;
    // A non-trivial state: deformed lattice, non-zero phi.
    let x0: Vec<f64> = (0..n)
        .map(|i| 0.05 * ((i as f64) * 0.7).sin() + 0.01 * (i % 3) as f64)
        .collect();
    let err = smoke::jacobian_fd_error(&s, p, &x0).expect("fd check");
    assert!(err < 1e-7, "relative Jacobian error {err:e}");
}

#[test]
fn unknown_preconditioner_is_a_clear_error() {
    let s = Session::get().expect("PETSc session");
    petsc::set_option(&s, "bad_pc_type", Some("nonsense")).expect("option");
    let err = smoke::solve(&s, params(), Some("bad_"))
        .err()
        .expect("must fail");
    let msg = err.to_string();
    assert!(
        msg.contains("nonsense"),
        "message does not name the bad value: {msg}"
    );
}

#[test]
fn options_set_in_code_yield_to_the_command_line() {
    let s = Session::get().expect("PETSc session");
    petsc::set_option(&s, "cli_ksp_type", Some("cg")).expect("option");
    petsc::set_default_option(&s, "cli_ksp_type", Some("gmres")).expect("default");
    assert_eq!(
        petsc::option_string(&s, "cli_ksp_type")
            .expect("get")
            .as_deref(),
        Some("cg")
    );
}
