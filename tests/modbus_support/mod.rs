//! Helpers of the Modbus tests: child processes read line by line (the simulator, pymodbus
//! scripts, socat), the pymodbus venv, pty pairs, and an in-process poller.
#![allow(clippy::unwrap_used, dead_code)]

use hytask::modbus::{Endpoint, LinkConfig, LinkEvent, UnitConfig};
use std::io::{BufRead, BufReader, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, Command, Stdio};
use std::sync::mpsc::{channel, Receiver};
use std::time::{Duration, Instant};

/// Hang guard of every wait.
pub const GUARD: Duration = Duration::from_secs(90);

/// A child process whose stdout lines arrive on `lines`; killed when dropped.
pub struct Proc {
    pub child: Child,
    pub stdin: ChildStdin,
    pub lines: Receiver<String>,
}

impl Proc {
    /// Spawns `cmd` with piped stdin/stdout.
    pub fn spawn(mut cmd: Command) -> Proc {
        let mut child = cmd
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .unwrap();
        let stdin = child.stdin.take().unwrap();
        let out = BufReader::new(child.stdout.take().unwrap());
        let (tx, lines) = channel();
        std::thread::spawn(move || {
            for l in out.lines() {
                let Ok(l) = l else { return };
                if tx.send(l).is_err() {
                    return;
                }
            }
        });
        Proc {
            child,
            stdin,
            lines,
        }
    }

    /// Sends one line.
    pub fn send(&mut self, line: &str) {
        writeln!(self.stdin, "{line}").unwrap();
        self.stdin.flush().unwrap();
    }

    /// Waits for a line matching `pred`; returns it.
    pub fn expect(&self, what: &str, pred: impl Fn(&str) -> bool) -> String {
        let t0 = Instant::now();
        let mut seen = Vec::new();
        while t0.elapsed() < GUARD {
            if let Ok(l) = self.lines.recv_timeout(Duration::from_millis(100)) {
                if pred(&l) {
                    return l;
                }
                seen.push(l);
            }
        }
        panic!("never saw {what}; saw {seen:#?}");
    }

    /// Waits for exactly the line `want`.
    pub fn expect_line(&self, want: &str) {
        self.expect(want, |l| l == want);
    }

    /// Waits for every line of `want`, in any order: changes that land in the same poll
    /// cycle (M9 then M5, or M3 with its S word) are reported in map order, not program order.
    pub fn expect_lines(&self, want: &[&str]) {
        let mut missing: Vec<&str> = want.to_vec();
        let t0 = Instant::now();
        let mut seen = Vec::new();
        while !missing.is_empty() && t0.elapsed() < GUARD {
            if let Ok(l) = self.lines.recv_timeout(Duration::from_millis(100)) {
                match missing.iter().position(|m| *m == l) {
                    Some(k) => {
                        missing.swap_remove(k);
                    }
                    None => seen.push(l),
                }
            }
        }
        assert!(missing.is_empty(), "never saw {missing:?}; saw {seen:#?}");
    }
}

