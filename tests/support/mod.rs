//! Shared helpers of the end-to-end tests: start the real `hytask serve` binary on a
//! private socket, talk to it, wait for conditions with hang guards.
//!
//! # Simulated clock or real time
//! Tests about behaviour (what the machine does: jobs, holds, steps, trips, probing) start the
//! daemon with [`Daemon::start_sim`]: the fast-homing mill of `tests/fixtures/sim-fast.toml`
//! with `[[thread]] clock = "simulated"`. Its servo thread is an ordinary thread whose time
//! advances exactly one period per cycle, paced at [`SIM_SPEED`] × real time: a loaded host
//! can slow the machine down but never skips a cycle or trips an overrun, so the machine does
//! the same thing cycle by cycle however loaded the host is. The tests act on states they
//! observe (a job line reached, a hold at rest), never after a wall-clock sleep, and every
//! wait is only a hang guard (60 s and more). Cycle-exact assertions (the e-stop quick stop,
//! the probe trip) live on the stepped runtime, in-process (`src/machine/servo/tests.rs`,
//! `tests/machine_no_alloc.rs`).
//!
//! A few real-time smoke tests keep [`Daemon::start`] on the real-time fixture (the servo
//! thread on `SCHED_FIFO` when permitted, overrun accounting on): SIGTERM, `hytask run`, the
//! overrun storm (`tests/daemon_overrun.rs`), and the zero-allocation windows
//! (`tests/daemon_no_alloc.rs`).
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

/// Runs the `hytask` binary with `args` in the package root to its end; returns what it did.
pub fn hytask(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_hytask"))
        .args(args)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .unwrap()
}

