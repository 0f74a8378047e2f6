//! Unilateral contact on the background grid: between rigid loading devices and the deformable bodies
//! ([`DeviceContact`], `docs/theory.md`, "Contact with rigid devices"), and between the specimen and
//! deformable bodies on their own velocity fields ([`BodyContact`], "Contact between bodies").
//!
//! A device has a flat contact face with the unit normal `n` (pointing from the device into the
//! specimen) and the tangent `t = (-n_y, n_x)`. Its contact nodes are the active grid nodes of the node
//! layer nearest to the face plane (`|n . x_I - c_f| <= h/2`) within the face's tangential extent. Each
//! has a gap `g_I >= 0` at the start of the step: the distance along `n` from the face to the nearest
//! corner of the specimen points interpolating to the node. With the device's increment `du_b(x_I)` the
//! condition after the step is `g_I + n . (du_I - du_b(x_I)) >= 0` and the contact force on the specimen
//! `F_I = R_I` (the unbalanced physical residual at the node, N per mm thickness) must push:
//! `lambda_I = n . F_I >= 0`.
//!
//! The condition is enforced with an active set of nodal constraints settled within the step: an active
//! node's block row is replaced by the constraint `s (n . du_I - n . du_b + g_I) = 0` and, in `t`, by
//! free sliding `t . R_I = 0`, sticking `s (t . du_I - t . du_b) = 0` or Coulomb slip
//! `t . R_I + mu sigma n . R_I = 0` (sigma = +-1, the assumed slip direction). All rows are linear in
//! the physical rows or in `du`, so the Jacobian is the exact derivative (linear combinations of the
//! physical block rows), and Newton converges quadratically for a fixed set. After each solve the set
//! is updated (tensile nodes released, penetrating nodes added, stick/slip switched by the Coulomb
//! cone and the slip direction) until it does not change.
//!
//! What the contact sets carry from one step to the next is their [`ContactMemory`] (`memory.rs`).

mod memory;

pub use memory::{ContactMemory, ContactRecord, DeviceMemory, PairMemory};

use nalgebra::{Matrix2, SVector, Vector2};

/// A converged solve as the contact updates read it.
#[derive(Debug, Clone, Copy)]
pub struct Converged<'a> {
    /// The solution: displacement increments (mm), `nf` unknowns per node copy.
    pub x: &'a [f64],
    /// The physical residual at `x`: the forces of the devices and of the other bodies on the nodes (N per
    /// mm thickness; N in 3D).
    pub phys: &'a [f64],
    /// Unknowns per node.
    pub nf: usize,
    /// Tolerance of the force sign tests (N per mm thickness; N in 3D).
    pub force_tol: f64,
    /// Tolerance of the gap sign tests (mm).
    pub gap_tol: f64,
}

/// Where a contact writes its Jacobian rows in the matrix values being filled.
pub trait RowMap {
    /// The start of block row `a` in the values, its number of block columns and the position of its
    /// diagonal block; `None`: the row is not among the values (e.g. owned by another process).
    fn row_of(&self, a: usize) -> Option<(usize, usize, usize)>;
    /// The position of entry (row component `i`, block column `pos`, column component `k`) within a
    /// block row of `ncols` block columns.
    fn offset(&self, ncols: usize, i: usize, pos: usize, k: usize) -> usize;
}

/// A [`RowMap`] of two functions: `row_of` and `offset` as the trait's methods.
pub struct BlockRows<R, O> {
    /// [`RowMap::row_of`].
    pub row_of: R,
    /// [`RowMap::offset`].
    pub offset: O,
}

impl<R, O> RowMap for BlockRows<R, O>
where
    R: Fn(usize) -> Option<(usize, usize, usize)>,
    O: Fn(usize, usize, usize, usize) -> usize,
{
    fn row_of(&self, a: usize) -> Option<(usize, usize, usize)> {
        (self.row_of)(a)
    }

    fn offset(&self, ncols: usize, i: usize, pos: usize, k: usize) -> usize {
        (self.offset)(ncols, i, pos, k)
    }
}

/// The contact law of a rigid device (`[[rigid_body]] contact = {...}`).
#[derive(Debug, Clone, PartialEq)]
pub struct Contact {
    /// Unit normal of the contact face at t = 0, from the device into the specimen.
    pub normal: Vector2<f64>,
    /// Coulomb friction coefficient mu (-), 0 = frictionless.
    pub friction: f64,
    /// Pin (mm) at t = 0: the device is driven at this point and turns freely about it (massless: the
    /// moment of the contact forces about the pin vanishes). `None`: the device translates only.
    pub pin: Option<Vector2<f64>>,
}

