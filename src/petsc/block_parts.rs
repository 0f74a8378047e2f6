//! The diagonal and off-diagonal parts of an `mpibaij` matrix (`MatMPIBAIJGetSeqBAIJ`), through which
//! [`Matrix::fill_block_rows`](super::Matrix::fill_block_rows) writes a process's block rows, and the
//! block pattern of a block-storage matrix as PETSc keeps it (`MatGetRowIJ`).

use super::{BlockCsr, PetscError, PetscInt, Result, check, sys};

/// The diagonal part (the columns of the process's own rows, as local indices) and the off-diagonal
/// part (the others, compressed through `garray`) of an `mpibaij` matrix, found to hold its block
/// pattern split at the process's block columns, with their numbers of blocks.
pub(super) struct SplitParts {
    diag: sys::Mat,
    off: sys::Mat,
    diag_blocks: usize,
    off_blocks: usize,
}

impl SplitParts {
    /// The parts of `m` if it is an `mpibaij` matrix whose parts hold the block pattern `p` split at this
    /// process's block columns: in each block row the diagonal part the columns in
    /// `p.first..p.first + p.block_rows()`, the off-diagonal part the others, in the same order (its
    /// compressed columns mapping to them through `garray`). `None` otherwise.
    ///
    /// # Safety
    /// `m` is a valid matrix; the parts are used while it lives and keeps its structure.
    pub(super) unsafe fn of(m: sys::Mat, p: &BlockCsr<'_>) -> Result<Option<Self>> {
        let mut kind: *const std::ffi::c_char = std::ptr::null();
        // SAFETY: PETSc's own type-name string (or null before MatSetType).
        check(unsafe { sys::MatGetType(m, &mut kind) }, "MatGetType")?;
        // SAFETY: null or a NUL-terminated string owned by PETSc.
        if kind.is_null() || unsafe { std::ffi::CStr::from_ptr(kind) }.to_bytes() != b"mpibaij" {
            return Ok(None);
        }
        let (mut diag, mut off, mut garray): (sys::Mat, sys::Mat, *const PetscInt) =
            (std::ptr::null_mut(), std::ptr::null_mut(), std::ptr::null());
        // SAFETY: out-parameters; the parts and `garray` belong to the matrix.
        check(
            unsafe { sys::MatMPIBAIJGetSeqBAIJ(m, &mut diag, &mut off, &mut garray) },
            "MatMPIBAIJGetSeqBAIJ",
        )?;
        // The off-diagonal part's columns are `garray`'s entries (one per block column of the part).
        let (mut rows_off, mut n, mut bs) = (0, 0, 0);
        // SAFETY: out-parameters of a valid matrix.
        check(
            unsafe { sys::MatGetLocalSize(off, &mut rows_off, &mut n) },
            "MatGetLocalSize",
        )?;
        // SAFETY: as above.
        check(
            unsafe { sys::MatGetBlockSize(off, &mut bs) },
            "MatGetBlockSize",
        )?;
        if usize::try_from(bs).ok() != Some(p.bs) {
            return Ok(None);
        }
        let compressed = usize::try_from(n).unwrap_or(0) / p.bs.max(1);
        if compressed > 0 && garray.is_null() {
            return Ok(None);
        }
        let global: &[PetscInt] = if compressed == 0 {
            &[]
        } else {
            // SAFETY: `garray` lists the global block column of each of the part's `compressed` columns.
            unsafe { std::slice::from_raw_parts(garray, compressed) }
        };
        let rows = p.block_rows();
        // Each part's blocks if every row holds the pattern's share: `map(l)` is the pattern's column of
        // the part's column `l`, `share(a)` the pattern's columns of row `a` that the part holds (in
        // two runs).
        type Share<'a> = dyn Fn(usize) -> (&'a [u32], &'a [u32]) + 'a;
        let blocks =
            |part: sys::Mat, map: &dyn Fn(PetscInt) -> Option<usize>, share: &Share<'_>| {
                // SAFETY: the parts are `seqbaij` matrices of the valid matrix `m`.
                unsafe {
                    with_block_pattern(part, |ia, ja| {
                        (ia.len() == rows + 1
                            && (0..rows).all(|a| {
                                let mine = &ja[ia[a] as usize..ia[a + 1] as usize];
                                let (first, second) = share(a);
                                mine.len() == first.len() + second.len()
                                    && mine
                                        .iter()
                                        .zip(first.iter().chain(second))
                                        .all(|(&l, &c)| map(l) == Some(c as usize))
                            }))
                        .then(|| ia[rows] as usize)
                    })
                }
            };
        let diag_blocks = blocks(
            diag,
            &|l| usize::try_from(l).ok().map(|l| l + p.first),
            &|a| {
                let (lo, hi) = p.own_columns(a);
                (&p.block_cols(a)[lo..hi], &[])
            },
        )?;
        let off_blocks = blocks(
            off,
            &|l| {
                usize::try_from(l)
                    .ok()
                    .and_then(|l| global.get(l))
                    .map(|&g| g as usize)
            },
            &|a| {
                let (lo, hi) = p.own_columns(a);
                let cols = p.block_cols(a);
                (&cols[..lo], &cols[hi..])
            },
        )?;
        let (Some(Some(diag_blocks)), Some(Some(off_blocks))) = (diag_blocks, off_blocks) else {
            return Ok(None);
        };
        Ok(Some(Self {
            diag,
            off,
            diag_blocks,
            off_blocks,
        }))
    }

    /// Copies the block rows `values` of the pattern `p` (in
    /// [`BlockLayout::Blocks`](super::BlockLayout::Blocks)) into the two parts: each row's own columns
    /// into the diagonal part, the columns before and after them into the off-diagonal part.
    pub(super) fn copy(&self, p: &BlockCsr<'_>, values: &[f64]) -> Result<()> {
        let bs2 = p.bs * p.bs;
        if values.len() != (self.diag_blocks + self.off_blocks) * bs2 {
            return Err(PetscError {
                code: 60,
                call: "fill_block_rows",
                message: format!(
                    "{} values for parts of {} and {} blocks of {bs2}",
                    values.len(),
                    self.diag_blocks,
                    self.off_blocks
                ),
            });
        }
        let row = |a: usize| {
            let (lo, hi) = p.own_columns(a);
            let row = &values[p.row_ptr[a] * bs2..p.row_ptr[a + 1] * bs2];
            (&row[..lo * bs2], &row[lo * bs2..hi * bs2], &row[hi * bs2..])
        };
        // SAFETY: `of` found the parts to hold these numbers of blocks.
        unsafe {
            with_values(self.diag, self.diag_blocks * bs2, |out| {
                let mut at = 0;
                for a in 0..p.block_rows() {
                    let (_, mid, _) = row(a);
                    out[at..at + mid.len()].copy_from_slice(mid);
                    at += mid.len();
                }
            })?;
            with_values(self.off, self.off_blocks * bs2, |out| {
                let mut at = 0;
                for a in 0..p.block_rows() {
                    let (left, _, right) = row(a);
                    for part in [left, right] {
                        out[at..at + part.len()].copy_from_slice(part);
                        at += part.len();
                    }
                }
            })
        }
    }
}

