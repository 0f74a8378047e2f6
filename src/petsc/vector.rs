//! PETSc `Vec` (called `PetscVec` in the bindings): distributed vectors with a block size.

use super::{
    PetscError, PetscInt, Result, SessionGuard, check, count_gathered, count_sent, create,
    ownership_range, sys, to_petsc_int,
};
use std::ops::Range;

/// A PETSc vector. Owned vectors are destroyed on drop; borrowed ones (handed to SNES callbacks) are not.
pub struct Vector {
    pub(crate) raw: sys::PetscVec,
    owned: bool,
}

/// A PETSc call that lends out (or takes back) the local array of a vector, with its name for errors.
type ArrayCall<P> = (
    unsafe extern "C" fn(sys::PetscVec, *mut P) -> sys::PetscErrorCode,
    &'static str,
);

impl Vector {
    /// A vector on PETSc's world communicator with `local` entries on this process (a multiple of
    /// `block_size`), e.g. 3 unknowns (u_x, u_y, eta_bar) per grid node.
    pub fn new(_s: &SessionGuard, local: usize, block_size: usize) -> Result<Self> {
        let n = to_petsc_int(local, "VecSetSizes")?;
        // Later failures leave `v` to Drop.
        let raw = create(sys::VecCreate, "VecCreate")?;
        let v = Self { raw, owned: true };
        check(
            unsafe { sys::VecSetSizes(v.raw, n, sys::mpmc_petsc_decide()) },
            "VecSetSizes",
        )?;
        check(
            unsafe { sys::VecSetBlockSize(v.raw, to_petsc_int(block_size, "VecSetBlockSize")?) },
            "VecSetBlockSize",
        )?;
        check(
            unsafe { sys::VecSetFromOptions(v.raw) },
            "VecSetFromOptions",
        )?;
        Ok(v)
    }

    /// Wraps a vector PETSc owns (e.g. inside a callback) without taking ownership.
    ///
    /// # Safety
    /// `raw` must be a valid vector for the lifetime of the returned value.
    pub(crate) unsafe fn borrowed(raw: sys::PetscVec) -> Self {
        Self { raw, owned: false }
    }

    /// A new vector with the same layout (values not copied).
    pub fn duplicate(&self) -> Result<Self> {
        let mut raw = std::ptr::null_mut();
        // SAFETY: self.raw is valid.
        check(
            unsafe { sys::VecDuplicate(self.raw, &mut raw) },
            "VecDuplicate",
        )?;
        Ok(Self { raw, owned: true })
    }

    /// Sets every entry to `alpha`.
    pub fn set_all(&mut self, alpha: f64) -> Result<()> {
        // SAFETY: valid vector.
        check(unsafe { sys::VecSet(self.raw, alpha) }, "VecSet")
    }

    /// Global size.
    pub fn global_size(&self) -> Result<usize> {
        let mut n = 0;
        // SAFETY: out-parameter.
        check(unsafe { sys::VecGetSize(self.raw, &mut n) }, "VecGetSize")?;
        Ok(n as usize)
    }

    /// Range `[start, end)` of global indices owned by this process.
    pub fn ownership_range(&self) -> Result<std::ops::Range<usize>> {
        ownership_range(
            // SAFETY: out-parameters.
            |lo, hi| unsafe { sys::VecGetOwnershipRange(self.raw, lo, hi) },
            "VecGetOwnershipRange",
        )
    }

    /// Euclidean norm.
    pub fn norm2(&self) -> Result<f64> {
        let mut r = 0.0;
        // SAFETY: out-parameter.
        check(
            unsafe { sys::VecNorm(self.raw, sys::NormType_NORM_2, &mut r) },
            "VecNorm",
        )?;
        Ok(r)
    }

    /// Copies the entries of `x` into `self` (same layout).
    pub fn copy_from(&mut self, x: &Vector) -> Result<()> {
        // SAFETY: both valid, same layout (checked by PETSc).
        check(unsafe { sys::VecCopy(x.raw, self.raw) }, "VecCopy")
    }