/// The state of a contact node within a step.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub enum NodeStatus {
    /// Not in contact: the node is free.
    Open,
    /// In contact, no tangential force (frictionless).
    Slide,
    /// In contact and sticking to the device.
    Stick,
    /// In contact and slipping; friction force `t . F = -mu lambda sigma` with `sigma` the sign of the
    /// tangential slip `t . (du - du_b)`.
    Slip(i8),
}

impl NodeStatus {
    /// True if the normal constraint is active.
    pub fn closed(self) -> bool {
        self != NodeStatus::Open
    }
}

/// One contact node of a device in a step.
#[derive(Debug, Clone)]
pub struct ContactNode {
    /// Grid node.
    pub node: usize,
    /// Active-node index (block row).
    pub row: usize,
    /// Gap at the start of the step (mm), >= 0 unless the specimen overlaps the device.
    pub gap: f64,
    /// Increment of the device at this node in the step (mm).
    pub du_device: Vector2<f64>,
    /// Status.
    pub status: NodeStatus,
}

/// The contact nodes of one device in a step.
#[derive(Debug, Clone)]
pub struct DeviceContact {
    /// Unit normal (from the device into the specimen) at the start of the step.
    pub normal: Vector2<f64>,
    /// Friction coefficient (-).
    pub friction: f64,
    /// The nodes.
    pub nodes: Vec<ContactNode>,
}

impl DeviceContact {
    /// Unit tangent `t = (-n_y, n_x)`.
    pub fn tangent(&self) -> Vector2<f64> {
        Vector2::new(-self.normal.y, self.normal.x)
    }

    /// The status of a node that just closed: sliding without friction, else sticking.
    pub fn closed_status(&self) -> NodeStatus {
        if self.friction > 0.0 {
            NodeStatus::Stick
        } else {
            NodeStatus::Slide
        }
    }

    fn row_order(&self) -> ((usize, f64), (usize, f64)) {
        row_order(self.normal)
    }

    /// Rewrites the residual block rows of the closed nodes (`r`: the physical residual, `nf` unknowns
    /// per node, `x` the iterate, `s` the row scale in MPa).
    pub fn residual_rows(&self, x: &[f64], r: &mut [f64], nf: usize, s: f64) {
        let (n, t) = (self.normal, self.tangent());
        let ((rn, sn), (rt, st)) = self.row_order();
        for c in &self.nodes {
            if !c.status.closed() {
                continue;
            }
            let b = c.row * nf;
            let du = Vector2::new(x[b], x[b + 1]);
            let rp = Vector2::new(r[b], r[b + 1]);
            r[b + rn] = sn * s * (n.dot(&(du - c.du_device)) + c.gap);
            r[b + rt] = st
                * match c.status {
                    NodeStatus::Stick => s * t.dot(&(du - c.du_device)),
                    NodeStatus::Slip(sigma) => {
                        t.dot(&rp) + self.friction * f64::from(sigma) * n.dot(&rp)
                    }
                    _ => t.dot(&rp),
                };
        }
    }

    /// Rewrites the Jacobian block rows of the closed nodes in place, where `rows` places them.
    pub fn jacobian_rows(
        &self,
        nf: usize,
        s: f64,
        rows: &(impl RowMap + ?Sized),
        values: &mut [f64],
    ) {
        let (n, t) = (self.normal, self.tangent());
        let ((rn, sn), (rt, st)) = self.row_order();
        let mut tangential = Vec::new();
        for c in &self.nodes {
            if !c.status.closed() {
                continue;
            }
            let Some((start, ncols, diag)) = rows.row_of(c.row) else {
                continue;
            };
            let at = |i, pos, k| start + rows.offset(ncols, i, pos, k);
            // The tangential row from the physical rows, before they are overwritten.
            tangential.clear();
            let w = match c.status {
                NodeStatus::Slip(sigma) => t + self.friction * f64::from(sigma) * n,
                _ => t,
            };
            for pos in 0..ncols {
                for k in 0..nf {
                    let v = match c.status {
                        NodeStatus::Stick => 0.0,
                        _ => w.x * values[at(0, pos, k)] + w.y * values[at(1, pos, k)],
                    };
                    tangential.push(st * v);
                }
            }
            for pos in 0..ncols {
                for k in 0..nf {
                    values[at(rt, pos, k)] = tangential[pos * nf + k];
                    values[at(rn, pos, k)] = 0.0;
                }
            }
            if c.status == NodeStatus::Stick {
                values[at(rt, diag, 0)] = st * s * t.x;
                values[at(rt, diag, 1)] = st * s * t.y;
            }
            values[at(rn, diag, 0)] = sn * s * n.x;
            values[at(rn, diag, 1)] = sn * s * n.y;
        }
    }

