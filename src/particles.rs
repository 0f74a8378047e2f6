//! Material points as a structure of arrays (spec `01-model.md`, Sec. 1, 2 and 5); their seeding from a
//! body is in [`crate::seeding`].
//!
//! # Units and plane strain
//! Lengths mm, time s, mass t, force N, stress MPa. The model is 2D plane strain: the deformation gradient is
//! stored as its in-plane block `F` (a `Matrix2`) with `F_33 = 1` and `F_13 = F_23 = F_31 = F_32 = 0`. Volumes
//! are per unit thickness: a volume `V_p` of `0.25` means 0.25 mm^2 of section times 1 mm of thickness =
//! 0.25 mm^3, so masses (t), nodal forces (N) and reactions are per 1 mm of thickness.

use nalgebra::{Matrix3, SMatrix, SVector};

use crate::geometry::GeometryError;
use crate::grid::cell_node_offset;
use thiserror::Error;

/// Errors of seeding and of particle-set operations.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum ParticleError {
    /// The geometry is malformed (no include region, a bad region).
    #[error(transparent)]
    Geometry(#[from] GeometryError),
    /// The geometry and seeding produced no material point.
    #[error("the geometry contains no material point (all candidate points excluded or outside)")]
    NoPoints,
    /// A seeding parameter is out of range.
    #[error("invalid seeding: {reason}")]
    InvalidSeeding {
        /// The parameter at fault.
        parameter: SeedingParameter,
        /// What is wrong.
        reason: String,
    },
    /// Particle sets with different history strides cannot be joined.
    #[error(
        "cannot append particles with history stride {other} to a set with history stride {this}"
    )]
    HistoryStrideMismatch {
        /// Stride of the receiving set.
        this: usize,
        /// Stride of the appended set.
        other: usize,
    },
}

/// A parameter of [`crate::geometry::Seeding`], as a seeding error names it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SeedingParameter {
    /// The cell size `h` (mm), or the lattice it makes for the geometry.
    CellSize,
    /// The points per cell and direction.
    PointsPerCell,
    /// The density (t/mm^3).
    Density,
}

/// Sign vector `s_c` in `{-1, 1}^D` of corner `c` of a CPDI domain: corner `c` is `x_p + r s_c`
/// ([`crate::grid::CellWeights`] order: counter-clockwise in 2D, lattice order in 3D).
#[inline]
pub fn corner_signs<const D: usize>(c: usize) -> SVector<f64, D> {
    let off = cell_node_offset::<D>(c);
    SVector::from_fn(|d, _| 2.0 * off[d] as f64 - 1.0)
}

/// Corner `c` of the parallelogram (parallelepiped) domain `x_p + r xi`, `xi` in `[-1, 1]^D`, whose columns
/// `r_d` are the half-edge vectors (mm): `x_p + r s_c` ([`corner_signs`]).
#[inline]
pub fn domain_corner<const D: usize>(
    x: &SVector<f64, D>,
    r: &SMatrix<f64, D, D>,
    c: usize,
) -> SVector<f64, D> {
    x + r * corner_signs::<D>(c)
}

/// Writes the `2^D` corners `x_p + r_p s_c` of the parallelogram (parallelepiped) domain into `out` (mm).
#[inline]
pub fn fill_domain_corners<const D: usize>(
    x: &SVector<f64, D>,
    r: &SMatrix<f64, D, D>,
    out: &mut [SVector<f64, D>],
) {
    for (c, o) in out.iter_mut().enumerate() {
        *o = domain_corner(x, r, c);
    }
}

