//! Second phase of a step attempt: SNES from the prepared guess, repeated while the contact active set and
//! the rotations of pinned devices settle.

use super::*;

/// What `Step::solve` hands to `Step::finish`.
pub(super) struct Solved {
    /// SNES statistics over all solves of the step.
    pub(super) info: SolveInfo,
    /// Physical residual `f_int + M a - f_ext` at the solution, per unknown (N; in 2D per mm thickness).
    pub(super) phys: Vec<f64>,
    /// Wall time of the solves (s) and of the residual and Jacobian evaluations in them (s).
    pub(super) solve_time: f64,
    pub(super) assembly_time: f64,
    /// Residual and Jacobian evaluations.
    pub(super) evaluations: [usize; 2],
    /// SNES solves of the step (more than one while a contact active set or a pin rotation settles).
    pub(super) contact_solves: usize,
}

impl<const D: usize> Step<'_, D> {
    /// Second phase: SNES from the prepared guess, repeated from the last solution while the contact
    /// active set and the rotation of pinned devices settle (`docs/theory.md`, "Contact with rigid
    /// devices"). `Ok(Err(reason))` if a solve fails (nothing committed).
    pub(super) fn solve(
        &mut self,
        session: &SessionGuard,
        plan: &mut StepPlan<D>,
        assembly_event: LogEvent,
    ) -> Result<Result<Solved, Failure>, StepError> {
        let t1 = Instant::now();
        let step = self.st.step;
        let s = self.m;
        let shared = self.st.distributed;
        let particles = &self.st.particles;
        let Workspace {
            table,
            dofs,
            grid_state,
            assembler,
            system,
            partners,
            ..
        } = &mut *self.ws;
        let StepPlan {
            devices,
            bodies,
            dtheta,
            pins,
            translations,
            face_lengths,
            loading,
            ..
        } = plan;
        let input = Self::step_input(s, particles, table, dofs, grid_state, loading, partners);
        let grid = &s.grid;
        let nf = dofs.fields();
        let n = dofs.len();
        let LinearSystem {
            x,
            jac,
            snes,
            tolerances,
            lag,
            owned,
            ..
        } = system.as_mut().expect("prepared linear system");
        let h = grid.cell_size();
        let mut info_total: Option<SolveInfo> = None;
        let (mut assembly_time, mut evaluations) = (0.0, [0usize; 2]);
        let mut contact_iterations = 0;
        let mut seen: Vec<Vec<NodeStatus>> = Vec::new();
        let mut frozen = false;
        let mut secant: Vec<Option<(f64, f64)>> = vec![None; devices.len()];
        let mut phys = vec![0.0; n];
        // During the solves each process evaluates the points of its own rows; the physical residual
        // after each solve and the commit evaluate them all.
        assembler.restrict_to_rows(&input, owned.rows.clone());
        loop {
            contact_iterations += 1;
            let mut problem = StepProblem {
                input: &input,
                event: assembly_event,
                assembler: &mut *assembler,
                assembly_time: 0.0,
                residuals: 0,
                jacobians: 0,
                contact: devices.as_slice(),
                bodies,
                row_scale: input.row_scale,
                owned,
                session,
                scratch: Vec::new(),
            };
            let info = match snes.solve(&mut problem, x, jac) {
                Ok(info) => info,
                // A numerical failure inside PETSc (e.g. MUMPS failing on a nearly singular matrix) fails
                // this attempt like a diverged solve; the objects are rebuilt for the next attempt.
                Err(e) if e.is_numerical() => {
                    *system = None;
                    return Ok(Err(Failure {
                        reason: format!("SNES failed: {e}"),
                        linear: true,
                    }));
                }
                Err(e) => return Err(e.into()),
            };
            assembly_time += problem.assembly_time;
            evaluations[0] += problem.residuals;
            evaluations[1] += problem.jacobians;
            if !info.converged() {
                let why = info.domain_errors.last().cloned().unwrap_or_default();
                return Ok(Err(Failure {
                    reason: format!(
                        "SNES {} after {} iterations {why}",
                        info.reason_name, info.iterations
                    ),
                    linear: matches!(
                        info.reason_name.as_str(),
                        "DIVERGED_LINEAR_SOLVE" | "DIVERGED_LINE_SEARCH"
                    ),
                }));
            }
            let in_contact = devices.iter().any(Option::is_some) || !bodies.pairs.is_empty();
            if info_total.is_none() && in_contact {
                // Re-solves after a change of the contact active set are held to the step's own standard,
                // `|R| <= max(atol, rtol |R_0|)` with `R_0` the residual at the start of the first solve,
                // rather than to `rtol` times their own (often tiny) initial residual. Where the
                // preconditioner is lagged anyway (`lag > 1`, e.g. the multigrid of stiffness-dominated steps),
                // they keep the last one of the first solve (lag -1: never rebuilt; a lag that persists
                // through solves would carry its count into later steps): a changed active set changes a
                // few rows, which GMRES absorbs in a few iterations, far cheaper than a new set-up
                // (docs/theory.md, "Contact with rigid devices").
                let r0 = info.residual_norms.first().copied().unwrap_or(0.0);
                snes.set_tolerances(&Tolerances {
                    atol: tolerances.atol.max(tolerances.rtol * r0),
                    ..*tolerances
                })?;
                if *lag > 1 {
                    snes.set_lag_preconditioner(-1)?;
                }
            }
            info_total = Some(match info_total.take() {
                None => info,
                Some(mut t) => {
                    t.iterations += info.iterations;
                    t.linear_iterations += info.linear_iterations;
                    // The norms of all solves of the step in order: the first is the step's initial
                    // residual, the last its final one.
                    t.residual_norms.extend(info.residual_norms);
                    t
                }
            });
            if !in_contact {
                break;
            }
            // Physical residual: the force of the devices on the specimen at the contact nodes.
            let xs = owned.gather(x)?;
            let local = assembler
                .evaluate(&input, &xs)
                .and_then(|()| assembler.residual(&input, &xs, &mut phys, true));
            agreed(session, shared, local.map_err(StepError::from))?;
            complete_rows(session, shared, owned.rows.clone(), nf, &mut phys)?;
            let force_scale = devices
                .iter()
                .flatten()
                .flat_map(|d| d.nodes.iter())
                .filter(|c| c.status.closed())
                .map(|c| Vector2::new(phys[c.row * nf], phys[c.row * nf + 1]).norm())
                .fold(bodies.force_scale(&phys, nf), f64::max);
            let (force_tol, gap_tol) = (1e-6 * force_scale.max(1e-300), 1e-6 * h);
            let mut changes = 0;
            if !frozen {
                for d in devices.iter_mut().flatten() {
                    changes += d.update(&xs, &phys, nf, force_tol, gap_tol);
                }
                changes += bodies.update(&xs, &phys, nf, force_tol, gap_tol);
                let statuses: Vec<NodeStatus> = devices
                    .iter()
                    .flatten()
                    .flat_map(|d| d.nodes.iter().map(|c| c.status))
                    .chain(bodies.pairs.iter().map(|c| match c.closed {
                        true => NodeStatus::Slide,
                        false => NodeStatus::Open,
                    }))
                    .collect();
                if changes > 0 && seen.contains(&statuses) {
                    // A cycle of sets: keep the current one (only the pin rotations may still change).
                    // Logged at debug level: with pins and steel inserts it happens in a quarter of the
                    // steps (nodes at the edge of a face flipping on round-off), and the summary counts
                    // the contact solves.
                    tracing::debug!(
                        "step {}: the contact active set cycles; kept after {contact_iterations} solves",
                        step + 1
                    );
                    frozen = true;
                }
                seen.push(statuses);
            }
            // Pinned devices: the moment of the contact forces about the pin must vanish (secant in dtheta).
            let mut moments_ok = true;
            for (k, d) in devices.iter_mut().enumerate() {
                let (Some(d), Some(pin)) = (d.as_mut(), pins[k]) else {
                    continue;
                };
                let (f, m) = d.resultant(&phys, nf, |i| xy(&grid.node_position(i)), pin);
                // Balanced to 1e-5 of the force times the face length (the resultant within 1e-5 of the
                // face length from the pin), the force taken at least as `1e-4 s h` (a strain of 1e-4
                // over one cell): a device that barely touches (a support the wave has not reached, a
                // plate the arm flies away from) has a moment of round-off, discontinuous in `dtheta`
                // as nodes open and close, which the secant would chase until the step fails.
                let tol = 1e-5 * f.norm().max(1e-4 * input.row_scale * h) * face_lengths[k] + 1e-12;
                if m.abs() <= tol || d.nodes.iter().all(|c| !c.status.closed()) {
                    continue;
                }
                moments_ok = false;
                let th = dtheta[k];
                let next = match secant[k] {
                    Some((th0, m0)) if m != m0 => th - m * (th - th0) / (m - m0),
                    _ => th + (0.1 * th.abs()).max(1e-9),
                };
                secant[k] = Some((th, m));
                dtheta[k] = next;
                let r = contact::rotation(next) - nalgebra::Matrix2::identity();
                let du_t = xy(&translations[k]);
                for c in &mut d.nodes {
                    c.du_device = du_t + r * (xy(&grid.node_position(c.node)) - pin);
                }
            }
            if (changes == 0 || frozen) && moments_ok {
                break;
            }
            if contact_iterations >= MAX_CONTACT_SOLVES {
                return Ok(Err(Failure {
                    reason: format!(
                        "contact not settled after {contact_iterations} solves ({changes} status \
                         changes, moment balance {})",
                        if moments_ok { "met" } else { "not met" }
                    ),
                    linear: false,
                }));
            }
            let mut xs = owned.gather(x)?;
            for d in devices.iter().flatten() {
                d.project_guess(&mut xs, nf);
            }
            bodies.project_guess(&mut xs, nf, |node| grid_state.mass[node]);
            owned.scatter(&xs, x)?;
        }

        let info = info_total.expect("at least one solve");
        let solve_time = t1.elapsed().as_secs_f64();
        // Converged: the physical residual (device forces, reactions) at the solution; the assembler keeps
        // the nodal increments of this evaluation for `finish`.
        let xs = owned.gather(x)?;
        let local = assembler
            .evaluate(&input, &xs)
            .and_then(|()| assembler.residual(&input, &xs, &mut phys, true));
        agreed(session, shared, local.map_err(StepError::from))?;
        complete_rows(session, shared, owned.rows.clone(), nf, &mut phys)?;
        Ok(Ok(Solved {
            info,
            phys,
            solve_time,
            assembly_time,
            evaluations,
            contact_solves: contact_iterations,
        }))
    }
}