    /// Projects the initial guess of the closed nodes onto their constraints.
    pub fn project_guess(&self, x: &mut [f64], nf: usize) {
        let (n, t) = (self.normal, self.tangent());
        for c in &self.nodes {
            if !c.status.closed() {
                continue;
            }
            let b = c.row * nf;
            let mut du = Vector2::new(x[b], x[b + 1]);
            du += n * (n.dot(&(c.du_device - du)) - c.gap);
            if c.status == NodeStatus::Stick {
                du += t * t.dot(&(c.du_device - du));
            }
            x[b] = du.x;
            x[b + 1] = du.y;
        }
    }

    /// Updates the statuses from a converged solve (`x` the solution, `phys` the physical residual,
    /// i.e. the force of the device on the specimen at the contact nodes, N per mm thickness):
    /// tensile nodes open, penetrating open nodes close (slipping in the direction they slide, or
    /// sticking), sticking nodes outside the Coulomb cone slip, slipping nodes whose slip reverses stick.
    /// Returns the number of changes.
    ///
    /// `at.force_tol` (N per mm thickness) and `at.gap_tol` (mm) are the tolerances of the sign tests.
    pub fn update(&mut self, at: Converged<'_>) -> usize {
        let (x, phys, nf) = (at.x, at.phys, at.nf);
        let (force_tol, gap_tol) = (at.force_tol, at.gap_tol);
        let (n, t, mu) = (self.normal, self.tangent(), self.friction);
        let closed = self.closed_status();
        let mut changes = 0;
        for c in &mut self.nodes {
            let b = c.row * nf;
            let du = Vector2::new(x[b], x[b + 1]);
            let f = Vector2::new(phys[b], phys[b + 1]);
            let (lambda, ft) = (n.dot(&f), t.dot(&f));
            let slip = t.dot(&(du - c.du_device));
            let next = match c.status {
                NodeStatus::Open => {
                    if c.gap + n.dot(&(du - c.du_device)) < -gap_tol {
                        // Closing while sliding along the device: slip that way (sticking would reverse
                        // the node's tangential velocity in the trapezoidal rule).
                        if closed == NodeStatus::Stick && slip.abs() > gap_tol {
                            NodeStatus::Slip(if slip > 0.0 { 1 } else { -1 })
                        } else {
                            closed
                        }
                    } else {
                        NodeStatus::Open
                    }
                }
                _ if lambda < -force_tol => NodeStatus::Open,
                NodeStatus::Slide => NodeStatus::Slide,
                NodeStatus::Stick => {
                    if ft.abs() > mu * lambda.max(0.0) + force_tol {
                        NodeStatus::Slip(if ft > 0.0 { -1 } else { 1 })
                    } else {
                        NodeStatus::Stick
                    }
                }
                NodeStatus::Slip(sigma) => {
                    if slip * f64::from(sigma) < -gap_tol {
                        NodeStatus::Stick
                    } else {
                        NodeStatus::Slip(sigma)
                    }
                }
            };
            if next != c.status {
                changes += 1;
                c.status = next;
            }
        }
        changes
    }

    /// Sum of the contact forces on the specimen over the closed nodes (N per mm thickness) and their
    /// moment about `pin` (N mm per mm thickness, counter-clockwise positive).
    pub fn resultant(
        &self,
        phys: &[f64],
        nf: usize,
        grid_x: impl Fn(usize) -> Vector2<f64>,
        pin: Vector2<f64>,
    ) -> (Vector2<f64>, f64) {
        let mut f = Vector2::zeros();
        let mut m = 0.0;
        for c in self.nodes.iter().filter(|c| c.status.closed()) {
            let b = c.row * nf;
            let fi = Vector2::new(phys[b], phys[b + 1]);
            let r = grid_x(c.node) - pin;
            f += fi;
            m += r.x * fi.y - r.y * fi.x;
        }
        (f, m)
    }
}

