//! The Zenoh bridge end to end: `hytask serve` on the simulated mill with `[zenoh]` on
//! loopback, and independent Zenoh sessions (Rust, and Eclipse's Python binding from the
//! venv made by tests/install-deps) that watch and operate it through the keys of
//! `hytask::bridge::keys`.
//!
//! Real processes: every wait is a hang guard, never a timing.
#![allow(clippy::unwrap_used)]

mod support;
mod zenoh_support;

use serde_json::{json, Value};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;
use support::Daemon;
use zenoh::Wait;
use zenoh_support::{client, free_port};

const GUARD: Duration = Duration::from_secs(60);

/// The simulated mill on a simulated clock with `[zenoh]` (key `mill`) on a loopback port.
fn daemon_with_zenoh(extra: &str) -> (Daemon, String, tempfile::TempDir) {
    let dir = tempfile::tempdir().unwrap();
    let base = support::sim_clock_config(dir.path(), support::SIM_SPEED, None);
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let mut text = std::fs::read_to_string(&base).unwrap();
    text.push_str(&format!(
        "\n[zenoh]\nkey = \"mill\"\nlisten = [\"{endpoint}\"]\nport_rate_hz = 100.0\n{extra}\n"
    ));
    let config = dir.path().join("zenoh.toml");
    std::fs::write(&config, text).unwrap();
    (Daemon::start(&config), endpoint, dir)
}

/// [`zenoh_support::query`] with the hang guard.
fn get(s: &zenoh::Session, key: &str, payload: Option<Value>) -> Result<Value, Value> {
    zenoh_support::query(s, key, payload.as_ref(), GUARD)
}

fn wait_for(what: &str, f: impl FnMut() -> bool) {
    zenoh_support::wait_for(what, GUARD * 2, f)
}

#[test]
fn a_zenoh_peer_watches_and_operates_the_mill() {
    let (_daemon, endpoint, _dir) = daemon_with_zenoh("");
    let s = client(&endpoint);
    let status = s.declare_subscriber("hytask/mill/status").wait().unwrap();
    let modes = s
        .declare_subscriber("hytask/mill/machine/event/mode")
        .wait()
        .unwrap();
    let first = status
        .recv_timeout(GUARD)
        .unwrap()
        .expect("a status publication");
    let first: Value = serde_json::from_slice(&first.payload().to_bytes()).unwrap();
    assert!(first["axes"].is_array(), "{first}");

    // The interface, as `hytask tasks` prints it.
    let tasks = get(&s, "hytask/mill/tasks", None).unwrap();
    let names: Vec<&str> = tasks["result"]
        .as_array()
        .unwrap()
        .iter()
        .map(|t| t["name"].as_str().unwrap())
        .collect();
    assert!(
        names.contains(&"machine") && names.contains(&"axis.X"),
        "{names:?}"
    );

    // A command rejected by the task comes back as an error reply with its reason...
    let mode = get(&s, "hytask/mill/status", None).unwrap()["result"]["mode"].clone();
    assert_eq!(mode, json!("estop"), "the sim starts in e-stop");
    let e = get(&s, "hytask/mill/machine/op/machine_on", None).unwrap_err();
    assert_eq!(e["status"], "rejected", "{e}");
    // ...an accepted one with its final status once its completion condition holds.
    get(&s, "hytask/mill/machine/op/estop_reset", None).unwrap();
    let on = get(&s, "hytask/mill/machine/op/machine_on", None).unwrap();
    assert_eq!(on["status"], "done", "{on}");
    // The realtime event `machine.mode` arrives as a publication.
    wait_for("a mode event", || {
        matches!(modes.try_recv(), Ok(Some(sample))
            if serde_json::from_slice::<Value>(&sample.payload().to_bytes()).unwrap()["mode"] == "idle")
    });

    // Control methods with parameters, and a port read.
    get(&s, "hytask/mill/control/home", Some(json!({"axis": "X"}))).unwrap();
    wait_for("X homed in its feedback port", || {
        get(&s, "hytask/mill/axis.X/port/axis.X.feedback", None)
            .is_ok_and(|v| v["result"]["homed"] == json!(true))
    });

    // Bad input gets an error reply and the bridge keeps answering.
    let job = json!({"text": "G21\nG0 X\n", "name": "bad.ngc"});
    let e = get(&s, "hytask/mill/control/job.load", Some(job)).unwrap_err();
    assert_eq!(e["status"], "invalid", "{e}");
    assert!(
        e["error"].as_str().unwrap().contains("bad.ngc:2:"),
        "a G-code error names file and line: {e}"
    );
    let e = s
        .get("hytask/mill/control/mdi")
        .payload("{not json")
        .wait()
        .unwrap();
    let e = e.recv().unwrap();
    let e: Value = serde_json::from_slice(&e.result().unwrap_err().payload().to_bytes()).unwrap();
    assert!(e["error"].as_str().unwrap().contains("not JSON"), "{e}");
    let e = get(&s, "hytask/mill/control/no.such", None).unwrap_err();
    assert!(
        e["error"].as_str().unwrap().contains("unknown method"),
        "{e}"
    );
    let e = get(&s, "hytask/mill/axis.X/port/no.such", None).unwrap_err();
    assert!(e["error"].as_str().unwrap().contains("no value"), "{e}");
    assert!(get(&s, "hytask/mill/status", None).is_ok());
}

