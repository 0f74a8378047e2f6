//! Convected particle domain interpolation: `S_Ip = (1/V_p) int_{Omega_p} N_I dx` with `N_I` replaced by its
//! multilinear interpolation from the `2^D` domain corners, so that only `N_I` at the corners `x_c` is
//! needed:
//!
//! ```text
//! S_Ip = sum_c wf_c N_I(x_c),        grad S_Ip = sum_c wg_c N_I(x_c)
//! ```
//!
//! CPDI1 (Sadeghirad, Brannon, Burghardt 2011, IJNME 86:1435): the parallelogram (3D: parallelepiped)
//! `x_p + r_p xi`, `xi` in `[-1, 1]^D`, whose columns are the half-edge vectors `r_d = F_p r_d^0`; corner `c`
//! is `x_c = x_p + r_p s_c` with the sign vector `s_c` in `{-1, 1}^D`
//! ([`corner_signs`](crate::particles::corner_signs)), `V_p = 2^D det r_p` and
//!
//! ```text
//! wf_c = 1 / 2^D,   wg_c = r_p^-T s_c / 2^D
//! ```
//!
//! In 2D with `r_p = [r1 r2]` and the corners `x_p - r1 - r2, x_p + r1 - r2, x_p + r1 + r2, x_p - r1 + r2`
//! this is `wg_1 = w1 / V_p`, `wg_2 = w2 / V_p`, `wg_3 = -w1 / V_p`, `wg_4 = -w2 / V_p` with
//! `w1 = (r1y - r2y, r2x - r1x)`, `w2 = (r1y + r2y, -r1x - r2x)`.
//!
//! CPDI2 (Sadeghirad, Brannon, Guilkey 2013, IJNME 95:928; CPDI-Q4 in 2D, hexahedra in 3D): the domain is
//! the isoparametric image `x(xi) = sum_c M_c(xi) x_c` of `[-1, 1]^D` under the multilinear functions `M_c`
//! of the tracked corners, `J = dx/dxi`, and
//!
//! ```text
//! V_p = int det J dxi,   wf_c = (1/V_p) int M_c det J dxi,   wg_c = (1/V_p) int cof(J) grad_xi M_c dxi
//! ```
//!
//! evaluated exactly by the `2^D`-point Gauss rule (the integrands are at most cubic per direction). In 2D
//! this is the closed form of the paper, e.g. `wg_1 = (y2 - y4, x4 - x2) / (2 V_p)`. On a parallelogram
//! `wf_c = 1/4` and CPDI2 equals CPDI1. `sum_I S_Ip x_I = sum_c wf_c x_c` is the centroid of the domain.
//! Support: the union of the cells owning the corners (with a corner hold, [`axis_weights`], the cells the
//! corners are held to), each node once (at most `4^D` nodes), in ascending node order when the corners lie
//! within `3^D` cells; a domain whose corners span more than that takes plain CPDI.

use nalgebra::{SMatrix, SVector};

use super::{At, Interpolator, ShapeError, Weight, add_merged, outside};
use crate::grid::{Grid, Locus, MAX_CELL_NODES, axis};
use crate::particles::{corner_signs, domain_corner};
use crate::space::{cofactor, det};

/// The default corner hold of the CPDI interpolators, in cell widths ([`axis_weights`], `[shape]
/// corner_hold`): none, plain CPDI. A hold keeps the support of a domain that crossed a line by a sliver
/// compact at the price of `O(eps)` in the nodal forces at the bodies' edges (docs/shape-functions.md),
/// so it is a run's choice.
pub const DEFAULT_CORNER_HOLD: f64 = 0.0;

/// CPDI1 interpolator (parallelogram or parallelepiped domain from `x_p` and `r_p`) with the corner hold
/// `hold` (cell widths; 0: the corners always take the hats of their cell).
#[derive(Debug, Clone, Copy)]
pub struct Cpdi1 {
    /// Corner hold, cell widths ([`axis_weights`]).
    pub hold: f64,
}

impl Default for Cpdi1 {
    fn default() -> Self {
        Self {
            hold: DEFAULT_CORNER_HOLD,
        }
    }
}

/// CPDI2 interpolator (quadrilateral or hexahedral domain from the tracked corners), with the corner
/// functions `M_c` and their gradients at the `2^D` Gauss points tabulated once, and the corner hold
/// `hold` (cell widths, as [`Cpdi1`]'s).
#[derive(Debug, Clone, Copy)]
pub struct Cpdi2<const D: usize> {
    /// Corner hold, cell widths ([`axis_weights`]).
    pub hold: f64,
    /// `M_c(xi_q)`, `[q][c]`.
    m: [[f64; MAX_CELL_NODES]; MAX_CELL_NODES],
    /// `grad_xi M_c(xi_q)`, `[q][c]`.
    dm: [[SVector<f64, D>; MAX_CELL_NODES]; MAX_CELL_NODES],
}

