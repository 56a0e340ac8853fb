//! The PLC in the machine, end to end (issue 11, sections 2 and 3): the built-in mill's PLC
//! program (config/plc/mill.st) driven through simulated inputs and G-code jobs on a daemon
//! with a simulated clock, and the bindings refused at deployment.

#![allow(clippy::unwrap_used)]

mod support;

use hytask::config::{self, MachineConfig};
use hytask::control::client::Client;
use serde_json::{json, Value};
use std::path::{Path, PathBuf};
use std::time::Duration;
use support::*;

const HANG: Duration = Duration::from_secs(120);

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// config/sim.toml with fast homing (as tests/fixtures/sim-fast.toml), on a simulated clock,
/// with its PLC program read from config/plc/mill.st by absolute path, and `edit` applied to the text.
fn mill_config(dir: &Path, edit: impl Fn(String) -> String) -> PathBuf {
    let mut text = std::fs::read_to_string(root().join("config/sim.toml")).unwrap();
    for (from, to, n) in [
        ("initial_position = 150.0", "initial_position = 298.0", 2),
        ("initial_position = -50.0", "initial_position = -2.0", 1),
        (
            "velocity = 20.0, latch_velocity = 2.0",
            "velocity = 40.0, latch_velocity = 5.0",
            2,
        ),
        (
            "velocity = 10.0, latch_velocity = 1.0",
            "velocity = 20.0, latch_velocity = 5.0",
            1,
        ),
        (
            "[[thread]]\n",
            &format!("[[thread]]\nclock = \"simulated\"\nsim_speed = {SIM_SPEED}\n"),
            2,
        ),
        (
            "program = \"builtin:plc/mill.st\"",
            &format!(
                "program = {:?}",
                root().join("config/plc/mill.st").display().to_string()
            ),
            1,
        ),
    ] {
        assert_eq!(
            text.matches(from).count(),
            n,
            "config/sim.toml changed: {from}"
        );
        text = text.replace(from, to);
    }
    // Tools 1-12 in pockets 1-12 of the carousel; tool 40 in a pocket it does not have.
    let table: String = (1..=12)
        .chain([40])
        .map(|t| format!("T{t} P{t} Z0 D0\n"))
        .collect();
    std::fs::write(dir.join("tools.tbl"), table).unwrap();
    text = text.replace("[plc]\n", "[tool_table]\npath = \"tools.tbl\"\n\n[plc]\n");
    let path = dir.join("mill.toml");
    std::fs::write(&path, edit(text)).unwrap();
    path
}

fn start(edit: impl Fn(String) -> String) -> (Daemon, tempfile::TempDir) {
    let dir = tempfile::tempdir().unwrap();
    let d = Daemon::start(&mill_config(dir.path(), edit));
    (d, dir)
}

fn input(c: &mut Client, name: &str, on: bool) {
    ok(c, "sim.input", json!({"name": name, "value": u8::from(on)}));
}

fn output(s: &Value, name: &str) -> f64 {
    s["outputs"][name]
        .as_f64()
        .unwrap_or_else(|| panic!("no output {name}: {s}"))
}

