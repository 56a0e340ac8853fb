//! A job much longer than the 4096-item segment queue on the simulated clock: the feeder
//! waits for room in servo cycles of the runtime's clock (not in wall-clock sleeps), so the
//! job runs as fast as the simulation does and ends at its programmed end pose.
//!
//! Every wait is a hang guard (see `tests/support/mod.rs`).
#![allow(clippy::unwrap_used)]

mod support;

use serde_json::{json, Value};
use std::time::Duration;
use support::*;

/// `n` dwells of one servo period each (a queue item per cycle: 4096 items last 4 s of
/// machine time), between two rapids.
fn dwells(n: usize) -> String {
    let mut text = String::from("G21 G90\nG0 X20 Y100 Z-5\n");
    for _ in 0..n {
        text.push_str("G4 P0.001\n");
    }
    text.push_str("G0 X30 Y90\nM2\n");
    text
}

/// Runs `n` dwells on `d`; returns the final status and the servo cycles the run took.
fn run_dwells(d: &Daemon, n: usize) -> (Value, f64, u64) {
    let mut c = d.client();
    ready(&mut c);
    let before = ok(&mut c, "status", Value::Null)["servo_cycle"]
        .as_u64()
        .unwrap();
    let info = run_text(&mut c, &dwells(n), "dwells.ngc");
    assert_eq!(info["lines"], json!(n + 4));
    let planned = info["planned_time_s"].as_f64().unwrap();
    let s = wait_job_end(&mut c, "the job's end", Duration::from_secs(600));
    assert_eq!(s["job"]["state"], json!("done"), "{}", s["job"]);
    let x = axis(&s, "X")["actual"].as_f64().unwrap();
    let y = axis(&s, "Y")["actual"].as_f64().unwrap();
    assert!(
        (x - 30.0).abs() < 1e-3 && (y - 90.0).abs() < 1e-3,
        "X {x} Y {y}"
    );
    // The last line (M2), however long ago the last progress sample was taken.
    assert_eq!(s["job"]["line"], json!(n + 4), "{}", s["job"]);
    let cycles = s["servo_cycle"].as_u64().unwrap() - before;
    (s, planned, cycles)
}

#[test]
fn a_job_of_25000_segments_runs_to_its_end_on_the_paced_simulated_clock() {
    let d = Daemon::start_sim();
    let (_, planned, cycles) = run_dwells(&d, 25_000);
    // The queue never ran dry: the job took its planned time plus the settling at its end.
    let planned_cycles = (planned / 1e-3).round() as u64;
    assert!(
        cycles < planned_cycles + 2_000,
        "{cycles} servo cycles for a job planned in {planned_cycles}"
    );
}

/// Unpaced, the machine takes hundreds of cycles per millisecond of wall time: the feeder
/// keeps up (and the job ends at once) only because it waits in servo cycles.
#[test]
fn a_job_of_25000_segments_runs_to_its_end_on_the_unpaced_simulated_clock() {
    let d = Daemon::start_sim_with(0, None);
    let (s, _, _) = run_dwells(&d, 25_000);
    assert_eq!(s["job"]["progress"], json!(1.0), "{}", s["job"]);
}