impl<const D: usize> Default for Cpdi2<D> {
    fn default() -> Self {
        let nc = Grid::<D>::CELL_NODES;
        let g = 1.0 / 3.0_f64.sqrt();
        let mut m = [[0.0; MAX_CELL_NODES]; MAX_CELL_NODES];
        let mut dm = [[SVector::zeros(); MAX_CELL_NODES]; MAX_CELL_NODES];
        for q in 0..nc {
            let xi = corner_signs::<D>(q) * g;
            for c in 0..nc {
                let s = corner_signs::<D>(c);
                let factor = |d: usize| 0.5 * (1.0 + s[d] * xi[d]);
                m[q][c] = (0..D).map(factor).product();
                dm[q][c] = SVector::from_fn(|d, _| {
                    (0..D)
                        .map(|e| if e == d { 0.5 * s[d] } else { factor(e) })
                        .product()
                });
            }
        }
        Self {
            hold: DEFAULT_CORNER_HOLD,
            m,
            dm,
        }
    }
}

impl<const D: usize> Cpdi2<D> {
    /// The CPDI2 interpolator with the corner hold `hold` (cell widths).
    pub fn held(hold: f64) -> Self {
        Self {
            hold,
            ..Self::default()
        }
    }
}

/// A corner's weight along an axis below which it is dropped in the blend of [`axis_weights`].
const TINY: f64 = 1e-12;

/// The weights of a corner along one axis: nodes `first`, `first + 1` and `first + 2` of the axis.
#[derive(Clone, Copy)]
struct AxisWeights {
    first: usize,
    w: [f64; 3],
}

impl AxisWeights {
    /// The last node of the axis with a nonzero weight.
    fn last(&self) -> usize {
        self.first + self.w.iter().rposition(|&w| w != 0.0).unwrap_or(0)
    }
}

/// The weights along one axis at the corner coordinate `s` (cell widths from the grid origin, within
/// `[0, n]` for an axis of `n` cells) of a domain centred at `centre` (same units), with the corner hold
/// `hold` (cell widths, [`DEFAULT_CORNER_HOLD`]).
///
/// A corner that has crossed an interior grid line `k` by `eps` away from its domain's centre is held to
/// the cell on the centre's side: it takes that cell's linear functions extended across the line
/// (`1 + eps` at node `k`, `-eps` at the node beyond) rather than the hats of the cell it entered (`1 - eps`
/// at `k`, `eps` at the node across). Up to `eps = a`, `a = min(hold, |centre - s| / 2)`, the corner is held;
/// from `a` to `2a` the two blend linearly; beyond `2a` the corner takes the hats of its cell, as plain
/// CPDI. The weights sum to one and reproduce `s` at every `eps`, and they are continuous in the corner's
/// position: the interpolation keeps CPDI's partition of unity, linear reproduction and continuity, and
/// a domain that crosses a line by a sliver adds no node to the support. What it gives up: domains that
/// share a corner no longer evaluate it alike (the rule depends on each domain's centre). Inside a body
/// the held corners of the lines around a node cancel and a homogeneous deformation still balances; at
/// the body's edges the nodal forces move by `O(eps)` (a held edge corner weighs the node inside by
/// `-eps` where plain CPDI weighs the node outside by `eps`).
fn axis_weights(s: f64, centre: f64, n: usize, hold: f64) -> AxisWeights {
    let k = s.round();
    let eps = (s - k).abs();
    let away = (s < k && centre > k) || (s > k && centre < k);
    let reach = hold.min(0.5 * (centre - s).abs());
    if away && k > 0.0 && k < n as f64 && eps < 2.0 * reach {
        let k = k as usize;
        // A weight below 1e-12 is rounding, not support: a corner within it of the line is on the line
        // (node `k` alone: `s` reproduced to 1e-12 cell), and a corner on the verge of either end of the
        // blend takes that end (the two differ by less than 1e-12).
        if eps < TINY {
            return AxisWeights {
                first: k,
                w: [1.0, 0.0, 0.0],
            };
        }
        let mut lambda = ((eps - reach) / reach).clamp(0.0, 1.0);
        if lambda * eps < TINY {
            lambda = 0.0;
        }
        if (1.0 - lambda) * eps >= TINY {
            let near = lambda * (1.0 - eps) + (1.0 - lambda) * (1.0 + eps);
            let (across, beyond) = (lambda * eps, -(1.0 - lambda) * eps);
            // The first node with a weight: `k - 1` unless the corner is held outright and node `k - 1`
            // is the one across (weight 0).
            return if s < k as f64 {
                match lambda > 0.0 {
                    true => AxisWeights {
                        first: k - 1,
                        w: [across, near, beyond],
                    },
                    false => AxisWeights {
                        first: k,
                        w: [near, beyond, 0.0],
                    },
                }
            } else {
                AxisWeights {
                    first: k - 1,
                    w: [beyond, near, across],
                }
            };
        }
    }
    // As `Grid::locate`: a point on an interior line belongs to the cell above it.
    let i = (s as usize).min(n - 1);
    let f = s - i as f64;
    AxisWeights {
        first: i,
        w: [1.0 - f, f, 0.0],
    }
}

