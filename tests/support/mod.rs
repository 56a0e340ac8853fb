//! Shared helpers of the end-to-end tests: start the real `hytask serve` binary on a
//! private socket, talk to it, wait for conditions with deadlines.
#![allow(clippy::unwrap_used, dead_code)]

use hytask::control::client::{Client, ClientError, Event};
use serde_json::{json, Value};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// The fast-homing simulated mill used by the end-to-end tests.
pub fn fast_sim() -> PathBuf {
    fixture("sim-fast.toml")
}

/// A file under tests/fixtures.
pub fn fixture(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures")
        .join(rel)
}

/// A running `hytask serve`, stopped with SIGTERM when dropped.
pub struct Daemon {
    pub child: Option<Child>,
    pub socket: PathBuf,
    _dir: tempfile::TempDir,
}

impl Daemon {
    /// Starts the daemon on `config` and waits for its socket.
    pub fn start(config: &Path) -> Daemon {
        let dir = tempfile::tempdir().unwrap();
        let socket = dir.path().join("control.sock");
        let child = Command::new(env!("CARGO_BIN_EXE_hytask"))
            .args(["serve", "--config"])
            .arg(config)
            .arg("--socket")
            .arg(&socket)
            .env("RUST_LOG", "info")
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let d = Daemon {
            child: Some(child),
            socket,
            _dir: dir,
        };
        let t0 = Instant::now();
        while Client::connect(&d.socket).is_err() {
            assert!(
                t0.elapsed() < Duration::from_secs(20),
                "daemon did not open its socket"
            );
            std::thread::sleep(Duration::from_millis(20));
        }
        d
    }

    /// A new client.
    pub fn client(&self) -> Client {
        Client::connect(&self.socket).unwrap()
    }

    /// Sends SIGTERM and waits; returns the exit status and stderr.
    pub fn terminate(&mut self) -> (std::process::ExitStatus, String) {
        let mut child = self.child.take().unwrap();
        let pid = nix::unistd::Pid::from_raw(child.id() as i32);
        nix::sys::signal::kill(pid, nix::sys::signal::Signal::SIGTERM).unwrap();
        let t0 = Instant::now();
        loop {
            if let Some(status) = child.try_wait().unwrap() {
                let mut err = String::new();
                use std::io::Read;
                child
                    .stderr
                    .take()
                    .unwrap()
                    .read_to_string(&mut err)
                    .unwrap();
                return (status, err);
            }
            if t0.elapsed() > Duration::from_secs(40) {
                let _ = child.kill();
                panic!("daemon did not exit after SIGTERM");
            }
            std::thread::sleep(Duration::from_millis(20));
        }
    }
}

impl Drop for Daemon {
    fn drop(&mut self) {
        if let Some(mut c) = self.child.take() {
            let pid = nix::unistd::Pid::from_raw(c.id() as i32);
            let _ = nix::sys::signal::kill(pid, nix::sys::signal::Signal::SIGTERM);
            let t0 = Instant::now();
            while t0.elapsed() < Duration::from_secs(30) {
                if let Ok(Some(_)) = c.try_wait() {
                    return;
                }
                std::thread::sleep(Duration::from_millis(20));
            }
            let _ = c.kill();
            let _ = c.wait();
        }
    }
}

/// Calls a method that must succeed.
pub fn ok(c: &mut Client, method: &str, params: Value) -> Value {
    match c.call(method, params) {
        Ok(v) => v,
        Err(e) => panic!("{method} failed: {e}"),
    }
}

/// Calls a method that must fail; returns (code, message).
pub fn err(c: &mut Client, method: &str, params: Value) -> (i64, String) {
    match c.call(method, params) {
        Err(ClientError::Remote { code, message }) => (code, message),
        other => panic!("{method}: expected an error, got {other:?}"),
    }
}

/// Polls status until `pred` holds.
pub fn wait_status(
    c: &mut Client,
    what: &str,
    timeout: Duration,
    pred: impl Fn(&Value) -> bool,
) -> Value {
    let t0 = Instant::now();
    loop {
        let s = ok(c, "status", Value::Null);
        if pred(&s) {
            return s;
        }
        assert!(t0.elapsed() < timeout, "timed out waiting for {what}: {s}");
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// Waits for an event matching `pred`, returning every event seen until then.
pub fn wait_event(
    c: &mut Client,
    what: &str,
    timeout: Duration,
    pred: impl Fn(&Event) -> bool,
) -> Vec<Event> {
    let t0 = Instant::now();
    let mut seen = Vec::new();
    while t0.elapsed() < timeout {
        if let Some(e) = c.next_event(Duration::from_millis(100)).unwrap() {
            let done = pred(&e);
            seen.push(e);
            if done {
                return seen;
            }
        }
    }
    let summary: Vec<String> = seen
        .iter()
        .filter(|e| e.topic != "progress")
        .map(|e| format!("{}: {}", e.topic, e.data))
        .collect();
    panic!("timed out waiting for {what}; saw (progress events left out) {summary:#?}");
}

/// E-stop reset, machine on, home all; returns when idle and homed.
pub fn ready(c: &mut Client) {
    let s = ok(c, "status", Value::Null);
    if s["mode"] == json!("estop") {
        ok(c, "estop.reset", Value::Null);
    }
    if s["mode"] != json!("idle") {
        ok(c, "machine.on", Value::Null);
    }
    ok(c, "home", Value::Null);
    wait_status(c, "homed and idle", Duration::from_secs(30), |s| {
        s["mode"] == json!("idle")
            && s["axes"]
                .as_array()
                .unwrap()
                .iter()
                .all(|a| a["homed"] == json!(true))
    });
}

/// Every axis' |velocity| in a status is below `tolerance`.
pub fn at_rest(s: &Value, tolerance: f64) -> bool {
    s["axes"]
        .as_array()
        .unwrap()
        .iter()
        .all(|a| a["velocity"].as_f64().unwrap().abs() < tolerance)
}

/// Axis `name`'s field from a status.
pub fn axis<'a>(s: &'a Value, name: &str) -> &'a Value {
    s["axes"]
        .as_array()
        .unwrap()
        .iter()
        .find(|a| a["name"] == json!(name))
        .unwrap()
}

/// Loads and runs a job file; returns once it is running.
pub fn run_job(c: &mut Client, rel: &str) -> Value {
    let path = fixture(rel);
    let info = ok(c, "job.load", json!({"path": path.display().to_string()}));
    ok(c, "job.run", Value::Null);
    info
}
