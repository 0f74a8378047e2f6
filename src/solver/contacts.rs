//! The contact sets of a step: the rigid devices in contact with the specimen and the node pairs between
//! bodies on their own velocity fields, found at the start of every attempt.

use super::*;

impl<const D: usize> Step<'_, D> {
    /// Current pin (mm) of rigid body `k`: its pin at t = 0 moved with the accumulated translation;
    /// `None` without a pin.
    pub(super) fn pin_of(&self, k: usize) -> Option<Vector2<f64>> {
        let s = self.m;
        let pin = s.rigid[k].contact.as_ref()?.pin?;
        let acc = self.st.accumulated[s.boxes.len() + k];
        Some(pin + Vector2::new(acc[0], acc[1]))
    }

    /// The contact devices of a step (`None` for glued rigid bodies) and the length of each device's
    /// face (mm): the contact nodes (active, unconstrained grid nodes of the node layer nearest to the
    /// face and within its extent) with their gaps at the start of the step, their first status (that of
    /// the last step, or closed if the node touches) and the device increment at the node for the
    /// translation `translations[k]` (mm) and the rotation `dtheta[k]` (rad) about `pins[k]` in a step of
    /// `dt` (s).
    pub(super) fn contact_devices(
        &self,
        session: &SessionGuard,
        translations: &[SVector<f64, D>],
        pins: &[Option<Vector2<f64>>],
        dtheta: &[f64],
        dt: f64,
    ) -> Result<(Vec<Option<DeviceContact>>, Vec<f64>), StepError> {
        let s = self.m;
        let grid = &s.grid;
        let h = grid.cell_size();
        let nf = self.ws.dofs.fields();
        let mut devices = Vec::with_capacity(s.rigid.len());
        let mut lengths = Vec::with_capacity(s.rigid.len());
        let mut index = vec![usize::MAX; s.field_nodes()];
        for (k, rb) in s.rigid.iter().enumerate() {
            let Some(c) = &rb.contact else {
                devices.push(None);
                lengths.push(0.0);
                continue;
            };
            let n = contact::rotation(self.st.rotations[k]) * c.normal;
            let t = Vector2::new(-n.y, n.x);
            let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
            for x in self.st.rigid[k].corners.iter().map(xy) {
                for (j, v) in [n.dot(&x), t.dot(&x)].into_iter().enumerate() {
                    lo[j] = lo[j].min(v);
                    hi[j] = hi[j].max(v);
                }
            }
            // Face plane n . x = c_f; depth of the device along n.
            let (cf, depth) = (hi[0], hi[0] - lo[0]);
            let r = contact::rotation(dtheta[k]) - nalgebra::Matrix2::identity();
            let translation = xy(&translations[k]);
            let device_du = |x: Vector2<f64>| match pins[k] {
                Some(pin) => translation + r * (x - pin),
                None => translation,
            };
            let warm = &self.st.contact_statuses[k];
            let mut nodes = Vec::new();
            for (a, &node) in self.ws.dofs.active_nodes().iter().enumerate() {
                let node = node as usize;
                let x = xy(&grid.node_position(node));
                let tx = t.dot(&x);
                if node / grid.num_nodes() != rb.field as usize
                    || (n.dot(&x) - cf).abs() > 0.5 * h + 1e-9
                    || tx < lo[1] - 1e-9
                    || tx > hi[1] + 1e-9
                    || (0..D).any(|c| self.ws.dofs.is_constrained(a * nf + c))
                {
                    continue;
                }
                index[node] = nodes.len();
                nodes.push(ContactNode {
                    node,
                    row: a,
                    gap: f64::INFINITY,
                    du_device: device_du(x),
                    status: NodeStatus::Open,
                });
            }
            // Gap: from the face to the nearest corner of the specimen points (in front of the device's
            // back face) interpolating to the node.
            let p = &self.st.particles;
            for q in 0..p.len() {
                if n.dot(&xy(&p.x[q])) < cf - depth {
                    continue;
                }
                let near = p
                    .corners(q)
                    .iter()
                    .map(|c| n.dot(&xy(c)))
                    .fold(f64::INFINITY, f64::min);
                for w in self.ws.table.weights(q) {
                    let i = index[w.node as usize];
                    if w.value > 1e-12 && i != usize::MAX {
                        nodes[i].gap = nodes[i].gap.min(near - cf);
                    }
                }
            }
            // The nearest corner over every process's points.
            if self.st.distributed {
                let mut gaps: Vec<f64> = nodes.iter().map(|c| c.gap).collect();
                session.min(&mut gaps)?;
                for (c, g) in nodes.iter_mut().zip(gaps) {
                    c.gap = g;
                }
            }
            // An overlap found at the start of a step is held, not pushed back: a negative gap in the
            // constraint would move the node out by |g| within one step, work that no reaction force
            // accounts for (it made the kinetic and stored energy exceed the device's work in the CT).
            for c in &mut nodes {
                c.gap = c.gap.max(0.0);
            }
            let mut device = DeviceContact {
                normal: n,
                friction: c.friction,
                nodes,
            };
            let closed = device.closed_status();
            for c in &mut device.nodes {
                index[c.node] = usize::MAX;
                // A node that closes with friction slips if its predicted motion slides along the device
                // (sticking it would reverse its tangential velocity in the trapezoidal rule).
                let (v, a) = (
                    self.ws.grid_state.velocity[c.node],
                    self.ws.grid_state.acceleration[c.node],
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
            devices.push(Some(device));
            lengths.push(hi[1] - lo[1]);
        }
        Ok((devices, lengths))
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
        devices: &[Option<DeviceContact>],
        dt: f64,
    ) -> Result<BodyContact<D>, StepError> {
        let s = self.m;
        let fields = s.num_fields();
        self.ws.partners.clear();
        if fields == 1 {
            return Ok(BodyContact::default());
        }
        let grid = &s.grid;
        let (nodes, all, h) = (grid.num_nodes(), s.field_nodes(), grid.cell_size());
        let (p, table, dofs) = (&self.st.particles, &self.ws.table, &self.ws.dofs);
        let nf = dofs.fields();
        let mut grad_m = vec![SVector::<f64, D>::zeros(); all];
        for q in 0..p.len() {
            for w in table.weights(q) {
                grad_m[w.node as usize] += p.mass[q] * w.grad;
            }
        }
        // Copies held by a device stay with it.
        let mut taken = vec![false; all];
        for c in devices.iter().flatten().flat_map(|d| &d.nodes) {
            taken[c.node] = true;
        }
        let free = |node: usize| {
            dofs.active_index(node)
                .filter(|&a| !taken[node] && (0..D).all(|c| !dofs.is_constrained(a * nf + c)))
        };
        let mut pairs = Vec::new();
        let mut pair_of = vec![usize::MAX; all];
        for i in 0..nodes {
            if dofs.active_index(i).is_none() {
                continue;
            }
            let mut others = (1..fields)
                .map(|f| i + f * nodes)
                .filter(|&b| dofs.active_index(b).is_some());
            let Some(b) = others.next() else { continue };
            if others.next().is_some() {
                let x = grid.node_position(i);
                let at: Vec<String> = x.iter().map(|c| format!("{c:.3}")).collect();
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
            pair_of[i] = pairs.len();
            pair_of[b] = pairs.len();
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
        self.ws.partners.resize(all, INACTIVE);
        let gs = &self.ws.grid_state;
        let predicted =
            |node: usize| dt * gs.velocity[node] + 0.5 * dt * dt * gs.acceleration[node];
        for (k, c) in pairs.iter_mut().enumerate() {
            c.gap = (near_b[k] - far_a[k]).max(0.0);
            let overlap = c.gap + c.normal.dot(&(predicted(c.node_b) - predicted(c.node_a)));
            let was_closed = self.st.closed_pairs.binary_search(&c.node_b).is_ok();
            c.closed = overlap < -1e-9 * h || (c.gap <= 1e-9 * h && was_closed);
            self.ws.partners[c.node_a] = c.node_b as u32;
            self.ws.partners[c.node_b] = c.node_a as u32;
        }
        Ok(BodyContact { pairs })
    }
}
