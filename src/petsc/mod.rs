//! Safe wrappers over PETSc (Debian's 3.18, real scalars, 32-bit `PetscInt`): the only module with
//! `unsafe` foreign calls.
//!
//! * [`Session`]: the process-wide PETSc/MPI session, initialised once with the program's arguments so
//!   that every `-snes_*`, `-ksp_*`, `-pc_*`, `-mat_*`, `-log_view`, `-help` option works. Every PETSc
//!   object is created and used while holding the session guard, which serialises PETSc calls (PETSc is
//!   not thread-safe; Rust's test harness runs tests on several threads).
//! * [`Vector`], [`Matrix`], [`IndexSet`], [`Snes`]: one owning type per PETSc object, destroyed on drop.
//! * Every PETSc error becomes a [`PetscError`] carrying PETSc's own message (captured by an error
//!   handler pushed at start-up), never an abort.

mod block_parts;
mod ksp;
mod matrix;
mod operator;
mod options;
mod preconditioner;
mod smoother;
mod snes;
pub mod sys;
mod vector;

pub use ksp::LinearSolve;
pub use matrix::{BlockCsr, BlockLayout, IndexSet, Matrix, matrix_type_for};
pub use operator::ThreadedOperator;
pub use options::{
    apply_default_options, clear_option, has_option, option_string, set_default_option, set_option,
    unused_options,
};
pub use preconditioner::use_threaded_ilu;
pub use snes::{CallbackError, NonlinearProblem, STALLED, Snes, SolveInfo, Tolerances};
pub use vector::{GatherAll, GatherRange, Vector};

use std::ffi::{CStr, CString, c_char, c_int, c_void};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Mutex, MutexGuard, OnceLock};

/// PETSc's index type (32-bit in Debian's `petsc-dev`).
pub type PetscInt = sys::PetscInt;

/// A failed PETSc call, with PETSc's error code and message.
#[derive(Debug, Clone, thiserror::Error)]
#[error("PETSc error {code} in {call}: {message}")]
pub struct PetscError {
    /// PETSc error code (e.g. 86 = unknown type).
    pub code: i32,
    /// The wrapper call that failed.
    pub call: &'static str,
    /// PETSc's message (first line of its traceback), or a description from the wrapper.
    pub message: String,
}

impl PetscError {
    /// True for the failures of a numerical method on the data it was given, which another solver or a
    /// smaller time step may avoid: a zero pivot (`PETSC_ERR_MAT_LU_ZRPVT` 71), a floating-point exception
    /// (`PETSC_ERR_FP` 72), an error of an external library such as MUMPS (`PETSC_ERR_LIB` 76), a failed
    /// iterative method (`PETSC_ERR_CONV_FAILED` 82, `PETSC_ERR_NOT_CONVERGED` 91). Other codes (unknown
    /// types, wrong arguments, memory) are not the data's fault.
    pub fn is_numerical(&self) -> bool {
        matches!(self.code, 71 | 72 | 76 | 82 | 91)
    }
}

/// Result of a PETSc wrapper call.
pub type Result<T> = std::result::Result<T, PetscError>;

/// The message of the most recent PETSc error, recorded by [`error_handler`].
static LAST_ERROR: Mutex<Option<String>> = Mutex::new(None);

/// Turns a PETSc return code into a `Result`, attaching the recorded message.
pub(crate) fn check(code: sys::PetscErrorCode, call: &'static str) -> Result<()> {
    if code == 0 {
        return Ok(());
    }
    let message = LAST_ERROR
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .take()
        .unwrap_or_else(|| "no message recorded".to_owned());
    Err(PetscError {
        code,
        call,
        message,
    })
}

/// PETSc error handler: keeps the initial message (the one that names the cause) instead of printing.
unsafe extern "C" fn error_handler(
    _comm: sys::MPI_Comm,
    line: c_int,
    func: *const c_char,
    file: *const c_char,
    n: sys::PetscErrorCode,
    p: sys::PetscErrorType,
    mess: *const c_char,
    _ctx: *mut c_void,
) -> sys::PetscErrorCode {
    let text = |s: *const c_char| {
        if s.is_null() {
            String::new()
        } else {
            // SAFETY: PETSc passes NUL-terminated strings valid for the duration of the call.
            unsafe { CStr::from_ptr(s) }.to_string_lossy().into_owned()
        }
    };
    if p == sys::PetscErrorType_PETSC_ERROR_INITIAL {
        let mut msg = text(mess).trim().to_owned();
        if msg.is_empty() {
            let mut generic: *const c_char = std::ptr::null();
            // SAFETY: PetscErrorMessage only writes a pointer to a static string.
            unsafe { sys::PetscErrorMessage(n, &mut generic, std::ptr::null_mut()) };
            msg = text(generic);
        }
        let origin = format!("{}() at {}:{}", text(func), text(file), line);
        *LAST_ERROR.lock().unwrap_or_else(|e| e.into_inner()) = Some(format!("{msg} [{origin}]"));
    }
    n
}

