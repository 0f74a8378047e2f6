//! Shape functions `S_Ip` and gradients `grad_{X_n} S_Ip` of the material points (`docs/shape-functions.md`),
//! evaluated once per step in the converged configuration at `t_n` and stored in a [`ShapeTable`].
//!
//! Five interpolators share the [`Interpolator`] interface, all built on the bilinear hat functions `N_I` of
//! the [`Grid`] (see `docs/shape-functions.md` for formulas, choices and a figure):
//!
//! | [`ShapeKind`]  | config       | support 2D (3D) | domain used |
//! |----------------|--------------|---------------------|-------------|
//! | `Linear`       | `"linear"`   | 4 (8)   | point `x_p` |
//! | `Gimp`         | `"gimp"`     | 9 (27)  | undeformed square (cube) of side `2 r_d^0` (`l_p = h / n`) around `x_p` |
//! | `Cpdi1`        | `"cpdi1"`    | 16 (64) | parallelogram (parallelepiped) `x_p + r_p xi`, `r_p = F_p r_p^0` |
//! | `Cpdi2`        | `"cpdi2"`    | 16 (64) | quadrilateral (hexahedron) with tracked corners |
//! | `Bspline2`     | `"bspline2"` | 9 (27)  | point `x_p`, quadratic B-spline |
//!
//! Everything here is generic over the space dimension `D` (2 or 3); `ShapeTable` and `Weight` alone are
//! the 2D ones.
//!
//! Every interpolator satisfies `sum_I S_Ip = 1`, `sum_I grad S_Ip = 0`, `sum_I S_Ip x_I = x_p` and
//! `sum_I x_I (x) grad S_Ip = I` (for CPDI2 `x_p` is the centroid of the quadrilateral); the tests check
//! this on random, edge, node, stretched, sheared and near-margin configurations.
//!
//! The table has a fixed stride per point (the maximum support of the interpolator) and a per-point count;
//! nodes appear once per point (the CPDI corners' contributions are merged) and entries whose value and
//! gradient are exactly zero are dropped (e.g. a CPDI corner or GIMP support edge exactly on a grid line).
//! Linear keeps all four nodes of the owning cell, since on a cell edge a node with `S = 0` still has a
//! non-zero gradient.

mod bspline;
mod cpdi;
mod gimp;
mod linear;

use nalgebra::{SMatrix, SVector};
use rayon::prelude::*;
use serde::Deserialize;
use thiserror::Error;

use crate::grid::{Grid, GridError, Locus};
use crate::particles::Particles;
use crate::space::{cofactor, det};

pub use bspline::Bspline2;
pub use cpdi::{Cpdi1, Cpdi2, DEFAULT_CORNER_HOLD};
pub use gimp::Gimp;
pub use linear::Linear;

/// The interpolator, chosen in the config by its lowercase name.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ShapeKind {
    /// Standard MPM: `S_Ip = N_I(x_p)`.
    Linear,
    /// uGIMP: `N_I` averaged over the undeformed particle square of side `l_p = h / n`.
    Gimp,
    /// CPDI1 (Sadeghirad, Brannon, Burghardt 2011): parallelogram domain `r_i = F_p r_i^0`.
    Cpdi1,
    /// CPDI2 / CPDI-Q4 (Sadeghirad, Brannon, Guilkey 2013): quadrilateral with tracked corners.
    Cpdi2,
    /// Quadratic B-spline on the grid nodes.
    Bspline2,
}

impl ShapeKind {
    /// All kinds, in config order.
    pub const ALL: [ShapeKind; 5] = [
        ShapeKind::Linear,
        ShapeKind::Gimp,
        ShapeKind::Cpdi1,
        ShapeKind::Cpdi2,
        ShapeKind::Bspline2,
    ];

