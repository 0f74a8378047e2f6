//! GMRES's ILU(0) on all of the process's threads: a PETSc shell preconditioner over
//! [`crate::ilu::SchwarzIlu`] (ILU(0) on overlapping subdomains, one per thread).
//!
//! PETSc (Debian's build has no OpenMP) factors and applies ILU(0) on one core; with the threaded
//! Jacobian product (`ThreadedOperator`) the triangular solves and the factorisations were the largest
//! part of a one-process run left on one core. The shell reads the assembled Jacobian's own values (block
//! or point-wise storage) at each set-up of the preconditioner (which SNES's lag decides as for PETSc's ILU) and factors
//! and applies the subdomains in parallel. A factorisation that meets a non-finite pivot marks the
//! preconditioner failed, so that the linear solve stops and the step goes to the fallback solver as with
//! PETSc's ILU.

use super::{BlockCsr, BlockLayout, Matrix, PetscError, Result, Snes, check, cstring, sys};
use crate::ilu::SchwarzIlu;
use std::ffi::c_void;

/// The shell's context: the subdomains and their factors, and the storage of the values they read.
struct Context {
    ilu: SchwarzIlu,
    layout: BlockLayout,
}

/// Makes the preconditioner of `snes` ILU(0) on one overlapping subdomain per thread for the Jacobian
/// `jacobian` with block pattern `pattern` (the whole matrix on one process): block ILU(0) for the
/// block storage (`seqbaij`), point ILU(0) for the point-wise one (`seqaij`). Returns false, changing
/// nothing, where it does not apply: the matrices of several processes, one thread, a block size other
/// than 2 to 4.
pub fn use_threaded_ilu(snes: &Snes, jacobian: &Matrix, pattern: &BlockCsr<'_>) -> Result<bool> {
    let layout = match jacobian.type_name()?.as_str() {
        "seqbaij" => BlockLayout::Blocks,
        "seqaij" => BlockLayout::Rows,
        _ => return Ok(false),
    };
    let threads = rayon::current_num_threads();
    if threads < 2 || pattern.first != 0 || !(2..=4).contains(&pattern.bs) {
        return Ok(false);
    }
    let (bs, row_ptr, cols) = (pattern.bs, pattern.row_ptr, pattern.cols);
    let ilu = match layout {
        BlockLayout::Blocks => SchwarzIlu::blocks(bs, row_ptr, cols, threads),
        BlockLayout::Rows => SchwarzIlu::points(bs, row_ptr, cols, threads),
    };
    let Ok(ilu) = ilu else {
        return Ok(false);
    };
    let pc = snes.pc()?;
    let ctx = Box::into_raw(Box::new(Context { ilu, layout })).cast::<c_void>();
    let name = cstring("ILU(0) on overlapping subdomains, one per thread")?;
    // SAFETY: valid PC; the shell keeps `ctx` until its destroy callback frees it. The callbacks match
    // PETSc's signatures for the shell's operations.
    unsafe {
        if let Err(e) = check(sys::PCSetType(pc, c"shell".as_ptr()), "PCSetType") {
            drop(Box::from_raw(ctx.cast::<Context>()));
            return Err(e);
        }
        check(sys::PCShellSetContext(pc, ctx), "PCShellSetContext")?;
        check(
            sys::PCShellSetDestroy(pc, Some(destroy)),
            "PCShellSetDestroy",
        )?;
        check(sys::PCShellSetSetUp(pc, Some(set_up)), "PCShellSetSetUp")?;
        check(sys::PCShellSetApply(pc, Some(apply)), "PCShellSetApply")?;
        check(sys::PCShellSetName(pc, name.as_ptr()), "PCShellSetName")?;
    }
    Ok(true)
}

/// The shell's context.
///
/// # Safety
/// `pc` is a shell made by [`use_threaded_ilu`].
unsafe fn context<'a>(pc: sys::PC) -> std::result::Result<&'a mut Context, sys::PetscErrorCode> {
    let mut ctx: *mut c_void = std::ptr::null_mut();
    // SAFETY: out-parameter (PETSc 3.18 takes the address of the context pointer as `void *`).
    let code = unsafe { sys::PCShellGetContext(pc, (&mut ctx as *mut *mut c_void).cast()) };
    if code != 0 || ctx.is_null() {
        return Err(if code != 0 { code } else { 1 });
    }
    // SAFETY: PETSc calls the shell's operations one at a time; the context lives until `destroy`.
    Ok(unsafe { &mut *ctx.cast::<Context>() })
}

/// The error of a shell whose context cannot be read.
fn context_error(code: sys::PetscErrorCode) -> PetscError {
    PetscError {
        code,
        call: "PCShellGetContext",
        message: "the threaded ILU's context is missing".into(),
    }
}

