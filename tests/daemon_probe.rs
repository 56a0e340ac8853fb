//! End to end: probing (G38.x) on the real `hytask serve` binary, on a simulated clock
//! (see `tests/support/mod.rs`). The machine's simulated touch plate under Z (top at Z-10)
//! drives the `probe` input inside the servo cycle, as a real plate would, so where the probe
//! trips does not depend on the host's load or on a watcher's polling.
#![allow(clippy::unwrap_used)]

mod support;

use serde_json::{json, Value};
use std::time::Duration;
use support::*;

/// Top of the simulated plate.
const PLATE: f64 = -10.0;

/// Hang guard of the waits for a job's end.
const GUARD: Duration = Duration::from_secs(180);

fn machine_with_plate() -> Daemon {
    Daemon::start_sim_with(SIM_SPEED, Some(PLATE))
}

#[test]
fn a_job_that_probes_measures_the_plate_and_goes_on_with_the_result() {
    let d = machine_with_plate();
    let mut c = d.client();
    ready(&mut c);
    let info = run_job(&mut c, "jobs/probe.ngc");
    assert_eq!(info["name"], json!("probe.ngc"));
    let s = wait_job_end(&mut c, "probing job", GUARD);
    assert_eq!(s["job"]["state"], json!("done"), "{}", s["job"]);
    assert_eq!(s["mode"], json!("idle"));
    // Two probes; the last (G38.3 along X) made no contact and ended at X170.
    assert_eq!(s["probe"]["count"], json!(2));
    assert_eq!(s["probe"]["tripped"], json!(false));
    assert!((s["probe"]["position"]["X"].as_f64().unwrap() - 170.0).abs() < 0.01);
    // Final move: X 100 + 10·#5070 = 100, Z = plate top + 1 (the plate trips the probe in
    // the servo cycle Z reaches it: 2 µm per cycle at 2 mm/s, plus the drive's lag).
    let x = axis(&s, "X")["actual"].as_f64().unwrap();
    let z = axis(&s, "Z")["actual"].as_f64().unwrap();
    assert!((x - 100.0).abs() < 0.002, "X {x}");
    assert!((-9.02..=-8.999).contains(&z), "Z {z}: plate at -10, + 1");
}

#[test]
fn g38_2_without_contact_fails_the_job_naming_the_line_and_the_machine_stays_on() {
    let d = machine_with_plate();
    let mut c = d.client();
    ready(&mut c);
    let text = "G21 G90\nG0 X150 Y150 Z-2\nG38.2 Z-6 F600\nG0 Z0\nM2\n";
    ok(
        &mut c,
        "job.load",
        json!({"text": text, "name": "miss.ngc"}),
    );
    ok(&mut c, "job.run", Value::Null);
    let s = wait_job_end(&mut c, "failed probe", GUARD);
    assert_eq!(s["job"]["state"], json!("failed"));
    let reason = s["job"]["reason"].as_str().unwrap();
    assert!(
        reason.contains("line 3") && reason.contains("G38.2 move finished without tripping"),
        "{reason}"
    );
    assert_eq!(s["mode"], json!("idle"), "a program error is not a fault");
    let z = axis(&s, "Z")["actual"].as_f64().unwrap();
    assert!(
        (z + 6.0).abs() < 0.01,
        "ran to the end of the probe move: {z}"
    );
    // The machine takes the next job at once.
    ok(&mut c, "mdi", json!({"line": "G0 Z-1"}));
    let s = wait_job_end(&mut c, "mdi after a failed probe", GUARD);
    assert_eq!(s["mode"], json!("idle"));
    assert!((axis(&s, "Z")["actual"].as_f64().unwrap() + 1.0).abs() < 0.01);
}

