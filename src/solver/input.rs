//! The assembler's view of a step ([`StepInput`]): built in one place, by the step's phases and by
//! [`StepData`] for tests and benches that call the assembler directly.

use super::prepare::{Loading, StepPlan};
use super::report::StepError;
use super::{Step, Workspace, row_scale};
use crate::assembly::StepInput;
use crate::dofs::DofMap;
use crate::model::{Model, State};
use crate::particles::Particles;
use crate::petsc::SessionGuard;
use crate::shape::ShapeTable;
use crate::transfer::GridState;

impl<const D: usize> Step<'_, D> {
    /// The assembler's view of the step (borrows the simulation's parts field by field, so that the
    /// assembler and the PETSc objects stay free to be borrowed mutably beside it).
    pub(super) fn step_input<'a>(
        model: &'a Model<D>,
        particles: &'a Particles<D>,
        table: &'a ShapeTable<D>,
        dofs: &'a DofMap,
        grid_state: &'a GridState<D>,
        loading: &'a Loading<D>,
        partners: &'a [u32],
    ) -> StepInput<'a, D> {
        StepInput {
            table,
            particles,
            materials: &model.params.materials,
            dofs,
            mass: &grid_state.mass,
            velocity: &grid_state.velocity,
            acceleration: &grid_state.acceleration,
            newmark: loading.newmark,
            body_force: model.params.body_force * loading.load_factor,
            nodal_force: &loading.nodal_force,
            row_scale: row_scale(&model.params.materials),
            partners,
        }
    }
}

impl<const D: usize> Workspace<D> {
    /// Starts the assembler's step ([`Assembler::begin_step`](crate::assembly::Assembler::begin_step)) on the
    /// workspace's shape functions, unknowns, grid state and contact pairs with the step's `loading`.
    pub(super) fn begin_assembly(
        &mut self,
        model: &Model<D>,
        particles: &Particles<D>,
        loading: &Loading<D>,
    ) {
        let Workspace {
            table,
            dofs,
            grid_state,
            partners,
            assembler,
            ..
        } = self;
        let input = Step::step_input(model, particles, table, dofs, grid_state, loading, partners);
        assembler.begin_step(&input);
    }
}

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