/// Material points, structure of arrays: entry `p` of every column belongs to point `p`; `Particles` alone
/// is the 2D (plane strain) set, `Particles<3>` the 3D one.
///
/// Invariant: every per-point column has [`Particles::len`] entries (`corners` `2^D` per point) and
/// `history` has `len() * history_stride()` entries. Columns are public so that solver stages can borrow
/// them disjointly; change their lengths only through [`Particles::seed`], [`Particles::append`],
/// [`Particles::unpack`], [`Particles::retain`] and [`Particles::resize_history`].
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Particles<const D: usize = 2> {
    /// Position `x_p` (mm).
    pub x: Vec<SVector<f64, D>>,
    /// Initial volume `V_p^0` (mm^3; in 2D per 1 mm of thickness).
    pub vol0: Vec<f64>,
    /// Current volume `v_p = det(F_p) V_p^0` (mm^3; in 2D per mm of thickness).
    pub vol: Vec<f64>,
    /// Mass `m_p` (t; in 2D per mm of thickness).
    pub mass: Vec<f64>,
    /// Velocity `v_p` (mm/s).
    pub v: Vec<SVector<f64, D>>,
    /// Acceleration `a_p` (mm/s^2).
    pub a: Vec<SVector<f64, D>>,
    /// Deformation gradient `F_p` [-] (in 2D the in-plane block, `F_33 = 1`).
    pub f: Vec<SMatrix<f64, D, D>>,
    /// CPDI1 half-edge vectors `r_d = F_p r_d^0` as the columns of `r_p = F_p r_p^0` (mm).
    pub r: Vec<SMatrix<f64, D, D>>,
    /// Initial half-edge vectors `r_d^0`, columns of `r_p^0` (mm).
    pub r0: Vec<SMatrix<f64, D, D>>,
    /// CPDI2 corners, `2^D` per point ([`Particles::corners`]; corner `c` starts at `x_p + r_p s_c`,
    /// [`corner_signs`]) (mm). Tracked by the grid motion for CPDI2; for the other interpolators G2P keeps
    /// them at `x_p + r_p s_c` (for output).
    pub corners: Vec<SVector<f64, D>>,
    /// Body tag (e.g. concrete vs. rigid loading plate).
    pub body: Vec<u16>,
    /// Material history, `history_stride` values per point, point `p` at `p * stride..(p + 1) * stride`.
    pub history: Vec<f64>,
    /// Nonlocal equivalent strain `eta_bar_p = sum_I S_Ip eta_bar_I` (output) [-].
    pub eta_bar: Vec<f64>,
    /// Scalar damage (output) [-].
    pub damage: Vec<f64>,
    /// Energy dissipated by the point's microplanes under tensile and under compressive normal strain
    /// since the start (N mm; in 2D per mm of thickness): per step the trapezoidal dissipation of the
    /// energy books, shared out as the planes' end-point dissipation is.
    pub dissipated: Vec<[f64; 2]>,
    /// Damage gained in steps where the point's local equivalent strain stayed below gamma_0: damage
    /// carried in by the nonlocal field only [-].
    pub nonlocal_damage: Vec<f64>,
    /// Cauchy stress `sigma_p` (MPa), 3x3 (in 2D `sigma_13 = sigma_23 = 0`, `sigma_33` from plane strain).
    pub stress: Vec<Matrix3<f64>>,
    /// The point's number in the whole set as built from the configuration (its place in output and
    /// checkpoint files); kept when points move between processes.
    pub id: Vec<u64>,
    history_stride: usize,
}

/// Applies a closure to each column with one value per point (all but `corners`, `history` and `id`,
/// whose lengths or values differ): `per_point_columns!(self, |column| ..)`, or with a second set's
/// matching column `per_point_columns!(self, other, |column, theirs| ..)`. One list of the columns, so
/// that a new column is not forgotten in one of the operations that change lengths.
macro_rules! per_point_columns {
    ($set:expr, |$c:ident| $body:expr) => {
        per_point_columns!(@each $set, |$c| $body;
            x vol0 vol mass v a f r r0 body eta_bar damage dissipated nonlocal_damage stress)
    };
    ($set:expr, $other:expr, |$c:ident, $o:ident| $body:expr) => {
        per_point_columns!(@pairs $set, $other, |$c, $o| $body;
            x vol0 vol mass v a f r r0 body eta_bar damage dissipated nonlocal_damage stress)
    };
    (@each $set:expr, |$c:ident| $body:expr; $($field:ident)*) => {
        $({
            let $c = &mut $set.$field;
            $body;
        })*
    };
    (@pairs $set:expr, $other:expr, |$c:ident, $o:ident| $body:expr; $($field:ident)*) => {
        $({
            let ($c, $o) = (&mut $set.$field, &$other.$field);
            $body;
        })*
    };
}