/// The PETSc session of this process. Obtain it with [`Session::initialize`] (the binary, with its
/// command line) or [`Session::get`] (tests and library users; initialises with no options if needed).
pub struct Session {
    _private: (),
}

static SESSION: OnceLock<std::result::Result<Mutex<Session>, PetscError>> = OnceLock::new();

/// Bytes this process has sent through the program's own exchanges ([`Session::bytes_sent`]).
static BYTES_SENT: AtomicU64 = AtomicU64::new(0);

/// Of [`BYTES_SENT`], the bytes of the [`GatherRange`] gathers ([`Session::bytes_gathered`]).
static BYTES_GATHERED: AtomicU64 = AtomicU64::new(0);

/// Counts `bytes` (B) as sent by this process ([`Session::bytes_sent`]).
fn count_sent(bytes: usize) {
    BYTES_SENT.fetch_add(bytes as u64, Ordering::Relaxed);
}

/// Counts `bytes` (B) as sent by this process in a [`GatherRange`] gather.
fn count_gathered(bytes: usize) {
    count_sent(bytes);
    BYTES_GATHERED.fetch_add(bytes as u64, Ordering::Relaxed);
}

/// Exclusive access to PETSc for the current thread; PETSc objects are created and used under it.
pub type SessionGuard = MutexGuard<'static, Session>;

impl Session {
    /// Initialises PETSc and MPI with `args` (the first is the program name; the rest are PETSc options
    /// such as `-snes_monitor`). Later calls return the existing session and ignore `args`.
    pub fn initialize(args: &[String]) -> Result<SessionGuard> {
        let session =
            SESSION.get_or_init(|| init_petsc(args).map(|()| Mutex::new(Session { _private: () })));
        match session {
            Ok(m) => Ok(m.lock().unwrap_or_else(|e| e.into_inner())),
            Err(e) => Err(e.clone()),
        }
    }

    /// The session, initialised with no command-line options if this is the first use.
    pub fn get() -> Result<SessionGuard> {
        Self::initialize(&["mpm_concrete".to_owned()])
    }

    /// Rank of this process in PETSc's world communicator.
    pub fn rank(&self) -> usize {
        // SAFETY: PETSc is initialised while a Session exists.
        unsafe { sys::mpmc_world_rank() as usize }
    }

    /// Number of processes in PETSc's world communicator.
    pub fn size(&self) -> usize {
        // SAFETY: as above.
        unsafe { sys::mpmc_world_size() as usize }
    }

    /// Bytes (B) this process has sent since PETSc started through the program's own exchanges: the
    /// records of [`Session::exchange`] for other processes, the buffers of [`Session::sum`],
    /// [`Session::min`] and [`Session::any`] (once per process: a reduction tree sends about its buffer
    /// from each process) and the entries of distributed vectors that [`GatherAll`] and [`GatherRange`]
    /// deliver to other processes. PETSc's own traffic (its Krylov solvers, preconditioners and matrix
    /// products) is not counted. On one process nothing is sent: 0.
    pub fn bytes_sent(&self) -> u64 {
        BYTES_SENT.load(Ordering::Relaxed)
    }

    /// Of [`Session::bytes_sent`], the bytes (B) this process has sent in the gathers of ranges of
    /// distributed vectors ([`GatherRange`]: the unknowns a process reads at an evaluation).
    pub fn bytes_gathered(&self) -> u64 {
        BYTES_GATHERED.load(Ordering::Relaxed)
    }

    /// True on every process if `flag` is true on any (collective: every process must call it; one
    /// process: `flag`).
    pub fn any(&self, flag: bool) -> bool {
        if self.size() == 1 {
            return flag;
        }
        count_sent(std::mem::size_of::<i32>());
        // SAFETY: as above; an MPI_Allreduce over the world communicator.
        unsafe { sys::mpmc_world_any(i32::from(flag)) != 0 }
    }

    /// `values[i]` summed over all processes, in place, with the same bits on every process (collective;
    /// one process: unchanged).
    pub fn sum(&self, values: &mut [f64]) -> Result<()> {
        self.reduce(
            values,
            sys::mpmc_sum_doubles,
            "values to sum",
            "MPI_Reduce (sum)",
        )
    }

