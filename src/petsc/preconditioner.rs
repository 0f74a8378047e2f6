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
//!
//! Where the matrix is several processes' (or there is one thread), the same shell takes the place of
//! PETSc's ILU(0) inside each subdomain of block Jacobi or additive Schwarz
//! ([`threaded_ilu_on_subdomains`], through `Snes::use_threaded_ilu_on_subdomains`): PETSc still makes
//! the subdomains' matrices and moves the vectors between processes.

use super::block_parts::block_pattern;
use super::{BlockCsr, BlockLayout, Matrix, PetscError, Result, Snes, check, sys};
use crate::ilu::SchwarzIlu;
use std::ffi::{CStr, c_void};

/// The shell's context: the subdomains and their factors, and the storage of the values they read.
struct Context {
    ilu: SchwarzIlu,
    layout: BlockLayout,
    /// How a failed factorisation is reported.
    failure: Failure,
    /// The last factorisation failed.
    failed: bool,
}

/// How the shell reports a factorisation that failed (a non-finite pivot).
#[derive(Clone, Copy, PartialEq)]
enum Failure {
    /// As the preconditioner's failure (`PCSetFailedReason`), which stops the Krylov solver at once and
    /// is cleared by the next factorisation that succeeds: the shell is the Krylov solver's own
    /// preconditioner.
    Reason,
    /// By applying as NaN, which the outer Krylov solver meets as `DIVERGED_NANORINF` (as PETSc's ILU(0)
    /// meets a NaN in the matrix): the shell is a subdomain's. Block Jacobi and additive Schwarz turn a
    /// subdomain's failure into their own from the sub-solver's last converged reason, which a later
    /// set-up does not clear (PETSc 3.18), so a failure marked there would fail every later solve of the
    /// same solver.
    NotANumber,
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
    // SAFETY: the SNES's own preconditioner.
    unsafe {
        install(
            snes.pc()?,
            (ilu, layout, Failure::Reason),
            c"ILU(0) on overlapping subdomains, one per thread",
        )
    }?;
    Ok(true)
}

/// Makes `pc` a shell over `ilu`, which reads the values of `pc`'s preconditioning matrix in `layout` and
/// reports a failed factorisation as `failure` says.
///
/// # Safety
/// `pc` is a valid PC whose preconditioning matrix, at every set-up, has the storage and pattern `ilu`
/// was built for.
unsafe fn install(
    pc: sys::PC,
    (ilu, layout, failure): (SchwarzIlu, BlockLayout, Failure),
    name: &CStr,
) -> Result<()> {
    let context = Context {
        ilu,
        layout,
        failure,
        failed: false,
    };
    // SAFETY: the caller's promise; the callbacks read a `Context`.
    unsafe {
        make_shell(pc, context, name, |pc| {
            check(sys::PCShellSetSetUp(pc, Some(set_up)), "PCShellSetSetUp")?;
            check(sys::PCShellSetApply(pc, Some(apply)), "PCShellSetApply")
        })
    }
}

/// Makes `pc` a shell preconditioner named `name` that owns `context` (freed when PETSc destroys the
/// shell or changes its type: [`destroy_context`]) and whose operations `operations` registers; the
/// operations read the context with [`shell_context`].
///
/// # Safety
/// `pc` is a valid PC; the operations `operations` registers read a `T` as the context.
pub(super) unsafe fn make_shell<T>(
    pc: sys::PC,
    context: T,
    name: &CStr,
    operations: impl FnOnce(sys::PC) -> Result<()>,
) -> Result<()> {
    let ctx = Box::into_raw(Box::new(context)).cast::<c_void>();
    // SAFETY: valid PC; the shell keeps `ctx` until its destroy callback frees it. The callbacks match
    // PETSc's signatures for the shell's operations.
    unsafe {
        if let Err(e) = check(sys::PCSetType(pc, c"shell".as_ptr()), "PCSetType") {
            drop(Box::from_raw(ctx.cast::<T>()));
            return Err(e);
        }
        check(sys::PCShellSetContext(pc, ctx), "PCShellSetContext")?;
        check(
            sys::PCShellSetDestroy(pc, Some(destroy_context::<T>)),
            "PCShellSetDestroy",
        )?;
        operations(pc)?;
        check(sys::PCShellSetName(pc, name.as_ptr()), "PCShellSetName")
    }
}

