//! The machine on CANopen drives, in this process: `config/vcan.toml` with its interface
//! switched to `sim`, so the master, the bus-owner tasks and three loopback CiA 402 drives
//! run on an in-memory bus stepped by the servo thread, on the simulated clock.
//!
//! Homing and a job to completion with the final position checked; then a drive fault, a
//! heartbeat loss, an EMCY and a bus error injected mid-job: each must give a controlled
//! stop, a fault naming the node and its cause, and a failed job naming its line. Faults
//! are injected as a test would on a real drive: an SDO write to the loopback drive's
//! fault-injection object 0x2000, over the runtime SDO path (never the servo thread).
//!
//! Every wait is a hang guard, never a timing.
#![allow(clippy::unwrap_used)]

mod support;

use hytask::machine::api::{JobSource, MachineApi, Mode, Status};
use hytask::machine::Machine;
use std::sync::Arc;
use std::time::Duration;
use support::wait_machine as wait;

const GUARD: Duration = Duration::from_secs(120);

fn config(dir: &std::path::Path) -> std::path::PathBuf {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let base = std::fs::read_to_string(root.join("config/vcan.toml")).unwrap();
    assert_eq!(base.matches("interface = \"vcan0\"").count(), 3);
    let text = base
        .replace("interface = \"vcan0\"", "interface = \"sim\"")
        .replace(
            "[[thread]]\n",
            "[[thread]]\nclock = \"simulated\"\nsim_speed = 4\n",
        );
    let path = dir.join("canopen-sim.toml");
    std::fs::write(&path, text).unwrap();
    path
}

fn machine() -> (tempfile::TempDir, Arc<Machine>) {
    machine_with(|t| t)
}

/// The machine of [`config`] with its text changed by `edit`.
fn machine_with(edit: impl FnOnce(String) -> String) -> (tempfile::TempDir, Arc<Machine>) {
    let dir = tempfile::tempdir().unwrap();
    let path = config(dir.path());
    std::fs::write(&path, edit(std::fs::read_to_string(&path).unwrap())).unwrap();
    let cfg = hytask::config::load(&path).unwrap();
    (dir, Machine::deploy(cfg).unwrap())
}

/// Drive-side homing on node 1 (axis X) with CiA 402 method `method`, home position 5 mm.
fn drive_homing(method: i8) -> impl FnOnce(String) -> String {
    move |t| {
        t.replacen(
            "interface = \"sim\"\nnode_id = 1\n",
            &format!(
                "interface = \"sim\"\nnode_id = 1\nhoming = \"drive\"\nhoming_method = {method}\nhoming_speeds = [5000, 1000]\n"
            ),
            1,
        )
        .replacen(
            "home = { method = \"current_position\", position = 0.0 }",
            "home = { method = \"current_position\", position = 5.0 }",
            1,
        )
    }
}

/// The error of loading the test configuration with the first `from` replaced by `to`.
fn load_error(from: &str, to: &str) -> String {
    let dir = tempfile::tempdir().unwrap();
    let path = config(dir.path());
    let text = std::fs::read_to_string(&path)
        .unwrap()
        .replacen(from, to, 1);
    std::fs::write(&path, text).unwrap();
    hytask::config::load(&path).unwrap_err().to_string()
}

fn ready(m: &Machine) {
    m.estop_reset().unwrap();
    m.machine_on().unwrap();
    wait(m, "drives enabled", |s| {
        s.mode == Mode::Idle && s.axes.iter().all(|a| a.drive_state == "operation enabled")
    });
    m.home(None).unwrap();
    wait(m, "homed and idle", |s| {
        s.mode == Mode::Idle && s.axes.iter().all(|a| a.homed)
    });
}

fn job(program: &str) -> JobSource {
    JobSource {
        path: None,
        text: Some(program.into()),
        name: Some("canopen.ngc".into()),
    }
}

fn shutdown(m: &Machine) {
    hytask::daemon::Deployed::shutdown(m).unwrap();
}

const SQUARE: &str = "G21 G90\nG1 X20 Y10 Z-5 F3000\nG1 X40 Y30\nG1 X12.5 Y7.25 Z-2\nM2\n";

