//! The shipped unit file: `systemd-analyze verify` accepts it, it keeps the settings realtime
//! depends on, `systemd-analyze security` scores its exposure at 2.5 or below, and the daemon
//! makes no system call that its `SystemCallFilter=` would refuse (checked by running the
//! real daemon, a job included, under strace).
#![allow(clippy::unwrap_used)]

mod support;

use serde_json::{json, Value};
use std::collections::BTreeSet;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

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
    for cap in ["CAP_SYS_NICE", "CAP_IPC_LOCK"] {
        assert!(caps.contains(cap), "missing {cap}");
    }
    assert_eq!(
        caps.split_whitespace().count(),
        2,
        "no more capabilities than needed"
    );
    // SCHED_FIFO and mlockall must not be filtered out.
    let filter = directive("SystemCallFilter");
    assert_eq!(filter.first().map(String::as_str), Some("@system-service"));
    assert!(filter
        .iter()
        .skip(1)
        .all(|f| !f.contains("@resources") && !f.contains("@memlock") && !f.contains("sched_")));
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

/// Whether a reference tool is installed; in CI a missing one is a failure, elsewhere a loud
/// notice.
fn have(tool: &str, package: &str) -> bool {
    if Command::new(tool)
        .arg("--version")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok()
    {
        return true;
    }
    assert!(
        std::env::var("CI").is_err(),
        "{tool} is required in CI (apt-get install {package})"
    );
    eprintln!("NOTICE: {tool} not installed; this check did not run");
    false
}

/// The unit with the test build of the binary in ExecStart, written to a temporary dir.
fn unit_file(dir: &std::path::Path) -> std::path::PathBuf {
    let unit = UNIT.replace("/usr/bin/hytask", env!("CARGO_BIN_EXE_hytask"));
    let path = dir.join("hytask.service");
    std::fs::write(&path, unit).expect("write unit");
    path
}

#[test]
fn systemd_analyze_security_scores_the_unit_at_most_2_5() {
    if !have("systemd-analyze", "systemd") {
        return;
    }
    let dir = tempfile::tempdir().expect("tempdir");
    let path = unit_file(dir.path());
    let out = Command::new("systemd-analyze")
        .args(["security", "--offline=yes", "--no-pager"])
        .arg(&path)
        .output()
        .expect("run systemd-analyze security");
    let text =
        String::from_utf8_lossy(&out.stdout).into_owned() + &String::from_utf8_lossy(&out.stderr);
    let score: f64 = text
        .lines()
        .find_map(|l| {
            let rest = l.split("Overall exposure level for").nth(1)?;
            rest.split(':')
                .nth(1)?
                .split_whitespace()
                .next()?
                .parse()
                .ok()
        })
        .unwrap_or_else(|| panic!("no exposure level in: {text}"));
    assert!(score <= 2.5, "exposure {score} > 2.5:\n{text}");
}

/// The system calls a `systemd-analyze syscall-filter` group stands for, nested groups
/// expanded.
fn expand(item: &str, seen: &mut BTreeSet<String>) -> BTreeSet<String> {
    if !item.starts_with('@') {
        return BTreeSet::from([item.to_string()]);
    }
    if !seen.insert(item.to_string()) {
        return BTreeSet::new();
    }
    let out = Command::new("systemd-analyze")
        .args(["syscall-filter", "--no-pager", item])
        .output()
        .expect("run systemd-analyze syscall-filter");
    assert!(out.status.success(), "unknown syscall group {item}");
    let mut calls = BTreeSet::new();
    for line in String::from_utf8_lossy(&out.stdout).lines().skip(1) {
        let name = line.trim();
        if name.is_empty() || name.starts_with('#') {
            continue;
        }
        calls.extend(expand(name, seen));
    }
    calls
}

