//! Remote peers (`hytask::bridge::remote`) in one process: a "remote" deployment served by
//! `PeerHost` on one Zenoh session, a local deployment reaching its task through a
//! `RemoteProxy` on another, linked over loopback TCP.
//!
//! Every wait is a hang guard (60 s), never a timing: the tests hold for any interleaving of
//! the two sessions' threads.
#![allow(clippy::unwrap_used)]

#[path = "zenoh/peer_rig.rs"]
mod peer_rig;
mod zenoh_support;

use hytask::bridge::remote::{RemoteLink, RemoteProxy};
use hytask::rt::prelude::*;
use peer_rig::{local_at, pair, remote, remote_cfg, remote_linked, zenoh_cfg, WorkCmd};
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use zenoh_support::free_port;

const GUARD: Duration = Duration::from_secs(60);

fn wait_final(h: &CommandHandle) -> CommandStatus {
    let s = h.wait(GUARD);
    assert!(s.is_final(), "no final status within {GUARD:?}: {s:?}");
    s
}

#[test]
fn a_remote_operation_completes_and_its_event_and_port_arrive() {
    let (peer, mut l) = pair("rt-far", 30.0, false);
    let h = l.worker.send(WorkCmd::Work(5)).unwrap();
    assert_eq!(wait_final(&h), CommandStatus::Done);
    let t0 = Instant::now();
    let got = loop {
        if let Some(n) = l.worked.pop() {
            break n;
        }
        assert!(t0.elapsed() < GUARD, "the remote event never arrived");
        std::thread::sleep(Duration::from_millis(10));
    };
    assert_eq!(got, 1);
    let mut count = l.rt.reader::<u32>("worker.count").unwrap();
    let t0 = Instant::now();
    while count.latest() != Some(1) {
        assert!(t0.elapsed() < GUARD, "the remote port never arrived");
        std::thread::sleep(Duration::from_millis(10));
    }
    // A remote rejection fails the command (accepted locally = forwarded).
    let h = l.worker.send(WorkCmd::Work(-1)).unwrap();
    assert_eq!(
        wait_final(&h),
        CommandStatus::Failed("remote peer rejected the operation")
    );
    assert!(
        l.link.last_error().contains("ms must not be negative"),
        "{}",
        l.link.last_error()
    );
    l.rt.stop();
    peer.stop();
}

#[test]
fn missing_remote_names_are_refused_by_name() {
    // Nobody serves this machine: refused after the configured timeout, naming the remote.
    let session = hytask::bridge::session::open(&zenoh_cfg(free_port(), None)).unwrap();
    let e = RemoteLink::connect(&session, &remote_cfg("nobody-here", 1.0, false))
        .err()
        .unwrap()
        .to_string();
    assert!(
        e.contains("'far'") && e.contains("hytask/nobody-here/tasks"),
        "{e}"
    );
    assert!(e.contains("within 1 s"), "{e}");

    let port = free_port();
    let peer = remote("names-far", port);
    let s2 = hytask::bridge::session::open(&zenoh_cfg(free_port(), Some(port))).unwrap();
    let link = RemoteLink::connect(&s2, &remote_cfg("names-far", 30.0, false)).unwrap();
    let e = link
        .require("ghost", &[], &[], &[])
        .unwrap_err()
        .to_string();
    assert!(e.contains("no task 'ghost'") && e.contains("worker"), "{e}");
    let e = link
        .require("worker", &["nope"], &["nada"], &["zilch"])
        .unwrap_err()
        .to_string();
    for name in [
        "operation 'worker.nope'",
        "event 'worker.nada'",
        "port 'zilch'",
    ] {
        assert!(e.contains(name), "{name} not in: {e}");
    }
    let e = RemoteProxy::<WorkCmd>::new(&link, "worker", "l")
        .unwrap()
        .event::<u32>("missing")
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("event 'worker.missing'"), "{e}");
    peer.stop();
}

#[test]
fn a_slow_remote_delays_only_its_own_commands() {
    let (peer, l) = pair("slow-far", 3.0, false);
    // `worker` is busy far longer than timeout_s: its command fails with the timeout...
    let slow = l.worker.send(WorkCmd::Work(600_000)).unwrap();
    // ... while `other`, another remote task behind another proxy, answers meanwhile.
    let quick = l.other.send(WorkCmd::Work(1)).unwrap();
    assert_eq!(wait_final(&quick), CommandStatus::Done);
    assert_eq!(
        wait_final(&slow),
        CommandStatus::Failed("remote peer: no final status within timeout_s")
    );
    assert!(
        l.link.last_error().contains("worker.work"),
        "{}",
        l.link.last_error()
    );
    l.rt.stop();
    peer.stop();
}

