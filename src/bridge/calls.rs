//! Running remote calls off the query thread: a small pool of call workers and one deadline
//! watcher, so that a call costs a hand-over to a waiting thread, not the start of new threads
//! (two threads per call cost about 1 ms of a ~2.5 ms round trip, see benches/README.md).
//!
//! - The pool starts with [`START_WORKERS`] threads and grows by one whenever more calls are
//!   running than it has workers, up to the limit of calls at once; its threads stay until
//!   the bridge stops. So a slow operation still delays only its own reply: every running
//!   call has a worker of its own, and a call beyond the limit is rejected "busy".
//! - The deadline watcher answers "timeout" for a call without a final status past the call
//!   timeout. It sleeps until the earliest deadline; a new call wakes it only when its
//!   deadline comes before that (with one timeout for all calls: only the first call after an
//!   idle spell), so the common call costs it nothing.
//!
//! Whichever of worker and watcher takes the reply from the call's [`Slot`] first answers;
//! the other finds it empty. A worker whose call timed out finishes the call (a command
//! already queued to a task is not withdrawn) and drops its result.

use super::BridgeError;
use serde_json::Value;
use std::cmp::Ordering as CmpOrdering;
use std::collections::BinaryHeap;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{mpsc, Arc, Condvar, Mutex, MutexGuard, PoisonError};
use std::time::{Duration, Instant};

/// Workers started with the pool: enough for a caller and a concurrent e-stop.
pub const START_WORKERS: usize = 2;

/// Where a call's final answer goes (a Zenoh query in the bridge).
pub trait Reply: Send + 'static {
    /// Sends `r`: `Ok` the reply payload, `Err` the error reply payload.
    fn send(self, r: Result<Value, Value>);
}

/// Runs a call: method name and parameters to the reply payload or the error reply payload.
pub type Runner = Arc<dyn Fn(&str, Value) -> Result<Value, Value> + Send + Sync>;

/// A call's reply, taken by whoever answers first.
struct Slot<R>(Mutex<Option<R>>);

impl<R> Slot<R> {
    fn take(&self) -> Option<R> {
        lock(&self.0).take()
    }
}

struct Job<R> {
    method: String,
    params: Value,
    slot: Arc<Slot<R>>,
}

/// Why [`Calls::submit`] did not take a call; the reply is handed back to be answered.
pub struct Refused<R> {
    /// The reply of the refused call.
    pub reply: R,
    /// Calls running at once (the limit reached).
    pub running: usize,
}

/// The call workers and the deadline watcher of one bridge.
pub struct Calls<R: Reply> {
    run: Runner,
    jobs: Option<mpsc::Sender<Job<R>>>,
    queue: Arc<Mutex<mpsc::Receiver<Job<R>>>>,
    workers: usize,
    max: usize,
    /// Calls accepted whose worker has not finished them.
    running: Arc<AtomicUsize>,
    timeout: Duration,
    deadlines: Arc<Deadlines<R>>,
}

impl<R: Reply> Calls<R> {
    /// A pool running calls with `run`, at most `max` at once, each answered "timeout" after
    /// `timeout` without a final status.
    pub fn start(run: Runner, max: usize, timeout: Duration) -> Result<Calls<R>, BridgeError> {
        let (tx, rx) = mpsc::channel();
        let deadlines = Arc::new(Deadlines {
            state: Mutex::new(Watch {
                heap: BinaryHeap::new(),
                planned: None,
                stop: false,
            }),
            wake: Condvar::new(),
        });
        let d = deadlines.clone();
        spawn("zenoh-deadline", move || d.watch(timeout))?;
        let mut calls = Calls {
            run,
            jobs: Some(tx),
            queue: Arc::new(Mutex::new(rx)),
            workers: 0,
            max: max.max(1),
            running: Arc::new(AtomicUsize::new(0)),
            timeout,
            deadlines,
        };
        for _ in 0..START_WORKERS.min(calls.max) {
            calls.add_worker()?;
        }
        Ok(calls)
    }

    /// Worker threads started so far.
    pub fn workers(&self) -> usize {
        self.workers
    }