    /// The config name.
    pub fn name(self) -> &'static str {
        match self {
            ShapeKind::Linear => "linear",
            ShapeKind::Gimp => "gimp",
            ShapeKind::Cpdi1 => "cpdi1",
            ShapeKind::Cpdi2 => "cpdi2",
            ShapeKind::Bspline2 => "bspline2",
        }
    }

    /// Maximum number of support nodes of one point in `D` dimensions (the table stride).
    pub fn max_support<const D: usize>(self) -> usize {
        match self {
            ShapeKind::Linear => <Linear as Interpolator<D>>::MAX_SUPPORT,
            ShapeKind::Gimp => <Gimp as Interpolator<D>>::MAX_SUPPORT,
            ShapeKind::Cpdi1 => <Cpdi1 as Interpolator<D>>::MAX_SUPPORT,
            ShapeKind::Cpdi2 => <Cpdi2<D> as Interpolator<D>>::MAX_SUPPORT,
            ShapeKind::Bspline2 => <Bspline2 as Interpolator<D>>::MAX_SUPPORT,
        }
    }
}

/// One support node of a material point: `S_Ip` [-] and `grad_{X_n} S_Ip` [1/mm].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Weight<const D: usize = 2> {
    /// Global grid node index `I`.
    pub node: u32,
    /// `S_Ip` [-].
    pub value: f64,
    /// `grad_{X_n} S_Ip` [1/mm], with respect to the start-of-step positions.
    pub grad: SVector<f64, D>,
}

impl<const D: usize> Default for Weight<D> {
    fn default() -> Self {
        Self {
            node: 0,
            value: 0.0,
            grad: SVector::zeros(),
        }
    }
}

/// Errors of the shape-function evaluation; all carry the material point index and are recoverable (report
/// them to SNES as domain errors or shorten the step).
#[derive(Debug, Clone, Copy, PartialEq, Error)]
pub enum ShapeError {
    /// A point, a CPDI corner or a GIMP/B-spline support left the grid.
    #[error(transparent)]
    Grid(#[from] GridError),
    /// A CPDI domain with zero or negative area (volume in 3D, inverted), so `grad S` is undefined.
    #[error(
        "material point {particle}: degenerate or inverted CPDI domain, signed area (volume in 3D) {area:e} \
         mm^2 (mm^3)"
    )]
    DegenerateDomain {
        /// Material point index.
        particle: usize,
        /// Signed area (3D: volume) of the domain (mm^2, mm^3).
        area: f64,
    },
    /// FEM mode: an element inverted at a Gauss point.
    #[error("material point {particle}: det F = {det:e} <= 0 (inverted element)")]
    InvertedElement {
        /// Material point index.
        particle: usize,
        /// `det F` of the point.
        det: f64,
    },
    /// A uGIMP half-width outside `(0, h/2]`, for which the support is no longer 3 x 3 nodes.
    #[error(
        "material point {particle}: uGIMP half-width {half_width} mm must lie in (0, h/2 = {half_h}] mm"
    )]
    GimpWidth {
        /// Material point index.
        particle: usize,
        /// Offending half-width `|r_i^0|` (mm).
        half_width: f64,
        /// `h / 2` (mm).
        half_h: f64,
    },
}

impl ShapeError {
    /// The material point the error is about (for deterministic reporting: the smallest index wins).
    pub fn particle(&self) -> usize {
        match *self {
            ShapeError::Grid(GridError::OutsideGrid { particle, .. })
            | ShapeError::DegenerateDomain { particle, .. }
            | ShapeError::InvertedElement { particle, .. }
            | ShapeError::GimpWidth { particle, .. } => particle,
            ShapeError::Grid(_) => 0,
        }
    }

    /// The error with its point index `p` replaced by `ids[p]` (a process's local index by the point's
    /// number in the whole set).
    pub fn renumbered(mut self, ids: &[u64]) -> Self {
        match &mut self {
            ShapeError::Grid(GridError::OutsideGrid { particle, .. })
            | ShapeError::DegenerateDomain { particle, .. }
            | ShapeError::InvertedElement { particle, .. }
            | ShapeError::GimpWidth { particle, .. } => {
                if let Some(&id) = ids.get(*particle) {
                    *particle = id as usize;
                }
            }
            ShapeError::Grid(_) => {}
        }
        self
    }
}

