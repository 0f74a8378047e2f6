//! PETSc `Mat` (AIJ with a block size; `-mat_type` may override) assembled in coordinate (COO) form, and
//! index sets.
//!
//! Two ways to give the nonzero pattern once and the values many times:
//! - **block CSR** ([`BlockCsr`], [`Matrix::set_block_pattern`], [`Matrix::fill_block_rows`]): the exact
//!   pattern of the process's block rows, sorted, as the MPM assembler produces it from the node-particle
//!   incidence. On one process the AIJ matrix is made directly over its scalar CSR in Rust's arrays (no
//!   copy, no insertion) and BAIJ is preallocated from it and the pattern inserted once, block row by
//!   block row; the values are then written in place into the matrix's value array, in parallel and
//!   without a copy. On several processes (MPI AIJ) the process's rows are handed over as CSR and every
//!   fill is one `MatUpdateMPIAIJWithArray` (no sorting, no search); other matrix types (`-mat_type`)
//!   are preallocated from the pattern and filled row by row.
//! - **COO** ([`Matrix::set_pattern_coo`], [`Matrix::set_values_coo`]): (row, column) pairs with repeats
//!   summed and negative indices ignored; PETSc sorts them once. Simple for small problems (the smoke
//!   lattice).

use super::block_parts::SplitParts;
use super::{
    PetscError, PetscInt, Result, SessionGuard, Vector, check, comm_world, create, ownership_range,
    sys, to_petsc_int,
};

/// A PETSc matrix. Owned matrices are destroyed on drop; borrowed ones (callbacks) are not.
pub struct Matrix {
    pub(crate) raw: sys::Mat,
    owned: bool,
    coo_len: Option<usize>,
}

impl Matrix {
    /// Sets the block size (which divides the rows, checked by PETSc) and then the options
    /// (`-mat_type` ...).
    fn set_block_size_and_options(&self, block_size: usize) -> Result<()> {
        // SAFETY: valid matrix.
        check(
            unsafe { sys::MatSetBlockSize(self.raw, to_petsc_int(block_size, "MatSetBlockSize")?) },
            "MatSetBlockSize",
        )?;
        // SAFETY: valid matrix.
        check(
            unsafe { sys::MatSetFromOptions(self.raw) },
            "MatSetFromOptions",
        )
    }

    /// Takes ownership of a matrix PETSc made (destroyed on drop).
    pub(crate) fn from_raw(raw: sys::Mat) -> Self {
        Self {
            raw,
            owned: true,
            coo_len: None,
        }
    }

    /// A square matrix with `local_rows` rows on this process (a multiple of `block_size`), type AIJ
    /// with the block size set (GAMG/hypre accept it; `-mat_type baij` etc. override it).
    pub fn new(s: &SessionGuard, local_rows: usize, block_size: usize) -> Result<Self> {
        Self::with_type(s, local_rows, block_size, "aij")
    }

    /// As [`Matrix::new`] with another default type, e.g. `baij` (blocked kernels: faster ILU and
    /// triangular solves, but no GAMG and no field split across a block); `-mat_type` still overrides it.
    pub fn with_type(
        _s: &SessionGuard,
        local_rows: usize,
        block_size: usize,
        mat_type: &str,
    ) -> Result<Self> {
        let n = to_petsc_int(local_rows, "MatSetSizes")?;
        let decide = unsafe { sys::mpmc_petsc_decide() };
        // Later failures leave `m` to Drop.
        let m = Self::from_raw(create(sys::MatCreate, "MatCreate")?);
        check(
            unsafe { sys::MatSetSizes(m.raw, n, n, decide, decide) },
            "MatSetSizes",
        )?;
        let t = super::cstring(mat_type)?;
        check(unsafe { sys::MatSetType(m.raw, t.as_ptr()) }, "MatSetType")?;
        m.set_block_size_and_options(block_size)?;
        Ok(m)
    }

