//! The contact sets of a step: the rigid devices in contact with the specimen and the node pairs between
//! bodies on their own velocity fields, found at the start of every attempt.

use super::Step;
use super::report::StepError;
use crate::assembly::Newmark;
use crate::contact::{
    self, BodyContact, ContactNode, Converged, DeviceContact, NodePair, NodeStatus, RowMap,
};
use crate::dofs::INACTIVE;
use crate::grid::Grid;
use crate::model::{Model, State};
use crate::particles::Particles;
use crate::petsc::SessionGuard;
use crate::space::{from_xy, xy};
use crate::transfer::GridState;
use nalgebra::{Matrix2, SVector, Vector2};
use std::ops::Range;

/// A rigid device in contact with the specimen during one step attempt: its contact nodes and its motion
/// in the step (translation, and rotation about its pin settled with the active set).
pub(super) struct Device {
    /// The rigid body (index into [`Parameters::rigid`](crate::model::Parameters::rigid)).
    pub(super) body: usize,
    /// The contact nodes with their statuses.
    pub(super) contact: DeviceContact,
    /// In-plane translation increment of the step (mm).
    pub(super) translation: Vector2<f64>,
    /// In-plane pin position (mm); `None` without a pin.
    pub(super) pin: Option<Vector2<f64>>,
    /// Rotation increment about the pin (rad, in the x-y plane).
    pub(super) dtheta: f64,
    /// Length of the contact face (mm).
    pub(super) face_length: f64,
    /// The last `(dtheta, moment)` of the secant on the moment balance.
    secant: Option<(f64, f64)>,
}

impl Device {
    /// The moment balance about the pin (`docs/theory.md`, "Contact with rigid devices"): true if the
    /// moment of the contact forces (`phys`, the physical residual) vanishes to within 1e-5 of the force
    /// times the face length, or the device has no pin or touches nowhere; otherwise one secant step in
    /// `dtheta` with the device increments at the nodes moved to it. The force is taken at least as
    /// `1e-4 s h` (a strain of 1e-4 over one cell, `s` the row scale in MPa, `h` the cell size in mm): a
    /// device that barely touches (a support the wave has not reached, a plate the arm flies away from)
    /// has a moment of round-off, discontinuous in `dtheta` as nodes open and close, which the secant
    /// would chase until the step fails.
    fn balance<const D: usize>(&mut self, phys: &[f64], nf: usize, grid: &Grid<D>, s: f64) -> bool {
        let Some(pin) = self.pin else { return true };
        let d = &mut self.contact;
        let (f, m) = d.resultant(phys, nf, |i| xy(&grid.node_position(i)), pin);
        let tol = 1e-5 * f.norm().max(1e-4 * s * grid.cell_size()) * self.face_length + 1e-12;
        if m.abs() <= tol || d.nodes.iter().all(|c| !c.status.closed()) {
            return true;
        }
        let th = self.dtheta;
        let next = match self.secant {
            Some((th0, m0)) if m != m0 => th - m * (th - th0) / (m - m0),
            _ => th + (0.1 * th.abs()).max(1e-9),
        };
        self.secant = Some((th, m));
        self.dtheta = next;
        let r = contact::rotation(next) - Matrix2::identity();
        for c in &mut d.nodes {
            c.du_device = self.translation + r * (xy(&grid.node_position(c.node)) - pin);
        }
        false
    }

