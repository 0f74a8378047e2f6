#define _GNU_SOURCE
#include <dlfcn.h>
#include "shim.h"

MPI_Comm mpmc_comm_world(void) { return PETSC_COMM_WORLD; }
MPI_Comm mpmc_comm_self(void) { return PETSC_COMM_SELF; }

int mpmc_world_rank(void)
{
  PetscMPIInt rank = 0;
  MPI_Comm_rank(PETSC_COMM_WORLD, &rank);
  return rank;
}

int mpmc_world_size(void)
{
  PetscMPIInt size = 1;
  MPI_Comm_size(PETSC_COMM_WORLD, &size);
  return size;
}

int mpmc_world_any(int flag)
{
  int any = flag;
  MPI_Allreduce(&flag, &any, 1, MPI_INT, MPI_LOR, PETSC_COMM_WORLD);
  return any;
}

PetscInt mpmc_petsc_decide(void) { return PETSC_DECIDE; }
PetscErrorCode mpmc_log_event_begin(PetscLogEvent e) { return PetscLogEventBegin(e, 0, 0, 0, 0); }
PetscErrorCode mpmc_log_event_end(PetscLogEvent e) { return PetscLogEventEnd(e, 0, 0, 0, 0); }

int mpmc_openblas_set_threads(int n)
{
  void (*set)(int) = (void (*)(int))dlsym(RTLD_DEFAULT, "openblas_set_num_threads");
  if (!set) return 0;
  set(n);
  return 1;
}
