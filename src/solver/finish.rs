//! Third phase of a step attempt: reactions, the new nodal accelerations, the work of the constraints,
//! G2P and the commit of the material state, the motion of the rigid bodies; the report.

use super::*;

impl<const D: usize> Step<'_, D> {
    /// Third phase: reactions and device forces, the new nodal accelerations, the work of the
    /// constraints, G2P and the commit of the material state, the motion of the rigid bodies; the report.
    pub(super) fn finish(
        &mut self,
        session: &SessionGuard,
        plan: StepPlan<D>,
        solved: Solved,
        t0: Instant,
    ) -> Result<StepReport, StepError> {
        let StepPlan {
            dt,
            t_new,
            set_du,
            sets,
            pins,
            dtheta,
            devices,
            bodies,
            load_nodes,
            loading:
                Loading {
                    newmark,
                    load_factor,
                    ..
                },
            new_pattern,
            setup_time,
            ..
        } = plan;
        let Solved {
            info,
            phys,
            solve_time,
            assembly_time,
            evaluations,
            contact_solves,
        } = solved;
        let nf = self.ws.dofs.fields();
        let n = self.ws.dofs.len();
        let s = self.m;
        let grid = &s.grid;
        let mut reactions: Vec<[f64; D]> = sets
            .iter()
            .map(|dofs| {
                let mut r = [0.0; D];
                for &d in dofs {
                    r[d % nf] += phys[d];
                }
                r
            })
            .collect();
        for (k, d) in devices.iter().enumerate() {
            if let Some(d) = d {
                let pin = pins[k].unwrap_or_else(Vector2::zeros);
                let (f, _) = d.resultant(&phys, nf, |i| xy(&grid.node_position(i)), pin);
                let r = &mut reactions[s.boxes.len() + k];
                r[0] = f.x;
                r[1] = f.y;
            }
        }
        let nodes = s.field_nodes();
        let du_nodes = self.ws.assembler.nodal_du().to_vec();
        let mut acc_nodes = vec![SVector::<f64, D>::zeros(); nodes];
        if let Some(nm) = newmark {
            for &node in self.ws.dofs.active_nodes() {
                let node = node as usize;
                acc_nodes[node] = nm.acceleration(
                    du_nodes[node],
                    self.ws.grid_state.velocity[node],
                    self.ws.grid_state.acceleration[node],
                );
            }
            // Closed contact nodes leave the step with the device's velocity in the constrained
            // directions (a perfectly inelastic impact at the node, as in the grid contact of Bardenhagen
            // et al.). The trapezoidal rule alone would give `v_n+1 = 2 du/dt - v_n`: a node arriving at
            // the relative speed w would bounce off at -w, and the chatter of the face nodes against a
            // moving device pumped energy into the specimen (kinetic energy twice the device's work).
            // The device's reaction includes the impulse of that correction, m (a - a_Newmark), which
            // the following step's Newmark acceleration cancels again, so that the trapezoidal impulse
            // and work of the reaction stay the block's change of momentum and the device's work.
            let first = s.boxes.len();
            for (k, d) in devices.iter().enumerate() {
                let Some(d) = d else { continue };
                let (n, t) = (from_xy::<D>(d.normal), from_xy::<D>(d.tangent()));
                for c in d.nodes.iter().filter(|c| c.status.closed()) {
                    let (v, a) = (
                        self.ws.grid_state.velocity[c.node],
                        self.ws.grid_state.acceleration[c.node],
                    );
                    let target = from_xy::<D>(c.du_device) / dt;
                    // The acceleration that makes v_n + dt ((1 - gamma) a_n + gamma a) equal the target.
                    let fit = |e: SVector<f64, D>| {
                        (e.dot(&target) - e.dot(&v) - dt * (1.0 - nm.gamma) * e.dot(&a))
                            / (nm.gamma * dt)
                    };
                    let acc = &mut acc_nodes[c.node];
                    let before = *acc;
                    *acc += (fit(n) - n.dot(acc)) * n;
                    if c.status == NodeStatus::Stick {
                        *acc += (fit(t) - t.dot(acc)) * t;
                    }
                    let f = self.ws.grid_state.mass[c.node] * (*acc - before);
                    for (r, f) in reactions[first + k].iter_mut().zip(f.iter()) {
                        *r += f;
                    }
                }
            }
            // Closed pairs between bodies leave the step with one normal velocity, the mass-weighted mean
            // of the two copies' (the same perfectly inelastic impact); the two corrections are equal
            // and opposite impulses, so the momentum of the pair is kept.
            let gs = &self.ws.grid_state;
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
            }
        }
        // Work of the constraints (trapezoidal in the set's reaction; every node of a set moves by the same
        // prescribed du) and of the body force (b . du weighted by nodal mass).
        let mut work = 0.0;
        let bf = s.body_force * load_factor;
        for &node in self.ws.dofs.active_nodes() {
            let node = node as usize;
            work += self.ws.grid_state.mass[node] * bf.dot(&du_nodes[node]);
        }
        let gamma = if newmark.is_some() { s.time.gamma } else { 0.0 };
        let sol = StepSolution {
            du: &du_nodes,
            acceleration: &acc_nodes,
            gamma,
            dt,
        };
        let mut displacements: Vec<[f64; D]> =
            set_du.iter().map(|d| d.map(|v| v.unwrap_or(0.0))).collect();
        for (load, nodes) in s.loads.iter().zip(&load_nodes) {
            // A load reports its resultant and the share-weighted mean displacement of its nodes.
            let f = load.force * load.factor(t_new);
            let du: SVector<f64, D> = nodes.iter().map(|&(n, w)| w * du_nodes[n]).sum();
            reactions.push(std::array::from_fn(|c| f[c]));
            displacements.push(std::array::from_fn(|c| du[c]));
        }
        for (k, (r, du)) in reactions.iter().zip(&displacements).enumerate() {
            for c in 0..D {
                work += 0.5 * (r[c] + self.st.last_reactions[k][c]) * du[c];
            }
        }
        let s = self.m;
        // The energies of this process's own points (the ghosts are other processes').
        let counted = self.own_point_count();
        let ps = &mut self.st.particles;
        // Eroded points (material `erosion_damage`) move with the grid but keep their deformation
        // gradient, volume and domain: a void does not deform, so it never inverts.
        let frozen: Vec<_> = (0..ps.len())
            .filter(|&p| s.materials[ps.body[p] as usize].is_eroded(ps.damage[p]))
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
        let g2p = transfer::grid_to_particles(&self.ws.table, &s.grid, &sol, ps);
        agreed(session, self.st.distributed, g2p.map_err(StepError::from))?;
        for (p, x, f, r, vol, corners) in frozen {
            let shift = ps.x[p] - x;
            ps.f[p] = f;
            ps.r[p] = r;
            ps.vol[p] = vol;
            for (c, c0) in ps.corners_mut(p).iter_mut().zip(corners) {
                *c = c0 + shift;
            }
        }
        if s.fem.is_some() {
            let (mut v, a) = (self.ws.grid_state.velocity.clone(), acc_nodes.clone());
            if let Some(nm) = newmark {
                for &node in self.ws.dofs.active_nodes() {
                    let node = node as usize;
                    v[node] += nm.dt
                        * ((1.0 - nm.gamma) * self.ws.grid_state.acceleration[node]
                            + nm.gamma * a[node]);
                }
            } else {
                v.iter_mut().for_each(|v| *v = SVector::zeros());
            }
            self.st.fem_nodal = Some((v, a));
        }
        if s.time.quasi_static {
            ps.v.iter_mut().for_each(|v| *v = SVector::zeros());
            ps.a.iter_mut().for_each(|a| *a = SVector::zeros());
        }
        let stored = self.ws.assembler.commit(ps, &s.materials, counted);
        for (k, (rb, du)) in self
            .st
            .rigid
            .iter_mut()
            .zip(&displacements[s.boxes.len()..])
            .enumerate()
        {
            // x' = x + du + (R(dtheta) - I) (x - pin): translation with the pin, rotation about it (about
            // the pin's axis, z, in 3D).
            let dx = SVector::<f64, D>::from_fn(|c, _| du[c]);
            let pin = from_xy::<D>(pins[k].unwrap_or_else(Vector2::zeros));
            let r = rotation_xy::<D>(dtheta[k]) - SMatrix::<f64, D, D>::identity();
            let moved = |x: &mut SVector<f64, D>| *x += dx + r * (*x - pin);
            rb.x.iter_mut().for_each(moved);
            rb.corners.iter_mut().for_each(moved);
            self.st.rotations[k] += dtheta[k];
            self.st.rotation_rates[k] = dtheta[k] / dt;
            if let Some(d) = &devices[k] {
                self.st.contact_statuses[k] = d.nodes.iter().map(|c| (c.node, c.status)).collect();
            }
        }
        self.st.closed_pairs = bodies
            .pairs
            .iter()
            .filter(|c| c.closed)
            .map(|c| c.node_b)
            .collect();
        self.st.closed_pairs.sort_unstable();
        for (acc, du) in self.st.accumulated.iter_mut().zip(&displacements) {
            for c in 0..D {
                acc[c] += du[c];
            }
        }
        self.st.last_reactions = reactions.clone();
        self.st.external_work += work;
        self.st.time = t_new;
        self.st.step += 1;
        // Kinetic energy: of the points in MPM (the grid is discarded); of the lumped nodal masses in FEM
        // mode, the energy the Newmark scheme conserves there.
        let kinetic = match &self.st.fem_nodal {
            Some((v, _)) => self
                .ws
                .dofs
                .active_nodes()
                .iter()
                .map(|&n| 0.5 * self.ws.grid_state.mass[n as usize] * v[n as usize].norm_squared())
                .sum(),
            None => {
                let ps = &self.st.particles;
                (0..counted)
                    .map(|p| 0.5 * ps.mass[p] * ps.v[p].norm_squared())
                    .sum()
            }
        };
        let mut energies = [kinetic, stored];
        if self.st.distributed {
            session.sum(&mut energies)?;
        }
        let [kinetic, stored] = energies;
        let names = s.set_names();

        Ok(StepReport {
            step: self.st.step,
            time: self.st.time,
            dt,
            attempts: 1,
            solve: info,
            unknowns: n,
            nonzeros: self
                .ws
                .system
                .as_ref()
                .map_or_else(|| self.ws.assembler.nonzeros(), |sys| sys.nonzeros),
            reactions: names
                .iter()
                .cloned()
                .zip(reactions.iter().map(|r| r.to_vec()))
                .collect(),
            displacements: names
                .into_iter()
                .zip(self.st.accumulated.iter().map(|d| d.to_vec()))
                .collect(),
            kinetic_energy: kinetic,
            stored_energy: stored,
            external_work: self.st.external_work,
            initial_energy: self.st.initial_energy,
            wall_setup: setup_time,
            wall_solve: solve_time,
            wall_assembly: assembly_time,
            evaluations,
            wall_total: t0.elapsed().as_secs_f64(),
            new_pattern,
            rotations: s
                .rigid
                .iter()
                .enumerate()
                .filter(|(_, r)| r.contact.as_ref().is_some_and(|c| c.pin.is_some()))
                .map(|(k, r)| (r.name.clone(), self.st.rotations[k]))
                .collect(),
            contact_solves,
            migrated: self.ws.moved[0],
            ghosts: self.ws.moved[1],
        })
    }
}
