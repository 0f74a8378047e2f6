//! Point columns written by every process into one HDF5 file ([`crate::petsc::Session::create_shared_file`]):
//! each process writes the points it holds at the rows of their ids, the order of a serial run, so that the
//! file is the serial run's whatever the number of processes, and nothing is gathered on one process. The
//! checksums of whole datasets ([`SharedCrc`]) are put together from every process's part the same way.

use crate::model::State;
use crate::petsc::{PetscError, SessionGuard};
use hdf5_metno::types::H5Type;
use std::borrow::Cow;
use std::ops::Range;

/// The points this process writes into a shared file, in the order of their ids, and the runs of
/// consecutive ids they form (one run per band of points seeded together; one in a serial run).
pub struct PointRows {
    /// Local indices of the points written, in the order of their ids.
    order: Vec<usize>,
    /// Runs of consecutive ids, with the position in `order` of each run's first point.
    runs: Vec<(Range<usize>, usize)>,
    /// Points written over all processes: the rows of a point dataset.
    total: usize,
}

/// A state as every process writes it into the shared files of a snapshot or checkpoint: the points
/// each process holds where they are shared out, all of them written by process 0 where every process
/// holds every point (one process; the runs whose points are not shared out).
pub struct SharedState<'a, const D: usize> {
    /// The processes.
    pub session: &'a SessionGuard,
    /// This process's state.
    pub state: &'a State<D>,
    /// The points this process writes.
    pub rows: PointRows,
}

impl<'a, const D: usize> SharedState<'a, D> {
    /// `state` of this process as written by all. Collective.
    pub fn new(session: &'a SessionGuard, state: &'a State<D>) -> Result<Self, PetscError> {
        let writes = state.distributed || session.rank() == 0;
        Ok(Self {
            session,
            state,
            rows: PointRows::new(session, &state.particles.id, writes)?,
        })
    }
}

/// How a column with `width` values per point is laid out in its dataset.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Layout {
    /// One value per point, or the point's values one after the other: shape (N * width).
    Flat,
    /// One row of `width` values per point: shape (N, width).
    Rows,
}

impl PointRows {
    /// The points with the ids `ids` (this process's, in its order) if this process `writes` them, none
    /// otherwise; the ids of all processes' written points together must be 0..N-1, once each.
    /// Collective (the count N).
    pub fn new(session: &SessionGuard, ids: &[u64], writes: bool) -> Result<Self, PetscError> {
        let mut order: Vec<usize> = if writes {
            (0..ids.len()).collect()
        } else {
            Vec::new()
        };
        order.sort_unstable_by_key(|&k| ids[k]);
        let mut runs = Vec::new();
        let mut k = 0;
        while k < order.len() {
            let first = ids[order[k]] as usize;
            let len = order[k..]
                .iter()
                .enumerate()
                .take_while(|&(j, &p)| ids[p] as usize == first + j)
                .count();
            runs.push((first..first + len, k));
            k += len;
        }
        let mut n = [order.len() as f64];
        session.sum(&mut n)?;
        Ok(Self {
            order,
            runs,
            total: n[0] as usize,
        })
    }

    /// Points over all processes (the rows of a point dataset).
    pub fn total(&self) -> usize {
        self.total
    }

    /// The local indices of the points this process writes, in the order of their ids.
    pub fn order(&self) -> &[usize] {
        &self.order
    }

    /// The values of the run `(ids, at)` ([`PointRows::runs`]) of `values` (this process's points in
    /// their local order, `width` per point) in the order of the ids: borrowed where the run's points are
    /// consecutive in the local order too (one run in a serial run, nearly always in a band), else copied.
    fn run_values<'v, T: Copy>(
        &self,
        values: &'v [T],
        width: usize,
        (ids, at): &(Range<usize>, usize),
    ) -> Cow<'v, [T]> {
        let local = &self.order[*at..at + ids.len()];
        let first = local[0];
        if local.iter().enumerate().all(|(j, &k)| k == first + j) {
            return Cow::Borrowed(&values[first * width..(first + local.len()) * width]);
        }
        Cow::Owned(
            local
                .iter()
                .flat_map(|&k| &values[k * width..(k + 1) * width])
                .copied()
                .collect(),
        )
    }

    /// Creates the dataset `name` of every process's points, `width` values per point laid out as
    /// `layout`, and writes this process's part: `values` in its points' local order. Collective (the
    /// creation; each process writes its runs independently).
    pub fn write<T: H5Type + Copy>(
        &self,
        file: &hdf5_metno::File,
        name: &str,
        (width, layout): (usize, Layout),
        values: &[T],
    ) -> hdf5_metno::Result<hdf5_metno::Dataset> {
        let ds = self.create::<T>(file, name, (width, layout))?;
        self.write_into(&ds, (width, layout), values)?;
        Ok(ds)
    }

    /// Creates the dataset `name` of every process's points, `width` values per point laid out as
    /// `layout` (collective).
    fn create<T: H5Type>(
        &self,
        file: &hdf5_metno::File,
        name: &str,
        (width, layout): (usize, Layout),
    ) -> hdf5_metno::Result<hdf5_metno::Dataset> {
        match layout {
            Layout::Flat => file
                .new_dataset::<T>()
                .shape(self.total * width)
                .create(name),
            Layout::Rows => file
                .new_dataset::<T>()
                .shape((self.total, width))
                .create(name),
        }
    }

    /// This process's runs of `values` into the dataset `ds` (independent).
    fn write_into<T: H5Type + Copy>(
        &self,
        ds: &hdf5_metno::Dataset,
        (width, layout): (usize, Layout),
        values: &[T],
    ) -> hdf5_metno::Result<()> {
        for run in &self.runs {
            let ids = &run.0;
            let part = self.run_values(values, width, run);
            let part = part.as_ref();
            match layout {
                Layout::Flat => ds.write_slice(part, ids.start * width..ids.end * width)?,
                Layout::Rows => {
                    let rows = ndarray::ArrayView2::from_shape((ids.len(), width), part)
                        .expect("width values per point");
                    ds.write_slice(rows, ndarray::s![ids.clone(), ..])?;
                }
            }
        }
        Ok(())
    }
}