#[test]
fn a_lost_critical_remote_fails_pending_commands_and_calls_the_stop_hook() {
    let (peer, l) = pair("lost-far", 600.0, true);
    let stops = Arc::new(AtomicU32::new(0));
    let message = Arc::new(Mutex::new(String::new()));
    let (s, m) = (stops.clone(), message.clone());
    l.link.on_lost(move |msg, critical| {
        assert!(critical);
        *m.lock().unwrap() = msg.to_owned();
        s.fetch_add(1, Ordering::AcqRel);
    });
    let mut lost = l.rt.event::<u32>("worker.peer_lost").unwrap().subscribe(4);
    let pending = l.worker.send(WorkCmd::Work(600_000)).unwrap();
    let t0 = Instant::now();
    while pending.status() != CommandStatus::Accepted {
        assert!(t0.elapsed() < GUARD, "not accepted: {:?}", pending.status());
        std::thread::sleep(Duration::from_millis(10));
    }
    // The remote goes away: its liveliness token is withdrawn.
    peer.stop();
    // Long before the 600 s timeout, the pending command fails as lost.
    assert_eq!(
        wait_final(&pending),
        CommandStatus::Failed("remote peer lost")
    );
    let t0 = Instant::now();
    while stops.load(Ordering::Acquire) == 0 || lost.pop().is_none() {
        assert!(t0.elapsed() < GUARD, "no stop hook or peer_lost event");
        std::thread::sleep(Duration::from_millis(10));
    }
    assert!(
        message.lock().unwrap().contains("'far'"),
        "{}",
        message.lock().unwrap()
    );
    assert!(!l.link.alive());
    l.rt.stop();
}

/// Until `f` holds (hang guard).
fn wait_for(what: &str, f: impl Fn() -> bool) {
    let t0 = Instant::now();
    while !f() {
        assert!(t0.elapsed() < GUARD, "waited too long for {what}");
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// A remote restarted after its loss: a command accepted meanwhile waits for it (its
/// `timeout_s` is far beyond the hang guard) and runs once its liveliness token is back,
/// instead of failing because the local side has not seen it back yet.
#[test]
fn a_command_accepted_while_the_remote_is_lost_runs_once_it_is_back() {
    let (port, local_port) = (free_port(), free_port());
    let peer = remote("back-far", port);
    let l = local_at(local_port, "back-far", port, 600.0, false);
    assert_eq!(
        wait_final(&l.worker.send(WorkCmd::Work(1)).unwrap()),
        CommandStatus::Done
    );
    peer.stop();
    wait_for("the loss", || !l.link.alive());
    let h = l.worker.send(WorkCmd::Work(1)).unwrap();
    wait_for("the command accepted while lost", || {
        h.status() == CommandStatus::Accepted
    });
    let peer = remote_linked("back-far", port, Some(local_port));
    assert_eq!(
        wait_final(&h),
        CommandStatus::Done,
        "{}",
        l.link.last_error()
    );
    assert!(l.link.alive());
    l.rt.stop();
    peer.stop();
}

/// A remote that does not come back within `timeout_s`: the command accepted while it was
/// lost fails then, with an error naming the remote, also given to the loss hook.
#[test]
fn a_command_for_a_remote_not_back_within_its_timeout_fails_naming_it() {
    let (peer, l) = pair("gone-far", 5.0, false);
    let reports = Arc::new(Mutex::new(Vec::<String>::new()));
    let r = reports.clone();
    l.link
        .on_lost(move |msg, _| r.lock().unwrap().push(msg.to_owned()));
    peer.stop();
    wait_for("the loss", || !l.link.alive());
    let h = l.worker.send(WorkCmd::Work(1)).unwrap();
    assert_eq!(
        wait_final(&h),
        CommandStatus::Failed("remote peer lost and not back within timeout_s")
    );
    let e = l.link.last_error();
    assert!(
        e.contains("'far'") && e.contains("worker.work") && e.contains("not back within"),
        "{e}"
    );
    wait_for("the report to the loss hook", || {
        reports
            .lock()
            .unwrap()
            .iter()
            .any(|m| m.contains("not back within"))
    });
    l.rt.stop();
}