/// Runs [`SQUARE`] on a ready machine to the end and checks every axis at rest on the
/// program's end point.
fn run_square(m: &Machine) -> Status {
    m.job_load(&job(SQUARE)).unwrap();
    m.job_run().unwrap();
    let s = wait(m, "job done", |s| {
        s.job.state == "done" || s.job.state == "failed"
    });
    assert_eq!(s.job.state, "done", "{:?} {:?}", s.job, s.faults);
    let s = wait(m, "at rest", |s| {
        s.axes.iter().all(|a| a.velocity.abs() < 1e-6)
    });
    for (a, want) in s.axes.iter().zip([12.5, 7.25, -2.0]) {
        assert!(
            (a.actual - want).abs() < 1e-3,
            "axis {} at {} (want {want})",
            a.name,
            a.actual
        );
    }
    s
}

#[test]
fn homes_and_runs_a_job_to_completion_on_canopen_drives() {
    let (_dir, m) = machine();
    ready(&m);
    run_square(&m);
    // The drives themselves report the final target, in counts (scale 1000/mm).
    let counts = m.can_sdo().read("x-servo", 0x6064, 0).unwrap();
    let counts = i32::from_le_bytes(counts[..4].try_into().unwrap());
    assert!((counts - 12_500).abs() <= 1, "0x6064 = {counts}");
    shutdown(&m);
}

/// Runs a long job, injects `inject` once it moves, and checks the controlled stop, the
/// fault naming node and cause, and the failed job with its line.
fn fault_mid_job(inject: impl FnOnce(&Machine), who: &str, cause: &str, bus_alive: bool) {
    let (_dir, m) = machine();
    ready(&m);
    m.job_load(&job(
        "G21 G90\nG1 X10 F600\nG1 X250 Y250 F1200\nG1 X0 Y0\nM2\n",
    ))
    .unwrap();
    m.job_run().unwrap();
    wait(&m, "job moving on line 3", |s| {
        s.mode == Mode::Running && s.job.line >= 3
    });
    inject(&m);
    let s = wait(&m, "job failed", |s| s.job.state == "failed");
    let reason = s.job.reason.clone().unwrap();
    assert!(reason.contains(who) && reason.contains(cause), "{reason}");
    assert!(reason.contains("line 3"), "{reason}");
    // Without a bus the feedback is stale: only the mode can be checked.
    let s = wait(&m, "stopped in fault", |s| {
        s.mode == Mode::Fault && (!bus_alive || s.axes.iter().all(|a| a.velocity.abs() < 1e-6))
    });
    assert!(
        s.faults
            .iter()
            .any(|f| f.contains(who) && f.contains(cause)),
        "{:?}",
        s.faults
    );
    shutdown(&m);
}

#[test]
fn a_drive_fault_mid_job_stops_the_machine_and_names_the_node() {
    fault_mid_job(
        |m| {
            m.can_sdo()
                .write("y-servo", 0x2000, 1, &0x2310u16.to_le_bytes())
                .unwrap()
        },
        "CANopen node 2",
        "0x2310",
        true,
    );
}

#[test]
fn a_lost_heartbeat_mid_job_stops_the_machine_and_names_the_node() {
    fault_mid_job(
        |m| m.can_sdo().write("z-servo", 0x2000, 2, &[1]).unwrap(),
        "CANopen node 3",
        "heartbeat lost",
        true,
    );
}

#[test]
fn an_emcy_mid_job_stops_the_machine_and_names_the_node() {
    fault_mid_job(
        |m| {
            m.can_sdo()
                .write("x-servo", 0x2000, 3, &0x4210u16.to_le_bytes())
                .unwrap()
        },
        "CANopen node 1",
        "emergency (error code 0x4210",
        true,
    );
}

#[test]
fn a_bus_off_mid_job_stops_the_machine_and_names_the_interface() {
    fault_mid_job(
        |m| m.sim_can_bus(0).unwrap().set_bus_off(true),
        "sim: bus-off",
        "error code 0x8140",
        false,
    );
}

#[test]
fn an_error_frame_mid_job_stops_the_machine_and_names_the_interface() {
    fault_mid_job(
        |m| m.sim_can_bus(0).unwrap().error_frame(),
        "sim: error frame",
        "error code 0x8120",
        true,
    );
}

#[test]
fn a_bus_over_its_load_budget_does_not_deploy_and_says_what_fits() {
    let dir = tempfile::tempdir().unwrap();
    let path = config(dir.path());
    let text =
        std::fs::read_to_string(&path)
            .unwrap()
            .replacen("period_us = 2000", "period_us = 1000", 1);
    std::fs::write(&path, text).unwrap();
    let err = Machine::deploy(hytask::config::load(&path).unwrap())
        .err()
        .unwrap()
        .to_string();
    assert!(
        err.contains("drive[0] (x-servo).canopen.interface (sim)")
            && err.contains("3 drives at 1 kHz need 106 % of 1 Mbit/s")
            && err.contains("at most 2 fit, or use 500 Hz"),
        "{err}"
    );
}

