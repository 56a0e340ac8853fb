//! The import side of the bridge: a task of another process or host as a local peer.
//!
//! A [`RemoteLink`] is one `[[remote]]` (`config::remote`) on an open session: at configure
//! time it fetches the remote's task list (`hytask/<machine>/tasks`, what `hytask tasks`
//! prints) and checks every name the local tasks need, so a missing remote task, operation,
//! event or port is refused by name before anything starts; no answer within `timeout_s` is
//! refused too. It also watches the remote's liveliness token (`hytask/<machine>/alive`):
//! when Zenoh withdraws it (the process died, the link broke), the remote is *lost*.
//!
//! A [`RemoteProxy`] is an ordinary local task standing for one remote task, added to the
//! deployment under the name local peers use (`peer_commands::<C>("camera")` works as for
//! a local camera). The realtime side only meets lock-free primitives:
//! - a command accepted by the proxy goes through a lock-free buffer to the proxy's worker
//!   thread (parked while idle, unparked by the accept), which calls
//!   `hytask/<machine>/<task>/op/<name>` and stores the final status in atomics; the
//!   proxy's completion condition reads them. Accept means "forwarded": a
//!   remote rejection, failure, timeout or loss makes the command *fail* with a fixed
//!   text (the remote's own message is logged and kept in [`RemoteLink::last_error`]);
//! - remote events arrive through a Zenoh subscriber into a lock-free buffer, and the proxy
//!   emits them as local events `<proxy>.<name>` (local subscribers see deferred events);
//! - remote data-object ports arrive the same way and the proxy writes them to a local data
//!   object (latest value wins);
//! - local inputs given with [`RemoteProxy::forward`] are published under
//!   `hytask/<local>/<proxy>/port/<object>` right before each call, on the same session, so
//!   the remote has them before it runs the operation (Zenoh keeps the order of one link).
//!
//! A slow or vanished remote delays only the proxy's own commands: they fail after
//! `timeout_s`, or at once when the remote is lost under them (the call was sent, or the
//! remote was there when it was accepted). A `critical` remote also calls the hook given to
//! [`RemoteLink::on_lost`] (the host stops its machine safely there) and the proxy emits
//! `<proxy>.peer_lost`.
//!
//! A command accepted while the remote is lost waits for it, up to `timeout_s`: a restarted
//! peer process is back once its liveliness token arrives, which can be a little after the
//! process answers. Only then is the call sent; a remote not back by then fails the command
//! and the loss hook is called again with an error naming the remote (`critical` false: the
//! stop, if any, happened at the loss). Callers such as the cell's selection need not know
//! whether the peer was seen back yet.
//!
//! Operations are forwarded one at a time, in order (the worker runs one call after the
//! other): the proxied command type should use `NextCommand::AfterCompletion`.

use super::{codec, keys};
use crate::config::remote::RemoteConfig;
use crate::machine::api::TaskInfo as RemoteTask;
use crate::rt::prelude::*;
use serde::de::DeserializeOwned;
use serde::Serialize;
use serde_json::Value;
use std::marker::PhantomData;
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicU8, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use zenoh::bytes::Encoding;
use zenoh::sample::SampleKind;
use zenoh::Wait;

/// A command type a proxy can forward: its arguments as the JSON object the remote's
/// `op/<name>` queryable takes (by parameter name, as for the `call` method). `Clone`: the
/// proxy hands a copy to its worker thread.
pub trait RemoteCommand: Commands + Clone {
    /// The arguments of this command.
    fn remote_args(&self) -> Value;
}

/// Why a remote peer cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum RemoteError {
    /// No answer to the task-list query within the timeout.
    #[error("remote peer '{remote}' ({key}): no answer within {timeout_s} s (is it running and reachable?)")]
    Unreachable {
        /// `[[remote]] name`.
        remote: String,
        /// The key queried.
        key: String,
        /// `timeout_s`.
        timeout_s: f64,
    },
    /// A task, operation, event or port the local side needs is not there.
    #[error("remote peer '{remote}': {what}")]
    Missing {
        /// `[[remote]] name`.
        remote: String,
        /// What is missing, by name.
        what: String,
    },
    /// Zenoh refused (declaring a subscriber).
    #[error("remote peer '{remote}': zenoh: {message}")]
    Zenoh {
        /// `[[remote]] name`.
        remote: String,
        /// Zenoh's message.
        message: String,
    },
}

