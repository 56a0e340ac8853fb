//! `hytask check` as a user runs it.
#![allow(clippy::unwrap_used)]

use std::process::{Command, Output};

fn check(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_hytask"))
        .arg("check")
        .args(args)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .unwrap()
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

#[test]
fn a_valid_file_prints_the_resolved_machine_and_exits_zero() {
    let out = check(&["config/sim.toml"]);
    let (stdout, stderr) = (text(&out.stdout), text(&out.stderr));
    assert!(out.status.success(), "{stderr}");
    assert!(stdout.contains("name = \"sim-mill\""), "{stdout}");
    // Defaults filled in: not written in sim.toml.
    assert!(
        stdout.contains("quick_stop_deceleration = 2000.0"),
        "{stdout}"
    );
    assert!(stdout.contains("max_feed_override = 2.0"), "{stdout}");
    assert!(
        stderr.contains("config/sim.toml: OK: machine \"sim-mill\", axes XYZ"),
        "{stderr}"
    );
    // The printed machine is itself a valid configuration.
    hytask::config::parse(&stdout, "stdout").unwrap();
}

#[test]
fn without_a_file_the_builtin_machine_is_checked() {
    let out = check(&["--quiet"]);
    assert!(out.status.success());
    assert!(out.stdout.is_empty(), "--quiet prints no machine");
    assert!(text(&out.stderr).contains("built-in sim: OK"));
}

#[test]
fn the_real_machine_example_checks_with_every_backend_built() {
    // CANopen drives and Modbus I/O are both in this build: no "not available" note.
    let out = check(&["-q", "config/example-canopen.toml"]);
    let stderr = text(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert!(
        stderr.contains("config/example-canopen.toml: OK: machine \"router-1\""),
        "{stderr}"
    );
    assert!(!stderr.contains("not available"), "{stderr}");
}

#[test]
fn an_invalid_file_lists_every_error_and_exits_non_zero() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bad.toml");
    let bad = hytask::config::BUILTIN_SIM_TOML
        .replacen("priority = 80", "priority = 0", 1)
        .replacen("estop_input = \"estop\"", "estop_input = \"nope\"", 1);
    std::fs::write(&path, bad).unwrap();
    let out = check(&[path.to_str().unwrap()]);
    let stderr = text(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(out.stdout.is_empty());
    assert!(stderr.contains("2 error(s):"), "{stderr}");
    assert!(
        stderr.contains("  thread[0] (servo).priority: must be in 1..=99, got 0"),
        "{stderr}"
    );
    assert!(
        stderr.contains("  safety.estop_input: no digital input named \"nope\" in any [[io]]"),
        "{stderr}"
    );
}

#[test]
fn an_unknown_key_fails_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("typo.toml");
    let bad =
        hytask::config::BUILTIN_SIM_TOML.replacen("[motion]\n", "[motion]\nlookahed = 5\n", 1);
    std::fs::write(&path, bad).unwrap();
    let out = check(&[path.to_str().unwrap()]);
    let stderr = text(&out.stderr);
    assert_eq!(out.status.code(), Some(1));
    assert!(
        stderr.contains("motion.lookahed: TOML parse error"),
        "{stderr}"
    );
    assert!(stderr.contains("unknown field `lookahed`"), "{stderr}");
}

#[test]
fn a_missing_file_fails() {
    let out = check(&["/nonexistent/machine.toml"]);
    assert_eq!(out.status.code(), Some(1));
    assert!(text(&out.stderr).contains("cannot read /nonexistent/machine.toml"));
}