/// `f` of the `len` values of a `seqbaij` matrix, written where PETSc keeps them. PETSc does not mark
/// the values changed: the caller assembles the matrix (or its parent) afterwards.
///
/// # Safety
/// `m` is a valid `seqbaij` matrix holding `len` values.
unsafe fn with_values(m: sys::Mat, len: usize, f: impl FnOnce(&mut [f64])) -> Result<()> {
    let mut a: *mut f64 = std::ptr::null_mut();
    // SAFETY: the caller's promise; the array is restored below.
    check(
        unsafe { sys::MatSeqBAIJGetArray(m, &mut a) },
        "MatSeqBAIJGetArray",
    )?;
    if len > 0 {
        // SAFETY: `len` values at `a` until restored (an empty part may give a null array).
        f(unsafe { std::slice::from_raw_parts_mut(a, len) });
    }
    // SAFETY: restoring the array taken above.
    check(
        unsafe { sys::MatSeqBAIJRestoreArray(m, &mut a) },
        "MatSeqBAIJRestoreArray",
    )
}

/// The block pattern (row pointers, block columns) of a block-storage matrix, `None` if PETSc does not
/// give it.
///
/// # Safety
/// `m` is a valid `seqbaij` matrix.
pub(super) unsafe fn block_pattern(m: sys::Mat) -> Result<Option<(Vec<usize>, Vec<u32>)>> {
    // SAFETY: the caller's promise.
    unsafe {
        with_block_pattern(m, |ia, ja| {
            (
                ia.iter().map(|&i| i as usize).collect::<Vec<_>>(),
                ja.iter().map(|&j| j as u32).collect::<Vec<_>>(),
            )
        })
    }
}

