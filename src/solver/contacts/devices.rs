//! The rigid devices against the specimen: loading plates and supports, flat-faced, translating with
//! their constraint sets and, on a pin, turning about it until the moment of the contact forces about
//! the pin vanishes (`docs/theory.md`, "Contact with rigid devices"). One set per rigid body in contact,
//! in the order of the rigid bodies; its memory is the body's
//! [`DeviceMemory`](crate::contact::DeviceMemory).

use super::{Attempt, ContactKind, ContactSet, Impact, Sets, Turn};
use crate::contact::{
    self, ContactMemory, ContactNode, Converged, DeviceContact, NodeStatus, RowMap,
};
use crate::grid::Grid;
use crate::model::Model;
use crate::particles::Particles;
use crate::petsc::SessionGuard;
use crate::solver::report::StepError;
use crate::solver::step::Step;
use crate::space::{from_xy, xy};
use crate::transfer::GridState;
use nalgebra::{Matrix2, SVector, Vector2};

/// A rigid device in contact with the specimen during one step attempt: its contact nodes and its motion
/// in the step (translation, and rotation about its pin settled with the active set).
struct Device {
    /// The rigid body (index into [`Parameters::rigid`](crate::model::Parameters::rigid)).
    body: usize,
    /// The contact nodes with their statuses.
    contact: DeviceContact,
    /// In-plane translation increment of the step (mm).
    translation: Vector2<f64>,
    /// In-plane pin position (mm); `None` without a pin.
    pin: Option<Vector2<f64>>,
    /// Rotation increment about the pin (rad, in the x-y plane).
    dtheta: f64,
    /// Length of the contact face (mm).
    face_length: f64,
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

impl<const D: usize> ContactSet<D> for Device {
    /// A device always takes part: its nodes may close in any step.
    fn in_play(&self) -> bool {
        true
    }

    fn project_guess(&self, x: &mut [f64], nf: usize, _mass: &[f64]) {
        self.contact.project_guess(x, nf);
    }

    fn residual_rows(&self, x: &[f64], r: &mut [f64], nf: usize, s: f64) {
        self.contact.residual_rows(x, r, nf, s);
    }

    fn jacobian_rows(&self, nf: usize, s: f64, rows: &dyn RowMap, values: &mut [f64]) {
        self.contact.jacobian_rows(nf, s, rows, values);
    }

    fn force_scale(&self, phys: &[f64], nf: usize) -> f64 {
        self.contact
            .nodes
            .iter()
            .filter(|c| c.status.closed())
            .map(|c| Vector2::new(phys[c.row * nf], phys[c.row * nf + 1]).norm())
            .fold(0.0, f64::max)
    }

    fn update(&mut self, at: Converged<'_>) -> usize {
        self.contact.update(at)
    }

    fn statuses(&self, out: &mut Vec<NodeStatus>) {
        out.extend(self.contact.nodes.iter().map(|c| c.status));
    }

    /// The moment balance about the pin ([`Device::balance`]).
    fn balance(&mut self, phys: &[f64], nf: usize, grid: &Grid<D>, s: f64) -> bool {
        Device::balance(self, phys, nf, grid, s)
    }

    /// The device's contact nodes stay with it.
    fn hold(&self, held: &mut [bool]) {
        for c in &self.contact.nodes {
            held[c.node] = true;
        }
    }

    /// Every unknown of the contact nodes (their forces and statuses are evaluated on every process).
    fn read_rows(&self, nf: usize, out: &mut Vec<usize>) {
        out.extend(
            self.contact
                .nodes
                .iter()
                .flat_map(|c| c.row * nf..(c.row + 1) * nf),
        );
    }

    /// The resultant of the contact forces, the rigid body's reaction.
    fn reaction(&self, model: &Model<D>, phys: &[f64], nf: usize, reactions: &mut [[f64; D]]) {
        let pin = self.pin.unwrap_or_else(Vector2::zeros);
        let grid_x = |i| xy(&model.params.grid.node_position(i));
        let (f, _) = self.contact.resultant(phys, nf, grid_x, pin);
        let r = &mut reactions[model.rigid_set(self.body)];
        r[0] = f.x;
        r[1] = f.y;
    }

    fn impact(
        &self,
        model: &Model<D>,
        at: &Impact<'_, D>,
        acc_nodes: &mut [SVector<f64, D>],
        reactions: &mut [[f64; D]],
    ) -> f64 {
        Device::impact(
            self,
            at,
            acc_nodes,
            &mut reactions[model.rigid_set(self.body)],
        )
    }

    fn turn(&self, turns: &mut [Turn]) {
        turns[self.body] = Turn {
            pin: self.pin,
            dtheta: self.dtheta,
        };
    }

    /// The final statuses, the first guess of the next step's active set, and the rotation about the
    /// pin with its rate, the first guess of the next step's.
    fn commit(&self, memory: &mut ContactMemory, dt: f64) {
        let m = &mut memory.devices[self.body];
        m.rotation += self.dtheta;
        m.rotation_rate = self.dtheta / dt;
        m.statuses = self
            .contact
            .nodes
            .iter()
            .map(|c| (c.node, c.status))
            .collect();
    }

    /// A touching node whose free acceleration `acc` would carry it into the device takes the device's
    /// normal acceleration (node by node: the lumped mass decouples them; friction is not applied at
    /// t = 0); the device's force is that of its pushed nodes.
    fn push_at_start(
        &self,
        model: &Model<D>,
        gs: &GridState<D>,
        (r, nf): (&[f64], usize),
        acc: &mut [SVector<f64, D>],
    ) -> Option<(usize, SVector<f64, D>)> {
        let n = from_xy::<D>(self.contact.normal);
        let mut force = SVector::<f64, D>::zeros();
        for c in self.contact.nodes.iter().filter(|c| c.status.closed()) {
            let push = n.dot(&(from_xy::<D>(c.du_device) - acc[c.node]));
            if push > 0.0 {
                acc[c.node] += push * n;
                let b = c.row * nf;
                force += SVector::<f64, D>::from_column_slice(&r[b..b + D])
                    + gs.mass[c.node] * acc[c.node];
            }
        }
        Some((model.rigid_set(self.body), force))
    }
}

/// The kind of the rigid devices: one set per rigid body in contact.
pub(super) struct Devices;

impl<const D: usize> ContactKind<D> for Devices {
    /// The devices translating with `attempt.translations` and, in a step, turning about their pins at
    /// the last step's rate ([`Step::contact_devices`]).
    fn build(
        &self,
        step: &mut Step<'_, D>,
        session: &SessionGuard,
        attempt: &Attempt<'_, D>,
        _earlier: &[Box<dyn ContactSet<D>>],
    ) -> Result<Sets<D>, StepError> {
        let (rotate, dt) = (attempt.dt.is_some(), attempt.dt.unwrap_or(0.0));
        let devices = step.contact_devices(session, attempt.translations, rotate, dt)?;
        Ok(devices
            .into_iter()
            .map(|d| Box::new(d) as Box<dyn ContactSet<D>>)
            .collect())
    }

    fn candidates(&self, step: &Step<'_, D>, out: &mut Vec<usize>) {
        out.extend(step.device_nodes());
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
    fn pin_of(&self, k: usize) -> Option<Vector2<f64>> {
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
    fn contact_devices(
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
    fn device_nodes(&self) -> Vec<usize> {
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
        let mut gaps: Vec<f64> = nodes.iter().map(|c| c.gap).collect();
        self.processes(session).min(&mut gaps)?;
        for (c, g) in nodes.iter_mut().zip(gaps) {
            c.gap = g;
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
}
