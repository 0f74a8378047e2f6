//! PETSc `Mat` (AIJ with a block size; `-mat_type` may override) assembled in coordinate (COO) form, and
//! index sets.
//!
//! COO assembly fits per-particle contributions computed in parallel: the pattern (row, column pairs,
//! repeats allowed and summed, negative indices ignored) is given once with
//! [`Matrix::set_pattern_coo`] — exact preallocation — and every Newton iteration passes one value
//! array in the same order to [`Matrix::set_values_coo`].

use super::{
    PetscError, PetscInt, Result, SessionGuard, Vector, check, comm_world, sys, to_petsc_int,
};

/// A PETSc matrix. Owned matrices are destroyed on drop; borrowed ones (callbacks) are not.
pub struct Matrix {
    pub(crate) raw: sys::Mat,
    owned: bool,
    coo_len: Option<usize>,
}

impl Matrix {
    /// A square matrix with `local_rows` rows on this process (a multiple of `block_size`), type AIJ
    /// with the block size set (GAMG/hypre accept it; `-mat_type baij` etc. override it).
    pub fn new(_s: &SessionGuard, local_rows: usize, block_size: usize) -> Result<Self> {
        let mut raw = std::ptr::null_mut();
        let n = to_petsc_int(local_rows, "MatSetSizes")?;
        let decide = unsafe { sys::mpmc_petsc_decide() };
        // SAFETY: out-parameter; later failures leave `m` to Drop.
        check(
            unsafe { sys::MatCreate(comm_world(), &mut raw) },
            "MatCreate",
        )?;
        let m = Self {
            raw,
            owned: true,
            coo_len: None,
        };
        check(
            unsafe { sys::MatSetSizes(m.raw, n, n, decide, decide) },
            "MatSetSizes",
        )?;
        check(
            unsafe { sys::MatSetType(m.raw, c"aij".as_ptr()) },
            "MatSetType",
        )?;
        check(
            unsafe { sys::MatSetBlockSize(m.raw, to_petsc_int(block_size, "MatSetBlockSize")?) },
            "MatSetBlockSize",
        )?;
        check(
            unsafe { sys::MatSetFromOptions(m.raw) },
            "MatSetFromOptions",
        )?;
        Ok(m)
    }

    /// Wraps a matrix PETSc owns (callbacks) without taking ownership.
    ///
    /// # Safety
    /// `raw` must be valid for the lifetime of the returned value.
    pub(crate) unsafe fn borrowed(raw: sys::Mat) -> Self {
        Self {
            raw,
            owned: false,
            coo_len: None,
        }
    }

    /// Declares the nonzero pattern as coordinate pairs (global indices; repeats are summed; a negative
    /// row or column drops the entry, e.g. for constrained unknowns). This is the exact preallocation;
    /// the matrix then accepts values through [`Matrix::set_values_coo`] in the same order.
    pub fn set_pattern_coo(&mut self, rows: &[PetscInt], cols: &[PetscInt]) -> Result<()> {
        if rows.len() != cols.len() {
            return Err(PetscError {
                code: 60,
                call: "MatSetPreallocationCOO",
                message: format!("{} rows but {} columns", rows.len(), cols.len()),
            });
        }
        // PETSc may modify the index arrays: hand it copies.
        let mut i = rows.to_vec();
        let mut j = cols.to_vec();
        // SAFETY: both arrays have rows.len() entries and live for the call.
        check(
            unsafe {
                sys::MatSetPreallocationCOO(
                    self.raw,
                    rows.len() as sys::PetscCount,
                    i.as_mut_ptr(),
                    j.as_mut_ptr(),
                )
            },
            "MatSetPreallocationCOO",
        )?;
        self.coo_len = Some(rows.len());
        Ok(())
    }

    /// Replaces all values: `values[k]` belongs to the k-th pair of the COO pattern (summed over
    /// repeats). Assembles the matrix.
    pub fn set_values_coo(&mut self, values: &[f64]) -> Result<()> {
        if let Some(n) = self.coo_len
            && n != values.len()
        {
            return Err(PetscError {
                code: 60,
                call: "MatSetValuesCOO",
                message: format!(
                    "pattern has {n} entries but {} values were given",
                    values.len()
                ),
            });
        }
        // SAFETY: values has as many entries as the pattern (checked when known).
        check(
            unsafe {
                sys::MatSetValuesCOO(self.raw, values.as_ptr(), sys::InsertMode_INSERT_VALUES)
            },
            "MatSetValuesCOO",
        )
    }

