//! Program stops through the control socket: M0 and M60 hold the job (mode and `job.state`
//! "holding") until `job.resume`, which goes on with the next line, as LinuxCNC's cycle start
//! does; M1 stops only while optional stop is on (`job.optional_stop`).
//!
//! Behaviour tests on the simulated clock: every wait is a hang guard (see
//! `tests/support/mod.rs`).
#![allow(clippy::unwrap_used)]

mod support;

use hytask::control::client::Client;
use serde_json::{json, Value};
use std::time::Duration;
use support::*;

const GUARD: Duration = Duration::from_secs(120);

fn x(s: &Value) -> f64 {
    axis(s, "X")["actual"].as_f64().unwrap()
}

/// Waits until the job stands still in a program stop on `line`.
fn stopped_at(c: &mut Client, line: u64) -> Value {
    let s = wait_status(c, &format!("program stop on line {line}"), GUARD, |s| {
        s["job"]["state"] == json!("holding") && at_rest(s, 1e-6)
    });
    assert_eq!(s["mode"], json!("holding"), "mode at a program stop");
    assert_eq!(s["job"]["line"], json!(line), "{}", s["job"]);
    s
}

fn job_done(c: &mut Client) -> Value {
    wait_job_end(c, "the job's end", GUARD)
}

/// A homed machine on the simulated clock, running `text`.
fn running(text: &str, name: &str) -> (Daemon, Client) {
    let d = Daemon::start_sim();
    let mut c = d.client();
    ready(&mut c);
    run_text(&mut c, text, name);
    (d, c)
}

#[test]
fn m0_and_m60_hold_the_job_and_job_resume_goes_on_with_the_next_line() {
    let text = "G21 G90\nG0 X100 Y100 Z-5\nM0\nG0 X110\nM60\nG0 X120\nM2\n";
    let (_d, mut c) = running(text, "stops.ngc");

    let s = stopped_at(&mut c, 3);
    assert!((x(&s) - 100.0).abs() < 0.002, "{}", x(&s));
    // Standing at the stop is no progress: the job's planned time done stays where it is.
    let cycle = s["servo_cycle"].as_u64().unwrap();
    let later = wait_status(&mut c, "a second at the stop", GUARD, |t| {
        t["servo_cycle"].as_u64().unwrap() > cycle + 1000
    });
    assert_eq!(
        later["job"]["progress"], s["job"]["progress"],
        "{}",
        later["job"]
    );
    let progress = s["job"]["progress"].as_f64().unwrap();
    assert!(progress > 0.1 && progress < 0.9, "{}", s["job"]);
    // A feed hold on top of the stop changes nothing, however often it is asked for (each
    // pause is done at once: pauses that never finished used to fill the machine task's
    // command slots until it took nothing more, e-stop included); one resume leaves both.
    for _ in 0..12 {
        ok(&mut c, "job.pause", Value::Null);
    }
    ok(&mut c, "job.resume", Value::Null);

    let s = stopped_at(&mut c, 5);
    assert!((x(&s) - 110.0).abs() < 0.002, "{}", x(&s));
    ok(&mut c, "job.resume", Value::Null);

    let s = job_done(&mut c);
    assert_eq!(s["job"]["state"], json!("done"), "{}", s["job"]);
    assert_eq!(s["mode"], json!("idle"));
    assert!((x(&s) - 120.0).abs() < 0.002, "{}", x(&s));
    // A finished job shows its last line (M2), not the last progress sample's.
    assert_eq!(s["job"]["line"], json!(7), "{}", s["job"]);
}

#[test]
fn job_step_at_an_m0_runs_the_next_line_and_abort_ends_the_stop() {
    // Lines 4 and 5 meet at a blended corner, so the hold at line 5 stops on the way.
    let text = "G21 G90\nG0 X100 Y100 Z-5\nM0\nG1 X110 Y105 F1200\nG1 X120 Y100\nM2\n";
    let (_d, mut c) = running(text, "step.ngc");
    stopped_at(&mut c, 3);
    ok(&mut c, "job.step", Value::Null);
    let s = wait_status(&mut c, "held after the step", GUARD, |s| {
        s["mode"] == json!("holding") && at_rest(s, 1e-6) && s["job"]["line"] != json!(3)
    });
    // Line 4 ran to its end; the hold began with line 5.
    assert_eq!(s["job"]["line"], json!(5), "{}", s["job"]);
    assert!(x(&s) > 110.0 && x(&s) < 120.0, "{}", x(&s));
    ok(&mut c, "job.abort", Value::Null);
    let s = job_done(&mut c);
    assert_eq!(s["job"]["state"], json!("aborted"), "{}", s["job"]);
    assert_eq!(s["mode"], json!("idle"));
}

#[test]
fn m1_stops_only_while_optional_stop_is_on() {
    let d = Daemon::start_sim();
    let mut c = d.client();
    ready(&mut c);
    let text = "G21 G90\nG0 X100 Y100 Z-5\nM1\nG0 X110\nM2\n";
    ok(&mut c, "job.load", json!({"text": text, "name": "m1.ngc"}));

    // Off (the default): M1 is passed over.
    let off = ok(&mut c, "job.optional_stop", json!({"on": false}));
    assert_eq!(off, json!({"optional_stop": false}));
    ok(&mut c, "job.run", Value::Null);
    let s = job_done(&mut c);
    assert_eq!(s["job"]["state"], json!("done"), "{}", s["job"]);
    assert!((x(&s) - 110.0).abs() < 0.002, "{}", x(&s));
    assert_eq!(s["optional_stop"], json!(false));

    // On: M1 stops like M0.
    ok(&mut c, "mdi", json!({"line": "G0 X90"}));
    wait_status(&mut c, "back at X90", GUARD, |s| {
        s["mode"] == json!("idle") && (x(s) - 90.0).abs() < 0.002
    });
    let on = ok(&mut c, "job.optional_stop", json!({"on": true}));
    assert_eq!(on, json!({"optional_stop": true}));
    run_text(&mut c, text, "m1.ngc");
    let s = stopped_at(&mut c, 3);
    assert_eq!(s["optional_stop"], json!(true));
    ok(&mut c, "job.resume", Value::Null);
    let s = job_done(&mut c);
    assert_eq!(s["job"]["state"], json!("done"), "{}", s["job"]);
    assert!((x(&s) - 110.0).abs() < 0.002, "{}", x(&s));

    let (code, msg) = err(&mut c, "job.optional_stop", json!({"on": "yes"}));
    assert_eq!(code, -32602, "{msg}");
}
