//! uGIMP (Bardenhagen & Kober 2004): the hat function averaged over the undeformed particle square,
//! `S_Ip = (1/V_p) int_{Omega_p} N_I dx`. Per direction, with the half-width `l = |r_k^0| / h` in cell units
//! (`l = 1/(2n)` for `n` points per cell, i.e. side `l_p = h / n`) and `d = (x_p - x_I) / h`:
//!
//! ```text
//! phi(d) = 1 - (d^2 + l^2) / (2 l)          |d| < l
//!        = 1 - |d|                          l <= |d| <= 1 - l
//!        = (1 + l - |d|)^2 / (4 l)          1 - l < |d| < 1 + l
//!        = 0                                otherwise
//! S_Ip = prod_d phi_d(d_d),   (grad S_Ip)_d = phi_d'(d_d) prod_{e != d} phi_e(d_e) / h
//! ```
//!
//! The domain is not updated with `F_p` ("undeformed" GIMP), and `l <= 1/2` keeps the support within
//! `3^D` nodes.

use nalgebra::SVector;

use super::{At, Interpolator, ShapeError, Weight, tensor_product_weights};

/// uGIMP interpolator with the particle square (cube) of sides `2 |r_d^0|`.
#[derive(Debug, Clone, Copy, Default)]
pub struct Gimp;

/// `(phi(d), phi'(d))` of the 1D uGIMP function with half-width `l`, in cell units.
fn gimp_1d(d: f64, l: f64) -> (f64, f64) {
    let a = d.abs();
    if a < l {
        (1.0 - (d * d + l * l) / (2.0 * l), -d / l)
    } else if a <= 1.0 - l {
        (1.0 - a, -d.signum())
    } else if a < 1.0 + l {
        let t = 1.0 + l - a;
        (t * t / (4.0 * l), -d.signum() * t / (2.0 * l))
    } else {
        (0.0, 0.0)
    }
}

impl<const D: usize> Interpolator<D> for Gimp {
    const MAX_SUPPORT: usize = 3_usize.pow(D as u32);

    fn weights(&self, at: At<'_, D>, out: &mut [Weight<D>]) -> Result<usize, ShapeError> {
        let At { grid, particles, p } = at;
        let h = grid.cell_size();
        let r0 = &particles.r0[p];
        let half = SVector::<f64, D>::from_fn(|d, _| r0.column(d).norm());
        if let Some(&half_width) = half.iter().find(|&&l| !(l > 0.0 && l <= 0.5 * h)) {
            return Err(ShapeError::GimpWidth {
                particle: p,
                half_width,
                half_h: 0.5 * h,
            });
        }
        let l = half / h;
        tensor_product_weights(grid, p, particles.x[p], |d, k| gimp_1d(d, l[k]), out)
    }
}
