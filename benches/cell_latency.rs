//! Servo-thread wake-up latency of the pick-and-place cell, side by side in one run:
//! idle (the selection homed, the camera idle), with the camera detecting back to back (a
//! non-periodic task at the selection thread's lower priority filtering 320×240 frames), and
//! with the cell sorting objects (selection, robot moves, camera), then idle again (the
//! A/A check: how much two identical windows differ here).
//!
//! Run: `cargo bench --bench cell_latency` (as root for `SCHED_FIFO`; a plain main, not
//! criterion: it measures a thread's timing, not a function). `CELL_BENCH_SECS` sets the
//! window length (default 20 s). Figures in benches/README.md, cell section. Under
//! `cargo test --all-targets` (no `--bench`) it runs 1 s windows as a smoke test.

use hytask::cell::camera::CameraCmd;
use hytask::cell::config::CellConfig;
use hytask::cell::deploy::deploy;
use hytask::cell::names;
use hytask::cell::selection::{SelectionCmd, SelectionState, SelectionStatus};
use hytask::rt::prelude::*;
use std::time::{Duration, Instant};

#[derive(Clone, Copy, PartialEq)]
enum Load {
    Idle,
    Detecting,
    Sorting,
}

fn window(load: Load, secs: u64) -> Result<String, Box<dyn std::error::Error>> {
    let cell = deploy(&CellConfig::with_seed(42))?;
    let camera = cell.camera.clone();
    let selection = cell.selection.clone();
    let rt = cell.deployment.start()?;
    let mut status = rt.reader::<SelectionStatus>(names::SELECTION_STATUS)?;
    let t0 = Instant::now();
    while !status
        .latest()
        .is_some_and(|s| s.state == SelectionState::Homed && s.entered)
    {
        if t0.elapsed() > Duration::from_secs(30) {
            return Err("the cell did not home".into());
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    let servo = rt.threads()[0].clone();
    // The window starts now: earlier samples (start-up) are left out by difference.
    let before = servo.stats.wakeup.histogram().counts();
    let end = Instant::now() + Duration::from_secs(secs);
    let mut detections = 0u64;
    let mut sort: Option<CommandHandle> = None;
    while Instant::now() < end {
        match load {
            Load::Idle => std::thread::sleep(Duration::from_millis(50)),
            Load::Detecting => {
                let h = camera.send(CameraCmd::StartDetection)?;
                if h.wait(Duration::from_secs(5)) == CommandStatus::Done {
                    detections += 1;
                }
            }
            Load::Sorting => {
                if sort.as_ref().is_none_or(|h| h.status().is_final()) {
                    sort = Some(selection.send(SelectionCmd::Run(1000))?);
                }
                std::thread::sleep(Duration::from_millis(50));
            }
        }
    }
    let after = servo.stats.wakeup.histogram().counts();
    let realtime = rt.realtime();
    let overruns = servo.stats.overruns();
    rt.stop();
    let counts: Vec<u64> = after.iter().zip(&before).map(|(a, b)| a - b).collect();
    let n: u64 = counts.iter().sum();
    let q = |p: f64| {
        let target = (p * n as f64).ceil() as u64;
        let mut acc = 0;
        for (i, c) in counts.iter().enumerate() {
            acc += c;
            if acc >= target {
                return i as u64;
            }
        }
        counts.len() as u64
    };
    let above = |us: usize| counts.iter().skip(us).sum::<u64>();
    let name = match load {
        Load::Idle => "idle",
        Load::Detecting => "camera detecting",
        Load::Sorting => "cell sorting",
    };
    Ok(format!(
        "{name:<17} cycles {n:>6}  p50 {:>3} us  p90 {:>3} us  p99 {:>4} us  >50us {:>4}  \
         >100us {:>4}  >500us {:>3}  overruns {overruns}  detections {detections}  realtime {realtime}",
        q(0.5),
        q(0.9),
        q(0.99),
        above(50),
        above(100),
        above(500),
    ))
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let bench = std::env::args().any(|a| a == "--bench");
    let secs = if bench {
        std::env::var("CELL_BENCH_SECS")
            .ok()
            .and_then(|s| s.parse().ok())
            .unwrap_or(20)
    } else {
        1
    };
    if hytask::rt::deploy::check_realtime().fifo_scheduling {
        let _ = hytask::rt::system::lock_memory();
    }
    println!("servo thread wake-up latency, 1 kHz, {secs} s windows (histogram: 1 us buckets)");
    for load in [Load::Idle, Load::Detecting, Load::Sorting, Load::Idle] {
        println!("{}", window(load, secs)?);
    }
    Ok(())
}