    /// Closed contact nodes leave the step with the device's velocity in the constrained directions (a
    /// perfectly inelastic impact at the node, as in the grid contact of Bardenhagen et al.). The
    /// trapezoidal rule alone would give `v_n+1 = 2 du/dt - v_n`: a node arriving at the relative speed w
    /// would bounce off at -w, and the chatter of the face nodes against a moving device pumped energy
    /// into the specimen (kinetic energy twice the device's work). The device's `reaction` includes the
    /// impulse of that correction, m (a - a_Newmark), which the following step's Newmark acceleration
    /// cancels again, so that the trapezoidal impulse and work of the reaction stay the block's change of
    /// momentum and the device's work.
    fn impact<const D: usize>(
        &self,
        at: &Impact<'_, D>,
        acc_nodes: &mut [SVector<f64, D>],
        reaction: &mut [f64; D],
    ) -> f64 {
        let (d, nm, gs) = (&self.contact, at.nm, at.gs);
        let dt = nm.dt;
        let (n, t) = (from_xy::<D>(d.normal), from_xy::<D>(d.tangent()));
        let mut loss = 0.0;
        for c in d.nodes.iter().filter(|c| c.status.closed()) {
            let (v, a) = (gs.velocity[c.node], gs.acceleration[c.node]);
            let target = from_xy::<D>(c.du_device) / dt;
            // The acceleration that makes v_n + dt ((1 - gamma) a_n + gamma a) equal the target.
            let fit = |e: SVector<f64, D>| {
                (e.dot(&target) - e.dot(&v) - dt * (1.0 - nm.gamma) * e.dot(&a)) / (nm.gamma * dt)
            };
            let acc = &mut acc_nodes[c.node];
            let before = *acc;
            *acc += (fit(n) - n.dot(acc)) * n;
            if c.status == NodeStatus::Stick {
                *acc += (fit(t) - t.dot(acc)) * t;
            }
            let m = gs.mass[c.node];
            let f = m * (*acc - before);
            for (r, f) in reaction.iter_mut().zip(f.iter()) {
                *r += f;
            }
            if at.owned.contains(&c.node) {
                // Relative to the device: the velocity before and after the correction.
                let relative = |acc: &SVector<f64, D>| {
                    (v + dt * ((1.0 - nm.gamma) * a + nm.gamma * acc) - target).norm_squared()
                };
                loss += 0.5 * m * (relative(&before) - relative(acc));
            }
        }
        loss
    }
}

/// What the inelastic-impact corrections of a step read: the Newmark constants, the grid state at the start
/// of the step, and the grid nodes whose energy loss this process counts.
pub(super) struct Impact<'a, const D: usize> {
    /// Newmark constants of the step.
    pub(super) nm: &'a Newmark,
    /// Nodal mass, velocity and acceleration at the start of the step.
    pub(super) gs: &'a GridState<D>,
    /// The grid nodes this process counts ([`Step::owned_nodes`]).
    pub(super) owned: Range<usize>,
}

/// Closed pairs between bodies leave the step with one normal velocity, the mass-weighted mean of the two
/// copies' (the same perfectly inelastic impact as at a device); the two corrections are equal and
/// opposite impulses, so the momentum of the pair is kept.
fn pair_impact<const D: usize>(
    bodies: &BodyContact<D>,
    at: &Impact<'_, D>,
    acc_nodes: &mut [SVector<f64, D>],
) -> f64 {
    let (nm, gs) = (at.nm, at.gs);
    let dt = nm.dt;
    let mut loss = 0.0;
    for c in bodies.pairs.iter().filter(|c| c.closed) {
        let n = c.normal;
        let normal_velocity = |node: usize, acc: &SVector<f64, D>| {
            n.dot(
                &(gs.velocity[node]
                    + dt * ((1.0 - nm.gamma) * gs.acceleration[node] + nm.gamma * acc)),
            )
        };
        let (va, vb) = (
            normal_velocity(c.node_a, &acc_nodes[c.node_a]),
            normal_velocity(c.node_b, &acc_nodes[c.node_b]),
        );
        let (ma, mb) = (gs.mass[c.node_a], gs.mass[c.node_b]);
        let common = (ma * va + mb * vb) / (ma + mb);
        acc_nodes[c.node_a] += n * ((common - va) / (nm.gamma * dt));
        acc_nodes[c.node_b] += n * ((common - vb) / (nm.gamma * dt));
        loss += 0.5 * (ma * (va - common).powi(2) + mb * (vb - common).powi(2));
    }
    loss
}

