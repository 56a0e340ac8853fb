//! Modbus TCP on loopback against the in-process simulator (`hytask modbus-sim`'s engine):
//!
//! 1. throughput and round trip: the link poller (merged reads of a panel map, polling as
//!    fast as it can) side by side with a bare `tokio-modbus` client loop doing the same
//!    reads, same connection type, same simulator; transactions/s, mean and p99 per
//!    transaction, and the ratio;
//! 2. latency at a 10 ms poll rate: an input changed at the simulator until the image the
//!    servo thread reads has it, and an output commanded by the servo side until the
//!    simulator's coil has it (p50/p99).
//!
//! Run: `cargo bench --bench modbus_poll` (a plain main, not criterion: it measures a
//! network loop, not a function). Figures in benches/README.md, Modbus section.
#![allow(clippy::unwrap_used)]

use hytask::modbus::link::{Link, TxStats};
use hytask::modbus::sim::{serve_tcp, Sim};
use hytask::modbus::{Endpoint, LinkConfig};
use hytask_hal::modbus::{plan_reads, PointSpec, Quality, Table};
use std::sync::mpsc::channel;
use std::sync::Arc;
use std::time::{Duration, Instant};
use tokio_modbus::client::Reader;

const MAP: &str = r#"
name = "panel"
backend = "modbus_tcp"
address = "127.0.0.1:1"
unit_id = 1
digital_inputs = [
    { name = "i0" }, { name = "i1" }, { name = "i2" }, { name = "i3" },
    { name = "i4" }, { name = "i5" }, { name = "i6" }, { name = "i7" },
]
digital_outputs = [{ name = "o0" }, { name = "o1" }, { name = "o2" }, { name = "o3" }]
analog_inputs = [{ name = "a0" }, { name = "a1" }, { name = "a2", type = "f32" }]
"#;

fn pct(v: &mut [f64], p: f64) -> f64 {
    v.sort_by(|a, b| a.total_cmp(b));
    v[((v.len() as f64 - 1.0) * p).round() as usize]
}

fn start_sim(io: &hytask::config::IoConfig) -> (Sim, String) {
    let sim = Sim::from_io(std::slice::from_ref(io), 256).unwrap();
    let (tx, rx) = channel();
    let s = sim.clone();
    std::thread::spawn(move || {
        let rt = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .unwrap();
        rt.block_on(async move {
            let l = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
            tx.send(l.local_addr().unwrap().to_string()).unwrap();
            serve_tcp(s, l).await.unwrap();
        });
    });
    (sim, rx.recv().unwrap())
}

fn run_link(
    io: &hytask::config::IoConfig,
    addr: &str,
    poll_ms: u64,
) -> (hytask::modbus::UnitConfig, Arc<TxStats>) {
    let mut u = hytask::modbus::unit(io, "io[0]", "-").unwrap();
    u.poll = Duration::from_millis(poll_ms);
    u.refresh = None;
    let cfg = LinkConfig {
        name: "bench".into(),
        endpoint: Endpoint::Tcp(addr.to_string()),
        timeout: Duration::from_millis(500),
        max_backoff: Duration::from_millis(100),
        units: vec![u.clone()],
    };
    let (tx, rx) = channel();
    let link = Link::new(cfg, tx);
    let stats = link.stats();
    std::thread::spawn(move || {
        let _keep = rx;
        tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .unwrap()
            .block_on(link.run());
    });
    (u, stats)
}

/// The bare client: the same reads as the poller's plan, back to back; per-transaction
/// round trips in µs.
fn bare(addr: &str, specs: &[Option<PointSpec>], n: usize) -> (Vec<f64>, f64) {
    let blocks = plan_reads(specs, 0);
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    rt.block_on(async {
        let sa = addr.parse().unwrap();
        let mut ctx = tokio_modbus::client::tcp::connect_slave(sa, tokio_modbus::Slave(1))
            .await
            .unwrap();
        let mut rtts = Vec::with_capacity(n);
        let t0 = Instant::now();
        for i in 0..n {
            let b = &blocks[i % blocks.len()];
            let t = Instant::now();
            match b.table {
                Table::Coil => drop(ctx.read_coils(b.start, b.count).await.unwrap().unwrap()),
                Table::DiscreteInput => drop(
                    ctx.read_discrete_inputs(b.start, b.count)
                        .await
                        .unwrap()
                        .unwrap(),
                ),
                Table::HoldingRegister => drop(
                    ctx.read_holding_registers(b.start, b.count)
                        .await
                        .unwrap()
                        .unwrap(),
                ),
                Table::InputRegister => drop(
                    ctx.read_input_registers(b.start, b.count)
                        .await
                        .unwrap()
                        .unwrap(),
                ),
            }
            rtts.push(t.elapsed().as_secs_f64() * 1e6);
        }
        (rtts, n as f64 / t0.elapsed().as_secs_f64())
    })
}

