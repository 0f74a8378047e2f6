#define _GNU_SOURCE
#include <dlfcn.h>
#include "shim.h"
#include <petscsf.h>
#include <hdf5.h>

_Static_assert(sizeof(hid_t) == sizeof(int64_t), "hid_t is 64-bit from HDF5 1.10 on");

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

/* In place: buf[i] = op over all processes of buf[i], the same bits on every process (MPI_Allreduce may
 * sum in another order on each process; a reduction on process 0 then a broadcast cannot). */
static PetscErrorCode reduce_doubles(double *buf, PetscInt n, MPI_Op op)
{
  PetscMPIInt rank, count;
  PetscFunctionBeginUser;
  if (n <= 0) PetscFunctionReturn(0);
  PetscCall(PetscMPIIntCast(n, &count));
  PetscCallMPI(MPI_Comm_rank(PETSC_COMM_WORLD, &rank));
  if (rank == 0) PetscCallMPI(MPI_Reduce(MPI_IN_PLACE, buf, count, MPI_DOUBLE, op, 0, PETSC_COMM_WORLD));
  else PetscCallMPI(MPI_Reduce(buf, NULL, count, MPI_DOUBLE, op, 0, PETSC_COMM_WORLD));
  PetscCallMPI(MPI_Bcast(buf, count, MPI_DOUBLE, 0, PETSC_COMM_WORLD));
  PetscFunctionReturn(0);
}

PetscErrorCode mpmc_sum_doubles(double *buf, PetscInt n) { return reduce_doubles(buf, n, MPI_SUM); }
PetscErrorCode mpmc_min_doubles(double *buf, PetscInt n) { return reduce_doubles(buf, n, MPI_MIN); }

PetscErrorCode mpmc_exchange_records(PetscInt width, const PetscInt *sendcounts, const double *send,
                                     PetscInt *nrecv, double **recv)
{
  PetscMPIInt  size, rank, r;
  PetscMPIInt *counts, *offsets, *incoming, *from;
  PetscInt     nroots = 0, nleaves = 0, k = 0, i;
  PetscSFNode *remote;
  PetscSF      sf;
  MPI_Datatype unit;
  PetscFunctionBeginUser;
  PetscCallMPI(MPI_Comm_size(PETSC_COMM_WORLD, &size));
  PetscCallMPI(MPI_Comm_rank(PETSC_COMM_WORLD, &rank));
  PetscCall(PetscMalloc4(size, &counts, size, &offsets, size, &incoming, size, &from));
  for (r = 0; r < size; r++) {
    PetscCall(PetscMPIIntCast(sendcounts[r], &counts[r]));
    PetscCall(PetscMPIIntCast(nroots, &offsets[r]));
    nroots += sendcounts[r];
  }
  /* Per source: how many records it sends here and where they start in its send buffer. */
  PetscCallMPI(MPI_Alltoall(counts, 1, MPI_INT, incoming, 1, MPI_INT, PETSC_COMM_WORLD));
  PetscCallMPI(MPI_Alltoall(offsets, 1, MPI_INT, from, 1, MPI_INT, PETSC_COMM_WORLD));
  for (r = 0; r < size; r++) nleaves += incoming[r];
  PetscCall(PetscMalloc1(nleaves, &remote));
  for (r = 0; r < size; r++)
    for (i = 0; i < incoming[r]; i++, k++) {
      remote[k].rank  = r;
      remote[k].index = from[r] + i;
    }
  PetscCall(PetscFree4(counts, offsets, incoming, from));
  /* Roots: this process's outgoing records; leaves: its incoming ones, ordered by source. */
  PetscCall(PetscSFCreate(PETSC_COMM_WORLD, &sf));
  PetscCall(PetscSFSetGraph(sf, nroots, nleaves, NULL, PETSC_OWN_POINTER, remote, PETSC_OWN_POINTER));
  PetscCall(PetscSFSetUp(sf));
  PetscCall(PetscMalloc1(nleaves * width + 1, recv));
  PetscCallMPI(MPI_Type_contiguous((int)width, MPI_DOUBLE, &unit));
  PetscCallMPI(MPI_Type_commit(&unit));
  PetscCall(PetscSFBcastBegin(sf, unit, send, *recv, MPI_REPLACE));
  PetscCall(PetscSFBcastEnd(sf, unit, send, *recv, MPI_REPLACE));
  PetscCallMPI(MPI_Type_free(&unit));
  PetscCall(PetscSFDestroy(&sf));
  *nrecv = nleaves;
  PetscFunctionReturn(0);
}

PetscErrorCode mpmc_free(void *p) { return PetscFree(p); }

PetscErrorCode mpmc_xor_u32(uint32_t *buf, PetscInt n)
{
  PetscMPIInt count;
  PetscFunctionBeginUser;
  if (n <= 0) PetscFunctionReturn(0);
  PetscCall(PetscMPIIntCast(n, &count));
  PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, buf, count, MPI_UINT32_T, MPI_BXOR, PETSC_COMM_WORLD));
  PetscFunctionReturn(0);
}

int64_t mpmc_h5_create_shared(const char *path)
{
  PetscMPIInt size = 1;
  hid_t       fapl, file;
  MPI_Comm_size(PETSC_COMM_WORLD, &size);
  fapl = H5Pcreate(H5P_FILE_ACCESS);
  if (fapl < 0) return -1;
  if (size > 1 && H5Pset_fapl_mpio(fapl, PETSC_COMM_WORLD, MPI_INFO_NULL) < 0) {
    H5Pclose(fapl);
    return -1;
  }
  file = H5Fcreate(path, H5F_ACC_TRUNC, H5P_DEFAULT, fapl);
  H5Pclose(fapl);
  return file;
}
