//! The exporter: a machine's task interfaces on Zenoh (keys in [`super::keys`]).
//!
//! Ordinary threads, never a realtime one (plus the call workers of [`super::calls`]):
//! - `zenoh-pub` publishes, every `1 / port_rate_hz`: each exported data-object port whose
//!   value changed (through a lock-free [`crate::rt::json::JsonPortReader`]), every realtime
//!   event queued since (a deferred subscription: the emitter never waits), every item of
//!   an exported buffer port, in order and none dropped (the bridge is the consumer of a
//!   buffer no task consumes, `hytask/<machine>/<task>/port/<buffer>`), the control
//!   socket's event stream, and the status every `1 / status_rate_hz`;
//! - `zenoh-query` answers queries under `hytask/<machine>/`: the task list, the status and
//!   port values (from the publisher's cache), and control methods and task operations. A
//!   call runs on a worker of a pool ([`super::calls`]: a worker per running call, threads
//!   kept, none started per call), so a slow operation delays only its own reply; it is
//!   answered with a timeout after `call_timeout_s`.
//!
//! Remote callers have the role of `[zenoh] role` and are checked like control-socket
//! clients (`control::access`). Over a network (not local-only) a job cannot be loaded from
//! a path on this host, only as text.

use super::calls::{Calls, Reply};
use super::{codec, keys, BridgeError};
use crate::config::{ZenohConfig, ZenohRole};
use crate::control::access::{self, Role};
use crate::control::methods;
use crate::control::protocol::{ControlError, ErrorCode};
use crate::machine::api::MachineApi;
use crate::rt::json::{JsonEventReceiver, JsonPortReader};
use serde_json::Value;
use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};
use zenoh::bytes::Encoding;
use zenoh::query::Query;
use zenoh::Wait;

/// Calls running at once; a call beyond is answered "rejected: busy".
const MAX_CALLS: usize = 16;
/// Events a realtime event's subscription queues between two publishing rounds.
const EVENT_QUEUE: usize = 256;

/// Latest published values by key, for queries of ports and status.
type Cache = Arc<Mutex<HashMap<String, Value>>>;

/// A running exporter; [`stop`](Self::stop) (or drop) ends its threads and closes the session.
pub struct Bridge {
    stop: Arc<AtomicBool>,
    threads: Vec<JoinHandle<()>>,
    session: zenoh::Session,
    prefix: String,
    ports: Vec<String>,
    /// `hytask/<machine>/alive`: remote users (`bridge::remote`) see the machine or peer lost
    /// the moment Zenoh withdraws it (stop, crash, broken link), not by a timeout.
    token: Option<zenoh::liveliness::LivelinessToken>,
    /// The `[[remote]]` peers watched ([`Self::watch`]).
    remotes: Vec<super::remote::RemoteLink>,
}

/// One exported port or event, found in the task list.
struct Exported<R> {
    key: String,
    source: R,
}

impl Bridge {
    /// Opens the session of `cfg` and exports `machine` (named `name`) on it.
    pub fn start(
        machine: Arc<dyn MachineApi>,
        name: &str,
        cfg: &ZenohConfig,
    ) -> Result<Bridge, BridgeError> {
        let session = super::session::open(cfg)?;
        Self::start_on(session, machine, name, cfg)
    }

