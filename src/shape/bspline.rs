//! Quadratic B-spline interpolation on the grid nodes. In cell units `d = (x_p - x_I) / h`:
//!
//! ```text
//! phi(d) = 3/4 - d^2             |d| <= 1/2
//!        = (3/2 - |d|)^2 / 2     1/2 < |d| < 3/2
//!        = 0                     otherwise
//! S_Ip = phi(d_x) phi(d_y),   grad S_Ip = (phi'(d_x) phi(d_y), phi(d_x) phi'(d_y)) / h
//! ```
//!
//! C1-continuous, no cell-crossing noise; the support spans 3 x 3 nodes, so the body needs at least one empty
//! cell of grid margin around it (uniform splines, no boundary-modified knots).

use super::{Interpolator, ShapeError, Weight, tensor_product_weights};
use crate::grid::Grid;
use crate::particles::Particles;

/// Quadratic B-spline interpolator.
#[derive(Debug, Clone, Copy, Default)]
pub struct Bspline2;

/// `(phi(d), phi'(d))` of the quadratic B-spline in cell units.
fn quadratic(d: f64) -> (f64, f64) {
    let a = d.abs();
    if a <= 0.5 {
        (0.75 - d * d, -2.0 * d)
    } else if a < 1.5 {
        let t = 1.5 - a;
        (0.5 * t * t, -t * d.signum())
    } else {
        (0.0, 0.0)
    }
}

impl Interpolator for Bspline2 {
    const MAX_SUPPORT: usize = 9;

    fn weights(
        &self,
        grid: &Grid,
        particles: &Particles,
        p: usize,
        out: &mut [Weight],
    ) -> Result<usize, ShapeError> {
        tensor_product_weights(grid, p, particles.x[p], |d, _| quadratic(d), out)
    }
}
