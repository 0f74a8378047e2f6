//! The process layer of a step: the one place where the step's phases meet the other processes.
//! [`Processes`] carries the exchanges of results (sums, minima, agreement on failures, residual rows
//! completed), each a no-op where every process holds every point; the `Step` methods here share the
//! points out with their ghosts, plan the nodal sums between neighbouring bands and give the block rows
//! each process owns. The physics of the other phases (`prepare`, `solve`, `finish`, the contacts and path
//! following) does not ask how many processes there are; the linear system (`system.rs`) chooses its
//! storage and gathers from it.

use super::contacts;
use super::report::StepError;
use super::step::Step;
use crate::assembly::AssemblyError;
use crate::dofs::DofMap;
use crate::partition::{self, NodalWindows, Partition};
use crate::petsc::{self, CallbackError, SessionGuard};
use crate::shape::ShapeTable;
use nalgebra::SVector;
use rayon::prelude::*;
use std::ops::Range;

/// A domain error (an inverted point, a failed material update) on any process, reported on all: SNES
/// takes domain errors collectively, and with each process evaluating the points of its own rows only
/// one of them may meet it.
pub(super) fn agree(
    session: &SessionGuard,
    local: Result<(), AssemblyError>,
) -> Result<(), CallbackError> {
    let any = session.any(local.is_err());
    match local {
        Err(e) => Err(CallbackError::Domain(e.to_string())),
        Ok(()) if any => Err(CallbackError::Domain(
            "a point of another process left its domain".into(),
        )),
        Ok(()) => Ok(()),
    }
}

/// The exchanges of a step's results between the processes, through which the step's phases reach the
/// other processes: sums and minima over the processes, agreement on a failure, residual rows completed.
/// Where every process holds every point (one process, or points not shared out) every process computed
/// everything itself, and each exchange is a no-op: the phases never ask how many processes there are.
#[derive(Clone, Copy)]
pub(super) struct Processes<'s> {
    session: &'s SessionGuard,
    /// The points are shared out: each process holds its own points and their ghosts.
    shared: bool,
}

impl<'s> Processes<'s> {
    /// The session, for the exchanges of PETSc's distributed vectors (made on several processes whether
    /// the points are shared out or not).
    pub(super) fn session(&self) -> &'s SessionGuard {
        self.session
    }

    /// Sums `v` element-wise over the processes (collective where the points are shared out).
    pub(super) fn sum(&self, v: &mut [f64]) -> Result<(), petsc::PetscError> {
        match self.shared {
            true => self.session.sum(v),
            false => Ok(()),
        }
    }

    /// The element-wise minimum of `v` over the processes (collective where the points are shared
    /// out).
    pub(super) fn min(&self, v: &mut [f64]) -> Result<(), petsc::PetscError> {
        match self.shared {
            true => self.session.min(v),
            false => Ok(()),
        }
    }

    /// A result of this process's points agreed on by every process before the next collective call:
    /// with the points shared out, a point's failure (it left the grid, its domain inverted) is met only
    /// by the processes that hold it. The failing processes keep their error, the others return
    /// [`StepError::OtherProcess`], so that all leave the step together.
    pub(super) fn agreed<T>(&self, local: Result<T, StepError>) -> Result<T, StepError> {
        if !self.shared {
            return local;
        }
        let failed = self.session.any(local.is_err());
        match local {
            Ok(_) if failed => Err(StepError::OtherProcess),
            r => r,
        }
    }

    /// Completes a residual `r` over all unknowns that this process evaluated from its own points and
    /// ghosts: its own block rows `rows` are complete, the others partial; they are zeroed and the
    /// vectors summed over the processes, so that every process holds every row (the same bits on
    /// each).
    pub(super) fn complete_rows(
        &self,
        rows: Range<usize>,
        nf: usize,
        r: &mut [f64],
    ) -> Result<(), StepError> {
        if !self.shared {
            return Ok(());
        }
        zero_foreign_rows(rows, nf, r);
        self.session.sum(r)?;
        Ok(())
    }

    /// Completes the physical residual `r` after a solve where the step reads it beyond this process's
    /// own block rows `rows` (`nf` unknowns per row): its own rows are complete, the others partial; they
    /// are zeroed and only the unknowns `read` (`solve.rs`'s constrained and contact rows) are summed over
    /// the processes (each from its owner, the others adding zeros: the same bits on every process).
    pub(super) fn complete_read_rows(
        &self,
        (rows, nf): (Range<usize>, usize),
        read: &[usize],
        r: &mut [f64],
    ) -> Result<(), StepError> {
        if !self.shared {
            return Ok(());
        }
        zero_foreign_rows(rows, nf, r);
        let mut values: Vec<f64> = read.iter().map(|&d| r[d]).collect();
        self.session.sum(&mut values)?;
        for (&d, v) in read.iter().zip(values) {
            r[d] = v;
        }
        Ok(())
    }
}