/// Names of the half-edge state columns `r1, r2[, r3]`.
const HALF_EDGES: [&str; 3] = ["r1", "r2", "r3"];

impl<const D: usize> Particles<D> {
    /// CPDI corners per point, `2^D`.
    pub const CORNERS: usize = 1 << D;

    /// Values of a point record ([`Particles::pack`]) before its history: position, velocity and
    /// acceleration, `r`, `r^0` and `F`, the corners, volumes and mass, body, eta_bar, damage, two
    /// dissipations, nonlocal damage, id and the 3 x 3 stress (45 in 2D).
    const RECORD_FIXED: usize = 3 * D + 3 * D * D + D * (1 << D) + 3 + 7 + 9;

    /// An empty set (history stride 0).
    pub fn new() -> Self {
        Self::default()
    }

    /// Number of material points.
    pub fn len(&self) -> usize {
        self.x.len()
    }

    /// Whether there is no material point.
    pub fn is_empty(&self) -> bool {
        self.x.is_empty()
    }

    /// The `2^D` CPDI corners of point `p` (mm).
    #[inline]
    pub fn corners(&self, p: usize) -> &[SVector<f64, D>] {
        &self.corners[p * Self::CORNERS..(p + 1) * Self::CORNERS]
    }

    /// The `2^D` CPDI corners of point `p`, mutable (mm).
    #[inline]
    pub fn corners_mut(&mut self, p: usize) -> &mut [SVector<f64, D>] {
        &mut self.corners[p * Self::CORNERS..(p + 1) * Self::CORNERS]
    }

    /// Mean distance between neighbouring points in the reference configuration, `(mean V_p^0)^(1/D)` (mm;
    /// in 2D `V_p^0` per mm of thickness is an area); 0 without points.
    pub fn point_spacing(&self) -> f64 {
        if self.vol0.is_empty() {
            return 0.0;
        }
        (self.vol0.iter().sum::<f64>() / self.vol0.len() as f64).powf(1.0 / D as f64)
    }

    /// The evolving per-point state, in a fixed order: what a checkpoint holds to continue a run (mass,
    /// initial volume, body tag and initial half-edges come from the configuration). Values per point:
    /// vectors `D`, `F` `D^2` and `sigma` 9 (column-major), CPDI corners `D 2^D`, the material history
    /// [`Particles::history_stride`].
    pub fn state_columns(&self) -> Vec<(&'static str, usize)> {
        let mut columns = vec![("x", D), ("v", D), ("a", D)];
        columns.extend(HALF_EDGES[..D].iter().map(|&name| (name, D)));
        columns.extend([
            ("vol", 1),
            ("f", D * D),
            ("stress", 9),
            ("corners", D * Self::CORNERS),
            ("history", self.history_stride),
            ("eta_bar", 1),
            ("damage", 1),
            ("dissipated", 2),
            ("nonlocal_damage", 1),
        ]);
        columns
    }

