//! Standard MPM: `S_Ip = N_I(x_p)`, `grad S_Ip = grad N_I(x_p)` (bilinear hat functions of the owning cell).

use super::{Interpolator, ShapeError, Weight, outside};
use crate::grid::{Grid, Locus};
use crate::particles::Particles;

/// Linear (bilinear) interpolation at the material point; suffers cell-crossing noise.
#[derive(Debug, Clone, Copy, Default)]
pub struct Linear;

impl Interpolator for Linear {
    const MAX_SUPPORT: usize = 4;

    fn weights(
        &self,
        grid: &Grid,
        particles: &Particles,
        p: usize,
        out: &mut [Weight],
    ) -> Result<usize, ShapeError> {
        let x = particles.x[p];
        let cell = grid
            .cell_weights(x)
            .ok_or_else(|| outside(p, Locus::Centre, x))?;
        for (k, w) in out.iter_mut().take(4).enumerate() {
            *w = Weight {
                node: cell.nodes[k],
                value: cell.values[k],
                grad: cell.grads[k],
            };
        }
        Ok(4)
    }
}
