//! Event-level Modbus latencies of the real daemon at a 10 ms poll (issue 10, Performance):
//!
//! (a) an input changed at the simulator until its event reaches a control-socket
//!     subscriber: the e-stop input of `config/sim-modbus.toml` pressed at the simulator,
//!     until the first `fault` or `mode` event of the e-stop;
//! (b) an M-code until the coil changes at the simulator: `mdi M8` / `mdi M9` sent on the
//!     control socket, until the simulator applies the write of `coolant_flood` (the time
//!     the simulator recorded for it, not when this program looked).
//!
//! The daemon is the real `hytask serve` (servo thread at 1 kHz) on `config/sim-modbus.toml`,
//! its panel on the simulator engine of `hytask modbus-sim` running in this process, so
//! both ends of each path are timed on one clock. Each change is desynchronised from the poll
//! phase. Run: `cargo bench --bench modbus_latency` (`MODBUS_LATENCY_SAMPLES`, default 100
//! per path). Without `--bench` (`cargo test --all-targets`) a smoke run of 3 samples.
#![allow(clippy::unwrap_used)]

#[path = "../tests/modbus_support/mod.rs"]
mod modbus_support;
#[path = "../tests/support/mod.rs"]
mod support;

use hytask::control::client::Client;
use hytask::modbus::sim::Sim;
use serde_json::{json, Value};
use std::path::Path;
use std::time::{Duration, Instant};
use support::{ok, ready, wait_status, Daemon};

/// Hang guard of every wait.
const GUARD: Duration = Duration::from_secs(60);

fn pct(v: &mut [f64], p: f64) -> f64 {
    v.sort_by(|a, b| a.total_cmp(b));
    v[((v.len() as f64 - 1.0) * p).round() as usize]
}

/// A pause of 1 to 11 ms, different for every sample: desynchronises a change from the
/// 10 ms poll.
fn desync(k: usize) {
    std::thread::sleep(Duration::from_micros(1000 + (k as u64 * 3779) % 10_000));
}

fn wait_until(what: &str, daemon: &Daemon, c: &mut Client, sim: &Sim, pred: impl Fn() -> bool) {
    let t0 = Instant::now();
    while !pred() {
        if t0.elapsed() > GUARD {
            let status = c.call("status", Value::Null);
            let log = daemon.log();
            let lines: Vec<&str> = log.lines().collect();
            let tail = lines[lines.len().saturating_sub(40)..].join("\n");
            // Is the poller still polling?
            let r0 = sim.lock().requests;
            std::thread::sleep(Duration::from_millis(200));
            let polls = sim.lock().requests - r0;
            let coils = sim.lock().values();
            panic!(
                "timed out waiting for {what}; {polls} requests at the simulator in 200 ms; \
                 simulator points {coils:?}; status {status:?}; daemon log:\n{tail}"
            );
        }
        std::thread::sleep(Duration::from_micros(200));
    }
}

fn report(what: &str, v: &mut [f64]) {
    println!(
        "{what}: p50 {:.2} ms, p99 {:.2} ms, max {:.2} ms ({} samples)",
        pct(v, 0.5),
        pct(v, 0.99),
        pct(v, 1.0),
        v.len()
    );
}

fn main() {
    let bench = std::env::args().any(|a| a == "--bench");
    let samples = if bench {
        std::env::var("MODBUS_LATENCY_SAMPLES")
            .ok()
            .and_then(|s| s.parse().ok())
            .unwrap_or(100)
    } else {
        3
    };
    let shipped = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/sim-modbus.toml");
    // The simulator engine serving the Modbus devices of the shipped file on a free port.
    let sim = Sim::from_io(&hytask::config::load(&shipped).unwrap().io, 256).unwrap();
    let (addr, _) = modbus_support::serve_sim(&sim);
    let dir = tempfile::tempdir().unwrap();
    let config = modbus_support::machine_config(dir.path(), &addr);
    let daemon = Daemon::start(&config);
    let mut c = daemon.client();
    ready(&mut c);

    // (b) M-code -> coil, alternating M8 / M9.
    let mut mcode = Vec::new();
    for k in 0..samples {
        let on = k % 2 == 0;
        desync(k);
        let before = sim.lock().changed_at("coolant_flood").unwrap();
        let t0 = Instant::now();
        ok(
            &mut c,
            "mdi",
            json!({ "line": if on { "M8" } else { "M9" } }),
        );
        let level = f64::from(u8::from(on));
        wait_until("the coolant coil", &daemon, &mut c, &sim, || {
            let s = sim.lock();
            s.get("coolant_flood").unwrap() == level
                && s.changed_at("coolant_flood").unwrap() != before
        });
        let at = sim.lock().changed_at("coolant_flood").unwrap().unwrap();
        mcode.push(at.duration_since(t0).as_secs_f64() * 1e3);
    }

    // (a) e-stop input at the simulator -> its event on the control socket.
    let mut sub = daemon.client();
    ok(&mut sub, "subscribe", Value::Null);
    let mut input = Vec::new();
    for k in 0..samples {
        while sub.next_event(Duration::from_millis(1)).unwrap().is_some() {} // drain
        desync(k);
        let t0 = Instant::now();
        sim.lock().set("estop", 1.0).unwrap();
        loop {
            let e = sub.next_event(GUARD).unwrap().expect("no e-stop event");
            let estop = (e.topic == "mode" && e.data["mode"] == json!("estop"))
                || (e.topic == "fault" && e.data["kind"] == json!("Estop"));
            if estop {
                input.push(t0.elapsed().as_secs_f64() * 1e3);
                break;
            }
        }
        sim.lock().set("estop", 0.0).unwrap();
        wait_status(&mut c, "e-stop released", GUARD, |s| {
            s["inputs"]["estop"] == json!(0.0)
        });
        ok(&mut c, "estop.reset", Value::Null);
        ok(&mut c, "machine.on", Value::Null);
        wait_status(&mut c, "machine on", GUARD, |s| s["mode"] != json!("estop"));
    }
    println!("daemon on config/sim-modbus.toml, poll 10 ms, servo 1 kHz");
    report(
        "input change at the simulator -> e-stop event on the control socket",
        &mut input,
    );
    report(
        "mdi M8/M9 sent -> coolant coil written at the simulator",
        &mut mcode,
    );
}