/// M6 waits for the PLC's carousel: the motor turns while the job stands at the M6, and the
/// job goes on once the PLC reports the change done.
#[test]
fn m6_waits_for_the_plc_carousel() {
    let (d, _dir) = start(|t| t);
    let mut c = d.client();
    ready(&mut c);
    run_text(&mut c, "G21 G90\nT11 M6\nG0 X100\nM2\n", "m6.ngc");
    let s = wait_status(&mut c, "carousel turning", HANG, |s| {
        output(s, "carousel_motor") == 1.0
    });
    assert_eq!(s["job"]["state"], json!("running"), "{s}");
    assert_eq!(s["job"]["line"], json!(2), "the job waits at the M6: {s}");
    let s = wait_job_end(&mut c, "job end", HANG);
    assert_eq!(s["job"]["state"], json!("done"), "{s}");
    assert_eq!(output(&s, "carousel_motor"), 0.0);
    assert!(
        (axis(&s, "X")["actual"].as_f64().unwrap() - 100.0).abs() < 0.01,
        "{s}"
    );
    let plc = &s["plc"];
    assert!(
        plc["scans"].as_u64().unwrap() > 0,
        "scan statistics in status: {s}"
    );
    assert_eq!(plc["fault"], json!(false));
    // The PLC is a task of its own, on its own thread, as `hytask tasks` lists it.
    let tasks = ok(&mut c, "tasks", Value::Null);
    let task = |name: &str| {
        tasks
            .as_array()
            .unwrap()
            .iter()
            .find(|t| t["name"] == name)
            .unwrap_or_else(|| panic!("no {name} task: {tasks}"))
            .clone()
    };
    let (plc, machine) = (task("plc"), task("machine"));
    assert_eq!(plc["state"], json!("running"), "{plc}");
    // config/sim.toml's `plc` thread: 10 ms, priority 60, not the 1 ms servo thread.
    assert_eq!(plc["thread"], json!("rt-p60-10000us"), "{plc}");
    assert_ne!(plc["thread"], machine["thread"], "{plc} {machine}");
}

/// A tool the carousel cannot find: the M6 times out and the job is aborted with its line.
#[test]
fn m6_timeout_aborts_the_job_naming_its_line() {
    let (d, _dir) = start(|t| {
        t.replace(
            "tool_change_timeout_s = 30.0",
            "tool_change_timeout_s = 1.0",
        )
    });
    let mut c = d.client();
    ready(&mut c);
    run_text(
        &mut c,
        "G21 G90\nG0 X50\nT40 M6\nG0 X100\nM2\n",
        "m6-timeout.ngc",
    );
    let s = wait_job_end(&mut c, "job end", HANG);
    assert_eq!(s["job"]["state"], json!("failed"), "{s}");
    let reason = s["job"]["reason"].as_str().unwrap_or_default();
    assert!(
        reason.contains("line 3") && reason.contains("M6"),
        "{reason}"
    );
    assert!(
        (axis(&s, "X")["actual"].as_f64().unwrap() - 50.0).abs() < 0.01,
        "{s}"
    );
    assert_eq!(
        s["mode"],
        json!("idle"),
        "a program error, not a machine fault: {s}"
    );
}

/// An M100–M199 the PLC takes but never finishes (M150: routed to the PLC, unknown to
/// mill.st): the job is aborted after `plc.mcode_timeout_s`, naming the M-code and its line.
#[test]
fn mcode_timeout_aborts_the_job_naming_its_line() {
    let (d, _dir) = start(|t| {
        for from in ["mcode_timeout_s = 5.0", "mcodes = [100]"] {
            assert_eq!(
                t.matches(from).count(),
                1,
                "config/sim.toml changed: {from}"
            );
        }
        t.replace("mcode_timeout_s = 5.0", "mcode_timeout_s = 1.0")
            .replace("mcodes = [100]", "mcodes = [100, 150]")
    });
    let mut c = d.client();
    ready(&mut c);
    run_text(
        &mut c,
        "G21 G90\nG0 X50\nM150\nG0 X100\nM2\n",
        "m150-timeout.ngc",
    );
    let s = wait_job_end(&mut c, "job end", HANG);
    assert_eq!(s["job"]["state"], json!("failed"), "{s}");
    let reason = s["job"]["reason"].as_str().unwrap_or_default();
    assert!(
        reason.contains("line 3") && reason.contains("M150") && reason.contains("mcode_timeout_s"),
        "{reason}"
    );
    assert!(
        (axis(&s, "X")["actual"].as_f64().unwrap() - 50.0).abs() < 0.01,
        "stopped before the move after the M150: {s}"
    );
}