    /// The values of state column `name` ([`Particles::state_columns`]), point after point; `None` for
    /// an unknown name.
    pub fn column(&self, name: &str) -> Option<Vec<f64>> {
        let vectors = |v: &[SVector<f64, D>]| v.iter().flat_map(|x| x.iter().copied()).collect();
        let matrices =
            |m: &[SMatrix<f64, D, D>]| m.iter().flat_map(|m| m.iter().copied()).collect();
        if let Some(d) = HALF_EDGES[..D].iter().position(|&n| n == name) {
            return Some(
                self.r
                    .iter()
                    .flat_map(|r| r.column(d).iter().copied().collect::<Vec<_>>())
                    .collect(),
            );
        }
        Some(match name {
            "x" => vectors(&self.x),
            "v" => vectors(&self.v),
            "a" => vectors(&self.a),
            "vol" => self.vol.clone(),
            "f" => matrices(&self.f),
            "stress" => self.stress.iter().flat_map(|m| m.iter().copied()).collect(),
            "corners" => vectors(&self.corners),
            "history" => self.history.clone(),
            "eta_bar" => self.eta_bar.clone(),
            "damage" => self.damage.clone(),
            "dissipated" => self.dissipated.iter().flatten().copied().collect(),
            "nonlocal_damage" => self.nonlocal_damage.clone(),
            _ => return None,
        })
    }

    /// Replaces state column `name` with `data` (as [`Particles::column`] gives it); an error names the
    /// column and the expected length.
    pub fn set_column(&mut self, name: &str, data: &[f64]) -> Result<(), String> {
        let width = self
            .state_columns()
            .iter()
            .find(|c| c.0 == name)
            .map(|c| c.1)
            .ok_or_else(|| format!("no point state column `{name}`"))?;
        if data.len() != width * self.len() {
            return Err(format!(
                "column `{name}` has {} values, {} points need {}",
                data.len(),
                self.len(),
                width * self.len()
            ));
        }
        let vectors = |d: &[f64]| -> Vec<SVector<f64, D>> {
            d.chunks_exact(D).map(SVector::from_column_slice).collect()
        };
        if let Some(d) = HALF_EDGES[..D].iter().position(|&n| n == name) {
            for (r, c) in self.r.iter_mut().zip(data.chunks_exact(D)) {
                r.set_column(d, &SVector::<f64, D>::from_column_slice(c));
            }
            return Ok(());
        }
        match name {
            "x" => self.x = vectors(data),
            "v" => self.v = vectors(data),
            "a" => self.a = vectors(data),
            "vol" => self.vol = data.to_vec(),
            "f" => {
                self.f = data
                    .chunks_exact(D * D)
                    .map(SMatrix::from_column_slice)
                    .collect()
            }
            "stress" => {
                self.stress = data
                    .chunks_exact(9)
                    .map(Matrix3::from_column_slice)
                    .collect()
            }
            "corners" => self.corners = vectors(data),
            "history" => self.history = data.to_vec(),
            "eta_bar" => self.eta_bar = data.to_vec(),
            "damage" => self.damage = data.to_vec(),
            "dissipated" => self.dissipated = data.chunks_exact(2).map(|c| [c[0], c[1]]).collect(),
            "nonlocal_damage" => self.nonlocal_damage = data.to_vec(),
            _ => unreachable!("listed in state_columns"),
        }
        Ok(())
    }

    /// Number of history values per point.
    pub fn history_stride(&self) -> usize {
        self.history_stride
    }

    /// History of point `p`.
    pub fn history(&self, p: usize) -> &[f64] {
        &self.history[p * self.history_stride..(p + 1) * self.history_stride]
    }

    /// Mutable history of point `p`.
    pub fn history_mut(&mut self, p: usize) -> &mut [f64] {
        &mut self.history[p * self.history_stride..(p + 1) * self.history_stride]
    }

    /// Sets the history stride and fills every point's history with `fill` (e.g. `gamma_0`).
    pub fn resize_history(&mut self, stride: usize, fill: f64) {
        self.history_stride = stride;
        self.history.clear();
        self.history.resize(self.len() * stride, fill);
    }

    /// Gives point `p` the deformation gradient `f`: `F_p = f`, `r_p = f r_p^0`, the corners at the
    /// deformed domain and `v_p = det(f) V_p^0`.
    pub fn set_deformation(&mut self, p: usize, f: SMatrix<f64, D, D>) {
        self.f[p] = f;
        self.r[p] = f * self.r0[p];
        self.vol[p] = crate::space::det(&f) * self.vol0[p];
        let (x, r) = (self.x[p], self.r[p]);
        fill_domain_corners(&x, &r, self.corners_mut(p));
    }