/// One contact set of a step: the interface through which the step's phases treat every kind of contact
/// alike (`prepare` builds the sets and projects the first guess onto them, the SNES callbacks rewrite
/// their rows, `solve` updates them at each converged iterate until they settle, `finish` takes their
/// reactions and velocity corrections and commits their statuses as the next step's first guess).
/// Devices come first, in the order of the rigid bodies, then the pairs between bodies.
pub(super) enum ContactSet<const D: usize> {
    /// A rigid device against the specimen.
    Device(Device),
    /// The node pairs between the specimen and the bodies on their own velocity fields.
    Bodies(BodyContact<D>),
}

impl<const D: usize> ContactSet<D> {
    /// True if the set takes part in the step (a device always; pairs between bodies if there are any).
    pub(super) fn in_play(&self) -> bool {
        match self {
            Self::Device(_) => true,
            Self::Bodies(b) => !b.pairs.is_empty(),
        }
    }

    /// The device of this set, if it is one.
    pub(super) fn device(&self) -> Option<&Device> {
        match self {
            Self::Device(d) => Some(d),
            Self::Bodies(_) => None,
        }
    }

    /// Projects the guess `x` (all unknowns, `nf` per node) onto the closed constraints (`mass`: the
    /// nodal masses, t).
    pub(super) fn project_guess(&self, x: &mut [f64], nf: usize, mass: &[f64]) {
        match self {
            Self::Device(d) => d.contact.project_guess(x, nf),
            Self::Bodies(b) => b.project_guess(x, nf, |node| mass[node]),
        }
    }

    /// Rewrites the residual rows of the closed constraints (`s`: the row scale, MPa).
    pub(super) fn residual_rows(&self, x: &[f64], r: &mut [f64], nf: usize, s: f64) {
        match self {
            Self::Device(d) => d.contact.residual_rows(x, r, nf, s),
            Self::Bodies(b) => b.residual_rows(x, r, nf, s),
        }
    }

    /// Rewrites the Jacobian rows of the closed constraints in place, where `rows` places them.
    pub(super) fn jacobian_rows(&self, nf: usize, s: f64, rows: &impl RowMap, values: &mut [f64]) {
        match self {
            Self::Device(d) => d.contact.jacobian_rows(nf, s, rows, values),
            Self::Bodies(b) => b.jacobian_rows(nf, s, rows, values),
        }
    }

    /// The largest contact force of the closed constraints (`phys`: the physical residual; N per mm
    /// thickness, N in 3D), the scale of the sign tests.
    pub(super) fn force_scale(&self, phys: &[f64], nf: usize) -> f64 {
        match self {
            Self::Device(d) => d
                .contact
                .nodes
                .iter()
                .filter(|c| c.status.closed())
                .map(|c| Vector2::new(phys[c.row * nf], phys[c.row * nf + 1]).norm())
                .fold(0.0, f64::max),
            Self::Bodies(b) => b.force_scale(phys, nf),
        }
    }

    /// Updates the statuses at the converged iterate `x` with the forces `phys`; returns the number of
    /// changes.
    pub(super) fn update(&mut self, at: Converged<'_>) -> usize {
        match self {
            Self::Device(d) => d.contact.update(at),
            Self::Bodies(b) => b.update(at),
        }
    }

    /// Appends the statuses of the set's nodes to `out` (a pair between bodies as sliding or open): the
    /// active set, compared from solve to solve to find cycles.
    pub(super) fn statuses(&self, out: &mut Vec<NodeStatus>) {
        match self {
            Self::Device(d) => out.extend(d.contact.nodes.iter().map(|c| c.status)),
            Self::Bodies(b) => out.extend(b.pairs.iter().map(|c| match c.closed {
                true => NodeStatus::Slide,
                false => NodeStatus::Open,
            })),
        }
    }

    /// The moment balance of a pinned device ([`Device::balance`]); true for every other set.
    pub(super) fn balance(&mut self, phys: &[f64], nf: usize, grid: &Grid<D>, s: f64) -> bool {
        match self {
            Self::Device(d) => d.balance(phys, nf, grid, s),
            Self::Bodies(_) => true,
        }
    }

