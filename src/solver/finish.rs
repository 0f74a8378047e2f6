//! Third phase of a step attempt: reactions, the new nodal accelerations, the work of the constraints,
//! G2P and the commit of the material state, the motion of the rigid bodies; the report.

use super::contacts::{self, Turn};
use super::path;
use super::prepare::StepPlan;
use super::report::{StepError, StepReport};
use super::solve::Solved;
use super::step::Step;
use crate::assembly::{Committed, Newmark};
use crate::petsc::SessionGuard;
use crate::space::{from_xy, rotation_xy};
use crate::transfer::{self, StepSolution};
use nalgebra::{SMatrix, SVector, Vector2};
use std::time::Instant;

/// What `finish` computes before the commit: per constraint set the reaction (N; in 2D per mm
/// thickness) and the prescribed displacement increment (mm), loads included, and the nodal increments
/// and accelerations of the solution.
struct Outcome<const D: usize> {
    reactions: Vec<[f64; D]>,
    displacements: Vec<[f64; D]>,
    du_nodes: Vec<SVector<f64, D>>,
    acc_nodes: Vec<SVector<f64, D>>,
    /// Kinetic energy lost at the inelastic impacts of the closed contact constraints on this process's
    /// nodes (N mm; in 2D per mm thickness).
    contact_loss: f64,
}

