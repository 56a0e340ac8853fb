//! Cancelling a job preparation in progress.
//!
//! Preparations are serialised ([`super::job`]), so one runaway program (`o1 repeat
//! [99999999]`, a ten-million-iteration loop) used to hold every other `job.load` for minutes.
//! A preparation now carries a [`Cancel`] token whose flag the interpreter polls every few
//! thousand blocks and the streaming planner after every chunk. Four things set it:
//! - `job.abort`, `estop` and the machine entering e-stop for any other reason (its e-stop
//!   input, the PLC) ([`cancel_current`]): the preparation in progress stops;
//! - the requesting client disconnecting (the control server hands its token to the request
//!   with [`with_request_token`]);
//! - the wall-clock budget `[job] prepare_timeout_s` ([`Budget`]).
//!
//! Job loads and MDI lines share it: [`guarded`] runs either under the one-at-a-time lock
//! with its token registered and its budget running.

use crate::machine::api::ApiError;
use std::cell::{Cell, RefCell};
use std::sync::atomic::{AtomicBool, AtomicU8, Ordering};
use std::sync::{mpsc, Arc, Mutex, PoisonError};
use std::time::Duration;

/// Why a preparation was cancelled.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Why {
    /// `job.abort`.
    Abort = 1,
    /// `estop`.
    Estop = 2,
    /// The requesting client disconnected before the answer.
    Disconnected = 3,
    /// The wall-clock budget ran out.
    Timeout = 4,
}

impl Why {
    fn from_u8(v: u8) -> Option<Why> {
        [Why::Abort, Why::Estop, Why::Disconnected, Why::Timeout]
            .into_iter()
            .find(|w| *w as u8 == v)
    }
}

/// A shared cancel flag with the first reason it was set for.
#[derive(Debug, Clone, Default)]
pub struct Cancel {
    flag: Arc<AtomicBool>,
    why: Arc<AtomicU8>,
}

impl Cancel {
    /// A token that is not cancelled.
    pub fn new() -> Self {
        Self::default()
    }

    /// Sets the flag; the first reason given is kept.
    pub fn cancel(&self, why: Why) {
        let _ = self
            .why
            .compare_exchange(0, why as u8, Ordering::AcqRel, Ordering::Acquire);
        self.flag.store(true, Ordering::Release);
    }

    /// Why it was cancelled, if it was.
    pub fn why(&self) -> Option<Why> {
        if !self.flag.load(Ordering::Acquire) {
            return None;
        }
        Why::from_u8(self.why.load(Ordering::Acquire))
    }

    /// The flag the interpreter polls (`InterpOptions::cancel`).
    pub fn flag(&self) -> Arc<AtomicBool> {
        self.flag.clone()
    }

    /// The error a preparation (`what`: "job", "MDI") cancelled for `why` answers; `budget`
    /// names the timeout.
    pub fn error(what: &str, why: Why, budget: Duration) -> ApiError {
        match why {
            Why::Timeout => ApiError::Timeout(format!(
                "{what} preparation took longer than {} s (job.prepare_timeout_s)",
                budget.as_secs_f64()
            )),
            Why::Abort => ApiError::Failed(format!("{what} preparation cancelled by job.abort")),
            Why::Estop => ApiError::Failed(format!("{what} preparation cancelled by an e-stop")),
            Why::Disconnected => ApiError::Failed(format!(
                "{what} preparation cancelled: the requesting client disconnected"
            )),
        }
    }
}

/// The token of the preparation holding the one-at-a-time lock and the machine it prepares
/// for ([`with_owner`]), for [`cancel_current`].
static CURRENT: Mutex<Option<(usize, Cancel)>> = Mutex::new(None);

thread_local! {
    static OWNER: Cell<usize> = const { Cell::new(0) };
}

/// Runs `f` with the preparations it starts on this thread registered as `owner`'s (a
/// machine's identity), so that only that machine's `estop` or `job.abort` cancels them.
/// Without it, in a process with several machines (a cell, the test binaries) one machine's
/// e-stop cancelled another's MDI line (CI caught it: `machine_api`'s e-stop test failed
/// its neighbour's `mdi M8`).
pub fn with_owner<R>(owner: usize, f: impl FnOnce() -> R) -> R {
    let previous = OWNER.with(|o| o.replace(owner));
    let out = f();
    OWNER.with(|o| o.set(previous));
    out
}

/// Cancels the preparation in progress for `owner` ([`with_owner`]), if any (`job.abort`,
/// `estop`). Preparations waiting for it are not cancelled: they were asked for after it and
/// run next.
pub fn cancel_current(owner: usize, why: Why) {
    if let Some((o, c)) = CURRENT
        .lock()
        .unwrap_or_else(PoisonError::into_inner)
        .as_ref()
    {
        if *o == owner {
            c.cancel(why);
        }
    }
}

