//! The Zenoh bridge's overhead, side by side with bare Zenoh doing the same work in the same
//! run, over loopback (benches/README.md, Zenoh section):
//!
//! 1. **operation call**: a client queries `hytask/bench/machine/op/set_optional_stop`
//!    (the bridge: role check, JSON, a call thread, the command through the machine task's
//!    queue, its final status) against a bare queryable that calls the same operation on the
//!    same machine and replies. Round trip p50/p99.
//! 2. **port update**: a stamping thread writes the monotonic time into a data object every
//!    millisecond; the bridge publishes it (polling at `port_rate_hz`, JSON) and a bare thread
//!    polls the same object at the same rate and puts the raw value. The client computes
//!    arrival minus stamp. p50/p99.
//!
//! Both sides share one server session and one client session, and run in alternating
//! windows (A, B, then A again as the A/A noise reference), many rounds, order rotating; the
//! figure is the median of the per-round ratios. The machine is the built-in simulated mill,
//! in process. Run: `cargo bench --bench zenoh_bridge` (`ZENOH_BENCH_ROUNDS`, default 9;
//! `ZENOH_BENCH_SAMPLES`, default 200 per window; `ZENOH_BENCH_RATE_HZ`, the publication
//! rate of both sides, default 2000). Under `cargo test --all-targets` (no `--bench`) it
//! runs one round of 5 samples as a smoke test.
#![allow(clippy::unwrap_used)]

#[path = "../tests/zenoh_support/mod.rs"]
mod zenoh_support;

use hytask::bridge::Bridge;
use hytask::machine::api::*;
use hytask::rt::data_object::DataObject;
use hytask::rt::json::JsonPortReader;
use serde_json::{json, Value};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, OnceLock};
use std::time::{Duration, Instant};
use zenoh::Wait;

fn origin() -> Instant {
    static O: OnceLock<Instant> = OnceLock::new();
    *O.get_or_init(Instant::now)
}
fn now_ns() -> u64 {
    origin().elapsed().as_nanos() as u64
}

/// The simulated mill plus one extra port, `bench.stamp` (task `bench`), written by a
/// stamping thread: everything else is the mill's.
struct BenchMachine {
    mill: Arc<dyn hytask::daemon::Deployed>,
    stamp: DataObject<u64>,
}

macro_rules! delegate {
    ($($name:ident($($a:ident: $t:ty),*) -> $r:ty;)*) => {
        $(fn $name(&self, $($a: $t),*) -> $r { self.mill.$name($($a),*) })*
    };
}

impl MachineApi for BenchMachine {
    delegate! {
        status() -> Status;
        estop() -> Result<(), ApiError>;
        estop_reset() -> Result<(), ApiError>;
        machine_on() -> Result<(), ApiError>;
        machine_off() -> Result<(), ApiError>;
        home(axis: Option<&str>) -> Result<(), ApiError>;
        jog(req: &JogRequest) -> Result<(), ApiError>;
        jog_stop() -> Result<(), ApiError>;
        mdi(line: &str) -> Result<(), ApiError>;
        job_load(src: &JobSource) -> Result<JobInfo, ApiError>;
        job_run() -> Result<(), ApiError>;
        job_pause() -> Result<(), ApiError>;
        job_resume() -> Result<(), ApiError>;
        job_abort() -> Result<(), ApiError>;
        job_step() -> Result<(), ApiError>;
        set_overrides(req: &OverrideRequest) -> Result<Overrides, ApiError>;
        call(task: &str, operation: &str, args: &Value) -> Result<Value, ApiError>;
        set_sim_input(name: &str, value: f64) -> Result<(), ApiError>;
        sim_fault(fault: &SimFault) -> Result<(), ApiError>;
        subscribe() -> tokio::sync::broadcast::Receiver<MachineEvent>;
    }
    fn tasks(&self) -> Vec<TaskInfo> {
        let mut t = self.mill.tasks();
        t.push(TaskInfo {
            name: "bench".into(),
            state: "running".into(),
            thread: "stamp".into(),
            operations: vec![],
            events: vec![],
            ports: vec!["out bench.stamp".into()],
            exec_us: MinAvgMax::default(),
        });
        t
    }
    fn port_json(&self, name: &str) -> Result<Box<dyn JsonPortReader>, ApiError> {
        if name == "bench.stamp" {
            let any: Box<dyn std::any::Any + Send + Sync> = Box::new(self.stamp.clone());
            return hytask::rt::json::port_reader(any.as_ref())
                .ok_or_else(|| ApiError::NotSupported(name.into()));
        }
        self.mill.port_json(name)
    }
}

