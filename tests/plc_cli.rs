//! `hytask plc check|run` as a machine builder uses them at a desk: every compile error on
//! stderr with file:line:col, the interface on stdout, offline runs printing what changed
//! per scan (or JSON), runtime faults with file and line and a distinct exit status.
#![allow(clippy::unwrap_used)]

mod support;

use support::hytask;

fn write(dir: &tempfile::TempDir, name: &str, text: &str) -> String {
    let p = dir.path().join(name);
    std::fs::write(&p, text).unwrap();
    p.display().to_string()
}

fn example(name: &str) -> String {
    format!("{}/config/plc/{name}", env!("CARGO_MANIFEST_DIR"))
}

#[test]
fn check_prints_the_interface() {
    let out = hytask(&["plc", "check", &example("estop_latch.st")]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(text.contains("PROGRAM EStopLatch"), "{text}");
    assert!(text.contains("  VAR_INPUT reset_button : BOOL"), "{text}");
    assert!(
        text.contains("  VAR_OUTPUT machine_enable : BOOL"),
        "{text}"
    );
    assert!(text.contains("  VAR latch : RS"), "{text}");
}

#[test]
fn check_reports_every_error_with_position() {
    let dir = tempfile::tempdir().unwrap();
    let f = write(
        &dir,
        "bad.st",
        "PROGRAM P\nVAR\n  a : INT;\n  b : BOOL;\nEND_VAR\n\
         a := TRUE;\n\
         c := 1;\n\
         IF a THEN b := 1 END_IF;\n\
         a := 100000;\n\
         END_PROGRAM\n",
    );
    let out = hytask(&["plc", "check", &f]);
    assert!(!out.status.success());
    let err = String::from_utf8(out.stderr).unwrap();
    for want in [
        format!("{f}:6:6: type mismatch: expected INT, found BOOL"),
        format!("{f}:7:1: unknown variable c"),
        format!("{f}:8:4: type mismatch: expected BOOL, found INT"),
        format!("{f}:8:18: expected ';', found END_IF"),
        format!("{f}:9:6: 100000 is out of the range of INT"),
    ] {
        assert!(err.contains(&want), "missing {want:?} in:\n{err}");
    }
    assert!(err.contains("5 error(s)"), "{err}");
}

#[test]
fn run_prints_changes_per_scan() {
    let out = hytask(&[
        "plc",
        "run",
        &example("estop_latch.st"),
        "--period",
        "10ms",
        "--scans",
        "70",
        "--set",
        "estop_panel=FALSE@5",
        "--set",
        "estop_panel=TRUE@20",
        "--set",
        "reset_button=TRUE@60",
        "--set",
        "EStopLatch.reset_button=FALSE@62",
        "--watch",
        "machine_enable",
        "--watch",
        "lamp",
        "--watch",
        "estop_panel",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8(out.stdout).unwrap();
    // The blink TON (500 ms) first elapses at scan 51 (t = 500 ms): lamp on while ready.
    assert_eq!(
        text,
        "scan 5: EStopLatch.estop_panel=FALSE\n\
         scan 20: EStopLatch.estop_panel=TRUE\n\
         scan 51: EStopLatch.lamp=TRUE\n\
         scan 60: EStopLatch.machine_enable=TRUE\n"
    );
}

#[test]
fn run_json_and_fault_with_line() {
    let dir = tempfile::tempdir().unwrap();
    let f = write(
        &dir,
        "div.st",
        "PROGRAM P\nVAR\n  d : INT := 2;\n  q : INT;\nEND_VAR\n\
         d := d - 1;\n\
         q := 10 / d;\n\
         END_PROGRAM\n",
    );
    let out = hytask(&["plc", "run", &f, "--scans", "5", "--json"]);
    assert_eq!(out.status.code(), Some(3), "a fault exits with 3");
    let doc: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(doc["scans"][0]["changed"]["P.d"], 1);
    assert_eq!(doc["scans"][0]["changed"]["P.q"], 10);
    assert_eq!(doc["fault"]["scan"], 2);
    assert_eq!(doc["fault"]["kind"], "division by zero");
    assert_eq!(doc["fault"]["line"], 7);
    let err = String::from_utf8(out.stderr).unwrap();
    assert!(err.contains(&format!("{f}:7:")), "{err}");
}

#[test]
fn run_refuses_bad_sets() {
    let f = example("estop_latch.st");
    for (set, want) in [
        ("nope=TRUE", "no variable \"nope\""),
        ("lamp=7", "is not a value of type BOOL"),
        ("lamp", "expected VAR=VALUE@SCAN"),
    ] {
        let out = hytask(&["plc", "run", &f, "--scans", "1", "--set", set]);
        assert!(!out.status.success());
        let err = String::from_utf8(out.stderr).unwrap();
        assert!(err.contains(want), "{set}: {err}");
    }
}
