//! A machine that depends on a peer process: `hytask serve` on the simulated mill with a
//! critical `[[remote]]` (the cell's camera served by `hytask peer`). Killing the peer
//! process while a job runs stops the machine under control: the job ends with an error
//! naming the remote, and a `fault` event reports the loss.
//!
//! Real processes: every wait is a hang guard (60 s and more), never a timing. The job's
//! feed move lasts minutes of wall time, so the kill lands while it runs on any host.
#![allow(clippy::unwrap_used)]

mod support;
mod zenoh_support;

use serde_json::{json, Value};
use std::time::Duration;
use support::{ok, wait_event, wait_job_end, wait_status, Daemon};
use zenoh_support::{free_port, Proc};

const GUARD: Duration = Duration::from_secs(120);

/// A feed move of 200 mm at 30 mm/min: 400 s of simulated time.
const JOB: &str = "G21 G90\nG0 X10 Y10\nG1 X210 F30\nM2\n";

#[test]
fn losing_a_critical_remote_stops_the_job_under_control_and_names_it() {
    let dir = tempfile::tempdir().unwrap();
    let (mill_port, peer_port) = (free_port(), free_port());
    let peer_cfg = zenoh_support::vision_peer_config(dir.path(), peer_port, mill_port);
    let mut peer = Proc::spawn(
        &["peer", "--config"],
        &peer_cfg,
        dir.path().join("peer.log"),
    );
    // The peer serves before the mill starts (the mill checks it at start, within timeout_s).
    let s = zenoh_support::peer_session(&format!("tcp/127.0.0.1:{peer_port}"));
    zenoh_support::wait_token(&s, "hytask/vision/alive", GUARD);

    let base = support::sim_clock_config(dir.path(), support::SIM_SPEED, None);
    let mut text = std::fs::read_to_string(base).unwrap();
    text.push_str(&format!(
        "\n[zenoh]\nkey = \"mill\"\nlisten = [\"tcp/127.0.0.1:{mill_port}\"]\n\
         connect = [\"tcp/127.0.0.1:{peer_port}\"]\n\n\
         [[remote]]\nname = \"vision\"\ntimeout_s = 60.0\ncritical = true\n"
    ));
    let config = dir.path().join("mill.toml");
    std::fs::write(&config, text).unwrap();
    let daemon = Daemon::start(&config);
    let mut c = daemon.client();
    let mut events = daemon.client();
    ok(&mut events, "subscribe", json!({"topics": ["fault"]}));
    support::ready(&mut c);
    support::run_text(&mut c, JOB, "long-feed.ngc");
    wait_status(&mut c, "the feed move running", GUARD, |s| {
        s["job"]["line"].as_u64().unwrap() >= 3 && s["mode"] == json!("running")
    });

    peer.child.kill().unwrap();
    peer.child.wait().unwrap();

    let seen = wait_event(&mut events, "a fault naming the remote", GUARD, |e| {
        e.topic == "fault"
            && e.data["message"]
                .as_str()
                .unwrap_or("")
                .contains("'vision'")
    });
    let fault = &seen.last().unwrap().data;
    assert_eq!(fault["critical"], json!(true), "{fault}");
    let end = wait_job_end(&mut c, "the job's end", GUARD);
    assert_eq!(end["job"]["state"], json!("failed"), "{}", end["job"]);
    let reason = end["job"]["reason"].as_str().unwrap_or("");
    assert!(
        reason.contains("remote peer 'vision'") && reason.contains("lost"),
        "the reason does not name the remote: {}\n{}",
        end["job"],
        daemon.log()
    );
    // A controlled stop: every axis at rest, the machine on and idle (not in e-stop), the
    // daemon still serving.
    let s = wait_status(&mut c, "the machine at rest", GUARD, |s| {
        s["mode"] == json!("idle") && support::at_rest(s, 1e-6)
    });
    let x = support::axis(&s, "X")["actual"].as_f64().unwrap();
    assert!(x < 209.0, "the feed move ran to its end (X {x})");
    assert!(
        ok(&mut c, "status", Value::Null)["mode"] == json!("idle"),
        "the daemon stopped serving:\n{}",
        daemon.log()
    );
}

/// The topology check covers remote peers: `hytask serve` refuses to start when a
/// `[[remote]]` does not answer within its `timeout_s`, naming it (nobody serves `vision`).
#[test]
fn a_missing_remote_refuses_the_start_naming_it_after_its_timeout() {
    let dir = tempfile::tempdir().unwrap();
    let base = support::sim_clock_config(dir.path(), support::SIM_SPEED, None);
    let mut text = std::fs::read_to_string(base).unwrap();
    text.push_str(&format!(
        "\n[zenoh]\nkey = \"mill\"\nlisten = [\"tcp/127.0.0.1:{}\"]\n\n\
         [[remote]]\nname = \"vision\"\ntimeout_s = 2.0\n",
        free_port()
    ));
    let config = dir.path().join("mill.toml");
    std::fs::write(&config, text).unwrap();
    let socket = dir.path().join("mill.sock");
    let mut mill = Proc::spawn(
        &["serve", "--socket", socket.to_str().unwrap(), "--config"],
        &config,
        dir.path().join("mill.log"),
    );
    let t0 = std::time::Instant::now();
    let status = loop {
        if let Some(s) = mill.child.try_wait().unwrap() {
            break s;
        }
        assert!(t0.elapsed() < GUARD, "still running:\n{}", mill.log());
        std::thread::sleep(Duration::from_millis(50));
    };
    let log = mill.log();
    assert!(!status.success(), "started without its remote:\n{log}");
    assert!(
        log.contains("remote peer 'vision'") && log.contains("no answer within 2 s"),
        "the refusal does not name the remote and its timeout:\n{log}"
    );
}

/// A machine file's `[[remote]]` tables are checked like the rest, each problem named by key.
#[test]
fn remotes_of_a_machine_file_are_checked_by_key() {
    let base = std::fs::read_to_string(support::fast_sim()).unwrap();
    let text = format!("{base}\n[[remote]]\nname = \"vision\"\ntimeout_s = 0\n");
    let e = hytask::config::parse(&text, "m.toml")
        .unwrap_err()
        .to_string();
    assert!(e.contains("remote[0].timeout_s"), "{e}");
    assert!(e.contains("add a [zenoh] table"), "{e}");
    let ok = format!("{base}\n[zenoh]\n\n[[remote]]\nname = \"vision\"\ncritical = true\n");
    let m = hytask::config::parse(&ok, "m.toml").unwrap();
    assert!(m.remotes[0].critical && m.remotes[0].machine() == "vision");
}
