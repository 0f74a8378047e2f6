//! Step control: a [`Simulation`] advances step by step ([`advance`]), each step in attempts, with
//! time-step halving when an attempt fails, the fallback solver after a linear-solver failure, and a
//! reduced time step doubled again once the steps converge.

use super::interrupt::Interrupt;
use super::processes;
use super::report::{Failure, StepError, StepReport};
use super::step::{Step, Workspace};
use crate::model::{InitialAcceleration, Model, Setup, State};
use crate::petsc::{LogEvent, SessionGuard};
use std::sync::Arc;
use std::time::Instant;

/// Converged steps in a row, without a retry, after which a reduced time step is doubled again: doubling
/// at once after a halved step made the crack onset of the 0.035 m/s CT fail every other attempt.
const GROW_AFTER: usize = 3;

/// A running simulation: the model, its state and the workspace of its steps.
pub struct Simulation<const D: usize = 2> {
    /// What defines the run.
    pub model: Model<D>,
    /// The committed state.
    pub state: State<D>,
    workspace: Workspace<D>,
}

impl<const D: usize> Simulation<D> {
    /// A simulation at t = 0 with virgin material history: `setup` split into [`Model`] and [`State`],
    /// with an empty [`Workspace`].
    pub fn new(setup: Setup<D>) -> Result<Self, StepError> {
        let (model, state) = Model::new(setup)?;
        Ok(Self {
            model,
            state,
            workspace: Workspace::new(),
        })
    }

    /// Makes the steps watch `interrupt`: once a request is older than
    /// [`FINISH_WITHIN`](super::interrupt::FINISH_WITHIN), the step in progress is abandoned at its next
    /// residual or Jacobian evaluation or linear-solver iteration ([`StepError::Interrupted`], nothing
    /// committed). While a step is watched, each of them costs one reduction over the processes, which
    /// agree on the one where they all abandon the step.
    pub fn watch(&mut self, interrupt: Arc<Interrupt>) {
        self.workspace.interrupt = Some(interrupt);
    }

    /// Advances one step: [`advance`] on the simulation's parts.
    pub fn advance(&mut self, session: &SessionGuard) -> Result<StepReport, StepError> {
        advance(&self.model, &mut self.state, &mut self.workspace, session)
    }
}

/// Advances `state` by one step of (at most) `state.dt` on `model`, with the scratch of `workspace`:
/// halving the step on failure down to `dt_min` (after a failure of the linear solver the fallback solver
/// is tried first at the same step); a reduced step is doubled again, up to the nominal `dt`, after
/// `GROW_AFTER` steps in a row converged at their first try. The first step of a dynamic run starts with the consistent initial
/// acceleration unless `initial_acceleration` is [`InitialAcceleration::Zero`] (computed into `state`
/// before the first attempt). A failed attempt leaves `state` as it was. A step abandoned on the
/// workspace's interrupt ([`Simulation::watch`]) is [`StepError::Interrupted`] at once, not retried.
pub fn advance<const D: usize>(
    model: &Model<D>,
    state: &mut State<D>,
    workspace: &mut Workspace<D>,
    session: &SessionGuard,
) -> Result<StepReport, StepError> {
    let before = [session.bytes_sent(), session.bytes_gathered()];
    let mut report = Step {
        model,
        state,
        work: workspace,
    }
    .advance(session)?;
    [report.bytes_sent, report.bytes_unknowns] = processes::bytes_per_process(session, before)?;
    Ok(report)
}

