//! First phase of a step attempt: shape functions and P2G, the unknowns and their constraints, the loads,
//! the PETSc objects and the first guess.

use super::contacts::{self, Attempt, Sets};
use super::input::Loading;
use super::path;
use super::processes::{self, largest};
use super::report::StepError;
use super::step::Step;
use super::system::LinearSystem;
use crate::boundary::{Motion, prescribed_increment};
use crate::petsc::SessionGuard;
use crate::shape::ShapeTable;
use crate::transfer;
use nalgebra::SVector;

/// Per load, its active grid nodes and their shares of the resultant (summing to 1).
pub(super) type LoadNodes = Vec<Vec<(usize, f64)>>;

/// What `Step::prepare` sets up for one step attempt, owned so that the later phases can borrow
/// the simulation freely.
pub(super) struct StepPlan<const D: usize> {
    /// Time step of the attempt (s) and the time it reaches.
    pub(super) dt: f64,
    pub(super) t_new: f64,
    /// Prescribed increment per constraint set and component (mm), boxes first, then rigid bodies.
    pub(super) set_du: Vec<[Option<f64>; D]>,
    /// The constrained unknowns of each set.
    pub(super) sets: Vec<Vec<usize>>,
    /// The contact sets of the step, kind after kind ([`contacts::build`]): the devices, then the pairs
    /// between bodies.
    pub(super) contacts: Sets<D>,
    /// Inertia and applied forces of the step, and the nodes of each load.
    pub(super) loading: Loading<D>,
    pub(super) load_nodes: LoadNodes,
    /// Whether the PETSc objects were built anew for this step.
    pub(super) new_pattern: bool,
    /// Wall time of the preparation (s).
    pub(super) setup_time: f64,
    /// Path following: the control of the attempt (`path.rs`).
    pub(super) path: Option<path::PathStep>,
}

/// The grid at the start of an attempt besides the grid state ([`Step::grid_phase`]).
pub(super) struct OnGrid<const D: usize> {
    /// Prescribed value per constraint set and component (boxes first, then rigid bodies).
    pub(super) set_values: Vec<[Option<f64>; D]>,
    /// The constrained unknowns of each set.
    pub(super) sets: Vec<Vec<usize>>,
    /// Applied nodal forces (N, in 2D per mm thickness; empty without loads) and the nodes of each load.
    pub(super) nodal_force: Vec<SVector<f64, D>>,
    pub(super) load_nodes: LoadNodes,
    /// The points' `eta_bar` at the active nodes (empty without gradient enhancement).
    pub(super) eta_bar: Vec<f64>,
}

