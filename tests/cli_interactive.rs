//! `hytask run`, `home`, `mdi` and `jog` driven as a person drives them: the real binary on a
//! pseudo-terminal (`tests/cli_pty`), Ctrl-C sent as SIGINT to its process group. The
//! machine is the fast-homing sim mill on a simulated clock (`tests/support`), so what the
//! machine does does not depend on the host's load; every wait is a hang guard.
#![allow(clippy::unwrap_used)]

mod cli_pty;
mod support;

use cli_pty::PtyChild;
use std::ffi::OsStr;
use support::*;

/// `hytask run` on the embedded machine: the first Ctrl-C holds the job and says how to go
/// on, the second aborts it; the embedded daemon stops the axes and the command exits with
/// 130 (interrupted) and a one-line summary, never "Broken pipe".
#[test]
fn ctrl_c_holds_then_aborts_a_run_on_the_embedded_machine() {
    let dir = tempfile::tempdir().unwrap();
    let config = sim_clock_config(dir.path(), SIM_SPEED, None);
    let job = fixture("jobs/long.ngc");
    let missing = dir.path().join("no-daemon.sock");
    let mut p = PtyChild::spawn(&[
        OsStr::new("run"),
        job.as_os_str(),
        OsStr::new("--config"),
        config.as_os_str(),
        OsStr::new("--socket"),
        missing.as_os_str(),
    ]);
    p.expect("running on the embedded machine");
    // The job is moving once its progress shows a line of the program.
    p.expect("line 6/");
    p.ctrl_c();
    let held = p.expect("Ctrl-C again aborts");
    assert!(held.contains("feed hold"), "{held}");
    p.ctrl_c();
    let (status, out) = p.wait();
    assert!(!out.contains("Broken pipe"), "{out}");
    assert_eq!(status.code(), Some(130), "{out}");
    assert!(out.contains("aborted by Ctrl-C"), "{out}");
    assert!(out.contains("axes stopped"), "{out}");
}

/// `hytask ARGS --socket S` on a pty.
fn hytask(d: &Daemon, args: &[&str]) -> PtyChild {
    let mut all: Vec<&OsStr> = args.iter().map(OsStr::new).collect();
    all.push(OsStr::new("--socket"));
    all.push(d.socket.as_os_str());
    PtyChild::spawn(&all)
}

fn actual(s: &serde_json::Value, name: &str) -> f64 {
    axis(s, name)["actual"].as_f64().unwrap()
}

/// `home`, `mdi` and `jog --distance` return when their motion has ended, so the next
/// command finds the machine idle (before, it failed with "machine is busy"); homing shows
/// each axis on the terminal.
#[test]
fn home_mdi_and_jog_wait_until_the_motion_has_ended() {
    let d = Daemon::start_sim();
    let mut c = d.client();
    ok(&mut c, "estop.reset", serde_json::Value::Null);
    ok(&mut c, "machine.on", serde_json::Value::Null);

    let mut p = hytask(&d, &["home"]);
    let progress = p.expect("homing:");
    let (status, out) = p.wait();
    assert!(status.success(), "{progress}{out}");
    assert!(out.contains(" homing") || out.contains(" homed"), "{out}");
    let s = ok(&mut c, "status", serde_json::Value::Null);
    assert_eq!(s["mode"], "idle", "{s}");
    assert!(s["axes"]
        .as_array()
        .unwrap()
        .iter()
        .all(|a| a["homed"] == true));

    let (status, out) = hytask(&d, &["mdi", "G0 X100 Y120 Z-5"]).wait();
    assert!(status.success(), "{out}");
    let s = ok(&mut c, "status", serde_json::Value::Null);
    assert_eq!(s["mode"], "idle", "{s}");
    assert!((actual(&s, "X") - 100.0).abs() < 0.01, "{s}");
    assert!((actual(&s, "Y") - 120.0).abs() < 0.01, "{s}");

    let (status, out) = hytask(&d, &["jog", "Y", "-20", "--distance", "15"]).wait();
    assert!(status.success(), "{out}");
    let s = ok(&mut c, "status", serde_json::Value::Null);
    assert_eq!(s["mode"], "idle", "{s}");
    assert!((actual(&s, "Y") - 105.0).abs() < 0.01, "{s}");
}

/// Ctrl-C during a waiting `mdi` stops the move under control (the machine stays on and
/// idle, short of the target) and exits 130; an e-stop during the wait fails the command
/// with an error naming it.
#[test]
fn ctrl_c_stops_a_waiting_mdi_and_an_estop_fails_it() {
    let d = Daemon::start_sim();
    let mut c = d.client();
    ready(&mut c);
    // 354 mm at 1 mm/s: minutes of machine time, so Ctrl-C lands in the move however late
    // this thread runs on a loaded host.
    let mut p = hytask(&d, &["mdi", "G1 X50 Y50 Z-5 F60"]);
    p.expect("MDI line:");
    p.ctrl_c();
    let (status, out) = p.wait();
    assert_eq!(status.code(), Some(130), "{out}");
    assert!(out.contains("MDI line stopped by Ctrl-C"), "{out}");
    let s = ok(&mut c, "status", serde_json::Value::Null);
    assert_eq!(s["mode"], "idle", "{s}");
    assert!(actual(&s, "X") > 51.0, "the move was not stopped: {s}");

    // Wherever the first move stopped, the farther end of X: at least 124 mm at 1 mm/s, so
    // the e-stop lands in the move too.
    let target = if actual(&s, "X") > 175.0 { 50 } else { 299 };
    let line = format!("G1 X{target} F60");
    let mut p = hytask(&d, &["mdi", &line]);
    p.expect("MDI line:");
    ok(&mut c, "estop", serde_json::Value::Null);
    let (status, out) = p.wait();
    assert_eq!(status.code(), Some(1), "{out}");
    assert!(out.contains("MDI line stopped: machine in estop"), "{out}");
}
