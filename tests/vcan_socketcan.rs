//! `SocketCanBus` on a real vcan0: round trip, filters, a full transmit queue, interface
//! down. Runs under `tests/vcan/run` (on the host's vcan0, or in the VM it boots where the
//! host kernel has no CAN), which sets `HYTASK_VCAN`; elsewhere each test says why and
//! returns. Tests change vcan0 (down, a qdisc), so the harness runs them one at a time.
#![allow(clippy::unwrap_used)]

use hytask_hal::socketcan::{IdFilter, SocketCanBus, SocketCanError};
use hytask_hal::{CanBus, CanFrame, CanId, Error as _, ErrorKind};
use std::process::Command;
use std::time::{Duration, Instant};

/// The interface to test on, or `None` (with the reason printed) outside the harness.
fn vcan() -> Option<String> {
    match std::env::var("HYTASK_VCAN") {
        Ok(i) if !i.is_empty() => Some(i),
        _ => {
            eprintln!(
                "vcan_socketcan: HYTASK_VCAN is unset, so this test does not run here: it needs \
                 a real vcan0 and runs under tests/vcan/run (which boots a VM when the host \
                 kernel has no CAN)"
            );
            None
        }
    }
}

fn sid(raw: u16) -> CanId {
    CanId::standard(raw).unwrap()
}

/// Runs a system command the test needs (`ip`, `tc`), panicking with its output on failure.
fn sh(args: &[&str]) {
    let o = Command::new(args[0]).args(&args[1..]).output().unwrap();
    assert!(
        o.status.success(),
        "{args:?}: {}",
        String::from_utf8_lossy(&o.stderr)
    );
}

/// Waits (hang guard 60 s) for the next frame on `bus`.
fn recv(bus: &mut SocketCanBus) -> CanFrame {
    let t0 = Instant::now();
    loop {
        if let Some(f) = bus.try_recv().unwrap() {
            return f;
        }
        assert!(t0.elapsed() < Duration::from_secs(60), "no frame in 60 s");
        std::thread::sleep(Duration::from_millis(1));
    }
}

/// Takes what is pending until 200 ms pass without a frame (the kernel delivers vcan frames
/// synchronously, so this is only slack for a slow emulator).
fn drain(bus: &mut SocketCanBus) -> Vec<CanFrame> {
    let mut got = Vec::new();
    let mut quiet = Instant::now();
    while quiet.elapsed() < Duration::from_millis(200) {
        if let Some(f) = bus.try_recv().unwrap() {
            got.push(f);
            quiet = Instant::now();
        } else {
            std::thread::sleep(Duration::from_millis(1));
        }
    }
    got
}

#[test]
fn frames_go_round_trip_between_two_sockets() {
    let Some(i) = vcan() else { return };
    let mut a = SocketCanBus::open(&i).unwrap();
    let mut b = SocketCanBus::open(&i).unwrap();
    assert_eq!(a.iface(), i);
    let frames = [
        CanFrame::new(sid(0x601), &[0x40, 0x00, 0x10, 0, 0, 0, 0, 0]).unwrap(),
        CanFrame::new(CanId::extended(0x18FF_0001).unwrap(), &[1, 2, 3]).unwrap(),
        CanFrame::remote(sid(0x701), 1).unwrap(),
        CanFrame::new(sid(0x080), &[]).unwrap(),
    ];
    for f in &frames {
        a.try_send(f).unwrap();
    }
    for f in &frames {
        assert_eq!(&recv(&mut b), f);
    }
    // A socket does not receive its own frames.
    assert!(drain(&mut a).is_empty());
    let mut buf = [frames[0]; 4];
    b.try_send(&frames[1]).unwrap();
    let t0 = Instant::now();
    let mut n = 0;
    while n == 0 && t0.elapsed() < Duration::from_secs(60) {
        n = a.recv_into(&mut buf).unwrap();
    }
    assert_eq!(&buf[..n], &frames[1..2]);
}

