//! # mpm_concrete
//!
//! Implicit dynamic Material Point Method (Newmark, updated Lagrangian, grid reset every step) with CPDI
//! shape functions and a finite-strain, gradient-enhanced microplane damage model for concrete, solved
//! monolithically in (u, eta_bar) by PETSc SNES.
//!
//! Source: Oropeza-Navarro, Platen, Chihadeh, Kaliske, "Modeling concrete at high-loading rates: insights by
//! the material point method". Units everywhere: mm, s, N, MPa, t (tonne).
//!
//! The kinematic core and the step are generic over the space dimension (`D` = 2, plane strain, by
//! default; `D` = 3 for specimens of finite thickness, e.g. `Setup::extrude`).
//!
//! Dependencies point one way:
//! `cli (main.rs) -> app -> io -> scenario -> solver -> model -> {boundary, assembly, transfer, material,
//! shape} -> {grid, particles, solids} -> space`,
//! and only `assembly`, `solver`, `solver_defaults` (and the PETSc smoke problem, `app::smoke`) talk to
//! [`petsc`], the one module with `unsafe` FFI.

#![warn(missing_docs)]
#![deny(unsafe_op_in_unsafe_fn)]

pub mod app;
pub mod assembly;
pub mod boundary;
pub mod checkpoint;
pub mod config;
pub mod contact;
pub mod crack;
pub mod dofs;
pub mod geometry;
pub mod grid;
pub mod io;
pub mod material;
pub mod model;
pub mod particles;
pub mod partition;
pub mod petsc;
pub mod plot;
pub mod preflight;
pub mod rundir;
pub mod scenario;
pub mod schema;
pub mod seeding;
pub mod shape;
pub mod solids;
pub mod solver;
pub mod solver_defaults;
pub mod space;
pub mod transfer;
