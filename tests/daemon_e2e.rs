//! End to end: the real `hytask serve` binary on a private socket with the simulated mill.
//! Jobs, progress and events; operator commands; the control socket under load.
//! Safety paths are in `tests/daemon_safety.rs`.
#![allow(clippy::unwrap_used)]

mod support;

use serde_json::{json, Value};
use std::time::{Duration, Instant};
use support::*;

#[test]
fn a_job_runs_to_the_end_with_progress_events_and_exact_final_position() {
    let d = Daemon::start(&fast_sim());
    let mut c = d.client();
    ok(&mut c, "subscribe", Value::Null);
    ready(&mut c);
    let info = run_job(&mut c, "jobs/square.ngc");
    assert_eq!(info["name"], json!("square.ngc"));
    assert!(info["planned_time_s"].as_f64().unwrap() > 1.0);
    let events = wait_event(&mut c, "job done", Duration::from_secs(60), |e| {
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
    let d = Daemon::start(&fast_sim());
    let mut c = d.client();
    ready(&mut c);
    run_job(&mut c, "jobs/long.ngc");
    std::thread::sleep(Duration::from_millis(1500));
    ok(&mut c, "job.pause", Value::Null);
    let held = wait_status(&mut c, "holding at rest", Duration::from_secs(5), |s| {
        s["mode"] == json!("holding") && at_rest(s, 1e-6)
    });
    let x = axis(&held, "X")["actual"].as_f64().unwrap();
    std::thread::sleep(Duration::from_millis(300));
    let still = ok(&mut c, "status", Value::Null);
    assert!((axis(&still, "X")["actual"].as_f64().unwrap() - x).abs() < 1e-6);
    ok(&mut c, "job.resume", Value::Null);
    let o = ok(&mut c, "override", json!({"feed": 1.5}));
    assert_eq!(o["feed"], json!(1.5));
    wait_status(&mut c, "moving again", Duration::from_secs(5), |s| {
        (axis(s, "X")["actual"].as_f64().unwrap() - x).abs() > 1.0
    });
    let (code, _) = err(&mut c, "override", json!({"feed": 5.0}));
    assert_eq!(code, -32602);
    ok(&mut c, "job.abort", Value::Null);
    let s = wait_status(&mut c, "idle after abort", Duration::from_secs(10), |s| {
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
    let d = Daemon::start(&fast_sim());
    let mut c = d.client();
    ready(&mut c);
    run_job(&mut c, "jobs/long.ngc");
    // Line 6 is "G1 X250 F1200": 200 mm at 20 mm/s. The deadlines below only guard against a
    // hang: a loaded host can slow the simulated machine to a fraction of real time.
    wait_status(&mut c, "on line 6", Duration::from_secs(120), |s| {
        s["job"]["line"] == json!(6)
    });
    ok(&mut c, "job.step", Value::Null);
    let held = wait_status(&mut c, "held on line 7", Duration::from_secs(120), |s| {
        s["mode"] == json!("holding") && at_rest(s, 1e-6)
    });
    assert_eq!(held["job"]["line"], json!(7), "{}", held["job"]);
    // Line 7 ("G1 Y250") had only just begun: X is at its end, Y barely moved.
    let (x, y) = (
        axis(&held, "X")["actual"].as_f64().unwrap(),
        axis(&held, "Y")["actual"].as_f64().unwrap(),
    );
    assert!((x - 250.0).abs() < 1.0 && y < 55.0, "X {x} Y {y}");
    ok(&mut c, "job.step", Value::Null);
    let held = wait_status(&mut c, "held on line 8", Duration::from_secs(120), |s| {
        s["mode"] == json!("holding") && s["job"]["line"] == json!(8)
    });
    assert!(axis(&held, "Y")["actual"].as_f64().unwrap() > 245.0);
    ok(&mut c, "job.abort", Value::Null);
    wait_status(&mut c, "idle", Duration::from_secs(60), |s| {
        s["mode"] == json!("idle")
    });
    let (code, msg) = err(&mut c, "job.step", Value::Null);
    assert_eq!(code, 1, "{msg}");
}

#[test]
fn jog_and_mdi_move_the_machine() {
    let d = Daemon::start(&fast_sim());
    let mut c = d.client();
    ready(&mut c);
    ok(&mut c, "mdi", json!({"line": "G0 X100 Y120 Z-30"}));
    let s = wait_status(&mut c, "mdi done", Duration::from_secs(20), |s| {
        s["mode"] == json!("idle")
    });
    assert!((axis(&s, "Y")["actual"].as_f64().unwrap() - 120.0).abs() < 0.002);
    ok(
        &mut c,
        "jog",
        json!({"axis": "X", "velocity": 20.0, "distance": 5.0}),
    );
    let s = wait_status(&mut c, "jog done", Duration::from_secs(10), |s| {
        s["mode"] == json!("idle")
            && (axis(s, "X")["actual"].as_f64().unwrap() - 105.0).abs() < 0.002
    });
    assert_eq!(s["faults"], json!([]));
    // A continuous jog stops on request, under control, without a fault.
    ok(&mut c, "jog", json!({"axis": "Y", "velocity": -30.0}));
    std::thread::sleep(Duration::from_millis(400));
    ok(&mut c, "jog.stop", Value::Null);
    let s = wait_status(&mut c, "jog stopped", Duration::from_secs(5), |s| {
        s["mode"] == json!("idle")
    });
    let y = axis(&s, "Y")["actual"].as_f64().unwrap();
    assert!(y < 119.0 && y > 90.0, "{y}");
    // MDI with a G-code error moves nothing and names the column.
    let (code, msg) = err(&mut c, "mdi", json!({"line": "G1 X10 G0"}));
    assert_eq!(code, 3, "{msg}");
    assert!(msg.starts_with("mdi:1:"), "{msg}");
}

#[test]
fn tasks_are_listed_and_operations_callable_by_name() {
    let d = Daemon::start(&fast_sim());
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
            "monitor"
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
    let d = Daemon::start(&fast_sim());
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
    let d = Daemon::start(&fast_sim());
    {
        let mut c = d.client();
        ready(&mut c);
        run_job(&mut c, "jobs/square.ngc");
        // c is dropped here: the job must go on without its client.
    }
    let deadline = Instant::now() + Duration::from_secs(60);
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
    std::thread::sleep(Duration::from_millis(800));
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
