//! End to end: LinuxCNC's log comments, `(LOGOPEN,…)`, `(LOGAPPEND,…)`, `(LOG,…)` and
//! `(LOGCLOSE)`, write a file on the real `hytask serve` binary, on a simulated clock (see
//! `tests/support/mod.rs`), confined to the machine's `[gcode] log_dir`. A probing job logs
//! the value it measured on the simulated touch plate (the piece after the probe is read
//! with the live result); a name outside the log directory, or a machine without one, writes
//! nothing, tells the operator with the line, and the job still runs to its end.
#![allow(clippy::unwrap_used)]

mod support;

use hytask::control::client::{Client, Event};
use serde_json::{json, Value};
use std::path::Path;
use std::time::Duration;
use support::*;

/// Hang guard of the waits for a job's end.
const GUARD: Duration = Duration::from_secs(180);

/// Top of the simulated touch plate under Z.
const PLATE: f64 = -10.0;

/// The simulated mill with a touch plate, with `[gcode] log_dir = "logs"` when `log_dir`.
fn machine(dir: &Path, log_dir: bool) -> Daemon {
    let config = sim_clock_config(dir, SIM_SPEED, Some(PLATE));
    if log_dir {
        std::fs::create_dir(dir.join("logs")).unwrap();
        let mut text = std::fs::read_to_string(&config).unwrap();
        assert!(
            !text.contains("[gcode]"),
            "the fixture has a [gcode] table now"
        );
        text.push_str("\n[gcode]\nlog_dir = \"logs\"\n");
        std::fs::write(&config, text).unwrap();
    }
    Daemon::start(&config)
}

fn run_to_end(c: &mut Client, text: &str, name: &str) -> (Value, Vec<Event>) {
    ok(c, "subscribe", Value::Null);
    run_text(c, text, name);
    let events = wait_event(c, "the job's end", GUARD, |e| {
        e.topic == "job"
            && matches!(
                e.data["state"].as_str(),
                Some("done" | "failed" | "aborted")
            )
    });
    (ok(c, "status", Value::Null), events)
}

#[test]
fn a_probing_job_logs_what_it_measured_into_the_log_dir() {
    let dir = tempfile::tempdir().unwrap();
    let d = machine(dir.path(), true);
    let mut c = d.client();
    ready(&mut c);
    let text = "G21 G90\n(LOGOPEN,probe.txt)\n(LOG,start)\nG0 X50 Y50 Z0\n\
                G38.2 Z-30 F300\n(LOG,z=#5063 ok=#5070)\n(LOGCLOSE)\n(LOG,not written)\n\
                (LOGAPPEND,probe.txt)\n(LOG,x=#<_x>)\n(LOGCLOSE)\nG0 Z0\nM2\n";
    let (s, _) = run_to_end(&mut c, text, "log-probe.ngc");
    assert_eq!(s["job"]["state"], json!("done"), "{}", s["job"]);
    let log = std::fs::read_to_string(dir.path().join("logs/probe.txt")).unwrap();
    let lines: Vec<&str> = log.lines().collect();
    assert_eq!(lines.len(), 3, "{log}");
    assert_eq!(lines[0], "start");
    // The plate trips the probe within a few µm of its top (2 µm per cycle at 5 mm/s).
    let z: f64 = lines[1]
        .strip_prefix("z=")
        .and_then(|r| r.split(' ').next())
        .unwrap()
        .parse()
        .unwrap();
    assert!((PLATE - 0.02..=PLATE + 0.001).contains(&z), "{log}");
    assert!(lines[1].ends_with("ok=1.000000"), "{log}");
    assert_eq!(lines[2], "x=50.000000", "{log}");
}

#[test]
fn a_name_outside_the_log_dir_writes_nothing_tells_the_line_and_the_job_runs_on() {
    let dir = tempfile::tempdir().unwrap();
    let d = machine(dir.path(), true);
    let mut c = d.client();
    ready(&mut c);
    let text = "G21 G90\n(LOGOPEN,../escape.txt)\n(LOG,secret)\nG0 X10\nM2\n";
    let (s, events) = run_to_end(&mut c, text, "log-escape.ngc");
    assert_eq!(s["job"]["state"], json!("done"), "{}", s["job"]);
    assert!(!dir.path().join("escape.txt").exists());
    let told = events.iter().find(|e| e.topic == "message").unwrap();
    assert_eq!(told.data["line"], json!(2), "{}", told.data);
    assert!(
        told.data["text"]
            .as_str()
            .unwrap()
            .contains("relative to [gcode] log_dir"),
        "{}",
        told.data
    );
}

#[test]
fn without_a_log_dir_log_comments_are_reported_and_the_job_runs() {
    let dir = tempfile::tempdir().unwrap();
    let d = machine(dir.path(), false);
    let mut c = d.client();
    ready(&mut c);
    let text = "G21 G90\nG0 X5\n(LOGAPPEND,x.txt)\n(LOG,x)\nG0 X10\nM2\n";
    let (s, events) = run_to_end(&mut c, text, "log-nodir.ngc");
    assert_eq!(s["job"]["state"], json!("done"), "{}", s["job"]);
    let told: Vec<&Event> = events.iter().filter(|e| e.topic == "message").collect();
    assert_eq!(told.len(), 1, "one message, for the LOGAPPEND");
    assert_eq!(told[0].data["line"], json!(3));
    assert!(told[0].data["text"]
        .as_str()
        .unwrap()
        .contains("no [gcode] log_dir"));
}