    /// `self += alpha * x`.
    pub fn axpy(&mut self, alpha: f64, x: &Vector) -> Result<()> {
        // SAFETY: both valid, same layout (checked by PETSc).
        check(unsafe { sys::VecAXPY(self.raw, alpha, x.raw) }, "VecAXPY")
    }

    /// Global dot product `self . other`.
    pub fn dot(&self, other: &Vector) -> Result<f64> {
        let mut r = 0.0;
        // SAFETY: both valid; out-parameter.
        check(
            unsafe { sys::VecDot(self.raw, other.raw, &mut r) },
            "VecDot",
        )?;
        Ok(r)
    }

    /// `self *= alpha`.
    pub fn scale(&mut self, alpha: f64) -> Result<()> {
        // SAFETY: valid vector.
        check(unsafe { sys::VecScale(self.raw, alpha) }, "VecScale")
    }

    /// Read access to the locally owned entries.
    pub fn read<R>(&self, f: impl FnOnce(&[f64]) -> R) -> Result<R> {
        let get: ArrayCall<*const f64> = (sys::VecGetArrayRead, "VecGetArrayRead");
        let restore: ArrayCall<*const f64> = (sys::VecRestoreArrayRead, "VecRestoreArrayRead");
        self.with_array(get, restore, std::ptr::null(), |ptr, n| {
            // SAFETY: `ptr` points to the `n` local values until the array is restored.
            f(if n == 0 {
                &[]
            } else {
                unsafe { std::slice::from_raw_parts(ptr, n) }
            })
        })
    }

    /// Write access to the locally owned entries.
    pub fn write<R>(&mut self, f: impl FnOnce(&mut [f64]) -> R) -> Result<R> {
        let get: ArrayCall<*mut f64> = (sys::VecGetArray, "VecGetArray");
        let restore: ArrayCall<*mut f64> = (sys::VecRestoreArray, "VecRestoreArray");
        self.with_array(get, restore, std::ptr::null_mut(), |ptr, n| {
            // SAFETY: as in `read`, with exclusive access guaranteed by &mut self.
            f(if n == 0 {
                &mut []
            } else {
                unsafe { std::slice::from_raw_parts_mut(ptr, n) }
            })
        })
    }

    /// Takes the local array with `get`, hands its pointer and length to `f` and gives the array back
    /// with `restore` (`null`: the pointer's initial value).
    fn with_array<P: Copy, R>(
        &self,
        get: ArrayCall<P>,
        restore: ArrayCall<P>,
        null: P,
        f: impl FnOnce(P, usize) -> R,
    ) -> Result<R> {
        let n = self.local_size()?;
        let mut ptr = null;
        // SAFETY: valid vector; PETSc returns a pointer to n contiguous values, valid until restored.
        check(unsafe { (get.0)(self.raw, &mut ptr) }, get.1)?;
        let r = f(ptr, n);
        // SAFETY: gives back the pointer taken above.
        check(unsafe { (restore.0)(self.raw, &mut ptr) }, restore.1)?;
        Ok(r)
    }

    /// Number of locally owned entries.
    pub fn local_size(&self) -> Result<usize> {
        let mut n = 0;
        // SAFETY: out-parameter.
        check(
            unsafe { sys::VecGetLocalSize(self.raw, &mut n) },
            "VecGetLocalSize",
        )?;
        Ok(n as usize)
    }