/// The guard door: open, cycle start is refused; opened mid-job, feed holds; resume is
/// refused until it is closed again, then the job finishes.
#[test]
fn guard_door_holds_feed_and_refuses_start() {
    let (d, _dir) = start(|t| t);
    let mut c = d.client();
    ready(&mut c);
    input(&mut c, "door_open", true);
    wait_status(&mut c, "start inhibited", HANG, |s| {
        s["inputs"]["door_open"] == json!(1.0)
    });
    // The PLC scans every 10 ms of simulated time: give it a few scans to see the door.
    std::thread::sleep(Duration::from_millis(200));
    ok(
        &mut c,
        "job.load",
        json!({"text": "G21 G90\nG1 X20 F600\nM2\n", "name": "door.ngc"}),
    );
    let (_, msg) = err(&mut c, "job.run", Value::Null);
    assert!(msg.contains("start_inhibit"), "{msg}");
    input(&mut c, "door_open", false);
    std::thread::sleep(Duration::from_millis(200));
    run_text(&mut c, "G21 G90\nG1 X20 F120\nM2\n", "door.ngc");
    wait_status(&mut c, "moving", HANG, |s| {
        s["mode"] == json!("running") && axis(s, "X")["actual"].as_f64().unwrap() < 290.0
    });
    input(&mut c, "door_open", true);
    let s = wait_status(&mut c, "feed hold", HANG, |s| s["mode"] == json!("holding"));
    assert_eq!(s["job"]["state"], json!("holding"), "{s}");
    let s = wait_status(&mut c, "at rest", HANG, |s| at_rest(s, 1e-6));
    let held_at = axis(&s, "X")["actual"].as_f64().unwrap();
    assert!(held_at > 25.0, "stopped on the path before the end: {s}");
    let (_, msg) = err(&mut c, "job.resume", Value::Null);
    assert!(msg.contains("start_inhibit"), "{msg}");
    input(&mut c, "door_open", false);
    std::thread::sleep(Duration::from_millis(200));
    ok(&mut c, "job.resume", Value::Null);
    let s = wait_job_end(&mut c, "job end", HANG);
    assert_eq!(s["job"]["state"], json!("done"), "{s}");
}

/// M8 runs the coolant pump through the PLC; M100 pulses the way-oil pump and completes when
/// the PLC says so.
#[test]
fn coolant_pump_and_m100_lubrication_pulse() {
    let (d, _dir) = start(|t| t);
    let mut c = d.client();
    ready(&mut c);
    // A move first: a dwell before any move dwells at the origin (lookahead last_pose).
    run_text(
        &mut c,
        "G21 G90\nG0 X100\nM8\nM100\nG4 P5\nM9\nM2\n",
        "lube.ngc",
    );
    let s = wait_status(&mut c, "lube pulse", HANG, |s| {
        output(s, "lube_pump") == 1.0
    });
    assert_eq!(output(&s, "coolant_pump"), 1.0, "{s}");
    let s = wait_job_end(&mut c, "job end", HANG);
    assert_eq!(s["job"]["state"], json!("done"), "{s}");
    let s = wait_status(&mut c, "pump off", HANG, |s| {
        output(s, "coolant_pump") == 0.0
    });
    assert_eq!(output(&s, "lube_pump"), 0.0, "the pulse is 2 s: {s}");
}