#[test]
fn observers_watch_and_e_stop_but_do_not_operate_and_slow_calls_time_out() {
    let (_daemon, endpoint, _dir) =
        daemon_with_zenoh("role = \"observer\"\ncall_timeout_s = 0.000001");
    let s = client(&endpoint);
    let e = get(&s, "hytask/mill/control/machine.on", None).unwrap_err();
    assert_eq!(e["status"], "forbidden", "{e}");
    assert!(e["error"].as_str().unwrap().contains("operator"), "{e}");
    let e = get(&s, "hytask/mill/machine/op/machine_on", None).unwrap_err();
    assert_eq!(e["status"], "forbidden", "{e}");
    // Permitted to an observer, but no final status within a microsecond: a timeout reply.
    let e = get(&s, "hytask/mill/control/estop", None).unwrap_err();
    assert_eq!(e["status"], "timeout", "{e}");
    // Watching needs no permission.
    assert!(get(&s, "hytask/mill/tasks", None).is_ok());
}

fn python() -> PathBuf {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("target/zenoh-venv/bin/python");
    let ok = Command::new(&p)
        .args(["-c", "import zenoh"])
        .status()
        .is_ok_and(|s| s.success());
    assert!(
        ok,
        "eclipse-zenoh venv missing at {}: run tests/install-deps",
        p.display()
    );
    p
}

#[test]
fn eclipse_zenoh_from_python_watches_and_operates_the_mill() {
    let py = python();
    let (_daemon, endpoint, _dir) = daemon_with_zenoh("");
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/zenoh/client.py");
    let out = Command::new(py)
        .arg(script)
        .args([&endpoint, "mill"])
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        out.status.success(),
        "python client failed:\n{stdout}\n{stderr}"
    );
    for step in [
        "status-subscription",
        "tasks",
        "operation",
        "homed",
        "port",
        "rejected",
        "events",
        "done",
    ] {
        assert!(
            stdout.lines().any(|l| l.starts_with(&format!("ok {step}"))),
            "step {step} missing:\n{stdout}"
        );
    }
}

/// A machine served by `hytask serve` declares its liveliness token like a peer process: a
/// remote that lists it (`[[remote]]`) sees it lost as soon as the daemon dies, not by a
/// call's timeout (its `timeout_s` here is far beyond the hang guard).
#[test]
fn a_remote_listing_the_mill_sees_it_lost_when_its_daemon_dies() {
    let (mut daemon, endpoint, _dir) = daemon_with_zenoh("");
    // A peer session, as a remote user's (`hytask serve`, `hytask peer`) is.
    let s = zenoh_support::peer_session(&endpoint);
    // The token is there while the daemon serves.
    zenoh_support::wait_token(&s, "hytask/mill/alive", GUARD);
    let cfg = hytask::config::remote::RemoteConfig {
        name: "mill".into(),
        machine: None,
        timeout_s: 3600.0,
        critical: false,
        check: true,
    };
    let link = hytask::bridge::remote::RemoteLink::connect(&s, &cfg).unwrap();
    let lost = std::sync::Arc::new(std::sync::Mutex::new(None));
    let l2 = lost.clone();
    link.on_lost(move |msg, _| *l2.lock().unwrap() = Some(msg.to_owned()));
    assert!(link.alive());
    daemon.child.as_mut().unwrap().kill().unwrap();
    wait_for("the loss seen through the liveliness token", || {
        lost.lock().unwrap().is_some()
    });
    assert!(!link.alive());
    let msg = lost.lock().unwrap().clone().unwrap();
    assert!(msg.contains("'mill'") && msg.contains("lost"), "{msg}");
}