#[test]
fn an_error_that_depends_on_the_measurement_fails_the_job_at_the_probe() {
    let d = machine_with_plate();
    let mut c = d.client();
    ready(&mut c);
    // The dry run before motion simulates a probe that reports #5070 = 0 (as rs274 does), so
    // the whole program checks out; live, the plate trips the probe, #5070 = 1 and line 3
    // divides by zero. The error can only show at the probe.
    let text = "G21 G90 F600\nG38.3 Z-20\nG1 Z[1 / [#5070 - 1]]\nM2\n";
    ok(&mut c, "job.load", json!({"text": text, "name": "div.ngc"}));
    ok(&mut c, "job.run", Value::Null);
    let s = wait_job_end(&mut c, "error after probe", GUARD);
    assert_eq!(s["job"]["state"], json!("failed"), "{}", s["job"]);
    let reason = s["job"]["reason"].as_str().unwrap();
    assert!(reason.starts_with("div.ngc:3:"), "{reason}");
    assert_eq!(s["mode"], json!("idle"));
    let z = axis(&s, "Z")["actual"].as_f64().unwrap();
    assert!((-12.0..=-10.0).contains(&z), "stopped at the plate: {z}");
}

#[test]
fn mdi_probing_touches_off_and_a_tripped_probe_refuses_to_start() {
    let d = machine_with_plate();
    let mut c = d.client();
    ready(&mut c);
    ok(&mut c, "mdi", json!({"line": "G21 G90 G38.2 Z-20 F300"}));
    let s = wait_status(&mut c, "mdi probe", Duration::from_secs(120), |s| {
        s["mode"] == json!("idle") && s["probe"]["count"] == json!(1)
    });
    assert_eq!(s["probe"]["tripped"], json!(true));
    let pz = s["probe"]["position"]["Z"].as_f64().unwrap();
    assert!((PLATE - 0.01..=PLATE).contains(&pz), "{pz}");
    // The probe stopped on the plate, so it is still touching: another G38.2 is refused
    // before it moves (LinuxCNC's rule).
    assert_eq!(s["inputs"]["probe"], json!(1.0), "{}", s["inputs"]);
    let z0 = axis(&s, "Z")["actual"].as_f64().unwrap();
    // Refused as an error before anything moves, whatever the timing (LinuxCNC: "Probe is
    // already tripped when starting G38.2 or G38.3 move"); the loaded or last job is left
    // as it was.
    let before = s["job"].clone();
    for line in ["G38.2 Z-20 F300", "G38.3 Z-20 F300"] {
        let (code, message) = err(&mut c, "mdi", json!({ "line": line }));
        assert_eq!(code, 1, "{message}");
        assert!(
            message.contains("probe is already tripped when starting G38.2 or G38.3 move"),
            "{message}"
        );
    }
    let s = ok(&mut c, "status", Value::Null);
    assert_eq!(s["mode"], json!("idle"));
    assert_eq!(s["job"], before);
    // G38.4 (away from the plate) is what starts from a tripped probe.
    ok(&mut c, "mdi", json!({"line": "G38.4 Z-5 F300"}));
    let s = wait_status(&mut c, "probe away", Duration::from_secs(120), |s| {
        s["mode"] == json!("idle") && s["probe"]["count"] == json!(2)
    });
    assert_eq!(s["job"]["state"], json!("done"), "{}", s["job"]);
    assert_eq!(s["inputs"]["probe"], json!(0.0));
    assert!(axis(&s, "Z")["actual"].as_f64().unwrap() > z0);
    // And from an untripped probe, G38.4 is refused the same way.
    let (code, message) = err(&mut c, "mdi", json!({"line": "G38.4 Z-1 F300"}));
    assert_eq!(code, 1, "{message}");
    assert!(
        message.contains("probe is not tripped when starting G38.4 or G38.5 move"),
        "{message}"
    );
    let z1 = axis(&s, "Z")["actual"].as_f64().unwrap();
    let s = ok(&mut c, "status", Value::Null);
    assert!((axis(&s, "Z")["actual"].as_f64().unwrap() - z1).abs() < 1e-3);
}