/// Registers `token` as the preparation in progress until dropped. Call while holding the
/// one-at-a-time lock.
pub(crate) struct Current(());

impl Current {
    pub(crate) fn enter(token: &Cancel) -> Current {
        let owner = OWNER.with(Cell::get);
        *CURRENT.lock().unwrap_or_else(PoisonError::into_inner) = Some((owner, token.clone()));
        Current(())
    }
}

impl Drop for Current {
    fn drop(&mut self) {
        *CURRENT.lock().unwrap_or_else(PoisonError::into_inner) = None;
    }
}

/// Cancels a token with [`Why::Timeout`] once `budget` has passed, unless dropped first.
/// A thread of its own that sleeps on a channel: the interpreter only polls a flag.
pub(crate) struct Budget {
    stop: Option<mpsc::Sender<()>>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Budget {
    pub(crate) fn start(token: &Cancel, budget: Duration) -> Budget {
        let (stop, rx) = mpsc::channel::<()>();
        let token = token.clone();
        let thread = std::thread::Builder::new()
            .name("job-budget".into())
            .spawn(move || {
                if let Err(mpsc::RecvTimeoutError::Timeout) = rx.recv_timeout(budget) {
                    token.cancel(Why::Timeout);
                }
            });
        match thread {
            Ok(t) => Budget {
                stop: Some(stop),
                thread: Some(t),
            },
            Err(e) => {
                // No timer thread: the preparation runs unbudgeted, still cancellable.
                tracing::warn!("cannot start the job preparation timer: {e}");
                Budget {
                    stop: None,
                    thread: None,
                }
            }
        }
    }
}

impl Drop for Budget {
    fn drop(&mut self) {
        drop(self.stop.take());
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// Runs the preparation `f` (`what`: "job", "MDI") one at a time under `lock`, with this
/// thread's request token ([`request_token`]) registered as the current one and `budget`
/// running. `f` polls the token it is given; a failure after a cancel answers the cancel's
/// reason, not the interpreter's "cancelled". A preparation that ends after its cancel
/// (a block or a plan is not cut in the middle) is refused too: an MDI line planned while
/// `job.abort` came must not start moving afterwards.
pub(crate) fn guarded<T>(
    lock: &Mutex<()>,
    what: &str,
    budget: Duration,
    f: impl FnOnce(&Cancel) -> Result<T, ApiError>,
) -> Result<T, ApiError> {
    let token = request_token();
    let _one_at_a_time = lock.lock().unwrap_or_else(PoisonError::into_inner);
    let _current = Current::enter(&token);
    if let Some(why) = token.why() {
        return Err(Cancel::error(what, why, budget));
    }
    let _budget = Budget::start(&token, budget);
    let out = f(&token);
    match token.why() {
        Some(why) => Err(Cancel::error(what, why, budget)),
        None => out,
    }
}

thread_local! {
    static REQUEST: RefCell<Option<Cancel>> = const { RefCell::new(None) };
}

/// Runs `f` with `token` as the cancel token of any preparation it starts on this thread
/// (the control server: set when the requesting client disconnects).
pub fn with_request_token<R>(token: &Cancel, f: impl FnOnce() -> R) -> R {
    let previous = REQUEST.with(|r| r.replace(Some(token.clone())));
    let out = f();
    REQUEST.with(|r| *r.borrow_mut() = previous);
    out
}

/// The token for a preparation starting on this thread: the request's, or a fresh one.
pub(crate) fn request_token() -> Cancel {
    REQUEST.with(|r| r.borrow().clone()).unwrap_or_default()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_first_reason_is_kept_and_a_budget_fires_only_when_it_runs_out() {
        let c = Cancel::new();
        assert_eq!(c.why(), None);
        c.cancel(Why::Abort);
        c.cancel(Why::Timeout);
        assert_eq!(c.why(), Some(Why::Abort));
        // Dropped before its time: never fires.
        let c = Cancel::new();
        drop(Budget::start(&c, Duration::from_secs(3600)));
        assert_eq!(c.why(), None);
        // A zero budget fires at once (hang guard 60 s).
        let c = Cancel::new();
        let _b = Budget::start(&c, Duration::ZERO);
        let t0 = std::time::Instant::now();
        while c.why().is_none() {
            assert!(t0.elapsed() < Duration::from_secs(60), "budget never fired");
            std::thread::sleep(Duration::from_millis(5));
        }
        assert_eq!(c.why(), Some(Why::Timeout));
        let msg = Cancel::error("job", Why::Timeout, Duration::from_secs(30)).to_string();
        assert!(
            msg.contains("longer than 30 s (job.prepare_timeout_s)"),
            "{msg}"
        );
    }
}