/// The liveliness token key of machine (or peer) `m`.
pub fn alive_key(m: &str) -> String {
    format!("{}/alive", keys::machine(m))
}

/// Declares this process's liveliness token as `m` (keep it as long as the process serves).
pub fn declare_alive(
    session: &zenoh::Session,
    m: &str,
) -> Result<zenoh::liveliness::LivelinessToken, super::BridgeError> {
    session
        .liveliness()
        .declare_token(alive_key(m))
        .wait()
        .map_err(|e| super::BridgeError::Zenoh(format!("liveliness token: {e}")))
}

type LostHook = Box<dyn Fn(&str, bool) + Send + Sync>;

struct LinkShared {
    session: zenoh::Session,
    cfg: RemoteConfig,
    alive: AtomicBool,
    /// Times the remote was lost (proxies emit `peer_lost` when it grows).
    losses: AtomicU64,
    on_lost: Mutex<Option<LostHook>>,
    last_error: Mutex<String>,
    tasks: Vec<RemoteTask>,
}

/// One remote peer on an open session (cheap to clone).
#[derive(Clone)]
pub struct RemoteLink {
    inner: Arc<LinkShared>,
    _liveliness: Arc<zenoh::pubsub::Subscriber<()>>,
}

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

impl RemoteLink {
    /// Reaches the remote of `cfg`: its task list (if `cfg.check`), within `timeout_s`, and
    /// a watch on its liveliness token.
    pub fn connect(session: &zenoh::Session, cfg: &RemoteConfig) -> Result<Self, RemoteError> {
        let timeout = Duration::from_secs_f64(cfg.timeout_s);
        let tasks = if cfg.check {
            fetch_tasks(session, cfg, timeout)?
        } else {
            Vec::new()
        };
        let inner = Arc::new(LinkShared {
            session: session.clone(),
            cfg: cfg.clone(),
            alive: AtomicBool::new(true),
            losses: AtomicU64::new(0),
            on_lost: Mutex::new(None),
            last_error: Mutex::new(String::new()),
            tasks,
        });
        let watch = Arc::downgrade(&inner);
        let sub = session
            .liveliness()
            .declare_subscriber(alive_key(cfg.machine()))
            .history(true)
            .callback(move |s| {
                if let Some(l) = watch.upgrade() {
                    l.liveliness(s.kind() == SampleKind::Put);
                }
            })
            .wait()
            .map_err(|e| RemoteError::Zenoh {
                remote: cfg.name.clone(),
                message: e.to_string(),
            })?;
        Ok(Self {
            inner,
            _liveliness: Arc::new(sub),
        })
    }

    /// `[[remote]] name`.
    pub fn name(&self) -> &str {
        &self.inner.cfg.name
    }

    /// False once its liveliness token was withdrawn (until it is declared again).
    pub fn alive(&self) -> bool {
        self.inner.alive.load(Ordering::Acquire)
    }

    /// The last remote error (rejection, failure, timeout, loss), with the remote's words.
    pub fn last_error(&self) -> String {
        lock(&self.inner.last_error).clone()
    }

    /// Runs `hook(message, critical)` (on a Zenoh thread) each time the remote is lost:
    /// report it there, and stop the machine safely when `critical` (`[[remote]] critical`).
    /// Also called (on a proxy's worker, `critical` false) when a command accepted while the
    /// remote was lost gives up waiting for it after `timeout_s`.
    pub fn on_lost(&self, hook: impl Fn(&str, bool) + Send + Sync + 'static) {
        *lock(&self.inner.on_lost) = Some(Box::new(hook));
    }

