//! The nonlinear problem of one step handed to SNES ([`StepProblem`]): the assembler's residual and
//! Jacobian on the rows this process owns with the rows of the step's contact sets, agreed over the
//! processes and abandoned on an interrupt.

use super::contacts::ContactSet;
use super::interrupt::Interrupt;
use super::processes::agree;
use super::system::OwnedRows;
use crate::assembly::{Assembler, StepInput};
use crate::contact::BlockRows;
use crate::petsc::{self, CallbackError, LogEvent, Matrix, NonlinearProblem, SessionGuard, Vector};
use std::time::Instant;

/// The nonlinear problem of one step, handed to SNES.
pub(super) struct StepProblem<'a, 'b, const D: usize> {
    pub(super) input: &'a StepInput<'b, D>,
    /// PETSc log event of the residual and Jacobian evaluations (shown by `-log_view`).
    pub(super) event: LogEvent,
    pub(super) assembler: &'a mut Assembler<D>,
    /// Wall time spent in residual and Jacobian evaluations (s).
    pub(super) assembly_time: f64,
    /// Residual and Jacobian evaluations.
    pub(super) residuals: usize,
    pub(super) jacobians: usize,
    /// The contact sets of the step (closed constraints get their own rows).
    pub(super) contacts: &'a [Box<dyn ContactSet<D>>],
    /// Scale of the constraint rows (MPa).
    pub(super) row_scale: f64,
    /// The block rows this process owns.
    pub(super) owned: &'a OwnedRows,
    /// For the processes' agreement on domain errors.
    pub(super) session: &'a SessionGuard,
    /// The residual of all unknowns (this process hands PETSc its own rows).
    pub(super) scratch: Vec<f64>,
    /// The Jacobian's values where the matrix does not lend its own array (several processes).
    pub(super) jacobian_values: Vec<f64>,
    /// The request to stop that the step watches (`Simulation::watch`).
    pub(super) interrupt: Option<&'a Interrupt>,
    /// The processes agreed to abandon the step at an evaluation ([`StepProblem::abandon`]).
    pub(super) abandoned: bool,
}

/// The message of the callback error that abandons a solve on an interrupt (SNES stops at once).
const ABANDONED: &str = "the step was abandoned on an interrupt";

impl<'a, 'b, const D: usize> StepProblem<'a, 'b, D> {
    /// The problem of the step `input` with its `contacts`, evaluated by `assembler` on the rows
    /// `owned` by this process (residual and Jacobian evaluations timed under `event`), abandoned on
    /// `interrupt`.
    pub(super) fn new(
        input: &'a StepInput<'b, D>,
        event: LogEvent,
        assembler: &'a mut Assembler<D>,
        (contacts, owned): (&'a [Box<dyn ContactSet<D>>], &'a OwnedRows),
        session: &'a SessionGuard,
        interrupt: Option<&'a Interrupt>,
    ) -> Self {
        Self {
            input,
            event,
            assembler,
            assembly_time: 0.0,
            residuals: 0,
            jacobians: 0,
            contacts,
            row_scale: input.row_scale,
            owned,
            session,
            scratch: Vec::new(),
            jacobian_values: Vec::new(),
            interrupt,
            abandoned: false,
        }
    }

    /// Before an evaluation and at each iteration of the linear solver: whether the step is to be
    /// abandoned on its interrupt, agreed by every process (one reduction while an interrupt is watched;
    /// SNES calls them on all processes in the same order, so they all leave at the same one). Once abandoned, every evaluation fails with
    /// a fatal error, which ends the solve at once; the caller tells it from a failure by
    /// [`StepProblem::abandoned`].
    fn abandon(&mut self) -> Result<(), CallbackError> {
        if !self.abandoned {
            let Some(interrupt) = self.interrupt else {
                return Ok(());
            };
            self.abandoned = self.session.any(interrupt.overdue());
        }
        if self.abandoned {
            return Err(CallbackError::Fatal(ABANDONED.into()));
        }
        Ok(())
    }
}

impl<const D: usize> NonlinearProblem for StepProblem<'_, '_, D> {
    fn residual(&mut self, x: &Vector, f: &mut Vector) -> Result<(), CallbackError> {
        self.abandon()?;
        let _event = self.event.begin();
        let t = Instant::now();
        let fatal = |e: petsc::PetscError| CallbackError::Fatal(e.to_string());
        let (asm, input, owned) = (&mut *self.assembler, self.input, self.owned);
        let (contacts, s) = (self.contacts, self.row_scale);
        let nf = input.dofs.unknowns_per_node();
        let r = &mut self.scratch;
        let xs = owned.gather(x).map_err(fatal)?;
        // Only this process's rows: the points in their support, the rows themselves.
        let local = asm.evaluate_owned(input, &xs).and_then(|()| {
            r.resize(xs.len(), 0.0);
            asm.residual_rows(input, &xs, r, false, owned.rows.clone())
        });
        let result = agree(self.session, local).and_then(|()| {
            for c in contacts {
                c.residual_rows(&xs, r, nf, s);
            }
            f.write(|out| out.copy_from_slice(&r[owned.scalars()]))
                .map_err(fatal)
        });
        self.assembly_time += t.elapsed().as_secs_f64();
        self.residuals += 1;
        result
    }

    /// Between evaluations a linear solve may take long: its iterations check the interrupt too.
    fn linear_iteration(&mut self) -> Result<(), CallbackError> {
        self.abandon()
    }

    fn jacobian(&mut self, x: &Vector, jac: &mut Matrix) -> Result<(), CallbackError> {
        self.abandon()?;
        let _event = self.event.begin();
        let t = Instant::now();
        let fatal = |e: petsc::PetscError| CallbackError::Fatal(e.to_string());
        let (asm, input, owned) = (&mut *self.assembler, self.input, self.owned);
        let xs = owned.gather(x).map_err(fatal)?;
        agree(self.session, asm.evaluate_owned(input, &xs))?;
        let (contacts, s) = (self.contacts, self.row_scale);
        let (pattern, own) = (owned.pattern(), owned.rows.clone());
        let r = jac
            .fill_block_rows_in(&pattern, &mut self.jacobian_values, |values, layout| {
                asm.jacobian_into(input, own.clone(), values, layout);
                let nf = input.dofs.unknowns_per_node();
                let row_of = |a: usize| {
                    let l = a.checked_sub(own.start).filter(|&l| l < own.len())?;
                    let (lo, hi) = (pattern.row_ptr[l], pattern.row_ptr[l + 1]);
                    let diag = pattern.cols[lo..hi]
                        .binary_search(&(a as u32))
                        .expect("diagonal block in the pattern");
                    Some((lo * nf * nf, hi - lo, diag))
                };
                let rows = BlockRows {
                    row_of,
                    offset: |ncols, i, pos, k| layout.offset(ncols, nf, i, pos, k),
                };
                for c in contacts {
                    c.jacobian_rows(nf, s, &rows, values);
                }
            })
            .map_err(fatal);
        self.assembly_time += t.elapsed().as_secs_f64();
        self.jacobians += 1;
        r
    }
}