    /// A rectangular AIJ matrix of `local_rows` x `local_cols` on this process (row and column block size
    /// `block_size`) with the entries `(rows[k], cols[k], values[k])` in global indices (repeats summed),
    /// assembled: the interpolation between two levels of a multigrid. Its type is not taken from
    /// `-mat_type`, which is meant for the Jacobian.
    pub fn rectangular(
        _s: &SessionGuard,
        (local_rows, local_cols): (usize, usize),
        block_size: usize,
        rows: &[PetscInt],
        cols: &[PetscInt],
        values: &[f64],
    ) -> Result<Self> {
        let m = to_petsc_int(local_rows, "MatSetSizes")?;
        let n = to_petsc_int(local_cols, "MatSetSizes")?;
        let bs = to_petsc_int(block_size, "MatSetBlockSizes")?;
        let decide = unsafe { sys::mpmc_petsc_decide() };
        let mut mat = Self::from_raw(create(sys::MatCreate, "MatCreate")?);
        // SAFETY: valid matrix; sizes and block sizes checked by PETSc.
        check(
            unsafe { sys::MatSetSizes(mat.raw, m, n, decide, decide) },
            "MatSetSizes",
        )?;
        let t = super::cstring("aij")?;
        check(
            unsafe { sys::MatSetType(mat.raw, t.as_ptr()) },
            "MatSetType",
        )?;
        check(
            unsafe { sys::MatSetBlockSizes(mat.raw, bs, bs) },
            "MatSetBlockSizes",
        )?;
        mat.set_pattern_coo(rows, cols)?;
        mat.set_values_coo(values)?;
        Ok(mat)
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

    /// Declares the exact nonzero pattern of this process's block rows (see [`BlockCsr`]) and leaves the
    /// matrix assembled with zero values. The nonzero structure, and with it any symbolic factorisation,
    /// stays fixed while values change. By type:
    /// - `seqaij` (one process, a matrix this wrapper owns): the matrix is replaced by one made directly
    ///   over the scalar CSR of the pattern (`MatCreateSeqAIJWithArrays`: no copy, no insertion), in
    ///   arrays Rust allocates and the PETSc object owns (`CsrArrays`); the options database is applied
    ///   to it as to the first. The half-resolution CT's Jacobian (30,108 rows) in 8 ms instead of the 41
    ///   of `MatSeqAIJSetPreallocationCSR`.
    /// - `mpiaij`: the process's rows handed over as scalar CSR (`MatMPIAIJSetPreallocationCSR`).
    /// - `seqbaij` (the default under a point-block ILU): preallocated per block row
    ///   (`MatXAIJSetPreallocation`, which zeroes the values), the block columns of all rows copied in
    ///   at once (`MatSeqBAIJSetColumnIndices`), assembled: the half-resolution CT's Jacobian (10,300
    ///   block rows, 250,000 blocks of 3 x 3) created and structured in 2.6 ms instead of the 7.1 of
    ///   one `MatSetValuesBlocked` of zeros per block row (which searches every row for each block)
    ///   and the 11.7 of `MatSeqBAIJSetPreallocationCSR`, which inserts block by block
    ///   (`MatCreateSeqBAIJWithArrays` refuses block sizes above 1 in PETSc 3.18).
    /// - other types (`-mat_type` overrides): preallocated per block row, the pattern inserted as
    ///   zeros with one `MatSetValuesBlocked` per block row, assembled.
    pub fn set_block_pattern(&mut self, p: &BlockCsr<'_>) -> Result<()> {
        p.check()?;
        let kind = self.type_name()?;
        if kind == "seqaij" && self.owned {
            return self.replace_by_scalar_csr(p);
        }
        if kind == "mpiaij" {
            let what = "MatMPIAIJSetPreallocationCSR";
            let (i, j) = scalar_csr(p, what)?;
            // SAFETY: i has rows + 1 entries, j has i[rows]; PETSc copies both (null values = zeros)
            // and assembles.
            return check(
                unsafe {
                    sys::MatMPIAIJSetPreallocationCSR(
                        self.raw,
                        i.as_ptr(),
                        j.as_ptr(),
                        std::ptr::null(),
                    )
                },
                what,
            );
        }
        let own = p.first..p.first + p.block_rows();
        let (mut dnnz, mut onnz) = (Vec::new(), Vec::new());
        for a in 0..p.block_rows() {
            let cols = p.block_cols(a);
            let d = cols
                .iter()
                .filter(|&&b| own.contains(&(b as usize)))
                .count();
            dnnz.push(to_petsc_int(d, "MatXAIJSetPreallocation")?);
            onnz.push(to_petsc_int(cols.len() - d, "MatXAIJSetPreallocation")?);
        }
        // SAFETY: one count per block row; the upper-triangle counts are only needed for SBAIJ.
        check(
            unsafe {
                sys::MatXAIJSetPreallocation(
                    self.raw,
                    to_petsc_int(p.bs, "MatXAIJSetPreallocation")?,
                    dnnz.as_ptr(),
                    onnz.as_ptr(),
                    std::ptr::null(),
                    std::ptr::null(),
                )
            },
            "MatXAIJSetPreallocation",
        )?;
        if kind == "seqbaij" {
            let what = "MatSeqBAIJSetColumnIndices";
            let mut cols = p
                .cols
                .iter()
                .map(|&b| to_petsc_int(b as usize, what))
                .collect::<Result<Vec<_>>>()?;
            // SAFETY: the preallocation holds exactly `cols.len()` blocks, row after row, and `cols`
            // lists them in that order, ascending within each row; PETSc copies them.
            check(
                unsafe { sys::MatSeqBAIJSetColumnIndices(self.raw, cols.as_mut_ptr()) },
                what,
            )?;
        } else {
            let widest = (0..p.block_rows())
                .map(|a| p.block_cols(a).len())
                .max()
                .unwrap_or(0);
            let zeros = vec![0.0; widest * p.bs * p.bs];
            self.set_block_rows(p, |_| &zeros)?;
        }
        self.assemble()
    }

    /// The `seqaij` matrix made anew over the scalar CSR of `p` with zero values, in place of this one
    /// (see [`Matrix::set_block_pattern`]).
    fn replace_by_scalar_csr(&mut self, p: &BlockCsr<'_>) -> Result<()> {
        let what = "MatCreateSeqAIJWithArrays";
        let (i, j) = scalar_csr(p, what)?;
        let rows = to_petsc_int(i.len() - 1, what)?;
        let mut arrays = Box::new(CsrArrays {
            i,
            j,
            values: vec![0.0; p.nonzeros()],
        });
        let (pi, pj, pa) = (
            arrays.i.as_mut_ptr(),
            arrays.j.as_mut_ptr(),
            arrays.values.as_mut_ptr(),
        );
        // Declared before the matrix, so dropped after it on every path: the arrays outlive the matrix.
        let holder = CsrArrays::into_container(arrays)?;
        let mut m = Self::from_raw(std::ptr::null_mut());
        // SAFETY: pi has rows + 1 entries from 0, pj and pa i[rows] (columns sorted within each row); the
        // arrays stay where they are until the container frees them, after the matrix is destroyed.
        check(
            unsafe {
                sys::MatCreateSeqAIJWithArrays(comm_world(), rows, rows, pi, pj, pa, &mut m.raw)
            },
            what,
        )?;
        // SAFETY: both are valid objects; the matrix takes a reference to the container.
        check(
            unsafe {
                sys::PetscObjectCompose(m.raw.cast(), c"mpmc_csr_arrays".as_ptr(), holder.0.cast())
            },
            "PetscObjectCompose",
        )?;
        // `-mat_type` resolves to `seqaij` again, as it did for this one.
        m.set_block_size_and_options(p.bs)?;
        *self = m;
        Ok(())
    }

    /// Replaces all values of a matrix whose pattern was declared with [`Matrix::set_block_pattern`]:
    /// `fill` receives an array of [`BlockCsr::nonzeros`] values in the given [`BlockLayout`] and must
    /// write all of them. For `seqaij` and `seqbaij` this is the matrix's own value array (no copy); for
    /// other types a scratch array, then handed over with one `MatUpdateMPIAIJWithArray` (`mpiaij`),
    /// copied into the diagonal and off-diagonal parts (`mpibaij` whose parts hold the pattern, found
    /// at every fill: [`SplitParts::of`]) or inserted with `MatSetValuesBlocked` row by row. Leaves
    /// the matrix assembled.
    pub fn fill_block_rows(
        &mut self,
        p: &BlockCsr<'_>,
        fill: impl FnOnce(&mut [f64], BlockLayout),
    ) -> Result<()> {
        self.fill_block_rows_in(p, &mut Vec::new(), fill)
    }

    /// [`Matrix::fill_block_rows`] with the caller's `scratch` for the matrices that need one, kept
    /// from fill to fill (the paper-size CT's half on one of two processes: 38 MB).
    pub fn fill_block_rows_in(
        &mut self,
        p: &BlockCsr<'_>,
        scratch: &mut Vec<f64>,
        fill: impl FnOnce(&mut [f64], BlockLayout),
    ) -> Result<()> {
        let nnz = p.nonzeros();
        type Access = unsafe extern "C" fn(sys::Mat, *mut *mut f64) -> sys::PetscErrorCode;
        let direct: Option<(Access, Access, BlockLayout)> = match self.type_name()?.as_str() {
            "seqaij" => Some((
                sys::MatSeqAIJGetArray,
                sys::MatSeqAIJRestoreArray,
                BlockLayout::Rows,
            )),
            "seqbaij" => Some((
                sys::MatSeqBAIJGetArray,
                sys::MatSeqBAIJRestoreArray,
                BlockLayout::Blocks,
            )),
            _ => None,
        };
        let mpiaij = self.type_name()? == "mpiaij";
        if direct.is_some() || mpiaij {
            // PETSc reads or writes as many values as its structure holds: it must be the pattern's.
            let mut info = std::mem::MaybeUninit::<sys::MatInfo>::uninit();
            // SAFETY: out-parameter filled by PETSc.
            check(
                unsafe { sys::MatGetInfo(self.raw, sys::MatInfoType_MAT_LOCAL, info.as_mut_ptr()) },
                "MatGetInfo",
            )?;
            // SAFETY: initialised by the successful call above.
            let used = unsafe { info.assume_init() }.nz_used as usize;
            if used != nnz {
                return Err(PetscError {
                    code: 60,
                    call: "fill_block_rows",
                    message: format!(
                        "the matrix holds {used} nonzeros but its declared block pattern {nnz}"
                    ),
                });
            }
        }
        if let Some((get, restore, layout)) = direct {
            let mut a: *mut f64 = std::ptr::null_mut();
            // SAFETY: the array has nnz entries in the order of `layout` for the block pattern
            // (set_block_pattern built the structure from it); it is restored below.
            check(unsafe { get(self.raw, &mut a) }, "MatSeq*GetArray")?;
            fill(unsafe { std::slice::from_raw_parts_mut(a, nnz) }, layout);
            check(unsafe { restore(self.raw, &mut a) }, "MatSeq*RestoreArray")?;
            // MatSeqAIJRestoreArray marks the values changed; MatSeqBAIJRestoreArray does not, so
            // without an assembly the preconditioner would never be rebuilt for the new values (ILU
            // silently lagged across Newton iterations and steps) and the cached inverse of the block
            // diagonal (point-block Jacobi, SOR) would stay stale.
            return match layout {
                BlockLayout::Blocks => self.assemble(),
                BlockLayout::Rows => Ok(()),
            };
        }
        // The scratch's values are all overwritten: only a change of length writes to it here.
        scratch.resize(nnz, 0.0);
        let values = scratch.as_mut_slice();
        // SAFETY: a valid matrix.
        if let Some(parts) = unsafe { SplitParts::of(self.raw, p) }? {
            fill(values, BlockLayout::Blocks);
            parts.copy(p, values)?;
            // The parts' values changed behind PETSc's back (see the `seqbaij` case above): the
            // assembly marks them, and the matrix, changed.
            return self.assemble();
        }
        fill(values, BlockLayout::Rows);
        if mpiaij {
            // SAFETY: the CSR of set_block_pattern (sorted columns) has nnz values in this order.
            check(
                unsafe { sys::MatUpdateMPIAIJWithArray(self.raw, values.as_ptr()) },
                "MatUpdateMPIAIJWithArray",
            )?;
            return self.assemble();
        }
        let bs2 = p.bs * p.bs;
        self.set_block_rows(p, |a| &values[p.row_ptr[a] * bs2..p.row_ptr[a + 1] * bs2])?;
        self.assemble()
    }

    /// Inserts every block row of `p` with one `MatSetValuesBlocked`: `row(a)` gives block row `a`'s
    /// values, row-oriented (bs rows of `block_cols(a).len() * bs` values), at least that many.
    fn set_block_rows<'v>(
        &mut self,
        p: &BlockCsr<'_>,
        row: impl Fn(usize) -> &'v [f64],
    ) -> Result<()> {
        let what = "MatSetValuesBlocked";
        let mut cols: Vec<PetscInt> = Vec::new();
        for a in 0..p.block_rows() {
            let r = to_petsc_int(p.first + a, what)?;
            cols.clear();
            for &b in p.block_cols(a) {
                cols.push(to_petsc_int(b as usize, what)?);
            }
            let values = row(a);
            assert!(
                values.len() >= cols.len() * p.bs * p.bs,
                "{what}: short block row"
            );
            // SAFETY: one block row of cols.len() blocks; `values` holds its bs^2 cols.len() values.
            check(
                unsafe {
                    sys::MatSetValuesBlocked(
                        self.raw,
                        1,
                        &r,
                        to_petsc_int(cols.len(), what)?,
                        cols.as_ptr(),
                        values.as_ptr(),
                        sys::InsertMode_INSERT_VALUES,
                    )
                },
                what,
            )?;
        }
        Ok(())
    }

