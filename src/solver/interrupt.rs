//! A request from outside the run to stop (a signal handler notes Ctrl-C in an [`Interrupt`]). A step
//! that ends soon after the request is kept; a longer one is abandoned at its next residual or Jacobian
//! evaluation or iteration of the linear solver, on every process at the same one, and leaves the
//! committed state as it was
//! (`StepError::Interrupted`). An MPI launcher kills the processes
//! a second or two after it forwards Ctrl-C to them, so a slow step cannot wait to end.

use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

/// How long after a request a step in progress may still run to its end; after that it is abandoned.
/// Open MPI's `mpirun` sends the processes SIGTERM 1 s after Ctrl-C and SIGKILL 1 s after that: what
/// is left of that second goes to the checkpoint (0.35 s for 92,000 points in a debug build).
pub const FINISH_WITHIN: Duration = Duration::from_millis(50);

/// A request to stop, shared between the signal handler that makes it and the steps that watch it
/// (`Simulation::watch`).
#[derive(Debug)]
pub struct Interrupt {
    /// The origin of the time stamps.
    epoch: Instant,
    /// The moment of the first request in microseconds since `epoch`, plus one (0: no request).
    first: AtomicU64,
}

impl Default for Interrupt {
    fn default() -> Self {
        Self::new()
    }
}

impl Interrupt {
    /// No request yet.
    pub fn new() -> Self {
        Self {
            epoch: Instant::now(),
            first: AtomicU64::new(0),
        }
    }

    /// The time since `epoch` in microseconds, plus one (never 0).
    fn now(&self) -> u64 {
        u64::try_from(self.epoch.elapsed().as_micros()).unwrap_or(u64::MAX - 1) + 1
    }

    /// Notes a request; true for the first one.
    pub fn request(&self) -> bool {
        let now = self.now();
        self.first
            .compare_exchange(0, now, Ordering::SeqCst, Ordering::SeqCst)
            .is_ok()
    }

    /// A request was made.
    pub fn requested(&self) -> bool {
        self.first.load(Ordering::SeqCst) != 0
    }

    /// A request was made more than [`FINISH_WITHIN`] ago: a step in progress is to be abandoned.
    pub fn overdue(&self) -> bool {
        let first = self.first.load(Ordering::SeqCst);
        first != 0 && self.now() >= first.saturating_add(FINISH_WITHIN.as_micros() as u64)
    }
}

#[cfg(test)]
mod tests {
    use super::{FINISH_WITHIN, Interrupt};
    use std::time::Duration;

    #[test]
    fn a_request_becomes_overdue_after_the_time_a_step_may_still_take() {
        let i = Interrupt::new();
        assert!(!i.requested() && !i.overdue());
        assert!(i.request());
        assert!(!i.request(), "only the first request counts");
        assert!(i.requested() && !i.overdue());
        std::thread::sleep(FINISH_WITHIN + Duration::from_millis(20));
        assert!(i.overdue());
    }
}