/// The spindle lamps of the mill's program: ready while the spindle is commanded on and at
/// speed; speed lost while it is commanded on lights the fault lamp, which stays until the
/// spindle is commanded off. The test plays the spindle drive: the simulated plant's own
/// spin-up (`spindle.at_speed_input`) is left out, so the at-speed input is the test's.
#[test]
fn spindle_ready_and_lost_speed_fault_lamps() {
    let (d, _dir) = start(|t| {
        assert_eq!(
            t.matches("at_speed_input = \"spindle_at_speed\"\n").count(),
            1
        );
        t.replace("at_speed_input = \"spindle_at_speed\"\n", "")
    });
    let mut c = d.client();
    ready(&mut c);
    // A move first: a dwell before any move dwells at the origin (lookahead last_pose).
    run_text(
        &mut c,
        "G21 G90\nG0 X100\nM3 S1000\nG4 P40\nM5\nM2\n",
        "spindle.ngc",
    );
    let s = wait_status(&mut c, "spindle on", HANG, |s| {
        output(s, "spindle_on") == 1.0
    });
    assert_eq!(output(&s, "spindle_ready"), 0.0, "not at speed yet: {s}");
    input(&mut c, "spindle_at_speed", true);
    let s = wait_status(&mut c, "ready lamp", HANG, |s| {
        output(s, "spindle_ready") == 1.0
    });
    assert_eq!(output(&s, "spindle_fault"), 0.0, "{s}");
    input(&mut c, "spindle_at_speed", false);
    let s = wait_status(&mut c, "fault lamp", HANG, |s| {
        output(s, "spindle_fault") == 1.0
    });
    assert_eq!(output(&s, "spindle_ready"), 0.0, "{s}");
    assert_eq!(output(&s, "spindle_on"), 1.0, "still commanded on: {s}");
    let s = wait_job_end(&mut c, "job end", HANG);
    assert_eq!(s["job"]["state"], json!("done"), "{s}");
    let s = wait_status(&mut c, "fault lamp off", HANG, |s| {
        output(s, "spindle_fault") == 0.0
    });
    assert_eq!(output(&s, "spindle_on"), 0.0, "M5: {s}");
    assert_eq!(output(&s, "spindle_ready"), 0.0, "{s}");
}

/// The e-stop chain: the button breaks it; `estop.reset` re-arms it with the machine, so the
/// machine comes back on as it always did.
#[test]
fn estop_chain_rearms_with_machine_reset() {
    let (d, _dir) = start(|t| t);
    let mut c = d.client();
    ready(&mut c);
    input(&mut c, "estop", true);
    wait_status(&mut c, "e-stop", HANG, |s| s["mode"] == json!("estop"));
    std::thread::sleep(Duration::from_millis(200));
    input(&mut c, "estop", false);
    ok(&mut c, "estop.reset", Value::Null);
    ok(&mut c, "machine.on", Value::Null);
    wait_status(&mut c, "idle", HANG, |s| s["mode"] == json!("idle"));
    std::thread::sleep(Duration::from_millis(500));
    let s = ok(&mut c, "status", Value::Null);
    assert_eq!(
        s["mode"],
        json!("idle"),
        "the PLC chain did not trip again: {s}"
    );
}

/// A runtime fault of a safety-relevant PLC: outputs safe, the machine stops, the fault names
/// the file and line.
#[test]
fn plc_runtime_fault_stops_the_machine() {
    let program = root().join("tests/plc/fault.st").display().to_string();
    let (d, _dir) = start(move |t| {
        let start = t.find("\n[plc]\n").unwrap() + 1;
        format!(
            "{}[plc]\nprogram = {program:?}\nsafety_relevant = true\n\
             [plc.inputs]\ntrigger = \"door_open\"\n[plc.outputs]\nlamp = \"spindle_ready\"\n",
            &t[..start]
        )
    });
    let mut c = d.client();
    ready(&mut c);
    let s = wait_status(&mut c, "lamp on", HANG, |s| {
        output(s, "spindle_ready") == 1.0
    });
    assert_eq!(s["plc"]["fault"], json!(false));
    run_text(&mut c, "G21 G90\nG1 X20 F120\nM2\n", "fault.ngc");
    wait_status(&mut c, "moving", HANG, |s| s["mode"] == json!("running"));
    input(&mut c, "door_open", true);
    let s = wait_status(&mut c, "fault", HANG, |s| s["mode"] == json!("fault"));
    assert_eq!(s["plc"]["fault"], json!(true), "{s}");
    let s = wait_job_end(&mut c, "job end", HANG);
    assert_eq!(s["job"]["state"], json!("failed"), "{s}");
    let faults = s["faults"].to_string();
    assert!(
        faults.contains("fault.st:18") && faults.contains("PLC"),
        "{faults}"
    );
    assert_eq!(
        output(&s, "spindle_ready"),
        0.0,
        "outputs at their safe values: {s}"
    );
}

