//! Safety paths, each driven end to end through the real daemon and its simulated machine:
//! e-stop (input and command), following error (stalled motor), drive fault, lost drive
//! communication, soft limits (refused before motion). The overrun storm has its own test
//! binary (`tests/daemon_overrun.rs`): it burns CPU at realtime priority on purpose, which
//! must not run beside other tests' servo threads.
//! Every path must end in a stopped machine, a fault event naming axis and value, and a
//! failed job naming its line.
//!
//! These are tests of behaviour: the machine runs on a simulated clock
//! ([`Daemon::start_sim`]), so a loaded host cannot add a spurious overrun trip or change
//! what the machine does, and every wait is a hang guard (see `tests/support/mod.rs`). How
//! fast a trip acts, in servo cycles, is asserted on the stepped runtime
//! (`src/machine/servo/tests.rs`).
#![allow(clippy::unwrap_used)]

mod support;

use serde_json::{json, Value};
use std::time::Duration;
use support::*;

/// Hang guard of every wait.
const GUARD: Duration = Duration::from_secs(120);

fn all_stopped(s: &Value) -> bool {
    at_rest(s, 1e-3)
}

fn drives_off(s: &Value) -> bool {
    s["axes"]
        .as_array()
        .unwrap()
        .iter()
        .all(|a| a["drive_state"] != json!("operation enabled"))
}

/// Starts the long job, waits until it moves, returns the client (subscribed).
fn running_long_job(d: &Daemon) -> hytask::control::client::Client {
    let mut c = d.client();
    ok(&mut c, "subscribe", Value::Null);
    ready(&mut c);
    run_job(&mut c, "jobs/long.ngc");
    wait_status(&mut c, "job moving", GUARD, |s| {
        s["job"]["line"].as_u64().unwrap() >= 6 && s["mode"] == json!("running")
    });
    c
}

#[test]
fn estop_input_quick_stops_makes_outputs_safe_and_refuses_reset_while_pressed() {
    let d = Daemon::start_sim();
    let mut c = running_long_job(&d);
    let before = ok(&mut c, "status", Value::Null);
    assert_eq!(before["outputs"]["spindle_on"], json!(1.0));
    assert_eq!(before["outputs"]["coolant_flood"], json!(1.0));
    ok(&mut c, "sim.input", json!({"name": "estop", "value": 1}));
    let events = wait_event(&mut c, "job failed", GUARD, |e| {
        e.topic == "job" && e.data["state"] == json!("failed")
    });
    assert!(events
        .iter()
        .any(|e| e.topic == "mode" && e.data["mode"] == json!("estop")));
    let job = &events.last().unwrap().data;
    assert!(job["reason"].as_str().unwrap().contains("e-stop"), "{job}");
    assert!(job["reason"].as_str().unwrap().contains("line"), "{job}");
    let s = wait_status(&mut c, "stopped and off", GUARD, |s| {
        all_stopped(s) && drives_off(s)
    });
    assert_eq!(s["mode"], json!("estop"));
    assert!(
        s["outputs"]
            .as_object()
            .unwrap()
            .values()
            .all(|v| v == &json!(0.0)),
        "{}",
        s["outputs"]
    );
    let (code, msg) = err(&mut c, "estop.reset", Value::Null);
    assert_eq!(code, 1);
    assert!(msg.contains("still active"), "{msg}");
    ok(&mut c, "sim.input", json!({"name": "estop", "value": 0}));
    ok(&mut c, "estop.reset", Value::Null);
    assert_eq!(ok(&mut c, "status", Value::Null)["mode"], json!("off"));
    // Nothing runs until the machine is switched on again.
    let (code, _) = err(&mut c, "job.run", Value::Null);
    assert_eq!(code, 1);
}

#[test]
fn estop_command_stops_every_axis_within_a_few_cycles() {
    let d = Daemon::start_sim();
    let mut c = running_long_job(&d);
    ok(&mut c, "estop", Value::Null);
    let s = ok(&mut c, "status", Value::Null);
    assert_eq!(s["mode"], json!("estop"));
    // Quick stop: the drives brake on their quick-stop ramp (2 × max acceleration); from
    // 20 mm/s that is ~10 ms of machine time, asserted cycle by cycle in
    // src/machine/servo/tests.rs (estop_input_quick_stops_every_drive_in_the_same_cycle).
    wait_status(&mut c, "stopped", GUARD, all_stopped);
    wait_status(&mut c, "drives off", GUARD, drives_off);
}

