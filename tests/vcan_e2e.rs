//! End to end on a real vcan0: the daemon with `config/vcan.toml` (3 axes, nodes 1-3) and
//! the loopback drives of `hytask sim-drive` in another process. It homes and runs a job
//! to completion with the final position checked; then a drive fault, a heartbeat loss and
//! an EMCY injected mid-job (SDO writes to the drives' object 0x2000 through the daemon's
//! `drive.sdo_write`) each give a controlled stop, a fault event naming node and cause, and
//! a failed job naming its line.
//!
//! Runs under `tests/vcan/run` (host vcan0 or the VM it boots), which sets `HYTASK_VCAN`;
//! elsewhere each test says why and returns. The servo period is stretched to 10 ms, the
//! heartbeat to 500 ms and the SDO timeout to 2 s here: under software emulation a 2 ms
//! loop overruns and processes stall for hundreds of ms, which is a property of the
//! emulator, not of the code under test. Waits are conditions with hang guards: the
//! daemon starts once the loopback drives said `ready`, never after a fixed delay.
#![allow(clippy::unwrap_used)]

mod support;
mod vcan;

use serde_json::{json, Value};
use std::process::{Child, Command, Stdio};
use std::time::Duration;
use support::*;

const GUARD: Duration = Duration::from_secs(180);
const PERIOD_US: u32 = 10_000;

const NAME: &str = "vcan_e2e";

/// The loopback drives, stopped when dropped.
struct Drives(Child);

impl Drop for Drives {
    fn drop(&mut self) {
        // SIGTERM: the drive process ends its loop and exits.
        let _ = Command::new("kill").arg(self.0.id().to_string()).status();
        let _ = self.0.wait();
    }
}

/// Starts the loopback drives and returns once they say `ready` (their boot-ups are on the
/// bus). The daemon's start-up gives the nodes a bounded time to boot after its NMT reset;
/// starting it before the drive process is up made that a race between two process starts,
/// which a loaded host (or the emulator) loses. Waiting for the line is a condition, bounded
/// by a hang guard only.
fn drives(iface: &str) -> Drives {
    use std::io::BufRead;
    let mut child = Command::new(env!("CARGO_BIN_EXE_hytask"))
        .args(["sim-drive", "--iface", iface, "--nodes", "1,2,3"])
        .args(["--cycle-us", &PERIOD_US.to_string()])
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    let stdout = child.stdout.take().unwrap();
    let drives = Drives(child);
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let mut lines = std::io::BufReader::new(stdout).lines();
        let first = lines.next();
        let _ = tx.send(first);
        // Keep reading so the drive process never blocks on a full pipe.
        for _ in lines {}
    });
    match rx.recv_timeout(GUARD) {
        Ok(Some(Ok(line))) if line.starts_with("ready") => drives,
        other => panic!("sim-drive did not say ready within {GUARD:?}: {other:?}"),
    }
}

fn daemon(iface: &str, dir: &std::path::Path) -> Daemon {
    daemon_with(iface, dir, |t| t)
}

/// The daemon on `config/vcan.toml` stretched for the emulator, its text changed by `edit`.
fn daemon_with(iface: &str, dir: &std::path::Path, edit: impl FnOnce(String) -> String) -> Daemon {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let text = std::fs::read_to_string(root.join("config/vcan.toml"))
        .unwrap()
        .replace("interface = \"vcan0\"", &format!("interface = \"{iface}\""))
        .replacen("period_us = 10000", "period_us = 20000", 1)
        .replacen("period_us = 2000", &format!("period_us = {PERIOD_US}"), 1)
        .replace(
            "heartbeat_ms = 50",
            "heartbeat_ms = 500\nsdo_timeout_ms = 2000",
        );
    let path = dir.join("vcan.toml");
    std::fs::write(&path, edit(text)).unwrap();
    Daemon::start(&path)
}

fn job(c: &mut hytask::control::client::Client, dir: &std::path::Path, text: &str) {
    let path = dir.join("job.ngc");
    std::fs::write(&path, text).unwrap();
    ok(c, "job.load", json!({"path": path.display().to_string()}));
    ok(c, "job.run", Value::Null);
}

#[test]
fn homes_and_runs_a_job_to_completion_on_vcan() {
    let Some(iface) = vcan::iface(NAME) else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let _drives = drives(&iface);
    let d = daemon(&iface, dir.path());
    let mut c = d.client();
    ready(&mut c);
    square_job(&mut c, dir.path(), &[("X", 12.5), ("Y", 7.25), ("Z", -2.0)]);
}

