//! The assembler's view of a step ([`StepInput`]): built in one place, by the step's phases and by
//! `StepData` (`data.rs`) for tests and benches that call the assembler directly; with the step's
//! inertia and loads ([`Loading`]) and the scale of its constraint rows.

use super::step::{Step, Workspace};
use crate::assembly::{Newmark, StepInput};
use crate::dofs::DofMap;
use crate::material::Material;
use crate::model::Model;
use crate::particles::Particles;
use crate::shape::ShapeTable;
use crate::transfer::GridState;
use nalgebra::SVector;

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

/// Inertia and applied forces of a step: what the assembler needs besides the points and the grid.
pub(super) struct Loading<const D: usize> {
    /// Newmark parameters (`None`: quasi-static).
    pub(super) newmark: Option<Newmark>,
    /// The body-force factor of a quasi-static ramp.
    pub(super) load_factor: f64,
    /// Applied nodal forces at `t_n+1` (N, in 2D per mm thickness, one per grid node; empty without loads).
    pub(super) nodal_force: Vec<SVector<f64, D>>,
}

impl<const D: usize> Loading<D> {
    /// The inertia and forces of a step of `dt` (s) reaching `t_new` (s) on `model` with the applied
    /// `nodal_force`: Newmark unless quasi-static, the body force ramped over `body_force_ramp` in a
    /// quasi-static run.
    pub(super) fn new(
        model: &Model<D>,
        t_new: f64,
        dt: f64,
        nodal_force: Vec<SVector<f64, D>>,
    ) -> Self {
        let time = &model.params.time;
        let newmark = (!time.quasi_static).then_some(Newmark {
            beta: time.beta,
            gamma: time.gamma,
            dt,
        });
        let load_factor = if time.quasi_static && model.params.body_force_ramp > 0.0 {
            (t_new / model.params.body_force_ramp).min(1.0)
        } else {
            1.0
        };
        Self {
            newmark,
            load_factor,
            nodal_force,
        }
    }
}

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