#[test]
fn the_control_socket_reads_and_writes_drive_objects_by_sdo_and_an_emcy_names_its_node() {
    use serde_json::json;
    let dir = tempfile::tempdir().unwrap();
    let d = support::Daemon::start(&config(dir.path()));
    let mut c = d.client();
    ok_sub(&mut c);
    let hb = support::ok(
        &mut c,
        "drive.sdo_read",
        json!({"drive": "y-servo", "index": "0x1017", "sub": 0}),
    );
    assert_eq!(hb, json!({"data": "3200", "value": 50}), "heartbeat 50 ms");
    let (code, msg) = support::err(
        &mut c,
        "drive.sdo_read",
        json!({"drive": "nope", "index": 4096}),
    );
    assert!(
        code != 0 && msg.contains("no CANopen drive 'nope'"),
        "{msg}"
    );
    let (_, msg) = support::err(
        &mut c,
        "drive.sdo_read",
        json!({"drive": "x-servo", "index": "0x5555"}),
    );
    assert!(msg.contains("node 1: SDO 5555:00 aborted"), "{msg}");
    // The CLI goes through the same method.
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_hytask"))
        .args(["sdo-read", "z-servo", "0x6060", "--socket"])
        .arg(&d.socket)
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success() && text.contains("\"value\": 8"),
        "{text}"
    );
    support::ready(&mut c);
    support::ok(
        &mut c,
        "drive.sdo_write",
        json!({"drive": "z-servo", "index": "0x2000", "sub": 3, "value": 0x4210, "size": 2}),
    );
    let events = support::wait_event(&mut c, "fault", GUARD, |e| e.topic == "fault");
    let f = &events.last().unwrap().data;
    assert!(
        f["message"]
            .as_str()
            .unwrap()
            .contains("axis Z: CANopen node 3: emergency (error code 0x4210"),
        "{f}"
    );
    let s = support::wait_status(&mut c, "fault mode", GUARD, |s| s["mode"] == json!("fault"));
    assert!(
        s["faults"].to_string().contains("CANopen node 3"),
        "{}",
        s["faults"]
    );
}

fn ok_sub(c: &mut hytask::control::client::Client) {
    support::ok(c, "subscribe", serde_json::Value::Null);
}

#[test]
fn a_canopen_axis_that_homes_on_a_switch_is_refused_by_the_check() {
    let err = load_error(
        "home = { method = \"current_position\", position = 0.0 }",
        "home = { method = \"switch\", position = 0.0, velocity = 10.0 }",
    );
    assert!(
        err.contains("drive[0] (x-servo).canopen: axis X homes with a switch, which the master cannot do on a CANopen drive")
            && err.contains("homing = \"drive\" and homing_method"),
        "{err}"
    );
}

/// `homing = "drive"`: the loopback drive searches its home switch (method 19: at 10 mm of
/// motor travel, positive direction), backs off to its edge and takes the home offset 0x607C
/// = 5 mm; the master switched it to homing mode and back to CSP through the PDOs. Then a
/// job runs from there without a jump (a jump would trip the 1 mm following-error limit).
#[test]
fn a_canopen_axis_homes_in_the_drive_then_runs_a_job() {
    let (_dir, m) = machine_with(drive_homing(19));
    m.estop_reset().unwrap();
    m.machine_on().unwrap();
    wait(&m, "drives enabled", |s| {
        s.mode == Mode::Idle && s.axes.iter().all(|a| a.drive_state == "operation enabled")
    });
    let sdo = |index, sub| m.can_sdo().read("x-servo", index, sub).unwrap();
    assert_eq!(sdo(0x6098, 0), [19], "method written at start-up");
    assert_eq!(
        sdo(0x607C, 0),
        5000i32.to_le_bytes(),
        "home offset in counts"
    );
    m.home(None).unwrap();
    // The drive moves toward its switch (10 mm at 5 mm/s): X is seen beyond 1 mm before it
    // is homed.
    wait(&m, "X searching its switch", |s| s.axes[0].actual > 1.0);
    let s = wait(&m, "homed and idle", |s| {
        s.mode == Mode::Idle && s.axes.iter().all(|a| a.homed)
    });
    assert!(
        (s.axes[0].actual - 5.0).abs() < 1e-3,
        "X at {}",
        s.axes[0].actual
    );
    assert_eq!(sdo(0x6061, 0), [8], "back in CSP");
    run_square(&m);
    let counts = i32::from_le_bytes(sdo(0x6064, 0)[..4].try_into().unwrap());
    assert!((counts - 12_500).abs() <= 1, "0x6064 = {counts}");
    shutdown(&m);
}