    /// Appends one point at `x` (mm), at rest and undeformed, with volume `vol0` (mm^3), mass `mass` (t),
    /// half-edge vectors `r0` (mm, as columns) and body tag `body`; its history is zero.
    pub fn push(
        &mut self,
        x: SVector<f64, D>,
        vol0: f64,
        mass: f64,
        r0: SMatrix<f64, D, D>,
        body: u16,
    ) {
        self.x.push(x);
        self.vol0.push(vol0);
        self.vol.push(vol0);
        self.mass.push(mass);
        self.v.push(SVector::zeros());
        self.a.push(SVector::zeros());
        self.f.push(SMatrix::identity());
        self.r.push(r0);
        self.r0.push(r0);
        self.corners
            .extend((0..Self::CORNERS).map(|c| domain_corner(&x, &r0, c)));
        self.body.push(body);
        self.history
            .extend(std::iter::repeat_n(0.0, self.history_stride));
        self.eta_bar.push(0.0);
        self.damage.push(0.0);
        self.dissipated.push([0.0; 2]);
        self.nonlocal_damage.push(0.0);
        self.stress.push(Matrix3::zeros());
        self.id.push(self.id.len() as u64);
    }

    /// Appends the points of `other` (e.g. a loading plate to the concrete). Both sets must have the same
    /// history stride unless one of them is empty. The appended points' ids continue after this set's.
    pub fn append(&mut self, other: &Self) -> Result<(), ParticleError> {
        if !other.is_empty() && !self.is_empty() && other.history_stride != self.history_stride {
            return Err(ParticleError::HistoryStrideMismatch {
                this: self.history_stride,
                other: other.history_stride,
            });
        }
        if self.is_empty() {
            self.history_stride = other.history_stride;
        }
        per_point_columns!(self, other, |column, theirs| column
            .extend_from_slice(theirs));
        self.corners.extend_from_slice(&other.corners);
        self.history.extend_from_slice(&other.history);
        let first = self.id.len() as u64;
        self.id.extend(other.id.iter().map(|i| first + i));
        Ok(())
    }

    /// Values of one point record ([`Particles::pack`]).
    pub fn record_width(&self) -> usize {
        Self::RECORD_FIXED + self.history_stride
    }

    /// Appends the whole of point `p` to `out` as one record of [`Particles::record_width`] values, for
    /// moving the point to another process ([`Particles::unpack`] reads it back).
    pub fn pack(&self, p: usize, out: &mut Vec<f64>) {
        out.extend_from_slice(self.x[p].as_slice());
        out.extend_from_slice(&[self.vol0[p], self.vol[p], self.mass[p]]);
        out.extend_from_slice(self.v[p].as_slice());
        out.extend_from_slice(self.a[p].as_slice());
        out.extend_from_slice(self.r[p].as_slice());
        out.extend_from_slice(self.r0[p].as_slice());
        out.extend_from_slice(self.f[p].as_slice());
        for c in self.corners(p) {
            out.extend_from_slice(c.as_slice());
        }
        out.extend_from_slice(&[
            f64::from(self.body[p]),
            self.eta_bar[p],
            self.damage[p],
            self.dissipated[p][0],
            self.dissipated[p][1],
            self.nonlocal_damage[p],
            self.id[p] as f64,
        ]);
        out.extend_from_slice(self.stress[p].as_slice());
        out.extend_from_slice(self.history(p));
    }

    /// Position of the id in a point record.
    #[cfg(test)]
    const RECORD_ID: usize = Self::RECORD_FIXED - 10;

    /// The id ([`Particles::id`]) of a point record of this set's layout (tests of the records).
    #[cfg(test)]
    pub(crate) fn record_id(&self, record: &[f64]) -> u64 {
        record[Self::RECORD_ID] as u64
    }

