//! The Jacobian's product with a vector by the solver's own kernel: a PETSc shell matrix that GMRES uses
//! as its operator while the preconditioner is built from the assembled Jacobian.
//!
//! PETSc (Debian's build has no OpenMP) multiplies a matrix on one core, and its block kernel
//! (`MatMult_SeqBAIJ_3`) took 2.99 ms per product of the half-resolution CT's Jacobian where this one
//! takes 1.33 ms on the same core (`docs/benchmarks.md`, "GMRES's product by the solver's kernel on one
//! thread and on every process"). This operator reads the values of the assembled Jacobian (PETSc's own
//! arrays, no copy) and multiplies by block rows in parallel on the process's threads (rayon), each row
//! summed in the order of PETSc's block kernels (`MatMult_SeqBAIJ_2/3`), so that the product has PETSc's
//! bits for the CT's block sizes. On several processes (`mpibaij`, `mpiaij`) it multiplies the diagonal
//! part so while the values of the other processes' columns arrive, then adds the off-diagonal part's
//! product as PETSc's `MatMult_MPIBAIJ` and `MatMult_MPIAIJ` do. `SNESSetJacobian(snes, operator,
//! jacobian)`: Krylov iterations use the operator, the preconditioner (ILU, field split, ...) the
//! Jacobian.

use super::block_parts::{block_pattern, with_row_ij};
use super::{
    BlockCsr, BlockLayout, Matrix, PetscError, PetscInt, Result, Vector, check, comm_world, sys,
    to_petsc_int,
};
use rayon::prelude::*;
use std::ffi::c_void;

/// Block rows per parallel task.
const CHUNK: usize = 256;

/// What the product needs: the Jacobian (a counted reference, released when PETSc destroys the shell),
/// the part of it the kernel multiplies (the Jacobian itself on one process, its diagonal part on
/// several) with its block pattern, and on several processes what the off-diagonal part needs.
struct Product {
    jacobian: sys::Mat,
    local: sys::Mat,
    rows: Rows,
    ghosts: Option<Ghosts>,
}

/// The off-diagonal part of a process's rows (`seqbaij`, columns compressed to the other processes'
/// block columns it holds, PETSc's `garray`), the scatter of those entries of `x` and their values.
struct Ghosts {
    off: sys::Mat,
    scatter: sys::VecScatter,
    values: sys::PetscVec,
}

/// The block rows of the product: how the values are laid out, the block size and the block pattern.
struct Rows {
    layout: BlockLayout,
    bs: usize,
    row_ptr: Vec<usize>,
    cols: Vec<u32>,
}

/// A shell matrix whose product is the Jacobian's, computed on the process's threads.
pub struct ThreadedOperator {
    pub(crate) shell: Matrix,
}