    /// Adds `values` at global `indices` (entries owned by other processes are communicated at
    /// [`Vector::assemble`]); negative indices are skipped (e.g. constrained unknowns).
    pub fn add_values(&mut self, indices: &[PetscInt], values: &[f64]) -> Result<()> {
        if indices.len() != values.len() {
            return Err(PetscError {
                code: 60,
                call: "VecSetValues",
                message: format!("{} indices but {} values", indices.len(), values.len()),
            });
        }
        // Debian's PETSc is built without debugging checks: an index past the end would corrupt memory,
        // and negative indices are only skipped with VEC_IGNORE_NEGATIVE_INDICES. Check the range and
        // pass the runs of non-negative indices.
        let size = self.global_size()?;
        if let Some(bad) = indices.iter().find(|&&i| i >= 0 && i as usize >= size) {
            return Err(PetscError {
                code: 63,
                call: "VecSetValues",
                message: format!("index {bad} out of range for a vector of size {size}"),
            });
        }
        let mut start = 0;
        while start < indices.len() {
            if indices[start] < 0 {
                start += 1;
                continue;
            }
            let len = indices[start..].iter().take_while(|&&i| i >= 0).count();
            let n = to_petsc_int(len, "VecSetValues")?;
            // SAFETY: the run has len in-range indices and as many values.
            check(
                unsafe {
                    sys::VecSetValues(
                        self.raw,
                        n,
                        indices[start..].as_ptr(),
                        values[start..].as_ptr(),
                        sys::InsertMode_ADD_VALUES,
                    )
                },
                "VecSetValues",
            )?;
            start += len;
        }
        Ok(())
    }

    /// Completes [`Vector::add_values`].
    pub fn assemble(&mut self) -> Result<()> {
        // SAFETY: valid vector.
        check(
            unsafe { sys::VecAssemblyBegin(self.raw) },
            "VecAssemblyBegin",
        )?;
        check(unsafe { sys::VecAssemblyEnd(self.raw) }, "VecAssemblyEnd")
    }

    /// All entries of the (possibly distributed) vector on every process, in global order.
    pub fn gather_all(&self) -> Result<Vec<f64>> {
        GatherAll::new(self)?.gather(self)
    }
}

/// A reusable gather of every entry of distributed vectors of one layout on every process
/// (`VecScatterCreateToAll` once, then one scatter per [`GatherAll::gather`]).
pub struct GatherAll {
    scatter: sys::VecScatter,
    all: Vector,
    /// Bytes this process sends per gather: its entries, to every other process.
    sent: usize,
}

impl GatherAll {
    /// The gather for vectors laid out like `like`.
    pub fn new(like: &Vector) -> Result<Self> {
        // SAFETY: PETSc is initialised while a vector exists.
        let others = unsafe { sys::mpmc_world_size() } as usize - 1;
        let sent = like.ownership_range()?.len() * others * std::mem::size_of::<f64>();
        let mut scatter: sys::VecScatter = std::ptr::null_mut();
        let mut all: sys::PetscVec = std::ptr::null_mut();
        // SAFETY: creates a sequential vector of the global size and a scatter into it, both owned here.
        check(
            unsafe { sys::VecScatterCreateToAll(like.raw, &mut scatter, &mut all) },
            "VecScatterCreateToAll",
        )?;
        Ok(Self {
            scatter,
            all: Vector {
                raw: all,
                owned: true,
            },
            sent,
        })
    }

    /// Every entry of `x` (laid out as the vector this gather was made for), in global order.
    pub fn gather(&self, x: &Vector) -> Result<Vec<f64>> {
        scatter_forward(self.scatter, x, &self.all)?;
        count_sent(self.sent);
        self.all.read(|s| s.to_vec())
    }
}

/// Runs `scatter` forward from `x` into `to`, inserting.
fn scatter_forward(scatter: sys::VecScatter, x: &Vector, to: &Vector) -> Result<()> {
    let forward = sys::ScatterMode_SCATTER_FORWARD;
    let insert = sys::InsertMode_INSERT_VALUES;
    // SAFETY: the caller's scatter maps vectors of x's layout into `to`.
    check(
        unsafe { sys::VecScatterBegin(scatter, x.raw, to.raw, insert, forward) },
        "VecScatterBegin",
    )?;
    check(
        unsafe { sys::VecScatterEnd(scatter, x.raw, to.raw, insert, forward) },
        "VecScatterEnd",
    )
}

/// A reusable gather of one contiguous range of the entries of distributed vectors of one layout onto
/// this process (`VecScatterCreate` from a stride index set, built once, then one scatter per
/// [`GatherRange::gather_into`]): the unknowns a process reads, its own and those of the neighbouring
/// processes' rows next to them, rather than all ([`GatherAll`]).
pub struct GatherRange {
    scatter: sys::VecScatter,
    local: Vector,
    range: Range<usize>,
    /// Bytes this process sends per gather: its entries in the other processes' ranges.
    sent: usize,
}

