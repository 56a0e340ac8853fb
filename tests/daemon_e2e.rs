//! End to end: the real `hytask serve` binary on a private socket with the simulated mill.
//! Jobs, progress and events; operator commands; the control socket under load.
//! Safety paths are in `tests/daemon_safety.rs`.
//!
//! Tests of behaviour run the machine on a simulated clock ([`Daemon::start_sim`]) and act on
//! observed states; the real-time smoke tests (a whole job with its progress events, SIGTERM,
//! `hytask run`) keep the real-time servo thread. Every wait is a hang guard: see
//! `tests/support/mod.rs`.
#![allow(clippy::unwrap_used)]

mod support;

use serde_json::{json, Value};
use std::time::{Duration, Instant};
use support::*;

/// Hang guard of the waits below: a loaded host may run the machine slower than planned.
const GUARD: Duration = Duration::from_secs(120);

#[test]
fn a_job_runs_to_the_end_with_progress_events_and_exact_final_position() {
    let d = Daemon::start(&fast_sim());
    let mut c = d.client();
    ok(&mut c, "subscribe", Value::Null);
    ready(&mut c);
    let info = run_job(&mut c, "jobs/square.ngc");
    assert_eq!(info["name"], json!("square.ngc"));
    assert!(info["planned_time_s"].as_f64().unwrap() > 1.0);
    let events = wait_event(&mut c, "job done", GUARD, |e| {
        e.topic == "job" && e.data["state"] == json!("done")
    });
    // Progress grows and names lines of the program.
    let progress: Vec<f64> = events
        .iter()
        .filter(|e| e.topic == "progress")
        .map(|e| e.data["progress"].as_f64().unwrap())
        .collect();
    assert!(progress.len() >= 5, "{progress:?}");
    assert!(progress.windows(2).all(|w| w[1] >= w[0]), "{progress:?}");
    assert!(events
        .iter()
        .any(|e| e.topic == "message" && e.data["text"].as_str().unwrap().contains("square job")));
    assert!(events
        .iter()
        .any(|e| e.topic == "mode" && e.data["mode"] == json!("running")));
    let s = ok(&mut c, "status", Value::Null);
    assert_eq!(s["job"]["state"], json!("done"));
    assert_eq!(s["job"]["progress"], json!(1.0));
    for (name, want) in [("X", 120.0), ("Y", 110.0), ("Z", -20.0)] {
        let a = axis(&s, name);
        let got = a["actual"].as_f64().unwrap();
        assert!((got - want).abs() < 0.002, "{name}: {got} vs {want}");
        assert!(a["max_following_error"].as_f64().unwrap() < 1.0);
    }
    // The job switched the spindle and coolant off at its end (M5, M9).
    assert_eq!(s["outputs"]["spindle_on"], json!(0.0));
    assert_eq!(s["outputs"]["coolant_flood"], json!(0.0));
    assert!(s["realtime"].is_boolean());
    assert!(s["threads"][0]["cycles"].as_u64().unwrap() > 1000);
}

#[test]
fn pause_resume_abort_and_overrides_act_on_a_running_job() {
    let d = Daemon::start_sim();
    let mut c = d.client();
    ready(&mut c);
    run_job(&mut c, "jobs/long.ngc");
    // Line 6 is "G1 X250 F1200": a 10 s feed move, then three more of Y and X.
    wait_status(&mut c, "on line 6", GUARD, |s| {
        s["job"]["line"].as_u64().unwrap() >= 6 && s["mode"] == json!("running")
    });
    ok(&mut c, "job.pause", Value::Null);
    let held = wait_status(&mut c, "holding at rest", GUARD, |s| {
        s["mode"] == json!("holding") && at_rest(s, 1e-6)
    });
    let xy = |s: &Value| {
        let at = |n| axis(s, n)["actual"].as_f64().unwrap();
        (at("X"), at("Y"))
    };
    let (x, y) = xy(&held);
    std::thread::sleep(Duration::from_millis(300));
    let still = ok(&mut c, "status", Value::Null);
    let (x1, y1) = xy(&still);
    assert!(
        (x1 - x).abs() < 1e-6 && (y1 - y).abs() < 1e-6,
        "moved during the hold"
    );
    ok(&mut c, "job.resume", Value::Null);
    let o = ok(&mut c, "override", json!({"feed": 1.5}));
    assert_eq!(o["feed"], json!(1.5));
    // Lines 6 to 9 move X or Y by 200 mm each: whichever the hold landed on moves on.
    wait_status(&mut c, "moving again", GUARD, |s| {
        let (x2, y2) = xy(s);
        (x2 - x).abs() > 1.0 || (y2 - y).abs() > 1.0
    });
    let (code, _) = err(&mut c, "override", json!({"feed": 5.0}));
    assert_eq!(code, -32602);
    ok(&mut c, "job.abort", Value::Null);
    let s = wait_status(&mut c, "idle after abort", GUARD, |s| {
        s["mode"] == json!("idle")
    });
    assert_eq!(s["job"]["state"], json!("aborted"));
    assert!(s["job"]["reason"].as_str().unwrap().contains("line"));
    assert!(
        s["faults"].as_array().unwrap().is_empty(),
        "abort is not a fault: {s}"
    );
    for a in s["axes"].as_array().unwrap() {
        assert!(a["velocity"].as_f64().unwrap().abs() < 1e-3, "{a}");
    }
}