    /// Checks that remote task `task` exists with these operations, events (short names)
    /// and ports (objects); every missing one is named. Passes when `check = false`.
    pub fn require(
        &self,
        task: &str,
        ops: &[&str],
        events: &[&str],
        ports: &[&str],
    ) -> Result<(), RemoteError> {
        if !self.inner.cfg.check {
            return Ok(());
        }
        let missing = |what: String| RemoteError::Missing {
            remote: self.name().to_owned(),
            what,
        };
        let t = self
            .inner
            .tasks
            .iter()
            .find(|t| t.name == task)
            .ok_or_else(|| {
                let known: Vec<&str> = self.inner.tasks.iter().map(|t| t.name.as_str()).collect();
                missing(format!("no task '{task}' (it has {known:?})"))
            })?;
        let mut gaps = Vec::new();
        for op in ops {
            if !t.operations.iter().any(|o| o.name == *op) {
                gaps.push(format!("operation '{task}.{op}'"));
            }
        }
        for ev in events {
            if !t.events.iter().any(|e| *e == format!("{task}.{ev}")) {
                gaps.push(format!("event '{task}.{ev}'"));
            }
        }
        for p in ports {
            if !t
                .ports
                .iter()
                .any(|q| q.rsplit_once(' ').map(|x| x.1) == Some(*p))
            {
                gaps.push(format!("port '{p}' of task '{task}'"));
            }
        }
        if gaps.is_empty() {
            Ok(())
        } else {
            Err(missing(format!("no {}", gaps.join(", no "))))
        }
    }
}

impl LinkShared {
    fn liveliness(&self, up: bool) {
        let was = self.alive.swap(up, Ordering::AcqRel);
        if up && !was {
            tracing::warn!("remote peer '{}' is back", self.cfg.name);
        }
        if !up && was {
            self.losses.fetch_add(1, Ordering::AcqRel);
            let msg = format!(
                "remote peer '{}' (hytask/{}) lost: its liveliness token was withdrawn",
                self.cfg.name,
                self.cfg.machine()
            );
            tracing::error!("{msg}");
            if let Some(h) = &*lock(&self.on_lost) {
                h(&msg, self.cfg.critical);
            }
            *lock(&self.last_error) = msg;
        }
    }

    fn fail(&self, msg: String) {
        tracing::warn!("{msg}");
        *lock(&self.last_error) = msg;
    }