/// Runs `f`, turning a PETSc error into its code and a panic into PETSc's user error.
fn guarded(f: impl FnOnce() -> std::result::Result<(), PetscError>) -> sys::PetscErrorCode {
    match std::panic::catch_unwind(std::panic::AssertUnwindSafe(f)) {
        Ok(Ok(())) => 0,
        Ok(Err(e)) => e.code,
        Err(_) => 83, // PETSC_ERR_USER
    }
}

/// `PCShellSetDestroy`: frees the context.
unsafe extern "C" fn destroy(pc: sys::PC) -> sys::PetscErrorCode {
    let mut ctx: *mut c_void = std::ptr::null_mut();
    // SAFETY: out-parameter; PETSc calls this once, for our shell.
    let code = unsafe { sys::PCShellGetContext(pc, (&mut ctx as *mut *mut c_void).cast()) };
    if code == 0 && !ctx.is_null() {
        // SAFETY: made by `Box::into_raw` in `use_threaded_ilu`, not used afterwards.
        drop(unsafe { Box::from_raw(ctx.cast::<Context>()) });
    }
    code
}

/// `PCShellSetSetUp`: factors the subdomains from the preconditioning matrix's current values; a
/// non-finite pivot marks the preconditioner failed (`PC_FACTOR_NUMERIC_ZEROPIVOT`).
unsafe extern "C" fn set_up(pc: sys::PC) -> sys::PetscErrorCode {
    guarded(|| {
        // SAFETY: our shell.
        let ctx = unsafe { context(pc) }.map_err(context_error)?;
        let (mut amat, mut pmat): (sys::Mat, sys::Mat) =
            (std::ptr::null_mut(), std::ptr::null_mut());
        let mut values: *mut f64 = std::ptr::null_mut();
        let mut read: *const f64 = std::ptr::null();
        // SAFETY: borrowed references to the operators; the values array is restored below (the reads
        // do not change the matrix's state).
        unsafe {
            check(
                sys::PCGetOperators(pc, &mut amat, &mut pmat),
                "PCGetOperators",
            )?;
            match ctx.layout {
                BlockLayout::Blocks => {
                    check(
                        sys::MatSeqBAIJGetArray(pmat, &mut values),
                        "MatSeqBAIJGetArray",
                    )?;
                    read = values;
                }
                BlockLayout::Rows => check(
                    sys::MatSeqAIJGetArrayRead(pmat, &mut read),
                    "MatSeqAIJGetArrayRead",
                )?,
            }
        }
        let len = ctx.ilu.values_len();
        // SAFETY: the Jacobian's values, in the storage and pattern the shell was made for.
        let factored = ctx
            .ilu
            .factor(unsafe { std::slice::from_raw_parts(read, len) });
        // SAFETY: as above.
        unsafe {
            match ctx.layout {
                BlockLayout::Blocks => check(
                    sys::MatSeqBAIJRestoreArray(pmat, &mut values),
                    "MatSeqBAIJRestoreArray",
                )?,
                BlockLayout::Rows => check(
                    sys::MatSeqAIJRestoreArrayRead(pmat, &mut read),
                    "MatSeqAIJRestoreArrayRead",
                )?,
            }
            if factored.is_err() {
                check(
                    sys::PCSetFailedReason(pc, sys::PCFailedReason_PC_FACTOR_NUMERIC_ZEROPIVOT),
                    "PCSetFailedReason",
                )?;
            }
        }
        Ok(())
    })
}

/// `PCShellSetApply`: `y = M^-1 x` on the process's threads.
unsafe extern "C" fn apply(pc: sys::PC, x: sys::PetscVec, y: sys::PetscVec) -> sys::PetscErrorCode {
    guarded(|| {
        // SAFETY: our shell.
        let ctx = unsafe { context(pc) }.map_err(context_error)?;
        let n = ctx.ilu.rows();
        let (mut xa, mut ya): (*const f64, *mut f64) = (std::ptr::null(), std::ptr::null_mut());
        // SAFETY: PETSc's arrays of two distinct vectors of the preconditioner's size, restored below.
        unsafe {
            check(sys::VecGetArrayRead(x, &mut xa), "VecGetArrayRead")?;
            check(sys::VecGetArray(y, &mut ya), "VecGetArray")?;
            ctx.ilu.apply(
                std::slice::from_raw_parts(xa, n),
                std::slice::from_raw_parts_mut(ya, n),
            );
            check(sys::VecRestoreArray(y, &mut ya), "VecRestoreArray")?;
            check(sys::VecRestoreArrayRead(x, &mut xa), "VecRestoreArrayRead")?;
        }
        Ok(())
    })
}
