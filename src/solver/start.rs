//! The start of a dynamic run: the consistent initial acceleration.

use super::*;

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
        self.project_to_grid(session)?;
        let t = self.st.time;
        let prescribed = self.constraint_values(|v, rise| prescribed_acceleration(v, rise, t));
        let sets = self.constrain(&prescribed)?;
        let (nodal_force, _) = self.nodal_loads(t)?;
        let eta_bar = self.nodal_eta_bar(session)?;
        let nf = self.ws.dofs.fields();
        let s = self.m;
        // No inertia and the full body force at t = 0.
        let loading = Loading {
            newmark: None,
            load_factor: 1.0,
            nodal_force,
        };
        let input = Self::step_input(
            s,
            &self.st.particles,
            &self.ws.table,
            &self.ws.dofs,
            &self.ws.grid_state,
            &loading,
            &[],
        );
        self.ws.assembler.begin_step(&input);
        let mut x = vec![0.0; self.ws.dofs.len()];
        if let Some(e) = self.ws.dofs.layout().eta_bar() {
            for (a, &node) in self.ws.dofs.active_nodes().iter().enumerate() {
                x[a * nf + e] = eta_bar[node as usize];
            }
        }
        // R = f_int - f_ext at du = 0 (no inertia), unbalanced forces in the constrained rows too.
        let mut r = vec![0.0; x.len()];
        let local = self
            .ws
            .assembler
            .evaluate(&input, &x)
            .and_then(|()| self.ws.assembler.residual(&input, &x, &mut r, true));
        agreed(session, self.st.distributed, local.map_err(StepError::from))?;
        let rows = self.own_rows(session);
        complete_rows(session, self.st.distributed, rows, nf, &mut r)?;
        let mut acc = vec![SVector::<f64, D>::zeros(); s.field_nodes()];
        for (a, &node) in self.ws.dofs.active_nodes().iter().enumerate() {
            let node = node as usize;
            let m = self.ws.grid_state.mass[node];
            acc[node] = SVector::from_fn(|c, _| {
                let d = a * nf + c;
                self.ws.dofs.prescribed(d).unwrap_or(-r[d] / m)
            });
        }
        // Devices in contact: a touching node whose free acceleration would carry it into the device takes
        // the device's normal acceleration (node by node: the lumped mass decouples them; friction is not
        // applied at t = 0).
        let nb = s.boxes.len();
        let device_acc: Vec<SVector<f64, D>> = prescribed[nb..]
            .iter()
            .map(|d| SVector::from_fn(|c, _| d[c].unwrap_or(0.0)))
            .collect();
        let pins: Vec<Option<Vector2<f64>>> = (0..s.rigid.len()).map(|k| self.pin_of(k)).collect();
        let (devices, _) =
            self.contact_devices(session, &device_acc, &pins, &vec![0.0; s.rigid.len()], 0.0)?;
        let mut contact_forces = vec![SVector::<f64, D>::zeros(); devices.len()];
        for (k, d) in devices.iter().enumerate() {
            let Some(d) = d else { continue };
            let n = from_xy::<D>(d.normal);
            for c in d.nodes.iter().filter(|c| c.status.closed()) {
                let push = n.dot(&(from_xy::<D>(c.du_device) - acc[c.node]));
                if push > 0.0 {
                    acc[c.node] += push * n;
                    let b = c.row * nf;
                    let m = self.ws.grid_state.mass[c.node];
                    contact_forces[k] +=
                        SVector::<f64, D>::from_column_slice(&r[b..b + D]) + m * acc[c.node];
                }
            }
        }
        // The reactions at t = 0, where the trapezoidal work of the first step starts: the unbalanced force
        // with the initial inertia in each constrained set, the applied resultant of each load.
        for (reaction, dofs) in self.st.last_reactions.iter_mut().zip(&sets) {
            *reaction = [0.0; D];
            for &d in dofs {
                let (node, c) = (self.ws.dofs.node(d / nf), d % nf);
                reaction[c] += r[d] + self.ws.grid_state.mass[node] * acc[node][c];
            }
        }
        for (k, f) in contact_forces.iter().enumerate() {
            if devices[k].is_some() {
                self.st.last_reactions[nb + k] = std::array::from_fn(|c| f[c]);
            }
        }
        for (reaction, load) in self.st.last_reactions[sets.len()..]
            .iter_mut()
            .zip(&s.loads)
        {
            let f = load.force * load.factor(t);
            *reaction = std::array::from_fn(|c| f[c]);
        }
        let table = &self.ws.table;
        for (p, ap) in self.st.particles.a.iter_mut().enumerate() {
            *ap = transfer::interpolate(table.weights(p), |i| acc[i]);
        }
        if self.m.fem.is_some() {
            self.st.fem_nodal = Some((self.ws.grid_state.velocity.clone(), acc));
        }
        Ok(())
    }
}
