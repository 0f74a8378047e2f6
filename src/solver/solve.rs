//! Second phase of a step attempt: SNES from the prepared guess, repeated while the contact active set and
//! the rotations of pinned devices settle.

use super::contacts::ContactSet;
use super::interrupt::Interrupt;
use super::path;
use super::prepare::{LoadNodes, StepPlan};
use super::problem::StepProblem;
use super::processes::Processes;
use super::report::{Failure, StepError};
use super::step::{Step, Workspace};
use super::system::LinearSystem;
use crate::assembly::{Assembler, StepInput};
use crate::contact::{Converged, NodeStatus};
use crate::dofs::DofMap;
use crate::grid::Grid;
use crate::petsc::{LogEvent, STALLED, SessionGuard, SolveInfo, Tolerances};
use std::time::Instant;

/// Most SNES solves of one step attempt while the contact active set and the pin rotations settle.
const MAX_CONTACT_SOLVES: usize = 30;

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

/// The solves of one attempt so far: SNES statistics, evaluation counts and the state of the contact
/// active set.
#[derive(Default)]
struct Solves {
    /// SNES statistics summed over the solves (`None` before the first).
    info: Option<SolveInfo>,
    /// Wall time of residual and Jacobian evaluations (s) and their counts.
    assembly_time: f64,
    evaluations: [usize; 2],
    /// SNES solves so far.
    count: usize,
    /// The active sets met after each solve, to find cycles; once one repeats the set is frozen.
    seen: Vec<Vec<NodeStatus>>,
    frozen: bool,
}

impl Solves {
    /// Adds the statistics of one converged solve: the norms of all solves of the step in order (the
    /// first is the step's initial residual, the last its final one).
    fn add(&mut self, info: SolveInfo) {
        self.info = Some(match self.info.take() {
            None => info,
            Some(mut t) => {
                t.iterations += info.iterations;
                t.linear_iterations += info.linear_iterations;
                t.residual_norms.extend(info.residual_norms);
                t
            }
        });
    }
}

/// The failure of a solve that did not converge: a linear-solver failure (another linear solver may
/// succeed at the same time step) or Newton's own. A Newton that stalled (an iteration left the residual
/// norm unchanged to [`STALLED`]) is a linear-solver failure too: GMRES preconditioned from the left stops
/// on the preconditioned residual, and an ILU(0) with a tiny pivot lets it "converge" in one iteration to
/// a step that changes nothing (the paper-size CT at 4.3 m/s stopped at step 373 so, halving dt down to
/// 1.6e-8 s, where the fallback's LU converges in 3 iterations at the first dt). SNES's convergence test
/// (`petsc::snes`, Newton with line search) ends such a solve as `DIVERGED_LINEAR_SOLVE` after as many
/// unchanged iterations in a row as the preconditioner's lag; the residual history names it here, and
/// also catches a stall that ran to the iteration limit (another SNES type, or a user's
/// `-snes_convergence_test`).
fn diverged(info: &SolveInfo) -> Failure {
    let why = info.domain_errors.last().cloned().unwrap_or_default();
    let stalled = stalled(&info.residual_norms);
    Failure {
        reason: format!(
            "SNES {} after {} iterations{} {why}",
            info.reason_name,
            info.iterations,
            if stalled {
                " (stalled: the linear solves changed nothing)"
            } else {
                ""
            }
        ),
        linear: stalled
            || matches!(
                info.reason_name.as_str(),
                "DIVERGED_LINEAR_SOLVE" | "DIVERGED_LINE_SEARCH"
            ),
    }
}

/// Whether the last Newton iteration of `norms` (the residual norms from the first guess on) left the
/// norm unchanged to a relative [`STALLED`].
fn stalled(norms: &[f64]) -> bool {
    match norms {
        [.., before, last] => (last - before).abs() <= STALLED * last.abs(),
        _ => false,
    }
}

