/* What bindgen cannot translate from PETSc's headers: macros and extern variables that only
 * exist after PetscInitialize. Implemented in shim.c, compiled by build.rs with the cc crate. */
#ifndef MPM_CONCRETE_PETSC_SHIM_H
#define MPM_CONCRETE_PETSC_SHIM_H
#include <petscsys.h>
#include <stdint.h>

/* PETSC_COMM_WORLD (an extern variable, valid after PetscInitialize). */
MPI_Comm mpmc_comm_world(void);
/* PETSC_COMM_SELF (a macro). */
MPI_Comm mpmc_comm_self(void);
/* Rank and size of PETSC_COMM_WORLD. */
int mpmc_world_rank(void);
int mpmc_world_size(void);
/* Logical OR of `flag` over PETSC_COMM_WORLD (collective). */
int mpmc_world_any(int flag);
/* PETSC_DECIDE as a value. */
PetscInt mpmc_petsc_decide(void);
/* PetscLogEventBegin/End are macros in 3.18. */
PetscErrorCode mpmc_log_event_begin(PetscLogEvent e);
PetscErrorCode mpmc_log_event_end(PetscLogEvent e);
/* Sets the thread count of an OpenBLAS loaded in the process (found at run time; other BLAS have no such
 * call). Returns 1 if OpenBLAS was found. */
int mpmc_openblas_set_threads(int n);
/* In place over PETSC_COMM_WORLD: the sum or the minimum of `buf` over all processes, bitwise the same on
 * every process (reduced on process 0, then broadcast). Collective. */
PetscErrorCode mpmc_sum_doubles(double *buf, PetscInt n);
PetscErrorCode mpmc_min_doubles(double *buf, PetscInt n);
/* Sends records of `width` doubles: `send` holds sendcounts[r] records for process r, in process order.
 * On return `*recv` (PetscMalloc'ed; free with mpmc_free) holds the `*nrecv` records sent here, ordered
 * by source process and, within one source, in its send order. A PetscSF whose roots are the outgoing
 * records and whose leaves the incoming ones (record counts and offsets found by MPI_Alltoall).
 * Collective. */
PetscErrorCode mpmc_exchange_records(PetscInt width, const PetscInt *sendcounts, const double *send,
                                     PetscInt *nrecv, double **recv);
PetscErrorCode mpmc_free(void *p);
/* In place over PETSC_COMM_WORLD: the bitwise exclusive or of `buf` over all processes. Collective. */
PetscErrorCode mpmc_xor_u32(uint32_t *buf, PetscInt n);
/* Creates (truncating) the HDF5 file `path` for writing by every process of PETSC_COMM_WORLD: through
 * MPI-IO (H5Pset_fapl_mpio) on several processes, HDF5's default driver on one. Returns the file's
 * identifier (an hid_t, int64_t in HDF5 >= 1.10), negative on failure. Collective. */
int64_t mpmc_h5_create_shared(const char *path);
#endif