    /// The matrix type, e.g. `seqaij`, `mpiaij`, `seqbaij`.
    pub fn type_name(&self) -> Result<String> {
        let mut t: *const std::ffi::c_char = std::ptr::null();
        // SAFETY: PETSc returns a pointer to its own type-name string (or null before MatSetType).
        check(unsafe { sys::MatGetType(self.raw, &mut t) }, "MatGetType")?;
        Ok(if t.is_null() {
            String::new()
        } else {
            // SAFETY: non-null NUL-terminated string owned by PETSc.
            unsafe { std::ffi::CStr::from_ptr(t) }
                .to_string_lossy()
                .into_owned()
        })
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
        ownership_range(
            // SAFETY: out-parameters.
            |lo, hi| unsafe { sys::MatGetOwnershipRange(self.raw, lo, hi) },
            "MatGetOwnershipRange",
        )
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

/// How the values of a block row are ordered in the array handed to [`Matrix::fill_block_rows`]. In both,
/// block row `a` occupies `row_ptr[a] bs^2 .. row_ptr[a + 1] bs^2`; within it, for scalar row `i` of the
/// block row, block position `pos` (0-based within the row, `n` blocks) and component `k`:
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BlockLayout {
    /// CSR order of the scalar rows (AIJ): offset `i n bs + pos bs + k`.
    Rows,
    /// Block after block, each stored column by column (BAIJ): offset `pos bs^2 + k bs + i`.
    Blocks,
}

impl BlockLayout {
    /// Offset within a block row of `n` blocks of size `bs`.
    #[inline(always)]
    pub fn offset(self, n: usize, bs: usize, i: usize, pos: usize, k: usize) -> usize {
        match self {
            BlockLayout::Rows => (i * n + pos) * bs + k,
            BlockLayout::Blocks => (pos * bs + k) * bs + i,
        }
    }
}

/// The exact nonzero pattern of one process's block rows, as block CSR with `bs x bs` dense blocks.
///
/// Block row `a` (global block row `first + a`, scalar rows `(first + a) bs .. (first + a + 1) bs`) has the
/// global block columns `cols[row_ptr[a]..row_ptr[a + 1]]`, strictly ascending. Values are ordered as
/// [`BlockLayout`] says.
#[derive(Debug, Clone, Copy)]
pub struct BlockCsr<'a> {
    /// Global index of the first block row of this process.
    pub first: usize,
    /// Block size (unknowns per node).
    pub bs: usize,
    /// Row pointers into `cols` (block rows + 1 entries, starting at 0).
    pub row_ptr: &'a [usize],
    /// Global block column indices, ascending within each row.
    pub cols: &'a [u32],
}

impl BlockCsr<'_> {
    /// Where block row `a`'s columns of this process's own rows start and end among its columns:
    /// those before `lo` and from `hi` on belong to other processes.
    pub(super) fn own_columns(&self, a: usize) -> (usize, usize) {
        let cols = self.block_cols(a);
        let own = self.first..self.first + self.block_rows();
        (
            cols.partition_point(|&c| (c as usize) < own.start),
            cols.partition_point(|&c| (c as usize) < own.end),
        )
    }

