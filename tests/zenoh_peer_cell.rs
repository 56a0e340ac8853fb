//! The pick-and-place cell with its camera in another process: `hytask peer` hosts the camera
//! (config/vision-peer.toml) and `hytask serve` the cell (config/pickplace-remote.toml), over
//! Zenoh on loopback. The remote cell sorts the same objects as the local one (same seed),
//! and when the peer process is killed mid-run the cell reports the loss and the error, and
//! sorts again once the peer is restarted.
//!
//! Real processes: every wait is a hang guard (60 s and more), never a timing; the kill lands
//! wherever the run is (moving, detecting), and each case ends in the same reported error.
#![allow(clippy::unwrap_used)]

mod cell_support;
mod zenoh_support;

use hytask::control::client::Client;
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};
use zenoh_support::{free_port, Proc};

const SEED: u64 = 42;
const GUARD: Duration = Duration::from_secs(120);

fn replace_once(text: &str, from: &str, to: &str) -> String {
    assert!(text.contains(from), "shipped config changed: no {from:?}");
    text.replace(from, to)
}

/// The shipped files on fresh ports; the cell on simulated time at 10x with generous
/// timeouts (a loaded host must not turn a slow detection into an error).
fn configs(dir: &Path) -> (PathBuf, PathBuf) {
    let (pc, pp) = (free_port(), free_port());
    let ports = |t: String| {
        t.replace("17460", &pc.to_string())
            .replace("17461", &pp.to_string())
    };
    let cell = std::fs::read_to_string("config/pickplace-remote.toml").unwrap();
    assert!(
        cell.contains(&format!("seed = {SEED}\nmass_kg")),
        "world seed changed"
    );
    let cell = replace_once(&cell, "# sim_speed = 10.0", "sim_speed = 10.0");
    let cell = replace_once(
        &cell,
        "detection_timeout_ms = 2000",
        "detection_timeout_ms = 100000",
    );
    let cell = replace_once(&cell, "timeout_s = 10.0", "timeout_s = 60.0");
    let script = std::fs::canonicalize("config/scripts/selection.st").unwrap();
    let cell = replace_once(
        &cell,
        "script = \"scripts/selection.st\"",
        &format!("script = {:?}", script.display().to_string()),
    );
    let c = dir.join("cell.toml");
    std::fs::write(&c, ports(cell)).unwrap();
    (c, zenoh_support::vision_peer_config(dir, pp, pc))
}

fn connect(socket: &Path, cell: &mut Proc) -> Client {
    let t0 = Instant::now();
    loop {
        if let Ok(c) = Client::connect(socket) {
            return c;
        }
        if let Some(s) = cell.child.try_wait().unwrap() {
            panic!("the cell exited ({s}):\n{}", cell.log());
        }
        assert!(t0.elapsed() < GUARD, "no cell socket:\n{}", cell.log());
        std::thread::sleep(Duration::from_millis(50));
    }
}

fn run_cell_command(config: &Path, socket: &Path, runs: u32) -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_hytask"));
    c.arg("run-cell")
        .arg(config)
        .args(["--runs", &runs.to_string(), "--socket"])
        .arg(socket);
    c
}

/// `hytask run-cell CONFIG --socket S --runs n`: (success, stdout, stderr).
fn run_cell(config: &Path, socket: &Path, runs: u32) -> (bool, String, String) {
    let out = run_cell_command(config, socket, runs).output().unwrap();
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

fn status(c: &mut Client) -> Value {
    c.call("status", Value::Null).unwrap()
}

#[test]
fn the_remote_camera_sorts_like_the_local_one_and_survives_a_peer_restart() {
    let dir = tempfile::tempdir().unwrap();
    let (cell_cfg, peer_cfg) = configs(dir.path());
    let socket = dir.path().join("cell.sock");
    let mut peer = Proc::spawn(
        &["peer", "--config"],
        &peer_cfg,
        dir.path().join("peer1.log"),
    );
    let mut cell = Proc::spawn(
        &["serve", "--socket", socket.to_str().unwrap(), "--config"],
        &cell_cfg,
        dir.path().join("cell.log"),
    );
    let mut c = connect(&socket, &mut cell);

    // The same objects, sorted the same way as the local cell with this seed.
    let (ok, out, err) = run_cell(&cell_cfg, &socket, 4);
    assert!(
        ok,
        "{out}\n{err}\ncell:\n{}\npeer:\n{}",
        cell.log(),
        peer.log()
    );
    let want = cell_support::expected_counts(SEED, 4);
    let line = format!(
        "per container: A {}  B {}  reject {}",
        want[0], want[1], want[2]
    );
    assert!(out.contains(&line), "want '{line}' in:\n{out}");

    // Kill the peer process while a long run goes on.
    let runs_before = status(&mut c)["job"]["line"].as_u64().unwrap();
    let long = run_cell_command(&cell_cfg, &socket, 40)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let t0 = Instant::now();
    while status(&mut c)["job"]["line"].as_u64().unwrap() == runs_before
        || status(&mut c)["job"]["total_lines"].as_u64() != Some(40)
    {
        assert!(t0.elapsed() < GUARD, "the long run did not start sorting");
        std::thread::sleep(Duration::from_millis(50));
    }
    peer.child.kill().unwrap();
    peer.child.wait().unwrap();
    let out = long.wait_with_output().unwrap();
    let (stdout, stderr) = (
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr),
    );
    assert!(
        !out.status.success(),
        "the run went on without its camera:\n{stdout}"
    );
    assert!(
        stderr.contains("remote peer 'vision'") && stderr.contains("lost"),
        "the loss is not reported:\n{stderr}\ncell:\n{}",
        cell.log()
    );
    assert!(stdout.contains("error:"), "{stdout}");
    // The cell itself is still up and answers.
    assert!(cell.child.try_wait().unwrap().is_none(), "{}", cell.log());

    // Restart the peer and run at once: the cell recovers (run-cell calls selection.stop)
    // and sorts again. The camera's proxy waits for the peer's liveliness token (up to the
    // remote's timeout_s) whether the run starts before or after the cell has seen it back.
    let peer2 = Proc::spawn(
        &["peer", "--config"],
        &peer_cfg,
        dir.path().join("peer2.log"),
    );
    let (ok, out, err) = run_cell(&cell_cfg, &socket, 3);
    assert!(
        ok,
        "{out}\n{err}\ncell:\n{}\npeer:\n{}",
        cell.log(),
        peer2.log()
    );
    assert!(out.contains("sorted:        3 of 3"), "{out}");
    assert!(cell.log().contains("is back"), "{}", cell.log());
}
