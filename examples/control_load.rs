//! Control-socket load benchmark (issue: "status requests per second and p99 latency with 50
//! clients, and the servo thread's p99/max wake-up latency with and without that load").
//!
//! In one process: deploys the simulated mill (tests/fixtures/sim-fast.toml), serves its
//! control socket, homes it and runs a long job. Then it alternates windows *without* and
//! *with* N clients calling `status` as fast as they can, and reports per window the servo
//! thread's wake-up latency (p50/p99/max and samples above 100 µs, from the thread's own
//! histogram, window deltas) and, for loaded windows, requests/s and request latency.
//! The with/without ratio of the servo p99 is the figure of merit (target ≤ 1.1); the
//! windows alternate so that host noise hits both kinds alike. Finally the process RSS.
//!
//! ```sh
//! cargo run --release --example control_load -- [--clients 50] [--window-s 5] [--pairs 3]
//! ```
#![allow(clippy::unwrap_used)]

use hytask::control::client::Client;
use hytask::daemon::Deployed;
use hytask::machine::Machine;
use serde_json::{json, Value};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

struct Args {
    clients: usize,
    window_s: f64,
    pairs: usize,
}

fn parse_args() -> Args {
    let mut a = Args {
        clients: 50,
        window_s: 5.0,
        pairs: 3,
    };
    let mut it = std::env::args().skip(1);
    while let Some(k) = it.next() {
        let v = it.next().unwrap_or_default();
        match k.as_str() {
            "--clients" => a.clients = v.parse().expect("--clients N"),
            "--window-s" => a.window_s = v.parse().expect("--window-s S"),
            "--pairs" => a.pairs = v.parse().expect("--pairs N"),
            other => panic!("unknown argument {other}"),
        }
    }
    a
}

/// Wake-up latency over a window, from histogram count deltas (1 µs buckets).
struct Window {
    p50_us: f64,
    p99_us: f64,
    max_us: f64,
    over_100us: u64,
    samples: u64,
}

fn window(before: &[u64], after: &[u64], bucket_ns: u64) -> Window {
    let d: Vec<u64> = after.iter().zip(before).map(|(a, b)| a - b).collect();
    let total: u64 = d.iter().sum();
    let q = |p: f64| {
        let target = (total as f64 * p).ceil() as u64;
        let mut acc = 0;
        for (i, c) in d.iter().enumerate() {
            acc += c;
            if acc >= target.max(1) {
                return (i as u64 + 1) * bucket_ns;
            }
        }
        d.len() as u64 * bucket_ns
    };
    let max = d
        .iter()
        .rposition(|&c| c > 0)
        .map_or(0, |i| (i as u64 + 1) * bucket_ns);
    let over = d.iter().skip((100_000 / bucket_ns) as usize).sum();
    Window {
        p50_us: q(0.5) as f64 / 1000.0,
        p99_us: q(0.99) as f64 / 1000.0,
        max_us: max as f64 / 1000.0,
        over_100us: over,
        samples: total,
    }
}

fn rss_kib() -> u64 {
    std::fs::read_to_string("/proc/self/status")
        .unwrap_or_default()
        .lines()
        .find_map(|l| l.strip_prefix("VmRSS:"))
        .and_then(|v| v.trim().trim_end_matches(" kB").trim().parse().ok())
        .unwrap_or(0)
}

