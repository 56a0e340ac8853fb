//! Modbus TCP on loopback against the in-process simulator (`hytask modbus-sim`'s engine):
//!
//! 1. throughput and round trip: the link poller (merged reads of a panel map, polling as
//!    fast as it can) side by side with a bare `tokio-modbus` client loop doing the same
//!    reads against the same simulator. The machine is a shared 2-vCPU VM whose load moves
//!    between seconds, so the sides run in short alternating windows, many rounds, in a
//!    rotating order, and each round gives a ratio; the figure is the median ratio with its
//!    spread. A second bare loop (A/A) in every round measures the noise band of the method.
//! 2. latency at a 10 ms poll rate: an input changed at the simulator until the image the
//!    servo thread reads has it, and an output commanded by the servo side until the
//!    simulator's coil has it (p50/p99). The daemon-level latencies (control socket event,
//!    M-code) are `benches/modbus_latency.rs`.
//!
//! Run: `cargo bench --bench modbus_poll` (a plain main, not criterion: it measures a
//! network loop, not a function). `MODBUS_BENCH_ROUNDS` (default 12) and
//! `MODBUS_BENCH_WINDOW_MS` (default 300) size part 1. Figures in benches/README.md, Modbus
//! section.
#![allow(clippy::unwrap_used)]

#[path = "../tests/modbus_support/mod.rs"]
mod modbus_support;

use hytask::modbus::link::Link;
use hytask::modbus::sim::Sim;
use hytask::modbus::stats::{quantile_us, window, TxStats};
use hytask::modbus::{Endpoint, LinkConfig, UnitConfig};
use hytask_hal::modbus::{plan_reads, PointSpec, Quality, ReadBlock, Table};
use modbus_support::{serve_sim, tid};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::channel;
use std::sync::Arc;
use std::thread::JoinHandle;
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

/// A named thread (the name shows in `perf report --sort comm`).
fn spawn(name: &str, f: impl FnOnce() + Send + 'static) -> JoinHandle<()> {
    std::thread::Builder::new()
        .name(name.into())
        .spawn(f)
        .unwrap()
}

/// Time thread `tid` of this process spent on a CPU and waiting for one, in ns
/// (`/proc/self/task/TID/schedstat`).
fn sched_ns(tid: i32) -> (u64, u64) {
    let s = std::fs::read_to_string(format!("/proc/self/task/{tid}/schedstat")).unwrap_or_default();
    let mut f = s.split_whitespace().map(|x| x.parse().unwrap_or(0));
    (f.next().unwrap_or(0), f.next().unwrap_or(0))
}

fn current_thread() -> tokio::runtime::Runtime {
    tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap()
}

/// A poller for the panel on its own thread with a current-thread runtime, as the daemon
/// runs one (`hytask::modbus::start`).
fn run_link(
    io: &hytask::config::IoConfig,
    addr: &str,
    poll_ms: u64,
) -> (UnitConfig, Arc<TxStats>, JoinHandle<()>, i32) {
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
    let (id_tx, id_rx) = channel();
    let thread = spawn("ours", move || {
        let _keep = rx;
        id_tx.send(tid()).unwrap();
        current_thread().block_on(link.run());
    });
    while u.image.di[0].sample().quality != Quality::Good {
        std::thread::sleep(Duration::from_millis(1));
    }
    (u, stats, thread, id_rx.recv().unwrap())
}

async fn bare_read(ctx: &mut tokio_modbus::client::Context, b: &ReadBlock) {
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
}

/// The bare client on its own thread with a current-thread runtime: the poller's reads,
/// back to back, each timed into `stats`, until `stop`. Returns once connected.
fn run_bare(addr: &str, blocks: Vec<ReadBlock>, stats: Arc<TxStats>) -> Bare {
    let stop = Arc::new(AtomicBool::new(false));
    let (ready_tx, ready) = channel();
    let (sa, halt) = (addr.parse().unwrap(), stop.clone());
    let thread = spawn("bare", move || {
        let id = tid();
        current_thread().block_on(async move {
            let mut ctx = tokio_modbus::client::tcp::connect_slave(sa, tokio_modbus::Slave(1))
                .await
                .unwrap();
            let mut i = 0;
            while !halt.load(Ordering::Relaxed) {
                let t = Instant::now();
                bare_read(&mut ctx, &blocks[i % blocks.len()]).await;
                stats.record(t.elapsed());
                i += 1;
                if i == blocks.len() {
                    let _ = ready_tx.send(id);
                }
            }
        });
    });
    let tid = ready.recv().unwrap();
    Bare { stop, thread, tid }
}