#[test]
fn filters_deliver_only_the_wanted_ids() {
    let Some(i) = vcan() else { return };
    let mut a = SocketCanBus::open(&i).unwrap();
    let mut b = SocketCanBus::open(&i).unwrap();
    b.set_filters(&[
        IdFilter::exact(sid(0x181)),
        IdFilter::masked(sid(0x580), 0x780),
    ])
    .unwrap();
    let send = |a: &mut SocketCanBus, id: CanId| {
        a.try_send(&CanFrame::new(id, &[id.raw() as u8]).unwrap())
            .unwrap()
    };
    for id in [
        sid(0x182),
        sid(0x181),
        CanId::extended(0x181).unwrap(),
        sid(0x5FF),
        sid(0x601),
        sid(0x581),
    ] {
        send(&mut a, id);
    }
    let got: Vec<CanId> = drain(&mut b).iter().map(|f| f.id()).collect();
    assert_eq!(got, vec![sid(0x181), sid(0x5FF), sid(0x581)]);
    b.set_filters(&[]).unwrap();
    send(&mut a, sid(0x181));
    assert!(
        drain(&mut b).is_empty(),
        "an empty filter list receives nothing"
    );
    b.accept_all().unwrap();
    send(&mut a, sid(0x182));
    assert_eq!(recv(&mut b).id(), sid(0x182));
}

/// Restores vcan0 whatever the test did (up, no qdisc), also when it panics.
struct Restore(String);

impl Drop for Restore {
    fn drop(&mut self) {
        let _ = Command::new("tc")
            .args(["qdisc", "del", "dev", &self.0, "root"])
            .output();
        let _ = Command::new("ip")
            .args(["link", "set", "up", &self.0])
            .output();
    }
}

#[test]
fn a_full_transmit_queue_is_would_block_naming_the_interface() {
    let Some(i) = vcan() else { return };
    let _restore = Restore(i.clone());
    let mut a = SocketCanBus::open(&i).unwrap();
    // vcan delivers synchronously and has no queue; a token bucket of 8 kbit/s with room
    // for a few frames makes its transmit queue fill the way a real controller's does.
    sh(&[
        "tc", "qdisc", "add", "dev", &i, "root", "tbf", "rate", "8kbit", "burst", "64", "limit",
        "64",
    ]);
    let f = CanFrame::new(sid(0x200), &[0; 8]).unwrap();
    let mut err: Option<SocketCanError> = None;
    for _ in 0..100_000 {
        if let Err(e) = a.try_send(&f) {
            err = Some(e);
            break;
        }
    }
    let e = err.expect("100000 frames queued at 8 kbit/s without the queue filling");
    assert_eq!(e.kind(), ErrorKind::WouldBlock, "{e}");
    assert!(e.kind().is_transient());
    assert!(e.to_string().contains(&i), "{e}");
    assert!(e.to_string().contains("transmit queue full"), "{e}");
}

#[test]
fn interface_down_is_a_link_failure_naming_the_interface() {
    let Some(i) = vcan() else { return };
    let _restore = Restore(i.clone());
    let mut a = SocketCanBus::open(&i).unwrap();
    let mut b = SocketCanBus::open(&i).unwrap();
    let f = CanFrame::new(sid(0x181), &[1]).unwrap();
    a.try_send(&f).unwrap();
    assert_eq!(recv(&mut b), f);
    sh(&["ip", "link", "set", "down", &i]);
    let e = a.try_send(&f).unwrap_err();
    assert_eq!(e.kind(), ErrorKind::Disconnected, "{e}");
    assert!(e.kind().is_link_failure());
    assert_eq!(
        e.to_string(),
        format!("CAN interface {i} is down (`ip link set {i} up`)")
    );
    // The receiving socket learns it too, on its next read.
    let e = b.try_recv().unwrap_err();
    assert!(matches!(e, SocketCanError::InterfaceDown { .. }), "{e:?}");
    sh(&["ip", "link", "set", "up", &i]);
    a.try_send(&f).unwrap();
    assert_eq!(recv(&mut b), f);
}

#[test]
fn opening_a_missing_interface_names_it() {
    let Some(_) = vcan() else { return };
    let e = SocketCanBus::open("vcan97").unwrap_err();
    assert!(matches!(e, SocketCanError::NoSuchInterface { .. }), "{e:?}");
    assert!(e.to_string().contains("vcan97"), "{e}");
}