fn pct(v: &mut [f64], p: f64) -> f64 {
    v.sort_by(|a, b| a.total_cmp(b));
    v[((v.len() as f64 - 1.0) * p).round() as usize]
}

fn median(mut v: Vec<f64>) -> f64 {
    pct(&mut v, 0.5)
}

/// Round trips of `n` queries on `key`, µs.
fn query_rtts(client: &zenoh::Session, key: &str, payload: &str, n: usize) -> Vec<f64> {
    (0..n)
        .map(|_| {
            let t0 = Instant::now();
            let r = client
                .get(key)
                .payload(payload)
                .timeout(Duration::from_secs(60))
                .wait()
                .unwrap();
            let reply = r.recv().unwrap();
            if let Err(e) = reply.result() {
                panic!("{key}: error reply {:?}", e.payload().try_to_string());
            }
            t0.elapsed().as_secs_f64() * 1e6
        })
        .collect()
}

/// Stamp-to-arrival delays of the next `n` publications on `key`, µs; `decode` reads the
/// stamp from a payload.
fn port_delays(
    sub: &zenoh::pubsub::Subscriber<zenoh::handlers::RingChannelHandler<zenoh::sample::Sample>>,
    n: usize,
    decode: fn(&[u8]) -> u64,
) -> Vec<f64> {
    while let Ok(Some(_)) = sub.try_recv() {} // stale ones
    (0..n)
        .map(|_| {
            let s = sub.recv().unwrap();
            let stamp = decode(&s.payload().to_bytes());
            (now_ns().saturating_sub(stamp)) as f64 / 1e3
        })
        .collect()
}

