//! Linear solves with the KSP of a SNES outside `SNESSolve`: the same solver and preconditioner the
//! options configured for the Newton solve, for a Newton loop run in Rust (the bordered Newton of path
//! following, `solver::path`).

use super::{Matrix, Result, Snes, Vector, check, sys};
use std::ffi::c_char;

/// The outcome of one linear solve.
#[derive(Debug, Clone, PartialEq)]
pub struct LinearSolve {
    /// Iterations of the Krylov method (1 for a direct solve).
    pub iterations: usize,
    /// PETSc's `KSPConvergedReason` code (> 0 converged, < 0 diverged).
    pub reason: i32,
    /// The reason as PETSc names it, e.g. `DIVERGED_PC_FAILED`.
    pub reason_name: String,
}

impl LinearSolve {
    /// True if the KSP reports convergence.
    pub fn converged(&self) -> bool {
        self.reason > 0
    }
}

impl Snes {
    /// Solves `jac x = rhs` with this SNES's KSP (its options, preconditioner and prefix), `jac` as the
    /// operator and the preconditioning matrix. The preconditioner is rebuilt when `jac` changed since
    /// the last solve (PETSc tracks the matrix's state), so solves with several right-hand sides and one
    /// matrix factorise it once. A solve that does not converge is `Ok` with
    /// [`LinearSolve::converged`] false.
    pub fn linear_solve(
        &mut self,
        jac: &Matrix,
        rhs: &Vector,
        x: &mut Vector,
    ) -> Result<LinearSolve> {
        let ksp = self.ksp()?;
        let (mut its, mut reason) = (0, 0);
        let mut name: *const c_char = std::ptr::null();
        // SAFETY: valid KSP (borrowed from the SNES), matrix and vectors; out-parameters.
        unsafe {
            check(
                sys::KSPSetOperators(ksp, jac.raw, jac.raw),
                "KSPSetOperators",
            )?;
        }
        self.install_replacement(jac.raw, jac.raw)?;
        // SAFETY: as above.
        unsafe {
            check(sys::KSPSolve(ksp, rhs.raw, x.raw), "KSPSolve")?;
            check(
                sys::KSPGetIterationNumber(ksp, &mut its),
                "KSPGetIterationNumber",
            )?;
            check(
                sys::KSPGetConvergedReason(ksp, &mut reason),
                "KSPGetConvergedReason",
            )?;
            check(
                sys::KSPGetConvergedReasonString(ksp, &mut name),
                "KSPGetConvergedReasonString",
            )?;
        }
        // SAFETY: null or a static string owned by PETSc.
        let reason_name = unsafe { super::reason_name(name, reason) };
        Ok(LinearSolve {
            iterations: its.max(0) as usize,
            reason,
            reason_name,
        })
    }
}