    /// Finishes assembly (needed after operations other than COO, and for matrix-free operators).
    pub fn assemble(&mut self) -> Result<()> {
        let fin = sys::MatAssemblyType_MAT_FINAL_ASSEMBLY;
        // SAFETY: valid matrix.
        check(
            unsafe { sys::MatAssemblyBegin(self.raw, fin) },
            "MatAssemblyBegin",
        )?;
        check(
            unsafe { sys::MatAssemblyEnd(self.raw, fin) },
            "MatAssemblyEnd",
        )
    }

    /// `y = A x`.
    pub fn mult(&self, x: &Vector, y: &mut Vector) -> Result<()> {
        // SAFETY: compatible layouts are checked by PETSc.
        check(unsafe { sys::MatMult(self.raw, x.raw, y.raw) }, "MatMult")
    }

    /// Rows `[start, end)` owned by this process.
    pub fn ownership_range(&self) -> Result<std::ops::Range<usize>> {
        let (mut lo, mut hi) = (0, 0);
        // SAFETY: out-parameters.
        check(
            unsafe { sys::MatGetOwnershipRange(self.raw, &mut lo, &mut hi) },
            "MatGetOwnershipRange",
        )?;
        Ok(lo as usize..hi as usize)
    }

    /// Attaches the near-null space given by the vectors (e.g. the rigid-body modes of the displacement
    /// field) for algebraic multigrid (GAMG, hypre). The vectors are orthonormalised here.
    pub fn set_near_null_space(&mut self, vectors: &mut [Vector]) -> Result<()> {
        orthonormalise(vectors)?;
        let raws: Vec<sys::PetscVec> = vectors.iter().map(|v| v.raw).collect();
        let mut ns: sys::MatNullSpace = std::ptr::null_mut();
        // SAFETY: raws holds valid vectors; PETSc takes references.
        check(
            unsafe {
                sys::MatNullSpaceCreate(
                    comm_world(),
                    sys::PetscBool_PETSC_FALSE,
                    to_petsc_int(raws.len(), "MatNullSpaceCreate")?,
                    raws.as_ptr(),
                    &mut ns,
                )
            },
            "MatNullSpaceCreate",
        )?;
        let r = check(
            unsafe { sys::MatSetNearNullSpace(self.raw, ns) },
            "MatSetNearNullSpace",
        );
        // SAFETY: drops our reference; the matrix keeps its own.
        unsafe { sys::MatNullSpaceDestroy(&mut ns) };
        r
    }
}

/// Gram-Schmidt (twice) so PETSc accepts the vectors as an orthonormal basis.
fn orthonormalise(vectors: &mut [Vector]) -> Result<()> {
    for i in 0..vectors.len() {
        let (done, rest) = vectors.split_at_mut(i);
        let v = &mut rest[0];
        for _ in 0..2 {
            for u in done.iter() {
                let d = v.dot(u)?;
                v.axpy(-d, u)?;
            }
        }
        let n = v.norm2()?;
        if n > 0.0 {
            v.scale(1.0 / n)?;
        }
    }
    Ok(())
}

impl Drop for Matrix {
    fn drop(&mut self) {
        if self.owned && !self.raw.is_null() {
            // SAFETY: we own the reference.
            unsafe { sys::MatDestroy(&mut self.raw) };
        }
    }
}

/// A PETSc index set of global indices, e.g. the unknowns of one field for `-pc_type fieldsplit`.
pub struct IndexSet {
    pub(crate) raw: sys::IS,
}

impl IndexSet {
    /// The given global indices (owned by this process).
    pub fn new(_s: &SessionGuard, indices: &[PetscInt]) -> Result<Self> {
        let mut raw = std::ptr::null_mut();
        // SAFETY: PETSc copies the indices.
        check(
            unsafe {
                sys::ISCreateGeneral(
                    comm_world(),
                    to_petsc_int(indices.len(), "ISCreateGeneral")?,
                    indices.as_ptr(),
                    sys::PetscCopyMode_PETSC_COPY_VALUES,
                    &mut raw,
                )
            },
            "ISCreateGeneral",
        )?;
        Ok(Self { raw })
    }
}

impl Drop for IndexSet {
    fn drop(&mut self) {
        // SAFETY: we own the reference.
        unsafe { sys::ISDestroy(&mut self.raw) };
    }
}