fn main() {
    let io: hytask::config::IoConfig = toml::from_str(MAP).unwrap();
    let (sim, addr) = start_sim(&io);
    let u = hytask::modbus::unit(&io, "io[0]", "-").unwrap();
    let specs: Vec<Option<PointSpec>> = u.inputs.iter().map(|p| Some(p.spec)).collect();
    let per_cycle = plan_reads(&specs, 0).len();
    // `cargo test --all-targets` runs this main without `--bench`: a short smoke run then.
    let bench = std::env::args().any(|a| a == "--bench");
    let secs = std::env::var("MODBUS_BENCH_S")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(5);
    let window = if bench {
        Duration::from_secs(secs)
    } else {
        Duration::from_millis(200)
    };

    // 1a. Bare tokio-modbus loop.
    let _ = bare(&addr, &specs, 500); // warm up
    let t0 = Instant::now();
    let mut all = Vec::new();
    let mut rates = Vec::new();
    while t0.elapsed() < window {
        let (r, rate) = bare(&addr, &specs, 2000);
        all.extend(r);
        rates.push(rate);
    }
    let bare_rate = rates.iter().sum::<f64>() / rates.len() as f64;
    let bare_mean = all.iter().sum::<f64>() / all.len() as f64;
    let bare_p99 = pct(&mut all, 0.99);

    // 1b. The poller, polling as fast as it can (poll = 0); its own round-trip histogram
    // (10 us bins) and the transactions counted at the simulator.
    let (poller, stats) = run_link(&io, &addr, 0);
    let img = poller.image.clone();
    while img.di[0].sample().quality != Quality::Good {
        std::thread::sleep(Duration::from_millis(1));
    }
    std::thread::sleep(Duration::from_millis(500)); // warm up
    let (r0, n0) = (sim.lock().requests, stats.count());
    let t0 = Instant::now();
    std::thread::sleep(window);
    let poll_rate = (sim.lock().requests - r0) as f64 / t0.elapsed().as_secs_f64();
    let n = stats.count() - n0;
    img.close();
    let (poll_p50, poll_p99) = (stats.quantile_us(0.5), stats.quantile_us(0.99));
    let bare_p50 = pct(&mut all, 0.5);
    println!("transactions per poll cycle: {per_cycle}; poller transactions measured: {n}");
    println!(
        "bare tokio-modbus: {bare_rate:.0} tx/s, mean {bare_mean:.1} us, p50 {bare_p50:.1} us, p99 {bare_p99:.1} us"
    );
    println!(
        "poller:            {poll_rate:.0} tx/s, p50 <= {poll_p50} us, p99 <= {poll_p99} us (10 us bins)"
    );
    println!(
        "ratio poller/bare: throughput {:.2}x, p50 {:.2}x, p99 {:.2}x",
        poll_rate / bare_rate,
        poll_p50 as f64 / bare_p50,
        poll_p99 as f64 / bare_p99
    );

    // 2. Latencies at a 10 ms poll rate.
    let (u, _) = run_link(&io, &addr, 10);
    let img = u.image.clone();
    while img.di[0].sample().quality != Quality::Good {
        std::thread::sleep(Duration::from_millis(1));
    }
    let samples = if bench { 200 } else { 10 };
    let mut input = Vec::new();
    let mut output = Vec::new();
    for k in 0..samples {
        let level = f64::from(u8::from(k % 2 == 0));
        // Desynchronise from the poll phase.
        std::thread::sleep(Duration::from_micros(1000 + (k as u64 * 3779) % 9000));
        let t = Instant::now();
        sim.lock().set("i3", level).unwrap();
        while img.di[3].sample().value != level {
            std::thread::sleep(Duration::from_micros(50));
        }
        input.push(t.elapsed().as_secs_f64() * 1e3);
        let t = Instant::now();
        img.dout[1].command(level);
        while sim.lock().get("o1").unwrap() != level {
            std::thread::sleep(Duration::from_micros(50));
        }
        output.push(t.elapsed().as_secs_f64() * 1e3);
    }
    println!(
        "input change -> image at 10 ms poll: p50 {:.2} ms, p99 {:.2} ms ({samples} samples)",
        pct(&mut input, 0.5),
        pct(&mut input, 0.99)
    );
    println!(
        "output command -> coil at the simulator: p50 {:.2} ms, p99 {:.2} ms",
        pct(&mut output, 0.5),
        pct(&mut output, 0.99)
    );
}
