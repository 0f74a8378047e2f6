//! The implicit MPM time step (spec Sec. 1): shape functions at `t_n`, P2G, unknown numbering and
//! constraints, Newton on the coupled (du, eta_bar) system through PETSc SNES, G2P and commit; with
//! time-step halving when a step fails.
//!
//! Committed state (particles, time) is only modified after SNES converges: a failed attempt leaves the
//! simulation exactly as it was, so it can be retried with a smaller time step.

use crate::assembly::Assembler;
use crate::dofs::DofMap;
use crate::material::Material;
use crate::model::{InitialAcceleration, Model, Setup, State};
use crate::partition::{NodalWindows, Partition};
use crate::petsc::{LogEvent, SessionGuard};
use crate::shape::ShapeTable;
use crate::transfer::GridState;
use std::sync::Arc;
use std::time::Instant;

mod contacts;
mod finish;
mod input;
mod interrupt;
mod path;
mod prepare;
mod processes;
mod report;
mod solve;
mod start;
mod system;

pub use input::StepData;
pub use interrupt::{FINISH_WITHIN, Interrupt};
use report::Failure;
pub use report::{PathPoint, StepError, StepReport};
use system::LinearSystem;

/// Converged steps in a row, without a retry, after which a reduced time step is doubled again: doubling
/// at once after a halved step made the crack onset of the 0.035 m/s CT fail every other attempt.
const GROW_AFTER: usize = 3;

/// Most SNES solves of one step attempt while the contact active set and the pin rotations settle.
const MAX_CONTACT_SOLVES: usize = 30;

/// Scale of constrained rows and of the Helmholtz rows (MPa): the largest P-wave modulus `K + 4G/3`.
fn row_scale(materials: &[Material]) -> f64 {
    materials
        .iter()
        .map(|m| {
            let e = m.elastic_moduli();
            e.bulk + 4.0 * e.shear / 3.0
        })
        .fold(0.0, f64::max)
}

/// The per-step scratch of the time step, reused from step to step: shape-function tables, grid fields,
/// the unknowns and their constraints, the assembler's buffers and the PETSc objects. Nothing in it
/// outlives a step's meaning: a workspace may be dropped and rebuilt between steps (a resumed run
/// starts with a fresh one) without changing the results.
#[derive(Default)]
pub struct Workspace<const D: usize = 2> {
    /// Shape functions of the points in the step's configuration.
    table: ShapeTable<D>,
    /// Shape functions of the rigid bodies' points (MPM mode; FEM mode uses the reference ones).
    rigid_tables: Vec<ShapeTable<D>>,
    /// Grid mass, velocity and acceleration from P2G.
    grid_state: GridState<D>,
    /// The unknowns and their constraints.
    dofs: DofMap,
    /// Per node copy, its partner in contact between bodies ([`INACTIVE`](crate::dofs::INACTIVE): none;
    /// empty: one field).
    partners: Vec<u32>,
    assembler: Assembler<D>,
    /// PETSc objects reused while the pattern does not change.
    system: Option<LinearSystem>,
    /// PETSc log events `MPMSetup` (shape functions, P2G, pattern) and `MPMAssembly` (residuals and
    /// Jacobians), registered at the first step.
    events: Option<[LogEvent; 2]>,
    /// The processes' bands of cell rows (MPM on several processes), set at the first step.
    partition: Option<Partition>,
    /// This process's own points during a step: the first `own_points` of the state's points; the
    /// others are copies of other processes' points (ghosts), dropped at the end of the attempt.
    own_points: usize,
    /// Points migrated and ghosts received at the start of the step, summed over the processes.
    moved: [usize; 2],
    /// MPM on several processes: the node rows of the step's nodal sums on every process (P2G and the
    /// `eta_bar` projection are summed over neighbouring processes only).
    windows: Option<NodalWindows>,
    /// The request to stop that the steps watch ([`Simulation::watch`]).
    interrupt: Option<Arc<Interrupt>>,
}

impl<const D: usize> Workspace<D> {
    /// An empty workspace; its buffers grow at the first step.
    pub fn new() -> Self {
        Self::default()
    }
}

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

    /// Makes the steps watch `interrupt`: once a request is older than [`FINISH_WITHIN`], the step in
    /// progress is abandoned at its next residual or Jacobian evaluation or linear-solver iteration
    /// ([`StepError::Interrupted`], nothing committed). While a step is watched, each of them costs one
    /// reduction over the processes, which agree on the one where they all abandon the step.
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

/// One step in progress: the model, the state it advances and the workspace it uses.
struct Step<'a, const D: usize> {
    /// What defines the run.
    model: &'a Model<D>,
    /// The committed state, changed only when an attempt converges.
    state: &'a mut State<D>,
    /// The step's scratch.
    work: &'a mut Workspace<D>,
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