impl ThreadedOperator {
    /// The product of `jacobian` (this process's rows of it: the block pattern `pattern`) by the solver's
    /// kernel, or `None` where it does not apply: a matrix type whose values are not CSR arrays the
    /// kernel reads (`seqaij`: scalar rows, `seqbaij`: column-major blocks, `mpiaij` and `mpibaij`: a
    /// process's diagonal part so), or a block size other than the 2 to 4 unknowns per node of 2D and
    /// 3D. The type and block size are the same on every process, so every process
    /// declines or makes the shell (collective) alike.
    pub fn over(jacobian: &Matrix, pattern: &BlockCsr<'_>) -> Result<Option<Self>> {
        if !(2..=4).contains(&pattern.bs) {
            return Ok(None);
        }
        let kind = jacobian.type_name()?;
        let seq = |layout| Rows {
            layout,
            bs: pattern.bs,
            row_ptr: pattern.row_ptr.to_vec(),
            cols: pattern.cols.to_vec(),
        };
        let (local, rows, ghosts) = match kind.as_str() {
            "seqaij" if pattern.first == 0 => (jacobian.raw, seq(BlockLayout::Rows), None),
            "seqbaij" if pattern.first == 0 => (jacobian.raw, seq(BlockLayout::Blocks), None),
            // SAFETY: a valid assembled `mpibaij` matrix (its pattern set), kept alive by the shell.
            "mpibaij" => unsafe { parts(jacobian.raw, pattern.bs, BlockLayout::Blocks)? },
            // SAFETY: as above, an `mpiaij` matrix of full node blocks (`Matrix::set_block_pattern`).
            "mpiaij" => unsafe { parts(jacobian.raw, pattern.bs, BlockLayout::Rows)? },
            _ => return Ok(None),
        };
        let n = to_petsc_int(
            rows.row_ptr.len().saturating_sub(1) * rows.bs,
            "MatCreateShell",
        );
        // SAFETY: PETSc takes a reference to the Jacobian; released in `destroy` with the context.
        let referenced = n.and_then(|n| {
            check(
                unsafe { sys::PetscObjectReference(jacobian.raw.cast()) },
                "PetscObjectReference",
            )
            .map(|()| n)
        });
        let n = match referenced {
            Ok(n) => n,
            Err(e) => {
                if let Some(mut g) = ghosts {
                    // SAFETY: made by `parts` just above, not used afterwards.
                    unsafe { g.free() };
                }
                return Err(e);
            }
        };
        let product = Box::new(Product {
            jacobian: jacobian.raw,
            local,
            rows,
            ghosts,
        });
        let ctx = Box::into_raw(product).cast::<c_void>();
        let mut raw: sys::Mat = std::ptr::null_mut();
        // SAFETY: out-parameter; the shell keeps `ctx` until its destroy operation frees it.
        let made = check(
            unsafe { sys::MatCreateShell(comm_world(), n, n, -1, -1, ctx, &mut raw) },
            "MatCreateShell",
        );
        if let Err(e) = made {
            // SAFETY: the shell was not made: the context and the reference are still ours.
            unsafe { release(ctx) };
            return Err(e);
        }
        let shell = Matrix::from_raw(raw);
        // SAFETY: the callbacks match PETSc's signatures for these operations (cast to the generic
        // `void (*)(void)` that MatShellSetOperation takes).
        unsafe {
            let mult: unsafe extern "C" fn(
                sys::Mat,
                sys::PetscVec,
                sys::PetscVec,
            ) -> sys::PetscErrorCode = multiply;
            let destroy: unsafe extern "C" fn(sys::Mat) -> sys::PetscErrorCode = destroy;
            check(
                sys::MatShellSetOperation(
                    shell.raw,
                    sys::MatOperation_MATOP_DESTROY,
                    Some(std::mem::transmute::<
                        unsafe extern "C" fn(sys::Mat) -> sys::PetscErrorCode,
                        unsafe extern "C" fn(),
                    >(destroy)),
                ),
                "MatShellSetOperation",
            )?;
            check(
                sys::MatShellSetOperation(
                    shell.raw,
                    sys::MatOperation_MATOP_MULT,
                    Some(std::mem::transmute::<
                        unsafe extern "C" fn(
                            sys::Mat,
                            sys::PetscVec,
                            sys::PetscVec,
                        ) -> sys::PetscErrorCode,
                        unsafe extern "C" fn(),
                    >(mult)),
                ),
                "MatShellSetOperation",
            )?;
        }
        Ok(Some(Self { shell }))
    }

    /// `y = J x` through PETSc (`MatMult` of the shell).
    pub fn mult(&self, x: &Vector, y: &mut Vector) -> Result<()> {
        self.shell.mult(x, y)
    }
}

