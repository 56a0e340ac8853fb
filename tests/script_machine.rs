//! Scripts on the mill daemon (`hytask serve`): the script host task `scripts` and its peer
//! `cnc` (the operator operations and the machine's events), through the control socket.
//! Every wait has a generous hang guard; nothing depends on how fast the host runs.
#![allow(clippy::unwrap_used)]

mod support;

use serde_json::{json, Value};
use std::path::Path;
use std::time::{Duration, Instant};
use support::{err, fixture, ok, Daemon};

const GUARD: Duration = Duration::from_secs(180);

/// The program an operator would load: home, run a job three times, an MDI move, wait for
/// the job's end event, switch the flood coolant output on.
fn program(job: &Path) -> String {
    format!(
        "VAR_GLOBAL runs : INT := 0; END_VAR\n\
         PROGRAM cell\n\
         \x20 DO cnc.estop_reset();\n\
         \x20 DO cnc.on();\n\
         \x20 DO cnc.home();\n\
         \x20 WHILE runs < 3 DO\n\
         \x20   DO cnc.run('{}');\n\
         \x20   runs := runs + 1;\n\
         \x20 END_WHILE;\n\
         \x20 DO cnc.mdi('G0 X50 Y50');\n\
         \x20 WAIT cnc.job_done TIMEOUT T#60s;\n\
         \x20 DO cnc.output('coolant_mist', TRUE);\n\
         END_PROGRAM\n",
        job.display()
    )
}