/// The ILU(0) of every subdomain of block Jacobi or additive Schwarz (`-pc_type bjacobi` or `asm` with
/// `-sub_pc_type ilu`: one subdomain per process, the matrices of several processes or one thread, where
/// [`use_threaded_ilu`] declines) made [`SchwarzIlu`] on the process's threads (one overlapping part per
/// thread; one part is the subdomain's plain ILU(0)) instead of PETSc's. Per core it is about twice as
/// fast as PETSc's (`docs/benchmarks.md`, "PETSc's ILU replaced on every subdomain"): the factors are
/// stored in the order the solves read them and the factorisation is specialised for blocks of 2 to 4.
///
/// PETSc makes the subdomains' matrices at the preconditioner's first set-up, so this sets the Krylov
/// solver's operators to `a` and `p` (which must hold assembled values: called after the first
/// Jacobian) and sets the preconditioner up; each subdomain whose preconditioner is ILU and whose matrix
/// is block storage (`seqbaij`) with block size `bs` (2 to 4) becomes a shell over its pattern, which
/// PETSc refills at each later set-up. Returns how many subdomains it replaced (0: it did not apply).
///
/// # Safety
/// `ksp`, `a` and `p` are valid; `p` holds assembled values.
pub(super) unsafe fn threaded_ilu_on_subdomains(
    ksp: sys::KSP,
    a: sys::Mat,
    p: sys::Mat,
    bs: usize,
) -> Result<usize> {
    type GetSubKsp = unsafe extern "C" fn(
        sys::PC,
        *mut sys::PetscInt,
        *mut sys::PetscInt,
        *mut *mut sys::KSP,
    ) -> sys::PetscErrorCode;
    if !(2..=4).contains(&bs) {
        return Ok(0);
    }
    let mut pc: sys::PC = std::ptr::null_mut();
    // SAFETY: valid KSP; out-parameter.
    check(unsafe { sys::KSPGetPC(ksp, &mut pc) }, "KSPGetPC")?;
    // SAFETY: valid PC.
    let get_sub: GetSubKsp = match unsafe { pc_type(pc) }?.as_str() {
        "asm" => sys::PCASMGetSubKSP,
        "bjacobi" => sys::PCBJacobiGetSubKSP,
        _ => return Ok(0),
    };
    let (mut n, mut subs): (sys::PetscInt, *mut sys::KSP) = (0, std::ptr::null_mut());
    // SAFETY: valid objects; the set-up makes the sub-solvers, whose array PETSc owns.
    unsafe {
        check(sys::KSPSetOperators(ksp, a, p), "KSPSetOperators")?;
        check(sys::PCSetUp(pc), "PCSetUp")?;
        // No first index asked for: that would be a collective scan over the processes.
        check(
            get_sub(pc, &mut n, std::ptr::null_mut(), &mut subs),
            "PCGetSubKSP",
        )?;
    }
    if subs.is_null() || n <= 0 {
        return Ok(0);
    }
    // SAFETY: `n` sub-solvers, owned by the preconditioner.
    let subs = unsafe { std::slice::from_raw_parts(subs, n as usize) };
    let threads = rayon::current_num_threads();
    let mut replaced = 0;
    for &sub in subs {
        let (mut sub_pc, mut amat, mut pmat): (sys::PC, sys::Mat, sys::Mat) = (
            std::ptr::null_mut(),
            std::ptr::null_mut(),
            std::ptr::null_mut(),
        );
        // SAFETY: a valid sub-solver; out-parameters (borrowed references).
        unsafe {
            check(sys::KSPGetPC(sub, &mut sub_pc), "KSPGetPC")?;
            check(
                sys::KSPGetOperators(sub, &mut amat, &mut pmat),
                "KSPGetOperators",
            )?;
        }
        // SAFETY: valid objects.
        if unsafe { pc_type(sub_pc) }? != "ilu"
            || unsafe { Matrix::borrowed(pmat) }.type_name()? != "seqbaij"
        {
            continue;
        }
        let mut block = 0;
        // SAFETY: valid matrix; out-parameter.
        check(
            unsafe { sys::MatGetBlockSize(pmat, &mut block) },
            "MatGetBlockSize",
        )?;
        if block as usize != bs {
            continue;
        }
        // SAFETY: valid matrix.
        // An empty subdomain keeps PETSc's (it has nothing to factor).
        let Some((row_ptr, cols)) = (unsafe { block_pattern(pmat) })? else {
            continue;
        };
        if row_ptr.len() < 2 {
            continue;
        }
        let Ok(ilu) = SchwarzIlu::blocks(bs, &row_ptr, &cols, threads) else {
            continue;
        };
        // SAFETY: the sub-preconditioner's matrix is `pmat`, whose pattern PETSc keeps at later set-ups
        // of the same Jacobian.
        unsafe {
            install(
                sub_pc,
                (ilu, BlockLayout::Blocks, Failure::NotANumber),
                c"ILU(0) of the subdomain, one overlapping part per thread",
            )
        }?;
        replaced += 1;
    }
    Ok(replaced)
}