struct Bare {
    stop: Arc<AtomicBool>,
    thread: JoinHandle<()>,
    tid: i32,
}

#[derive(Clone, Copy, PartialEq)]
enum Side {
    Ours,
    Bare,
    /// The same bare loop again: the A/A reference.
    Bare2,
}

/// One side's window: transactions/s counted at the simulator, its round-trip histogram,
/// and per transaction the CPU time of the client's thread and of the simulator's thread
/// and the client's wait for a CPU (run queue), in ns.
struct Window {
    rate: f64,
    hist: Vec<u64>,
    cpu: f64,
    sim_cpu: f64,
    runq: f64,
}

/// Runs `side` for `dur` after a short warm-up, on a fresh connection; measured the same
/// way for every side: the simulator's request counter and a `TxStats` histogram.
fn measure(
    side: Side,
    io: &hytask::config::IoConfig,
    sim: &(Sim, i32),
    addr: &str,
    dur: Duration,
) -> Window {
    let (stats, client);
    let (sim, sim_tid) = (&sim.0, sim.1);
    let stop: Box<dyn FnOnce()> = match side {
        Side::Ours => {
            let (u, s, thread, id) = run_link(io, addr, 0);
            (stats, client) = (s, id);
            Box::new(move || {
                u.image.close();
                thread.join().unwrap();
            })
        }
        Side::Bare | Side::Bare2 => {
            let u = hytask::modbus::unit(io, "io[0]", "-").unwrap();
            let specs: Vec<Option<PointSpec>> = u.inputs.iter().map(|p| Some(p.spec)).collect();
            stats = Arc::new(TxStats::default());
            let b = run_bare(addr, plan_reads(&specs, 0), stats.clone());
            client = b.tid;
            Box::new(move || {
                b.stop.store(true, Ordering::Relaxed);
                b.thread.join().unwrap();
            })
        }
    };
    std::thread::sleep(Duration::from_millis(30)); // warm-up
    let at = || {
        let (c, q) = sched_ns(client);
        (
            stats.snapshot(),
            sim.lock().requests,
            Instant::now(),
            c,
            q,
            sched_ns(sim_tid).0,
        )
    };
    let (h0, r0, t0, c0, q0, s0) = at();
    std::thread::sleep(dur);
    let (h1, r1, t1, c1, q1, s1) = at();
    stop();
    let n = (r1 - r0).max(1) as f64;
    Window {
        rate: (r1 - r0) as f64 / (t1 - t0).as_secs_f64(),
        hist: window(&h0, &h1),
        cpu: (c1 - c0) as f64 / n,
        sim_cpu: (s1 - s0) as f64 / n,
        runq: (q1 - q0) as f64 / n,
    }
}

/// Quartiles and extremes of a sample: `[min, q1, median, q3, max]`.
fn spread(v: &[f64]) -> [f64; 5] {
    let mut s = v.to_vec();
    [0.0, 0.25, 0.5, 0.75, 1.0].map(|p| pct(&mut s, p))
}

fn show(name: &str, v: &[f64]) {
    let [min, q1, med, q3, max] = spread(v);
    println!(
        "  {name:<34} median {med:.3}  (quartiles {q1:.3} .. {q3:.3}, range {min:.3} .. {max:.3})"
    );
}

