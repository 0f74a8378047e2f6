/* Header that bindgen translates into src/petsc/sys.rs (see build.rs).
 * Only PETSc's public C API (SNES pulls in KSP, PC, Mat, Vec, IS) plus the small C shim
 * for what bindgen cannot express: communicator macros and static inline functions. */
#include <petscsnes.h>
#include "src/petsc/shim.h"