#[test]
fn a_stalled_motor_trips_the_following_error_limit_and_stops_under_control() {
    let d = Daemon::start_sim();
    let mut c = running_long_job(&d);
    ok(&mut c, "sim.fault", json!({"kind": "stall", "axis": "X"}));
    let events = wait_event(&mut c, "fault event", GUARD, |e| e.topic == "fault");
    let f = &events.last().unwrap().data;
    assert_eq!(f["axis"], json!("X"), "{f}");
    assert!(f["value"].as_f64().unwrap().abs() > 1.0, "{f}");
    assert!(
        f["message"].as_str().unwrap().contains("following error"),
        "{f}"
    );
    assert!(f["line"].as_u64().unwrap() >= 6, "{f}");
    let events = wait_event(&mut c, "job failed", GUARD, |e| {
        e.topic == "job" && e.data["state"] == json!("failed")
    });
    let job = &events.last().unwrap().data;
    assert!(job["reason"].as_str().unwrap().contains("line"), "{job}");
    let s = wait_status(&mut c, "stopped, drives off", GUARD, |s| {
        all_stopped(s) && drives_off(s)
    });
    assert_eq!(s["mode"], json!("fault"));
    assert!(s["faults"][0].as_str().unwrap().contains("axis X"), "{s}");
    // Cleared once the cause is gone: switching on again is accepted.
    ok(
        &mut c,
        "sim.fault",
        json!({"kind": "stall", "axis": "X", "on": false}),
    );
    ok(&mut c, "machine.on", Value::Null);
    assert_eq!(ok(&mut c, "status", Value::Null)["mode"], json!("idle"));
}

#[test]
fn a_drive_fault_stops_the_machine_and_names_axis_and_code() {
    let d = Daemon::start_sim();
    let mut c = running_long_job(&d);
    ok(
        &mut c,
        "sim.fault",
        json!({"kind": "drive_fault", "axis": "Y", "code": 0x7500}),
    );
    let events = wait_event(&mut c, "fault event", GUARD, |e| e.topic == "fault");
    let f = &events.last().unwrap().data;
    assert_eq!(f["axis"], json!("Y"), "{f}");
    assert_eq!(f["value"], json!(f64::from(0x7500)), "{f}");
    assert!(f["message"].as_str().unwrap().contains("0x7500"), "{f}");
    let s = wait_status(&mut c, "stopped", GUARD, |s| {
        s["mode"] == json!("fault")
            && all_stopped(s)
            && drives_off(s)
            && s["job"]["state"] == json!("failed")
    });
    assert!(
        s["job"]["reason"].as_str().unwrap().contains("axis Y"),
        "{s}"
    );
    // machine.on resets the drive fault and brings the machine back.
    ok(&mut c, "machine.on", Value::Null);
    assert_eq!(ok(&mut c, "status", Value::Null)["mode"], json!("idle"));
}

#[test]
fn lost_drive_communication_stops_the_machine() {
    let d = Daemon::start_sim();
    let mut c = running_long_job(&d);
    ok(
        &mut c,
        "sim.fault",
        json!({"kind": "disconnect", "axis": "Z"}),
    );
    let events = wait_event(&mut c, "fault event", GUARD, |e| e.topic == "fault");
    let f = &events.last().unwrap().data;
    assert_eq!(f["axis"], json!("Z"), "{f}");
    assert!(
        f["message"].as_str().unwrap().contains("communication"),
        "{f}"
    );
    wait_status(&mut c, "fault", GUARD, |s| s["mode"] == json!("fault"));
    // Shutdown in fault mode must not wait for a machine-off the machine does not take: it
    // used to wait its full 30 s, past systemd's 20 s stop timeout, then log that the
    // controlled stop failed. Checked by that log line, not by the elapsed time (a loaded
    // host may take long to stop anyway).
    drop(c);
    let mut d = d;
    let (status, err) = d.terminate();
    assert!(status.success(), "{status}: {err}");
    assert!(
        !err.contains("controlled stop at shutdown"),
        "shutdown after a fault waited for a machine-off:\n{err}"
    );
}

#[test]
fn a_job_leaving_the_soft_limits_is_refused_before_any_motion() {
    let d = Daemon::start_sim();
    let mut c = d.client();
    ready(&mut c);
    let before = ok(&mut c, "status", Value::Null);
    let path = fixture("jobs/outside.ngc");
    let (code, msg) = err(
        &mut c,
        "job.load",
        json!({"path": path.display().to_string()}),
    );
    assert_eq!(code, 3);
    assert!(
        msg.contains("outside.ngc") && msg.contains("line 3") && msg.contains("axis X"),
        "{msg}"
    );
    let (code, _) = err(&mut c, "job.run", Value::Null);
    assert_eq!(code, 1, "no job may be loaded after a refusal");
    let after = ok(&mut c, "status", Value::Null);
    assert_eq!(before["axes"], after["axes"]);
    // Continuous jog stops at the soft limit, not beyond.
    ok(&mut c, "jog", json!({"axis": "Z", "velocity": 40.0}));
    let s = wait_status(&mut c, "jog at limit", GUARD, |s| {
        s["mode"] == json!("idle")
    });
    let z = axis(&s, "Z")["actual"].as_f64().unwrap();
    assert!(z <= 0.0 + 1e-6 && z > -0.01, "{z}");
    assert_eq!(s["faults"], json!([]));
}
