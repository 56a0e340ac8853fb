//! The cell through the daemon: `hytask serve --config <cell>` serves it on the control
//! socket (operations by name through `call`, events on topic `task`, counts in `status`),
//! and `hytask run-cell` runs it on an embedded daemon and prints the counts. Simulated time
//! (`cell.sim_speed`) keeps the runs short and independent of the host's load; every wait
//! has a generous hang guard.
#![allow(clippy::unwrap_used)]

mod cell_support;
mod support;

use cell_support::expected_counts;
use serde_json::{json, Value};
use std::path::{Path, PathBuf};
use std::time::Duration;
use support::{err, ok, wait_event, wait_status, Daemon};

const SEED: u64 = 42;

/// The shipped config on simulated time at 20x, with `extra` appended to `[cell]`.
fn fast_config(dir: &Path, extra: &str) -> PathBuf {
    let text = std::fs::read_to_string("config/pickplace.toml").unwrap();
    assert!(
        text.contains("# sim_speed = 10.0"),
        "config/pickplace.toml changed"
    );
    assert!(
        text.contains(&format!("seed = {SEED}\nmass_kg")),
        "world seed changed"
    );
    let text = text.replace("# sim_speed = 10.0", &format!("sim_speed = 20.0\n{extra}"));
    // The copy lives elsewhere: name the shipped script by its absolute path.
    let script = std::fs::canonicalize("config/scripts/selection.st").unwrap();
    let relative = "script = \"scripts/selection.st\"";
    assert!(text.contains(relative), "config/pickplace.toml changed");
    let text = text.replace(
        relative,
        &format!("script = {:?}", script.display().to_string()),
    );
    let path = dir.join("pickplace-fast.toml");
    std::fs::write(&path, text).unwrap();
    path
}

fn outputs(s: &Value) -> [u64; 4] {
    let n = |k: &str| s["outputs"][k].as_f64().unwrap() as u64;
    [
        n("container.A"),
        n("container.B"),
        n("container.reject"),
        n("floor"),
    ]
}

#[test]
fn daemon_serves_the_cell_and_sorts_through_socket_calls() {
    let dir = tempfile::tempdir().unwrap();
    let d = Daemon::start(&fast_config(dir.path(), ""));
    let mut c = d.client();
    ok(&mut c, "subscribe", json!({"topics": ["task", "fault"]}));
    wait_status(&mut c, "homed", Duration::from_secs(60), |s| {
        s["job"]["state"] == json!("homed")
    });
    // The machine's motion methods are refused with what to use instead.
    let (_, why) = err(&mut c, "mdi", json!({"line": "G0 X1"}));
    assert!(
        why.contains("mdi: this is a pick-and-place cell; use `call`"),
        "{why}"
    );
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
            "sensor",
            "robot",
            "pid",
            "effector",
            "hw",
            "selection",
            "camera"
        ]
    );
    // The selection is the script's state machine, visible as a script host.
    let selection = &tasks[5];
    let machine = &selection["scripts"][0];
    assert_eq!(
        (&machine["name"], &machine["kind"], &machine["status"]),
        (
            &json!("selection"),
            &json!("state_machine"),
            &json!("running")
        ),
        "{selection}"
    );
    assert_eq!(machine["state"], json!("homed"), "{machine}");
    assert!(machine["file"]
        .as_str()
        .unwrap()
        .ends_with("config/scripts/selection.st"));
    let r = ok(
        &mut c,
        "call",
        json!({"task": "selection", "operation": "run", "args": {"n": 5}}),
    );
    assert_eq!(r["status"], json!("accepted"));
    let mut done = 0;
    let events = wait_event(&mut c, "5 objects sorted", Duration::from_secs(120), |e| {
        e.topic == "task"
            && e.data["event"] == json!("selection.operation_n_done")
            && e.data["run"] == json!(5)
    });
    for e in &events {
        if e.data["event"] == json!("selection.operation_n_done") {
            done += 1;
        }
        assert_ne!(e.topic, "fault", "{}", e.data);
    }
    assert_eq!(done, 5);
    let s = wait_status(&mut c, "homed again", Duration::from_secs(60), |s| {
        s["job"]["state"] == json!("homed")
    });
    let want = expected_counts(SEED, 5);
    assert_eq!(
        outputs(&s),
        [
            u64::from(want[0]),
            u64::from(want[1]),
            u64::from(want[2]),
            0
        ]
    );
    assert_eq!(s["job"]["line"], json!(5));
    let list = ok(&mut c, "script.list", Value::Null);
    let m = &list[0];
    assert_eq!(
        (&m["task"], &m["state"]),
        (&json!("selection"), &json!("homed"))
    );
    assert!(m["transitions"].as_u64().unwrap() > 5 * 6, "{m}");
    assert_eq!(s["mode"], json!("idle"));
    // A robot operation by name: the e-stop stops the robot; the selection is idle so the
    // mode says e-stop.
    ok(&mut c, "estop", Value::Null);
    wait_status(&mut c, "estop", Duration::from_secs(120), |s| {
        s["mode"] == json!("estop")
    });
}

#[test]
fn run_cell_prints_the_counts_and_fails_on_an_injected_drop() {
    let dir = tempfile::tempdir().unwrap();
    let run = |config: &Path, runs: &str| {
        std::process::Command::new(env!("CARGO_BIN_EXE_hytask"))
            .args(["run-cell"])
            .arg(config)
            .args(["--runs", runs])
            .output()
            .unwrap()
    };
    let out = run(&fast_config(dir.path(), ""), "6");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stdout}\n{stderr}");
    let w = expected_counts(SEED, 6);
    assert!(
        stdout.contains(&format!(
            "per container: A {}  B {}  reject {}",
            w[0], w[1], w[2]
        )),
        "{stdout}"
    );
    assert!(stdout.contains("sorted:        6 of 6"), "{stdout}");
    assert!(stdout.contains("cycle time:"), "{stdout}");
    assert!(stderr.contains("run   6/6"), "{stderr}");

    let faulty = dir.path().join("faulty.toml");
    let text = std::fs::read_to_string(fast_config(dir.path(), ""))
        .unwrap()
        .replace(
            "# faults = { drop_on_grab = 3 }",
            "faults = { drop_on_grab = 3 }",
        );
    std::fs::write(&faulty, text).unwrap();
    let out = run(&faulty, "5");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(!out.status.success(), "{stdout}");
    assert!(stdout.contains("sorted:        2 of 5"), "{stdout}");
    assert!(stdout.contains("error:         object lost"), "{stdout}");
}

/// `realtime` of a cell on real-time threads is read once every thread has set itself up:
/// as root (SCHED_FIFO and mlockall allowed) it must say true; it said false when read right
/// after the start, and `hytask run-cell` printed "not realtime". Without the privileges
/// both sides are false.
#[test]
fn realtime_is_read_after_the_threads_set_themselves_up() {
    use hytask::daemon::Deployed;
    let file = hytask::cell::config::load(Path::new("config/pickplace.toml")).unwrap();
    assert!(
        file.cell.sim_speed.is_none(),
        "the shipped cell runs on real time"
    );
    let d = hytask::cell::daemon::CellDaemon::deploy(&file).unwrap();
    let possible = hytask::rt::system::capabilities().realtime;
    assert_eq!(d.realtime(), possible);
    d.shutdown().unwrap();
}
