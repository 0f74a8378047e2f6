//! The geometric multigrid's SOR smoother on all threads: on each level whose smoother is PETSc's
//! symmetric SOR (`-mg_levels_pc_type sor`, the default of stiffness-dominated elastic steps), a shell
//! preconditioner over [`crate::sor`] takes its place.
//!
//! PETSc (Debian's build has no OpenMP) sweeps a level on one core, and the sweeps were the largest part
//! of the multigrid's V-cycle (`docs/benchmarks.md`, "The multigrid's smoother on all threads"). The
//! shell does what PETSc's SOR does under Richardson (`PCApplyRichardson`: the sweeps from the level's
//! guess, or from zero) and as a preconditioner (`PCApply`: one sweep from zero): block Gauss-Seidel over
//! a node's rows, as PETSc's sweep of a matrix with "inodes". It reads the level's matrix (`seqaij`) where
//! PETSc keeps it at every application, so that it follows the Jacobian's values as PETSc's SOR does
//! when SNES lags the rest of the hierarchy, and keeps only the plan of its pattern
//! ([`crate::sor::SweepPlan`], remade when the matrix or its nonzero pattern changes).
//!
//! Replaced only where PETSc would sweep the same way: one process (`seqaij` levels), `omega = 1`, one
//! iteration of one local sweep, symmetric, no diagonal shift. Other SOR settings keep PETSc's.

use super::block_parts::with_row_ij;
use super::preconditioner::{guarded, make_shell, pc_type, shell_context};
use super::{Matrix, PetscError, Result, Vector, check, sys};
use crate::sor::{self, Csr, SweepPlan, SweepWork};
use std::ffi::{CStr, CString};

/// The shell's plan of the level's pattern, with the matrix and nonzero state it was made for, and its
/// work space.
struct Context {
    plan: Option<(sys::Mat, sys::PetscObjectState, SweepPlan)>,
    work: SweepWork,
}

/// Makes every level's symmetric SOR of the multigrid preconditioner of `ksp` (operators `a`, `p`,
/// which must hold assembled values) the threaded sweep: sets the operators and the preconditioner up
/// (PETSc makes the levels and their smoothers from the options at the first set-up) and replaces each
/// level's SOR that [`plain_sor`] accepts. Returns how many levels it replaced (0 where the
/// preconditioner is not a multigrid).
///
/// # Safety
/// `ksp`, `a` and `p` are valid; `p` holds assembled values.
pub(super) unsafe fn threaded_sor_on_levels(
    ksp: sys::KSP,
    a: sys::Mat,
    p: sys::Mat,
) -> Result<usize> {
    let mut pc: sys::PC = std::ptr::null_mut();
    // SAFETY: valid KSP; out-parameter.
    check(unsafe { sys::KSPGetPC(ksp, &mut pc) }, "KSPGetPC")?;
    // SAFETY: valid PC.
    if unsafe { pc_type(pc) }? != "mg" {
        return Ok(0);
    }
    let mut levels: sys::PetscInt = 0;
    // SAFETY: valid objects; the set-up makes the levels' smoothers from the options.
    unsafe {
        check(sys::KSPSetOperators(ksp, a, p), "KSPSetOperators")?;
        check(sys::PCSetUp(pc), "PCSetUp")?;
        check(sys::PCMGGetLevels(pc, &mut levels), "PCMGGetLevels")?;
    }
    let mut replaced = 0;
    // Level 0 is the coarse solve. The down-smoother is also the up-smoother unless
    // `-pc_mg_distinct_smoothup` made another, which keeps PETSc's SOR.
    for level in 1..levels {
        let (mut smoother, mut level_pc): (sys::KSP, sys::PC) =
            (std::ptr::null_mut(), std::ptr::null_mut());
        // SAFETY: a level of the multigrid; borrowed references.
        unsafe {
            check(
                sys::PCMGGetSmoother(pc, level, &mut smoother),
                "PCMGGetSmoother",
            )?;
            check(sys::KSPGetPC(smoother, &mut level_pc), "KSPGetPC")?;
        }
        // SAFETY: the level's valid preconditioner.
        if unsafe { plain_sor(level_pc) }? {
            // SAFETY: as above.
            unsafe { install(level_pc) }?;
            replaced += 1;
        }
    }
    Ok(replaced)
}

