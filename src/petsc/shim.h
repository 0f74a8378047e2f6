/* What bindgen cannot translate from PETSc's headers: macros and extern variables that only
 * exist after PetscInitialize. Implemented in shim.c, compiled by build.rs with the cc crate. */
#ifndef MPM_CONCRETE_PETSC_SHIM_H
#define MPM_CONCRETE_PETSC_SHIM_H
#include <petscsys.h>

/* PETSC_COMM_WORLD (an extern variable, valid after PetscInitialize). */
MPI_Comm mpmc_comm_world(void);
/* PETSC_COMM_SELF (a macro). */
MPI_Comm mpmc_comm_self(void);
/* Rank and size of PETSC_COMM_WORLD. */
int mpmc_world_rank(void);
int mpmc_world_size(void);
/* PETSC_DEFAULT / PETSC_DETERMINE / PETSC_DECIDE as values. */
PetscInt mpmc_petsc_decide(void);
PetscReal mpmc_petsc_default_real(void);
/* The version PETSc was built as, "3.18.5". */
const char *mpmc_petsc_version(void);
/* PetscLogEventBegin/End are macros in 3.18. */
PetscErrorCode mpmc_log_event_begin(PetscLogEvent e);
PetscErrorCode mpmc_log_event_end(PetscLogEvent e);
#endif