    /// Number of block rows.
    pub fn block_rows(&self) -> usize {
        self.row_ptr.len().saturating_sub(1)
    }

    /// The block columns of block row `a`.
    pub fn block_cols(&self, a: usize) -> &[u32] {
        &self.cols[self.row_ptr[a]..self.row_ptr[a + 1]]
    }

    /// Number of scalar nonzeros.
    pub fn nonzeros(&self) -> usize {
        self.row_ptr.last().copied().unwrap_or(0) * self.bs * self.bs
    }

    fn check(&self) -> Result<()> {
        let bad = |message: String| {
            Err(PetscError {
                code: 60,
                call: "set_block_pattern",
                message,
            })
        };
        if self.bs == 0 || self.row_ptr.first() != Some(&0) {
            return bad(format!(
                "block size {} and row pointers starting at {:?}",
                self.bs,
                self.row_ptr.first()
            ));
        }
        if self.row_ptr.last() != Some(&self.cols.len()) {
            return bad("row pointers do not end at the number of columns".into());
        }
        for a in 0..self.block_rows() {
            if self.row_ptr[a] > self.row_ptr[a + 1]
                || !self.block_cols(a).windows(2).all(|w| w[0] < w[1])
            {
                return bad(format!("block row {a}: columns not strictly ascending"));
            }
        }
        Ok(())
    }
}