fn throughput(io: &hytask::config::IoConfig, sim: &(Sim, i32), addr: &str, bench: bool) {
    let env = |k: &str, d: u64| {
        std::env::var(k)
            .ok()
            .and_then(|s| s.parse().ok())
            .unwrap_or(d)
    };
    let (rounds, dur) = if bench {
        (
            env("MODBUS_BENCH_ROUNDS", 12),
            Duration::from_millis(env("MODBUS_BENCH_WINDOW_MS", 300)),
        )
    } else {
        (2, Duration::from_millis(50)) // `cargo test --all-targets`: a smoke run
    };
    const ORDERS: [[Side; 3]; 6] = {
        use Side::{Bare as B, Bare2 as A, Ours as O};
        [
            [O, B, A],
            [B, A, O],
            [A, O, B],
            [O, A, B],
            [A, B, O],
            [B, O, A],
        ]
    };
    // Per round, ours / bare and bare again / bare: tx/s, p50, p99, client CPU per tx.
    let mut ratio: [Vec<f64>; 4] = Default::default();
    let mut aa: [Vec<f64>; 4] = Default::default();
    let mut per_tx: [Vec<(f64, f64, f64)>; 3] = Default::default();
    let mut pooled = [vec![0u64; 0], Vec::new(), Vec::new()];
    let mut rates = [Vec::new(), Vec::new(), Vec::new()];
    for r in 0..rounds as usize {
        let mut w: [Option<Window>; 3] = [None, None, None];
        for side in ORDERS[r % ORDERS.len()] {
            w[side as usize] = Some(measure(side, io, sim, addr, dur));
        }
        let [o, b, a] = w.map(Option::unwrap);
        let q = |w: &Window, p| quantile_us(&w.hist, p) as f64;
        for (out, x) in [(&mut ratio, &o), (&mut aa, &a)] {
            out[0].push(x.rate / b.rate);
            out[1].push(q(x, 0.5) / q(&b, 0.5));
            out[2].push(q(x, 0.99) / q(&b, 0.99));
            out[3].push(x.cpu / b.cpu);
        }
        for (k, x) in [o, b, a].into_iter().enumerate() {
            rates[k].push(x.rate);
            per_tx[k].push((x.cpu, x.sim_cpu, x.runq));
            if pooled[k].is_empty() {
                pooled[k] = x.hist;
            } else {
                pooled[k].iter_mut().zip(&x.hist).for_each(|(p, h)| *p += h);
            }
        }
    }
    println!(
        "throughput: {rounds} rounds of 3 windows of {} ms (ours, bare, bare again), rotating order",
        dur.as_millis()
    );
    for (k, name) in ["poller (ours)", "bare tokio-modbus", "bare again (A/A)"]
        .iter()
        .enumerate()
    {
        let med = |f: fn(&(f64, f64, f64)) -> f64| {
            spread(&per_tx[k].iter().map(f).collect::<Vec<_>>())[2]
        };
        println!(
            "  {name:<18} median {:>6.0} tx/s; pooled round trip p50 {} us, p99 {} us ({} tx); \
             per tx (median): client CPU {:.1} us, simulator CPU {:.1} us, client waiting for a CPU {:.1} us",
            spread(&rates[k])[2],
            quantile_us(&pooled[k], 0.5),
            quantile_us(&pooled[k], 0.99),
            pooled[k].iter().sum::<u64>(),
            med(|x| x.0) / 1e3,
            med(|x| x.1) / 1e3,
            med(|x| x.2) / 1e3,
        );
    }
    for (title, r) in [
        ("ours / bare", &ratio),
        ("bare again / bare (A/A, the noise band)", &aa),
    ] {
        println!("per-round ratios, {title}:");
        show("throughput", &r[0]);
        show("round trip p50", &r[1]);
        show("round trip p99", &r[2]);
        show("client CPU per transaction", &r[3]);
    }
}

/// Part 2: latencies at a 10 ms poll rate, at the image.
fn latency(io: &hytask::config::IoConfig, sim: &Sim, addr: &str, bench: bool) {
    let (u, ..) = run_link(io, addr, 10);
    let img = u.image.clone();
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
    img.close();
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

fn main() {
    let io: hytask::config::IoConfig = toml::from_str(MAP).unwrap();
    let sim = Sim::from_io(std::slice::from_ref(&io), 256).unwrap();
    let (addr, sim_tid) = serve_sim(&sim);
    // `cargo test --all-targets` runs this main without `--bench`: a short smoke run then.
    let bench = std::env::args().any(|a| a == "--bench");
    let u = hytask::modbus::unit(&io, "io[0]", "-").unwrap();
    let specs: Vec<Option<PointSpec>> = u.inputs.iter().map(|p| Some(p.spec)).collect();
    println!(
        "transactions per poll cycle: {}",
        plan_reads(&specs, 0).len()
    );
    let sim = (sim, sim_tid);
    throughput(&io, &sim, &addr, bench);
    let sim = sim.0;
    latency(&io, &sim, &addr, bench);
}