    /// Appends the point of a record written by [`Particles::pack`] of a set with the same history stride.
    pub fn unpack(&mut self, record: &[f64]) {
        assert_eq!(record.len(), self.record_width(), "a point record's length");
        let mut at = 0;
        let mut take = |n: usize| {
            at += n;
            &record[at - n..at]
        };
        self.x.push(SVector::from_column_slice(take(D)));
        let [vol0, vol, mass] = take(3).try_into().expect("three values");
        self.vol0.push(vol0);
        self.vol.push(vol);
        self.mass.push(mass);
        self.v.push(SVector::from_column_slice(take(D)));
        self.a.push(SVector::from_column_slice(take(D)));
        self.r.push(SMatrix::from_column_slice(take(D * D)));
        self.r0.push(SMatrix::from_column_slice(take(D * D)));
        self.f.push(SMatrix::from_column_slice(take(D * D)));
        for _ in 0..Self::CORNERS {
            self.corners.push(SVector::from_column_slice(take(D)));
        }
        let rest = take(7);
        self.body.push(rest[0] as u16);
        self.eta_bar.push(rest[1]);
        self.damage.push(rest[2]);
        self.dissipated.push([rest[3], rest[4]]);
        self.nonlocal_damage.push(rest[5]);
        self.id.push(rest[6] as u64);
        self.stress.push(Matrix3::from_column_slice(take(9)));
        self.history
            .extend_from_slice(&record[Self::RECORD_FIXED..]);
    }

    /// Keeps the points `p` with `keep[p]`, in order.
    pub fn retain(&mut self, keep: &[bool]) {
        assert_eq!(keep.len(), self.len(), "one flag per point");
        fn filter<T>(v: &mut Vec<T>, keep: &[bool], stride: usize) {
            let mut k = 0;
            v.retain(|_| {
                k += 1;
                keep[(k - 1) / stride]
            });
        }
        per_point_columns!(self, |column| filter(column, keep, 1));
        filter(&mut self.id, keep, 1);
        filter(&mut self.corners, keep, Self::CORNERS);
        if self.history_stride > 0 {
            filter(&mut self.history, keep, self.history_stride);
        }
    }

    /// Keeps the first `n` points.
    pub fn truncate(&mut self, n: usize) {
        per_point_columns!(self, |column| column.truncate(n));
        self.id.truncate(n);
        self.corners.truncate(n * Self::CORNERS);
        self.history.truncate(n * self.history_stride);
    }

    /// An empty set with this one's history stride (to unpack records into, or the columns' widths of
    /// a process that holds no points).
    pub fn empty_like(&self) -> Self {
        Self {
            history_stride: self.history_stride,
            ..Self::default()
        }
    }

    /// Bounding box of the positions and CPDI corners (mm); `None` without points.
    pub fn bounding_box(&self) -> Option<(SVector<f64, D>, SVector<f64, D>)> {
        self.x
            .iter()
            .chain(self.corners.iter())
            .map(|&x| (x, x))
            .reduce(|(lo, hi), (l, h)| (lo.inf(&l), hi.sup(&h)))
    }
}