    /// Runs `method` with `params` on a worker; `reply` gets its result or the timeout.
    pub fn submit(&mut self, reply: R, method: String, params: Value) -> Result<(), Refused<R>> {
        let running = self.running.fetch_add(1, Ordering::AcqRel) + 1;
        if running > self.max {
            self.running.fetch_sub(1, Ordering::AcqRel);
            return Err(Refused {
                reply,
                running: self.max,
            });
        }
        if running > self.workers {
            // Every running call gets a worker; if none can be started the call waits for one.
            if let Err(e) = self.add_worker() {
                tracing::warn!("zenoh: {e}");
            }
        }
        let slot = Arc::new(Slot(Mutex::new(Some(reply))));
        self.deadlines
            .add(Instant::now() + self.timeout, slot.clone());
        let job = Job {
            method,
            params,
            slot,
        };
        if let Some(Err(mpsc::SendError(job))) = self.jobs.as_ref().map(|j| j.send(job)) {
            // No worker left (all panicked): answer rather than leave the caller waiting.
            self.running.fetch_sub(1, Ordering::AcqRel);
            if let Some(r) = job.slot.take() {
                r.send(Err(super::codec::failure(
                    "failed",
                    "no call worker running",
                )));
            }
        }
        Ok(())
    }

    fn add_worker(&mut self) -> Result<(), BridgeError> {
        let (queue, run, running) = (self.queue.clone(), self.run.clone(), self.running.clone());
        spawn("zenoh-call", move || loop {
            // One idle worker waits in `recv`, the others for the lock: either way asleep.
            let job = lock(&queue).recv();
            let Ok(job) = job else { break };
            let r = run(&job.method, job.params);
            // Counted out before answering, so a caller told the result may call again.
            running.fetch_sub(1, Ordering::AcqRel);
            if let Some(reply) = job.slot.take() {
                reply.send(r);
            }
        })?;
        self.workers += 1;
        Ok(())
    }
}

impl<R: Reply> Drop for Calls<R> {
    /// Idle workers end when the job channel closes; a worker inside a call ends after it.
    fn drop(&mut self) {
        self.jobs = None;
        lock(&self.deadlines.state).stop = true;
        self.deadlines.wake.notify_all();
    }
}

struct Deadlines<R> {
    state: Mutex<Watch<R>>,
    wake: Condvar,
}

struct Watch<R> {
    heap: BinaryHeap<Deadline<R>>,
    /// When the watcher wakes next (`None`: when told).
    planned: Option<Instant>,
    stop: bool,
}

struct Deadline<R> {
    at: Instant,
    slot: Arc<Slot<R>>,
}

impl<R> PartialEq for Deadline<R> {
    fn eq(&self, other: &Self) -> bool {
        self.at == other.at
    }
}
impl<R> Eq for Deadline<R> {}
impl<R> PartialOrd for Deadline<R> {
    fn partial_cmp(&self, other: &Self) -> Option<CmpOrdering> {
        Some(self.cmp(other))
    }
}
impl<R> Ord for Deadline<R> {
    /// Reversed: the max-heap's top is the earliest deadline.
    fn cmp(&self, other: &Self) -> CmpOrdering {
        other.at.cmp(&self.at)
    }
}

impl<R: Reply> Deadlines<R> {
    fn add(&self, at: Instant, slot: Arc<Slot<R>>) {
        let mut st = lock(&self.state);
        st.heap.push(Deadline { at, slot });
        if st.planned.is_none_or(|p| at < p) {
            st.planned = Some(at);
            self.wake.notify_one();
        }
    }

    fn watch(&self, timeout: Duration) {
        let mut expired = Vec::new();
        let mut st = lock(&self.state);
        while !st.stop {
            let now = Instant::now();
            while st.heap.peek().is_some_and(|d| d.at <= now) {
                if let Some(d) = st.heap.pop() {
                    expired.push(d.slot);
                }
            }
            if !expired.is_empty() {
                drop(st);
                for slot in expired.drain(..) {
                    if let Some(reply) = slot.take() {
                        reply.send(Err(super::codec::failure(
                            "timeout",
                            format!("no final status within {:.1} s", timeout.as_secs_f64()),
                        )));
                    }
                }
                st = lock(&self.state);
                continue;
            }
            let planned = st.heap.peek().map(|d| d.at);
            st.planned = planned;
            st = match planned {
                Some(at) => {
                    self.wake
                        .wait_timeout(st, at.saturating_duration_since(now))
                        .unwrap_or_else(PoisonError::into_inner)
                        .0
                }
                None => self.wake.wait(st).unwrap_or_else(PoisonError::into_inner),
            };
        }
    }
}