/// Zeroes the partial rows of `r` outside this process's own block rows `rows` (`nf` unknowns per row).
fn zero_foreign_rows(rows: Range<usize>, nf: usize, r: &mut [f64]) {
    r[..rows.start * nf].fill(0.0);
    r[rows.end * nf..].fill(0.0);
}

/// The largest of `value` over the processes (collective).
pub(super) fn largest(session: &SessionGuard, value: f64) -> Result<f64, petsc::PetscError> {
    let mut v = [-value];
    session.min(&mut v)?;
    Ok(-v[0])
}

/// The bytes (B) every process sent in a step through the program's own exchanges, and of them in the
/// gathers of the unknowns for the evaluations ([`SessionGuard::bytes_sent`],
/// [`SessionGuard::bytes_gathered`]), one per process, from this process's counts `before` the step
/// (collective; empty on one process).
pub(super) fn bytes_per_process(
    session: &SessionGuard,
    before: [u64; 2],
) -> Result<[Vec<u64>; 2], StepError> {
    let size = session.size();
    if size == 1 {
        return Ok([Vec::new(), Vec::new()]);
    }
    let now = [session.bytes_sent(), session.bytes_gathered()];
    let mut counts = vec![0.0; 2 * size];
    for k in 0..2 {
        counts[k * size + session.rank()] = (now[k] - before[k]) as f64;
    }
    session.sum(&mut counts)?;
    let of = |k: usize| {
        counts[k * size..(k + 1) * size]
            .iter()
            .map(|&b| b as u64)
            .collect()
    };
    Ok([of(0), of(1)])
}

