//! [`StepData`]: a step's data on the grid built the solver's way, for tests and benches that call the
//! assembler directly.

use super::prepare::StepPlan;
use super::report::StepError;
use super::step::{Step, Workspace};
use crate::assembly::StepInput;
use crate::dofs::DofMap;
use crate::model::{Model, State};
use crate::petsc::SessionGuard;

/// A step's data on the grid built the solver's way from a model and a state: shape functions and P2G, the
/// unknowns with the constraints of the model's boxes and glued bodies, the loads, the pairs between bodies
/// and the inertia of a step of `dt`: what the step prepares before its PETSc objects. For tests and benches
/// that call the [`Assembler`](crate::assembly::Assembler) directly ([`StepData::input`]); the solver itself
/// never builds one.
pub struct StepData<const D: usize = 2> {
    /// The state the step starts from (a copy: preparing a step may reorder the points among the
    /// processes).
    state: State<D>,
    /// The shape functions, grid state, unknowns and pairs of the step.
    work: Workspace<D>,
    /// The step's plan (inertia, loads, constraint and contact sets).
    plan: StepPlan<D>,
}

impl<const D: usize> StepData<D> {
    /// The data of a step of `dt` (s) from `state` on `model` (one process).
    pub fn new(
        session: &SessionGuard,
        model: &Model<D>,
        state: &State<D>,
        dt: f64,
    ) -> Result<Self, StepError> {
        let mut state = state.clone();
        let mut work = Workspace::new();
        let (plan, _) = Step {
            model,
            state: &mut state,
            work: &mut work,
        }
        .plan(session, dt)?;
        Ok(Self { state, work, plan })
    }

    /// The assembler's input of the step on `model` (the model the data was built from).
    pub fn input<'a>(&'a self, model: &'a Model<D>) -> StepInput<'a, D> {
        Step::step_input(
            model,
            &self.state.particles,
            &self.work.table,
            &self.work.dofs,
            &self.work.grid_state,
            &self.plan.loading,
            &self.work.partners,
        )
    }

    /// The unknowns of the step and their constraints.
    pub fn dofs(&self) -> &DofMap {
        &self.work.dofs
    }

    /// Per node copy, its partner in contact between bodies ([`INACTIVE`](crate::dofs::INACTIVE): none;
    /// empty: one field).
    pub fn partners(&self) -> &[u32] {
        &self.work.partners
    }
}
