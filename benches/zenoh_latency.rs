//! Servo-thread wake-up latency with the Zenoh bridge publishing every port at 1 kHz, side by
//! side with the same machine idle, in one run (issue 15: "unchanged within the noise band").
//!
//! The built-in simulated mill runs on its real periodic servo thread (1 kHz, `SCHED_FIFO`
//! when permitted), switched on and standing still. Each round has three windows of the same
//! length: with the bridge (a session, every output port and realtime event exported,
//! `port_rate_hz = 1000`, and a remote client session subscribed to `hytask/bench/**`), idle
//! (no bridge), and idle again, the A/A reference that shows how much two identical windows
//! differ on this machine. The first two windows swap places every round. The bridge and
//! client are started before and stopped after their window, outside it. Per window: p50 / p90
//! / p99 of the servo thread's wake-up latency (its own 1 µs histogram), ratios bridge ÷ idle
//! and idle-again ÷ idle; tails are judged by pooled counts above 50 µs, 100 µs and 500 µs
//! (half the period), never by a ratio of maxima (/work/shared/notes/rt-measurement.md).
//!
//! Run: `cargo bench --bench zenoh_latency` (root for `SCHED_FIFO`; `ZENOH_LAT_ROUNDS`, default
//! 4; `ZENOH_LAT_SECS` per window, default 15). Under `cargo test --all-targets` (no `--bench`)
//! one round of 1 s windows as a smoke test. Figures in benches/README.md, Zenoh section.
#![allow(clippy::unwrap_used)]

#[path = "../tests/zenoh_support/mod.rs"]
mod zenoh_support;

use hytask::bridge::Bridge;
use hytask::daemon::Deployed;
use hytask::machine::api::MachineApi;
use hytask::machine::Machine;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::Duration;
use zenoh::Wait;