    /// `values[i]` replaced by its minimum over all processes, in place (collective; as [`Session::sum`]).
    pub fn min(&self, values: &mut [f64]) -> Result<()> {
        self.reduce(
            values,
            sys::mpmc_min_doubles,
            "values to reduce",
            "MPI_Reduce (min)",
        )
    }

    /// `values` reduced in place over all processes by the MPI reduction and broadcast `op` (`what`
    /// names the buffer, `call` the reduction in errors; collective; one process: unchanged).
    fn reduce(
        &self,
        values: &mut [f64],
        op: unsafe extern "C" fn(*mut f64, PetscInt) -> sys::PetscErrorCode,
        what: &'static str,
        call: &'static str,
    ) -> Result<()> {
        if self.size() == 1 {
            return Ok(());
        }
        let n = to_petsc_int(values.len(), what)?;
        count_sent(std::mem::size_of_val(values));
        // SAFETY: the buffer holds n doubles; `op` reduces and broadcasts over the world communicator.
        check(unsafe { op(values.as_mut_ptr(), n) }, call)
    }

    /// `values[i]` replaced by its bitwise exclusive or over all processes, in place (collective; one
    /// process: unchanged).
    pub fn xor(&self, values: &mut [u32]) -> Result<()> {
        if self.size() == 1 {
            return Ok(());
        }
        let n = to_petsc_int(values.len(), "values to reduce")?;
        count_sent(std::mem::size_of_val(values));
        // SAFETY: the buffer holds n unsigned 32-bit integers, reduced in place over the world communicator.
        check(
            unsafe { sys::mpmc_xor_u32(values.as_mut_ptr(), n) },
            "MPI_Allreduce (xor)",
        )
    }

    /// Creates (truncating) the HDF5 file `path` that every process writes its part of: through MPI-IO on
    /// several processes, HDF5's default driver on one. Every later call on the file that creates or
    /// changes an object (datasets, attributes) and the file's closing are collective: every process
    /// makes them in the same order with the same arguments; the data of a dataset each process writes
    /// independently (its own selection). Collective.
    pub fn create_shared_file(
        &self,
        path: &std::path::Path,
    ) -> hdf5_metno::Result<hdf5_metno::File> {
        let c = std::ffi::CString::new(path.as_os_str().as_encoded_bytes())
            .map_err(|_| hdf5_metno::Error::from("a file name with a NUL byte"))?;
        // Under the HDF5 crate's lock and after its initialisation (which keeps HDF5 from closing at exit
        // what a failed write left open: a file whose flush failed on a full disk).
        let id = hdf5_metno::sync::sync(|| {
            // SAFETY: c outlives the call; the shim returns a new file identifier (or a negative value),
            // whose single reference the File below takes over and closes when dropped.
            unsafe { sys::mpmc_h5_create_shared(c.as_ptr()) }
        });
        if id < 0 {
            return Err(hdf5_metno::Error::from(
                format!("{}: H5Fcreate failed", path.display()).as_str(),
            ));
        }
        // SAFETY: a valid file identifier just created, with one reference.
        unsafe { hdf5_metno::from_id::<hdf5_metno::File>(id) }
    }

    /// Sends records of `width` values: `send` holds `counts[r]` records for process `r`, in process
    /// order (`counts` has one entry per process). Returns the records sent to this process, ordered by
    /// source process and, from one source, in its order. Built on a PetscSF whose roots are the outgoing
    /// and whose leaves the incoming records (collective).
    pub fn exchange(&self, width: usize, counts: &[usize], send: &[f64]) -> Result<Vec<f64>> {
        let total: usize = counts.iter().sum();
        if counts.len() != self.size() || send.len() != total * width || width == 0 {
            return Err(PetscError {
                code: 62, // PETSC_ERR_ARG_WRONG
                call: "exchange",
                message: format!(
                    "{} record counts for {} processes, {} values for {total} records of {width}",
                    counts.len(),
                    self.size(),
                    send.len()
                ),
            });
        }
        let counts = counts
            .iter()
            .map(|&c| to_petsc_int(c, "records to send"))
            .collect::<Result<Vec<_>>>()?;
        let width_p = to_petsc_int(width, "record width")?;
        let elsewhere = total - counts[self.rank()] as usize;
        count_sent(elsewhere * width * std::mem::size_of::<f64>());
        let (mut n, mut recv): (PetscInt, *mut f64) = (0, std::ptr::null_mut());
        // SAFETY: counts has one entry per process and send the records they count; the shim allocates
        // `recv` with PetscMalloc (n * width values), copied out and freed below.
        check(
            unsafe {
                sys::mpmc_exchange_records(
                    width_p,
                    counts.as_ptr(),
                    // Nothing to send: no pointer (a dangling one would reach MPI).
                    if send.is_empty() {
                        std::ptr::null()
                    } else {
                        send.as_ptr()
                    },
                    &mut n,
                    &mut recv,
                )
            },
            "PetscSFBcast (records)",
        )?;
        let len = n as usize * width;
        // SAFETY: recv holds len doubles (allocated by the shim, which succeeded).
        let out = unsafe { std::slice::from_raw_parts(recv, len) }.to_vec();
        // SAFETY: allocated with PetscMalloc by the shim.
        unsafe { sys::mpmc_free(recv.cast()) };
        Ok(out)
    }