impl<const D: usize> Step<'_, D> {
    /// Advances one step of (at most) `self.state.dt` (the rules of [`advance`]). The first step of a
    /// dynamic run starts with the consistent initial acceleration unless `initial_acceleration` is
    /// [`InitialAcceleration::Zero`].
    pub fn advance(&mut self, session: &SessionGuard) -> Result<StepReport, StepError> {
        // Before the first step only: a resumed run continues with its checkpointed accelerations.
        let time = &self.model.params.time;
        if self.state.counters.step == 0
            && !time.quasi_static
            && time.initial_acceleration == InitialAcceleration::Consistent
        {
            let r = self.initialize_acceleration(session);
            self.drop_ghosts();
            r?;
        }
        let started = Instant::now();
        let mut dt = self.state.counters.dt;
        let mut attempts = 0;
        self.work.moved = [0; 2];
        // The main solver first; after a linear-solver failure the fallback solver (if any) at the same
        // dt, then halving.
        let mut prefix = self.model.params.options_prefix.clone();
        loop {
            attempts += 1;
            let attempt = self.try_step(session, dt, prefix.as_deref());
            self.drop_ghosts();
            match attempt? {
                Ok(mut report) => {
                    report.attempts = attempts;
                    report.wall_total = started.elapsed().as_secs_f64();
                    // A reduced step is kept until GROW_AFTER steps in a row converged at the first try,
                    // then doubled (up to the nominal dt).
                    let st = &mut *self.state;
                    st.counters.calm_steps = if attempts == 1 {
                        st.counters.calm_steps + 1
                    } else {
                        0
                    };
                    st.counters.dt = dt;
                    if dt < self.model.params.time.dt && st.counters.calm_steps >= GROW_AFTER {
                        st.counters.dt = (dt * 2.0).min(self.model.params.time.dt);
                        st.counters.calm_steps = 0;
                    }
                    return Ok(report);
                }
                Err(Failure { reason, linear }) => {
                    if let Some(fb) = &self.model.params.fallback_prefix
                        && linear
                        && prefix.as_deref() != Some(fb.as_str())
                    {
                        tracing::warn!(
                            "step {} at t = {:.6e} s: {reason}; retrying with the fallback solver (-{fb}*)",
                            self.state.counters.step + 1,
                            self.state.counters.time
                        );
                        prefix = Some(fb.clone());
                        continue;
                    }
                    let next = dt / 2.0;
                    if next < self.model.params.time.dt_min {
                        return Err(StepError::Diverged {
                            step: self.state.counters.step + 1,
                            time: self.state.counters.time,
                            dt,
                            dt_min: self.model.params.time.dt_min,
                            reason,
                        });
                    }
                    tracing::warn!(
                        "step {} at t = {:.6e} s: {reason}; retrying with dt = {next:.3e} s",
                        self.state.counters.step + 1,
                        self.state.counters.time
                    );
                    dt = next;
                }
            }
        }
    }

    /// One attempt: `Ok(Ok(report))` converged and committed, `Ok(Err(reason))` did not converge
    /// (nothing changed), `Err` a failure that a smaller step cannot fix. The attempt runs in three
    /// phases: `Step::prepare` (grid, unknowns, constraints, devices, loads, PETSc objects, first
    /// guess), `Step::solve` (SNES, repeated while the contact active set and the pin rotations
    /// settle) and `Step::finish` (reactions, accelerations, G2P, commit, report).
    fn try_step(
        &mut self,
        session: &SessionGuard,
        dt: f64,
        prefix: Option<&str>,
    ) -> Result<Result<StepReport, Failure>, StepError> {
        let t0 = Instant::now();
        let events = match self.work.events {
            Some(e) => e,
            None => {
                let e = [
                    LogEvent::register(session, "MPMSetup")?,
                    LogEvent::register(session, "MPMAssembly")?,
                ];
                *self.work.events.insert(e)
            }
        };
        let setup_guard = events[0].begin();
        let mut plan = self.prepare(session, dt, prefix)?;
        drop(setup_guard);
        plan.setup_time = t0.elapsed().as_secs_f64();
        let solved = match self.solve(session, &mut plan, events[1])? {
            Ok(solved) => solved,
            Err(failure) => return Ok(Err(failure)),
        };
        Ok(Ok(self.finish(session, plan, solved, t0)?))
    }
}