    /// Exports `machine` on an open `session` (tests and `hytask peer` share a session).
    pub fn start_on(
        session: zenoh::Session,
        machine: Arc<dyn MachineApi>,
        name: &str,
        cfg: &ZenohConfig,
    ) -> Result<Bridge, BridgeError> {
        let m = cfg.key.clone().unwrap_or_else(|| name.to_owned());
        let prefix = keys::machine(&m);
        let Exports {
            ports,
            events,
            streams,
        } = discover(&*machine, &m, cfg)?;
        let port_keys = ports.iter().map(|p| p.key.clone()).collect();
        let cache: Cache = Arc::default();
        let stop = Arc::new(AtomicBool::new(false));
        let queryable = session
            .declare_queryable(format!("{prefix}/**"))
            .wait()
            .map_err(|e| BridgeError::Zenoh(format!("cannot declare {prefix}/**: {e}")))?;
        let publisher = Publisher {
            session: session.clone(),
            machine: machine.clone(),
            m: m.clone(),
            ports,
            events,
            streams,
            cache: cache.clone(),
            period: Duration::from_secs_f64(1.0 / cfg.port_rate_hz),
            status_period: Duration::from_secs_f64(1.0 / cfg.status_rate_hz),
        };
        let runner = machine.clone();
        let mut server = Server {
            machine,
            prefix: prefix.clone(),
            cache,
            role: match cfg.effective_role() {
                ZenohRole::Observer => Role::Observer,
                ZenohRole::Operator => Role::Operator,
            },
            local: cfg.local_only(),
            calls: Calls::start(
                Arc::new(move |method: &str, params: Value| {
                    methods::dispatch(&*runner, method, params)
                        .map(codec::done)
                        .map_err(|e| codec::control_failure(&e))
                }),
                MAX_CALLS,
                Duration::from_secs_f64(cfg.call_timeout_s),
            )?,
        };
        let spawn = |name: &str, f: Box<dyn FnOnce() + Send>| {
            std::thread::Builder::new()
                .name(name.into())
                .spawn(f)
                .map_err(|e| BridgeError::Zenoh(format!("cannot start thread {name}: {e}")))
        };
        let s1 = stop.clone();
        let s2 = stop.clone();
        let threads = vec![
            spawn("zenoh-pub", Box::new(move || publisher.run(&s1)))?,
            spawn(
                "zenoh-query",
                Box::new(move || {
                    while !s2.load(Ordering::Acquire) {
                        match queryable.recv_timeout(Duration::from_millis(100)) {
                            Ok(Some(q)) => server.answer(q),
                            Ok(None) => {}
                            Err(_) => break,
                        }
                    }
                }),
            )?,
        ];
        // Declared last: a remote user sees the machine alive once it answers.
        let token = Some(super::remote::declare_alive(&session, &m)?);
        tracing::info!("zenoh: exporting machine '{m}' under {prefix}/");
        Ok(Bridge {
            stop,
            threads,
            session,
            prefix,
            ports: port_keys,
            token,
            remotes: Vec::new(),
        })
    }

    /// Watches the machine's `[[remote]]` peers on this bridge's session ([`super::watch`]),
    /// for as long as the bridge runs.
    pub fn watch(
        &mut self,
        machine: &Arc<dyn MachineApi>,
        remotes: &[crate::config::remote::RemoteConfig],
    ) -> Result<(), super::remote::RemoteError> {
        let links = super::watch::watch(&self.session, machine, remotes)?;
        self.remotes.extend(links);
        Ok(())
    }

    /// `hytask/<machine>`.
    pub fn prefix(&self) -> &str {
        &self.prefix
    }

    /// Keys of the data-object ports being published.
    pub fn port_keys(&self) -> &[String] {
        &self.ports
    }

    /// Stops publishing and answering, and closes the session.
    pub fn stop(mut self) {
        self.shut();
    }

    fn shut(&mut self) {
        // Withdrawn first: remote users stop sending before the queryable goes away.
        drop(self.token.take());
        self.remotes.clear();
        self.stop.store(true, Ordering::Release);
        for t in self.threads.drain(..) {
            let _ = t.join();
        }
        let _ = self.session.close().wait();
    }
}

impl Drop for Bridge {
    fn drop(&mut self) {
        if !self.threads.is_empty() {
            self.shut();
        }
    }
}

/// The exported ports (outputs of every task, or those `cfg.ports` names) and events.
fn discover(machine: &dyn MachineApi, m: &str, cfg: &ZenohConfig) -> Result<Exports, BridgeError> {
    let tasks = machine.tasks();
    let mut ports = Vec::new();
    let mut events = Vec::new();
    let mut streams = Vec::new();
    for t in &tasks {
        for p in &t.ports {
            if let Some(name) = p.strip_prefix("out (buffer) ") {
                export_buffer(machine, m, &t.name, name, &mut streams);
                continue;
            }
            let Some(object) = p.strip_prefix("out ") else {
                continue;
            };
            let wanted = cfg.ports.as_ref().map(|l| l.iter().any(|n| n == object));
            match (machine.port_json(object), wanted) {
                (Ok(source), None | Some(true)) => ports.push(Exported {
                    key: keys::port(m, &t.name, object),
                    source,
                }),
                (Err(e), Some(true)) => {
                    return Err(BridgeError::Config {
                        key: "zenoh.ports".into(),
                        message: format!("port '{object}': {e}"),
                    })
                }
                (Err(e), None) => tracing::debug!("zenoh: port '{object}' not exported: {e}"),
                (_, Some(false)) => {}
            }
        }
        for e in &t.events {
            let short = e
                .strip_prefix(&format!("{}.", t.name))
                .unwrap_or(e.as_str());
            match machine.event_json(e, EVENT_QUEUE) {
                Ok(source) => events.push(Exported {
                    key: keys::event(m, &t.name, short),
                    source,
                }),
                Err(err) => tracing::debug!("zenoh: event '{e}' not exported: {err}"),
            }
        }
    }
    if let Some(list) = &cfg.ports {
        for name in list {
            if !ports
                .iter()
                .any(|p| p.key.ends_with(&format!("/port/{}", keys::segment(name))))
            {
                return Err(BridgeError::Config {
                    key: "zenoh.ports".into(),
                    message: format!("no output port named '{name}'"),
                });
            }
        }
    }
    Ok(Exports {
        ports,
        events,
        streams,
    })
}