/// The error for point `particle` whose `locus` at `x` left the grid.
pub(crate) fn outside<const D: usize>(
    particle: usize,
    locus: Locus,
    x: SVector<f64, D>,
) -> ShapeError {
    ShapeError::Grid(GridError::outside(particle, locus, &x))
}

/// Material point `p` of `particles` on `grid`: what an interpolator reads to weight one point.
#[derive(Clone, Copy)]
pub struct At<'a, const D: usize> {
    /// The background grid.
    pub grid: &'a Grid<D>,
    /// The material points.
    pub particles: &'a Particles<D>,
    /// Index of the point.
    pub p: usize,
}

/// An interpolator in `D` dimensions: writes the compact weight list of one material point.
pub trait Interpolator<const D: usize>: Sync {
    /// Maximum number of support nodes of one point.
    const MAX_SUPPORT: usize;

    /// Writes the weights of point `p` into `out[..n]` (`out.len() == MAX_SUPPORT`), each node at most once,
    /// and returns `n`.
    fn weights(&self, at: At<'_, D>, out: &mut [Weight<D>]) -> Result<usize, ShapeError>;
}

/// Adds `(value, grad)` to the entry of `node` in `out[..*count]`, appending it if absent.
#[inline]
pub(crate) fn add_merged<const D: usize>(
    out: &mut [Weight<D>],
    count: &mut usize,
    node: u32,
    value: f64,
    grad: SVector<f64, D>,
) {
    if let Some(w) = out[..*count].iter_mut().find(|w| w.node == node) {
        w.value += value;
        w.grad += grad;
    } else {
        out[*count] = Weight { node, value, grad };
        *count += 1;
    }
}

/// Weights of a tensor-product kernel `S_Ip = prod_d phi_d(s_d - i_d)` on the `3^D` nodes around the node
/// nearest to `x_p` (`s = (x_p - x_0) / h` in cell units, `kernel(d, k) = (phi_k(d), phi_k'(d))` for direction
/// `k`, support `|d| < 3/2`), direction 0 fastest. Nodes whose value and gradient are exactly zero are
/// dropped; a contributing node outside the grid is an error.
pub(crate) fn tensor_product_weights<const D: usize>(
    grid: &Grid<D>,
    p: usize,
    x: SVector<f64, D>,
    kernel: impl Fn(f64, usize) -> (f64, f64),
    out: &mut [Weight<D>],
) -> Result<usize, ShapeError> {
    if grid.cell_of(x).is_none() {
        return Err(outside(p, Locus::Centre, x));
    }
    let s = grid.lattice_coords(x);
    let inv_h = 1.0 / grid.cell_size();
    let nearest: [i64; D] = std::array::from_fn(|k| s[k].round() as i64);
    let phi: [[(f64, f64); 3]; D] = std::array::from_fn(|k| {
        std::array::from_fn(|a| kernel(s[k] - (nearest[k] + a as i64 - 1) as f64, k))
    });
    let cells = grid.cells();
    let mut count = 0;
    'nodes: for combo in 0..3_usize.pow(D as u32) {
        let mut node = [0_usize; D];
        let mut rest = combo;
        for k in 0..D {
            let a = rest % 3;
            rest /= 3;
            let (v, dv) = phi[k][a];
            if v == 0.0 && dv == 0.0 {
                continue 'nodes;
            }
            let i = nearest[k] + a as i64 - 1;
            if i < 0 || i > cells[k] as i64 {
                return Err(outside(p, Locus::Centre, x));
            }
            node[k] = i as usize;
        }
        let factor = |k: usize| phi[k][(combo / 3_usize.pow(k as u32)) % 3];
        out[count] = Weight {
            node: grid.node_at(node) as u32,
            value: (0..D).map(|k| factor(k).0).product(),
            grad: SVector::from_fn(|d, _| {
                (0..D)
                    .map(|k| if k == d { factor(k).1 } else { factor(k).0 })
                    .product::<f64>()
                    * inv_h
            }),
        };
        count += 1;
    }
    Ok(count)
}