/// A file that every process writes its points' columns into ([`PointRows`]): after a failed write on
/// one process every process still makes the same collective calls (each dataset's creation, the flush,
/// the closing), and [`SharedFile::close`] agrees on the outcome, so that no process waits in a
/// collective call that another has left and a file one process failed to write is not taken as whole.
pub struct SharedFile<'r> {
    file: Option<hdf5_metno::File>,
    rows: &'r PointRows,
    /// The first error of this process.
    failed: Option<hdf5_metno::Error>,
}

impl<'r> SharedFile<'r> {
    /// Creates (truncating) `path` for the points `rows` of every process. Collective.
    pub fn create(session: &SessionGuard, path: &std::path::Path, rows: &'r PointRows) -> Self {
        let (file, failed) = match session.create_shared_file(path) {
            Ok(f) => (Some(f), None),
            Err(e) => (None, Some(e)),
        };
        Self { file, rows, failed }
    }

    /// The dataset `name` ([`PointRows::write`]) with this process's `values`, unless an earlier write
    /// of this process failed (the dataset is created all the same). Collective.
    pub fn column<T: H5Type + Copy>(&mut self, name: &str, shape: (usize, Layout), values: &[T]) {
        let Some(file) = &self.file else {
            return;
        };
        // The creation every process makes; its own part only while nothing failed here.
        let written = self
            .rows
            .create::<T>(file, name, shape)
            .and_then(|ds| match self.failed {
                None => self.rows.write_into(&ds, shape, values),
                Some(_) => Ok(()),
            });
        if let Err(e) = written {
            self.failed.get_or_insert(e);
        }
    }

    /// Flushes and closes the file, and agrees with the other processes: `Ok` if every process wrote
    /// its part, this process's error or a failure elsewhere otherwise. Collective, so also a barrier
    /// after which the file is whole on disk for any process to open.
    pub fn close(mut self, session: &SessionGuard) -> hdf5_metno::Result<()> {
        if let Some(file) = self.file.take() {
            if let Err(e) = file.flush() {
                self.failed.get_or_insert(e);
            }
            drop(file);
        }
        let elsewhere = session.any(self.failed.is_some());
        match self.failed {
            Some(e) => Err(e),
            None if elsewhere => Err(hdf5_metno::Error::from("writing failed on another process")),
            None => Ok(()),
        }
    }
}

/// The CRC-32 of a stream of point columns in the order of the ids (the bytes a serial run hashes),
/// put together from every process's part: each process hashes the whole stream with its own values in
/// place and zeros elsewhere, and the CRC of the whole is the exclusive or of these (the CRC is affine in
/// the bytes of a message of given length: `crc(a ^ b) = crc(a) ^ crc(b) ^ crc(0)`), with `crc(0)` once
/// more for an even number of processes. Each process hashes the length of the whole stream (zeros at
/// about 10 GB/s): cheap next to the write.
pub struct SharedCrc {
    hasher: crc32fast::Hasher,
    /// Bytes hashed so far.
    len: u64,
}

/// A block of zeros for [`SharedCrc`]'s gaps.
const ZEROS: [u8; 8192] = [0; 8192];

impl Default for SharedCrc {
    fn default() -> Self {
        Self::new()
    }
}

impl SharedCrc {
    /// An empty stream.
    pub fn new() -> Self {
        Self {
            hasher: crc32fast::Hasher::new(),
            len: 0,
        }
    }

    fn zeros(&mut self, mut bytes: usize) {
        self.len += bytes as u64;
        while bytes > 0 {
            let n = bytes.min(ZEROS.len());
            self.hasher.update(&ZEROS[..n]);
            bytes -= n;
        }
    }