impl<const D: usize> Step<'_, D> {
    /// First phase of a step attempt: the step's data on the grid ([`Step::plan`]), the PETSc objects
    /// (kept if the pattern is unchanged) and the first guess of the solution.
    pub(super) fn prepare(
        &mut self,
        session: &SessionGuard,
        dt: f64,
        prefix: Option<&str>,
    ) -> Result<StepPlan<D>, StepError> {
        let (plan, eta_bar) = self.plan(session, dt)?;
        self.work
            .begin_assembly(self.model, &self.state.particles, &plan.loading);
        let new_pattern = self.linear_system(session, prefix)?;
        let xs = self.first_guess(&plan, &eta_bar);
        let rows = self.own_rows(session);
        let (table, dofs) = (&self.work.table, &self.work.dofs);
        let sys = self.work.system.as_mut().expect("linear system just built");
        sys.owned.scatter(&xs, &mut sys.x)?;
        sys.owned.set_window(session, &sys.x, || {
            processes::unknowns_window(table, dofs, rows)
        })?;
        Ok(StepPlan {
            new_pattern,
            ..plan
        })
    }

    /// The step's data on the grid at `t_n+1 = t_n + dt`: shape functions and P2G, the unknowns and
    /// their constraints, the loads, the contact sets and the inertia of the step; with the points'
    /// `eta_bar` on the nodes (the first guess of the Helmholtz unknowns). Everything the assembler
    /// reads ([`Step::step_input`]) is then in the workspace and the plan.
    pub(super) fn plan(
        &mut self,
        session: &SessionGuard,
        dt: f64,
    ) -> Result<(StepPlan<D>, Vec<f64>), StepError> {
        self.refuse_what_processes_cannot_share(session)?;
        let (t, t_new) = (self.state.counters.time, self.state.counters.time + dt);
        let g = self.grid_phase(session, t_new, |v, rise| {
            prescribed_increment(v, rise, t, dt)
        })?;
        let contacts = self.contact_sets(session, &g.set_values, dt)?;
        let path = self.path_step(session, dt)?;
        let plan = StepPlan {
            dt,
            t_new,
            set_du: g.set_values,
            sets: g.sets,
            contacts,
            loading: Loading::new(self.model, t_new, dt, g.nodal_force),
            load_nodes: g.load_nodes,
            new_pattern: false,
            setup_time: 0.0,
            path,
        };
        Ok((plan, g.eta_bar))
    }

    /// Shape functions, P2G and the unknowns ([`Step::project_to_grid`]); the constraint sets with the
    /// prescribed `value(v, rise_time)` of each moving component; the loads at time `t` and the
    /// points' `eta_bar` on the nodes.
    pub(super) fn grid_phase(
        &mut self,
        session: &SessionGuard,
        t: f64,
        value: impl Fn(f64, f64) -> f64,
    ) -> Result<OnGrid<D>, StepError> {
        self.project_to_grid(session)?;
        let set_values = self.constraint_values(value);
        let sets = self.constrain(&set_values)?;
        self.complete_beyond_windows(session, &sets)?;
        // Loads: the resultant at t spread over the active nodes of each segment.
        let (nodal_force, load_nodes) = self.nodal_loads(t)?;
        let eta_bar = self.nodal_eta_bar(session)?;
        Ok(OnGrid {
            set_values,
            sets,
            nodal_force,
            load_nodes,
            eta_bar,
        })
    }

    /// The contact sets of the attempt: the devices, translating with their prescribed increments
    /// `set_du` and turning about their pins (first guess: the last step's rate), then the pairs between
    /// bodies.
    fn contact_sets(
        &mut self,
        session: &SessionGuard,
        set_du: &[[Option<f64>; D]],
        dt: f64,
    ) -> Result<Sets<D>, StepError> {
        let translations = self.rigid_values(set_du);
        let attempt = Attempt {
            translations: &translations,
            dt: Some(dt),
        };
        contacts::build(self, session, &attempt)
    }

    /// The rigid bodies' entries of the per-set values `set_values` as vectors (free components 0).
    pub(super) fn rigid_values(&self, set_values: &[[Option<f64>; D]]) -> Vec<SVector<f64, D>> {
        set_values[self.model.params.boxes.len()..]
            .iter()
            .map(|d| SVector::from_fn(|c, _| d[c].unwrap_or(0.0)))
            .collect()
    }

    /// The PETSc objects of the step: kept from the last step if the unknowns and the pattern are
    /// unchanged on every process (with points shared out, each sees the pattern of its own points only),
    /// else built anew (returns true). The first solve of an attempt runs with the configured tolerances
    /// and lag (the contact re-solves of an earlier attempt may have changed both) and so starts with a
    /// fresh preconditioner: PETSc rebuilds it at the first Newton iteration of every solve unless the
    /// lag is -1 or persists (`-snes_lag_preconditioner_persists`, a user's choice, left alone).
    fn linear_system(
        &mut self,
        session: &SessionGuard,
        prefix: Option<&str>,
    ) -> Result<bool, StepError> {
        let fits = self
            .work
            .system
            .as_ref()
            .is_some_and(|sys| sys.fits(prefix, &self.work.dofs, &self.work.assembler));
        let new_pattern = session.any(!fits);
        if new_pattern {
            self.work.system = None; // free the old objects first
            let rows = self.own_rows(session);
            self.work.system = Some(LinearSystem::new(
                session,
                prefix,
                &self.model.params.grid,
                &self.work.dofs,
                &self.work.assembler,
                rows,
            )?);
        }
        let sys = self.work.system.as_mut().expect("linear system just built");
        sys.snes.set_tolerances(&sys.tolerances)?;
        if sys.lag > 1 {
            sys.snes.set_lag_preconditioner(sys.lag)?;
        }
        Ok(new_pattern)
    }

    /// The first guess of all unknowns: du = dt v_I + dt^2/2 a_I and the prescribed values for dynamics;
    /// zero everywhere quasi-statically (the first Newton step is then the linear predictor that carries
    /// the prescribed increments into the body); `eta_bar` from the particles (mass-weighted projection);
    /// projected onto the closed contact constraints.
    fn first_guess(&self, plan: &StepPlan<D>, eta_bar: &[f64]) -> Vec<f64> {
        let (dofs, gs, dt) = (&self.work.dofs, &self.work.grid_state, plan.dt);
        let newmark = plan.loading.newmark;
        let nf = dofs.unknowns_per_node();
        let mut xs = vec![0.0; dofs.len()];
        for (a, &node) in dofs.active_nodes().iter().enumerate() {
            let node = node as usize;
            let du = match newmark {
                Some(_) => dt * gs.velocity[node] + 0.5 * dt * dt * gs.acceleration[node],
                None => SVector::zeros(),
            };
            xs[a * nf..a * nf + D].copy_from_slice(du.as_slice());
            if let Some(e) = dofs.layout().eta_bar() {
                xs[a * nf + e] = eta_bar[node];
            }
            for c in 0..nf {
                if let (Some(v), Some(_)) = (dofs.prescribed(a * nf + c), newmark) {
                    xs[a * nf + c] = v;
                }
            }
        }
        for c in &plan.contacts {
            c.project_guess(&mut xs, nf, &gs.mass);
        }
        xs
    }

    /// Shape functions on the committed configuration, P2G (in FEM mode the carried nodal velocity and
    /// acceleration replace the projected ones) and the numbering of the unknowns, nothing constrained
    /// yet. MPM on several processes shares the points out first; P2G sums the own points' nodal values
    /// over the processes, so every process holds the whole grid state.
    pub(super) fn project_to_grid(&mut self, session: &SessionGuard) -> Result<(), StepError> {
        let model = self.model;
        self.share_points(session)?;
        let ps = &self.state.particles;
        let counted = self.own_point_count();
        let local = match &model.fem {
            None => {
                let table = &mut self.work.table;
                table.set_corner_hold(model.params.corner_hold);
                table.compute(model.params.shape, &model.params.grid, ps)
            }
            Some(fem) => self.work.table.push_forward(&fem.points, &ps.f),
        }
        .map_err(|e| StepError::from(e.renumbered(&ps.id)))
        .and_then(|()| self.check_reach());
        self.processes(session).agreed(local)?;
        let fields = model.num_fields();
        if fields > 1 {
            let (nodes, body) = (model.params.grid.num_nodes(), &ps.body);
            self.work.table.offset_fields(nodes, fields, |p| {
                model.params.fields[body[p] as usize] as usize
            });
        }
        self.plan_windows(session)?;
        let ps = &self.state.particles;
        let windows = self.work.windows.as_ref();
        transfer::particles_to_grid_shared(
            &self.work.table,
            ps,
            counted,
            &model.params.grid,
            model.params.mass_tolerance,
            &mut self.work.grid_state,
            (
                |sums: &mut [f64]| match windows {
                    Some(w) => w.sum(session, 1 + 2 * D, sums).map_err(|e| e.to_string()),
                    None => Ok(()),
                },
                |max| match windows {
                    Some(_) => largest(session, max).map_err(|e| e.to_string()),
                    None => Ok(max),
                },
            ),
        )?;
        if let (Some(part), Some(_)) = (&self.work.partition, windows) {
            // The active nodes beyond the rows read: their owners'.
            part.share_owned_flags(session, &mut self.work.grid_state.active)?;
        }
        if let Some((v, a)) = &self.state.fem_nodal {
            // FEM: the nodal state carries over (the same nodes are active in every step).
            self.work.grid_state.velocity.copy_from_slice(v);
            self.work.grid_state.acceleration.copy_from_slice(a);
        }
        let layout = model.layout();
        self.work.dofs.rebuild(&self.work.grid_state.active, layout);
        Ok(())
    }

    /// Per constraint set (boxes first, then rigid bodies) and component: `value(v, rise_time)` for a
    /// component moving with velocity `v`, `None` for a free one.
    pub(super) fn constraint_values(
        &self,
        value: impl Fn(f64, f64) -> f64,
    ) -> Vec<[Option<f64>; D]> {
        let model = self.model;
        model
            .params
            .boxes
            .iter()
            .map(|b| (b.motion, b.rise_time))
            .chain(model.params.rigid.iter().map(|r| (r.motion, r.rise_time)))
            .map(|(motion, rise)| {
                motion.map(|m| match m {
                    Motion::Free => None,
                    Motion::Velocity(v) => Some(value(v, rise)),
                })
            })
            .collect()
    }

    /// Prescribes `values` (one per set, as from `Step::constraint_values`) on the active nodes of
    /// every constraint set; returns each set's constrained unknowns.
    pub(super) fn constrain(
        &mut self,
        values: &[[Option<f64>; D]],
    ) -> Result<Vec<Vec<usize>>, StepError> {
        let model = self.model;
        let grid = &model.params.grid;
        let nf = self.work.dofs.unknowns_per_node();
        let mut sets: Vec<Vec<usize>> = Vec::new();
        for (b, du) in model.params.boxes.iter().zip(values) {
            let mut dofs_of_set = Vec::new();
            // A box holds every body's copy of its nodes.
            for node in 0..model.field_nodes() {
                let x = grid.node_position(node);
                let inside = (0..D).all(|k| x[k] >= b.min[k] - 1e-9 && x[k] <= b.max[k] + 1e-9);
                if let (true, Some(a)) = (inside, self.work.dofs.active_index(node)) {
                    for (c, d) in du.iter().enumerate() {
                        if let Some(d) = d {
                            self.work.dofs.constrain(node, c, *d);
                            dofs_of_set.push(a * nf + c);
                        }
                    }
                }
            }
            sets.push(dofs_of_set);
        }
        let nrigid = model.params.rigid.len();
        self.work.rigid_tables.resize_with(nrigid, ShapeTable::new);
        for (k, (rb, du)) in model
            .params
            .rigid
            .iter()
            .zip(&values[model.params.boxes.len()..])
            .enumerate()
        {
            if rb.contact.is_some() {
                // In contact: constrained by the active set of the step, not here.
                sets.push(Vec::new());
                continue;
            }
            // Glued: the nodes under the body's points (of the reference configuration in FEM mode).
            let points = &self.state.rigid[k];
            let rt = match &model.fem {
                Some(fem) => &fem.rigid[k],
                None => {
                    let table = &mut self.work.rigid_tables[k];
                    table.set_corner_hold(model.params.corner_hold);
                    table.compute(model.params.shape, grid, points)?;
                    &self.work.rigid_tables[k]
                }
            };
            let mut dofs_of_set = Vec::new();
            // The copies of the nodes in the velocity field the body holds.
            let shift = rb.field as usize * grid.num_nodes();
            for p in 0..points.len() {
                for w in rt.weights(p) {
                    if w.value <= 0.0 {
                        continue;
                    }
                    let node = w.node as usize + shift;
                    if let Some(a) = self.work.dofs.active_index(node) {
                        for (c, d) in du.iter().enumerate() {
                            if let Some(d) = d {
                                self.work.dofs.constrain(node, c, *d);
                                dofs_of_set.push(a * nf + c);
                            }
                        }
                    }
                }
            }
            dofs_of_set.sort_unstable();
            dofs_of_set.dedup();
            sets.push(dofs_of_set);
        }
        Ok(sets)
    }

    /// The loads at time `t` on the active nodes: the nodal forces (one per grid node; empty without
    /// loads) and, per load, its nodes with their shares renormalised to 1.
    pub(super) fn nodal_loads(
        &self,
        t: f64,
    ) -> Result<(Vec<SVector<f64, D>>, LoadNodes), StepError> {
        let model = self.model;
        let mut nodal_force = Vec::new();
        let mut load_nodes = Vec::with_capacity(model.params.loads.len());
        for (load, shares) in model.params.loads.iter().zip(&self.model.load_shares) {
            let active: Vec<(usize, f64)> = shares
                .iter()
                .copied()
                .filter(|&(node, _)| self.work.grid_state.active[node])
                .collect();
            let total: f64 = active.iter().map(|(_, w)| w).sum();
            if total <= 0.0 {
                return Err(StepError::Setup(format!(
                    "load `{}`: no node of its segment carries mass (is the segment on the body's \
                     boundary?)",
                    load.name
                )));
            }
            if nodal_force.is_empty() {
                nodal_force = vec![SVector::zeros(); model.params.grid.num_nodes()];
            }
            let f = load.force * load.factor(t);
            let active: Vec<(usize, f64)> =
                active.into_iter().map(|(n, w)| (n, w / total)).collect();
            for &(node, w) in &active {
                nodal_force[node] += w * f;
            }
            load_nodes.push(active);
        }
        Ok((nodal_force, load_nodes))
    }

    /// The points' `eta_bar` projected to the active nodes (mass-weighted), one per grid node; empty for
    /// a run without gradient enhancement.
    pub(super) fn nodal_eta_bar(&self, session: &SessionGuard) -> Result<Vec<f64>, StepError> {
        if self.work.dofs.layout().eta_bar().is_none() {
            return Ok(Vec::new());
        }
        let p = &self.state.particles;
        let mut eb = vec![0.0; self.work.grid_state.mass.len()];
        for q in 0..self.own_point_count() {
            for w in self.work.table.weights(q) {
                eb[w.node as usize] += w.value * p.mass[q] * p.eta_bar[q];
            }
        }
        if let Some(w) = &self.work.windows {
            w.sum(session, 1, &mut eb)?;
        }
        for &node in self.work.dofs.active_nodes() {
            let m = self.work.grid_state.mass[node as usize];
            // Without mass on this process: an active node beyond the rows it reads.
            if m > 0.0 {
                eb[node as usize] /= m;
            }
        }
        Ok(eb)
    }
}