fn main() {
    let args = parse_args();
    let cfg_path =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/sim-fast.toml");
    let cfg = hytask::config::load(&cfg_path).unwrap();
    let machine = Machine::deploy(cfg).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let socket = dir.path().join("control.sock");
    let listener = hytask::control::server::bind(&hytask::control::server::SocketOptions {
        path: socket.clone(),
        mode: 0o600,
        group: None,
    })
    .unwrap();
    let (stop_tx, stop_rx) = tokio::sync::oneshot::channel::<()>();
    let served: Arc<dyn Deployed> = machine.clone();
    let server = std::thread::spawn(move || {
        hytask::daemon::run(served, listener, async move {
            let _ = stop_rx.await;
        })
    });
    let mut c = Client::connect(&socket).unwrap();
    c.call("estop.reset", Value::Null).unwrap();
    c.call("machine.on", Value::Null).unwrap();
    c.call("home", Value::Null).unwrap();
    while c.call("status", Value::Null).unwrap()["mode"] != json!("idle") {
        std::thread::sleep(Duration::from_millis(20));
    }
    let job = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/jobs/long.ngc");
    c.call("job.load", json!({"path": job.display().to_string()}))
        .unwrap();
    c.call("job.run", Value::Null).unwrap();
    std::thread::sleep(Duration::from_millis(500));
    // Before any client thread exists: with mlockall(MCL_FUTURE) every new thread's stack is
    // locked and resident, so the load's own threads would inflate the figure.
    let rss_running = rss_kib();
    println!(
        "realtime {}  clients {}  window {} s  pairs {}",
        machine.realtime(),
        args.clients,
        args.window_s,
        args.pairs
    );
    let servo = machine.servo_thread().clone();
    let hist = || servo.stats.wakeup.histogram().counts();
    let bucket_ns = servo.stats.wakeup.histogram().bucket_ns();
    let mut ratios = Vec::new();
    let mut all_lat: Vec<Duration> = Vec::new();
    let mut total_req = 0usize;
    let mut loaded_s = 0.0;
    for pair in 0..args.pairs {
        let mut pair_p99 = [0.0; 2];
        for (k, loaded) in [false, true].into_iter().enumerate() {
            let before = hist();
            let t0 = Instant::now();
            let stop = Arc::new(AtomicBool::new(false));
            let workers: Vec<_> = (0..if loaded { args.clients } else { 0 })
                .map(|_| {
                    let socket = socket.clone();
                    let stop = stop.clone();
                    std::thread::spawn(move || {
                        let mut c = Client::connect(&socket).unwrap();
                        let mut lat = Vec::with_capacity(50_000);
                        while !stop.load(Ordering::Relaxed) {
                            let t = Instant::now();
                            c.call("status", Value::Null).unwrap();
                            lat.push(t.elapsed());
                        }
                        lat
                    })
                })
                .collect();
            std::thread::sleep(Duration::from_secs_f64(args.window_s));
            stop.store(true, Ordering::Relaxed);
            let mut lat: Vec<Duration> = workers
                .into_iter()
                .flat_map(|w| w.join().unwrap())
                .collect();
            let secs = t0.elapsed().as_secs_f64();
            let w = window(&before, &hist(), bucket_ns);
            pair_p99[k] = w.p99_us;
            let mut line = format!(
                "pair {pair} {:<8} servo wake-up p50 {:6.1} µs  p99 {:6.1} µs  max {:8.1} µs  >100µs {:4} of {:6}",
                if loaded { "loaded" } else { "idle" },
                w.p50_us,
                w.p99_us,
                w.max_us,
                w.over_100us,
                w.samples
            );
            if loaded {
                lat.sort();
                let pct = |p: f64| lat[((lat.len() - 1) as f64 * p) as usize];
                line += &format!(
                    "  | {:7.0} req/s  p50 {:?}  p99 {:?}",
                    lat.len() as f64 / secs,
                    pct(0.5),
                    pct(0.99)
                );
                total_req += lat.len();
                loaded_s += secs;
                all_lat.extend(lat);
            }
            println!("{line}");
        }
        ratios.push(pair_p99[1] / pair_p99[0].max(1e-9));
    }
    all_lat.sort();
    let pct = |p: f64| all_lat[((all_lat.len() - 1) as f64 * p) as usize];
    println!(
        "status requests: {:.0} req/s over loaded windows, p50 {:?}, p99 {:?}",
        total_req as f64 / loaded_s,
        pct(0.5),
        pct(0.99)
    );
    println!(
        "servo p99 ratio loaded/idle per pair: {}",
        ratios
            .iter()
            .map(|r| format!("{r:.2}"))
            .collect::<Vec<_>>()
            .join(" ")
    );
    println!(
        "daemon RSS while running the job (before the load's client threads): {:.1} MiB",
        rss_running as f64 / 1024.0
    );
    let _ = c.call("job.abort", Value::Null);
    drop(c);
    let _ = stop_tx.send(());
    server.join().unwrap().unwrap();
}
