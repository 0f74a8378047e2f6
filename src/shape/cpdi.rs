//! Convected particle domain interpolation: `S_Ip = (1/V_p) int_{Omega_p} N_I dx` with `N_I` replaced by its
//! bilinear interpolation from the domain corners, so that only `N_I` at the four corners `x_c` is needed:
//!
//! ```text
//! S_Ip = sum_c wf_c N_I(x_c),        grad S_Ip = sum_c wg_c N_I(x_c)
//! ```
//!
//! CPDI1 (Sadeghirad, Brannon, Burghardt 2011, IJNME 86:1435), parallelogram `x_p -+ r1 -+ r2` with
//! `r_i = F_p r_i^0`, corners `x1 = x_p - r1 - r2, x2 = x_p + r1 - r2, x3 = x_p + r1 + r2, x4 = x_p - r1 + r2`,
//! `V_p = 4 r1 x r2`:
//!
//! ```text
//! wf_c = 1/4,   wg_1 = w1 / V_p,  wg_2 = w2 / V_p,  wg_3 = -w1 / V_p,  wg_4 = -w2 / V_p
//! w1 = (r1y - r2y, r2x - r1x),   w2 = (r1y + r2y, -r1x - r2x)
//! ```
//!
//! CPDI2 / CPDI-Q4 (Sadeghirad, Brannon, Guilkey 2013, IJNME 95:928), tracked corners `x_1..x_4`
//! (counter-clockwise), `V_p = (1/2) sum_c (x_c y_{c+1} - x_{c+1} y_c) = (1/2) (x3 - x1) x (x4 - x2)`:
//!
//! ```text
//! c1 = (x2-x1)(y4-y1) - (y2-y1)(x4-x1),   c2 = (x2-x1)(y3-y2) - (y2-y1)(x3-x2)
//! c3 = (x3-x4)(y4-y1) - (y3-y4)(x4-x1),   c4 = (x3-x4)(y3-y2) - (y3-y4)(x3-x2)
//! wf = 1/(36 V_p) [4c1+2c2+2c3+c4, 2c1+4c2+c3+2c4, c1+2c2+2c3+4c4, 2c1+c2+4c3+2c4]
//! wg_1 = 1/(2 V_p) (y2-y4, x4-x2),  wg_2 = 1/(2 V_p) (y3-y1, x1-x3),  wg_3 = -wg_1,  wg_4 = -wg_2
//! ```
//!
//! On a parallelogram `wf_c = 1/4` and CPDI2 equals CPDI1. `sum_I S_Ip x_I = sum_c wf_c x_c` is the area
//! centroid of the quadrilateral. Support: the union of the cells owning the corners, each node once
//! (at most 16 nodes), in ascending node order when the corners lie within 3 x 3 cells.

use nalgebra::Vector2;

use super::{Interpolator, ShapeError, Weight, add_merged, outside};
use crate::grid::{Grid, Locus};
use crate::particles::{Particles, parallelogram_corners};

/// CPDI1 interpolator (parallelogram domain from `x_p`, `r1`, `r2`).
#[derive(Debug, Clone, Copy, Default)]
pub struct Cpdi1;

/// CPDI2 / CPDI-Q4 interpolator (quadrilateral domain from the tracked `corners`).
#[derive(Debug, Clone, Copy, Default)]
pub struct Cpdi2;

