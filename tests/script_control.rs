//! The `script.*` control methods (as JSON, through [`ScriptHosts`], which the control
//! socket dispatches to) and `hytask script check`.
#![allow(clippy::unwrap_used)]

mod script_support;

use hytask::script::ScriptHosts;
use serde_json::json;

const SRC: &str = "VAR_GLOBAL n : INT; END_VAR\nSTATE_MACHINE m\n  INITIAL STATE a\n    ENTRY n := 1; END_ENTRY\n    TRANSITION WHEN n > 1 TO b;\n  END_STATE\n  FINAL STATE b\n    ENTRY DO arm.grab(); END_ENTRY\n  END_STATE\nEND_STATE_MACHINE\nPROGRAM p\n  n := 2;\n  n := 3;\nEND_PROGRAM\n";

#[test]
fn load_start_step_list_unload_over_json() {
    let mut c = script_support::cell();
    let mut hosts = ScriptHosts::default();
    hosts.add(c.control.clone(), c.bindings.clone());
    let r = hosts
        .handle("load", json!({"file": "m.st", "source": SRC}))
        .unwrap();
    assert_eq!(
        r,
        json!({"slot": 0, "items": [{"name": "m", "kind": "state_machine"}, {"name": "p", "kind": "program"}]})
    );
    hosts
        .handle("start", json!({"file": "m.st", "name": "m"}))
        .unwrap();
    c.rt.run_cycles(2);
    let list = hosts.handle("list", json!(null)).unwrap();
    assert_eq!(list[0]["task"], "cell");
    assert_eq!(list[0]["state"], "a");
    assert_eq!(list[0]["status"], "running");
    assert_eq!(list[1]["status"], "idle");
    // Step the program statement by statement.
    hosts
        .handle("start", json!({"task": "cell", "slot": 0, "name": "p"}))
        .unwrap();
    hosts
        .handle("pause", json!({"slot": 0, "name": "p"}))
        .unwrap();
    c.rt.run_cycles(1);
    assert_eq!(hosts.list()[1]["line"], 12);
    hosts
        .handle("step", json!({"slot": 0, "name": "p"}))
        .unwrap();
    c.rt.run_cycles(1);
    assert_eq!(hosts.list()[1]["line"], 13);
    assert_eq!(hosts.list()[1]["status"], "paused");
    c.rt.run_cycles(3);
    assert_eq!(hosts.list()[0]["state"], "b", "n = 2 fired the transition");
    assert_eq!(hosts.list()[0]["status"], "finished");
    let err = hosts
        .handle("start", json!({"slot": 0, "name": "nope"}))
        .unwrap_err();
    assert_eq!(
        err.to_string(),
        "no PROGRAM or STATE_MACHINE 'nope' in the script"
    );
    let err = hosts
        .handle("start", json!({"task": "robot", "slot": 0, "name": "m"}))
        .unwrap_err();
    assert_eq!(err.to_string(), "no script host task 'robot' (hosts: cell)");
    let err = hosts
        .handle(
            "load",
            json!({"file": "bad.st", "source": "PROGRAM q\n  WAIT x.y;\nEND_PROGRAM\n"}),
        )
        .unwrap_err();
    assert_eq!(err.to_string(), "bad.st:2:3: unknown event 'x.y'");
    hosts.handle("unload", json!({"file": "m.st"})).unwrap();
    c.rt.run_cycles(1);
    assert_eq!(hosts.list(), json!([]));
}

#[test]
fn cli_check_prints_items_or_errors_with_place() {
    let dir = std::env::temp_dir().join(format!("hytask-script-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let good = dir.join("good.st");
    std::fs::write(&good, SRC).unwrap();
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_hytask"))
        .args(["script", "check"])
        .arg(&good)
        .output()
        .unwrap();
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("STATE_MACHINE m\n"), "{text}");
    assert!(text.contains("calls arm.grab"), "{text}");
    let bad = dir.join("bad.st");
    std::fs::write(&bad, "PROGRAM q\n  n := 1;\nEND_PROGRAM\n").unwrap();
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_hytask"))
        .args(["script", "check"])
        .arg(&bad)
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("bad.st:2:3: "), "{err}");
    std::fs::remove_dir_all(&dir).unwrap();
}