/// The block-row components of the normal and the tangential row for the unit normal `n` and their
/// signs: the normal constraint takes the component in which `n` is largest, each row is signed so that
/// its diagonal entry is positive (pivoting-free factorisations need non-zero pivots).
fn row_order(n: Vector2<f64>) -> ((usize, f64), (usize, f64)) {
    let t = Vector2::new(-n.y, n.x);
    let rn = if n.y.abs() > n.x.abs() { 1 } else { 0 };
    let rt = 1 - rn;
    ((rn, n[rn].signum()), (rt, t[rt].signum()))
}

/// One node of two-body grid contact in a step: the copies of a grid node in the velocity field of the
/// specimen (`a`) and of another body (`b`), both active (`docs/theory.md`, "Contact between bodies"),
/// in `D` = 2 or 3 dimensions.
#[derive(Debug, Clone)]
pub struct NodePair<const D: usize = 2> {
    /// The specimen's copy of the grid node (field 0: the grid node id).
    pub node_a: usize,
    /// The other body's copy, `node_a + f N` for field `f` and `N` grid nodes.
    pub node_b: usize,
    /// Active-node index (block row) of `node_a`.
    pub row_a: usize,
    /// Active-node index (block row) of `node_b`.
    pub row_b: usize,
    /// Unit normal from body `a` into body `b` (from the nodal mass gradients of the two fields).
    pub normal: SVector<f64, D>,
    /// Gap between the bodies along the normal at the start of the step (mm), >= 0.
    pub gap: f64,
    /// Whether the normal constraint is active (frictionless: no tangential force when it is).
    pub closed: bool,
}

/// A row of copy `b` of a closed pair: its component, its sign and the direction it constrains.
type PairRow<const D: usize> = (usize, f64, SVector<f64, D>);

impl<const D: usize> NodePair<D> {
    /// The rows of copy `b`: first the normal constraint, in the component where `n` is largest; then
    /// the `D - 1` frictionless rows `t . R_b = 0` in the other components, each signed so that its
    /// diagonal entry is positive (pivoting-free factorisations need non-zero pivots). In 2D `t = (-n_y,
    /// n_x)`; in 3D the tangent of component `k` is the projection of `e_k` onto the contact plane,
    /// `(e_k - n_k n) / |e_k - n_k n|` (the two span the plane because `n` is largest in the third).
    pub fn rows(&self) -> [PairRow<D>; D] {
        let n = self.normal;
        let rn = (0..D).fold(0, |m, k| if n[k].abs() > n[m].abs() { k } else { m });
        let mut rows = [(rn, n[rn].signum(), n); D];
        let others = (0..D).filter(|&k| k != rn);
        if D == 2 {
            let t = SVector::<f64, D>::from_fn(|k, _| if k == 0 { -n[1] } else { n[0] });
            let rt = 1 - rn;
            rows[1] = (rt, t[rt].signum(), t);
        } else {
            for (slot, k) in others.enumerate() {
                let t = SVector::<f64, D>::from_fn(|d, _| f64::from(u8::from(d == k))) - n * n[k];
                rows[slot + 1] = (k, 1.0, t / t.norm());
            }
        }
        rows
    }
}

/// Frictionless unilateral contact between the specimen's velocity field and the fields of other
/// deformable bodies (multi-velocity-field grid contact after Bardenhagen et al. 2001, with the
/// displacement gap of Nairn 2013), enforced with an active set settled within the step like
/// [`DeviceContact`]. At a closed pair the block rows `R_a`, `R_b` (the physical residuals of the two
/// copies, i.e. the contact forces on the two bodies) become
///
/// ```text
/// R_a + R_b = 0                       (the contact forces are equal and opposite: momentum)
/// s (g + n . (du_b - du_a)) = 0       (no gap left, no penetration)
/// t . R_b = 0  for the D - 1 tangents (frictionless)
/// ```
///
/// in the rows of copy `a` (all components) and of copy `b` (normal, tangential components,
/// [`NodePair::rows`]). All are linear in the physical rows or in `du`, so the Jacobian stays exact; the
/// two rows of a pair share their block columns (the assembler's pattern joins them), so the sum is
/// formed entry by entry. A closed pair opens when the normal force on `b` pulls (`n . R_b < 0`), an
/// open one closes when the bodies overlap (`g + n . (du_b - du_a) < 0`).
#[derive(Debug, Clone, Default)]
pub struct BodyContact<const D: usize = 2> {
    /// The pairs of the step.
    pub pairs: Vec<NodePair<D>>,
}