/// Merges `sum_c wf_c N_I(x_c)` and `sum_c wg_c N_I(x_c)` over the corners into `out`, one entry per node with
/// `N_I(x_c) != 0` for some corner.
///
/// Fast path: when the corners' cells span at most 3 x 3 cells, the sums are accumulated in a dense 4 x 4 node
/// window and emitted in ascending node order; larger domains fall back to a linear-search merge.
fn corner_weights(
    grid: &Grid,
    p: usize,
    corners: &[Vector2<f64>; 4],
    wf: [f64; 4],
    wg: [Vector2<f64>; 4],
    out: &mut [Weight],
) -> Result<usize, ShapeError> {
    let mut cells = [(0, 0); 4];
    let mut hats = [[0.0; 4]; 4];
    for (c, &xc) in corners.iter().enumerate() {
        let (cell, f) = grid
            .locate(xc)
            .ok_or_else(|| outside(p, Locus::Corner(c as u8), xc))?;
        cells[c] = cell;
        hats[c] = [
            (1.0 - f.x) * (1.0 - f.y),
            f.x * (1.0 - f.y),
            f.x * f.y,
            (1.0 - f.x) * f.y,
        ];
    }
    let (i0, j0) = cells
        .iter()
        .fold((usize::MAX, usize::MAX), |(i0, j0), &(i, j)| {
            (i0.min(i), j0.min(j))
        });
    if cells.iter().any(|&(i, j)| i - i0 > 2 || j - j0 > 2) {
        let mut count = 0;
        for (c, &(i, j)) in cells.iter().enumerate() {
            let (n0, n3) = (
                grid.node_index(i, j) as u32,
                grid.node_index(i, j + 1) as u32,
            );
            for (node, n) in [n0, n0 + 1, n3 + 1, n3].into_iter().zip(hats[c]) {
                if n != 0.0 {
                    add_merged(out, &mut count, node, wf[c] * n, wg[c] * n);
                }
            }
        }
        return Ok(count);
    }
    // Window slot `a + 4 b` is node `(i0 + a, j0 + b)`.
    let mut value = [0.0; 16];
    let mut grad = [Vector2::zeros(); 16];
    let mut used = 0_u16;
    for (c, &(i, j)) in cells.iter().enumerate() {
        let base = (i - i0) + 4 * (j - j0);
        for (slot, n) in [base, base + 1, base + 5, base + 4]
            .into_iter()
            .zip(hats[c])
        {
            if n != 0.0 {
                value[slot] += wf[c] * n;
                grad[slot] += wg[c] * n;
                used |= 1 << slot;
            }
        }
    }
    let mut count = 0;
    while used != 0 {
        let slot = used.trailing_zeros() as usize;
        used &= used - 1;
        let node = grid.node_index(i0 + slot % 4, j0 + slot / 4) as u32;
        out[count] = Weight {
            node,
            value: value[slot],
            grad: grad[slot],
        };
        count += 1;
    }
    Ok(count)
}

/// Errors unless the signed domain area is positive and finite.
fn check_area(p: usize, area: f64) -> Result<(), ShapeError> {
    if area > 0.0 && area.is_finite() {
        Ok(())
    } else {
        Err(ShapeError::DegenerateDomain { particle: p, area })
    }
}

impl Interpolator for Cpdi1 {
    const MAX_SUPPORT: usize = 16;

    fn weights(
        &self,
        grid: &Grid,
        particles: &Particles,
        p: usize,
        out: &mut [Weight],
    ) -> Result<usize, ShapeError> {
        let (r1, r2) = (particles.r1[p], particles.r2[p]);
        let vol = 4.0 * (r1.x * r2.y - r1.y * r2.x);
        check_area(p, vol)?;
        let w1 = Vector2::new(r1.y - r2.y, r2.x - r1.x) / vol;
        let w2 = Vector2::new(r1.y + r2.y, -r1.x - r2.x) / vol;
        let corners = parallelogram_corners(particles.x[p], r1, r2);
        corner_weights(grid, p, &corners, [0.25; 4], [w1, w2, -w1, -w2], out)
    }
}

impl Interpolator for Cpdi2 {
    const MAX_SUPPORT: usize = 16;

    fn weights(
        &self,
        grid: &Grid,
        particles: &Particles,
        p: usize,
        out: &mut [Weight],
    ) -> Result<usize, ShapeError> {
        let corners = &particles.corners[p];
        let [x1, x2, x3, x4] = *corners;
        // Shoelace area written with the diagonals, free of cancellation far from the origin.
        let vol = 0.5 * (x3 - x1).perp(&(x4 - x2));
        check_area(p, vol)?;
        let c1 = (x2 - x1).perp(&(x4 - x1));
        let c2 = (x2 - x1).perp(&(x3 - x2));
        let c3 = (x3 - x4).perp(&(x4 - x1));
        let c4 = (x3 - x4).perp(&(x3 - x2));
        let s = 1.0 / (36.0 * vol);
        let wf = [
            s * (4.0 * c1 + 2.0 * c2 + 2.0 * c3 + c4),
            s * (2.0 * c1 + 4.0 * c2 + c3 + 2.0 * c4),
            s * (c1 + 2.0 * c2 + 2.0 * c3 + 4.0 * c4),
            s * (2.0 * c1 + c2 + 4.0 * c3 + 2.0 * c4),
        ];
        let g = 0.5 / vol;
        let wg1 = Vector2::new(x2.y - x4.y, x4.x - x2.x) * g;
        let wg2 = Vector2::new(x3.y - x1.y, x1.x - x3.x) * g;
        corner_weights(grid, p, corners, wf, [wg1, wg2, -wg1, -wg2], out)
    }
}