/// Merges `sum_c wf_c N_I(x_c)` and `sum_c wg_c N_I(x_c)` over the corners into `out`, one entry per node with
/// `N_I(x_c) != 0` for some corner; `N_I(x_c)` are the tensor products of [`axis_weights`] (the hats of the
/// corner's cell, or of the cell it is held to), `centre` the domain's centre.
///
/// Fast path: when the corners' cells span at most 3 cells per axis, the sums are accumulated in a dense
/// `4^D` node window and emitted in ascending node order; larger domains fall back to plain CPDI merged by
/// linear search ([`plain_merge`]).
fn corner_weights<const D: usize>(
    (grid, hold): (&Grid<D>, f64),
    (p, centre): (usize, SVector<f64, D>),
    corners: &[SVector<f64, D>],
    (wf, wg): (&[f64], &[SVector<f64, D>]),
    out: &mut [Weight<D>],
) -> Result<usize, ShapeError> {
    let n = grid.cells();
    let c0 = (centre - grid.origin()) / grid.cell_size();
    let mut axes = [[AxisWeights {
        first: 0,
        w: [0.0; 3],
    }; D]; MAX_CELL_NODES];
    for (c, &xc) in corners.iter().enumerate() {
        let s = (xc - grid.origin()) / grid.cell_size();
        for d in 0..D {
            // `!(s >= 0)` also rejects NaN.
            if !(s[d] >= 0.0 && s[d] <= n[d] as f64) {
                return Err(outside(p, Locus::Corner(c as u8), xc));
            }
            axes[c][d] = axis_weights(s[d], c0[d], n[d], hold);
        }
    }
    let axes = &axes[..corners.len()];
    let low: [usize; D] =
        std::array::from_fn(|d| axes.iter().map(|a| a[d].first).min().unwrap_or(0));
    // Plain CPDI's corners each reach 2 nodes per axis from their cell `first`: a span of more than 3
    // cells is plain CPDI's fallback; a held corner reaches 3 nodes, which must fit the window too.
    if axes
        .iter()
        .any(|a| (0..D).any(|d| a[d].first - low[d] > 2 || a[d].last() - low[d] > 3))
    {
        return plain_merge(grid, corners, (wf, wg), out);
    }
    // Window slot `sum_k a_(axis k) 4^k` is node `low + a` (axes in the grid's numbering order, so that
    // ascending slots are ascending nodes); `out` (4^D entries) is the window, written on first touch (no
    // clearing), then compacted in ascending slot order (a slot is never below its new place).
    let mut used = 0_u64;
    for (c, a) in axes.iter().enumerate() {
        // The nodes a corner weighs per axis: 2 (its cell's), 3 where it is held or blended.
        let len: [usize; D] = std::array::from_fn(|d| a[d].last() - a[d].first + 1);
        for m in 0..len.iter().product() {
            let (mut ijk, mut n_c, mut rest) = ([0; D], 1.0, m);
            for d in 0..D {
                let j = rest % len[d];
                rest /= len[d];
                ijk[d] = a[d].first + j;
                n_c *= a[d].w[j];
            }
            if n_c == 0.0 {
                continue;
            }
            let (value, grad) = (wf[c] * n_c, wg[c] * n_c);
            let slot = (0..D).rev().fold(0, |acc, k| {
                let d = axis::<D>(k);
                4 * acc + ijk[d] - low[d]
            });
            if used & (1 << slot) == 0 {
                out[slot].value = value;
                out[slot].grad = grad;
                used |= 1 << slot;
            } else {
                out[slot].value += value;
                out[slot].grad += grad;
            }
        }
    }
    let mut count = 0;
    while used != 0 {
        let slot = used.trailing_zeros() as usize;
        used &= used - 1;
        let mut ijk = low;
        for k in 0..D {
            ijk[axis::<D>(k)] += (slot >> (2 * k)) % 4;
        }
        let node = grid.node_at(ijk);
        out[count] = Weight {
            node: node as u32,
            value: out[slot].value,
            grad: out[slot].grad,
        };
        count += 1;
    }
    Ok(count)
}