impl Drop for Proc {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// `hytask modbus-sim` with `args`; returns it once it printed its `listening` lines.
pub fn modbus_sim(args: &[&str], listening: usize) -> Proc {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_hytask"));
    cmd.arg("modbus-sim").args(args);
    let p = Proc::spawn(cmd);
    for _ in 0..listening {
        p.expect("listening", |l| l.starts_with("listening "));
    }
    p
}

/// The address of a `listening tcp ADDR` line.
pub fn listen_addr(line: &str) -> String {
    line.strip_prefix("listening tcp ").unwrap().to_string()
}

/// The pymodbus venv's python (made by tests/install-deps). Missing: a failure under CI,
/// else `None` with a note (the suite is then skipped on this developer machine).
pub fn python() -> Option<PathBuf> {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("target/modbus-venv/bin/python");
    let ok = Command::new(&p)
        .args(["-c", "import pymodbus, serial"])
        .status()
        .is_ok_and(|s| s.success());
    if ok {
        return Some(p);
    }
    assert!(
        std::env::var("CI").is_err(),
        "pymodbus venv missing at {}: run tests/install-deps",
        p.display()
    );
    eprintln!("skipped: no pymodbus venv (run tests/install-deps)");
    None
}

/// A script under tests/modbus.
pub fn script(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/modbus")
        .join(name)
}

/// A pty pair linked as `dir/a` and `dir/b` by socat (kept while the returned process
/// lives). Missing socat fails under CI, like the venv.
pub fn pty_pair(dir: &Path) -> Option<(Proc, PathBuf, PathBuf)> {
    let (a, b) = (dir.join("a"), dir.join("b"));
    let have = Command::new("socat").arg("-V").output().is_ok();
    if !have {
        assert!(
            std::env::var("CI").is_err(),
            "socat missing: run tests/install-deps"
        );
        eprintln!("skipped: no socat (run tests/install-deps)");
        return None;
    }
    let mut cmd = Command::new("socat");
    cmd.arg(format!("pty,raw,echo=0,link={}", a.display()))
        .arg(format!("pty,raw,echo=0,link={}", b.display()));
    let p = Proc::spawn(cmd);
    let t0 = Instant::now();
    while !(a.exists() && b.exists()) {
        assert!(t0.elapsed() < GUARD, "socat made no pty pair");
        std::thread::sleep(Duration::from_millis(10));
    }
    Some((p, a, b))
}

/// A unit from an `[[io]]` TOML table.
pub fn unit(io_toml: &str) -> UnitConfig {
    let io: hytask::config::IoConfig = toml::from_str(io_toml).unwrap();
    hytask::modbus::unit(&io, "io[0]", "estop").unwrap()
}

/// Runs a poller for `units` on `endpoint` on its own thread; returns its events.
pub fn run_link(name: &str, endpoint: Endpoint, units: Vec<UnitConfig>) -> Receiver<LinkEvent> {
    let (tx, rx) = channel();
    let link = hytask::modbus::link::Link::new(
        LinkConfig {
            name: name.to_string(),
            endpoint,
            timeout: Duration::from_millis(300),
            max_backoff: Duration::from_millis(200),
            units,
        },
        tx,
    );
    std::thread::spawn(move || {
        tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .unwrap()
            .block_on(link.run());
    });
    rx
}

/// Waits until `pred` holds (polling).
pub fn wait_until(what: &str, pred: impl Fn() -> bool) {
    let t0 = Instant::now();
    while !pred() {
        assert!(t0.elapsed() < GUARD, "timed out waiting for {what}");
        std::thread::sleep(Duration::from_millis(5));
    }
}

/// Waits for an event matching `pred`; returns it.
pub fn wait_link_event(rx: &Receiver<LinkEvent>, pred: impl Fn(&LinkEvent) -> bool) -> LinkEvent {
    let t0 = Instant::now();
    let mut seen = Vec::new();
    while t0.elapsed() < GUARD {
        if let Ok(e) = rx.recv_timeout(Duration::from_millis(100)) {
            if pred(&e) {
                return e;
            }
            seen.push(e.message());
        }
    }
    panic!("no matching link event; saw {seen:#?}");
}

/// `config/sim-modbus.toml` with the panel at `addr` and fast homing (the axes start near
/// their home switches), written into `dir`.
pub fn machine_config(dir: &Path, addr: &str) -> PathBuf {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut text = std::fs::read_to_string(root.join("config/sim-modbus.toml")).unwrap();
    let fast = |t: String, from: &str, to: &str, n: usize| {
        assert_eq!(
            t.matches(from).count(),
            n,
            "sim-modbus.toml changed: {from}"
        );
        t.replace(from, to)
    };
    text = fast(
        text,
        "address = \"127.0.0.1:15020\"",
        &format!("address = \"{addr}\""),
        1,
    );
    text = fast(
        text,
        "initial_position = 150.0",
        "initial_position = 298.0",
        2,
    );
    text = fast(
        text,
        "initial_position = -50.0",
        "initial_position = -2.0",
        1,
    );
    text = fast(
        text,
        "velocity = 20.0, latch_velocity = 2.0",
        "velocity = 40.0, latch_velocity = 5.0",
        2,
    );
    text = fast(
        text,
        "velocity = 10.0, latch_velocity = 1.0",
        "velocity = 20.0, latch_velocity = 5.0",
        1,
    );
    let path = dir.join("machine.toml");
    std::fs::write(&path, text).unwrap();
    path
}

/// The calling thread's kernel id (for `/proc/self/task/TID`).
pub fn tid() -> i32 {
    // SAFETY: gettid has no preconditions.
    unsafe { libc::gettid() }
}

/// Serves `sim` over Modbus TCP on a free loopback port from its own thread ("sim") with a
/// current-thread runtime, as `hytask modbus-sim` runs it; returns the address and the
/// thread's kernel id.
pub fn serve_sim(sim: &hytask::modbus::sim::Sim) -> (String, i32) {
    let (tx, rx) = channel();
    let s = sim.clone();
    std::thread::Builder::new()
        .name("sim".into())
        .spawn(move || {
            let id = tid();
            let rt = tokio::runtime::Builder::new_current_thread()
                .enable_all()
                .build()
                .unwrap();
            rt.block_on(async move {
                let l = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
                tx.send((l.local_addr().unwrap().to_string(), id)).unwrap();
                hytask::modbus::sim::serve_tcp(s, l).await.unwrap();
            });
        })
        .unwrap();
    rx.recv().unwrap()
}
