//! End to end over Modbus TCP: the real `hytask serve` on `config/sim-modbus.toml` (with the
//! fast-homing drives of the test fixture), its e-stop, spindle and coolant on the real
//! `hytask modbus-sim`.
//!
//! - M3/M8 in a job switch the simulator's coils;
//! - the e-stop input on the simulator stops the job;
//! - killing the simulator stops the machine with an `io` event naming the link, unit and
//!   point; the reset is refused while the link is down; a restarted simulator and a reset
//!   recover.
//!
//! Real time, as a daemon runs: every wait is a hang guard of a minute or more, never a
//! timing.
#![allow(clippy::unwrap_used)]

mod modbus_support;
mod support;

use modbus_support::{listen_addr, machine_config, Proc, GUARD};
use serde_json::{json, Value};
use std::path::Path;
use support::{err, ok, ready, wait_event, wait_status, Daemon};

/// `hytask modbus-sim` serving the map of `config` on `listen`, with the spindle's at-speed
/// input following its run coil; returns it and its address.
fn start_sim(config: &Path, listen: &str) -> (Proc, String) {
    let config = config.display().to_string();
    let args = [
        "--config",
        &config,
        "--listen",
        listen,
        "--exec",
        "follow spindle_at_speed spindle_on 200",
    ];
    let mut cmd = std::process::Command::new(env!("CARGO_BIN_EXE_hytask"));
    cmd.arg("modbus-sim").args(args);
    let p = Proc::spawn(cmd);
    let l = p.expect("listening", |l| l.starts_with("listening tcp "));
    (p, listen_addr(&l))
}

fn mode(s: &Value) -> &str {
    s["mode"].as_str().unwrap_or("")
}

#[test]
fn coils_follow_the_job_the_estop_input_stops_it_and_a_lost_link_needs_a_reset() {
    let dir = tempfile::tempdir().unwrap();
    // The simulator serves the map of the shipped file on a free port; the machine is then
    // pointed at that port.
    let shipped = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/sim-modbus.toml");
    let (mut sim, addr) = start_sim(&shipped, "127.0.0.1:0");
    let config = machine_config(dir.path(), &addr);
    let daemon = Daemon::start(&config);
    let mut c = daemon.client();
    ready(&mut c);

    // 1. M3/M8 in a job switch the coils; M9/M5 switch them off again.
    let job = dir.path().join("coolant.ngc");
    std::fs::write(&job, "G21 G90\nM3 S1200\nM8\nG1 X290 F600\nM9\nM5\nM2\n").unwrap();
    ok(
        &mut c,
        "job.load",
        json!({"path": job.display().to_string()}),
    );
    ok(&mut c, "job.run", Value::Null);
    // The simulator reports the changes of one poll cycle in map order, not program order.
    sim.expect_lines(&[
        "out spindle_on 1",
        "out spindle_speed 1200",
        "out coolant_flood 1",
    ]);
    // M9 and M5 often land in one poll cycle: either order is right.
    sim.expect_lines(&["out coolant_flood 0", "out spindle_on 0"]);
    wait_status(&mut c, "job done", GUARD, |s| {
        s["job"]["state"] == json!("done")
    });

    // 2. The e-stop input on the simulator stops a running job.
    let long = dir.path().join("long.ngc");
    std::fs::write(&long, "G21 G90\nM8\nG1 X100 F60\nM2\n").unwrap();
    ok(
        &mut c,
        "job.load",
        json!({"path": long.display().to_string()}),
    );
    ok(&mut c, "job.run", Value::Null);
    sim.expect_line("out coolant_flood 1");
    sim.send("set estop 1");
    let s = wait_status(&mut c, "e-stop from the Modbus input", GUARD, |s| {
        mode(s) == "estop"
    });
    assert_ne!(s["job"]["state"], json!("running"), "{s}");
    sim.expect_line("out coolant_flood 0");
    sim.send("set estop 0");
    wait_status(&mut c, "e-stop input released", GUARD, |s| {
        s["inputs"]["estop"] == json!(0.0)
    });
    ok(&mut c, "estop.reset", Value::Null);
    ready(&mut c);

    // 3. Killing the simulator stops the machine, naming the link, unit and point.
    ok(&mut c, "subscribe", Value::Null);
    drop(sim);
    let seen = wait_event(&mut c, "an io event for the lost link", GUARD, |e| {
        e.topic == "io" && e.data["kind"] != json!("recovered")
    });
    let io = &seen.last().unwrap().data;
    assert_eq!(io["link"], json!(format!("tcp:{addr}")), "{io}");
    assert_eq!(io["unit"], json!(1), "{io}");
    assert_eq!(io["device"], json!("panel"), "{io}");
    assert!(
        io["critical"].as_array().unwrap().contains(&json!("estop")),
        "{io}"
    );
    let msg = io["message"].as_str().unwrap();
    assert!(msg.contains(&format!("tcp:{addr} unit 1 (panel)")), "{msg}");
    let s = wait_status(&mut c, "e-stop on the lost link", GUARD, |s| {
        mode(s) == "estop"
    });
    let faults = s["faults"].to_string();
    assert!(faults.contains("communication lost"), "{s}");
    // No reset while the e-stop input is unknown.
    let (_, why) = err(&mut c, "estop.reset", Value::Null);
    assert!(!why.is_empty());

    // 4. The simulator is back: the points recover, and a reset brings the machine back.
    let (sim, _) = start_sim(&shipped, &addr);
    wait_event(&mut c, "the link's recovery", GUARD, |e| {
        e.topic == "io" && e.data["kind"] == json!("recovered")
    });
    assert_eq!(
        mode(&ok(&mut c, "status", Value::Null)),
        "estop",
        "latched until reset"
    );
    ok(&mut c, "estop.reset", Value::Null);
    ready(&mut c);
    ok(&mut c, "mdi", json!({"line": "M8"}));
    sim.expect_line("out coolant_flood 1");
}
