//! Fault injection for the farm's own tests (tests/farm.rs): workers that
//! SIGKILL themselves mid-task, stall, send NaN or subtly wrong tiles or
//! claim another protocol, and a coordinator that SIGKILLs itself after a
//! number of journaled columns. The hidden `--fault-*` flags of `sky
//! worker` and `sky render` that set them are refused unless
//! `SKY_FAULT_INJECTION=1` is set (`cli::faults_allowed`); without them no
//! hook fires. They are compiled into every build so that `make test` shares
//! the user's release build instead of compiling the crate twice.

use std::time::Duration;

/// Faults a worker commits (hidden `sky worker --fault-*` flags).
#[derive(Debug, Clone, Default)]
pub struct WorkerFaults {
    /// After this many tasks, accept tasks and never answer again.
    pub stall_after_tasks: Option<u64>,
    /// Send tiles with a NaN in them.
    pub corrupt_tiles: bool,
    /// Send tiles whose values are off by one ulp (a wrong but plausible
    /// result, which only verification catches).
    pub perturb_tiles: bool,
    /// Claim this protocol version instead of the real one.
    pub protocol_version: Option<u32>,
    /// On this task (counting from 0), SIGKILL the worker's own process a
    /// moment after the render starts.
    pub sigkill_on_task: Option<u64>,
    /// Take this long more to unpack optics a task brings (a loaded PC).
    pub slow_unpack: Option<Duration>,
}

/// Faults a coordinator commits (the hidden `sky render
/// --fault-kill-after-columns`).
#[derive(Debug, Clone, Default)]
pub struct CoordinatorFaults {
    /// SIGKILL this process once the render holds at least this many
    /// accepted columns (journaled, resumed ones included).
    pub kill_after_columns: Option<u32>,
}

impl CoordinatorFaults {
    /// Called after each accepted tile with the columns accepted so far.
    pub(crate) fn accepted(&self, columns: u32) {
        if self.kill_after_columns.is_some_and(|n| columns >= n) {
            kill_self();
        }
    }
}

impl WorkerFaults {
    /// Whether task number `started` (from 0) should stall forever.
    pub(crate) fn stalls(&self, started: u64) -> bool {
        self.stall_after_tasks.is_some_and(|n| started >= n)
    }

    /// Kills the worker a moment after task number `started` begins, if
    /// that is its fault.
    pub(crate) fn maybe_kill_during(&self, started: u64) {
        if self.sigkill_on_task == Some(started) {
            tokio::spawn(async {
                tokio::time::sleep(Duration::from_millis(150)).await;
                kill_self();
            });
        }
    }

    /// Sleeps the unpacking thread as told.
    pub(crate) fn unpacking(&self) {
        if let Some(d) = self.slow_unpack {
            std::thread::sleep(d);
        }
    }

    /// Spoils a finished tile as told.
    pub(crate) fn spoil(&self, t: &mut super::proto::Tile) {
        if self.corrupt_tiles {
            t.values[0] = f64::NAN;
        }
        if self.perturb_tiles {
            t.values[1] = f64::from_bits(t.values[1].to_bits() + 1);
        }
    }
}

/// SIGKILL to this process: no destructors, no flushing, as a crash.
fn kill_self() {
    // SAFETY: sending a signal to our own process.
    #[cfg(unix)]
    unsafe {
        libc::kill(libc::getpid(), libc::SIGKILL);
    }
    #[cfg(not(unix))]
    std::process::abort();
}