#[cfg(test)]
mod tests {
    use crate::grid::Grid;
    use crate::particles::Particles;
    use crate::shape::{ShapeError, ShapeKind, ShapeTable};
    use nalgebra::Vector2;

    #[test]
    fn pushed_forward_gradients_reproduce_the_deformed_configuration() {
        // FEM mode: with nodes at x_I = F X_I, sum_I x_I (x) grad_{X_n} S_Ip = I.
        let grid = Grid::new(Vector2::zeros(), 1.0, [4, 4]).unwrap();
        let mut p = Particles::new();
        let (r1, r2) = (Vector2::new(0.25, 0.0), Vector2::new(0.0, 0.25));
        for x in [Vector2::new(1.3, 2.2), Vector2::new(0.4, 0.7)] {
            p.push(x, 0.25, 0.25, nalgebra::Matrix2::from_columns(&[r1, r2]), 0);
        }
        let mut reference = ShapeTable::new();
        reference.compute(ShapeKind::Linear, &grid, &p).unwrap();
        let f = nalgebra::Matrix2::new(1.2, 0.3, -0.1, 0.9);
        let mut table = ShapeTable::new();
        table.push_forward(&reference, &[f, f]).unwrap();
        for q in 0..2 {
            let mut m = nalgebra::Matrix2::zeros();
            let mut sum = 0.0;
            for (w, w0) in table.weights(q).iter().zip(reference.weights(q)) {
                assert_eq!(w.value, w0.value);
                m += (f * grid.node_position(w.node as usize)) * w.grad.transpose();
                sum += w.value;
            }
            assert!((m - nalgebra::Matrix2::identity()).norm() < 1e-13, "{m}");
            assert!((sum - 1.0).abs() < 1e-14);
        }
        let inverted = nalgebra::Matrix2::new(-1.0, 0.0, 0.0, 1.0);
        assert!(matches!(
            table.push_forward(&reference, &[f, inverted]),
            Err(ShapeError::InvertedElement { particle: 1, .. })
        ));
    }
}