/// The `D` components of block row `first` (e.g. `row * nf`) of `v`.
fn block<const D: usize>(v: &[f64], first: usize) -> SVector<f64, D> {
    SVector::from_column_slice(&v[first..first + D])
}

impl<const D: usize> BodyContact<D> {
    /// Rewrites the residual block rows of the closed pairs (`r`: the physical residual, `nf` unknowns
    /// per node, `x` the iterate, `s` the row scale in MPa).
    pub fn residual_rows(&self, x: &[f64], r: &mut [f64], nf: usize, s: f64) {
        for c in self.pairs.iter().filter(|c| c.closed) {
            let n = c.normal;
            let constraint_rows = c.rows();
            let ((rn, sn, _), tangents) = (constraint_rows[0], &constraint_rows[1..]);
            let (a, b) = (c.row_a * nf, c.row_b * nf);
            let (dua, dub, rb) = (block::<D>(x, a), block::<D>(x, b), block::<D>(r, b));
            for d in 0..D {
                r[a + d] += rb[d];
            }
            r[b + rn] = sn * s * (c.gap + n.dot(&(dub - dua)));
            for &(rt, st, t) in tangents {
                r[b + rt] = st * t.dot(&rb);
            }
        }
    }

    /// Rewrites the Jacobian block rows of the closed pairs in place (placed by `rows`;
    /// the two rows of a pair have the same block columns).
    pub fn jacobian_rows(
        &self,
        nf: usize,
        s: f64,
        rows: &(impl RowMap + ?Sized),
        values: &mut [f64],
    ) {
        for c in self.pairs.iter().filter(|c| c.closed) {
            let (Some((sa, ncols, diag_a)), Some((sb, ncols_b, diag_b))) =
                (rows.row_of(c.row_a), rows.row_of(c.row_b))
            else {
                continue;
            };
            debug_assert_eq!(
                ncols, ncols_b,
                "the rows of a contact pair share their columns"
            );
            let n = c.normal;
            let constraint_rows = c.rows();
            let ((rn, sn, _), tangents) = (constraint_rows[0], &constraint_rows[1..]);
            for pos in 0..ncols {
                for k in 0..nf {
                    let rb = SVector::<f64, D>::from_fn(|d, _| {
                        values[sb + rows.offset(ncols, d, pos, k)]
                    });
                    for d in 0..D {
                        values[sa + rows.offset(ncols, d, pos, k)] += rb[d];
                    }
                    for &(rt, st, t) in tangents {
                        values[sb + rows.offset(ncols, rt, pos, k)] = st * t.dot(&rb);
                    }
                    values[sb + rows.offset(ncols, rn, pos, k)] = 0.0;
                }
            }
            for k in 0..D {
                values[sb + rows.offset(ncols, rn, diag_b, k)] = sn * s * n[k];
                values[sb + rows.offset(ncols, rn, diag_a, k)] = -sn * s * n[k];
            }
        }
    }

    /// Projects the initial guess of the closed pairs onto their constraints, moving the two copies
    /// against each other in inverse proportion to their masses (`mass(node)`, t) so that their
    /// momentum is kept.
    pub fn project_guess(&self, x: &mut [f64], nf: usize, mass: impl Fn(usize) -> f64) {
        for c in self.pairs.iter().filter(|c| c.closed) {
            let (a, b) = (c.row_a * nf, c.row_b * nf);
            let n = c.normal;
            let (dua, dub) = (block::<D>(x, a), block::<D>(x, b));
            let excess = c.gap + n.dot(&(dub - dua));
            let (ma, mb) = (mass(c.node_a), mass(c.node_b));
            let (wa, wb) = (mb / (ma + mb), ma / (ma + mb));
            let (na, nb) = (dua + wa * excess * n, dub - wb * excess * n);
            for d in 0..D {
                (x[a + d], x[b + d]) = (na[d], nb[d]);
            }
        }
    }