/// The fallback of [`corner_weights`] for a domain whose corners span more than `3^D` cells (stretched
/// far beyond a sliver crossing): plain CPDI, each corner on the `2^D` hats of its cell (at most `4^D`
/// nodes in all), merged by linear search. The corners are known to lie in the grid.
fn plain_merge<const D: usize>(
    grid: &Grid<D>,
    corners: &[SVector<f64, D>],
    (wf, wg): (&[f64], &[SVector<f64, D>]),
    out: &mut [Weight<D>],
) -> Result<usize, ShapeError> {
    let nc = Grid::<D>::CELL_NODES;
    let mut count = 0;
    for (c, &xc) in corners.iter().enumerate() {
        let (cell, f) = grid.locate(xc).expect("corner checked to lie in the grid");
        let nodes = grid.cell_nodes(cell);
        for (&node, &n) in nodes[..nc].iter().zip(&Grid::<D>::cell_values(&f)[..nc]) {
            if n != 0.0 {
                add_merged(out, &mut count, node, wf[c] * n, wg[c] * n);
            }
        }
    }
    Ok(count)
}

/// Errors unless the signed domain area (volume) is positive and finite.
fn check_area(p: usize, area: f64) -> Result<(), ShapeError> {
    if area > 0.0 && area.is_finite() {
        Ok(())
    } else {
        Err(ShapeError::DegenerateDomain { particle: p, area })
    }
}

impl<const D: usize> Interpolator<D> for Cpdi1 {
    const MAX_SUPPORT: usize = 4_usize.pow(D as u32);

    fn weights(&self, at: At<'_, D>, out: &mut [Weight<D>]) -> Result<usize, ShapeError> {
        let At { grid, particles, p } = at;
        let r = &particles.r[p];
        let nc = Grid::<D>::CELL_NODES;
        let det_r = det(r);
        check_area(p, nc as f64 * det_r)?;
        let r_inv_t = cofactor(r) / (det_r * nc as f64);
        let mut corners = [SVector::<f64, D>::zeros(); MAX_CELL_NODES];
        let mut wg = [SVector::<f64, D>::zeros(); MAX_CELL_NODES];
        for c in 0..nc {
            corners[c] = domain_corner(&particles.x[p], r, c);
            wg[c] = r_inv_t * corner_signs::<D>(c);
        }
        let wf = [1.0 / nc as f64; MAX_CELL_NODES];
        corner_weights(
            (grid, self.hold),
            (p, particles.x[p]),
            &corners[..nc],
            (&wf[..nc], &wg[..nc]),
            out,
        )
    }
}

impl<const D: usize> Interpolator<D> for Cpdi2<D> {
    const MAX_SUPPORT: usize = 4_usize.pow(D as u32);

    fn weights(&self, at: At<'_, D>, out: &mut [Weight<D>]) -> Result<usize, ShapeError> {
        let At { grid, particles, p } = at;
        let corners = particles.corners(p);
        let nc = corners.len();
        let mut vol = 0.0;
        let mut wf = [0.0; MAX_CELL_NODES];
        let mut wg = [SVector::<f64, D>::zeros(); MAX_CELL_NODES];
        for (m, dm) in self.m.iter().zip(&self.dm).take(nc) {
            // J from corner differences: free of cancellation far from the origin.
            let mut jac = SMatrix::<f64, D, D>::zeros();
            for c in 1..nc {
                jac += (corners[c] - corners[0]) * dm[c].transpose();
            }
            let (det_j, cof) = (det(&jac), cofactor(&jac));
            vol += det_j;
            for c in 0..nc {
                wf[c] += m[c] * det_j;
                wg[c] += cof * dm[c];
            }
        }
        check_area(p, vol)?;
        for c in 0..nc {
            wf[c] /= vol;
            wg[c] /= vol;
        }
        let centre = corners.iter().sum::<SVector<f64, D>>() / nc as f64;
        corner_weights(
            (grid, self.hold),
            (p, centre),
            corners,
            (&wf[..nc], &wg[..nc]),
            out,
        )
    }
}
