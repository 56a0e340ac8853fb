//! The two sides of the remote-peer tests (`tests/zenoh_peer.rs`, `tests/zenoh_proxy_alloc.rs`):
//! a "remote" deployment of `Worker` tasks served by `PeerHost` on one Zenoh session, and a
//! local deployment reaching them through `RemoteProxy`s on another, over loopback TCP.
//! Include with `#[path = "zenoh/peer_rig.rs"] mod peer_rig;` next to `mod zenoh_support;`.
#![allow(clippy::unwrap_used, dead_code)]

use crate::zenoh_support::free_port;
use hytask::bridge::remote::{RemoteCommand, RemoteLink, RemoteProxy};
use hytask::bridge::remote_host::{PeerHost, RunningPeer};
use hytask::config::remote::RemoteConfig;
use hytask::config::ZenohConfig;
use hytask::rt::deploy::Runtime;
use hytask::rt::prelude::*;
use serde_json::{json, Value};

/// `work(ms)`: done `ms` after it was accepted, then emits `worked` (a count) and writes
/// the count to `<task>.count`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum WorkCmd {
    Work(i64),
}

pub const OPS: &[OperationDescriptor] = &[OperationDescriptor {
    name: "work",
    doc: "Work for ms milliseconds.",
    params: &[ParamDescriptor {
        name: "ms",
        ty: ArgType::Int,
    }],
    next: NextCommand::AfterCompletion,
}];

impl Commands for WorkCmd {
    fn operations() -> &'static [OperationDescriptor] {
        OPS
    }
    fn operation_index(&self) -> usize {
        0
    }
    fn from_args(op: &str, args: &[ArgValue]) -> Result<Self, ArgError> {
        let a = Args::new(OPS, op, args)?;
        Ok(WorkCmd::Work(a.int(0)?))
    }
}

impl RemoteCommand for WorkCmd {
    fn remote_args(&self) -> Value {
        let WorkCmd::Work(ms) = self;
        json!({ "ms": ms })
    }
}

#[derive(Default)]
pub struct Worker {
    due_ns: u64,
    count: u32,
    worked: Option<EventSource<u32>>,
    out: Option<DataWriter<u32>>,
}

impl Task for Worker {
    type Command = WorkCmd;
    fn configure(&mut self, ctx: &mut Configure<'_>) -> Result<(), TaskError> {
        self.worked = Some(ctx.event("worked"));
        self.out = Some(ctx.output(&format!("{}.count", ctx.task_name())));
        Ok(())
    }
    fn update(&mut self, _: &StepContext) -> Result<(), TaskError> {
        Ok(())
    }
    fn accept(&mut self, c: &WorkCmd, ctx: &StepContext) -> Result<(), RejectReason> {
        let WorkCmd::Work(ms) = *c;
        if ms < 0 {
            return Err(RejectReason::BadParameters("ms must not be negative"));
        }
        self.due_ns = ctx.now_ns + ms as u64 * 1_000_000;
        Ok(())
    }
    fn progress(&mut self, _: &WorkCmd, ctx: &StepContext) -> Progress {
        if ctx.now_ns < self.due_ns {
            return Progress::Running;
        }
        self.count += 1;
        if let Some(e) = &mut self.worked {
            e.emit(self.count);
        }
        if let Some(o) = &mut self.out {
            o.set(self.count);
        }
        Progress::Done
    }
}

pub const SCHED: Schedule = Schedule {
    priority: 10,
    period_ns: 2_000_000,
    cpu: None,
};

pub fn zenoh_cfg(listen: u16, connect: Option<u16>) -> ZenohConfig {
    let connect = connect
        .map(|p| format!("connect = [\"tcp/127.0.0.1:{p}\"]"))
        .unwrap_or_default();
    toml::from_str(&format!(
        "listen = [\"tcp/127.0.0.1:{listen}\"]\n{connect}\nport_rate_hz = 200.0\ncall_timeout_s = 120.0\n"
    ))
    .unwrap()
}

pub fn remote_cfg(machine: &str, timeout_s: f64, critical: bool) -> RemoteConfig {
    RemoteConfig {
        name: "far".into(),
        machine: Some(machine.into()),
        timeout_s,
        critical,
        check: true,
    }
}

/// A remote process stand-in: tasks `worker` and `other` served as `machine`.
pub fn remote(machine: &str, port: u16) -> RunningPeer {
    remote_linked(machine, port, None)
}

/// [`remote`], also connecting to `local` (a restarted remote reaches the local side
/// without waiting for its reconnection attempts).
pub fn remote_linked(machine: &str, port: u16, local: Option<u16>) -> RunningPeer {
    let cfg = zenoh_cfg(port, local);
    let session = hytask::bridge::session::open(&cfg).unwrap();
    let mut app = Deployment::new();
    app.add_periodic("worker", Worker::default(), SCHED)
        .unwrap();
    app.add_periodic("other", Worker::default(), SCHED).unwrap();
    app.configure().unwrap();
    PeerHost::serve(session, app.start().unwrap(), machine, &cfg).unwrap()
}

pub struct Local {
    pub rt: Runtime,
    pub worker: TaskHandle<WorkCmd>,
    pub other: TaskHandle<WorkCmd>,
    pub worked: EventReceiver<u32>,
    pub link: RemoteLink,
    _session: zenoh::Session,
}

/// The local side: proxies `worker` and `other` of the remote, importing `worker`'s event
/// and port.
pub fn local(machine: &str, remote_port: u16, timeout_s: f64, critical: bool) -> Local {
    local_at(free_port(), machine, remote_port, timeout_s, critical)
}

/// A remote serving `machine` and the local side reaching it.
pub fn pair(machine: &str, timeout_s: f64, critical: bool) -> (RunningPeer, Local) {
    let port = free_port();
    let peer = remote(machine, port);
    (peer, local(machine, port, timeout_s, critical))
}

/// [`local`], listening on `port`.
pub fn local_at(
    port: u16,
    machine: &str,
    remote_port: u16,
    timeout_s: f64,
    critical: bool,
) -> Local {
    let session = hytask::bridge::session::open(&zenoh_cfg(port, Some(remote_port))).unwrap();
    let link = RemoteLink::connect(&session, &remote_cfg(machine, timeout_s, critical)).unwrap();
    let proxy = RemoteProxy::<WorkCmd>::new(&link, "worker", "local")
        .unwrap()
        .event::<u32>("worked")
        .unwrap()
        .port::<u32>("worker.count")
        .unwrap();
    let mut app = Deployment::new();
    let worker = app.add_periodic("worker", proxy, SCHED).unwrap();
    let other = RemoteProxy::<WorkCmd>::new(&link, "other", "local").unwrap();
    let other = app.add_periodic("other", other, SCHED).unwrap();
    app.configure().unwrap();
    let worked = app.event::<u32>("worker.worked").unwrap().subscribe(16);
    Local {
        rt: app.start().unwrap(),
        worker,
        other,
        worked,
        link,
        _session: session,
    }
}