/// The diagonal part of the `mpibaij` (`layout` Blocks) or `mpiaij` (Rows: full node blocks of `bs`
/// unknowns, stored row by row) matrix `m` with its block pattern, and its off-diagonal part with the
/// scatter (collective) of the entries of `x` its columns stand for.
///
/// # Safety
/// `m` is a valid matrix of that type whose structure is assembled; the parts are used while it lives.
unsafe fn parts(
    m: sys::Mat,
    bs: usize,
    layout: BlockLayout,
) -> Result<(sys::Mat, Rows, Option<Ghosts>)> {
    let (mut diag, mut off, mut garray): (sys::Mat, sys::Mat, *const PetscInt) =
        (std::ptr::null_mut(), std::ptr::null_mut(), std::ptr::null());
    // SAFETY: out-parameters; the parts and `garray` (the off-diagonal part's global columns: of
    // blocks for `mpibaij`, of unknowns for `mpiaij`) belong to the matrix.
    check(
        unsafe {
            match layout {
                BlockLayout::Blocks => {
                    sys::MatMPIBAIJGetSeqBAIJ(m, &mut diag, &mut off, &mut garray)
                }
                BlockLayout::Rows => sys::MatMPIAIJGetSeqAIJ(m, &mut diag, &mut off, &mut garray),
            }
        },
        "MatMPI(B)AIJGetSeq(B)AIJ",
    )?;
    // SAFETY: the diagonal part is a valid `seqbaij` or `seqaij` matrix.
    let pattern = unsafe {
        match layout {
            BlockLayout::Blocks => block_pattern(diag)?,
            BlockLayout::Rows => node_block_pattern(diag, bs)?,
        }
    };
    let (row_ptr, cols) = pattern.ok_or_else(|| PetscError {
        code: 83, // PETSC_ERR_USER
        call: "MatGetRowIJ",
        message: "the diagonal part holds no pattern of whole node blocks".into(),
    })?;
    let (mut rows_off, mut n) = (0, 0);
    // SAFETY: out-parameters of a valid matrix.
    check(
        unsafe { sys::MatGetLocalSize(off, &mut rows_off, &mut n) },
        "MatGetLocalSize",
    )?;
    // The off-diagonal part's columns: blocks of `bs` unknowns, or single unknowns.
    let (width, count) = match layout {
        BlockLayout::Blocks => (bs, usize::try_from(n).unwrap_or(0) / bs),
        BlockLayout::Rows => (1, usize::try_from(n).unwrap_or(0)),
    };
    let columns: Vec<PetscInt> = if count == 0 || garray.is_null() {
        Vec::new()
    } else {
        // SAFETY: `garray` lists the global column of each of the part's `count` columns.
        unsafe { std::slice::from_raw_parts(garray, count) }.to_vec()
    };
    let count = to_petsc_int(columns.len(), "ISCreateBlock")?;
    let block = to_petsc_int(width, "ISCreateBlock")?;
    let mut ghosts = Ghosts {
        off,
        scatter: std::ptr::null_mut(),
        values: std::ptr::null_mut(),
    };
    // SAFETY: a sequential vector of the ghost entries, an index set of their blocks (copied, destroyed
    // below), a vector laid out like `m`'s columns (destroyed below) and the scatter between them, owned
    // by `ghosts` (freed by `release`, or here on failure). Collective: every process makes its scatter.
    let made = unsafe {
        let self_comm = sys::mpmc_comm_self();
        let mut code = sys::VecCreateSeq(self_comm, count * block, &mut ghosts.values);
        let (mut from, mut like): (sys::IS, sys::PetscVec) =
            (std::ptr::null_mut(), std::ptr::null_mut());
        if code == 0 {
            code = sys::ISCreateBlock(
                self_comm,
                block,
                count,
                columns.as_ptr(),
                sys::PetscCopyMode_PETSC_COPY_VALUES,
                &mut from,
            );
        }
        if code == 0 {
            code = sys::MatCreateVecs(m, &mut like, std::ptr::null_mut());
        }
        if code == 0 {
            code = sys::VecScatterCreate(
                like,
                from,
                ghosts.values,
                std::ptr::null_mut(),
                &mut ghosts.scatter,
            );
        }
        sys::ISDestroy(&mut from);
        sys::VecDestroy(&mut like);
        code
    };
    if let Err(e) = check(made, "VecScatterCreate") {
        // SAFETY: made above (null where not), not used afterwards.
        unsafe { ghosts.free() };
        return Err(e);
    }
    let rows = Rows {
        layout,
        bs,
        row_ptr,
        cols,
    };
    Ok((diag, rows, Some(ghosts)))
}

/// The node-block pattern (row pointers, block columns) of a `seqaij` matrix whose rows come in whole
/// blocks of `bs` unknowns (each block row's `bs` rows with the same columns, blocks of `bs` consecutive
/// columns), read from its scalar CSR arrays; `None` if PETSc does not give them or they are not so.
///
/// # Safety
/// `m` is a valid `seqaij` matrix.
unsafe fn node_block_pattern(m: sys::Mat, bs: usize) -> Result<Option<(Vec<usize>, Vec<u32>)>> {
    // SAFETY: the caller's promise; the scalar CSR arrays.
    Ok(unsafe { with_row_ij(m, false, |ia, ja| blocks_of_rows(ia, ja, bs))? }.flatten())
}