/// Re-solves after a change of the contact active set are held to the step's own standard,
/// `|R| <= max(atol, rtol |R_0|)` with `R_0` the residual at the start of the first solve (`first`),
/// rather than to `rtol` times their own (often tiny) initial residual. Where the preconditioner is lagged
/// anyway (`lag > 1`, e.g. the multigrid of stiffness-dominated steps), they keep the last one of the
/// first solve (lag -1: never rebuilt; a lag that persists through solves would carry its count into
/// later steps): a changed active set changes a few rows, which GMRES absorbs in a few iterations, far
/// cheaper than a new set-up (docs/theory.md, "Contact with rigid devices").
fn hold_to_first_solve(sys: &mut LinearSystem, first: &SolveInfo) -> Result<(), StepError> {
    let r0 = first.residual_norms.first().copied().unwrap_or(0.0);
    let tol = sys.tolerances;
    sys.snes.set_tolerances(&Tolerances {
        atol: tol.atol.max(tol.rtol * r0),
        ..tol
    })?;
    if sys.lag > 1 {
        sys.snes.set_lag_preconditioner(-1)?;
    }
    Ok(())
}

/// Updates the contact sets at the converged iterate `xs` with the forces `phys` (unless the active set
/// is frozen), freezing it when it cycles; returns the number of status changes.
fn update_contacts<const D: usize>(
    contacts: &mut [Box<dyn ContactSet<D>>],
    solves: &mut Solves,
    (xs, phys, nf): (&[f64], &[f64], usize),
    h: f64,
    step: usize,
) -> usize {
    if solves.frozen {
        return 0;
    }
    let force_scale = contacts
        .iter()
        .map(|c| c.force_scale(phys, nf))
        .fold(0.0, f64::max);
    let (force_tol, gap_tol) = (1e-6 * force_scale.max(1e-300), 1e-6 * h);
    let at = Converged {
        x: xs,
        phys,
        nf,
        force_tol,
        gap_tol,
    };
    let mut changes = 0;
    for c in contacts.iter_mut() {
        changes += c.update(at);
    }
    let mut statuses = Vec::new();
    for c in contacts.iter() {
        c.statuses(&mut statuses);
    }
    if changes > 0 && solves.seen.contains(&statuses) {
        // A cycle of sets: keep the current one (only the pin rotations may still change). Logged at
        // debug level: with pins and steel inserts it happens in a quarter of the steps (nodes at the edge
        // of a face flipping on round-off), and the summary counts the contact solves.
        tracing::debug!(
            "step {}: the contact active set cycles; kept after {} solves",
            step + 1,
            solves.count
        );
        solves.frozen = true;
    }
    solves.seen.push(statuses);
    changes
}

/// After a converged solve with the contact sets in play: updates the active set at the solution `xs`
/// with the forces `phys` and balances the moments of the pinned devices. `Ok(true)`: settled (no
/// change, or a frozen cycle, and the moments balanced); `Ok(false)`: solve again; a failure after
/// [`MAX_CONTACT_SOLVES`] solves.
fn settle<const D: usize>(
    contacts: &mut [Box<dyn ContactSet<D>>],
    solves: &mut Solves,
    (xs, phys, nf): (&[f64], &[f64], usize),
    grid: &Grid<D>,
    row_scale: f64,
    step: usize,
) -> Result<bool, Failure> {
    let changes = update_contacts(contacts, solves, (xs, phys, nf), grid.cell_size(), step);
    // Pinned devices: the moment of the contact forces about the pin must vanish.
    let mut moments_ok = true;
    for c in contacts.iter_mut() {
        moments_ok &= c.balance(phys, nf, grid, row_scale);
    }
    if (changes == 0 || solves.frozen) && moments_ok {
        return Ok(true);
    }
    if solves.count >= MAX_CONTACT_SOLVES {
        return Err(Failure {
            reason: format!(
                "contact not settled after {} solves ({changes} status changes, moment balance {})",
                solves.count,
                if moments_ok { "met" } else { "not met" }
            ),
            linear: false,
        });
    }
    Ok(false)
}