    /// Registers a logging stage (shown by `-log_view`).
    pub fn register_stage(&self, name: &str) -> Result<sys::PetscLogStage> {
        let c = cstring(name)?;
        let mut stage = 0;
        // SAFETY: c outlives the call; PETSc copies the name.
        check(
            unsafe { sys::PetscLogStageRegister(c.as_ptr(), &mut stage) },
            "PetscLogStageRegister",
        )?;
        Ok(stage)
    }

    /// Enters a logging stage until the returned guard is dropped.
    pub fn push_stage(&self, stage: sys::PetscLogStage) -> Result<StageGuard> {
        // SAFETY: stage was registered.
        check(
            unsafe { sys::PetscLogStagePush(stage) },
            "PetscLogStagePush",
        )?;
        Ok(StageGuard { _private: () })
    }

    /// Finalises PETSc (prints `-log_view`, `-options_left` reports). PETSc cannot be re-initialised in
    /// the same process, so this is for the end of `main` only.
    pub fn finalize(self_guard: SessionGuard) -> Result<()> {
        drop(self_guard);
        // SAFETY: every object wrapper has been dropped by the caller (they borrow nothing from the
        // guard, so this is the caller's contract: call at the very end of the program).
        check(unsafe { sys::PetscFinalize() }, "PetscFinalize")
    }
}

/// Leaves a logging stage on drop.
pub struct StageGuard {
    _private: (),
}

impl Drop for StageGuard {
    fn drop(&mut self) {
        // SAFETY: paired with the PetscLogStagePush of the constructor.
        unsafe { sys::PetscLogStagePop() };
    }
}

fn init_petsc(args: &[String]) -> Result<()> {
    // PETSc keeps argc/argv for the whole session: leak them deliberately (a few bytes, once).
    // argv is NULL-terminated, as MPI_Init expects.
    let mut c_args: Vec<*mut c_char> = args
        .iter()
        .map(|a| {
            CString::new(a.as_str())
                .unwrap_or_else(|_| CString::from(c"?"))
                .into_raw()
        })
        .collect();
    let argc_value = c_args.len() as c_int;
    c_args.push(std::ptr::null_mut());
    let argv: &'static mut Vec<*mut c_char> = Box::leak(Box::new(c_args));
    let argc: &'static mut c_int = Box::leak(Box::new(argc_value));
    let argv_ptr: &'static mut *mut *mut c_char = Box::leak(Box::new(argv.as_mut_ptr()));
    let help = c"mpm_concrete: implicit MPM with a gradient-enhanced microplane damage model.\nPETSc options follow; see `mpm-concrete --help` for the program's own arguments.\n";
    // SAFETY: argc/argv live for the rest of the process; help is a static C string.
    let code = unsafe { sys::PetscInitialize(argc, argv_ptr, std::ptr::null(), help.as_ptr()) };
    if code != 0 {
        return Err(PetscError {
            code,
            call: "PetscInitialize",
            message: "PETSc/MPI initialisation failed".to_owned(),
        });
    }
    // The dense kernels of the direct solvers (MUMPS) run on the system BLAS. OpenBLAS's own threads
    // would compete with rayon's (and with other MPI ranks) and spin while waiting: on a busy 2-core
    // machine a factorisation took 7x longer with 2 OpenBLAS threads than with 1. One thread per process
    // unless the user chose otherwise (OPENBLAS_NUM_THREADS).
    if std::env::var_os("OPENBLAS_NUM_THREADS").is_none() {
        // SAFETY: looks the function up at run time and calls it with a plain int.
        unsafe { sys::mpmc_openblas_set_threads(1) };
    }
    // SAFETY: the handler is a plain function with the expected signature and no context.
    check(
        unsafe { sys::PetscPushErrorHandler(Some(error_handler), std::ptr::null_mut()) },
        "PetscPushErrorHandler",
    )
}

