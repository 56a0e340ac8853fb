//! Buffer ports on Zenoh: a buffer that no task consumes is exported as an ordered stream on
//! `hytask/<machine>/<task>/port/<buffer>`, every item in order, none lost or reordered under
//! a burst (the bridge drains it as its consumer and publishes with congestion control
//! `Block`). A peer process stand-in (`PeerHost`) serves a task whose `burst(n)` operation
//! pushes `n` consecutive numbers in one realtime step; a Zenoh client calls it through the
//! bridge and subscribes to the stream.
//!
//! Every wait is a hang guard (60 s), never a timing; the check holds for any interleaving
//! (a subscriber declared late misses a prefix of the stream, never an item after it).
#![allow(clippy::unwrap_used)]

#[path = "zenoh/peer_rig.rs"]
mod peer_rig;
mod zenoh_support;

use hytask::bridge::remote_host::PeerHost;
use hytask::rt::prelude::*;
use peer_rig::{zenoh_cfg, SCHED};
use serde_json::json;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use zenoh::Wait;
use zenoh_support::{free_port, query};

const GUARD: Duration = Duration::from_secs(60);
/// Items per burst, and bursts.
const BURST: i64 = 1000;
const BURSTS: i64 = 5;
/// Larger than everything the test can push (bursts and probes): the buffer never drops,
/// whatever the bridge's pace, so a gap could only be the bridge's or Zenoh's.
const CAPACITY: usize = 8192;

/// `burst(n)`.
#[derive(Debug, Clone, Copy, PartialEq)]
struct BurstCmd(i64);

const OPS: &[OperationDescriptor] = &[OperationDescriptor {
    name: "burst",
    doc: "Push n consecutive numbers into the buffer.",
    params: &[ParamDescriptor {
        name: "n",
        ty: ArgType::Int,
    }],
    next: NextCommand::AfterCompletion,
}];

impl Commands for BurstCmd {
    fn operations() -> &'static [OperationDescriptor] {
        OPS
    }
    fn operation_index(&self) -> usize {
        0
    }
    fn from_args(op: &str, args: &[ArgValue]) -> Result<Self, ArgError> {
        Ok(BurstCmd(Args::new(OPS, op, args)?.int(0)?))
    }
}

#[derive(Default)]
struct Burst {
    next: u64,
    out: Option<BufferWriter<u64>>,
}

impl Task for Burst {
    type Command = BurstCmd;
    fn configure(&mut self, ctx: &mut Configure<'_>) -> Result<(), TaskError> {
        self.out = Some(ctx.buffer_out("burst.items", CAPACITY, FullPolicy::DropNewest));
        Ok(())
    }
    fn update(&mut self, _: &StepContext) -> Result<(), TaskError> {
        Ok(())
    }
    fn accept(&mut self, c: &BurstCmd, _: &StepContext) -> Result<(), RejectReason> {
        if let Some(out) = &self.out {
            for _ in 0..c.0 {
                out.push(self.next);
                self.next += 1;
            }
        }
        Ok(())
    }
    fn progress(&mut self, _: &BurstCmd, _: &StepContext) -> Progress {
        Progress::Done
    }
}

#[test]
fn a_buffer_port_arrives_as_an_ordered_stream_without_loss_under_bursts() {
    let port = free_port();
    let cfg = zenoh_cfg(port, None);
    let mut app = Deployment::new();
    app.add_periodic("burst", Burst::default(), SCHED).unwrap();
    app.configure().unwrap();
    let session = hytask::bridge::session::open(&cfg).unwrap();
    let peer = PeerHost::serve(session, app.start().unwrap(), "streams", &cfg).unwrap();

    let s = zenoh_support::client(&format!("tcp/127.0.0.1:{port}"));
    let tasks = query(&s, "hytask/streams/tasks", None, GUARD).unwrap();
    assert!(
        tasks.to_string().contains("out (buffer) burst.items"),
        "{tasks}"
    );
    let got = Arc::new(Mutex::new(Vec::<u64>::new()));
    let g = got.clone();
    let _sub = s
        .declare_subscriber("hytask/streams/burst/port/burst.items")
        .callback(move |sample| {
            let v: u64 = serde_json::from_slice(&sample.payload().to_bytes()).unwrap();
            g.lock().unwrap().push(v);
        })
        .wait()
        .unwrap();
    let burst = |n: i64| {
        let r = query(
            &s,
            "hytask/streams/burst/op/burst",
            Some(&json!({"n": n})),
            GUARD,
        );
        assert_eq!(r.unwrap()["status"], "done");
    };
    // Until the route to the subscriber is known, items published find no subscriber: probe
    // with single items until one arrives.
    let mut pushed = 0;
    let t0 = Instant::now();
    while got.lock().unwrap().is_empty() {
        assert!(t0.elapsed() < GUARD, "no stream item arrived");
        burst(1);
        pushed += 1;
        std::thread::sleep(Duration::from_millis(100));
    }
    for _ in 0..BURSTS {
        burst(BURST);
        pushed += BURST;
    }
    let last = pushed as u64 - 1;
    let t0 = Instant::now();
    while got.lock().unwrap().last() != Some(&last) {
        let n = got.lock().unwrap().len();
        assert!(t0.elapsed() < GUARD, "{n} items arrived, not up to {last}");
        std::thread::sleep(Duration::from_millis(20));
    }
    let got = got.lock().unwrap().clone();
    let first = got[0];
    let want: Vec<u64> = (first..=last).collect();
    assert!(
        got == want,
        "not every item from {first} to {last} in order: {} items, first gap at {:?}",
        got.len(),
        got.windows(2).find(|w| w[1] != w[0] + 1)
    );
    assert!(got.len() as i64 >= BURST * BURSTS);
    drop(_sub);
    let _ = s.close().wait();
    peer.stop();
}

/// The bridge is a buffer's consumer, so a buffer that a task consumes is not exported (and
/// a consumer-less one only once); the error names the consumer.
#[test]
fn a_buffer_a_task_consumes_is_not_exported() {
    struct Sink(Option<BufferReader<u64>>);
    impl Task for Sink {
        type Command = NoCommands;
        fn configure(&mut self, ctx: &mut Configure<'_>) -> Result<(), TaskError> {
            self.0 = Some(ctx.buffer_in("burst.items"));
            Ok(())
        }
        fn update(&mut self, _: &StepContext) -> Result<(), TaskError> {
            Ok(())
        }
    }
    let mut app = Deployment::new();
    app.add_periodic("burst", Burst::default(), SCHED).unwrap();
    app.add_periodic("sink", Sink(None), SCHED).unwrap();
    app.configure().unwrap();
    let mut rt = app.start().unwrap();
    let e = rt.json_buffer("burst.items").err().unwrap().to_string();
    assert!(e.contains("consumed by task 'sink'"), "{e}");
    rt.stop();

    let mut app = Deployment::new();
    app.add_periodic("burst", Burst::default(), SCHED).unwrap();
    app.configure().unwrap();
    let mut rt = app.start().unwrap();
    assert!(rt.json_buffer("burst.items").is_ok());
    let e = rt.json_buffer("burst.items").err().unwrap().to_string();
    assert!(e.contains("consumed by an exporter"), "{e}");
    rt.stop();
}