/// Whether `pc` is PETSc's SOR as the shell sweeps it: one symmetric sweep (local or not: one process)
/// with `omega = 1` and no diagonal shift per application, on a `seqaij` matrix.
///
/// # Safety
/// `pc` is a valid set-up preconditioner.
unsafe fn plain_sor(pc: sys::PC) -> Result<bool> {
    // SAFETY: valid PC.
    if unsafe { pc_type(pc) }? != "sor" {
        return Ok(false);
    }
    let (mut omega, mut its, mut local, mut kind) = (0.0, 0, 0, 0);
    let mut pmat: sys::Mat = std::ptr::null_mut();
    let mut prefix: *const std::ffi::c_char = std::ptr::null();
    // SAFETY: an SOR preconditioner; out-parameters (a borrowed matrix, PETSc's own prefix string).
    unsafe {
        check(sys::PCSORGetOmega(pc, &mut omega), "PCSORGetOmega")?;
        check(
            sys::PCSORGetIterations(pc, &mut its, &mut local),
            "PCSORGetIterations",
        )?;
        check(sys::PCSORGetSymmetric(pc, &mut kind), "PCSORGetSymmetric")?;
        check(
            sys::PCGetOperators(pc, std::ptr::null_mut(), &mut pmat),
            "PCGetOperators",
        )?;
        check(
            sys::PCGetOptionsPrefix(pc, &mut prefix),
            "PCGetOptionsPrefix",
        )?;
    }
    // PCSOR has no getter of its diagonal shift: the option is read where PETSc reads it.
    let prefix = if prefix.is_null() {
        String::new()
    } else {
        // SAFETY: a NUL-terminated string owned by PETSc.
        unsafe { CStr::from_ptr(prefix) }
            .to_string_lossy()
            .into_owned()
    };
    let shift =
        CString::new(format!("-{prefix}pc_sor_diagonal_shift")).map_err(|_| PetscError {
            code: 62, // PETSC_ERR_ARG_WRONG
            call: "PCGetOptionsPrefix",
            message: format!("an options prefix with a NUL byte: {prefix:?}"),
        })?;
    let mut shifted = sys::PetscBool_PETSC_FALSE;
    // SAFETY: PETSc reads the name during the call; out-parameter.
    check(
        unsafe {
            sys::PetscOptionsHasName(
                std::ptr::null_mut(),
                std::ptr::null(),
                shift.as_ptr(),
                &mut shifted,
            )
        },
        "PetscOptionsHasName",
    )?;
    let symmetric = kind == sys::MatSORType_SOR_SYMMETRIC_SWEEP
        || kind == sys::MatSORType_SOR_LOCAL_SYMMETRIC_SWEEP;
    // SAFETY: the preconditioner's valid matrix.
    let seqaij = unsafe { Matrix::borrowed(pmat) }.type_name()? == "seqaij";
    Ok(omega == 1.0
        && its == 1
        && local == 1
        && symmetric
        && shifted != sys::PetscBool_PETSC_TRUE
        && seqaij)
}

/// Makes `pc` the threaded sweep's shell.
///
/// # Safety
/// `pc` is valid and its matrix a `seqaij` one at every application.
unsafe fn install(pc: sys::PC) -> Result<()> {
    let context = Context {
        plan: None,
        work: SweepWork::default(),
    };
    // SAFETY: the caller's promise; the callbacks read a `Context`.
    unsafe {
        make_shell(pc, context, c"symmetric SOR, one part per thread", |pc| {
            check(sys::PCShellSetApply(pc, Some(apply)), "PCShellSetApply")?;
            check(
                sys::PCShellSetApplyRichardson(pc, Some(apply_richardson)),
                "PCShellSetApplyRichardson",
            )
        })
    }
}

