//! A machine whose PLC program does not compile: `hytask check CONFIG` reports every error
//! with file:line:col, and `hytask serve` refuses to start with the same errors (issue 11:
//! compile errors name file, line and column, for every error found).
#![allow(clippy::unwrap_used)]

mod support;

use std::path::Path;
use support::hytask;

/// config/sim.toml with its PLC program replaced by `program` (written beside it as
/// `mill.st`, named relative to the machine file), in `dir`.
fn machine_with_program(dir: &Path, program: &str) -> String {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let text = std::fs::read_to_string(root.join("config/sim.toml")).unwrap();
    let builtin = "program = \"builtin:plc/mill.st\"";
    assert!(text.contains(builtin), "config/sim.toml changed");
    std::fs::write(dir.join("mill.st"), program).unwrap();
    let path = dir.join("mill.toml");
    std::fs::write(&path, text.replace(builtin, "program = \"mill.st\"")).unwrap();
    path.display().to_string()
}

/// The mill's own program with two errors after its declarations: an undeclared variable
/// and a REAL assigned to a BOOL (the rest as shipped, so only these two are wrong).
fn broken_mill() -> String {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let good = std::fs::read_to_string(root.join("config/plc/mill.st")).unwrap();
    let mut lines: Vec<&str> = good.lines().collect();
    let body = lines.iter().rposition(|l| l.trim() == "END_VAR").unwrap() + 1;
    lines.insert(body, "feed_hold := 3.5;");
    lines.insert(body, "nosuch := TRUE;");
    lines.join("\n") + "\n"
}

fn error_lines(stderr: &str) -> Vec<String> {
    stderr
        .lines()
        .filter(|l| l.contains("mill.st:"))
        .map(|l| l.trim().to_string())
        .collect()
}

#[test]
fn check_and_serve_report_every_plc_error_with_position() {
    let dir = tempfile::tempdir().unwrap();
    let program = broken_mill();
    let first: usize = program
        .lines()
        .position(|l| l == "nosuch := TRUE;")
        .unwrap()
        + 1;
    let config = machine_with_program(dir.path(), &program);

    let out = hytask(&["check", "--quiet", &config]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "check accepted it:\n{stderr}");
    let errors = error_lines(&stderr);
    assert_eq!(errors.len(), 2, "{stderr}");
    assert!(
        errors[0].contains(&format!("mill.st:{first}:1:")) && errors[0].contains("nosuch"),
        "{stderr}"
    );
    assert!(
        errors[1].contains(&format!("mill.st:{}:", first + 1)),
        "{stderr}"
    );

    let socket = dir.path().join("control.sock");
    let out = hytask(&[
        "serve",
        "--config",
        &config,
        "--socket",
        &socket.display().to_string(),
    ]);
    let served = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "the daemon started:\n{served}");
    assert_eq!(error_lines(&served), errors, "{served}");
}

#[test]
fn check_accepts_the_mill_program_from_a_file() {
    let dir = tempfile::tempdir().unwrap();
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let good = std::fs::read_to_string(root.join("config/plc/mill.st")).unwrap();
    let config = machine_with_program(dir.path(), &good);
    let out = hytask(&["check", "--quiet", &config]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}