/// `f` of the block CSR arrays (row pointers, block columns) of a block-storage matrix, read where
/// PETSc keeps them (`MatGetRowIJ` with block compression); `None` if PETSc does not give them.
///
/// # Safety
/// `m` is a valid `seqbaij` matrix.
unsafe fn with_block_pattern<T>(
    m: sys::Mat,
    f: impl FnOnce(&[PetscInt], &[PetscInt]) -> T,
) -> Result<Option<T>> {
    // SAFETY: the caller's promise.
    unsafe { with_row_ij(m, true, f) }
}

/// `f` of the CSR arrays (row pointers, columns) of a sequential matrix as `MatGetRowIJ` gives them:
/// with `compressed` a block matrix's block arrays, without it the scalar arrays of a `seqaij` matrix;
/// `None` if PETSc does not give them.
///
/// # Safety
/// `m` is a valid `seqbaij` (compressed) or `seqaij` matrix.
pub(super) unsafe fn with_row_ij<T>(
    m: sys::Mat,
    compressed: bool,
    f: impl FnOnce(&[PetscInt], &[PetscInt]) -> T,
) -> Result<Option<T>> {
    let (mut n, mut ia, mut ja, mut done): (
        sys::PetscInt,
        *const sys::PetscInt,
        *const sys::PetscInt,
        sys::PetscBool,
    ) = (
        0,
        std::ptr::null(),
        std::ptr::null(),
        sys::PetscBool_PETSC_FALSE,
    );
    let (no, yes) = (sys::PetscBool_PETSC_FALSE, sys::PetscBool_PETSC_TRUE);
    let blocks = if compressed { yes } else { no };
    // SAFETY: out-parameters; with block compression a block matrix gives its own block CSR arrays,
    // returned below.
    check(
        unsafe { sys::MatGetRowIJ(m, 0, no, blocks, &mut n, &mut ia, &mut ja, &mut done) },
        "MatGetRowIJ",
    )?;
    if done != yes || ia.is_null() || n < 0 {
        return Ok(None);
    }
    let rows = n as usize;
    // SAFETY: `rows + 1` row pointers and `ia[rows]` columns, valid until restored.
    let out = unsafe {
        let ia = std::slice::from_raw_parts(ia, rows + 1);
        let ja: &[PetscInt] = if ia[rows] == 0 {
            &[]
        } else {
            std::slice::from_raw_parts(ja, ia[rows] as usize)
        };
        f(ia, ja)
    };
    // SAFETY: as above.
    check(
        unsafe { sys::MatRestoreRowIJ(m, 0, no, blocks, &mut n, &mut ia, &mut ja, &mut done) },
        "MatRestoreRowIJ",
    )?;
    Ok(Some(out))
}
