//! End to end: M66 and #5399 on the real `hytask serve` binary (issue 11), on a simulated
//! clock (see `tests/support/mod.rs`). A job runs to its M66, the machine waits there for a
//! simulated input (set by the test through `sim.input`) or the timeout (simulated time),
//! and the program goes on with #5399: the value read, or -1 after a timeout. Which branch
//! the program took shows in where the machine ends. `status` shows the M66 the job waits at.
//!
//! The waits that the test ends through the input have timeouts far beyond the hang guard,
//! so only the input can end them, whenever the test's request lands.
#![allow(clippy::unwrap_used)]

mod support;

use hytask::control::client::Client;
use serde_json::{json, Value};
use std::time::Duration;
use support::*;

/// Hang guard of every wait below.
const GUARD: Duration = Duration::from_secs(180);

/// M66 P1 is the `probe` input of the simulated mill (no touch plate here: only the test
/// drives it). A timeout takes X20; a satisfied wait X[30 + #5399] = X31.
fn branch(q: &str) -> String {
    format!(
        "G21 G90\nG0 X10 Y10\nM66 P1 L1 Q{q}\n\
         O100 if [#5399 LT 0]\n  G0 X20\nO100 else\n  G0 X[30 + #5399]\nO100 endif\nM2\n"
    )
}

fn probe_input(c: &mut Client, on: bool) {
    ok(
        c,
        "sim.input",
        json!({"name": "probe", "value": u8::from(on)}),
    );
}

/// Waits until the job stands at the M66 of line 3, waiting for its input; returns that status.
fn waiting_at_the_m66(c: &mut Client) -> Value {
    let s = wait_status(c, "the job waiting at its M66", GUARD, |s| {
        !s["job"]["input_wait"].is_null()
    });
    assert_eq!(
        s["job"]["input_wait"],
        json!({"line": 3, "input": "digital", "index": 1, "until": "rise"}),
        "{s}"
    );
    assert_eq!(s["job"]["state"], json!("running"));
    s
}

fn x(s: &Value) -> f64 {
    axis(s, "X")["actual"].as_f64().unwrap()
}

#[test]
fn a_job_branches_on_5399_after_a_timed_out_and_after_a_satisfied_m66() {
    let d = Daemon::start_sim();
    let mut c = d.client();
    ready(&mut c);
    probe_input(&mut c, false);

    // Nothing raises the input: the wait times out after 0.5 s of machine time, #5399 = -1,
    // and the job goes on (a timeout is not an error).
    run_text(&mut c, &branch("0.5"), "m66-timeout.ngc");
    let s = wait_job_end(&mut c, "the job after a timed-out M66", GUARD);
    assert_eq!(s["job"]["state"], json!("done"), "{s}");
    assert!((x(&s) - 20.0).abs() < 0.01, "timeout branch: {s}");
    assert!(s["job"]["input_wait"].is_null(), "{s}");

    // The same program, the input raised while the machine waits: a rising edge, #5399 = 1.
    run_text(&mut c, &branch("100000"), "m66-input.ngc");
    let s = waiting_at_the_m66(&mut c);
    assert!((x(&s) - 10.0).abs() < 0.01, "held at the M66: {s}");
    probe_input(&mut c, true);
    let s = wait_job_end(&mut c, "the job after a satisfied M66", GUARD);
    assert_eq!(s["job"]["state"], json!("done"), "{s}");
    assert!((x(&s) - 31.0).abs() < 0.01, "X[30 + #5399]: {s}");
}

/// A daemon whose job `name` waits at its M66 for an input that nothing raises.
fn held_at_an_m66(name: &str) -> (Daemon, Client) {
    let d = Daemon::start_sim();
    let mut c = d.client();
    ready(&mut c);
    probe_input(&mut c, false);
    run_text(&mut c, &branch("100000"), name);
    waiting_at_the_m66(&mut c);
    (d, c)
}

#[test]
fn an_abort_at_an_m66_stops_the_job_and_the_machine_takes_the_next_one() {
    let (d, mut c) = held_at_an_m66("m66-abort.ngc");
    // `hytask status` says what the job waits for.
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_hytask"))
        .arg("status")
        .arg("--socket")
        .arg(&d.socket)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{stdout}");
    assert!(
        stdout.contains("waiting at line 3: M66 on digital input 1 (rise)"),
        "{stdout}"
    );
    ok(&mut c, "job.abort", Value::Null);
    let s = wait_job_end(&mut c, "the aborted job", GUARD);
    assert_eq!(s["job"]["state"], json!("aborted"), "{s}");
    assert_eq!(s["mode"], json!("idle"), "{s}");
    assert!(s["job"]["input_wait"].is_null(), "{s}");
    assert!((x(&s) - 10.0).abs() < 0.01, "{s}");
    // The input rising now moves nothing.
    probe_input(&mut c, true);
    ok(&mut c, "mdi", json!({"line": "G0 X5"}));
    let s = wait_job_end(&mut c, "mdi after the abort", GUARD);
    assert_eq!(s["job"]["state"], json!("done"), "{s}");
    assert!((x(&s) - 5.0).abs() < 0.01, "{s}");
}

#[test]
fn an_estop_at_an_m66_fails_the_job() {
    let (_d, mut c) = held_at_an_m66("m66-estop.ngc");
    ok(&mut c, "estop", Value::Null);
    let s = wait_job_end(&mut c, "the job after an e-stop", GUARD);
    assert_eq!(s["job"]["state"], json!("failed"), "{s}");
    assert_eq!(s["mode"], json!("estop"), "{s}");
    assert!(s["job"]["input_wait"].is_null(), "{s}");
    // Back on, the machine runs again.
    ready(&mut c);
    ok(&mut c, "mdi", json!({"line": "G0 X5"}));
    let s = wait_job_end(&mut c, "mdi after the e-stop", GUARD);
    assert_eq!(s["job"]["state"], json!("done"), "{s}");
}