/// A homing method the drive does not have: the drive sets statusword bit 13 (homing
/// error), which is a fault naming node and axis, and homing fails.
#[test]
fn a_drive_homing_error_is_a_fault_naming_node_and_axis() {
    let (_dir, m) = machine_with(drive_homing(1));
    m.estop_reset().unwrap();
    m.machine_on().unwrap();
    wait(&m, "drives enabled", |s| {
        s.mode == Mode::Idle && s.axes.iter().all(|a| a.drive_state == "operation enabled")
    });
    m.home(None).unwrap();
    let s = wait(&m, "homing error reported", |s| {
        s.faults
            .iter()
            .any(|f| f.contains("CANopen node 1: homing error"))
    });
    assert!(
        s.faults
            .iter()
            .any(|f| f.contains("axis X") && f.contains("CANopen node 1: homing error")),
        "{:?}",
        s.faults
    );
    assert!(!s.axes[0].homed);
    assert_eq!(
        m.can_sdo().read("x-servo", 0x6061, 0).unwrap(),
        [8],
        "back in CSP after the error"
    );
    shutdown(&m);
}

#[test]
fn drive_homing_without_a_method_is_refused_naming_the_key() {
    let err = load_error("node_id = 1\n", "node_id = 1\nhoming = \"drive\"\n");
    assert!(
        err.contains("drive[0] (x-servo).canopen.homing_method: required with homing = \"drive\""),
        "{err}"
    );
}

/// A fault while the machine is in e-stop (drives disabled, nothing moving) is still a
/// fault event naming node and cause: the operator must learn about it before the next
/// machine-on, not from a refused enable.
fn fault_in_estop(inject: impl FnOnce(&Machine), node: u8, cause: &str) {
    let (_dir, m) = machine();
    wait(&m, "feedback from every drive", |s| {
        s.axes.iter().all(|a| a.drive_state == "switch on disabled")
    });
    assert_eq!(m.status().mode, Mode::Estop);
    inject(&m);
    let s = wait(&m, "fault reported", |s| {
        s.faults
            .iter()
            .any(|f| f.contains(&format!("CANopen node {node}")) && f.contains(cause))
    });
    assert_eq!(s.mode, Mode::Estop, "still in e-stop: {:?}", s.faults);
    shutdown(&m);
}

#[test]
fn a_drive_fault_in_estop_is_reported() {
    fault_in_estop(
        |m| {
            m.can_sdo()
                .write("y-servo", 0x2000, 1, &0x2310u16.to_le_bytes())
                .unwrap()
        },
        2,
        "0x2310",
    );
}

#[test]
fn an_emcy_and_a_lost_heartbeat_in_estop_are_reported() {
    fault_in_estop(
        |m| {
            m.can_sdo()
                .write("x-servo", 0x2000, 3, &0x4210u16.to_le_bytes())
                .unwrap()
        },
        1,
        "emergency (error code 0x4210",
    );
    fault_in_estop(
        |m| m.can_sdo().write("z-servo", 0x2000, 2, &[1]).unwrap(),
        3,
        "heartbeat lost",
    );
}

/// Every loopback drive follows with position-loop lag `lag_s`, every axis has the
/// following-error limit `limit`; runs a full-feed move on X and returns the final status.
fn full_feed_job(lag_s: f64, limit: f64) -> Status {
    let (_dir, m) = machine_with(|t| {
        t.replace(
            "interface = \"sim\"\n",
            &format!("interface = \"sim\"\nloopback_lag_s = {lag_s:?}\n"),
        )
        .replace(
            "following_error_limit = 1.0",
            &format!("following_error_limit = {limit:?}"),
        )
    });
    ready(&m);
    // F6000 = 100 mm/s, X's max_velocity: 0.2 mm per 2 ms cycle.
    m.job_load(&job("G21 G90\nG1 X100 F6000\nG1 X0\nM2\n"))
        .unwrap();
    m.job_run().unwrap();
    let s = wait(&m, "job ended", |s| {
        s.job.state == "done" || s.job.state == "failed"
    });
    shutdown(&m);
    s
}