fn env_or<T: std::str::FromStr>(name: &str, default: T) -> T {
    std::env::var(name)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

/// Wake-up latencies of one window: samples per 1 µs bucket.
struct Window(Vec<u64>);

impl Window {
    fn samples(&self) -> u64 {
        self.0.iter().sum()
    }

    /// The bucket (µs) holding quantile `p`.
    fn quantile(&self, p: f64) -> f64 {
        let rank = (p * self.samples() as f64).ceil().max(1.0) as u64;
        let mut below = 0;
        let bucket = self.0.iter().position(|&c| {
            below += c;
            below >= rank
        });
        bucket.unwrap_or(self.0.len()) as f64
    }

    fn above(&self, us: usize) -> u64 {
        self.0.iter().skip(us).sum()
    }
}

/// Runs `secs` of the servo thread while `load` is in place, and returns its histogram delta.
fn measure(machine: &Machine, secs: f64) -> Window {
    let stats = &machine.servo_thread().stats.wakeup;
    let before = stats.histogram().counts();
    std::thread::sleep(Duration::from_secs_f64(secs));
    let after = stats.histogram().counts();
    Window(after.iter().zip(&before).map(|(a, b)| a - b).collect())
}

/// The bridge on a fresh loopback session and a client subscribed to all of it; the count of
/// samples the client received.
struct Exported {
    bridge: Bridge,
    client: zenoh::Session,
    received: Arc<AtomicU64>,
}

fn export(machine: &Arc<Machine>) -> Exported {
    let (cfg, endpoint) = zenoh_support::bridge_config("bench", "port_rate_hz = 1000.0");
    let api: Arc<dyn MachineApi> = machine.clone();
    let bridge = Bridge::start(api, "bench", &cfg).unwrap();
    let client = zenoh_support::client(&endpoint);
    let received = Arc::new(AtomicU64::new(0));
    let r = received.clone();
    client
        .declare_subscriber("hytask/bench/**")
        .callback(move |_| {
            r.fetch_add(1, Ordering::Relaxed);
        })
        .background()
        .wait()
        .unwrap();
    // Publications flowing before the window starts (hang guard: 60 s).
    zenoh_support::wait_for("publications", Duration::from_secs(60), || {
        received.load(Ordering::Relaxed) >= 100
    });
    Exported {
        bridge,
        client,
        received,
    }
}

fn line(name: &str, w: &Window, idle: &Window, extra: &str) -> String {
    format!(
        "{name:<11} n {:>6}  p50 {:>3} p90 {:>3} p99 {:>4} us  (÷ idle {:.2} / {:.2} / {:.2})  \
         >50us {:>3} >100us {:>3} >500us {:>3}{extra}",
        w.samples(),
        w.quantile(0.5),
        w.quantile(0.9),
        w.quantile(0.99),
        w.quantile(0.5) / idle.quantile(0.5),
        w.quantile(0.9) / idle.quantile(0.9),
        w.quantile(0.99) / idle.quantile(0.99),
        w.above(50),
        w.above(100),
        w.above(500),
    )
}

fn main() {
    let bench = std::env::args().any(|a| a == "--bench");
    let (rounds, secs) = if bench {
        (
            env_or("ZENOH_LAT_ROUNDS", 4),
            env_or("ZENOH_LAT_SECS", 15.0),
        )
    } else {
        (1, 1.0)
    };
    let machine = Machine::deploy(hytask::machine::load_config(None).unwrap()).unwrap();
    zenoh_support::switch_on(&*machine);
    println!(
        "servo thread wake-up latency, 1 kHz, {rounds} rounds of {secs} s windows, realtime {}",
        machine.servo_thread().realtime()
    );
    // Pooled tail counts: (>50, >100, >500 µs) per kind of window.
    let mut pooled = [[0u64; 3]; 3];
    let mut ratios: [Vec<[f64; 3]>; 2] = [Vec::new(), Vec::new()];
    for round in 0..rounds {
        let with_bridge = || {
            let e = export(&machine);
            let n0 = e.received.load(Ordering::Relaxed);
            let w = measure(&machine, secs);
            let rate = (e.received.load(Ordering::Relaxed) - n0) as f64 / secs;
            let ports = e.bridge.port_keys().len();
            let _ = e.client.close().wait();
            e.bridge.stop();
            (
                w,
                format!("  ({ports} ports, {rate:.0} samples/s received)"),
            )
        };
        let ((bridge, extra), idle) = if round % 2 == 0 {
            let b = with_bridge();
            (b, measure(&machine, secs))
        } else {
            let i = measure(&machine, secs);
            (with_bridge(), i)
        };
        let again = measure(&machine, secs);
        println!("round {round}");
        for (k, (name, w, x)) in [
            ("idle", &idle, ""),
            ("bridge", &bridge, extra.as_str()),
            ("idle again", &again, ""),
        ]
        .into_iter()
        .enumerate()
        {
            println!("  {}", line(name, w, &idle, x));
            for (slot, us) in pooled[k].iter_mut().zip([50, 100, 500]) {
                *slot += w.above(us);
            }
            assert!(w.samples() > 0, "window '{name}' measured nothing");
        }
        for (r, w) in ratios.iter_mut().zip([&bridge, &again]) {
            r.push([0.5, 0.9, 0.99].map(|p| w.quantile(p) / idle.quantile(p)));
        }
    }
    let median = |v: &[[f64; 3]], i: usize| {
        let mut x: Vec<f64> = v.iter().map(|r| r[i]).collect();
        x.sort_by(f64::total_cmp);
        x[x.len() / 2]
    };
    for (name, r) in [
        ("bridge ÷ idle", &ratios[0]),
        ("A/A (idle again ÷ idle)", &ratios[1]),
    ] {
        println!(
            "median {name}: p50 {:.2}  p90 {:.2}  p99 {:.2}",
            median(r.as_slice(), 0),
            median(r.as_slice(), 1),
            median(r.as_slice(), 2)
        );
    }
    for (name, p) in ["idle", "bridge", "idle again"].iter().zip(pooled) {
        println!(
            "pooled {name:<11}: >50us {}  >100us {}  >500us {}",
            p[0], p[1], p[2]
        );
    }
    machine.shutdown().unwrap();
}