    /// Updates the statuses from a converged solve (`x` the solution, `phys` the physical residual):
    /// pairs pulling by more than `force_tol` (N per mm thickness; N in 3D) open, open pairs overlapping
    /// by more than `gap_tol` (mm) close. Returns the number of changes.
    pub fn update(&mut self, at: Converged<'_>) -> usize {
        let (x, phys, nf) = (at.x, at.phys, at.nf);
        let (force_tol, gap_tol) = (at.force_tol, at.gap_tol);
        let mut changes = 0;
        for c in &mut self.pairs {
            let (a, b) = (c.row_a * nf, c.row_b * nf);
            let next = if c.closed {
                c.normal.dot(&block::<D>(phys, b)) >= -force_tol
            } else {
                let rel = block::<D>(x, b) - block::<D>(x, a);
                c.gap + c.normal.dot(&rel) < -gap_tol
            };
            if next != c.closed {
                c.closed = next;
                changes += 1;
            }
        }
        changes
    }

    /// The largest contact force of the closed pairs (N per mm thickness; N in 3D), the scale of the
    /// sign tests.
    pub fn force_scale(&self, phys: &[f64], nf: usize) -> f64 {
        self.pairs
            .iter()
            .filter(|c| c.closed)
            .map(|c| block::<D>(phys, c.row_b * nf).norm())
            .fold(0.0, f64::max)
    }
}

/// Rotation by the angle `theta` (rad, counter-clockwise).
pub fn rotation(theta: f64) -> Matrix2<f64> {
    let (s, c) = theta.sin_cos();
    Matrix2::new(c, -s, s, c)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The converged iterate `x`, `phys` of one 2D node with tight tolerances.
    fn converged<'a>(x: &'a [f64], phys: &'a [f64]) -> Converged<'a> {
        Converged {
            x,
            phys,
            nf: 2,
            force_tol: 1e-12,
            gap_tol: 1e-12,
        }
    }

    fn device(status: NodeStatus, friction: f64) -> DeviceContact {
        DeviceContact {
            normal: Vector2::new(0.0, 1.0),
            friction,
            nodes: vec![ContactNode {
                node: 0,
                row: 0,
                gap: 0.1,
                du_device: Vector2::new(0.2, -0.3),
                status,
            }],
        }
    }

    #[test]
    fn statuses_follow_the_sign_tests() {
        // Compressive normal force (+y on the specimen), tangential force inside the cone: stays stuck.
        let mut d = device(NodeStatus::Stick, 0.5);
        assert_eq!(d.update(converged(&[0.2, -0.4], &[0.4, 1.0])), 0);
        // Outside the cone: slips against the force on the specimen (F_x > 0: slides towards -x = +t).
        assert_eq!(d.update(converged(&[0.2, -0.4], &[0.6, 1.0])), 1);
        assert_eq!(d.nodes[0].status, NodeStatus::Slip(1));
        // Tensile: opens.
        d.update(converged(&[0.2, -0.4], &[0.0, -1.0]));
        assert_eq!(d.nodes[0].status, NodeStatus::Open);
        // Open and penetrating (gap 0.1 + (-0.5 + 0.3) < 0) without sliding: closes, sticking.
        d.update(converged(&[0.2, -0.5], &[0.0, 0.0]));
        assert_eq!(d.nodes[0].status, NodeStatus::Stick);
        // Closing while sliding (t . (du - du_b) = -(0 - 0.2) > 0): slips that way.
        d.nodes[0].status = NodeStatus::Open;
        d.update(converged(&[0.0, -0.5], &[0.0, 0.0]));
        assert_eq!(d.nodes[0].status, NodeStatus::Slip(1));
        // Frictionless: closes sliding.
        let mut d = device(NodeStatus::Open, 0.0);
        d.update(converged(&[0.0, -0.5], &[0.0, 0.0]));
        assert_eq!(d.nodes[0].status, NodeStatus::Slide);
    }

    #[test]
    fn constraint_rows_vanish_on_the_constraint() {
        let d = device(NodeStatus::Stick, 0.3);
        let mut x = vec![1.0, 2.0];
        d.project_guess(&mut x, 2);
        let mut r = vec![5.0, 7.0];
        d.residual_rows(&x, &mut r, 2, 1e3);
        assert!(r.iter().all(|v| v.abs() < 1e-12), "{r:?}");
        // The new gap is zero: the node sits on the device face.
        assert!((x[1] - (-0.3 - 0.1)).abs() < 1e-15);
    }
}