    /// Waits until the remote is alive, up to `timeout` or until `stop` (a worker thread,
    /// never realtime); false if it is not back by then.
    fn wait_alive(&self, timeout: Duration, stop: &AtomicBool) -> bool {
        let t0 = Instant::now();
        while !self.alive.load(Ordering::Acquire) {
            if t0.elapsed() >= timeout || stop.load(Ordering::Acquire) {
                return false;
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        true
    }

    /// A command gave up waiting for the remote: logged, kept, and reported through the
    /// loss hook (not critical: the loss itself already was).
    fn not_back(&self, what: &str) {
        let msg = format!(
            "{what}: remote peer '{}' (hytask/{}) lost and not back within timeout_s = {} s",
            self.cfg.name,
            self.cfg.machine(),
            self.cfg.timeout_s
        );
        self.fail(msg.clone());
        if let Some(h) = &*lock(&self.on_lost) {
            h(&msg, false);
        }
    }
}

fn fetch_tasks(
    session: &zenoh::Session,
    cfg: &RemoteConfig,
    timeout: Duration,
) -> Result<Vec<RemoteTask>, RemoteError> {
    let key = keys::tasks(cfg.machine());
    let t0 = Instant::now();
    // The remote may still be starting, or the link still forming: ask again until the
    // timeout (a query nobody answers ends at once).
    while t0.elapsed() < timeout {
        let left = timeout.saturating_sub(t0.elapsed());
        if let Ok(replies) = session.get(key.as_str()).timeout(left).wait() {
            if let Ok(reply) = replies.recv() {
                let parsed = match reply.result() {
                    Ok(s) => codec::decode(Some(s.payload().to_bytes().as_ref())),
                    Err(e) => Err(String::from_utf8_lossy(&e.payload().to_bytes()).into()),
                };
                let list = parsed.and_then(|v| {
                    serde_json::from_value::<Vec<RemoteTask>>(v["result"].clone())
                        .map_err(|e| e.to_string())
                });
                return list.map_err(|e| RemoteError::Missing {
                    remote: cfg.name.clone(),
                    what: format!("unreadable task list on {key}: {e}"),
                });
            }
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    Err(RemoteError::Unreachable {
        remote: cfg.name.clone(),
        key,
        timeout_s: cfg.timeout_s,
    })
}

/// Final status of a forwarded call.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
enum Outcome {
    Done = 1,
    Rejected,
    Failed,
    Timeout,
    Unreachable,
    Lost,
    NotBack,
}

impl Outcome {
    fn from_u8(v: u8) -> Option<Self> {
        [
            Self::Done,
            Self::Rejected,
            Self::Failed,
            Self::Timeout,
            Self::Unreachable,
            Self::Lost,
            Self::NotBack,
        ]
        .into_iter()
        .find(|o| *o as u8 == v)
    }

    /// The command's final status (fixed texts: the realtime side never formats).
    fn progress(self) -> Progress {
        match self {
            Self::Done => Progress::Done,
            Self::Rejected => Progress::Failed("remote peer rejected the operation"),
            Self::Failed => Progress::Failed("remote operation failed"),
            Self::Timeout => Progress::Failed("remote peer: no final status within timeout_s"),
            Self::Unreachable => Progress::Failed("remote peer unreachable"),
            Self::Lost => Progress::Failed("remote peer lost"),
            Self::NotBack => Progress::Failed("remote peer lost and not back within timeout_s"),
        }
    }
}

/// The worker's answer for call `seq`: `outcome` is written before `seq` (release).
#[derive(Default)]
struct Results {
    seq: AtomicU64,
    outcome: AtomicU8,
}

/// Moves remote values into a local primitive, in the proxy's step.
trait Pump: Send {
    fn pump(&mut self);
    fn pending(&self) -> bool;
}

struct EventPump<T> {
    rx: BufferReader<T>,
    src: EventSource<T>,
}

impl<T: Clone + Send + 'static> Pump for EventPump<T> {
    fn pump(&mut self) {
        let src = &mut self.src;
        self.rx.drain(|v| src.emit(v));
    }
    fn pending(&self) -> bool {
        !self.rx.is_empty()
    }
}

struct PortPump<T> {
    rx: BufferReader<T>,
    out: DataWriter<T>,
}

impl<T: Clone + Default + Send + Sync + 'static> Pump for PortPump<T> {
    fn pump(&mut self) {
        let out = &mut self.out;
        self.rx.drain(|v| out.set(v));
    }
    fn pending(&self) -> bool {
        !self.rx.is_empty()
    }
}

/// Publishes a local input before each call.
trait Forward: Send {
    fn publish(&mut self, session: &zenoh::Session);
}

struct PortForward<T> {
    key: String,
    reader: DataReader<T>,
}

impl<T: Clone + Default + Send + Sync + Serialize + 'static> Forward for PortForward<T> {
    fn publish(&mut self, session: &zenoh::Session) {
        if let Some(v) = self.reader.latest() {
            let bytes = serde_json::to_vec(&v).unwrap_or_default();
            if let Err(e) = session
                .put(&self.key, bytes)
                .encoding(Encoding::APPLICATION_JSON)
                .wait()
            {
                tracing::warn!("zenoh: cannot publish {}: {e}", self.key);
            }
        }
    }
}

type Subscribers = Vec<zenoh::pubsub::Subscriber<()>>;
type ImportFn = Box<
    dyn FnOnce(&mut Configure<'_>, &RemoteLink, &mut Subscribers) -> Result<Box<dyn Pump>, String>
        + Send,
>;
type ForwardFn = Box<dyn FnOnce(&mut Configure<'_>, &str) -> Box<dyn Forward> + Send>;

/// A call handed to the worker: its sequence number, the command, and the link as the
/// proxy saw it when it accepted the command.
struct Call<C> {
    seq: u64,
    cmd: C,
    seen: LinkSeen,
}

/// The link at a command's acceptance: a call made for a remote that was there must not be
/// sent to (or wait for) a later incarnation of it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct LinkSeen {
    /// The remote was alive.
    alive: bool,
    /// Its loss count.
    losses: u64,
}

impl LinkSeen {
    fn now(link: &LinkShared) -> Self {
        // Losses first: a loss between the two loads then shows as a changed count.
        let losses = link.losses.load(Ordering::Acquire);
        Self {
            alive: link.alive.load(Ordering::Acquire),
            losses,
        }
    }

    /// The remote was lost under this call: it was there at acceptance and is gone now, or
    /// it was lost again since.
    fn lost_since(&self, link: &LinkShared) -> bool {
        let now = Self::now(link);
        now.losses != self.losses || (self.alive && !now.alive)
    }
}

/// Queued calls between the proxy's step and its worker.
const CALL_QUEUE: usize = 16;
/// Remote values queued between two steps of the proxy.
const IMPORT_QUEUE: usize = 64;

/// A local task standing for remote task `<remote>/<task>` (see the module doc).
pub struct RemoteProxy<C: RemoteCommand> {
    link: RemoteLink,
    remote_task: String,
    local_machine: String,
    imports: Vec<ImportFn>,
    forwards: Vec<ForwardFn>,
    pumps: Vec<Box<dyn Pump>>,
    subscribers: Subscribers,
    calls: BufferWriter<Call<C>>,
    calls_rx: Option<BufferReader<Call<C>>>,
    results: Arc<Results>,
    next_seq: u64,
    /// The call in progress and the link as it was when it was accepted.
    waiting: Option<(u64, LinkSeen)>,
    losses_seen: u64,
    lost_event: Option<EventSource<u32>>,
    stop: Arc<AtomicBool>,
    /// The worker, parked while it has no call: [`Task::accept`] unparks it (an atomic swap
    /// and, if it sleeps, one futex wake: no allocation, lock or blocking on the realtime
    /// thread).
    worker: Option<std::thread::Thread>,
    _c: PhantomData<fn() -> C>,
}

impl<C: RemoteCommand> RemoteProxy<C> {
    /// A proxy of `remote_task` on `link`; `local_machine` names this side's key (for
    /// forwarded ports). Checks that the remote task has every operation of `C`.
    pub fn new(
        link: &RemoteLink,
        remote_task: &str,
        local_machine: &str,
    ) -> Result<Self, RemoteError> {
        let ops: Vec<&str> = C::operations().iter().map(|o| o.name).collect();
        link.require(remote_task, &ops, &[], &[])?;
        let (calls, calls_rx) = buffer(CALL_QUEUE, FullPolicy::DropNewest);
        Ok(Self {
            link: link.clone(),
            remote_task: remote_task.to_owned(),
            local_machine: local_machine.to_owned(),
            imports: Vec::new(),
            forwards: Vec::new(),
            pumps: Vec::new(),
            subscribers: Vec::new(),
            calls,
            calls_rx: Some(calls_rx),
            results: Arc::default(),
            next_seq: 0,
            waiting: None,
            losses_seen: 0,
            lost_event: None,
            stop: Arc::new(AtomicBool::new(false)),
            worker: None,
            _c: PhantomData,
        })
    }

    /// Imports remote event `<task>.<name>` as local event `<proxy>.<name>` (checked by name).
    pub fn event<T>(mut self, name: &str) -> Result<Self, RemoteError>
    where
        T: Clone + Send + DeserializeOwned + 'static,
    {
        self.link.require(&self.remote_task, &[], &[name], &[])?;
        let name = name.to_owned();
        let task = self.remote_task.clone();
        self.imports.push(Box::new(move |ctx, link, subs| {
            let key = keys::event(link.inner.cfg.machine(), &task, &name);
            let src = ctx.event::<T>(&name);
            let rx = subscribe::<T>(link, &key, subs)?;
            Ok(Box::new(EventPump { rx, src }) as Box<dyn Pump>)
        }));
        Ok(self)
    }

    /// Imports the remote task's data-object port `object` as a local output of the proxy
    /// (same object name; checked by name).
    pub fn port<T>(mut self, object: &str) -> Result<Self, RemoteError>
    where
        T: Clone + Default + Send + Sync + DeserializeOwned + 'static,
    {
        self.link.require(&self.remote_task, &[], &[], &[object])?;
        let object = object.to_owned();
        let task = self.remote_task.clone();
        self.imports.push(Box::new(move |ctx, link, subs| {
            let key = keys::port(link.inner.cfg.machine(), &task, &object);
            let out = ctx.output::<T>(&object);
            let rx = subscribe::<T>(link, &key, subs)?;
            Ok(Box::new(PortPump { rx, out }) as Box<dyn Pump>)
        }));
        Ok(self)
    }

    /// Reads local data object `object` (an input of the proxy) and publishes its latest
    /// value under `hytask/<local>/<proxy>/port/<object>` before each forwarded call.
    pub fn forward<T>(mut self, object: &str) -> Self
    where
        T: Clone + Default + Send + Sync + Serialize + 'static,
    {
        let object = object.to_owned();
        let m = self.local_machine.clone();
        self.forwards.push(Box::new(move |ctx, proxy| {
            Box::new(PortForward::<T> {
                key: keys::port(&m, proxy, &object),
                reader: ctx.input::<T>(&object),
            }) as Box<dyn Forward>
        }));
        self
    }

    fn start_worker(&mut self, forwards: Vec<Box<dyn Forward>>) -> Result<(), TaskError> {
        let Some(mut rx) = self.calls_rx.take() else {
            return Ok(());
        };
        let link = self.link.clone();
        let results = self.results.clone();
        let stop = self.stop.clone();
        let task = self.remote_task.clone();
        let mut forwards = forwards;
        let worker = std::thread::Builder::new()
            .name(format!("zenoh-remote-{}", link.name()))
            .spawn(move || {
                while !stop.load(Ordering::Acquire) {
                    let Some(c) = rx.pop() else {
                        // Until `accept` (or drop) unparks it. A call pushed between the
                        // `pop` and here left the unpark token set, so `park` returns at
                        // once: no call waits for a later one. A spurious return loops.
                        std::thread::park();
                        continue;
                    };
                    let outcome = match reach(&link, &task, &c, &stop) {
                        Ok(()) => {
                            for f in &mut forwards {
                                f.publish(&link.inner.session);
                            }
                            call(&link, &task, &c.cmd)
                        }
                        Err(o) => o,
                    };
                    results.outcome.store(outcome as u8, Ordering::Relaxed);
                    results.seq.store(c.seq, Ordering::Release);
                }
            })
            .map_err(|_| TaskError::Fatal("cannot start the remote proxy's worker thread"))?;
        self.worker = Some(worker.thread().clone());
        Ok(())
    }
}

impl<C: RemoteCommand> Drop for RemoteProxy<C> {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Release);
        if let Some(w) = &self.worker {
            w.unpark();
        }
    }
}