/// [`hytask`] that must succeed (the failure shows its stdout and stderr).
pub fn hytask_ok(args: &[&str]) -> std::process::Output {
    let out = hytask(args);
    assert!(
        out.status.success(),
        "hytask {args:?}: {}\n{}{}",
        out.status,
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// A running `hytask serve`, stopped with SIGTERM when dropped.
pub struct Daemon {
    pub child: Option<Child>,
    pub socket: PathBuf,
    /// The daemon's stderr, read as it comes: a pipe nobody reads fills up (64 KiB) and then
    /// blocks whichever daemon thread logs next. `log` holds what was read so far.
    stderr: Option<std::thread::JoinHandle<()>>,
    log: std::sync::Arc<std::sync::Mutex<String>>,
    _dir: tempfile::TempDir,
}

/// Reads `child`'s piped stderr to its end on a thread of its own, line by line into `log`
/// (so a bench or a hang guard can show the log while the daemon still runs).
fn collect_stderr(
    child: &mut Child,
    log: std::sync::Arc<std::sync::Mutex<String>>,
) -> std::thread::JoinHandle<()> {
    let pipe = child.stderr.take().unwrap();
    std::thread::spawn(move || {
        use std::io::BufRead;
        for line in std::io::BufReader::new(pipe).lines().map_while(Result::ok) {
            let mut l = log.lock().unwrap();
            l.push_str(&line);
            l.push('\n');
        }
    })
}

/// Simulated seconds per wall-clock second of the behaviour tests' machine: fast enough to
/// shorten the tests, slow enough that a state a test waits for (a 10 s feed move of the long
/// job) lasts seconds of wall time, so a test's request lands in it even on a loaded host.
pub const SIM_SPEED: u32 = 4;

/// Writes the fast-homing mill on a simulated clock (`sim_speed` = `speed`, 0: unpaced) into
/// `dir`; with `plate_top`, a touch plate under Z drives the `probe` input inside the servo
/// cycle (as in config/sim.toml), so probing does not depend on a watcher's timing.
pub fn sim_clock_config(dir: &Path, speed: u32, plate_top: Option<f64>) -> PathBuf {
    let base = std::fs::read_to_string(fast_sim()).unwrap();
    let thread = "[[thread]]\n";
    assert_eq!(base.matches(thread).count(), 2, "sim-fast.toml changed");
    let mut text = base.replace(
        thread,
        &format!("{thread}clock = \"simulated\"\nsim_speed = {speed}\n"),
    );
    if let Some(top) = plate_top {
        let panel = "name = \"panel\"\n";
        assert!(text.contains(panel), "sim-fast.toml changed");
        text = text.replace(
            panel,
            &format!("{panel}touch_plate = {{ input = \"probe\", axis = \"Z\", top = {top:?} }}\n"),
        );
    }
    let path = dir.join("sim-clock.toml");
    std::fs::write(&path, text).unwrap();
    path
}

impl Daemon {
    /// Starts the daemon on `config` (real time) and waits for its socket.
    pub fn start(config: &Path) -> Daemon {
        Self::start_in(tempfile::tempdir().unwrap(), config)
    }

    /// Starts the daemon on the fast-homing mill on a simulated clock at [`SIM_SPEED`] (see
    /// the module documentation).
    pub fn start_sim() -> Daemon {
        Self::start_sim_with(SIM_SPEED, None)
    }

    /// [`start_sim`](Self::start_sim) at `speed` (0: unpaced), with an optional touch plate
    /// under Z at `plate_top`.
    pub fn start_sim_with(speed: u32, plate_top: Option<f64>) -> Daemon {
        let dir = tempfile::tempdir().unwrap();
        let config = sim_clock_config(dir.path(), speed, plate_top);
        Self::start_in(dir, &config)
    }

    fn start_in(dir: tempfile::TempDir, config: &Path) -> Daemon {
        let socket = dir.path().join("control.sock");
        let mut child = Command::new(env!("CARGO_BIN_EXE_hytask"))
            .args(["serve", "--config"])
            .arg(config)
            .arg("--socket")
            .arg(&socket)
            .env("RUST_LOG", "info")
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let log = std::sync::Arc::default();
        let stderr = Some(collect_stderr(&mut child, std::sync::Arc::clone(&log)));
        let mut d = Daemon {
            child: Some(child),
            socket,
            stderr,
            log,
            _dir: dir,
        };
        let t0 = Instant::now();
        while Client::connect(&d.socket).is_err() {
            if let Some(status) = d.child.as_mut().unwrap().try_wait().unwrap() {
                d.stderr.take().unwrap().join().unwrap();
                let err = d.log();
                panic!("daemon exited ({status}) before opening its socket:\n{err}");
            }
            assert!(
                t0.elapsed() < Duration::from_secs(60),
                "daemon did not open its socket"
            );
            std::thread::sleep(Duration::from_millis(20));
        }
        d
    }

    /// The daemon's stderr so far.
    pub fn log(&self) -> String {
        self.log.lock().unwrap().clone()
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
                self.stderr.take().unwrap().join().unwrap();
                return (status, self.log());
            }
            if t0.elapsed() > Duration::from_secs(60) {
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
    wait_status(c, "homed and idle", Duration::from_secs(120), |s| {
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

/// Waits until the job has ended (done, failed or aborted); returns that status.
pub fn wait_job_end(c: &mut Client, what: &str, timeout: Duration) -> Value {
    wait_status(c, what, timeout, |s| {
        matches!(
            s["job"]["state"].as_str(),
            Some("done" | "failed" | "aborted")
        )
    })
}

/// Loads the inline program `text` as `name` and runs it; returns the `job.load` reply.
pub fn run_text(c: &mut Client, text: &str, name: &str) -> Value {
    let info = ok(c, "job.load", json!({ "text": text, "name": name }));
    ok(c, "job.run", Value::Null);
    info
}

/// Polls a machine deployed in this process until `pred` holds; a two-minute hang guard,
/// never a timing. A timeout shows the last status' mode, job, faults and axes.
pub fn wait_machine(
    m: &hytask::machine::Machine,
    what: &str,
    pred: impl Fn(&hytask::machine::api::Status) -> bool,
) -> hytask::machine::api::Status {
    use hytask::machine::api::MachineApi;
    let t0 = Instant::now();
    loop {
        let s = m.status();
        if pred(&s) {
            return s;
        }
        assert!(
            t0.elapsed() < Duration::from_secs(120),
            "timed out waiting for {what}: mode {:?}, job {:?}, faults {:?}, axes {:?}",
            s.mode,
            s.job,
            s.faults,
            s.axes
        );
        std::thread::sleep(Duration::from_millis(5));
    }
}

/// Deploys the machine of `config` in-process, resets e-stop, switches it on and homes it,
/// then returns it once every axis is homed and the machine idle.
pub fn deploy_homed(config: &std::path::Path) -> std::sync::Arc<hytask::machine::Machine> {
    use hytask::machine::api::{MachineApi, Mode};
    let m = hytask::machine::Machine::deploy(hytask::config::load(config).unwrap()).unwrap();
    m.estop_reset().unwrap();
    m.machine_on().unwrap();
    m.home(None).unwrap();
    wait_machine(&m, "homed and idle", |s| {
        s.mode == Mode::Idle && s.axes.iter().all(|a| a.homed)
    });
    m
}
