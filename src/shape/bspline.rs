//! Quadratic B-spline interpolation on the grid nodes. In cell units `d = (x_p - x_I) / h`:
//!
//! ```text
//! phi(d) = 3/4 - d^2             |d| <= 1/2
//!        = (3/2 - |d|)^2 / 2     1/2 < |d| < 3/2
//!        = 0                     otherwise
//! S_Ip = prod_d phi(d_d),   (grad S_Ip)_d = phi'(d_d) prod_{e != d} phi(d_e) / h
//! ```
//!
//! C1-continuous, no cell-crossing noise; the support spans `3^D` nodes, so the body needs at least one empty
//! cell of grid margin around it (uniform splines, no boundary-modified knots).

use super::{At, Interpolator, ShapeError, Weight, tensor_product_weights};

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

impl<const D: usize> Interpolator<D> for Bspline2 {
    const MAX_SUPPORT: usize = 3_usize.pow(D as u32);

    fn weights(&self, at: At<'_, D>, out: &mut [Weight<D>]) -> Result<usize, ShapeError> {
        let At { grid, particles, p } = at;
        tensor_product_weights(grid, p, particles.x[p], |d, _| quadratic(d), out)
    }
}