/// The type name of a preconditioner ("" if unset).
///
/// # Safety
/// `pc` is valid.
pub(super) unsafe fn pc_type(pc: sys::PC) -> Result<String> {
    let mut name: *const std::ffi::c_char = std::ptr::null();
    // SAFETY: out-parameter; PETSc's own string.
    check(unsafe { sys::PCGetType(pc, &mut name) }, "PCGetType")?;
    // SAFETY: null or a NUL-terminated string owned by PETSc.
    Ok(unsafe { super::reason_name(name, "") })
}

/// The context of a shell made by [`make_shell`] with a `T`.
///
/// # Safety
/// `pc` is such a shell.
pub(super) unsafe fn shell_context<'a, T>(pc: sys::PC) -> Result<&'a mut T> {
    let mut ctx: *mut c_void = std::ptr::null_mut();
    // SAFETY: out-parameter (PETSc 3.18 takes the address of the context pointer as `void *`).
    let code = unsafe { sys::PCShellGetContext(pc, (&mut ctx as *mut *mut c_void).cast()) };
    if code != 0 || ctx.is_null() {
        return Err(PetscError {
            code: if code != 0 { code } else { 1 },
            call: "PCShellGetContext",
            message: "a shell preconditioner's context is missing".into(),
        });
    }
    // SAFETY: PETSc calls the shell's operations one at a time; the context lives until
    // `destroy_context`.
    Ok(unsafe { &mut *ctx.cast::<T>() })
}

/// Runs `f`, turning a PETSc error into its code and a panic into PETSc's user error.
pub(super) fn guarded(
    f: impl FnOnce() -> std::result::Result<(), PetscError>,
) -> sys::PetscErrorCode {
    match std::panic::catch_unwind(std::panic::AssertUnwindSafe(f)) {
        Ok(Ok(())) => 0,
        Ok(Err(e)) => e.code,
        Err(_) => 83, // PETSC_ERR_USER
    }
}

/// `PCShellSetDestroy` of a shell made by [`make_shell`] with a `T`: frees the context.
unsafe extern "C" fn destroy_context<T>(pc: sys::PC) -> sys::PetscErrorCode {
    let mut ctx: *mut c_void = std::ptr::null_mut();
    // SAFETY: out-parameter; PETSc calls this once, for our shell.
    let code = unsafe { sys::PCShellGetContext(pc, (&mut ctx as *mut *mut c_void).cast()) };
    if code == 0 && !ctx.is_null() {
        // SAFETY: made by `Box::into_raw` in `make_shell`, not used afterwards.
        drop(unsafe { Box::from_raw(ctx.cast::<T>()) });
    }
    code
}