    /// The inelastic-impact correction of the closed constraints' nodal accelerations, with its impulse
    /// added to the device's entry of `reactions` (one per constraint set of `model`); returns the
    /// kinetic energy the impacts took out on the nodes `at.owned` (N mm; in 2D per mm thickness).
    pub(super) fn impact(
        &self,
        model: &Model<D>,
        at: &Impact<'_, D>,
        acc_nodes: &mut [SVector<f64, D>],
        reactions: &mut [[f64; D]],
    ) -> f64 {
        match self {
            Self::Device(d) => d.impact(at, acc_nodes, &mut reactions[model.rigid_set(d.body)]),
            Self::Bodies(b) => pair_impact(b, at, acc_nodes),
        }
    }

    /// Keeps the set's final statuses in `state`: the first guess of the next step's active set.
    pub(super) fn commit(&self, state: &mut State<D>) {
        match self {
            Self::Device(d) => {
                state.counters.contact.devices[d.body].statuses =
                    d.contact.nodes.iter().map(|c| (c.node, c.status)).collect();
            }
            Self::Bodies(b) => {
                let closed = &mut state.counters.contact.pairs.closed;
                *closed = b
                    .pairs
                    .iter()
                    .filter(|c| c.closed)
                    .map(|c| c.node_b)
                    .collect();
                closed.sort_unstable();
            }
        }
    }
}

/// The contact face of a rigid device: its unit normal `n` (into the specimen), tangent `t` and the extent
/// of the device's corners along both (mm).
struct Face {
    n: Vector2<f64>,
    t: Vector2<f64>,
    lo: [f64; 2],
    hi: [f64; 2],
}

impl Face {
    /// The face with normal `n` of the device whose points are `points`.
    fn of<const D: usize>(n: Vector2<f64>, points: &Particles<D>) -> Self {
        let t = Vector2::new(-n.y, n.x);
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for x in points.corners.iter().map(xy) {
            for (j, v) in [n.dot(&x), t.dot(&x)].into_iter().enumerate() {
                lo[j] = lo[j].min(v);
                hi[j] = hi[j].max(v);
            }
        }
        Self { n, t, lo, hi }
    }

    /// The face plane `n . x = c_f` (mm).
    fn plane(&self) -> f64 {
        self.hi[0]
    }

    /// The depth of the device along `n` (mm).
    fn depth(&self) -> f64 {
        self.hi[0] - self.lo[0]
    }
}

