//! The finite-difference check of rewritten contact rows shared by `tests/contact.rs` (rigid devices) and
//! `tests/body_contact.rs` (pairs between bodies): a linear "physical" residual `R(x) = K x + c` of two
//! nodes with 3 unknowns each, whose rows a contact law rewrites; the rewritten rows are linear in the
//! physical rows and in `x`, so their Jacobian must match central differences to round-off.

use mpm_concrete::petsc::BlockLayout;

/// Unknowns per node and nodes.
pub const NF: usize = 3;
pub const NN: usize = 2;
const N: usize = NF * NN;

/// The physical residual `K x + c` (`K` regular, diagonally dominant; fixed pseudo-random entries).
pub struct LinearRows {
    k: Vec<f64>,
    c: Vec<f64>,
}

impl LinearRows {
    pub fn new() -> Self {
        Self {
            k: (0..N * N)
                .map(|i| ((i * 37 % 11) as f64 - 5.0) + if i % (N + 1) == 0 { 20.0 } else { 0.0 })
                .collect(),
            c: (0..N).map(|i| 0.3 * i as f64 - 1.0).collect(),
        }
    }

    /// `K x + c`.
    pub fn phys(&self, x: &[f64]) -> Vec<f64> {
        (0..N)
            .map(|i| self.c[i] + (0..N).map(|j| self.k[i * N + j] * x[j]).sum::<f64>())
            .collect()
    }

    /// For both block layouts: `K` in a dense 2 x 2 block pattern (block row `a` at `a * NN * NF^2`,
    /// block columns 0 and 1, so row `a`'s diagonal block is at position `a`), rewritten by
    /// `rewrite(values, layout)`, checked entry by entry against central differences of `residual` at
    /// `x0`; `what` names the case in a failure. Returns the rewritten Jacobian as a dense row-major
    /// matrix.
    pub fn check(
        &self,
        residual: impl Fn(&[f64]) -> Vec<f64>,
        rewrite: impl Fn(&mut [f64], BlockLayout),
        x0: &[f64],
        what: &str,
    ) -> Vec<f64> {
        let mut dense = vec![0.0; N * N];
        for layout in [BlockLayout::Rows, BlockLayout::Blocks] {
            let at = |a: usize, i: usize, pos: usize, k: usize| {
                a * NN * NF * NF + layout.offset(NN, NF, i, pos, k)
            };
            let mut values = vec![0.0; N * N];
            for a in 0..NN {
                for i in 0..NF {
                    for pos in 0..NN {
                        for k in 0..NF {
                            values[at(a, i, pos, k)] = self.k[(a * NF + i) * N + pos * NF + k];
                        }
                    }
                }
            }
            rewrite(&mut values, layout);
            let eps = 1e-6;
            for j in 0..N {
                let (mut xp, mut xm) = (x0.to_vec(), x0.to_vec());
                xp[j] += eps;
                xm[j] -= eps;
                let (rp, rm) = (residual(&xp), residual(&xm));
                for i in 0..N {
                    let fd = (rp[i] - rm[i]) / (2.0 * eps);
                    let jac = values[at(i / NF, i % NF, j / NF, j % NF)];
                    assert!(
                        (fd - jac).abs() < 1e-6 * (1.0 + jac.abs()),
                        "{what} {layout:?}: J[{i}][{j}] = {jac} vs FD {fd}"
                    );
                    dense[i * N + j] = jac;
                }
            }
        }
        dense
    }
}

/// The block rows of the dense 2 x 2 block pattern of [`LinearRows::check`]: start, block columns and
/// the diagonal position of block row `a`, as the contact laws' `jacobian_rows` take them.
pub fn row_of(a: usize) -> Option<(usize, usize, usize)> {
    Some((a * NN * NF * NF, NN, a))
}