/// The set the unit's `SystemCallFilter=` lines allow: the first line is an allow list (it
/// sets the default action to deny), later `~` lines remove from it and plain lines add.
fn allowed_syscalls() -> BTreeSet<String> {
    let mut allowed = BTreeSet::new();
    for (i, line) in directive("SystemCallFilter").iter().enumerate() {
        let (remove, items) = match line.strip_prefix('~') {
            Some(rest) => (true, rest),
            None => (false, line.as_str()),
        };
        assert!(
            i > 0 || !remove,
            "the first SystemCallFilter= must be an allow list"
        );
        for item in items.split_whitespace() {
            let calls = expand(item, &mut BTreeSet::new());
            if remove {
                allowed.retain(|c| !calls.contains(c));
            } else {
                allowed.extend(calls);
            }
        }
    }
    allowed
}

/// System call names from `strace -c` summary tables.
fn syscalls_in_summary(summary: &str) -> BTreeSet<String> {
    summary
        .lines()
        .filter(|l| {
            l.trim_start()
                .chars()
                .next()
                .is_some_and(|c| c.is_ascii_digit())
        })
        .filter_map(|l| l.split_whitespace().last())
        .filter(|name| *name != "total")
        .map(str::to_string)
        .collect()
}

#[test]
fn the_daemon_makes_no_system_call_the_unit_filters_out() {
    if !have("systemd-analyze", "systemd") || !have("strace", "strace") {
        return;
    }
    let allowed = allowed_syscalls();
    assert!(allowed.contains("sched_setscheduler") && allowed.contains("mlockall"));
    let dir = tempfile::tempdir().expect("tempdir");
    let socket = dir.path().join("control.sock");
    let summary = dir.path().join("strace.txt");
    let mut strace = Command::new("strace")
        .args(["-f", "-qq", "-c", "-o"])
        .arg(&summary)
        .arg(env!("CARGO_BIN_EXE_hytask"))
        .args(["serve", "--config"])
        .arg(support::fast_sim())
        .arg("--socket")
        .arg(&socket)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("start strace");
    let t0 = Instant::now();
    let mut c = loop {
        if let Ok(c) = hytask::control::client::Client::connect(&socket) {
            break c;
        }
        assert!(
            t0.elapsed() < Duration::from_secs(60),
            "daemon did not open its socket"
        );
        std::thread::sleep(Duration::from_millis(50));
    };
    // The daemon's pid, from the socket's peer credentials (strace is its parent).
    let peer = std::os::unix::net::UnixStream::connect(&socket).expect("connect");
    let pid = nix::sys::socket::getsockopt(&peer, nix::sys::socket::sockopt::PeerCredentials)
        .expect("peer credentials")
        .pid();
    drop(peer);
    // A whole life: homing, a job with spindle, coolant and messages, status, subscribe.
    support::ready(&mut c);
    support::ok(&mut c, "subscribe", json!({"topics": ["job"]}));
    support::run_job(&mut c, "jobs/square.ngc");
    support::wait_status(&mut c, "job done", Duration::from_secs(180), |s| {
        s["job"]["state"] == json!("done")
    });
    support::ok(&mut c, "tasks", Value::Null);
    drop(c);
    nix::sys::signal::kill(
        nix::unistd::Pid::from_raw(pid),
        nix::sys::signal::Signal::SIGTERM,
    )
    .expect("SIGTERM");
    let t0 = Instant::now();
    let status = loop {
        if let Some(s) = strace.try_wait().expect("wait") {
            break s;
        }
        if t0.elapsed() > Duration::from_secs(120) {
            let _ = strace.kill();
            panic!("daemon did not exit under strace");
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    assert!(status.success(), "daemon under strace exited with {status}");
    let text = std::fs::read_to_string(&summary).expect("strace summary");
    let used = syscalls_in_summary(&text);
    for needed in ["sched_setscheduler", "mlockall", "clock_nanosleep"] {
        assert!(
            used.contains(needed),
            "the daemon did not call {needed}:\n{text}"
        );
    }
    let refused: Vec<&String> = used.iter().filter(|c| !allowed.contains(*c)).collect();
    assert!(
        refused.is_empty(),
        "system calls the unit's SystemCallFilter= refuses: {refused:?}\n{text}"
    );
}