/// `PCShellSetSetUp`: factors the subdomains from the preconditioning matrix's current values; a
/// non-finite pivot marks the preconditioner failed (`PC_FACTOR_NUMERIC_ZEROPIVOT`).
unsafe extern "C" fn set_up(pc: sys::PC) -> sys::PetscErrorCode {
    guarded(|| {
        // SAFETY: our shell.
        let ctx = unsafe { shell_context::<Context>(pc) }?;
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
        }
        // The factorisation reads as many values as the pattern it was built for: refuse a matrix of
        // another size (PETSc would hand the shell another matrix after a change of pattern) instead of
        // reading past its array.
        let len = ctx.ilu.values_len();
        let mut info = std::mem::MaybeUninit::<sys::MatInfo>::uninit();
        // SAFETY: out-parameter filled by PETSc.
        check(
            unsafe { sys::MatGetInfo(pmat, sys::MatInfoType_MAT_LOCAL, info.as_mut_ptr()) },
            "MatGetInfo",
        )?;
        // SAFETY: initialised by the successful call above.
        let held = unsafe { info.assume_init() }.nz_used as usize;
        if held != len {
            return Err(PetscError {
                code: 60, // PETSC_ERR_ARG_SIZ
                call: "PCSetUp_Shell",
                message: format!(
                    "the threaded ILU(0) was built for {len} matrix values, the matrix holds {held}"
                ),
            });
        }
        // SAFETY: as above.
        unsafe {
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
            ctx.failed = factored.is_err();
            // A failure is marked, and cleared by the next factorisation that succeeds (PETSc's ILU
            // clears it at each set-up; a shell's is left to the shell), so that a solve after a failed
            // one is not failed with it.
            if ctx.failure == Failure::Reason {
                let reason = if ctx.failed {
                    sys::PCFailedReason_PC_FACTOR_NUMERIC_ZEROPIVOT
                } else {
                    sys::PCFailedReason_PC_NOERROR
                };
                check(sys::PCSetFailedReason(pc, reason), "PCSetFailedReason")?;
            }
        }
        Ok(())
    })
}

/// `PCShellSetApply`: `y = M^-1 x` on the process's threads.
unsafe extern "C" fn apply(pc: sys::PC, x: sys::PetscVec, y: sys::PetscVec) -> sys::PetscErrorCode {
    guarded(|| {
        // SAFETY: our shell.
        let ctx = unsafe { shell_context::<Context>(pc) }?;
        let n = ctx.ilu.rows();
        for v in [x, y] {
            let mut len = 0;
            // SAFETY: a valid vector; out-parameter.
            check(
                unsafe { sys::VecGetLocalSize(v, &mut len) },
                "VecGetLocalSize",
            )?;
            if len as usize != n {
                return Err(PetscError {
                    code: 60, // PETSC_ERR_ARG_SIZ
                    call: "PCApply_Shell",
                    message: format!("the threaded ILU(0) has {n} rows, a vector {len}"),
                });
            }
        }
        if n == 0 {
            return Ok(());
        }
        let (mut xa, mut ya): (*const f64, *mut f64) = (std::ptr::null(), std::ptr::null_mut());
        // SAFETY: PETSc's arrays of two distinct vectors of the preconditioner's size (checked above),
        // restored below.
        unsafe {
            check(sys::VecGetArrayRead(x, &mut xa), "VecGetArrayRead")?;
            check(sys::VecGetArray(y, &mut ya), "VecGetArray")?;
            let out = std::slice::from_raw_parts_mut(ya, n);
            if ctx.failed {
                out.fill(f64::NAN);
            } else {
                ctx.ilu.apply(std::slice::from_raw_parts(xa, n), out);
            }
            check(sys::VecRestoreArray(y, &mut ya), "VecRestoreArray")?;
            check(sys::VecRestoreArrayRead(x, &mut xa), "VecRestoreArrayRead")?;
        }
        Ok(())
    })
}