impl<const D: usize> Step<'_, D> {
    /// Third phase: reactions and device forces, the new nodal accelerations, the work of the
    /// constraints, G2P and the commit of the material state, the motion of the rigid bodies; the report.
    pub(super) fn finish(
        &mut self,
        session: &SessionGuard,
        mut plan: StepPlan<D>,
        solved: Solved,
        t0: Instant,
    ) -> Result<StepReport, StepError> {
        if let Some(p) = &plan.path {
            path::scale_increments(&mut plan.set_du, p.ratio);
        }
        let out = self.outcome(&plan, &solved.phys);
        let work = self.work(session, &plan, &out)?;
        let counted = self.own_point_count();
        let grid_kinetic = self.grid_kinetic_energies(&plan, &out);
        let points_kinetic = self.kinetic_energy(counted);
        let stress_work =
            self.work
                .assembler
                .stress_work(&self.work.table, &self.state.particles, counted);
        let committed = self.move_points(session, &plan, &out, counted)?;
        self.move_rigid_bodies(&plan, &out);
        let st = &mut *self.state;
        for (acc, du) in st.counters.accumulated.iter_mut().zip(&out.displacements) {
            for c in 0..D {
                acc[c] += du[c];
            }
        }
        st.counters.last_reactions = out.reactions.clone();
        st.counters.external_work += work;
        st.counters.time = plan.t_new;
        st.counters.step += 1;
        let kinetic = self.kinetic_energy(counted);
        let transfer = match grid_kinetic {
            Some([start, end]) => (points_kinetic - start) - (kinetic - end),
            None => 0.0,
        };
        let mut energies = [kinetic, committed.stored];
        let mut books = [
            committed.dissipated,
            committed.eroding,
            out.contact_loss,
            transfer,
            stress_work[0],
            stress_work[1],
        ];
        let processes = self.processes(session);
        processes.sum(&mut energies)?;
        processes.sum(&mut books)?;
        let b = &mut self.state.counters.books;
        b.damage += books[0];
        // The points eroded in the last step carry no stress from this step on.
        b.erosion += b.eroding;
        b.eroding = books[1];
        b.contact += books[2];
        b.transfer += books[3];
        if let (Some(all), Some(eroded)) = (b.stress_work.as_mut(), b.eroded_work.as_mut()) {
            *all += books[4];
            *eroded += books[5];
        }
        let mut report = self.report(&plan, solved, &out, energies, t0);
        report.path = self.path_point(session, plan.path.as_ref())?;
        Ok(report)
    }

    /// The reactions of the constraint sets and devices and the loads' resultants, the sets'
    /// displacement increments, and the new nodal accelerations (Newmark, with the inelastic-impact
    /// correction of the closed contact constraints, whose impulse the devices' reactions include).
    fn outcome(&self, plan: &StepPlan<D>, phys: &[f64]) -> Outcome<D> {
        let (model, nf) = (self.model, self.work.dofs.unknowns_per_node());
        let mut reactions: Vec<[f64; D]> = plan
            .sets
            .iter()
            .map(|dofs| {
                let mut r = [0.0; D];
                for &d in dofs {
                    r[d % nf] += phys[d];
                }
                r
            })
            .collect();
        for c in &plan.contacts {
            c.reaction(model, phys, nf, &mut reactions);
        }
        let du_nodes = self.work.assembler.nodal_du().to_vec();
        let mut acc_nodes = vec![SVector::<f64, D>::zeros(); model.field_nodes()];
        let mut contact_loss = 0.0;
        if let Some(nm) = plan.loading.newmark {
            let gs = &self.work.grid_state;
            for &node in self.work.dofs.active_nodes() {
                let node = node as usize;
                acc_nodes[node] =
                    nm.acceleration(du_nodes[node], gs.velocity[node], gs.acceleration[node]);
            }
            let owned = self.owned_nodes();
            for c in &plan.contacts {
                let impact = contacts::Impact {
                    nm: &nm,
                    gs,
                    owned: owned.clone(),
                };
                contact_loss += c.impact(model, &impact, &mut acc_nodes, &mut reactions);
            }
        }
        let mut displacements: Vec<[f64; D]> = plan
            .set_du
            .iter()
            .map(|d| d.map(|v| v.unwrap_or(0.0)))
            .collect();
        for (load, nodes) in model.params.loads.iter().zip(&plan.load_nodes) {
            // A load reports its resultant and the share-weighted mean displacement of its nodes.
            let f = load.force * load.factor(plan.t_new);
            let du: SVector<f64, D> = nodes.iter().map(|&(n, w)| w * du_nodes[n]).sum();
            reactions.push(std::array::from_fn(|c| f[c]));
            displacements.push(std::array::from_fn(|c| du[c]));
        }
        Outcome {
            reactions,
            displacements,
            du_nodes,
            acc_nodes,
            contact_loss,
        }
    }

    /// The grid's kinetic energy `sum_I m_I/2 |v_I|^2` over this process's active nodes at the start of
    /// the step (the P2G velocities) and at its end (the Newmark velocities `v_I + dt ((1 - gamma) a_I +
    /// gamma a_I^n+1)` with the impacts' corrections; N mm, in 2D per mm thickness); `None` where the grid
    /// does not reset (FEM mode) or without inertia.
    fn grid_kinetic_energies(&self, plan: &StepPlan<D>, out: &Outcome<D>) -> Option<[f64; 2]> {
        let nm = plan.loading.newmark?;
        if self.state.fem_nodal.is_some() {
            return None;
        }
        let (gs, owned) = (&self.work.grid_state, self.owned_nodes());
        let mut k = [0.0; 2];
        for &node in self.work.dofs.active_nodes() {
            let node = node as usize;
            if owned.contains(&node) {
                let (m, v, a) = (gs.mass[node], gs.velocity[node], gs.acceleration[node]);
                let v_new = v + nm.dt * ((1.0 - nm.gamma) * a + nm.gamma * out.acc_nodes[node]);
                k[0] += 0.5 * m * v.norm_squared();
                k[1] += 0.5 * m * v_new.norm_squared();
            }
        }
        Some(k)
    }

    /// Work of the step (N mm; in 2D per mm thickness): of the body force (b . du weighted by nodal
    /// mass) and of the constraints (trapezoidal in the set's reaction; every node of a set moves by the
    /// same prescribed du).
    /// Collective: with the points shared out each process counts the body force on its own nodes.
    fn work(
        &self,
        session: &SessionGuard,
        plan: &StepPlan<D>,
        out: &Outcome<D>,
    ) -> Result<f64, StepError> {
        let mut work = 0.0;
        let bf = self.model.params.body_force * plan.loading.load_factor;
        let owned = self.owned_nodes();
        for &node in self.work.dofs.active_nodes() {
            let node = node as usize;
            if owned.contains(&node) {
                work += self.work.grid_state.mass[node] * bf.dot(&out.du_nodes[node]);
            }
        }
        let mut sum = [work];
        self.processes(session).sum(&mut sum)?;
        work = sum[0];
        for (k, (r, du)) in out.reactions.iter().zip(&out.displacements).enumerate() {
            for c in 0..D {
                work += 0.5 * (r[c] + self.state.counters.last_reactions[k][c]) * du[c];
            }
        }
        Ok(work)
    }

    /// G2P of the solution onto the points (eroded points keep their deformation), the FEM mode's nodal
    /// state, and the commit of the material state; returns the energies of the `counted` own points
    /// (stored, dissipated by damage in the step, stored in the points eroding; N mm; in 2D per mm
    /// thickness).
    fn move_points(
        &mut self,
        session: &SessionGuard,
        plan: &StepPlan<D>,
        out: &Outcome<D>,
        counted: usize,
    ) -> Result<Committed, StepError> {
        let model = self.model;
        let newmark = plan.loading.newmark;
        let sol = StepSolution {
            du: &out.du_nodes,
            acceleration: &out.acc_nodes,
            gamma: if newmark.is_some() {
                model.params.time.gamma
            } else {
                0.0
            },
            dt: plan.dt,
        };
        let processes = self.processes(session);
        let ps = &mut self.state.particles;
        // Eroded points (material `erosion_damage`) move with the grid but keep their deformation
        // gradient, volume and domain: a void does not deform, so it never inverts.
        let frozen: Vec<_> = (0..ps.len())
            .filter(|&p| model.params.materials[ps.body[p] as usize].is_eroded(ps.damage[p]))
            .map(|p| {
                (
                    p,
                    ps.x[p],
                    ps.f[p],
                    ps.r[p],
                    ps.vol[p],
                    ps.corners(p).to_vec(),
                )
            })
            .collect();
        let g2p = transfer::grid_to_particles(&self.work.table, &model.params.grid, &sol, ps);
        processes.agreed(g2p.map_err(StepError::from))?;
        for (p, x, f, r, vol, corners) in frozen {
            let shift = ps.x[p] - x;
            ps.f[p] = f;
            ps.r[p] = r;
            ps.vol[p] = vol;
            for (c, c0) in ps.corners_mut(p).iter_mut().zip(corners) {
                *c = c0 + shift;
            }
        }
        if model.fem.is_some() {
            self.state.fem_nodal = Some(self.fem_nodal_state(newmark, &out.acc_nodes));
        }
        let ps = &mut self.state.particles;
        if model.params.time.quasi_static {
            ps.v.iter_mut().for_each(|v| *v = SVector::zeros());
            ps.a.iter_mut().for_each(|a| *a = SVector::zeros());
        }
        Ok(self
            .work
            .assembler
            .commit(ps, &model.params.materials, counted))
    }

    /// The FEM mode's nodal velocity and acceleration after the step (velocities by the trapezoidal rule
    /// from the new accelerations `acc`; zero quasi-statically).
    fn fem_nodal_state(
        &self,
        newmark: Option<Newmark>,
        acc: &[SVector<f64, D>],
    ) -> (Vec<SVector<f64, D>>, Vec<SVector<f64, D>>) {
        let gs = &self.work.grid_state;
        let (mut v, a) = (gs.velocity.clone(), acc.to_vec());
        if let Some(nm) = newmark {
            for &node in self.work.dofs.active_nodes() {
                let node = node as usize;
                v[node] += nm.dt * ((1.0 - nm.gamma) * gs.acceleration[node] + nm.gamma * a[node]);
            }
        } else {
            v.iter_mut().for_each(|v| *v = SVector::zeros());
        }
        (v, a)
    }

    /// The rigid bodies move with their sets' increments and turn about their pins as the contact sets
    /// say ([`ContactSet::turn`](contacts::ContactSet::turn)); the contact sets keep what they carry to
    /// the next step in the run's contact memory.
    fn move_rigid_bodies(&mut self, plan: &StepPlan<D>, out: &Outcome<D>) {
        let (model, dt) = (self.model, plan.dt);
        let st = &mut *self.state;
        let mut turns = vec![Turn::default(); st.rigid.len()];
        for c in &plan.contacts {
            c.turn(&mut turns);
        }
        for (k, rb) in st.rigid.iter_mut().enumerate() {
            let du = out.displacements[model.rigid_set(k)];
            let Turn { pin, dtheta } = turns[k];
            // x' = x + du + (R(dtheta) - I) (x - pin): translation with the pin, rotation about it (about
            // the pin's axis, z, in 3D).
            let dx = SVector::<f64, D>::from_fn(|c, _| du[c]);
            let pin = from_xy::<D>(pin.unwrap_or_else(Vector2::zeros));
            let r = rotation_xy::<D>(dtheta) - SMatrix::<f64, D, D>::identity();
            let moved = |x: &mut SVector<f64, D>| *x += dx + r * (*x - pin);
            rb.x.iter_mut().for_each(moved);
            rb.corners.iter_mut().for_each(moved);
        }
        for c in &plan.contacts {
            c.commit(&mut st.counters.contact, dt);
        }
    }

    /// Kinetic energy of the `counted` own points in MPM (the grid is discarded); of the lumped nodal
    /// masses in FEM mode, the energy the Newmark scheme conserves there (N mm; in 2D per mm thickness).
    fn kinetic_energy(&self, counted: usize) -> f64 {
        match &self.state.fem_nodal {
            Some((v, _)) => self
                .work
                .dofs
                .active_nodes()
                .iter()
                .map(|&n| {
                    0.5 * self.work.grid_state.mass[n as usize] * v[n as usize].norm_squared()
                })
                .sum(),
            None => {
                let ps = &self.state.particles;
                (0..counted)
                    .map(|p| 0.5 * ps.mass[p] * ps.v[p].norm_squared())
                    .sum()
            }
        }
    }

    /// The report of the committed step.
    fn report(
        &self,
        plan: &StepPlan<D>,
        solved: Solved,
        out: &Outcome<D>,
        [kinetic, stored]: [f64; 2],
        t0: Instant,
    ) -> StepReport {
        let (model, st) = (self.model, &*self.state);
        let names = model.set_names();
        StepReport {
            step: st.counters.step,
            time: st.counters.time,
            dt: plan.dt,
            attempts: 1,
            solve: solved.info,
            unknowns: self.work.dofs.len(),
            nonzeros: self
                .work
                .system
                .as_ref()
                .map_or_else(|| self.work.assembler.nonzeros(), |sys| sys.nonzeros),
            reactions: names
                .iter()
                .cloned()
                .zip(out.reactions.iter().map(|r| r.to_vec()))
                .collect(),
            displacements: names
                .into_iter()
                .zip(st.counters.accumulated.iter().map(|d| d.to_vec()))
                .collect(),
            kinetic_energy: kinetic,
            stored_energy: stored,
            external_work: st.counters.external_work,
            initial_energy: st.counters.initial_energy,
            books: st.counters.books,
            crack: None,
            wall_setup: plan.setup_time,
            wall_solve: solved.solve_time,
            wall_assembly: solved.assembly_time,
            evaluations: solved.evaluations,
            wall_total: t0.elapsed().as_secs_f64(),
            new_pattern: plan.new_pattern,
            rotations: model
                .params
                .rigid
                .iter()
                .enumerate()
                .filter(|(_, r)| r.contact.as_ref().is_some_and(|c| c.pin.is_some()))
                .map(|(k, r)| (r.name.clone(), st.counters.contact.devices[k].rotation))
                .collect(),
            contact_solves: solved.contact_solves,
            migrated: self.work.moved[0],
            ghosts: self.work.moved[1],
            bytes_sent: Vec::new(),
            bytes_unknowns: Vec::new(),
            path: None,
        }
    }
}