impl GatherRange {
    /// The gather of the global entries `range` for vectors laid out like `like` (collective: every
    /// process passes its own range).
    pub fn new(session: &SessionGuard, like: &Vector, range: Range<usize>) -> Result<Self> {
        let sent = sent_to_others(session, &like.ownership_range()?, &range)?;
        let n = to_petsc_int(range.len(), "VecScatterCreate")?;
        let first = to_petsc_int(range.start, "ISCreateStride")?;
        let mut local: sys::PetscVec = std::ptr::null_mut();
        // SAFETY: out-parameter; the sequential vector is owned below.
        check(
            unsafe { sys::VecCreateSeq(sys::mpmc_comm_self(), n, &mut local) },
            "VecCreateSeq",
        )?;
        let local = Vector {
            raw: local,
            owned: true,
        };
        let (mut from, mut to): (sys::IS, sys::IS) = (std::ptr::null_mut(), std::ptr::null_mut());
        let mut scatter: sys::VecScatter = std::ptr::null_mut();
        // SAFETY: two stride index sets on this process (destroyed below) and a scatter from `like`'s
        // layout into `local`, owned by the result.
        let made = unsafe {
            let self_comm = sys::mpmc_comm_self();
            let mut code = sys::ISCreateStride(self_comm, n, first, 1, &mut from);
            if code == 0 {
                code = sys::ISCreateStride(self_comm, n, 0, 1, &mut to);
            }
            if code == 0 {
                code = sys::VecScatterCreate(like.raw, from, local.raw, to, &mut scatter);
            }
            sys::ISDestroy(&mut from);
            sys::ISDestroy(&mut to);
            code
        };
        check(made, "VecScatterCreate")?;
        Ok(Self {
            scatter,
            local,
            range,
            sent,
        })
    }

    /// The global entries this gather delivers.
    pub fn range(&self) -> Range<usize> {
        self.range.clone()
    }

    /// Writes the entries `range` of `x` (laid out as the vector this gather was made for) into
    /// `out[range]` (`out` indexed by global entry; the other entries are left as they are).
    pub fn gather_into(&self, x: &Vector, out: &mut [f64]) -> Result<()> {
        scatter_forward(self.scatter, x, &self.local)?;
        count_gathered(self.sent);
        self.local
            .read(|s| out[self.range.clone()].copy_from_slice(s))
    }
}

/// Entries (as bytes) of this process's `own` range that lie in the other processes' gathered
/// ranges, from every process's `wanted` range (collective: the ranges are summed over the processes).
fn sent_to_others(
    session: &SessionGuard,
    own: &Range<usize>,
    wanted: &Range<usize>,
) -> Result<usize> {
    let (rank, size) = (session.rank(), session.size());
    let mut ranges = vec![0.0; 2 * size];
    ranges[2 * rank] = wanted.start as f64;
    ranges[2 * rank + 1] = wanted.end as f64;
    session.sum(&mut ranges)?;
    let overlap = |r: usize| {
        let (lo, hi) = (ranges[2 * r] as usize, ranges[2 * r + 1] as usize);
        hi.min(own.end).saturating_sub(lo.max(own.start))
    };
    let entries: usize = (0..size).filter(|&r| r != rank).map(overlap).sum();
    Ok(entries * std::mem::size_of::<f64>())
}

impl Drop for GatherRange {
    fn drop(&mut self) {
        // SAFETY: created in `new`, destroyed once.
        unsafe { sys::VecScatterDestroy(&mut self.scatter) };
    }
}

impl Drop for GatherAll {
    fn drop(&mut self) {
        // SAFETY: created in `new`, destroyed once.
        unsafe { sys::VecScatterDestroy(&mut self.scatter) };
    }
}

impl Drop for Vector {
    fn drop(&mut self) {
        if self.owned && !self.raw.is_null() {
            // SAFETY: we own the reference; errors on destruction cannot be reported from Drop.
            unsafe { sys::VecDestroy(&mut self.raw) };
        }
    }
}
