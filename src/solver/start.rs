//! The start of a dynamic run: the consistent initial acceleration.

use super::contacts::{self, Attempt};
use super::input::Loading;
use super::report::StepError;
use super::step::Step;
use crate::boundary::prescribed_acceleration;
use crate::petsc::SessionGuard;
use crate::transfer;
use nalgebra::SVector;

impl<const D: usize> Step<'_, D> {
    /// The consistent initial acceleration of a dynamic run (`docs/theory.md`, "Initial acceleration"):
    /// on the grid at t = 0, `m_I a_I = f_ext,I - f_int,I` with the lumped mass, `f_ext` the body force
    /// and the loads at t = 0 and `f_int` the internal force of the points' state (the residual of a
    /// quasi-static step at `du = 0`); constrained components take the acceleration of their prescribed
    /// motion ([`prescribed_acceleration`]). Carried to the points with the G2P interpolation,
    /// `a_p = sum_I S_Ip a_I`; in FEM mode it is also the carried nodal acceleration. The result depends
    /// only on the state at t = 0, not on the points' previous `a_p`.
    pub(super) fn initialize_acceleration(
        &mut self,
        session: &SessionGuard,
    ) -> Result<(), StepError> {
        let t = self.state.counters.time;
        let g = self.grid_phase(session, t, |v, rise| prescribed_acceleration(v, rise, t))?;
        let r = self.unbalanced_force(session, g.nodal_force, &g.eta_bar)?;
        let nf = self.work.dofs.unknowns_per_node();
        let mut acc = vec![SVector::<f64, D>::zeros(); self.model.field_nodes()];
        for (a, &node) in self.work.dofs.active_nodes().iter().enumerate() {
            let node = node as usize;
            let m = self.work.grid_state.mass[node];
            acc[node] = SVector::from_fn(|c, _| {
                let d = a * nf + c;
                self.work.dofs.prescribed(d).unwrap_or(-r[d] / m)
            });
        }
        let contact_forces = self.push_at_contacts(session, &g.set_values, &r, &mut acc)?;
        self.initial_reactions(&g.sets, &r, &acc, &contact_forces);
        let table = &self.work.table;
        for (p, ap) in self.state.particles.a.iter_mut().enumerate() {
            *ap = transfer::interpolate(table.weights(p), |i| acc[i]);
        }
        if self.model.fem.is_some() {
            self.state.fem_nodal = Some((self.work.grid_state.velocity.clone(), acc));
        }
        Ok(())
    }

    /// `R = f_int - f_ext` at `du = 0` without inertia, with the full body force and the applied
    /// `nodal_force` at t = 0: the unbalanced forces of every row, the constrained ones included.
    fn unbalanced_force(
        &mut self,
        session: &SessionGuard,
        nodal_force: Vec<SVector<f64, D>>,
        eta_bar: &[f64],
    ) -> Result<Vec<f64>, StepError> {
        let nf = self.work.dofs.unknowns_per_node();
        let loading = Loading {
            newmark: None,
            load_factor: 1.0,
            nodal_force,
        };
        let input = Self::step_input(
            self.model,
            &self.state.particles,
            &self.work.table,
            &self.work.dofs,
            &self.work.grid_state,
            &loading,
            &[],
        );
        self.work.assembler.begin_step(&input);
        let mut x = vec![0.0; self.work.dofs.len()];
        if let Some(e) = self.work.dofs.layout().eta_bar() {
            for (a, &node) in self.work.dofs.active_nodes().iter().enumerate() {
                x[a * nf + e] = eta_bar[node as usize];
            }
        }
        let mut r = vec![0.0; x.len()];
        let local = self
            .work
            .assembler
            .evaluate(&input, &x)
            .and_then(|()| self.work.assembler.residual(&input, &x, &mut r, true));
        let processes = self.processes(session);
        processes.agreed(local.map_err(StepError::from))?;
        processes.complete_rows(self.own_rows(session), nf, &mut r)?;
        Ok(r)
    }

    /// The contact sets at t = 0, moving with the `prescribed` accelerations of the rigid bodies, push
    /// the nodes whose free acceleration `acc` would carry them into a device
    /// ([`ContactSet::push_at_start`](contacts::ContactSet::push_at_start); `r`: the unbalanced forces).
    /// Returns the force of each set that has one on the specimen, with its constraint set.
    fn push_at_contacts(
        &mut self,
        session: &SessionGuard,
        prescribed: &[[Option<f64>; D]],
        r: &[f64],
        acc: &mut [SVector<f64, D>],
    ) -> Result<Vec<(usize, SVector<f64, D>)>, StepError> {
        let nf = self.work.dofs.unknowns_per_node();
        let translations = self.rigid_values(prescribed);
        let attempt = Attempt {
            translations: &translations,
            dt: None,
        };
        let sets = contacts::build(self, session, &attempt)?;
        let (model, gs) = (self.model, &self.work.grid_state);
        Ok(sets
            .iter()
            .filter_map(|c| c.push_at_start(model, gs, (r, nf), acc))
            .collect())
    }

    /// The reactions at t = 0, where the trapezoidal work of the first step starts: the unbalanced force
    /// `r` with the initial inertia in each constrained set, the contact forces `contact_forces` (per
    /// constraint set), the applied resultant of each load.
    fn initial_reactions(
        &mut self,
        sets: &[Vec<usize>],
        r: &[f64],
        acc: &[SVector<f64, D>],
        contact_forces: &[(usize, SVector<f64, D>)],
    ) {
        let (model, nf, t) = (
            self.model,
            self.work.dofs.unknowns_per_node(),
            self.state.counters.time,
        );
        let last = &mut self.state.counters.last_reactions;
        for (reaction, dofs) in last.iter_mut().zip(sets) {
            *reaction = [0.0; D];
            for &d in dofs {
                let (node, c) = (self.work.dofs.node(d / nf), d % nf);
                reaction[c] += r[d] + self.work.grid_state.mass[node] * acc[node][c];
            }
        }
        for &(set, f) in contact_forces {
            last[set] = std::array::from_fn(|c| f[c]);
        }
        for (reaction, load) in last[sets.len()..].iter_mut().zip(&model.params.loads) {
            let f = load.force * load.factor(t);
            *reaction = std::array::from_fn(|c| f[c]);
        }
    }
}