fn subscribe<T: Send + DeserializeOwned + 'static>(
    link: &RemoteLink,
    key: &str,
    subs: &mut Subscribers,
) -> Result<BufferReader<T>, String> {
    let (tx, rx) = buffer::<T>(IMPORT_QUEUE, FullPolicy::DropOldest);
    let k = key.to_owned();
    let sub = link
        .inner
        .session
        .declare_subscriber(key)
        .callback(
            move |s| match serde_json::from_slice::<T>(&s.payload().to_bytes()) {
                Ok(v) => {
                    tx.push(v);
                }
                Err(e) => tracing::warn!("zenoh: unreadable value on {k}: {e}"),
            },
        )
        .wait()
        .map_err(|e| format!("cannot subscribe to {key}: {e}"))?;
    subs.push(sub);
    Ok(rx)
}

/// `remote peer '<name>': <task>.<op>`, how the worker's messages name a call.
fn describe<C: RemoteCommand>(l: &LinkShared, task: &str, cmd: &C) -> (String, &'static str) {
    let op = C::operations()
        .get(cmd.operation_index())
        .map_or("?", |o| o.name);
    (format!("remote peer '{}': {task}.{op}", l.cfg.name), op)
}

/// Before a call is sent: a remote lost under it fails it unsent; a remote that was already
/// lost when it was accepted is waited for, up to `timeout_s`.
fn reach<C: RemoteCommand>(
    link: &RemoteLink,
    task: &str,
    c: &Call<C>,
    stop: &AtomicBool,
) -> Result<(), Outcome> {
    let l = &link.inner;
    let (what, _) = describe(l, task, &c.cmd);
    if !c.seen.alive && !l.wait_alive(Duration::from_secs_f64(l.cfg.timeout_s), stop) {
        l.not_back(&what);
        return Err(Outcome::NotBack);
    }
    if c.seen.lost_since(l) {
        l.fail(format!("{what}: not sent, the peer was lost"));
        return Err(Outcome::Lost);
    }
    Ok(())
}