/// The lattice positions `0..counts[d]` per direction, direction 0 fastest.
pub fn lattice<const D: usize>(counts: [usize; D]) -> impl Iterator<Item = [usize; D]> {
    let total: usize = counts.iter().product();
    (0..total).map(move |mut k| {
        std::array::from_fn(|d| {
            let i = k % counts[d];
            k /= counts[d];
            i
        })
    })
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::geometry::{Geometry, Region};
    use nalgebra::{Matrix2, Vector2};

    /// Sets every state column of `p` to distinct values `start + 1, start + 2, ..`.
    fn distinct_state(p: &mut Particles, start: f64) {
        let mut value = start;
        for (name, width) in p.state_columns() {
            let data: Vec<f64> = (0..width * p.len())
                .map(|_| {
                    value += 1.0;
                    value
                })
                .collect();
            p.set_column(name, &data).unwrap();
        }
    }

    /// `n` points in a row at `x = k` (mm), each with its own volume `0.25 + k` (mm^3), mass
    /// `(k + 1) 1e-9` (t) and body tag `k`, half-edges 0.25 mm.
    fn row(n: u16) -> Particles {
        let mut p = Particles::new();
        let (r1, r2) = (Vector2::new(0.25, 0.0), Vector2::new(0.0, 0.25));
        for k in 0..n {
            p.push(
                Vector2::new(k as f64, 1.0),
                0.25 + k as f64,
                1e-9 * (k + 1) as f64,
                Matrix2::from_columns(&[r1, r2]),
                k,
            );
        }
        p
    }

    #[test]
    fn every_state_column_survives_a_round_trip() {
        let mut p = row(3);
        p.resize_history(3, 0.0);
        distinct_state(&mut p, 0.0);
        let mut q = p.clone();
        for (name, _) in p.state_columns() {
            let data = p.column(name).unwrap();
            q.set_column(name, &vec![0.0; data.len()]).unwrap();
            q.set_column(name, &data).unwrap();
            assert_eq!(q.column(name).unwrap(), data, "{name}");
        }
        assert_eq!(q.x, p.x);
        assert_eq!(q.f, p.f);
        assert_eq!(q.stress, p.stress);
        assert_eq!(q.corners, p.corners);
        assert_eq!(q.dissipated, p.dissipated);
        assert_eq!(p.f[0], Matrix2::new(34.0, 36.0, 35.0, 37.0), "column-major");
        let e = q.set_column("damage", &[1.0]).unwrap_err();
        assert!(e.contains("damage") && e.contains("3 points"), "{e}");
        assert!(q.set_column("bogus", &[]).is_err());
        assert!(q.column("bogus").is_none());
    }

    /// A point packed into a record and unpacked elsewhere is the same point in every column (constant
    /// ones, the id and the history included); `retain` and `truncate` keep whole points.
    #[test]
    fn a_point_record_carries_the_whole_point() {
        let mut p = row(4);
        p.resize_history(5, 0.0);
        distinct_state(&mut p, 0.5);
        p.r0[2].set_column(0, &Vector2::new(0.3, -0.1));
        let mut records = Vec::new();
        for k in [3, 1, 0, 2] {
            p.pack(k, &mut records);
        }
        assert_eq!(records.len(), 4 * p.record_width());
        let mut q = p.empty_like();
        for r in records.chunks_exact(p.record_width()) {
            q.unpack(r);
        }
        assert_eq!(q.id, vec![3, 1, 0, 2]);
        let mut back = p.empty_like();
        let mut sorted: Vec<&[f64]> = records.chunks_exact(p.record_width()).collect();
        sorted.sort_by_key(|r| p.record_id(r));
        for r in sorted {
            back.unpack(r);
        }
        assert_eq!(back, p, "every column of every point");
        // Keep points 1 and 3, then the first of them.
        let mut kept = p.clone();
        kept.retain(&[false, true, false, true]);
        assert_eq!(kept.id, vec![1, 3]);
        assert_eq!(kept.history(1), p.history(3));
        assert_eq!(kept.body, vec![1, 3]);
        kept.truncate(1);
        assert_eq!((kept.len(), kept.history.len()), (1, 5));
        assert_eq!(kept.stress[0], p.stress[1]);
        // Appending renumbers the other set's ids after this one's.
        let mut both = p.clone();
        both.append(&p).unwrap();
        assert_eq!(both.id, (0..8).collect::<Vec<u64>>());
    }

    /// The rectangle `[min, max]` (mm).
    pub(crate) fn rect(min: [f64; 2], max: [f64; 2]) -> Region {
        Region::Rect { min, max }
    }

    /// The geometry of the one rectangle `[min, max]` (mm).
    pub(crate) fn rect_geometry(min: [f64; 2], max: [f64; 2]) -> Geometry {
        Geometry {
            include: vec![rect(min, max)],
            exclude: vec![],
        }
    }
}
