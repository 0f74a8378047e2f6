//! The implicit MPM time step (spec Sec. 1): shape functions at `t_n`, P2G, unknown numbering and
//! constraints, Newton on the coupled (du, eta_bar) system through PETSc SNES, G2P and commit; with
//! time-step halving when a step fails.
//!
//! Committed state (particles, time) is only modified after SNES converges: a failed attempt leaves the
//! simulation exactly as it was, so it can be retried with a smaller time step.
//!
//! This file only declares the step's files and re-exports what the rest of the crate uses; the files
//! form layers, each using only files of the layers below it (docs/architecture.md): the step's hub
//! ([`Workspace`] and the step in progress, `step.rs`) near the bottom, its control ([`Simulation`],
//! [`advance`], `control.rs`) at the top.

mod contacts;
mod control;
mod data;
mod finish;
mod input;
mod interrupt;
mod path;
mod prepare;
mod problem;
mod processes;
mod report;
mod solve;
mod start;
mod step;
mod system;

pub use control::{Simulation, advance};
pub use data::StepData;
pub use interrupt::{FINISH_WITHIN, Interrupt};
pub use report::{PathPoint, StepError, StepReport};
pub use step::Workspace;
