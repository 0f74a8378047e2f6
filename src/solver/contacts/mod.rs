//! The contact sets of a step: one interface, [`ContactSet`], through which the step's phases treat
//! every kind of contact alike, and the list of the kinds, [`kinds`], that build the sets of a step
//! attempt (`docs/architecture.md`, "A new contact kind").
//!
//! The kinds: the rigid devices (plates, supports, pinned or not) against the specimen (`devices.rs`),
//! and the node pairs between the specimen and the bodies on their own velocity fields (`bodies.rs`).
//! What a set carries from one step to the next is its entry of the run's
//! [`ContactMemory`](crate::contact::ContactMemory).

mod bodies;
mod devices;

use super::report::StepError;
use super::step::Step;
use crate::assembly::Newmark;
use crate::contact::{ContactMemory, Converged, NodeStatus, RowMap};
use crate::grid::Grid;
use crate::model::Model;
use crate::petsc::SessionGuard;
use crate::transfer::GridState;
use nalgebra::{SVector, Vector2};
use std::ops::Range;

/// The contact sets of a step attempt, in the order of [`kinds`] (devices in the order of the rigid
/// bodies, then the pairs between bodies).
pub(super) type Sets<const D: usize> = Vec<Box<dyn ContactSet<D>>>;

/// One contact set of a step: `prepare` builds the sets ([`build`]) and projects the first guess onto
/// them, the SNES callbacks rewrite their rows, `solve` updates them at each converged iterate until
/// they settle, `finish` takes their reactions, velocity corrections and rigid-body rotations and
/// commits what they carry to the next step. Forces are N per mm thickness in 2D (N in 3D),
/// displacements mm.
pub(super) trait ContactSet<const D: usize> {
    /// True if the set takes part in the step (it constrains some node).
    fn in_play(&self) -> bool;

    /// Projects the guess `x` (all unknowns, `nf` per node) onto the closed constraints (`mass`: the
    /// nodal masses, t).
    fn project_guess(&self, x: &mut [f64], nf: usize, mass: &[f64]);

    /// Rewrites the residual rows of the closed constraints (`s`: the row scale, MPa).
    fn residual_rows(&self, x: &[f64], r: &mut [f64], nf: usize, s: f64);

    /// Rewrites the Jacobian rows of the closed constraints in place, where `rows` places them.
    fn jacobian_rows(&self, nf: usize, s: f64, rows: &dyn RowMap, values: &mut [f64]);

    /// The largest contact force of the closed constraints (`phys`: the physical residual), the scale
    /// of the sign tests.
    fn force_scale(&self, phys: &[f64], nf: usize) -> f64;