/// The position a CANopen axis reports answers the setpoint of the previous cycle: the
/// monitor compares it with that one, so a drive that follows exactly does not trip a
/// limit (0.1 mm) tighter than one cycle's travel at full feed (0.2 mm).
#[test]
fn a_following_error_limit_under_one_cycles_travel_holds_at_full_feed() {
    let s = full_feed_job(0.0, 0.1);
    assert_eq!(s.job.state, "done", "{:?} {:?}", s.job, s.faults);
    assert!(
        s.axes[0].max_following_error < 0.1,
        "X max following error {}",
        s.axes[0].max_following_error
    );
}

/// A drive that really lags (50 ms: 5 mm at 100 mm/s) still trips its 1 mm limit.
#[test]
fn a_lagging_canopen_drive_still_trips_its_following_error_limit() {
    let s = full_feed_job(0.05, 1.0);
    assert_eq!(s.job.state, "failed", "{:?}", s.job);
    assert!(
        s.faults
            .iter()
            .any(|f| f.contains("axis X: following error") && f.contains("exceeds the limit 1")),
        "{:?}",
        s.faults
    );
}

/// `[drive.canopen]` of node 1 (x-servo) with `keys` added: the EDS of the loopback drive
/// and PDO mappings by its object names.
fn eds_keys(keys: &str) -> impl FnOnce(String) -> String + '_ {
    move |t| {
        let eds =
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("config/loopback-drive.eds");
        t.replacen(
            "interface = \"sim\"\nnode_id = 1\n",
            &format!(
                "interface = \"sim\"\nnode_id = 1\neds = {:?}\n{keys}\n",
                eds.display().to_string()
            ),
            1,
        )
    }
}

/// TPDO1 mapped by names to statusword, position and error code (8 bytes, not the default
/// layout): the drive is configured so and the machine homes and runs a job on it.
#[test]
fn pdos_mapped_by_eds_names_configure_the_drive_and_run_a_job() {
    let (_dir, m) = machine_with(eds_keys(
        "rpdo = [\"Controlword\", \"Target position\"]\ntpdo = [\"Statusword\", \"position actual value\", \"Error code\"]",
    ));
    let sdo = |index, sub| m.can_sdo().read("x-servo", index, sub).unwrap();
    assert_eq!(sdo(0x1A00, 0), [3]);
    assert_eq!(sdo(0x1A00, 3), 0x603F_0010u32.to_le_bytes());
    ready(&m);
    run_square(&m);
    shutdown(&m);
}

fn deploy_error(keys: &str) -> String {
    let dir = tempfile::tempdir().unwrap();
    let path = config(dir.path());
    let text = eds_keys(keys)(std::fs::read_to_string(&path).unwrap());
    std::fs::write(&path, text).unwrap();
    match Machine::deploy(hytask::config::load(&path).unwrap()) {
        Ok(_) => panic!("{keys}: deployed"),
        Err(e) => e.to_string(),
    }
}

#[test]
fn pdo_names_that_do_not_resolve_are_refused_naming_key_and_name() {
    let err = deploy_error("rpdo = [\"Controlword\", \"Target pos\"]");
    assert!(
        err.contains(
            "drive[0] (x-servo).canopen.rpdo[1]: no object named \"Target pos\" in the EDS"
        ),
        "{err}"
    );
    let err = deploy_error("tpdo = [\"Statusword\", \"Home offset\"]");
    assert!(
        err.contains(
            "drive[0] (x-servo).canopen.tpdo[1]: \"Home offset\" (607C:00) is not PDO-mappable"
        ),
        "{err}"
    );
    let err = deploy_error("tpdo = [\"Statusword\", \"Velocity actual value\"]");
    assert!(
        err.contains("drive[0] (x-servo).canopen.tpdo: must map Position actual value (6064:00)"),
        "{err}"
    );
    let err = deploy_error(
        "tpdo = [\"Statusword\", \"Position actual value\", \"Velocity actual value\"]",
    );
    assert!(
        err.contains(
            "drive[0] (x-servo).canopen.tpdo: PDO mapping: the mapped objects exceed the 8 bytes"
        ) && err.contains("take 10 bytes"),
        "{err}"
    );
}
