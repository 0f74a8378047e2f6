//! Contact between the specimen (field 0) and the bodies on their own velocity fields: node pairs
//! whose two copies may not overlap (`docs/theory.md`, "Contact between bodies"). One set per step
//! (none with one velocity field, none at t = 0); its memory is the run's
//! [`PairMemory`](crate::contact::PairMemory).

use super::{Attempt, ContactKind, ContactSet, Impact, Sets};
use crate::contact::{BodyContact, ContactMemory, Converged, NodePair, NodeStatus, RowMap};
use crate::dofs::INACTIVE;
use crate::model::Model;
use crate::petsc::SessionGuard;
use crate::solver::report::StepError;
use crate::solver::step::Step;
use nalgebra::SVector;

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

impl<const D: usize> ContactSet<D> for BodyContact<D> {
    /// True if there are pairs.
    fn in_play(&self) -> bool {
        !self.pairs.is_empty()
    }

    fn project_guess(&self, x: &mut [f64], nf: usize, mass: &[f64]) {
        BodyContact::project_guess(self, x, nf, |node| mass[node]);
    }

    fn residual_rows(&self, x: &[f64], r: &mut [f64], nf: usize, s: f64) {
        BodyContact::residual_rows(self, x, r, nf, s);
    }

    fn jacobian_rows(&self, nf: usize, s: f64, rows: &dyn RowMap, values: &mut [f64]) {
        BodyContact::jacobian_rows(self, nf, s, rows, values);
    }

    fn force_scale(&self, phys: &[f64], nf: usize) -> f64 {
        BodyContact::force_scale(self, phys, nf)
    }

    fn update(&mut self, at: Converged<'_>) -> usize {
        BodyContact::update(self, at)
    }

    /// A closed pair as sliding, an open one as open.
    fn statuses(&self, out: &mut Vec<NodeStatus>) {
        out.extend(self.pairs.iter().map(|c| match c.closed {
            true => NodeStatus::Slide,
            false => NodeStatus::Open,
        }));
    }

    /// The pairs have no constraint set: their impulses cancel.
    fn impact(
        &self,
        _model: &Model<D>,
        at: &Impact<'_, D>,
        acc_nodes: &mut [SVector<f64, D>],
        _reactions: &mut [[f64; D]],
    ) -> f64 {
        pair_impact(self, at, acc_nodes)
    }

    /// The closed pairs (the other body's node copies, sorted), the first guess of the next step's.
    fn commit(&self, memory: &mut ContactMemory, _dt: f64) {
        let closed = &mut memory.pairs.closed;
        *closed = self
            .pairs
            .iter()
            .filter(|c| c.closed)
            .map(|c| c.node_b)
            .collect();
        closed.sort_unstable();
    }
}

/// The kind of the contact between bodies: one set of node pairs per step if the model has more than
/// one velocity field.
pub(super) struct Bodies;

impl<const D: usize> ContactKind<D> for Bodies {
    /// The pairs of the step ([`Step::body_pairs`]) on the nodes the `earlier` sets leave free; none at
    /// t = 0.
    fn build(
        &self,
        step: &mut Step<'_, D>,
        _session: &SessionGuard,
        attempt: &Attempt<'_, D>,
        earlier: &[Box<dyn ContactSet<D>>],
    ) -> Result<Sets<D>, StepError> {
        let Some(dt) = attempt.dt else {
            return Ok(Vec::new());
        };
        let bodies = step.body_pairs(earlier, dt)?;
        Ok(match step.model.num_fields() > 1 {
            true => vec![Box::new(bodies)],
            false => Vec::new(),
        })
    }
}

impl<const D: usize> Step<'_, D> {
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
    fn body_pairs(
        &mut self,
        earlier: &[Box<dyn ContactSet<D>>],
        dt: f64,
    ) -> Result<BodyContact<D>, StepError> {
        let all = self.model.field_nodes();
        self.work.partners.clear();
        if self.model.num_fields() == 1 {
            return Ok(BodyContact::default());
        }
        let mut pairs = self.node_pairs(earlier)?;
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
    /// one other field are active and free (not constrained, not held by one of the `earlier` sets), with the
    /// normal along the difference of the fields' nodal mass gradients.
    fn node_pairs(
        &self,
        earlier: &[Box<dyn ContactSet<D>>],
    ) -> Result<Vec<NodePair<D>>, StepError> {
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
        // Copies held by an earlier set (a device's contact nodes) stay with it.
        let mut taken = vec![false; all];
        for set in earlier {
            set.hold(&mut taken);
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