/// Buffer `name` (produced by `task`) as an ordered stream, unless a task consumes it or
/// another of its producers already had it exported.
fn export_buffer(
    machine: &dyn MachineApi,
    m: &str,
    task: &str,
    name: &str,
    streams: &mut Vec<Exported<Box<dyn JsonEventReceiver>>>,
) {
    let seg = format!("/port/{}", keys::segment(name));
    if streams.iter().any(|s| s.key.ends_with(&seg)) {
        return;
    }
    match machine.buffer_json(name) {
        Ok(source) => streams.push(Exported {
            key: keys::port(m, task, name),
            source,
        }),
        Err(e) => tracing::debug!("zenoh: buffer '{name}' not exported: {e}"),
    }
}

/// What [`discover`] found to export.
struct Exports {
    ports: Vec<Exported<Box<dyn JsonPortReader>>>,
    events: Vec<Exported<Box<dyn JsonEventReceiver>>>,
    /// Buffers, published item by item in order.
    streams: Vec<Exported<Box<dyn JsonEventReceiver>>>,
}

struct Publisher {
    session: zenoh::Session,
    machine: Arc<dyn MachineApi>,
    m: String,
    ports: Vec<Exported<Box<dyn JsonPortReader>>>,
    events: Vec<Exported<Box<dyn JsonEventReceiver>>>,
    streams: Vec<Exported<Box<dyn JsonEventReceiver>>>,
    cache: Cache,
    period: Duration,
    status_period: Duration,
}

impl Publisher {
    fn run(mut self, stop: &AtomicBool) {
        let mut news = self.machine.subscribe();
        let status_key = keys::status(&self.m);
        let mut next_status = Instant::now();
        let mut next = Instant::now();
        while !stop.load(Ordering::Acquire) {
            for p in &mut self.ports {
                if let Some(v) = p.source.fresh() {
                    put(&self.session, &p.key, &v);
                    lock(&self.cache).insert(p.key.clone(), v);
                }
            }
            for e in &mut self.events {
                let (session, key) = (&self.session, &e.key);
                e.source.drain(&mut |v| put(session, key, &v));
            }
            for b in &mut self.streams {
                let (session, key) = (&self.session, &b.key);
                b.source.drain(&mut |v| put_in_order(session, key, &v));
            }
            loop {
                match news.try_recv() {
                    Ok(ev) => self.put(&keys::news(&self.m, &ev.topic), &ev.data),
                    Err(tokio::sync::broadcast::error::TryRecvError::Lagged(n)) => {
                        tracing::warn!("zenoh: {n} machine events skipped (publisher too slow)")
                    }
                    Err(_) => break,
                }
            }
            let now = Instant::now();
            if now >= next_status {
                if let Ok(v) = serde_json::to_value(self.machine.status()) {
                    self.put(&status_key, &v);
                    lock(&self.cache).insert(status_key.clone(), v);
                }
                next_status = now + self.status_period;
            }
            next += self.period;
            let now = Instant::now();
            if next > now {
                std::thread::sleep(next - now);
            } else {
                next = now;
            }
        }
    }

    fn put(&self, key: &str, v: &Value) {
        put(&self.session, key, v);
    }
}

fn put(session: &zenoh::Session, key: &str, v: &Value) {
    if let Err(e) = session
        .put(key, codec::encode(v))
        .encoding(Encoding::APPLICATION_JSON)
        .wait()
    {
        tracing::warn!("zenoh: cannot publish {key}: {e}");
    }
}