/// The scalar CSR of the block rows of `p`: row pointers from 0 and global columns, sorted within each
/// row (`what` names the PETSc call in errors).
fn scalar_csr(p: &BlockCsr<'_>, what: &'static str) -> Result<(Vec<PetscInt>, Vec<PetscInt>)> {
    let bs = p.bs;
    let mut i: Vec<PetscInt> = Vec::with_capacity(p.block_rows() * bs + 1);
    let mut j: Vec<PetscInt> = Vec::with_capacity(p.nonzeros());
    i.push(0);
    for a in 0..p.block_rows() {
        let cols = p.block_cols(a);
        for _ in 0..bs {
            for &b in cols {
                let c = b as usize * bs;
                for k in 0..bs {
                    j.push(to_petsc_int(c + k, what)?);
                }
            }
            i.push(to_petsc_int(j.len(), what)?);
        }
    }
    Ok((i, j))
}

/// The arrays a `seqaij` matrix is made over (`MatCreateSeqAIJWithArrays`), which PETSc neither copies
/// nor frees. They belong to a PETSc container composed with the matrix, so they are freed when PETSc
/// destroys the matrix, after its last reference (a SNES or preconditioner may hold one after the Rust
/// [`Matrix`] is gone) and never before.
struct CsrArrays {
    i: Vec<PetscInt>,
    j: Vec<PetscInt>,
    values: Vec<f64>,
}