#[test]
fn job_step_runs_one_line_then_holds() {
    let d = Daemon::start_sim();
    let mut c = d.client();
    ready(&mut c);
    run_job(&mut c, "jobs/long.ngc");
    // Held at once (spindle start and the 2.5 s rapid of line 5 come first), then stepped
    // line by line to the start of line 6: no step depends on when a request lands.
    ok(&mut c, "job.pause", Value::Null);
    let held_at_rest = |s: &Value| s["mode"] == json!("holding") && at_rest(s, 1e-6);
    let mut held = wait_status(&mut c, "held", GUARD, held_at_rest);
    for _ in 0..6 {
        let line = held["job"]["line"].as_u64().unwrap();
        assert!(line <= 6, "the hold came after line 6: {}", held["job"]);
        if line == 6 {
            break;
        }
        ok(&mut c, "job.step", Value::Null);
        held = wait_status(&mut c, "held after a step", GUARD, |s| {
            held_at_rest(s) && s["job"]["line"].as_u64().unwrap() > line
        });
    }
    assert_eq!(held["job"]["line"], json!(6), "{}", held["job"]);
    // Line 6 is "G1 X250 F1200", 200 mm at 20 mm/s.
    ok(&mut c, "job.step", Value::Null);
    let held = wait_status(&mut c, "held on line 7", GUARD, |s| {
        held_at_rest(s) && s["job"]["line"].as_u64().unwrap() > 6
    });
    assert_eq!(held["job"]["line"], json!(7), "{}", held["job"]);
    // Line 7 ("G1 Y250") had only just begun: X is at its end, Y barely moved.
    let (x, y) = (
        axis(&held, "X")["actual"].as_f64().unwrap(),
        axis(&held, "Y")["actual"].as_f64().unwrap(),
    );
    assert!((x - 250.0).abs() < 1.0 && y < 55.0, "X {x} Y {y}");
    ok(&mut c, "job.step", Value::Null);
    let held = wait_status(&mut c, "held on line 8", GUARD, |s| {
        held_at_rest(s) && s["job"]["line"] == json!(8)
    });
    assert!(axis(&held, "Y")["actual"].as_f64().unwrap() > 245.0);
    ok(&mut c, "job.abort", Value::Null);
    wait_status(&mut c, "idle", GUARD, |s| s["mode"] == json!("idle"));
    let (code, msg) = err(&mut c, "job.step", Value::Null);
    assert_eq!(code, 1, "{msg}");
}

#[test]
fn jog_and_mdi_move_the_machine() {
    let d = Daemon::start_sim();
    let mut c = d.client();
    ready(&mut c);
    ok(&mut c, "mdi", json!({"line": "G0 X100 Y120 Z-30"}));
    let s = wait_status(&mut c, "mdi done", GUARD, |s| s["mode"] == json!("idle"));
    assert!((axis(&s, "Y")["actual"].as_f64().unwrap() - 120.0).abs() < 0.002);
    ok(
        &mut c,
        "jog",
        json!({"axis": "X", "velocity": 20.0, "distance": 5.0}),
    );
    let s = wait_status(&mut c, "jog done", GUARD, |s| {
        s["mode"] == json!("idle")
            && (axis(s, "X")["actual"].as_f64().unwrap() - 105.0).abs() < 0.002
    });
    assert_eq!(s["faults"], json!([]));
    // A continuous jog stops on request, under control, without a fault, short of the soft
    // limit at Y0 (at 5 mm/s it would take 24 s of machine time to get there).
    ok(&mut c, "jog", json!({"axis": "Y", "velocity": -5.0}));
    wait_status(&mut c, "jogging", GUARD, |s| {
        axis(s, "Y")["actual"].as_f64().unwrap() < 119.0
    });
    ok(&mut c, "jog.stop", Value::Null);
    let s = wait_status(&mut c, "jog stopped", GUARD, |s| s["mode"] == json!("idle"));
    let y = axis(&s, "Y")["actual"].as_f64().unwrap();
    assert!(y < 119.0 && y > 1.0, "{y}");
    assert_eq!(s["faults"], json!([]));
    // MDI with a G-code error moves nothing and names the column.
    let (code, msg) = err(&mut c, "mdi", json!({"line": "G1 X10 G0"}));
    assert_eq!(code, 3, "{msg}");
    assert!(msg.starts_with("mdi:1:"), "{msg}");
}