/// A buffer's item: a stream loses nothing, so when Zenoh's queue towards a subscriber is
/// full the publisher thread waits (`Block`) rather than drop the item (the default). The
/// buffer itself keeps its own full policy towards its producers meanwhile.
fn put_in_order(session: &zenoh::Session, key: &str, v: &Value) {
    if let Err(e) = session
        .put(key, codec::encode(v))
        .encoding(Encoding::APPLICATION_JSON)
        .congestion_control(zenoh::qos::CongestionControl::Block)
        .wait()
    {
        tracing::warn!("zenoh: cannot publish {key}: {e}");
    }
}

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

struct Server {
    machine: Arc<dyn MachineApi>,
    prefix: String,
    cache: Cache,
    role: Role,
    local: bool,
    calls: Calls<Query>,
}

impl Server {
    fn answer(&mut self, q: Query) {
        let key = q.key_expr().as_str().to_owned();
        let Some(target) = keys::parse(&self.prefix, &key) else {
            return reply(
                &q,
                Err(codec::failure("invalid", format!("no such key '{key}'"))),
            );
        };
        let params = match codec::decode(q.payload().map(|p| p.to_bytes()).as_deref()) {
            Ok(v) => v,
            Err(e) => return reply(&q, Err(codec::failure("invalid", e))),
        };
        match target {
            keys::Target::Tasks => {
                let r = methods::dispatch(&*self.machine, "tasks", Value::Null);
                reply(
                    &q,
                    r.map(codec::done).map_err(|e| codec::control_failure(&e)),
                );
            }
            keys::Target::Status | keys::Target::Port(..) => {
                let v = lock(&self.cache).get(&key).cloned();
                let v = match (v, target) {
                    (Some(v), _) => Ok(v),
                    (None, keys::Target::Status) => {
                        serde_json::to_value(self.machine.status()).map_err(|e| e.to_string())
                    }
                    (None, _) => Err(format!("no value published on '{key}' (yet)")),
                };
                reply(
                    &q,
                    v.map(codec::done).map_err(|e| codec::failure("invalid", e)),
                );
            }
            keys::Target::Control(method) => {
                let method = method.to_owned();
                self.call(q, method, params);
            }
            keys::Target::Op(task, op) => {
                let args = serde_json::json!({"task": task, "operation": op, "args": params});
                self.call(q, "call".into(), args);
            }
        }
    }

    /// Runs `method` on a call worker ([`super::calls`]), which replies with its result;
    /// the deadline watcher replies "timeout" if it has none within `call_timeout_s`.
    fn call(&mut self, q: Query, method: String, params: Value) {
        if let Err(e) = self.permitted(&method, &params) {
            return reply(&q, Err(codec::control_failure(&e)));
        }
        if let Err(refused) = self.calls.submit(q, method, params) {
            reply(
                &refused.reply,
                Err(codec::failure(
                    "rejected",
                    format!("busy: {} calls running", refused.running),
                )),
            );
        }
    }

    /// The control socket's role check, and no job read from a path of this host for a
    /// caller that may be off the host.
    fn permitted(&self, method: &str, params: &Value) -> Result<(), ControlError> {
        if !access::permits(self.role, method) {
            return Err(ControlError::new(
                ErrorCode::Forbidden,
                format!(
                    "'{method}' needs the operator role; Zenoh callers are {}",
                    self.role.as_str()
                ),
            ));
        }
        if !self.local && method == "job.load" && params.get("path").is_some() {
            return Err(ControlError::new(
                ErrorCode::Forbidden,
                "over a network a job is sent as text, not read from a path on the machine",
            ));
        }
        Ok(())
    }
}

impl Reply for Query {
    fn send(self, r: Result<Value, Value>) {
        reply(&self, r);
    }
}

fn reply(q: &Query, r: Result<Value, Value>) {
    let key = q.key_expr().clone();
    let sent = match r {
        Ok(v) => q
            .reply(key, codec::encode(&v))
            .encoding(Encoding::APPLICATION_JSON)
            .wait(),
        Err(v) => q
            .reply_err(codec::encode(&v))
            .encoding(Encoding::APPLICATION_JSON)
            .wait(),
    };
    if let Err(e) = sent {
        tracing::warn!("zenoh: cannot reply to {}: {e}", q.key_expr());
    }
}