/// One forwarded call, on the worker thread.
fn call<C: RemoteCommand>(link: &RemoteLink, task: &str, cmd: &C) -> Outcome {
    let l = &link.inner;
    let (what, op) = describe(l, task, cmd);
    let key = keys::op(l.cfg.machine(), task, op);
    let timeout = Duration::from_secs_f64(l.cfg.timeout_s);
    let t0 = Instant::now();
    let replies = match l
        .session
        .get(key.as_str())
        .payload(codec::encode(&cmd.remote_args()))
        .timeout(timeout)
        .wait()
    {
        Ok(r) => r,
        Err(e) => {
            l.fail(format!("{what}: cannot query {key}: {e}"));
            return Outcome::Unreachable;
        }
    };
    let Ok(reply) = replies.recv() else {
        return if !link.alive() {
            l.fail(format!("{what}: lost while waiting"));
            Outcome::Lost
        } else if t0.elapsed() + Duration::from_millis(50) >= timeout {
            l.fail(format!("{what}: no reply within {} s", l.cfg.timeout_s));
            Outcome::Timeout
        } else {
            l.fail(format!("{what}: nobody answers {key}"));
            Outcome::Unreachable
        };
    };
    match reply.result() {
        Ok(_) => Outcome::Done,
        Err(e) => {
            let bytes = e.payload().to_bytes();
            let v = codec::decode(Some(bytes.as_ref())).unwrap_or(Value::Null);
            // Zenoh itself answers a query that timed out with an error reply of its own
            // (not the exporter's JSON).
            let status = match v["status"].as_str() {
                Some(s) => s,
                None if t0.elapsed() + Duration::from_millis(50) >= timeout => "timeout",
                None => "failed",
            };
            let text = match v["error"].as_str() {
                Some(t) => t.to_owned(),
                None => String::from_utf8_lossy(&bytes).into_owned(),
            };
            l.fail(format!("{what}: {status}: {text}"));
            match status {
                "rejected" | "forbidden" | "invalid" => Outcome::Rejected,
                "timeout" => Outcome::Timeout,
                _ => Outcome::Failed,
            }
        }
    }
}