#[test]
fn tasks_are_listed_and_operations_callable_by_name() {
    let d = Daemon::start_sim();
    let mut c = d.client();
    let tasks = ok(&mut c, "tasks", Value::Null);
    let names: Vec<&str> = tasks
        .as_array()
        .unwrap()
        .iter()
        .map(|t| t["name"].as_str().unwrap())
        .collect();
    assert_eq!(
        names,
        [
            "io",
            "machine",
            "interpolator",
            "axis.X",
            "axis.Y",
            "axis.Z",
            "monitor",
            "cnc",
            "scripts"
        ]
    );
    let machine = &tasks[1];
    assert!(machine["operations"]
        .as_array()
        .unwrap()
        .iter()
        .any(|o| o["name"] == json!("set_overrides")));
    let r = ok(
        &mut c,
        "call",
        json!({"task": "machine", "operation": "set_overrides",
               "args": {"feed": 0.5, "rapid": 0.25, "spindle": 1.0}}),
    );
    assert_eq!(r["status"], json!("done"));
    let s = ok(&mut c, "status", Value::Null);
    assert_eq!(s["overrides"]["feed"], json!(0.5));
    assert_eq!(s["overrides"]["rapid"], json!(0.25));
    // Wrong operation, wrong argument type, rejected by state: each says so.
    let (code, msg) = err(
        &mut c,
        "call",
        json!({"task": "machine", "operation": "fly"}),
    );
    assert_eq!(code, -32602, "{msg}");
    let (code, _) = err(
        &mut c,
        "call",
        json!({"task": "machine", "operation": "home", "args": ["all"]}),
    );
    assert_eq!(code, -32602);
    let (code, msg) = err(
        &mut c,
        "call",
        json!({"task": "machine", "operation": "pause"}),
    );
    assert_eq!(code, 1, "{msg}");
    assert!(msg.contains("e-stop"), "{msg}");
}

#[test]
fn malformed_requests_get_errors_and_the_daemon_keeps_running() {
    use std::io::{BufRead, BufReader, Write};
    let d = Daemon::start_sim();
    let s = std::os::unix::net::UnixStream::connect(&d.socket).unwrap();
    let mut r = BufReader::new(s.try_clone().unwrap());
    let mut w = s;
    for bad in [
        "{oops",
        "42",
        "{\"method\":\"nope\"}",
        "{\"method\":\"home\",\"params\":{\"axis\":\"Q\"}}",
    ] {
        w.write_all(bad.as_bytes()).unwrap();
        w.write_all(b"\n").unwrap();
        let mut line = String::new();
        r.read_line(&mut line).unwrap();
        let v: Value = serde_json::from_str(&line).unwrap();
        assert!(v["error"]["code"].is_i64(), "{bad} -> {line}");
    }
    let mut c = d.client();
    assert_eq!(ok(&mut c, "status", Value::Null)["mode"], json!("estop"));
}

#[test]
fn fifty_clients_poll_status_while_a_job_runs_and_a_vanished_client_does_not_stop_it() {
    let d = Daemon::start_sim();
    {
        let mut c = d.client();
        ready(&mut c);
        run_job(&mut c, "jobs/square.ngc");
        // c is dropped here: the job must go on without its client.
    }
    let deadline = Instant::now() + GUARD;
    let pollers: Vec<_> = (0..50)
        .map(|_| {
            let socket = d.socket.clone();
            std::thread::spawn(move || {
                let mut c = hytask::control::client::Client::connect(&socket).unwrap();
                let mut n = 0;
                loop {
                    let s = ok(&mut c, "status", Value::Null);
                    n += 1;
                    if s["job"]["state"] == json!("done") || Instant::now() > deadline {
                        return (n, s["job"]["state"].clone());
                    }
                    std::thread::sleep(Duration::from_millis(5));
                }
            })
        })
        .collect();
    for p in pollers {
        let (n, state) = p.join().unwrap();
        assert_eq!(state, json!("done"));
        assert!(n > 1);
    }
}

#[test]
fn sigterm_stops_the_machine_under_control_and_exits_zero() {
    let mut d = Daemon::start(&fast_sim());
    let mut c = d.client();
    ready(&mut c);
    run_job(&mut c, "jobs/long.ngc");
    wait_status(&mut c, "job moving", GUARD, |s| {
        s["job"]["line"].as_u64().unwrap() >= 5 && s["mode"] == json!("running")
    });
    let (status, stderr) = d.terminate();
    assert!(status.success(), "exit {status:?}\n{stderr}");
    assert!(stderr.contains("SIGTERM"), "{stderr}");
    assert!(stderr.contains("machine stopped"), "{stderr}");
}

#[test]
fn hytask_run_uses_the_daemon_when_one_is_reachable() {
    let d = Daemon::start(&fast_sim());
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_hytask"))
        .arg("run")
        .arg(fixture("jobs/square.ngc"))
        .arg("--socket")
        .arg(&d.socket)
        .arg("--no-embedded")
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stdout}\n{stderr}");
    assert!(stdout.contains("result:     done"), "{stdout}");
    assert!(stderr.contains("using the daemon"), "{stderr}");
    assert!(stderr.contains("progress"), "{stderr}");
}

#[test]
fn hytask_run_refuses_a_bad_job_naming_file_line_and_column() {
    let d = Daemon::start(&fast_sim());
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_hytask"))
        .arg("run")
        .arg(fixture("jobs/bad.ngc"))
        .arg("--socket")
        .arg(&d.socket)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(stderr.contains("bad.ngc:3:"), "{stderr}");
    assert!(stderr.contains("nothing moved"), "{stderr}");
}
