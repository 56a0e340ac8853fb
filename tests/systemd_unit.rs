//! The shipped unit file: `systemd-analyze verify` accepts it, and it keeps the settings
//! realtime depends on.

use std::process::Command;

const UNIT: &str = include_str!("../systemd/hytask.service");

fn directive(name: &str) -> Vec<String> {
    UNIT.lines()
        .filter_map(|l| l.strip_prefix(&format!("{name}=")))
        .map(str::to_string)
        .collect()
}

#[test]
fn unit_keeps_realtime_and_notify_settings() {
    assert_eq!(directive("Type"), ["notify"]);
    assert_eq!(directive("LimitMEMLOCK"), ["infinity"]);
    assert_eq!(directive("LimitRTPRIO"), ["99"]);
    assert_eq!(directive("Restart"), ["on-failure"]);
    assert!(!directive("WatchdogSec").is_empty());
    assert_eq!(directive("RuntimeDirectory"), ["hytask"]);
    // RestrictRealtime=yes would forbid SCHED_FIFO.
    assert!(directive("RestrictRealtime").iter().all(|v| v == "no"));
    let caps = directive("CapabilityBoundingSet").join(" ");
    for cap in [
        "CAP_SYS_NICE",
        "CAP_IPC_LOCK",
        "CAP_NET_RAW",
        "CAP_NET_ADMIN",
    ] {
        assert!(caps.contains(cap), "missing {cap}");
    }
    assert_eq!(
        caps.split_whitespace().count(),
        4,
        "no more capabilities than needed"
    );
}

#[test]
fn systemd_analyze_verify_accepts_the_unit() {
    let which = Command::new("systemd-analyze").arg("--version").output();
    if which.is_err() {
        assert!(
            std::env::var("CI").is_err(),
            "systemd-analyze is required in CI (apt-get install systemd)"
        );
        eprintln!("NOTICE: systemd-analyze not installed; unit verification not run");
        return;
    }
    let dir = tempfile::tempdir().expect("tempdir");
    let unit = UNIT.replace("/usr/bin/hytask", env!("CARGO_BIN_EXE_hytask"));
    let path = dir.path().join("hytask.service");
    std::fs::write(&path, unit).expect("write unit");
    let out = Command::new("systemd-analyze")
        .arg("verify")
        .arg(&path)
        .output()
        .expect("run systemd-analyze");
    let stderr = String::from_utf8_lossy(&out.stderr);
    let relevant: Vec<&str> = stderr
        .lines()
        .filter(|l| l.contains("hytask.service"))
        .collect();
    assert!(out.status.success(), "verify failed: {stderr}");
    assert!(relevant.is_empty(), "verify warnings: {relevant:?}");
}