/// Polls `script.list` until `pred` holds for item `name`; returns the item.
fn wait_item(
    c: &mut hytask::control::client::Client,
    name: &str,
    what: &str,
    pred: impl Fn(&Value) -> bool,
) -> Value {
    let t0 = Instant::now();
    loop {
        let list = ok(c, "script.list", Value::Null);
        if let Some(item) = list.as_array().unwrap().iter().find(|i| i["name"] == name) {
            if pred(item) {
                return item.clone();
            }
        }
        assert!(t0.elapsed() < GUARD, "timed out waiting for {what}: {list}");
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// The scripts of task `scripts` in `tasks`.
fn task_scripts(c: &mut hytask::control::client::Client) -> Value {
    let tasks = ok(c, "tasks", Value::Null);
    let t = tasks
        .as_array()
        .unwrap()
        .iter()
        .find(|t| t["name"] == "scripts")
        .unwrap_or_else(|| panic!("no task 'scripts' in {tasks}"))
        .clone();
    t["scripts"].clone()
}

#[test]
fn a_program_homes_runs_a_job_three_times_and_sets_an_output() {
    let d = Daemon::start_sim();
    let mut c = d.client();
    let job = fixture("jobs/square.ngc");
    let r = ok(
        &mut c,
        "script.load",
        json!({"task": "scripts", "file": "cell.st", "source": program(&job)}),
    );
    assert_eq!(
        r,
        json!({"slot": 0, "items": [{"name": "cell", "kind": "program"}]})
    );
    ok(
        &mut c,
        "script.start",
        json!({"file": "cell.st", "name": "cell"}),
    );
    // While it runs, its state and current line show in script.list and in `tasks`.
    let item = wait_item(&mut c, "cell", "the program inside its loop", |i| {
        i["status"] == "running" && i["line"].as_u64().unwrap() >= 6
    });
    assert_eq!(item["task"], "scripts");
    let s = task_scripts(&mut c);
    assert_eq!(s[0]["name"], "cell", "{s}");
    assert!(
        matches!(s[0]["status"].as_str(), Some("running" | "finished")),
        "{s}"
    );
    let item = wait_item(&mut c, "cell", "the program's end", |i| {
        matches!(i["status"].as_str(), Some("error" | "finished"))
    });
    assert_eq!(item["status"], "finished", "{item}");
    assert_eq!(item["error"], Value::Null);
    let st = ok(&mut c, "status", Value::Null);
    assert_eq!(st["job"]["name"], "mdi");
    assert_eq!(st["job"]["state"], "done");
    assert_eq!(st["outputs"]["coolant_mist"], json!(1.0), "{st}");
    let x = st["axes"][0]["commanded"].as_f64().unwrap();
    assert!((x - 50.0).abs() < 0.01, "the MDI move ran last: {st}");
    let all = |s: &Value| {
        s["axes"]
            .as_array()
            .unwrap()
            .iter()
            .all(|a| a["homed"] == true)
    };
    assert!(all(&st), "homed by the program: {st}");
}

#[test]
fn an_estop_stops_a_running_script_in_error_at_its_line() {
    let d = Daemon::start_sim();
    let mut c = d.client();
    let src =
        "PROGRAM hold\n  DO cnc.estop_reset();\n  DO cnc.on();\n  WAIT cnc.homed;\nEND_PROGRAM\n";
    ok(
        &mut c,
        "script.load",
        json!({"file": "hold.st", "source": src}),
    );
    ok(
        &mut c,
        "script.start",
        json!({"file": "hold.st", "name": "hold"}),
    );
    wait_item(&mut c, "hold", "the program waiting for homed", |i| {
        i["status"] == "running" && i["line"] == 4
    });
    ok(&mut c, "estop", Value::Null);
    let item = wait_item(&mut c, "hold", "the e-stop to stop it", |i| {
        matches!(i["status"].as_str(), Some("error" | "finished" | "stopped"))
    });
    assert_eq!(item["status"], "error");
    assert_eq!(
        item["error"], "hold.st:4:3: stopped by the e-stop",
        "{item}"
    );
    // Releasing the e-stop does not bring it back.
    ok(&mut c, "estop.reset", Value::Null);
    std::thread::sleep(Duration::from_millis(200));
    let list = ok(&mut c, "script.list", Value::Null);
    assert_eq!(list[0]["status"], "error", "{list}");
}

#[test]
fn on_the_shipped_sim_errors_name_file_line_col_and_a_failed_command_is_caught() {
    let d = Daemon::start(Path::new("config/sim.toml"));
    let mut c = d.client();
    // A compile error and a bind error, each with its place.
    let (_, msg) = err(
        &mut c,
        "script.load",
        json!({"file": "bad.st", "source": "PROGRAM p\n  x := ;\nEND_PROGRAM\n"}),
    );
    assert!(msg.starts_with("bad.st:2:"), "{msg}");
    let (_, msg) = err(
        &mut c,
        "script.load",
        json!({"file": "bad.st", "source": "PROGRAM p\n  DO cnc.mdi(5);\n  WAIT cnc.nothing;\nEND_PROGRAM\n"}),
    );
    assert_eq!(
        msg,
        "bad.st:2:3: argument 1 ('line') of 'cnc.mdi' must be a string literal\n\
         bad.st:3:3: unknown event 'cnc.nothing'"
    );
    // The machine starts in e-stop: `cnc.on` is rejected, TRY catches it.
    let src = "VAR_GLOBAL caught : BOOL; END_VAR\nPROGRAM p\n  TRY\n    DO cnc.on();\n  CATCH\n    caught := TRUE;\n  END_TRY;\n  DO cnc.run('/nonexistent.ngc');\nEND_PROGRAM\n";
    ok(
        &mut c,
        "script.load",
        json!({"file": "p.st", "source": src}),
    );
    ok(&mut c, "script.start", json!({"file": "p.st", "name": "p"}));
    let item = wait_item(&mut c, "p", "the failed run", |i| {
        matches!(i["status"].as_str(), Some("error" | "finished"))
    });
    assert_eq!(
        item["error"], "p.st:8:3: command failed: invalid parameter (see the daemon's log)",
        "the unreadable file: {item}"
    );
    let s = task_scripts(&mut c);
    assert_eq!(s[0]["status"], "error", "{s}");
    // Operations of the peer are listed with the task.
    let tasks = ok(&mut c, "tasks", Value::Null);
    let cnc = tasks
        .as_array()
        .unwrap()
        .iter()
        .find(|t| t["name"] == "cnc")
        .unwrap();
    let ops: Vec<&str> = cnc["operations"]
        .as_array()
        .unwrap()
        .iter()
        .map(|o| o["name"].as_str().unwrap())
        .collect();
    assert_eq!(
        ops,
        ["estop_reset", "on", "off", "home", "mdi", "run", "output"]
    );
    assert_ne!(cnc["thread"], tasks[0]["thread"], "not on the servo thread");
}

#[test]
fn loading_and_starting_scripts_needs_the_operator_role() {
    use hytask::control::access::{permits, Role};
    for m in [
        "script.load",
        "script.start",
        "script.step",
        "script.unload",
    ] {
        assert!(!permits(Role::Observer, m), "{m}");
        assert!(permits(Role::Operator, m), "{m}");
    }
}