/// The node-block pattern of the scalar CSR `(ia, ja)` if its rows come in whole blocks of `bs`.
fn blocks_of_rows(ia: &[PetscInt], ja: &[PetscInt], bs: usize) -> Option<(Vec<usize>, Vec<u32>)> {
    let rows = ia.len().checked_sub(1)?;
    if rows % bs != 0 {
        return None;
    }
    let (mut row_ptr, mut cols) = (vec![0usize], Vec::new());
    for a in 0..rows / bs {
        let first = &ja[ia[a * bs] as usize..ia[a * bs + 1] as usize];
        if first.len() % bs != 0 {
            return None;
        }
        for chunk in first.chunks_exact(bs) {
            let b = usize::try_from(chunk[0]).ok()?;
            if b % bs != 0 || chunk.iter().enumerate().any(|(k, &c)| c as usize != b + k) {
                return None;
            }
            cols.push(u32::try_from(b / bs).ok()?);
        }
        let same = (1..bs).all(|i| {
            let r = a * bs + i;
            ja[ia[r] as usize..ia[r + 1] as usize] == *first
        });
        if !same {
            return None;
        }
        row_ptr.push(cols.len());
    }
    Some((row_ptr, cols))
}

impl Ghosts {
    /// Destroys the scatter and the ghost values.
    ///
    /// # Safety
    /// Made by [`parts`]; not used afterwards.
    unsafe fn free(&mut self) {
        // SAFETY: the caller's contract; PETSc's destroy functions accept null handles.
        unsafe {
            sys::VecScatterDestroy(&mut self.scatter);
            sys::VecDestroy(&mut self.values);
        }
    }
}

/// Frees a context made by [`ThreadedOperator::over`] and releases its reference to the Jacobian.
///
/// # Safety
/// `ctx` came from `Box::into_raw` of a [`Product`] and is not used afterwards.
unsafe fn release(ctx: *mut c_void) -> sys::PetscErrorCode {
    // SAFETY: the caller's contract.
    let mut product = unsafe { Box::from_raw(ctx.cast::<Product>()) };
    if let Some(g) = product.ghosts.as_mut() {
        // SAFETY: made by `parts` for this product, freed once.
        unsafe { g.free() };
    }
    // SAFETY: the reference taken in `over`.
    unsafe { sys::MatDestroy(&mut product.jacobian) }
}

/// The context of a shell made by [`ThreadedOperator::over`].
///
/// # Safety
/// `shell` is such a shell.
unsafe fn context(shell: sys::Mat) -> std::result::Result<*mut c_void, sys::PetscErrorCode> {
    let mut ctx: *mut c_void = std::ptr::null_mut();
    // SAFETY: out-parameter (PETSc 3.18 takes the address of the context pointer as `void *`).
    let code = unsafe { sys::MatShellGetContext(shell, (&mut ctx as *mut *mut c_void).cast()) };
    if code != 0 || ctx.is_null() {
        return Err(if code != 0 { code } else { 1 });
    }
    Ok(ctx)
}

/// `MATOP_DESTROY`: frees the context when PETSc destroys the shell (its last reference).
unsafe extern "C" fn destroy(shell: sys::Mat) -> sys::PetscErrorCode {
    // SAFETY: PETSc calls this once, for our shell.
    match unsafe { context(shell) } {
        Ok(ctx) => unsafe { release(ctx) },
        Err(code) => code,
    }
}