/// `sweeps` symmetric sweeps of the shell `pc`'s matrix from `x` (or zero) towards `b`.
///
/// # Safety
/// `pc` is a shell made by [`install`]; `b` and `x` are distinct valid vectors.
unsafe fn sweep(
    pc: sys::PC,
    b: sys::PetscVec,
    x: sys::PetscVec,
    sweeps: usize,
    zero_guess: bool,
) -> Result<()> {
    // SAFETY: our shell.
    let ctx = unsafe { shell_context::<Context>(pc) }?;
    let mut pmat: sys::Mat = std::ptr::null_mut();
    let mut state: sys::PetscObjectState = 0;
    // SAFETY: a borrowed reference to the preconditioning matrix; out-parameter.
    unsafe {
        check(
            sys::PCGetOperators(pc, std::ptr::null_mut(), &mut pmat),
            "PCGetOperators",
        )?;
        check(
            sys::MatGetNonzeroState(pmat, &mut state),
            "MatGetNonzeroState",
        )?;
    }
    // SAFETY: valid vectors for the duration of the call; their arrays are restored by the wrappers.
    let (b, mut x) = unsafe { (Vector::borrowed(b), Vector::borrowed(x)) };
    // SAFETY: the level's `seqaij` matrix (checked when the shell was made); its scalar CSR arrays and
    // values are read while PETSc holds them, and restored before returning.
    let done = unsafe {
        with_row_ij(pmat, false, |ia, ja| -> Result<()> {
            let n = ia.len() - 1;
            let mut vals: *const f64 = std::ptr::null();
            check(
                sys::MatSeqAIJGetArrayRead(pmat, &mut vals),
                "MatSeqAIJGetArrayRead",
            )?;
            let a = Csr {
                row_ptr: ia,
                cols: ja,
                vals: if ja.is_empty() {
                    &[]
                } else {
                    std::slice::from_raw_parts(vals, ja.len())
                },
            };
            let parts = rayon::current_num_threads();
            let plan = match ctx.plan.take() {
                Some((m, s, plan)) if m == pmat && s == state && plan.fits(a, parts) => plan,
                _ => SweepPlan::new(a, parts),
            };
            let swept = b.read(|b| {
                x.write(|x| {
                    if b.len() != n || x.len() != n {
                        return Err(PetscError {
                            code: 60, // PETSC_ERR_ARG_SIZ
                            call: "PCApply_Shell",
                            message: format!(
                                "the threaded SOR's matrix has {n} rows, the vectors {} and {}",
                                b.len(),
                                x.len()
                            ),
                        });
                    }
                    sor::symmetric_sweeps(a, &plan, b, x, sweeps, zero_guess, &mut ctx.work);
                    Ok(())
                })
            });
            ctx.plan = Some((pmat, state, plan));
            let restored = check(
                sys::MatSeqAIJRestoreArrayRead(pmat, &mut vals),
                "MatSeqAIJRestoreArrayRead",
            );
            swept.and_then(|w| w).and_then(|s| s)?;
            restored
        })
    }?;
    done.unwrap_or_else(|| {
        Err(PetscError {
            code: 56, // PETSC_ERR_SUP
            call: "MatGetRowIJ",
            message: "the threaded SOR cannot read the level's matrix".into(),
        })
    })
}

/// `PCShellSetApply`: one symmetric sweep from zero, as PETSc's SOR applies as a preconditioner.
unsafe extern "C" fn apply(pc: sys::PC, b: sys::PetscVec, x: sys::PetscVec) -> sys::PetscErrorCode {
    // SAFETY: PETSc's shell and vectors.
    guarded(|| unsafe { sweep(pc, b, x, 1, true) })
}

/// `PCShellSetApplyRichardson`: `its` symmetric sweeps from `x`, or from zero if `zero_guess`, as
/// PETSc's SOR under Richardson (which then skips its own residual); the tolerances do not apply (the
/// multigrid's smoothers run a fixed number of iterations).
#[allow(clippy::too_many_arguments)]
unsafe extern "C" fn apply_richardson(
    pc: sys::PC,
    b: sys::PetscVec,
    x: sys::PetscVec,
    _work: sys::PetscVec,
    _rtol: f64,
    _abstol: f64,
    _dtol: f64,
    its: sys::PetscInt,
    zero_guess: sys::PetscBool,
    done: *mut sys::PetscInt,
    reason: *mut sys::PCRichardsonConvergedReason,
) -> sys::PetscErrorCode {
    guarded(|| {
        let sweeps = usize::try_from(its).unwrap_or(0);
        // SAFETY: PETSc's shell and vectors; the out-parameters are PETSc's.
        unsafe {
            sweep(pc, b, x, sweeps, zero_guess == sys::PetscBool_PETSC_TRUE)?;
            *done = its;
            *reason = sys::PCRichardsonConvergedReason_PCRICHARDSON_CONVERGED_ITS;
        }
        Ok(())
    })
}