/// The name PETSc gives a converged reason (`name` from `*GetConvergedReasonString`), or the number
/// `reason` when it gives none.
///
/// # Safety
/// `name` must be null or point to a NUL-terminated string that lives through the call.
pub(crate) unsafe fn reason_name(name: *const std::ffi::c_char, reason: impl ToString) -> String {
    if name.is_null() {
        return reason.to_string();
    }
    // SAFETY: guaranteed by the caller.
    unsafe { std::ffi::CStr::from_ptr(name) }
        .to_string_lossy()
        .into_owned()
}

/// A Rust string as a C string, or a PETSc-style error if it holds a NUL byte.
pub(crate) fn cstring(s: &str) -> Result<CString> {
    CString::new(s).map_err(|_| PetscError {
        code: 62,
        call: "CString::new",
        message: format!("string {s:?} contains a NUL byte"),
    })
}

/// Converts a count or index to `PetscInt`, failing if it does not fit in 32 bits.
pub(crate) fn to_petsc_int(n: usize, what: &'static str) -> Result<PetscInt> {
    PetscInt::try_from(n).map_err(|_| PetscError {
        code: 63,
        call: what,
        message: format!("{n} exceeds the 32-bit PetscInt of this PETSc build (use petsc64-dev)"),
    })
}

/// The world communicator (valid after initialisation).
pub(crate) fn comm_world() -> sys::MPI_Comm {
    // SAFETY: reads PETSC_COMM_WORLD; only called while a session exists.
    unsafe { sys::mpmc_comm_world() }
}

/// A new PETSc object (vector, matrix, solver) made on the world communicator by the constructor
/// `create`, named `call` in errors.
pub(crate) fn create<T>(
    create: unsafe extern "C" fn(sys::MPI_Comm, *mut *mut T) -> sys::PetscErrorCode,
    call: &'static str,
) -> Result<*mut T> {
    let mut raw = std::ptr::null_mut();
    // SAFETY: `raw` is an out-parameter of a PETSc constructor; the caller's wrapper owns the object.
    check(unsafe { create(comm_world(), &mut raw) }, call)?;
    Ok(raw)
}

/// The range `[start, end)` of rows or entries owned by this process, as written by the PETSc query
/// `get` (named `call` in errors).
pub(crate) fn ownership_range(
    get: impl FnOnce(&mut PetscInt, &mut PetscInt) -> sys::PetscErrorCode,
    call: &'static str,
) -> Result<std::ops::Range<usize>> {
    let (mut lo, mut hi) = (0, 0);
    check(get(&mut lo, &mut hi), call)?;
    Ok(lo as usize..hi as usize)
}

/// A user-registered logging event; time spent between [`LogEvent::begin`] and the drop of the returned
/// guard is reported by `-log_view`.
#[derive(Clone, Copy, Debug)]
pub struct LogEvent(sys::PetscLogEvent);

impl LogEvent {
    /// Registers an event under PETSc's generic object class.
    pub fn register(_session: &Session, name: &str) -> Result<Self> {
        static CLASS: OnceLock<sys::PetscClassId> = OnceLock::new();
        let class = match CLASS.get() {
            Some(c) => *c,
            None => {
                let mut class = 0;
                // SAFETY: PETSc copies the name.
                check(
                    unsafe { sys::PetscClassIdRegister(c"mpm_concrete".as_ptr(), &mut class) },
                    "PetscClassIdRegister",
                )?;
                *CLASS.get_or_init(|| class)
            }
        };
        let c = cstring(name)?;
        let mut event = 0;
        // SAFETY: PETSc copies the name.
        check(
            unsafe { sys::PetscLogEventRegister(c.as_ptr(), class, &mut event) },
            "PetscLogEventRegister",
        )?;
        Ok(Self(event))
    }

    /// Starts timing; stops when the guard drops.
    pub fn begin(self) -> EventGuard {
        // SAFETY: the event was registered.
        unsafe { sys::mpmc_log_event_begin(self.0) };
        EventGuard(self.0)
    }
}

/// Ends a [`LogEvent`] on drop.
pub struct EventGuard(sys::PetscLogEvent);

impl Drop for EventGuard {
    fn drop(&mut self) {
        // SAFETY: paired with mpmc_log_event_begin.
        unsafe { sys::mpmc_log_event_end(self.0) };
    }
}