impl<C: RemoteCommand> Task for RemoteProxy<C> {
    type Command = C;

    fn configure(&mut self, ctx: &mut Configure<'_>) -> Result<(), TaskError> {
        self.lost_event = Some(ctx.event("peer_lost"));
        let link = self.link.clone();
        for import in std::mem::take(&mut self.imports) {
            match import(ctx, &link, &mut self.subscribers) {
                Ok(p) => self.pumps.push(p),
                Err(e) => {
                    tracing::error!("remote peer '{}': {e}", link.name());
                    return Err(TaskError::Fatal(
                        "cannot subscribe to a remote port or event",
                    ));
                }
            }
        }
        let proxy = ctx.task_name().to_owned();
        let forwards = std::mem::take(&mut self.forwards)
            .into_iter()
            .map(|f| f(ctx, &proxy))
            .collect();
        self.start_worker(forwards)
    }

    fn update(&mut self, _: &StepContext) -> Result<(), TaskError> {
        for p in &mut self.pumps {
            p.pump();
        }
        let losses = self.link.inner.losses.load(Ordering::Acquire);
        if losses != self.losses_seen {
            self.losses_seen = losses;
            if let Some(e) = &mut self.lost_event {
                e.emit(losses as u32);
            }
        }
        Ok(())
    }

    /// Accepted even while the remote is lost: the worker waits for it (module doc).
    fn accept(&mut self, cmd: &C, _: &StepContext) -> Result<(), RejectReason> {
        self.next_seq += 1;
        let seq = self.next_seq;
        let seen = LinkSeen::now(&self.link.inner);
        // A copy goes to the worker (commands are small values; no allocation here).
        let call = Call {
            seq,
            cmd: cmd.clone(),
            seen,
        };
        match self.calls.try_push(call) {
            Ok(()) => {
                if let Some(w) = &self.worker {
                    w.unpark();
                }
                self.waiting = Some((seq, seen));
                Ok(())
            }
            Err(_) => Err(RejectReason::Busy),
        }
    }

    fn progress(&mut self, _: &C, _: &StepContext) -> Progress {
        let Some((seq, seen)) = self.waiting else {
            return Progress::Done;
        };
        if self.results.seq.load(Ordering::Acquire) == seq {
            self.waiting = None;
            let o = Outcome::from_u8(self.results.outcome.load(Ordering::Relaxed));
            return o.map_or(
                Progress::Failed("remote call: no outcome"),
                Outcome::progress,
            );
        }
        if seen.lost_since(&self.link.inner) {
            self.waiting = None;
            return Progress::Failed("remote peer lost");
        }
        Progress::Running
    }

    fn has_work(&self) -> bool {
        self.waiting.is_some()
            || self.pumps.iter().any(|p| p.pending())
            || self.link.inner.losses.load(Ordering::Acquire) != self.losses_seen
    }
}