/// One reference to a PETSc container, released on drop.
struct Container(sys::PetscContainer);

impl Drop for Container {
    fn drop(&mut self) {
        // SAFETY: we own this reference.
        unsafe { sys::PetscContainerDestroy(&mut self.0) };
    }
}

impl CsrArrays {
    /// A container that owns `arrays` (freed when its last reference goes).
    fn into_container(arrays: Box<Self>) -> Result<Container> {
        let c = Container(create(sys::PetscContainerCreate, "PetscContainerCreate")?);
        let ptr = Box::into_raw(arrays);
        // SAFETY: valid container; `ptr` is a leaked box, which the destructor reclaims once.
        let r = check(
            unsafe { sys::PetscContainerSetPointer(c.0, ptr.cast()) },
            "PetscContainerSetPointer",
        )
        .and_then(|()| {
            check(
                unsafe { sys::PetscContainerSetUserDestroy(c.0, Some(Self::destroy)) },
                "PetscContainerSetUserDestroy",
            )
        });
        if let Err(e) = r {
            // SAFETY: the container does not own the box without its destructor: reclaim it here.
            drop(unsafe { Box::from_raw(ptr) });
            return Err(e);
        }
        Ok(c)
    }

    /// The container's destructor.
    unsafe extern "C" fn destroy(ptr: *mut std::ffi::c_void) -> sys::PetscErrorCode {
        // SAFETY: `ptr` is the box leaked in `into_container`; PETSc calls this once, when the container
        // (and with it the matrix that held it) is destroyed.
        drop(unsafe { Box::from_raw(ptr.cast::<Self>()) });
        0
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

/// The storage of the Jacobian (`-mat_type` overrides it): under an ILU (`ilu`, or block Jacobi or
/// additive Schwarz with ILU on the blocks: the defaults of inertia-dominated steps in 2D and 3D, on any
/// number of processes) BAIJ, whose kernels work on the node's `bs x bs` blocks. On the first 200 steps of
/// the half-resolution CT at 4.3 m/s (38,900 points, 3 unknowns per node, one process) the factorisations
/// took 24.7 against 35.6 ms and a triangular solve 2.2 against 4.1 ms, for the same Krylov iterations
/// (2736 against 2737), and whole runs took 0.86x the time; on two processes (additive Schwarz, whose
/// overlapping blocks PETSc extracts as BAIJ too) the half-resolution CT's first 150 steps took 0.79x and
/// its whole run to 1 ms 0.80x the time, and the 3D demo's first 30 steps on one process 0.49-0.60x, with
/// the same iterations in the first steps (`docs/benchmarks.md`, "Block storage on several processes and
/// in 3D"). Block ILU(0) shifts a pivot only when it is exactly zero: in 5 of the
/// 1000 steps of that CT, after the crack branched, it failed where point ILU(0) passed and the fallback
/// solved the step (about 3 % of the run); docs/benchmarks.md, "Block storage for the CT's ILU".
/// Everywhere else AIJ with the block size set: GAMG, hypre and the field split need it.
pub fn matrix_type_for(pc: Option<&str>, sub_pc: Option<&str>) -> &'static str {
    let point_block_ilu = match pc {
        Some("ilu") => true,
        Some("bjacobi" | "asm") => sub_pc.is_none_or(|s| s == "ilu"),
        _ => false,
    };
    if point_block_ilu { "baij" } else { "aij" }
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

    /// Declares the indices to come in blocks of `bs` consecutive unknowns (e.g. the displacement
    /// components of a node), which a preconditioner of the sub-matrix may use (BoomerAMG then coarsens
    /// the components as separate functions).
    pub fn with_block_size(self, bs: usize) -> Result<Self> {
        // SAFETY: valid IS.
        check(
            unsafe { sys::ISSetBlockSize(self.raw, to_petsc_int(bs, "ISSetBlockSize")?) },
            "ISSetBlockSize",
        )?;
        Ok(self)
    }
}

impl Drop for IndexSet {
    fn drop(&mut self) {
        // SAFETY: we own the reference.
        unsafe { sys::ISDestroy(&mut self.raw) };
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn block_storage_only_under_a_point_block_ilu() {
        for pc in ["bjacobi", "asm"] {
            assert_eq!(matrix_type_for(Some(pc), None), "baij", "{pc}");
            assert_eq!(matrix_type_for(Some(pc), Some("ilu")), "baij", "{pc}");
            assert_eq!(matrix_type_for(Some(pc), Some("lu")), "aij", "{pc}");
        }
        assert_eq!(matrix_type_for(Some("ilu"), None), "baij");
        for pc in ["gamg", "hypre", "fieldsplit", "mg", "lu"] {
            assert_eq!(matrix_type_for(Some(pc), None), "aij", "{pc}");
        }
        assert_eq!(matrix_type_for(None, None), "aij");
    }
}