/// `name` from the environment, or `default`.
fn env_or<T: std::str::FromStr>(name: &str, default: T) -> T {
    std::env::var(name)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

fn main() {
    // `cargo test --all-targets` runs this main without `--bench`: a short smoke run then
    // (every path once, a few samples), the full run only under `cargo bench`.
    let bench = std::env::args().any(|a| a == "--bench");
    let (rounds, samples) = if bench {
        (
            env_or("ZENOH_BENCH_ROUNDS", 9),
            env_or("ZENOH_BENCH_SAMPLES", 200),
        )
    } else {
        (1, 5)
    };
    let rate_hz: f64 = env_or("ZENOH_BENCH_RATE_HZ", 2000.0);
    let (cfg, endpoint) = zenoh_support::bridge_config(
        "bench",
        &format!("port_rate_hz = {rate_hz}\nports = [\"bench.stamp\"]"),
    );

    let mill = hytask::machine::deploy_from(None).unwrap();
    let machine = Arc::new(BenchMachine {
        mill: mill.clone(),
        stamp: DataObject::new("bench.stamp", 4),
    });
    let stop = Arc::new(AtomicBool::new(false));
    let mut writer = machine.stamp.writer().unwrap();
    let stamping = {
        let stop = stop.clone();
        std::thread::spawn(move || {
            while !stop.load(Ordering::Relaxed) {
                writer.set(now_ns());
                std::thread::sleep(Duration::from_millis(1));
            }
        })
    };

    let server = hytask::bridge::session::open(&cfg).unwrap();
    let bridge = Bridge::start_on(server.clone(), machine.clone(), "bench", &cfg).unwrap();

    // The bare side: a queryable that calls the same operation, and a poller that puts the
    // raw stamp, on the same server session.
    let bare_q = server.declare_queryable("bare/op").wait().unwrap();
    let m2 = machine.clone();
    let s2 = stop.clone();
    let bare_query = std::thread::spawn(move || {
        while !s2.load(Ordering::Relaxed) {
            if let Ok(Some(q)) = bare_q.recv_timeout(Duration::from_millis(50)) {
                let r = m2.call("machine", "set_optional_stop", &json!({"on": true}));
                let sent = match r {
                    Ok(v) => q
                        .reply(q.key_expr().clone(), serde_json::to_vec(&v).unwrap())
                        .wait(),
                    Err(e) => q.reply_err(e.to_string()).wait(),
                };
                sent.unwrap();
            }
        }
    });
    let mut bare_reader = machine.stamp.reader().unwrap();
    let (s3, srv) = (stop.clone(), server.clone());
    let bare_pub = std::thread::spawn(move || {
        let period = Duration::from_secs_f64(1.0 / rate_hz);
        let mut next = Instant::now();
        while !s3.load(Ordering::Relaxed) {
            if let (hytask::rt::data_object::FlowStatus::NewData, v) = bare_reader.read() {
                srv.put("bare/port", v.to_le_bytes().to_vec())
                    .wait()
                    .unwrap();
            }
            next += period;
            if let Some(d) = next.checked_duration_since(Instant::now()) {
                std::thread::sleep(d);
            } else {
                next = Instant::now();
            }
        }
    });

    let client = zenoh_support::client(&endpoint);
    // Ring channels: a FIFO subscriber nobody drains (the other side's, during a window)
    // fills up and then blocks the session's receive path, replies included.
    let ring = || zenoh::handlers::RingChannel::new(64);
    let sub_bridge = client
        .declare_subscriber("hytask/bench/bench/port/bench.stamp")
        .with(ring())
        .wait()
        .unwrap();
    let sub_bare = client
        .declare_subscriber("bare/port")
        .with(ring())
        .wait()
        .unwrap();
    // Warm up: routes learnt, threads running.
    let op_key = "hytask/bench/machine/op/set_optional_stop";
    let args = r#"{"on": true}"#;
    let warm = if bench { 20 } else { 2 };
    query_rtts(&client, op_key, args, warm);
    query_rtts(&client, "bare/op", "", warm);
    port_delays(&sub_bridge, warm, |b| serde_json::from_slice(b).unwrap());
    port_delays(&sub_bare, warm, |b| {
        u64::from_le_bytes(b.try_into().unwrap())
    });

    let mut op_ratio = (Vec::new(), Vec::new(), Vec::new()); // p50 ours/bare, p99, A/A p50
    let mut port_ratio = (Vec::new(), Vec::new(), Vec::new());
    let mut op_abs = (Vec::new(), Vec::new());
    let mut port_abs = (Vec::new(), Vec::new());
    for round in 0..rounds {
        let order = round % 2 == 0;
        let (mut a1, mut b, mut a2) = if order {
            let a1 = query_rtts(&client, "bare/op", "", samples);
            let b = query_rtts(&client, op_key, args, samples);
            (a1, b, query_rtts(&client, "bare/op", "", samples))
        } else {
            let b = query_rtts(&client, op_key, args, samples);
            let a1 = query_rtts(&client, "bare/op", "", samples);
            (a1, b, query_rtts(&client, "bare/op", "", samples))
        };
        let (pa, pb, pa2) = (pct(&mut a1, 0.5), pct(&mut b, 0.5), pct(&mut a2, 0.5));
        op_ratio.0.push(pb / pa);
        op_ratio.1.push(pct(&mut b, 0.99) / pct(&mut a1, 0.99));
        op_ratio.2.push(pa2 / pa);
        op_abs.0.push(pa);
        op_abs.1.push(pb);

        let bare = |n| port_delays(&sub_bare, n, |b| u64::from_le_bytes(b.try_into().unwrap()));
        let ours = |n| port_delays(&sub_bridge, n, |b| serde_json::from_slice(b).unwrap());
        let (mut a1, mut b, mut a2) = if order {
            let a1 = bare(samples);
            let b = ours(samples);
            (a1, b, bare(samples))
        } else {
            let b = ours(samples);
            (bare(samples), b, bare(samples))
        };
        let (pa, pb, pa2) = (pct(&mut a1, 0.5), pct(&mut b, 0.5), pct(&mut a2, 0.5));
        port_ratio.0.push(pb / pa);
        port_ratio.1.push(pct(&mut b, 0.99) / pct(&mut a1, 0.99));
        port_ratio.2.push(pa2 / pa);
        port_abs.0.push(pa);
        port_abs.1.push(pb);
    }
    // The smoke run asserts only that every path worked (a number for every window).
    for r in [&op_ratio, &port_ratio] {
        assert!(
            [&r.0, &r.1, &r.2]
                .iter()
                .all(|v| v.len() == rounds && v.iter().all(|x| x.is_finite() && *x > 0.0)),
            "a window measured nothing"
        );
    }
    println!("zenoh bridge vs bare zenoh, loopback, {rounds} rounds x {samples} samples (median of per-round ratios)");
    println!(
        "operation call RTT : p50 ours/bare {:.2} (bare {:.0} us, ours {:.0} us), p99 ratio {:.2}, A/A p50 {:.2}",
        median(op_ratio.0),
        median(op_abs.0),
        median(op_abs.1),
        median(op_ratio.1),
        median(op_ratio.2)
    );
    println!(
        "port update delay  : p50 ours/bare {:.2} (bare {:.0} us, ours {:.0} us), p99 ratio {:.2}, A/A p50 {:.2}",
        median(port_ratio.0),
        median(port_abs.0),
        median(port_abs.1),
        median(port_ratio.1),
        median(port_ratio.2)
    );
    stop.store(true, Ordering::Relaxed);
    let _ = (stamping.join(), bare_query.join(), bare_pub.join());
    bridge.stop();
    let _ = mill.shutdown();
}