/// The physical residual `phys` (`f_int + M a - f_ext`, every row, on every process) at the solution
/// of `sys`, whose unknowns it returns; the assembler keeps the nodal increments of this evaluation.
fn physical_residual<const D: usize>(
    assembler: &mut Assembler<D>,
    input: &StepInput<'_, D>,
    sys: &LinearSystem,
    (processes, read): (Processes<'_>, &[usize]),
    phys: &mut [f64],
) -> Result<Vec<f64>, StepError> {
    let xs = sys
        .owned
        .gather_solution(processes.session(), &sys.x, read)?;
    let local = assembler
        .evaluate(input, &xs)
        .and_then(|()| assembler.residual(input, &xs, phys, true));
    processes.agreed(local.map_err(StepError::from))?;
    let nf = input.dofs.unknowns_per_node();
    processes.complete_read_rows((sys.owned.rows.clone(), nf), read, phys)?;
    Ok(xs)
}

/// The unknowns every process reads after a solve, of the solution and of the physical residual: the
/// constrained ones of `sets` (the reactions), those the contact sets read ([`ContactSet::read_rows`]:
/// their forces and statuses) and the displacements of the loads' nodes `load_nodes` (the loads'
/// displacements and external work; `dofs` numbers them).
fn read_rows<const D: usize>(
    sets: &[Vec<usize>],
    contacts: &[Box<dyn ContactSet<D>>],
    (load_nodes, dofs): (&LoadNodes, &DofMap),
) -> Vec<usize> {
    let nf = dofs.unknowns_per_node();
    let mut rows: Vec<usize> = sets.iter().flatten().copied().collect();
    for c in contacts {
        c.read_rows(nf, &mut rows);
    }
    for &(node, _) in load_nodes.iter().flatten() {
        if let Some(a) = dofs.active_index(node) {
            rows.extend((0..D).map(|c| a * nf + c));
        }
    }
    rows
}

/// One SNES solve of the attempt from the current iterate of `system`, its evaluations counted in
/// `solves`: the statistics of a solve that ended (converged or not), a failure of the attempt (a
/// numerical failure inside PETSc: the objects are rebuilt for the next attempt), or
/// [`StepError::Interrupted`] when the processes abandoned it on the interrupt (`at`: the step and time
/// of the committed state).
fn newton_once<const D: usize>(
    system: &mut Option<LinearSystem>,
    (input, event, assembler, contacts): (
        &StepInput<'_, D>,
        LogEvent,
        &mut Assembler<D>,
        &[Box<dyn ContactSet<D>>],
    ),
    (session, interrupt): (&SessionGuard, Option<&Interrupt>),
    path: Option<&mut path::PathStep>,
    solves: &mut Solves,
    (step, time): (usize, f64),
) -> Result<Result<SolveInfo, Failure>, StepError> {
    let LinearSystem {
        x,
        jac,
        snes,
        owned,
        ..
    } = system.as_mut().expect("prepared linear system");
    let mut problem = StepProblem::new(
        input,
        event,
        assembler,
        (contacts, owned),
        session,
        interrupt,
    );
    let result = path::newton(snes, &mut problem, x, jac, path);
    solves.assembly_time += problem.assembly_time;
    solves.evaluations[0] += problem.residuals;
    solves.evaluations[1] += problem.jacobians;
    if problem.abandoned {
        // Every process left the solve at the same evaluation. PETSc's objects, left in the middle of a
        // solve, are built anew should the run go on.
        *system = None;
        return Err(StepError::Interrupted {
            step: step + 1,
            time,
        });
    }
    match result {
        Ok(info) => Ok(Ok(info)),
        // A numerical failure inside PETSc (e.g. MUMPS failing on a nearly singular matrix) fails this
        // attempt like a diverged solve; the objects are rebuilt for the next attempt.
        Err(e) if e.is_numerical() => {
            *system = None;
            Ok(Err(Failure {
                reason: format!("SNES failed: {e}"),
                linear: true,
            }))
        }
        Err(e) => Err(e.into()),
    }
}

impl<const D: usize> Step<'_, D> {
    /// Second phase: SNES from the prepared guess, repeated from the last solution while the contact
    /// active set and the rotation of pinned devices settle (`docs/theory.md`, "Contact with rigid
    /// devices"). `Ok(Err(reason))` if a solve fails (nothing committed); [`StepError::Interrupted`] if
    /// it was abandoned on the workspace's interrupt.
    pub(super) fn solve(
        &mut self,
        session: &SessionGuard,
        plan: &mut StepPlan<D>,
        assembly_event: LogEvent,
    ) -> Result<Result<Solved, Failure>, StepError> {
        let t1 = Instant::now();
        let (step, model) = (self.state.counters.step, self.model);
        let processes = self.processes(session);
        let Workspace {
            table,
            dofs,
            grid_state,
            assembler,
            system,
            partners,
            interrupt,
            ..
        } = &mut *self.work;
        let interrupt = interrupt.as_deref();
        let StepPlan {
            contacts,
            loading,
            path,
            sets,
            load_nodes,
            ..
        } = plan;
        let input = Self::step_input(
            model,
            &self.state.particles,
            table,
            dofs,
            grid_state,
            loading,
            partners,
        );
        let nf = dofs.unknowns_per_node();
        let in_contact = contacts.iter().any(|c| c.in_play());
        let mut solves = Solves::default();
        let mut phys = vec![0.0; dofs.len()];
        let read = read_rows(sets, contacts, (load_nodes, dofs));
        let procs = (processes, read.as_slice());
        // During the solves each process evaluates the points of its own rows; the physical residual
        // after each solve and the commit evaluate them all.
        let rows = system
            .as_ref()
            .expect("prepared linear system")
            .owned
            .rows
            .clone();
        assembler.restrict_to_rows(&input, rows);
        loop {
            solves.count += 1;
            let info = match newton_once(
                system,
                (&input, assembly_event, &mut *assembler, contacts.as_slice()),
                (session, interrupt),
                path.as_mut(),
                &mut solves,
                (step, self.state.counters.time),
            )? {
                Ok(info) => info,
                Err(failure) => return Ok(Err(failure)),
            };
            let sys = system.as_mut().expect("prepared linear system");
            if !info.converged() {
                return Ok(Err(diverged(&info)));
            }
            if solves.info.is_none() && in_contact {
                hold_to_first_solve(sys, &info)?;
            }
            solves.add(info);
            if !in_contact {
                break;
            }
            // Physical residual: the force of the devices on the specimen at the contact nodes.
            let mut xs = physical_residual(assembler, &input, sys, procs, &mut phys)?;
            match settle(
                contacts,
                &mut solves,
                (&xs, &phys, nf),
                &model.params.grid,
                input.row_scale,
                step,
            ) {
                Ok(true) => break,
                Ok(false) => {}
                Err(failure) => return Ok(Err(failure)),
            }
            for c in contacts.iter() {
                c.project_guess(&mut xs, nf, &grid_state.mass);
            }
            sys.owned.scatter(&xs, &mut sys.x)?;
        }
        let solve_time = t1.elapsed().as_secs_f64();
        // Converged: the physical residual (device forces, reactions) at the solution; the assembler keeps
        // the nodal increments of this evaluation for `finish`.
        let sys = system.as_ref().expect("prepared linear system");
        physical_residual(assembler, &input, sys, procs, &mut phys)?;
        Ok(Ok(Solved {
            info: solves.info.expect("at least one solve"),
            phys,
            solve_time,
            assembly_time: solves.assembly_time,
            evaluations: solves.evaluations,
            contact_solves: solves.count,
        }))
    }
}

#[cfg(test)]
mod tests {
    use super::stalled;

    #[test]
    fn a_newton_whose_last_iteration_changed_nothing_has_stalled() {
        // The paper-size CT's step 373: GMRES "converged" in one iteration to a step that left the
        // residual as it was.
        assert!(stalled(&[3477.254071886, 3477.254071886, 3477.254071886]));
        // Slow but moving (a damage front, a contact set): not stalled.
        assert!(!stalled(&[3477.0, 50.0, 49.9]));
        assert!(!stalled(&[3477.0, 3476.9]));
        // Growing, or too short a history to tell.
        assert!(!stalled(&[1.0, 2.0]));
        assert!(!stalled(&[1.0]));
        assert!(!stalled(&[]));
    }
}