impl<const D: usize> Step<'_, D> {
    /// Current pin (mm) of rigid body `k`: its pin at t = 0 moved with the accumulated translation;
    /// `None` without a pin.
    pub(super) fn pin_of(&self, k: usize) -> Option<Vector2<f64>> {
        let model = self.model;
        let pin = model.params.rigid[k].contact.as_ref()?.pin?;
        let acc = self.state.counters.accumulated[model.params.boxes.len() + k];
        Some(pin + Vector2::new(acc[0], acc[1]))
    }

    /// The devices in contact of a step attempt, in the order of the rigid bodies: the contact nodes
    /// (active, unconstrained grid nodes of the node layer nearest to the face and within its extent) with
    /// their gaps at the start of the step, their first status (that of the last step, or closed if the
    /// node touches) and the device increment at the node for the translation `translations[k]` (mm) of
    /// rigid body `k` and its rotation about its pin in a step of `dt` (s): the last step's rate times
    /// `dt` if `rotate`, else none.
    pub(super) fn contact_devices(
        &self,
        session: &SessionGuard,
        translations: &[SVector<f64, D>],
        rotate: bool,
        dt: f64,
    ) -> Result<Vec<Device>, StepError> {
        let mut index = vec![usize::MAX; self.model.field_nodes()];
        let mut devices = Vec::new();
        for (k, rb) in self.model.params.rigid.iter().enumerate() {
            let Some(c) = &rb.contact else { continue };
            let pin = self.pin_of(k);
            let dtheta = match pin {
                Some(_) if rotate => self.state.counters.contact.devices[k].rotation_rate * dt,
                _ => 0.0,
            };
            let face = Face::of(
                contact::rotation(self.state.counters.contact.devices[k].rotation) * c.normal,
                &self.state.rigid[k],
            );
            let translation = xy(&translations[k]);
            let r = contact::rotation(dtheta) - Matrix2::identity();
            let motion = |x: Vector2<f64>| match pin {
                Some(pin) => translation + r * (x - pin),
                None => translation,
            };
            let mut nodes = self.face_nodes(&face, rb.field as usize, motion, &mut index);
            self.gaps(session, &face, &mut nodes, &index)?;
            let mut device = DeviceContact {
                normal: face.n,
                friction: c.friction,
                nodes,
            };
            self.first_statuses(
                &mut device,
                &self.state.counters.contact.devices[k].statuses,
                dt,
                &mut index,
            );
            devices.push(Device {
                body: k,
                contact: device,
                translation,
                pin,
                dtheta,
                face_length: face.hi[1] - face.lo[1],
                secant: None,
            });
        }
        Ok(devices)
    }

    /// The candidate contact nodes of every device at the start of the step (grid node indices; the
    /// nodes [`Step::contact_devices`] starts from).
    pub(super) fn device_nodes(&self) -> Vec<usize> {
        let mut index = vec![usize::MAX; self.model.field_nodes()];
        let mut all = Vec::new();
        for (k, rb) in self.model.params.rigid.iter().enumerate() {
            let Some(c) = &rb.contact else { continue };
            let face = Face::of(
                contact::rotation(self.state.counters.contact.devices[k].rotation) * c.normal,
                &self.state.rigid[k],
            );
            let nodes = self.face_nodes(&face, rb.field as usize, |_| Vector2::zeros(), &mut index);
            for c in nodes {
                index[c.node] = usize::MAX;
                all.push(c.node);
            }
        }
        all
    }

    /// The candidate contact nodes of a device's `face` in velocity field `field`, each with the device's
    /// increment `motion(x_I)` and its place in `index` (grid node -> position in the list).
    fn face_nodes(
        &self,
        face: &Face,
        field: usize,
        motion: impl Fn(Vector2<f64>) -> Vector2<f64>,
        index: &mut [usize],
    ) -> Vec<ContactNode> {
        let grid = &self.model.params.grid;
        let (h, nf) = (grid.cell_size(), self.work.dofs.unknowns_per_node());
        let (n, t) = (face.n, face.t);
        let mut nodes = Vec::new();
        for (a, &node) in self.work.dofs.active_nodes().iter().enumerate() {
            let node = node as usize;
            let x = xy(&grid.node_position(node));
            let tx = t.dot(&x);
            if node / grid.num_nodes() != field
                || (n.dot(&x) - face.plane()).abs() > 0.5 * h + 1e-9
                || tx < face.lo[1] - 1e-9
                || tx > face.hi[1] + 1e-9
                || (0..D).any(|c| self.work.dofs.is_constrained(a * nf + c))
            {
                continue;
            }
            index[node] = nodes.len();
            nodes.push(ContactNode {
                node,
                row: a,
                gap: f64::INFINITY,
                du_device: motion(x),
                status: NodeStatus::Open,
            });
        }
        nodes
    }

    /// The gap of every contact node: from the face to the nearest corner of the specimen points (in
    /// front of the device's back face) interpolating to the node, over every process's points; an
    /// overlap found at the start of a step is held, not pushed back (gap 0).
    fn gaps(
        &self,
        session: &SessionGuard,
        face: &Face,
        nodes: &mut [ContactNode],
        index: &[usize],
    ) -> Result<(), StepError> {
        let (n, cf, depth) = (face.n, face.plane(), face.depth());
        let p = &self.state.particles;
        for q in 0..p.len() {
            if n.dot(&xy(&p.x[q])) < cf - depth {
                continue;
            }
            let near = p
                .corners(q)
                .iter()
                .map(|c| n.dot(&xy(c)))
                .fold(f64::INFINITY, f64::min);
            for w in self.work.table.weights(q) {
                let i = index[w.node as usize];
                if w.value > 1e-12 && i != usize::MAX {
                    nodes[i].gap = nodes[i].gap.min(near - cf);
                }
            }
        }
        if self.state.distributed {
            let mut gaps: Vec<f64> = nodes.iter().map(|c| c.gap).collect();
            session.min(&mut gaps)?;
            for (c, g) in nodes.iter_mut().zip(gaps) {
                c.gap = g;
            }
        }
        // A negative gap in the constraint would move the node out by |g| within one step, work that no
        // reaction force accounts for (it made the kinetic and stored energy exceed the device's work in
        // the CT).
        for c in nodes {
            c.gap = c.gap.max(0.0);
        }
        Ok(())
    }

    /// The first status of every contact node of `device`: that of the last step (`warm`), else closed
    /// if the node touches (slipping where its predicted motion slides along a device with friction:
    /// sticking it would reverse its tangential velocity in the trapezoidal rule), else open. Clears the
    /// nodes' places in `index`.
    fn first_statuses(
        &self,
        device: &mut DeviceContact,
        warm: &[(usize, NodeStatus)],
        dt: f64,
        index: &mut [usize],
    ) {
        let h = self.model.params.grid.cell_size();
        let t = device.tangent();
        let closed = device.closed_status();
        for c in &mut device.nodes {
            index[c.node] = usize::MAX;
            let (v, a) = (
                self.work.grid_state.velocity[c.node],
                self.work.grid_state.acceleration[c.node],
            );
            let slide = t.dot(&(xy(&(dt * v + 0.5 * dt * dt * a)) - c.du_device));
            let fresh = if closed == NodeStatus::Stick && slide.abs() > 1e-9 * h {
                NodeStatus::Slip(if slide > 0.0 { 1 } else { -1 })
            } else {
                closed
            };
            c.status = match warm.iter().find(|(node, _)| *node == c.node) {
                Some(&(_, status)) => status,
                None if c.gap <= 1e-9 * h => fresh,
                None => NodeStatus::Open,
            };
            if device.friction == 0.0 && c.status.closed() {
                c.status = NodeStatus::Slide;
            }
        }
    }

    /// The contact pairs between the specimen (field 0) and the bodies of other velocity fields at the
    /// start of the step (`docs/theory.md`, "Contact between bodies"), and the partner of every node copy
    /// in `Workspace::partners` (for the pattern). A pair is a grid node whose copies in field 0 and in
    /// one other field are both active and free (no constraint, not a device's contact node). Its
    /// normal points from the specimen into the other body along the difference of the fields' nodal
    /// mass gradients `sum_p m_p grad S_Ip` (which point out of a body:
    /// the specimen's minus the other's); its gap is the distance along the normal from the farthest
    /// corner of the specimen's points to the nearest corner of the other body's points that
    /// interpolate to the node (held at 0 when they overlap, as for the devices). A pair starts closed
    /// if the predicted increments `dt v_I + dt^2/2 a_I` of its copies overlap, or if it touches and
    /// was closed at the end of the last step.
    pub(super) fn body_pairs(
        &mut self,
        devices: &[Device],
        dt: f64,
    ) -> Result<BodyContact<D>, StepError> {
        let all = self.model.field_nodes();
        self.work.partners.clear();
        if self.model.num_fields() == 1 {
            return Ok(BodyContact::default());
        }
        let mut pairs = self.node_pairs(devices)?;
        let (far_a, near_b) = self.pair_extents(&pairs, all);
        self.work.partners.resize(all, INACTIVE);
        let h = self.model.params.grid.cell_size();
        let gs = &self.work.grid_state;
        let predicted =
            |node: usize| dt * gs.velocity[node] + 0.5 * dt * dt * gs.acceleration[node];
        for (k, c) in pairs.iter_mut().enumerate() {
            c.gap = (near_b[k] - far_a[k]).max(0.0);
            let overlap = c.gap + c.normal.dot(&(predicted(c.node_b) - predicted(c.node_a)));
            let was_closed = self
                .state
                .counters
                .contact
                .pairs
                .closed
                .binary_search(&c.node_b)
                .is_ok();
            c.closed = overlap < -1e-9 * h || (c.gap <= 1e-9 * h && was_closed);
            self.work.partners[c.node_a] = c.node_b as u32;
            self.work.partners[c.node_b] = c.node_a as u32;
        }
        Ok(BodyContact { pairs })
    }

    /// The node pairs of the step without gaps or statuses: grid nodes whose copies in field 0 and in
    /// one other field are active and free (not constrained, not held by one of the `devices`), with the
    /// normal along the difference of the fields' nodal mass gradients.
    fn node_pairs(&self, devices: &[Device]) -> Result<Vec<NodePair<D>>, StepError> {
        let (model, p, table, dofs) = (
            self.model,
            &self.state.particles,
            &self.work.table,
            &self.work.dofs,
        );
        let (grid, fields, all) = (&model.params.grid, model.num_fields(), model.field_nodes());
        let nodes = grid.num_nodes();
        let nf = dofs.unknowns_per_node();
        let mut grad_m = vec![SVector::<f64, D>::zeros(); all];
        for q in 0..p.len() {
            for w in table.weights(q) {
                grad_m[w.node as usize] += p.mass[q] * w.grad;
            }
        }
        // Copies held by a device stay with it.
        let mut taken = vec![false; all];
        for c in devices.iter().flat_map(|d| &d.contact.nodes) {
            taken[c.node] = true;
        }
        let free = |node: usize| {
            dofs.active_index(node)
                .filter(|&a| !taken[node] && (0..D).all(|c| !dofs.is_constrained(a * nf + c)))
        };
        let mut pairs = Vec::new();
        for i in 0..nodes {
            if dofs.active_index(i).is_none() {
                continue;
            }
            let mut others = (1..fields)
                .map(|f| i + f * nodes)
                .filter(|&b| dofs.active_index(b).is_some());
            let Some(b) = others.next() else { continue };
            if others.next().is_some() {
                let at: Vec<String> = grid
                    .node_position(i)
                    .iter()
                    .map(|c| format!("{c:.3}"))
                    .collect();
                return Err(StepError::Setup(format!(
                    "the grid node at ({}) mm carries the specimen and two other bodies: contact is \
                     between the specimen and one body per node; keep the other bodies at least two \
                     cells apart",
                    at.join(", ")
                )));
            }
            let (Some(row_a), Some(row_b)) = (free(i), free(b)) else {
                continue;
            };
            // `sum_p m_p grad S_Ip` points out of a body at its boundary nodes.
            let g = grad_m[i] - grad_m[b];
            if g.norm() == 0.0 {
                continue;
            }
            pairs.push(NodePair {
                node_a: i,
                node_b: b,
                row_a,
                row_b,
                normal: g / g.norm(),
                gap: 0.0,
                closed: false,
            });
        }
        Ok(pairs)
    }

    /// Per pair, the farthest corner of the specimen's points and the nearest corner of the other body's
    /// points along the pair's normal (mm), over the points that interpolate to the pair's copies.
    fn pair_extents(&self, pairs: &[NodePair<D>], all: usize) -> (Vec<f64>, Vec<f64>) {
        let (p, table) = (&self.state.particles, &self.work.table);
        let mut pair_of = vec![usize::MAX; all];
        for (k, c) in pairs.iter().enumerate() {
            pair_of[c.node_a] = k;
            pair_of[c.node_b] = k;
        }
        let mut far_a = vec![f64::NEG_INFINITY; pairs.len()];
        let mut near_b = vec![f64::INFINITY; pairs.len()];
        for q in 0..p.len() {
            for w in table.weights(q) {
                let k = pair_of[w.node as usize];
                if w.value <= 1e-12 || k == usize::MAX {
                    continue;
                }
                let n = pairs[k].normal;
                let along = p.corners(q).iter().map(|c| n.dot(c));
                if w.node as usize == pairs[k].node_a {
                    far_a[k] = along.fold(far_a[k], f64::max);
                } else {
                    near_b[k] = along.fold(near_b[k], f64::min);
                }
            }
        }
        (far_a, near_b)
    }
}