/// `MATOP_MULT`: `y = J x` on the process's threads.
unsafe extern "C" fn multiply(
    shell: sys::Mat,
    x: sys::PetscVec,
    y: sys::PetscVec,
) -> sys::PetscErrorCode {
    // SAFETY: PETSc hands our shell and two vectors of its size for the duration of the call.
    let ctx = match unsafe { context(shell) } {
        Ok(c) => c,
        Err(code) => return code,
    };
    // SAFETY: the context lives as long as the shell.
    let product = unsafe { &*ctx.cast::<Product>() };
    let rows = &product.rows;
    let run = || -> std::result::Result<(), PetscError> {
        let n = rows.row_ptr.len().saturating_sub(1) * rows.bs;
        let nnz = rows.row_ptr.last().copied().unwrap_or(0) * rows.bs * rows.bs;
        let (mut xa, mut ya, mut va): (*const f64, *mut f64, *const f64) =
            (std::ptr::null(), std::ptr::null_mut(), std::ptr::null());
        let (forward, insert) = (
            sys::ScatterMode_SCATTER_FORWARD,
            sys::InsertMode_INSERT_VALUES,
        );
        if let Some(g) = &product.ghosts {
            // SAFETY: the scatter of `x`'s layout into the ghost values, ended below.
            check(
                unsafe { sys::VecScatterBegin(g.scatter, x, g.values, insert, forward) },
                "VecScatterBegin",
            )?;
        }
        // This process's rows: the Jacobian's (or its diagonal part's) values times `x`'s own entries.
        let mut local = || -> std::result::Result<(), PetscError> {
            // SAFETY: PETSc's arrays of the vectors and of the Jacobian's values, restored below; the
            // read accessors leave the Jacobian's state (and so its preconditioner) alone.
            unsafe {
                check(sys::VecGetArrayRead(x, &mut xa), "VecGetArrayRead")?;
                check(sys::VecGetArray(y, &mut ya), "VecGetArray")?;
                match rows.layout {
                    BlockLayout::Rows => check(
                        sys::MatSeqAIJGetArrayRead(product.local, &mut va),
                        "MatSeqAIJGetArrayRead",
                    )?,
                    BlockLayout::Blocks => {
                        let mut v: *mut f64 = std::ptr::null_mut();
                        check(
                            sys::MatSeqBAIJGetArray(product.local, &mut v),
                            "MatSeqBAIJGetArray",
                        )?;
                        va = v;
                    }
                }
                // A process without rows (or an empty part) may be handed null arrays: nothing to
                // multiply.
                if n > 0 && nnz > 0 {
                    let (xs, ys, vs) = (
                        std::slice::from_raw_parts(xa, n),
                        std::slice::from_raw_parts_mut(ya, n),
                        std::slice::from_raw_parts(va, nnz),
                    );
                    rows.apply(vs, xs, ys);
                } else if n > 0 {
                    std::slice::from_raw_parts_mut(ya, n).fill(0.0);
                }
                match rows.layout {
                    BlockLayout::Rows => check(
                        sys::MatSeqAIJRestoreArrayRead(product.local, &mut va),
                        "MatSeqAIJRestoreArrayRead",
                    )?,
                    BlockLayout::Blocks => {
                        // MatSeqBAIJRestoreArray does not mark the values changed (see fill_block_rows).
                        let mut v = va.cast_mut();
                        check(
                            sys::MatSeqBAIJRestoreArray(product.local, &mut v),
                            "MatSeqBAIJRestoreArray",
                        )?;
                    }
                }
                check(sys::VecRestoreArray(y, &mut ya), "VecRestoreArray")?;
                check(sys::VecRestoreArrayRead(x, &mut xa), "VecRestoreArrayRead")
            }
        };
        let done = local();
        if let Some(g) = &product.ghosts {
            // SAFETY: the scatter begun above, ended whether the local product failed or not (so that
            // the next product starts none while this one is in flight); then `y += off * ghosts`, as
            // `MatMult_MPIBAIJ` adds it.
            unsafe {
                check(
                    sys::VecScatterEnd(g.scatter, x, g.values, insert, forward),
                    "VecScatterEnd",
                )?;
                done?;
                check(sys::MatMultAdd(g.off, g.values, y, y), "MatMultAdd")?;
            }
            return Ok(());
        }
        done
    };
    match std::panic::catch_unwind(std::panic::AssertUnwindSafe(run)) {
        Ok(Ok(())) => 0,
        Ok(Err(e)) => e.code,
        Err(_) => 83, // PETSC_ERR_USER
    }
}

impl Rows {
    /// `y = J x` with the values `v` of the Jacobian, block rows in parallel, with the block size
    /// (2 to 4: [`ThreadedOperator::over`]) known to the compiler.
    fn apply(&self, v: &[f64], x: &[f64], y: &mut [f64]) {
        match self.bs {
            2 => self.apply_of::<2>(v, x, y),
            3 => self.apply_of::<3>(v, x, y),
            4 => self.apply_of::<4>(v, x, y),
            bs => unreachable!("block size {bs}: the operator is made for 2 to 4 only"),
        }
    }