    /// Appends a column of every process's points (`rows`), `width` values of 8 bytes per point, whose
    /// little-endian bytes `bytes` gives for this process's points (`values` in their local order).
    pub fn column<T: Copy>(
        &mut self,
        rows: &PointRows,
        width: usize,
        values: &[T],
        bytes: impl Fn(T) -> [u8; 8],
    ) {
        let mut at = 0;
        let mut buffer = Vec::with_capacity(8 * ZEROS.len());
        for run in &rows.runs {
            let ids = &run.0;
            self.zeros((ids.start - at) * width * 8);
            for chunk in rows.run_values(values, width, run).chunks(ZEROS.len()) {
                buffer.clear();
                buffer.extend(chunk.iter().flat_map(|&v| bytes(v)));
                self.hasher.update(&buffer);
            }
            self.len += (ids.len() * width * 8) as u64;
            at = ids.end;
        }
        self.zeros((rows.total - at) * width * 8);
    }

    /// The CRC-32 of the whole stream, the same on every process. Collective.
    pub fn finish(self, session: &SessionGuard) -> Result<u32, PetscError> {
        let mut crc = [self.hasher.finalize()];
        session.xor(&mut crc)?;
        if session.size() % 2 == 0 {
            let mut zero = SharedCrc::new();
            zero.zeros(self.len as usize);
            crc[0] ^= zero.hasher.finalize();
        }
        Ok(crc[0])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Points held out of the order of their ids, in three runs of consecutive ids: each dataset holds
    /// them in the order of the ids, and the shared checksum is the CRC of the bytes in that order.
    #[test]
    fn points_are_written_at_the_rows_of_their_ids() {
        let session = crate::petsc::Session::get().expect("PETSc");
        let ids: Vec<u64> = vec![3, 0, 4, 1, 2, 7, 5, 6, 9, 8];
        let rows = PointRows::new(&session, &ids, true).expect("rows");
        assert_eq!(rows.total(), 10);
        assert_eq!(rows.order()[..3], [1, 3, 4]);
        let (w, flat_w) = (3usize, 2usize);
        let rows_values: Vec<f64> = ids
            .iter()
            .flat_map(|&i| (0..w).map(move |j| (10 * i as usize + j) as f64))
            .collect();
        let flat_values: Vec<i64> = ids
            .iter()
            .flat_map(|&i| (0..flat_w).map(move |j| -((10 * i as usize + j) as i64)))
            .collect();
        let path = std::env::temp_dir().join(format!("mpmc-shared-{}.h5", std::process::id()));
        {
            let f = session.create_shared_file(&path).expect("file");
            rows.write(&f, "rows", (w, Layout::Rows), &rows_values)
                .expect("rows");
            rows.write(&f, "flat", (flat_w, Layout::Flat), &flat_values)
                .expect("flat");
            rows.write::<f64>(&f, "none", (0, Layout::Flat), &[])
                .expect("empty");
        }
        let f = hdf5_metno::File::open(&path).expect("open");
        let r: ndarray::Array2<f64> = f.dataset("rows").unwrap().read_2d().unwrap();
        assert_eq!(r.shape(), [10, 3]);
        for i in 0..10 {
            for j in 0..w {
                assert_eq!(r[(i, j)], (10 * i + j) as f64);
            }
        }
        let flat: Vec<i64> = f.dataset("flat").unwrap().read_raw().unwrap();
        let expected: Vec<i64> = (0..10)
            .flat_map(|i| (0..flat_w).map(move |j| -((10 * i + j) as i64)))
            .collect();
        assert_eq!(flat, expected);
        assert_eq!(f.dataset("none").unwrap().size(), 0);
        let mut crc = SharedCrc::new();
        crc.column(&rows, w, &rows_values, f64::to_le_bytes);
        crc.column(&rows, flat_w, &flat_values, i64::to_le_bytes);
        let mut h = crc32fast::Hasher::new();
        r.iter().for_each(|v| h.update(&v.to_le_bytes()));
        flat.iter().for_each(|v| h.update(&v.to_le_bytes()));
        assert_eq!(crc.finish(&session).expect("crc"), h.finalize());
        drop(f);
        let _ = std::fs::remove_file(&path);
    }

    /// The affine property the shared checksum rests on, for 1 to 4 parts of a stream split at random.
    #[test]
    fn the_crc_of_a_stream_is_put_together_from_zero_filled_parts() {
        let n = 1000;
        let values: Vec<f64> = (0..n).map(|i| (i as f64).sin() * 1e3).collect();
        let whole = {
            let mut h = crc32fast::Hasher::new();
            for v in &values {
                h.update(&v.to_le_bytes());
            }
            h.finalize()
        };
        let mut seed = 12345u64;
        for parts in 1..=4usize {
            let mut owner = vec![0usize; n];
            for o in owner.iter_mut() {
                seed = seed
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                *o = (seed >> 33) as usize % parts;
            }
            let mut crc = 0u32;
            let mut len = 0;
            for part in 0..parts {
                let mut h = SharedCrc::new();
                for (v, &o) in values.iter().zip(&owner) {
                    if o == part {
                        h.hasher.update(&v.to_le_bytes());
                        h.len += 8;
                    } else {
                        h.zeros(8);
                    }
                }
                len = h.len;
                crc ^= h.hasher.finalize();
            }
            if parts % 2 == 0 {
                let mut zero = SharedCrc::new();
                zero.zeros(len as usize);
                crc ^= zero.hasher.finalize();
            }
            assert_eq!(crc, whole, "{parts} parts");
        }
    }
}