fn builtin_with(edit: impl Fn(&mut MachineConfig)) -> Result<(), String> {
    let mut cfg = config::builtin_sim().unwrap();
    edit(&mut cfg);
    let map = hytask::machine::devices::IoMap::new(&cfg).unwrap();
    hytask::plc::deploy::prepare(&cfg, &map, 0.001).map(|_| ())
}

/// The built-in mill's bindings resolve; bad ones are refused naming the key and variable.
#[test]
fn bad_bindings_are_refused_naming_key_and_variable() {
    builtin_with(|_| {}).unwrap();
    // (table, variable, signal, what the error must say)
    let cases: [(&str, &str, &str, &[&str]); 5] = [
        (
            "inputs",
            "tool_number",
            "door_open",
            &["plc.inputs.tool_number", "Mill.tool_number", "BOOL"],
        ),
        (
            "inputs",
            "door_open",
            "door_opne",
            &["plc.inputs.door_open: unknown signal \"door_opne\""],
        ),
        (
            "outputs",
            "coolant_pump",
            "coolant_flood",
            &["plc.outputs.coolant_pump", "two owners"],
        ),
        (
            "outputs",
            "no_such",
            "lube_pump",
            &["plc.outputs.no_such", "no variable"],
        ),
        (
            "outputs",
            "door_open",
            "lube_pump",
            &["plc.outputs.door_open", "VAR_OUTPUT"],
        ),
    ];
    for (table, var, signal, wanted) in cases {
        let e = builtin_with(|c| {
            let plc = c.plc.as_mut().unwrap();
            let map = if table == "inputs" {
                &mut plc.inputs
            } else {
                &mut plc.outputs
            };
            map.insert(var.into(), signal.into());
        })
        .unwrap_err();
        assert!(wanted.iter().all(|w| e.contains(w)), "{table}.{var}: {e}");
    }
}

/// `[plc] m66_digital`: M66 P0 waits on the PLC's `coolant_pump`: L4 (low) passes at once,
/// L3 (high) waits until the operator forces it on (the timeouts are far beyond the hang
/// guard, so only the PLC variable can end these waits), and a wait that times out lets
/// the program go on, as LinuxCNC's M66 does, with #5399 = 1 after the PLC's answer and -1
/// after the timeout (the end positions show it).
#[test]
fn m66_waits_on_a_plc_variable() {
    let (d, _dir) = start(|t| {
        t.replace(
            "[plc.inputs]\n",
            "m66_digital = [\"coolant_pump\"]\n\n[plc.inputs]\n",
        )
    });
    let mut c = d.client();
    ready(&mut c);
    run_text(
        &mut c,
        "G21 G90\nM66 P0 L4 Q100000\nG0 X20\nM66 P0 L3 Q100000\nG0 X[39 + #5399]\nM2\n",
        "m66.ngc",
    );
    let s = wait_status(&mut c, "waiting at the M66 L3", HANG, |s| {
        s["job"]["line"] == json!(4)
    });
    assert!(
        (axis(&s, "X")["actual"].as_f64().unwrap() - 20.0).abs() < 0.01,
        "{s}"
    );
    let s = ok(&mut c, "status", Value::Null);
    assert_eq!(s["job"]["state"], json!("running"), "still waiting: {s}");
    let v = ok(
        &mut c,
        "plc.force",
        json!({"name": "coolant_pump", "value": true}),
    );
    assert_eq!(v["forced"], json!(true), "{v}");
    let s = wait_status(&mut c, "forced in status", HANG, |s| {
        s["plc"]["forced"] == json!(1)
    });
    assert_eq!(s["plc"]["forced"], json!(1));
    let s = wait_job_end(&mut c, "job end", HANG);
    assert_eq!(s["job"]["state"], json!("done"), "{s}");
    assert!(
        (axis(&s, "X")["actual"].as_f64().unwrap() - 40.0).abs() < 0.01,
        "{s}"
    );
    ok(&mut c, "plc.unforce", json!({}));

    // Nothing turns the pump on: the wait times out after 0.3 s and the job goes on.
    run_text(
        &mut c,
        "G21 G90\nM66 P0 L3 Q0.3\nG0 X[11 + #5399]\nM2\n",
        "m66-timeout.ngc",
    );
    let s = wait_job_end(&mut c, "job end", HANG);
    assert_eq!(s["job"]["state"], json!("done"), "{s}");
    assert!(
        (axis(&s, "X")["actual"].as_f64().unwrap() - 10.0).abs() < 0.01,
        "{s}"
    );
}

