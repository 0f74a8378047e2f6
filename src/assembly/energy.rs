//! The energy books' share of the assembly: the work the time integration charges the points'
//! stresses over a converged step (`docs/theory.md`, "Energy books").

use super::{Assembler, PointEval};
use crate::particles::Particles;
use crate::shape::ShapeTable;
use crate::space::{det, lift3};
use nalgebra::SMatrix;
use rayon::prelude::*;

/// Points per task of [`Assembler::stress_work`].
const WORK_CHUNK: usize = 4096;

impl<const D: usize> Assembler<D> {
    /// The work of the points' stresses over the converged step by the trapezoidal rule of the time
    /// integration, `sum_p V^0 (P_n + P) : (F - F_n) / 2` with `F - F_n = grad du F_n` (N mm; in 2D per
    /// mm thickness), over the first `counted` points (a process's own), and of it the share of the
    /// points that carry no stress at the step's end (eroded in the last step: half their stress at
    /// the step's start, which the projected start of the step still carries). `table` is the step's
    /// start-of-step shape-function table and `particles` the committed state at `t_n` (before G2P:
    /// `F_n`, `sigma_n`); `P_n : (F - F_n) = det F_n sigma_n : grad du`.
    pub fn stress_work(
        &self,
        table: &ShapeTable<D>,
        particles: &Particles<D>,
        counted: usize,
    ) -> [f64; 2] {
        let du = &self.du;
        let point = |p: usize, ev: &PointEval<D>| {
            let mut grad_du = SMatrix::<f64, D, D>::zeros();
            for w in table.weights(p) {
                grad_du += du[w.node as usize] * w.grad.transpose();
            }
            let f_n = particles.f[p];
            let start = det(&f_n) * particles.stress[p].fixed_view::<D, D>(0, 0);
            let end = (ev.p * lift3(&f_n).transpose())
                .fixed_view::<D, D>(0, 0)
                .into_owned();
            0.5 * particles.vol0[p] * (start + end).dot(&grad_du)
        };
        // Summed chunk by chunk in a fixed order: the same digits on any number of threads.
        let chunks: Vec<[f64; 2]> = self.evals[..counted]
            .par_chunks(WORK_CHUNK)
            .enumerate()
            .map(|(c, evals)| {
                let mut sums = [0.0; 2];
                for (i, ev) in evals.iter().enumerate() {
                    let work = point(c * WORK_CHUNK + i, ev);
                    sums[0] += work;
                    if ev.eroded {
                        sums[1] += work;
                    }
                }
                sums
            })
            .collect();
        chunks
            .iter()
            .fold([0.0; 2], |a, b| [a[0] + b[0], a[1] + b[1]])
    }
}