/// Points per parallel work item of [`ShapeTable::compute`].
const CHUNK: usize = 512;

/// The shape functions of all material points for one step: a fixed stride of
/// [`ShapeKind::max_support`] entries per point and a per-point count. Reuse one table across steps: after
/// the first step [`ShapeTable::compute`] does not allocate.
#[derive(Debug, Clone)]
pub struct ShapeTable<const D: usize = 2> {
    kind: Option<ShapeKind>,
    stride: usize,
    weights: Vec<Weight<D>>,
    counts: Vec<u8>,
    /// Velocity fields the node ids run over (set by `offset_fields`; 0, before any table, counts as 1).
    fields: usize,
    /// The CPDI interpolators' corner hold, in cell widths ([`DEFAULT_CORNER_HOLD`]).
    corner_hold: f64,
}

impl<const D: usize> Default for ShapeTable<D> {
    fn default() -> Self {
        Self {
            kind: None,
            stride: 0,
            weights: Vec::new(),
            counts: Vec::new(),
            fields: 0,
            corner_hold: DEFAULT_CORNER_HOLD,
        }
    }
}

impl<const D: usize> ShapeTable<D> {
    /// An empty table.
    pub fn new() -> Self {
        Self::default()
    }

    /// The corner hold of the CPDI interpolators (cell widths).
    pub fn corner_hold(&self) -> f64 {
        self.corner_hold
    }

    /// Sets the corner hold of the CPDI interpolators (cell widths; 0: plain CPDI, every corner on the hats
    /// of its cell), used from the next [`ShapeTable::compute`] on.
    pub fn set_corner_hold(&mut self, hold: f64) {
        debug_assert!((0.0..=0.25).contains(&hold), "corner hold {hold}");
        self.corner_hold = hold;
    }

    /// Number of material points in the table (0 after a failed [`ShapeTable::compute`]).
    pub fn len(&self) -> usize {
        self.counts.len()
    }

    /// Whether the table holds no point.
    pub fn is_empty(&self) -> bool {
        self.counts.is_empty()
    }

    /// The interpolator of the last successful [`ShapeTable::compute`].
    pub fn kind(&self) -> Option<ShapeKind> {
        self.kind
    }

    /// Velocity fields the supports map onto (1 unless [`ShapeTable::offset_fields`] moved them): the
    /// node ids run over `fields` copies of the grid's nodes.
    pub fn fields(&self) -> usize {
        self.fields.max(1)
    }

    /// Entries reserved per point.
    pub fn stride(&self) -> usize {
        self.stride
    }

    /// The support of point `p`: each node once, with `S_Ip` and `grad_{X_n} S_Ip`.
    #[inline]
    pub fn weights(&self, p: usize) -> &[Weight<D>] {
        let start = p * self.stride;
        &self.weights[start..start + self.counts[p] as usize]
    }

    /// Iterator over `(p, weights(p))` for all points.
    pub fn iter(&self) -> impl Iterator<Item = (usize, &[Weight<D>])> {
        (0..self.len()).map(|p| (p, self.weights(p)))
    }

    /// Evaluates `S_Ip` and `grad_{X_n} S_Ip` of every point with interpolator `kind` on `grid`, in the
    /// current (start-of-step) configuration of `particles`, in parallel. On error the table is left empty and
    /// the error names the smallest offending point index.
    pub fn compute(
        &mut self,
        kind: ShapeKind,
        grid: &Grid<D>,
        particles: &Particles<D>,
    ) -> Result<(), ShapeError> {
        let result = match kind {
            ShapeKind::Linear => self.fill(&Linear, grid, particles),
            ShapeKind::Gimp => self.fill(&Gimp, grid, particles),
            ShapeKind::Cpdi1 => {
                let hold = self.corner_hold;
                self.fill(&Cpdi1 { hold }, grid, particles)
            }
            ShapeKind::Cpdi2 => {
                let hold = self.corner_hold;
                self.fill(&Cpdi2::<D>::held(hold), grid, particles)
            }
            ShapeKind::Bspline2 => self.fill(&Bspline2, grid, particles),
        };
        self.fields = 1;
        match result {
            Ok(()) => self.kind = Some(kind),
            Err(_) => {
                self.kind = None;
                self.counts.clear();
            }
        }
        result
    }