/// A new version of the mill's program loaded while a job runs takes over at a scan
/// boundary: the job finishes, the PLC keeps scanning without a fault, and the status
/// counts the load. A version that does not compile is refused with file:line:col.
#[test]
fn plc_load_while_a_job_runs() {
    let (d, dir) = start(|t| t);
    let mut c = d.client();
    ready(&mut c);
    let good = std::fs::read_to_string(root().join("config/plc/mill.st")).unwrap();
    // `hytask plc ARGS --socket S`: its standard output, once it succeeded.
    let cli = |d: &Daemon, args: &[&str]| -> String {
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_hytask"))
            .arg("plc")
            .args(args)
            .arg("--socket")
            .arg(&d.socket)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "hytask plc {args:?}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        String::from_utf8(out.stdout).unwrap()
    };
    run_text(&mut c, "G21 G90\nG1 X150 F300\nG1 X0\nM2\n", "long.ngc");
    wait_status(&mut c, "job running", HANG, |s| {
        s["job"]["state"] == json!("running")
    });
    let before = ok(&mut c, "status", Value::Null)["plc"]["scans"]
        .as_u64()
        .unwrap();
    let (code, msg) = err(
        &mut c,
        "plc.load",
        json!({"file": "bad.st", "source": good.replace("started := TRUE;", "started := 1.5;")}),
    );
    assert_ne!(code, 0);
    assert!(
        msg.contains("bad.st:") && msg.contains("unchanged"),
        "{msg}"
    );
    let changed = good.replace(
        "    lube_now : BOOL;",
        "    lube_now : BOOL;\n    loads : DINT := 1;",
    );
    // The operator's way: `hytask plc load FILE`, then `plc get`, `force`, `vars`.
    let file = dir.path().join("mill-v2.st");
    std::fs::write(&file, changed).unwrap();
    let out = cli(&d, &["load", &file.display().to_string()]);
    assert!(out.contains("loaded version 2"), "{out}");
    assert!(out.contains("1 reset: Mill.loads"), "{out}");
    assert!(out.contains("0 removed"), "{out}");
    let s = ok(&mut c, "status", Value::Null);
    assert_eq!(
        s["job"]["state"],
        json!("running"),
        "loaded while the job runs: {s}"
    );
    assert_eq!(cli(&d, &["get", "loads"]).trim(), "Mill.loads : DINT = 1");
    let out = cli(&d, &["force", "loads", "5"]);
    assert_eq!(out.trim(), "Mill.loads : DINT = 5 FORCED");
    let out = cli(&d, &["vars", "loads"]);
    assert_eq!(out.trim(), "Mill.loads : DINT = 5 FORCED");
    cli(&d, &["unforce"]);
    let v = ok(&mut c, "plc.get", json!({"name": "loads"}));
    assert_eq!(v["forced"], json!(false), "{v}");
    let s = wait_job_end(&mut c, "job end", HANG);
    assert_eq!(s["job"]["state"], json!("done"), "{s}");
    let plc = &s["plc"];
    assert_eq!(plc["reloads"], json!(1), "{s}");
    assert_eq!(plc["fault"], json!(false), "{s}");
    assert!(plc["scans"].as_u64().unwrap() > before, "{s}");
}
