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
//! Dependencies point one way, from the application (`main.rs`, [`app`]) through the run's files
//! ([`checkpoint`], [`rundir`], [`io`], [`output_file`]), its construction ([`config`], [`scenario`],
//! [`preflight`], [`solver_defaults`]) and the step ([`solver`], [`partition`]) to the model ([`model`])
//! and the physics ([`assembly`], [`transfer`], [`boundary`], [`contact`], [`material`], [`shape`]) on the
//! geometry and the points; `docs/architecture.md` draws the layers. [`petsc`] holds the bindings and
//! their safe wrappers (with shell preconditioners over [`ilu`], the ILU(0) on one overlapping part of
//! the grid per thread, and over [`sor`], the multigrid's Gauss-Seidel smoother on one part per
//! thread): `unsafe` code lives only there and in the microplane model's SIMD kernel;
//! [`assembly`] (block layouts), [`partition`] (star forests), [`solver`], [`solver_defaults`] and
//! [`app`] (the run, the PETSc smoke problem) use its safe types.

#![warn(missing_docs)]
#![deny(unsafe_op_in_unsafe_fn)]

pub mod app;
pub mod assembly;
pub mod bar;
pub mod boundary;
pub mod checkpoint;
pub mod config;
pub mod contact;
pub mod crack;
pub mod csg;
pub mod dofs;
pub mod geometry;
pub mod grid;
pub mod ilu;
pub mod input;
pub mod io;
pub mod material;
pub mod model;
pub mod multigrid;
pub mod output_file;
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
pub mod sor;
pub mod space;
pub mod transfer;
