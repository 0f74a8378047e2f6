//! The applications built on the library, one module per command of `mpm-concrete` besides `run`:
//! cross-checks against reference solutions (`compare`), solver-comparison studies (`study`), the
//! benchmark command (`bench`), the material-point driver (`material_driver`) and the PETSc lattice smoke
//! problem (`smoke`). The library below them (material, solver, io, ...) imports none of them, nor the
//! command-line parser.

pub mod bench;
pub mod compare;
pub mod material_driver;
pub mod smoke;
pub mod study;