    fn apply_of<const B: usize>(&self, v: &[f64], x: &[f64], y: &mut [f64]) {
        y.par_chunks_mut(CHUNK * B).enumerate().for_each(|(c, yc)| {
            for (l, yr) in yc.chunks_mut(B).enumerate() {
                let a = c * CHUNK + l;
                let (lo, hi) = (self.row_ptr[a], self.row_ptr[a + 1]);
                let (vals, cols) = (&v[lo * B * B..hi * B * B], &self.cols[lo..hi]);
                match self.layout {
                    BlockLayout::Blocks => block_row::<B>(vals, cols, x, yr),
                    BlockLayout::Rows => scalar_rows::<B>(vals, cols, x, yr),
                }
            }
        });
    }
}

/// One block row of column-major `B x B` blocks: `y_i = sum_blocks (sum_k V_ik x_k)`, each block's
/// contribution summed over `k` first and then added, as PETSc's `MatMult_SeqBAIJ_2/3/4` do.
#[inline(always)]
fn block_row<const B: usize>(vals: &[f64], cols: &[u32], x: &[f64], y: &mut [f64]) {
    let mut sum = [0.0; B];
    for (blk, &c) in vals.chunks_exact(B * B).zip(cols) {
        let c = c as usize * B;
        let xb: &[f64; B] = x[c..c + B].try_into().expect("a block of x");
        for (i, s) in sum.iter_mut().enumerate() {
            let mut t = blk[i] * xb[0];
            for k in 1..B {
                t += blk[k * B + i] * xb[k];
            }
            *s += t;
        }
    }
    y.copy_from_slice(&sum);
}

/// The `B` scalar rows of one block row stored row by row (row `i`: the blocks' row `i`, columns in
/// order), each a running sum as in PETSc's AIJ product.
#[inline(always)]
fn scalar_rows<const B: usize>(vals: &[f64], cols: &[u32], x: &[f64], y: &mut [f64]) {
    let n = cols.len();
    for (i, yi) in y.iter_mut().enumerate() {
        let row = &vals[i * n * B..(i + 1) * n * B];
        let mut s = 0.0;
        for (vb, &c) in row.chunks_exact(B).zip(cols) {
            let c = c as usize * B;
            let xb: &[f64; B] = x[c..c + B].try_into().expect("a block of x");
            for k in 0..B {
                s += vb[k] * xb[k];
            }
        }
        *yi = s;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The threaded product of a small block matrix in both layouts equals the dense product.
    #[test]
    fn block_rows_multiply_as_the_dense_matrix() {
        // 3 block rows of size 2; pattern: row 0 {0, 2}, row 1 {1}, row 2 {0, 1, 2}.
        let (bs, row_ptr, cols) = (2usize, vec![0usize, 2, 3, 6], vec![0u32, 2, 1, 0, 1, 2]);
        let dense = |r: usize, c: usize| -> f64 {
            let (a, b) = (r / bs, c / bs);
            let lo = row_ptr[a];
            if cols[lo..row_ptr[a + 1]].contains(&(b as u32)) {
                1.0 + (7 * r + 3 * c) as f64 * 0.25 - (r * c) as f64 * 0.1
            } else {
                0.0
            }
        };
        let x: Vec<f64> = (0..6).map(|i| 1.0 - 0.3 * i as f64).collect();
        let expect: Vec<f64> = (0..6)
            .map(|r| (0..6).map(|c| dense(r, c) * x[c]).sum())
            .collect();
        for layout in [BlockLayout::Blocks, BlockLayout::Rows] {
            let mut v = vec![0.0; 6 * bs * bs];
            for a in 0..3 {
                let n = row_ptr[a + 1] - row_ptr[a];
                for (pos, &b) in cols[row_ptr[a]..row_ptr[a + 1]].iter().enumerate() {
                    for i in 0..bs {
                        for k in 0..bs {
                            let off = row_ptr[a] * bs * bs + layout.offset(n, bs, i, pos, k);
                            v[off] = dense(a * bs + i, b as usize * bs + k);
                        }
                    }
                }
            }
            let p = Rows {
                layout,
                bs,
                row_ptr: row_ptr.clone(),
                cols: cols.clone(),
            };
            let mut y = vec![f64::NAN; 6];
            p.apply(&v, &x, &mut y);
            for (a, b) in y.iter().zip(&expect) {
                assert!(
                    (a - b).abs() < 1e-12,
                    "{layout:?}: {y:?} against {expect:?}"
                );
            }
        }
    }
}
