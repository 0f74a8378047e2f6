//! Standard MPM: `S_Ip = N_I(x_p)`, `grad S_Ip = grad N_I(x_p)` (multilinear hat functions of the owning
//! cell).

use super::{At, Interpolator, ShapeError, Weight, outside};
use crate::grid::{Grid, Locus};

/// Linear (bilinear, trilinear) interpolation at the material point; suffers cell-crossing noise.
#[derive(Debug, Clone, Copy, Default)]
pub struct Linear;

impl<const D: usize> Interpolator<D> for Linear {
    const MAX_SUPPORT: usize = 1 << D;

    fn weights(&self, at: At<'_, D>, out: &mut [Weight<D>]) -> Result<usize, ShapeError> {
        let At { grid, particles, p } = at;
        let x = particles.x[p];
        let cell = grid
            .cell_weights(x)
            .ok_or_else(|| outside(p, Locus::Centre, x))?;
        let n = Grid::<D>::CELL_NODES;
        for (k, w) in out.iter_mut().take(n).enumerate() {
            *w = Weight {
                node: cell.nodes[k],
                value: cell.values[k],
                grad: cell.grads[k],
            };
        }
        Ok(n)
    }
}