fn spawn(name: &str, f: impl FnOnce() + Send + 'static) -> Result<(), BridgeError> {
    std::thread::Builder::new()
        .name(name.into())
        .spawn(f)
        .map(drop)
        .map_err(|e| BridgeError::Zenoh(format!("cannot start thread {name}: {e}")))
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(PoisonError::into_inner)
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;
    use std::sync::mpsc::{channel, Receiver, Sender};

    /// A reply that reports (call id, answer) on a channel.
    struct Probe(u32, Sender<(u32, Result<Value, Value>)>);

    impl Reply for Probe {
        fn send(self, r: Result<Value, Value>) {
            let _ = self.1.send((self.0, r));
        }
    }

    /// Calls named "block" wait until the returned sender says go; others answer at once.
    fn runner() -> (Runner, Sender<()>) {
        let (go, gate) = channel::<()>();
        let gate = Mutex::new(gate);
        let run: Runner = Arc::new(move |method: &str, params: Value| {
            if method == "block" {
                let _ = lock(&gate).recv();
            }
            Ok(json!({"method": method, "params": params}))
        });
        (run, go)
    }

    const HANG: Duration = Duration::from_secs(60);

    fn next(rx: &Receiver<(u32, Result<Value, Value>)>) -> (u32, Result<Value, Value>) {
        rx.recv_timeout(HANG).expect("a reply")
    }

    #[test]
    fn sequential_calls_reuse_the_workers_and_each_gets_its_result() {
        let (run, _go) = runner();
        let mut calls = Calls::start(run, 16, HANG).unwrap();
        let (tx, rx) = channel();
        for i in 0..100 {
            calls
                .submit(Probe(i, tx.clone()), "m".into(), json!(i))
                .map_err(|_| "refused")
                .unwrap();
            let (id, r) = next(&rx);
            assert_eq!(id, i);
            assert_eq!(r.unwrap()["params"], json!(i));
        }
        assert_eq!(calls.workers(), START_WORKERS, "no thread per call");
    }

    #[test]
    fn a_blocked_call_delays_only_itself_and_times_out_once() {
        let (run, go) = runner();
        let mut calls = Calls::start(run, 16, Duration::from_millis(1)).unwrap();
        let (tx, rx) = channel();
        for i in 0..3 {
            assert!(calls
                .submit(Probe(i, tx.clone()), "block".into(), json!(i))
                .is_ok());
        }
        // Three blocked calls: three timeouts, a worker each (the pool grew past its start).
        let mut timed_out: Vec<u32> = (0..3)
            .map(|_| {
                let (id, r) = next(&rx);
                assert_eq!(r.unwrap_err()["status"], "timeout");
                id
            })
            .collect();
        timed_out.sort_unstable();
        assert_eq!(timed_out, [0, 1, 2]);
        assert_eq!(calls.workers(), 3);
        for _ in 0..3 {
            go.send(()).unwrap();
        }
        // A later call is answered by its own result (a 1 ms timeout may beat it on a loaded
        // host: either answer, exactly one), and the finished blocked calls answer nothing.
        assert!(calls
            .submit(Probe(9, tx.clone()), "m".into(), json!(9))
            .is_ok());
        let (id, r) = next(&rx);
        assert_eq!(id, 9);
        if let Err(e) = r {
            assert_eq!(e["status"], "timeout");
        }
        drop((calls, tx));
        assert!(rx.recv_timeout(HANG).is_err(), "a second answer");
    }

    #[test]
    fn calls_beyond_the_limit_are_refused_and_a_slow_one_does_not_hold_a_fast_one() {
        let (run, go) = runner();
        let mut calls = Calls::start(run, 2, HANG).unwrap();
        let (tx, rx) = channel();
        assert!(calls
            .submit(Probe(1, tx.clone()), "block".into(), json!(1))
            .is_ok());
        assert!(calls
            .submit(Probe(2, tx.clone()), "block".into(), json!(2))
            .is_ok());
        let refused = calls.submit(Probe(3, tx.clone()), "m".into(), json!(3));
        assert!(matches!(refused, Err(Refused { running: 2, .. })));
        go.send(()).unwrap();
        let (first, r) = next(&rx);
        assert!(r.is_ok() && (first == 1 || first == 2));
        // One worker free again: a fast call passes the one still blocked.
        assert!(calls
            .submit(Probe(4, tx.clone()), "m".into(), json!(4))
            .is_ok());
        let (id, r) = next(&rx);
        assert_eq!((id, r.unwrap()["params"].clone()), (4, json!(4)));
        go.send(()).unwrap();
        let (last, r) = next(&rx);
        assert!(r.is_ok() && last == 3 - first);
        assert_eq!(calls.workers(), 2);
    }
}