impl<const D: usize> Step<'_, D> {
    /// The exchanges of this step with the other processes ([`Processes`]).
    pub(super) fn processes<'s>(&self, session: &'s SessionGuard) -> Processes<'s> {
        Processes {
            session,
            shared: self.state.distributed,
        }
    }

    /// What runs on one process only, refused on several: contact between bodies (a body with its own
    /// velocity field), whose contact rows combine the rows of two node copies that a process may not
    /// both own.
    pub(super) fn refuse_what_processes_cannot_share(
        &self,
        session: &SessionGuard,
    ) -> Result<(), StepError> {
        if session.size() > 1 && self.model.num_fields() > 1 {
            return Err(StepError::Setup(
                "contact between bodies (a body with its own velocity field) runs on one process: \
                 its contact rows combine the rows of two node copies, which a process may not both own"
                    .into(),
            ));
        }
        Ok(())
    }

    /// MPM on several processes: the points shared out (at the first step: each process keeps those of
    /// its band; later: the points that left a band migrate), then the ghosts appended. Nothing on one
    /// process or in FEM mode (each process holds every point).
    pub(super) fn share_points(&mut self, session: &SessionGuard) -> Result<(), StepError> {
        if session.size() == 1 || self.model.fem.is_some() {
            return Ok(());
        }
        let st = &mut *self.state;
        if self.work.partition.is_none() {
            let p = Partition::balanced(
                session,
                &self.model.params.grid,
                &st.particles,
                !st.distributed,
            )
            .map_err(StepError::Setup)?;
            self.work.partition = Some(p);
        }
        let part = self.work.partition.as_ref().expect("set above");
        let migrated = if st.distributed {
            partition::migrate(session, part, &mut st.particles)?
        } else {
            partition::keep_own(part, &mut st.particles);
            st.distributed = true;
            0
        };
        self.work.own_points = st.particles.len();
        let ghosts = partition::add_ghosts(session, part, &mut st.particles)?;
        let mut moved = [migrated as f64, ghosts as f64];
        session.sum(&mut moved)?;
        // Points that migrated in any attempt of the step; the ghosts of the last attempt.
        self.work.moved = [self.work.moved[0] + moved[0] as usize, moved[1] as usize];
        Ok(())
    }

    /// The processes' bands of cell rows, where the points are shared out among them.
    fn shared_partition(&self) -> Option<&Partition> {
        self.work
            .partition
            .as_ref()
            .filter(|_| self.state.distributed)
    }

    /// With the points shared out: each own point's support lies within the node rows its process reads
    /// (`Partition::check_reach`).
    pub(super) fn check_reach(&self) -> Result<(), StepError> {
        match self.shared_partition() {
            Some(part) => part
                .check_reach(
                    &self.work.table,
                    &self.state.particles,
                    self.own_point_count(),
                )
                .map_err(StepError::Setup),
            None => Ok(()),
        }
    }

    /// The node rows of the step's nodal sums ([`Step::nodal_windows`]) with the points shared out, none
    /// otherwise (every process sums all of its nodes itself).
    pub(super) fn plan_windows(&mut self, session: &SessionGuard) -> Result<(), StepError> {
        self.work.windows = match self.shared_partition() {
            Some(part) => Some(self.nodal_windows(session, part)?),
            None => None,
        };
        Ok(())
    }

    /// This process's own points: the first of the state's (all of them unless shared out).
    pub(super) fn own_point_count(&self) -> usize {
        if self.state.distributed {
            self.work.own_points
        } else {
            self.state.particles.len()
        }
    }

    /// The grid nodes whose energy this process counts: those of its node rows with the points shared
    /// out, every node otherwise.
    pub(super) fn owned_nodes(&self) -> Range<usize> {
        match self.shared_partition() {
            Some(part) => part.owned_nodes(),
            None => 0..usize::MAX,
        }
    }

    /// Drops the ghosts of the step (the state keeps this process's own points only).
    pub(super) fn drop_ghosts(&mut self) {
        if self.state.distributed {
            self.state.particles.truncate(self.work.own_points);
        }
    }

    /// The block rows this process owns: with the points shared out, the active nodes of its node
    /// rows ([`Partition::owned_nodes`]); otherwise an equal share of the active nodes.
    pub(super) fn own_rows(&self, session: &SessionGuard) -> Range<usize> {
        let active = self.work.dofs.active_nodes();
        match self.shared_partition() {
            Some(part) => {
                let nodes = part.owned_nodes();
                let first = |n: usize| active.partition_point(|&a| (a as usize) < n);
                first(nodes.start)..first(nodes.end)
            }
            None => {
                let (rank, size, n) = (session.rank(), session.size(), active.len());
                n * rank / size..n * (rank + 1) / size
            }
        }
    }

    /// The node rows of the step's nodal sums on every process ([`Partition::windows`]): this process
    /// touches the rows its own points reach and reads its own node rows and those its own points and
    /// ghosts reach.
    pub(super) fn nodal_windows(
        &self,
        session: &SessionGuard,
        part: &Partition,
    ) -> Result<NodalWindows, StepError> {
        let table = &self.work.table;
        let touched = part.rows_reached(table, 0..self.own_point_count());
        let (reached, own) = (
            part.rows_reached(table, 0..table.len()),
            part.own_node_rows(),
        );
        let read = match reached.is_empty() {
            true => own,
            false => reached.start.min(own.start)..reached.end.max(own.end),
        };
        Ok(part.windows(session, touched, read)?)
    }

    /// With the nodal sums complete on the rows each process reads only: mass, velocity and
    /// acceleration also on the nodes of the constraint sets `sets` and the contact sets' candidates
    /// beyond them ([`contacts::candidates`]; their reactions, statuses and impacts are evaluated on
    /// every process), from their owners (collective; nothing to do where every process holds the
    /// whole grid).
    pub(super) fn complete_beyond_windows(
        &mut self,
        session: &SessionGuard,
        sets: &[Vec<usize>],
    ) -> Result<(), StepError> {
        let (Some(part), Some(_)) = (&self.work.partition, &self.work.windows) else {
            return Ok(());
        };
        let nf = self.work.dofs.unknowns_per_node();
        let mut nodes: Vec<usize> = sets
            .iter()
            .flatten()
            .map(|&d| self.work.dofs.node(d / nf))
            .chain(contacts::candidates(self))
            .collect();
        nodes.sort_unstable();
        nodes.dedup();
        let (owned, gs) = (part.owned_nodes(), &mut self.work.grid_state);
        let width = 1 + 2 * D;
        let mut values = vec![0.0; nodes.len() * width];
        for (v, &n) in values.chunks_exact_mut(width).zip(&nodes) {
            if owned.contains(&n) {
                v[0] = gs.mass[n];
                v[1..1 + D].copy_from_slice(gs.velocity[n].as_slice());
                v[1 + D..].copy_from_slice(gs.acceleration[n].as_slice());
            }
        }
        session.sum(&mut values)?;
        for (v, &n) in values.chunks_exact(width).zip(&nodes) {
            gs.mass[n] = v[0];
            gs.velocity[n] = SVector::from_column_slice(&v[1..1 + D]);
            gs.acceleration[n] = SVector::from_column_slice(&v[1 + D..]);
        }
        Ok(())
    }
}

/// The unknowns (indices in [`DofMap`] order) a process reads at an evaluation: those of the active
/// nodes from the lowest to the highest node in the support of its points in `table` (its own and the
/// ghosts; all points where they are not shared out) and of its own block rows `rows`, a contiguous
/// range because the nodes are numbered row by row.
pub(super) fn unknowns_window<const D: usize>(
    table: &ShapeTable<D>,
    dofs: &DofMap,
    rows: Range<usize>,
) -> Range<usize> {
    let (lo, hi) = (0..table.len())
        .into_par_iter()
        .map(|p| {
            table.weights(p).iter().fold((u32::MAX, 0), |(lo, hi), w| {
                (lo.min(w.node), hi.max(w.node))
            })
        })
        .reduce(|| (u32::MAX, 0), |a, b| (a.0.min(b.0), a.1.max(b.1)));
    let active = dofs.active_nodes();
    let first = active.partition_point(|&a| a < lo).min(rows.start);
    let last = active.partition_point(|&a| a <= hi).max(rows.end);
    let nf = dofs.unknowns_per_node();
    first * nf..last * nf
}
