//! Process-wide realtime setup: locking memory and checking whether realtime scheduling is
//! available.
//!
//! Why a capability check instead of failing: development machines and CI run without
//! `CAP_SYS_NICE`/`CAP_IPC_LOCK`. The runtime still runs there, but must say so: one clear
//! warning, and `realtime: false` in the status, never a silent degradation.

use std::sync::atomic::{AtomicBool, Ordering};

/// What the process can do for realtime.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub struct Capabilities {
    /// `mlockall` succeeded (or was already in effect).
    pub memory_locked: bool,
    /// A thread may switch to `SCHED_FIFO`.
    pub fifo_scheduling: bool,
    /// Both of the above: the status reported as `realtime`.
    pub realtime: bool,
}

/// Errors of the realtime setup calls.
#[derive(Debug, thiserror::Error)]
pub enum SystemError {
    /// `mlockall` failed (usually missing `CAP_IPC_LOCK` or a low `RLIMIT_MEMLOCK`).
    #[error("mlockall failed: {0}")]
    LockMemory(std::io::Error),
    /// `sched_setscheduler`/`pthread_setschedparam` failed.
    #[error("cannot set SCHED_FIFO priority {priority}: {source}")]
    Scheduler {
        /// Priority requested.
        priority: i32,
        /// OS error.
        source: std::io::Error,
    },
    /// `sched_setaffinity` failed.
    #[error("cannot pin to CPU {cpu}: {source}")]
    Affinity {
        /// CPU requested.
        cpu: usize,
        /// OS error.
        source: std::io::Error,
    },
}

static MEMORY_LOCKED: AtomicBool = AtomicBool::new(false);
static WARNED: AtomicBool = AtomicBool::new(false);

/// Locks all current and future pages of the process in RAM (`mlockall(MCL_CURRENT |
/// MCL_FUTURE)`), so a realtime step never takes a page fault to disk. The daemon calls it
/// once at start.
pub fn lock_memory() -> Result<(), SystemError> {
    // SAFETY: plain syscall without pointers.
    let rc = unsafe { libc::mlockall(libc::MCL_CURRENT | libc::MCL_FUTURE) };
    if rc != 0 {
        return Err(SystemError::LockMemory(std::io::Error::last_os_error()));
    }
    MEMORY_LOCKED.store(true, Ordering::Release);
    Ok(())
}

/// True once [`lock_memory`] succeeded in this process.
pub fn memory_locked() -> bool {
    MEMORY_LOCKED.load(Ordering::Acquire)
}

/// Whether this process may use `SCHED_FIFO`: checked by asking for it on a short-lived
/// probe thread (the honest test: capabilities, rlimits and cgroup RT budgets all matter).
pub fn can_use_fifo() -> bool {
    std::thread::spawn(|| set_fifo_priority(1).is_ok())
        .join()
        .unwrap_or(false)
}

/// The realtime capabilities of this process right now.
pub fn capabilities() -> Capabilities {
    let memory_locked = memory_locked();
    let fifo_scheduling = can_use_fifo();
    Capabilities {
        memory_locked,
        fifo_scheduling,
        realtime: memory_locked && fifo_scheduling,
    }
}

/// Logs, once per process, that realtime is not available and why. Everything that degrades
/// calls this, so the operator sees exactly one clear line.
pub fn warn_not_realtime(why: &str) {
    if !WARNED.swap(true, Ordering::AcqRel) {
        tracing::warn!(
            "realtime NOT available ({why}); running with ordinary scheduling: timing is not \
             guaranteed (status reports realtime: false)"
        );
    }
}

/// Switches the calling thread to `SCHED_FIFO` at `priority` (1..=99).
pub fn set_fifo_priority(priority: i32) -> Result<(), SystemError> {
    let param = libc::sched_param {
        sched_priority: priority,
    };
    // SAFETY: valid pointer; pthread_self is the calling thread.
    let rc = unsafe { libc::pthread_setschedparam(libc::pthread_self(), libc::SCHED_FIFO, &param) };
    if rc != 0 {
        return Err(SystemError::Scheduler {
            priority,
            source: std::io::Error::from_raw_os_error(rc),
        });
    }
    Ok(())
}

/// Pins the calling thread to one CPU.
pub fn pin_to_cpu(cpu: usize) -> Result<(), SystemError> {
    let mut set = nix::sched::CpuSet::new();
    set.set(cpu).map_err(|e| SystemError::Affinity {
        cpu,
        source: std::io::Error::from_raw_os_error(e as i32),
    })?;
    nix::sched::sched_setaffinity(nix::unistd::Pid::from_raw(0), &set).map_err(|e| {
        SystemError::Affinity {
            cpu,
            source: std::io::Error::from_raw_os_error(e as i32),
        }
    })
}

/// Touches `bytes` of the calling thread's stack so those pages are mapped (and, after
/// `mlockall`, locked) before the first realtime step instead of faulting during it.
#[inline(never)]
pub fn prefault_stack(bytes: usize) {
    const CHUNK: usize = 16 * 1024;
    fn touch(left: usize) {
        let mut buf = [0u8; CHUNK];
        std::hint::black_box(&mut buf);
        if left > CHUNK {
            touch(left - CHUNK);
        }
        std::hint::black_box(&buf);
    }
    touch(bytes);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn capabilities_are_consistent() {
        let c = capabilities();
        assert_eq!(c.realtime, c.memory_locked && c.fifo_scheduling);
        prefault_stack(64 * 1024);
    }

    #[test]
    fn bad_priority_is_an_error() {
        let r = std::thread::spawn(|| set_fifo_priority(1000))
            .join()
            .unwrap();
        assert!(matches!(r, Err(SystemError::Scheduler { .. })));
    }
}
