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
//! Support: the union of the cells owning the corners, each node once (at most `4^D` nodes), in ascending
//! node order when the corners lie within `3^D` cells.

use nalgebra::{SMatrix, SVector};

use super::{At, Interpolator, ShapeError, Weight, add_merged, outside};
use crate::grid::{Grid, Locus, MAX_CELL_NODES, axis, cell_node_offset};
use crate::particles::{corner_signs, domain_corner};
use crate::space::{cofactor, det};

/// CPDI1 interpolator (parallelogram or parallelepiped domain from `x_p` and `r_p`).
#[derive(Debug, Clone, Copy, Default)]
pub struct Cpdi1;

/// CPDI2 interpolator (quadrilateral or hexahedral domain from the tracked corners), with the corner
/// functions `M_c` and their gradients at the `2^D` Gauss points tabulated once.
#[derive(Debug, Clone, Copy)]
pub struct Cpdi2<const D: usize> {
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
        Self { m, dm }
    }
}

/// Merges `sum_c wf_c N_I(x_c)` and `sum_c wg_c N_I(x_c)` over the corners into `out`, one entry per node with
/// `N_I(x_c) != 0` for some corner.
///
/// Fast path: when the corners' cells span at most `3^D` cells, the sums are accumulated in a dense `4^D`
/// node window and emitted in ascending node order; larger domains fall back to a linear-search merge.
fn corner_weights<const D: usize>(
    grid: &Grid<D>,
    p: usize,
    corners: &[SVector<f64, D>],
    wf: &[f64],
    wg: &[SVector<f64, D>],
    out: &mut [Weight<D>],
) -> Result<usize, ShapeError> {
    let nc = Grid::<D>::CELL_NODES;
    let mut cells = [[0; D]; MAX_CELL_NODES];
    let mut hats = [[0.0; MAX_CELL_NODES]; MAX_CELL_NODES];
    for (c, &xc) in corners.iter().enumerate() {
        let (cell, f) = grid
            .locate(xc)
            .ok_or_else(|| outside(p, Locus::Corner(c as u8), xc))?;
        cells[c] = cell;
        hats[c] = Grid::<D>::cell_values(&f);
    }
    let cells = &cells[..nc];
    let low: [usize; D] =
        std::array::from_fn(|d| cells.iter().map(|cell| cell[d]).min().unwrap_or(0));
    if cells
        .iter()
        .any(|cell| (0..D).any(|d| cell[d] - low[d] > 2))
    {
        let mut count = 0;
        for (c, cell) in cells.iter().enumerate() {
            let nodes = grid.cell_nodes(*cell);
            for (&node, &n) in nodes[..nc].iter().zip(&hats[c][..nc]) {
                if n != 0.0 {
                    add_merged(out, &mut count, node, wf[c] * n, wg[c] * n);
                }
            }
        }
        return Ok(count);
    }
    // Window slot `sum_k a_(axis k) 4^k` is node `low + a` (axes in the grid's numbering order, so that
    // ascending slots are ascending nodes); `out` (4^D entries) is the window, written on first touch (no
    // clearing), then compacted in ascending slot order (a slot is never below its new place).
    let mut used = 0_u64;
    for (c, cell) in cells.iter().enumerate() {
        for (k, &n) in hats[c][..nc].iter().enumerate() {
            if n != 0.0 {
                let off = cell_node_offset::<D>(k);
                let slot = (0..D).rev().fold(0, |acc, k| {
                    let d = axis::<D>(k);
                    4 * acc + cell[d] - low[d] + off[d]
                });
                let (value, grad) = (wf[c] * n, wg[c] * n);
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
        corner_weights(grid, p, &corners[..nc], &wf[..nc], &wg[..nc], out)
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
        corner_weights(grid, p, corners, &wf[..nc], &wg[..nc], out)
    }
}