/// Runs the two-move job to completion; checks that it ended `done` and that each of `want`'s
/// axes is at rest where the job left it.
fn square_job(
    c: &mut hytask::control::client::Client,
    dir: &std::path::Path,
    want: &[(&str, f64)],
) {
    job(
        c,
        dir,
        // 20 mm/s: 0.2 mm per stretched 10 ms cycle, well inside the 1 mm limit with the
        // loopback drive's lag (the monitor compares each position with the setpoint it
        // answers, also when a TPDO comes a cycle or more late under emulation).
        "G21 G90\nG1 X20 Y10 Z-5 F1200\nG1 X12.5 Y7.25 Z-2\nM2\n",
    );
    let s = wait_status(c, "job done", GUARD, |s| {
        s["job"]["state"] == json!("done") || s["job"]["state"] == json!("failed")
    });
    assert_eq!(s["job"]["state"], json!("done"), "{}", s["job"]);
    let s = wait_status(c, "at rest", GUARD, |s| at_rest(s, 1e-6));
    for &(name, want) in want {
        let x = axis(&s, name)["actual"].as_f64().unwrap();
        assert!((x - want).abs() < 1e-3, "{name} at {x}, want {want}");
    }
}

/// `homing = "drive"` on node 1 (X): the loopback drive in the other process searches its
/// home switch (method 19, at 10 mm of motor travel), takes the home offset (5 mm) and the
/// master brings it back to CSP through the PDOs; then a job runs to completion from there.
#[test]
fn homes_in_the_drive_then_runs_a_job_on_vcan() {
    let Some(iface) = vcan::iface(NAME) else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let _drives = drives(&iface);
    let d = daemon_with(&iface, dir.path(), |t| {
        t.replacen(
            &format!("interface = \"{iface}\"\nnode_id = 1\n"),
            &format!(
                "interface = \"{iface}\"\nnode_id = 1\nhoming = \"drive\"\nhoming_method = 19\n"
            ),
            1,
        )
        .replacen(
            "home = { method = \"current_position\", position = 0.0 }",
            "home = { method = \"current_position\", position = 5.0 }",
            1,
        )
    });
    let mut c = d.client();
    ready(&mut c);
    let s = ok(&mut c, "status", Value::Null);
    let x = axis(&s, "X")["actual"].as_f64().unwrap();
    assert!(
        (x - 5.0).abs() < 1e-3,
        "X homed at {x}, want the home offset 5"
    );
    square_job(&mut c, dir.path(), &[("X", 12.5)]);
}

fn fault_mid_job(drive: &str, sub: u8, value: i64, size: u8, node: u8, cause: &str) {
    let Some(iface) = vcan::iface(NAME) else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let _drives = drives(&iface);
    let d = daemon(&iface, dir.path());
    let mut c = d.client();
    ok(&mut c, "subscribe", Value::Null);
    ready(&mut c);
    job(
        &mut c,
        dir.path(),
        "G21 G90\nG1 X10 F600\nG1 X250 Y250 F1200\nG1 X0 Y0\nM2\n",
    );
    wait_status(&mut c, "job moving on line 3", GUARD, |s| {
        s["mode"] == json!("running") && s["job"]["line"].as_u64().unwrap() >= 3
    });
    ok(
        &mut c,
        "drive.sdo_write",
        json!({"drive": drive, "index": "0x2000", "sub": sub, "value": value, "size": size}),
    );
    let events = wait_event(&mut c, "job failed", GUARD, |e| {
        e.topic == "job" && e.data["state"] == json!("failed")
    });
    let fault = events
        .iter()
        .find(|e| e.topic == "fault")
        .map(|e| e.data["message"].as_str().unwrap().to_string())
        .unwrap();
    assert!(
        fault.contains(&format!("CANopen node {node}")) && fault.contains(cause),
        "{fault}"
    );
    let reason = events.last().unwrap().data["reason"].to_string();
    assert!(reason.contains("line 3"), "{reason}");
    let s = wait_status(&mut c, "stopped in fault", GUARD, |s| {
        s["mode"] == json!("fault") && at_rest(s, 1e-6)
    });
    assert!(s["faults"].to_string().contains(&format!("node {node}")));
}

#[test]
fn a_drive_fault_on_vcan_stops_the_machine_naming_the_node() {
    fault_mid_job("y-servo", 1, 0x2310, 2, 2, "0x2310");
}

#[test]
fn a_heartbeat_loss_on_vcan_stops_the_machine_naming_the_node() {
    fault_mid_job("z-servo", 2, 1, 1, 3, "heartbeat lost");
}

#[test]
fn an_emcy_on_vcan_stops_the_machine_naming_the_node() {
    fault_mid_job("x-servo", 3, 0x4210, 2, 1, "emergency (error code 0x4210");
}