    /// Updates the statuses at the converged iterate `at`; returns the number of changes.
    fn update(&mut self, at: Converged<'_>) -> usize;

    /// Appends the statuses of the set's constraints to `out`: the active set, compared from solve to
    /// solve to find cycles.
    fn statuses(&self, out: &mut Vec<NodeStatus>);

    /// After the statuses settled: true if the set is in balance with the forces `phys` (`grid`: the
    /// background grid, `s`: the row scale, MPa); false after changing its own motion, to be solved
    /// again. No such condition unless a kind has one.
    fn balance(&mut self, _phys: &[f64], _nf: usize, _grid: &Grid<D>, _s: f64) -> bool {
        true
    }

    /// Marks in `held` (one per grid node copy) the nodes the set constrains, which the kinds built
    /// after it leave alone.
    fn hold(&self, _held: &mut [bool]) {}

    /// Appends to `out` the unknowns whose rows of the physical residual every process must read after
    /// a solve (the set's forces and statuses), when the points are shared out.
    fn read_rows(&self, _nf: usize, _out: &mut Vec<usize>) {}

    /// Writes the set's force on the specimen into its constraint set's entry of `reactions` (one per
    /// constraint set of `model`; `phys`: the physical residual).
    fn reaction(&self, _model: &Model<D>, _phys: &[f64], _nf: usize, _reactions: &mut [[f64; D]]) {}

    /// The inelastic-impact correction of the closed constraints' nodal accelerations (mm/s^2), its
    /// impulse added to the set's entry of `reactions`; returns the kinetic energy the impacts took out
    /// on the nodes `at.owned` (N mm; in 2D per mm thickness).
    fn impact(
        &self,
        model: &Model<D>,
        at: &Impact<'_, D>,
        acc_nodes: &mut [SVector<f64, D>],
        reactions: &mut [[f64; D]],
    ) -> f64;

    /// Writes the rotation of the step of the set's rigid body into `turns` (one per rigid body).
    fn turn(&self, _turns: &mut [Turn]) {}

    /// Keeps what the set carries to the next step (its final statuses, its rotation over a step of
    /// `dt`, s) in its entry of `memory`.
    fn commit(&self, memory: &mut ContactMemory, dt: f64);

    /// At t = 0: the acceleration `acc` (mm/s^2, one per grid node copy) of the nodes the set pushes,
    /// from the unbalanced forces `r` (every row, `nf` unknowns per node; `gs`: the grid state);
    /// returns the set's constraint set in `model` and its
    /// force on the specimen, if the set has one.
    fn push_at_start(
        &self,
        _model: &Model<D>,
        _gs: &GridState<D>,
        _r: (&[f64], usize),
        _acc: &mut [SVector<f64, D>],
    ) -> Option<(usize, SVector<f64, D>)> {
        None
    }
}

/// The rotation of a rigid body in a step: about `pin` (mm, in the x-y plane; `None`: no pin) by
/// `dtheta` (rad).
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct Turn {
    /// The pin (mm).
    pub(super) pin: Option<Vector2<f64>>,
    /// The rotation increment (rad).
    pub(super) dtheta: f64,
}

/// What the inelastic-impact corrections of a step read: the Newmark constants, the grid state at the start
/// of the step, and the grid nodes whose energy loss this process counts.
pub(super) struct Impact<'a, const D: usize> {
    /// Newmark constants of the step.
    pub(super) nm: &'a Newmark,
    /// Nodal mass, velocity and acceleration at the start of the step.
    pub(super) gs: &'a GridState<D>,
    /// The grid nodes this process counts (`Step::owned_nodes`).
    pub(super) owned: Range<usize>,
}

/// What the sets of an attempt are built for: the prescribed motion of the rigid bodies and the time
/// step.
pub(super) struct Attempt<'a, const D: usize> {
    /// Per rigid body, the prescribed translation of its set in the step (mm); at t = 0 its prescribed
    /// acceleration (mm/s^2).
    pub(super) translations: &'a [SVector<f64, D>],
    /// The time step (s); `None` at t = 0, where the start of a dynamic run balances the forces.
    pub(super) dt: Option<f64>,
}

/// A kind of contact: builds its sets for a step attempt.
pub(super) trait ContactKind<const D: usize> {
    /// The sets of this kind for `attempt`, after the sets `earlier` of the kinds before it (whose
    /// nodes it leaves alone, [`ContactSet::hold`]).
    fn build(
        &self,
        step: &mut Step<'_, D>,
        session: &SessionGuard,
        attempt: &Attempt<'_, D>,
        earlier: &[Box<dyn ContactSet<D>>],
    ) -> Result<Sets<D>, StepError>;

    /// Appends to `out` the grid nodes the kind's sets may constrain, before they are built: their
    /// nodal sums are completed on every process.
    fn candidates(&self, _step: &Step<'_, D>, _out: &mut Vec<usize>) {}
}

/// The kinds of contact, in the order their sets are built and solved.
fn kinds<const D: usize>() -> [&'static dyn ContactKind<D>; 2] {
    [&devices::Devices, &bodies::Bodies]
}

/// The contact sets of a step attempt, kind after kind.
pub(super) fn build<const D: usize>(
    step: &mut Step<'_, D>,
    session: &SessionGuard,
    attempt: &Attempt<'_, D>,
) -> Result<Sets<D>, StepError> {
    let mut sets: Sets<D> = Vec::new();
    for kind in kinds::<D>() {
        let more = kind.build(step, session, attempt, &sets)?;
        sets.extend(more);
    }
    Ok(sets)
}

/// The grid nodes the contact sets of the next attempt may constrain ([`ContactKind::candidates`]).
pub(super) fn candidates<const D: usize>(step: &Step<'_, D>) -> Vec<usize> {
    let mut out = Vec::new();
    for kind in kinds::<D>() {
        kind.candidates(step, &mut out);
    }
    out
}