    /// FEM mode: the shape functions of `reference` (evaluated at the reference positions `X_p`) with the
    /// gradients pushed forward to the start-of-step configuration, `grad_{X_n} S_Ip = F_p^-T grad_X S_Ip`
    /// (`f` holds `F_p`, one per point). An error names the first point with `det F_p <= 0`.
    pub fn push_forward(
        &mut self,
        reference: &ShapeTable<D>,
        f: &[SMatrix<f64, D, D>],
    ) -> Result<(), ShapeError> {
        if let Some(particle) = f.iter().position(|f| det(f).is_nan() || det(f) <= 0.0) {
            return Err(ShapeError::InvertedElement {
                particle,
                det: det(&f[particle]),
            });
        }
        self.kind = reference.kind;
        self.fields = reference.fields;
        self.stride = reference.stride;
        self.counts.clone_from(&reference.counts);
        self.weights
            .resize(reference.weights.len(), Weight::default());
        let stride = self.stride.max(1);
        self.weights
            .par_chunks_mut(stride)
            .zip(reference.weights.par_chunks(stride))
            .zip(f.par_iter())
            .for_each(|((out, w0), f)| {
                let f_inv_t = cofactor(f) / det(f);
                for (o, w) in out.iter_mut().zip(w0) {
                    *o = Weight {
                        grad: f_inv_t * w.grad,
                        ..*w
                    };
                }
            });
        Ok(())
    }

    /// Moves every point's support onto the node copies of its velocity field (multi-velocity-field
    /// contact): node `I` of a point `p` of field `f = field(p) < fields` becomes `I + f nodes`, with
    /// `nodes` the number of grid nodes.
    pub fn offset_fields(
        &mut self,
        nodes: usize,
        fields: usize,
        field: impl Fn(usize) -> usize + Sync,
    ) {
        self.fields = fields.max(1);
        let stride = self.stride.max(1);
        self.weights
            .par_chunks_mut(stride)
            .enumerate()
            .for_each(|(p, ws)| {
                debug_assert!(
                    field(p) < fields,
                    "point {p}: field {} of {fields}",
                    field(p)
                );
                let shift = (field(p) * nodes) as u32;
                if shift > 0 {
                    ws.iter_mut().for_each(|w| w.node += shift);
                }
            });
    }

    fn fill<I: Interpolator<D>>(
        &mut self,
        interp: &I,
        grid: &Grid<D>,
        particles: &Particles<D>,
    ) -> Result<(), ShapeError> {
        let n = particles.len();
        let stride = I::MAX_SUPPORT;
        self.stride = stride;
        // Within capacity after the first step: no allocation.
        self.weights.resize(n * stride, Weight::default());
        self.counts.resize(n, 0);
        self.weights
            .par_chunks_mut(stride * CHUNK)
            .zip(self.counts.par_chunks_mut(CHUNK))
            .enumerate()
            .map(|(chunk, (weights, counts))| {
                for (k, (out, count)) in weights
                    .chunks_exact_mut(stride)
                    .zip(counts.iter_mut())
                    .enumerate()
                {
                    let at = At {
                        grid,
                        particles,
                        p: chunk * CHUNK + k,
                    };
                    *count = interp.weights(at, out)? as u8;
                }
                Ok(())
            })
            .reduce(
                || Ok(()),
                |a: Result<(), ShapeError>, b| match (a, b) {
                    (Err(a), Err(b)) => Err(if a.particle() <= b.particle() { a } else { b }),
                    (Err(e), Ok(())) | (Ok(()), Err(e)) => Err(e),
                    (Ok(()), Ok(())) => Ok(()),
                },
            )
    }
}

#[cfg(test)]
mod tests;
