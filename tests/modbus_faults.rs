//! Bad input: our poller against `hytask modbus-sim` with injected faults, and our
//! simulator against malformed frames. Every fault must end in a clear, distinct report
//! (link event naming link, unit and points) and the points marked bad; never a panic or a
//! hang; and the link must recover once the fault is gone.
//!
//! Real processes: every wait is a hang guard, never a timing.
#![allow(clippy::unwrap_used)]

mod modbus_support;

use hytask::modbus::{Endpoint, LinkEvent};
use hytask_hal::modbus::{FaultKind, Image, Quality};
use modbus_support::{
    listen_addr, modbus_sim, pty_pair, run_link, script, unit, wait_link_event, wait_until, Proc,
};
use std::io::{Read, Write};
use std::sync::mpsc::Receiver;
use std::sync::Arc;
use std::time::Duration;

fn panel(unit_id: u8) -> hytask::modbus::UnitConfig {
    unit(&format!(
        r#"
        name = "panel"
        backend = "modbus_tcp"
        address = "127.0.0.1:1"
        unit_id = {unit_id}
        digital_inputs = [{{ name = "a" }}, {{ name = "b", critical = true }}]
        digital_outputs = [{{ name = "lamp" }}]
        "#
    ))
}

fn tcp_sim() -> (Proc, String) {
    let map = script("map.toml").display().to_string();
    let mut cmd = std::process::Command::new(env!("CARGO_BIN_EXE_hytask"));
    cmd.args([
        "modbus-sim",
        "--map",
        &map,
        "--listen",
        "127.0.0.1:0",
        "--exec",
        "set b 1",
    ]);
    let p = Proc::spawn(cmd);
    let addr = listen_addr(&p.expect("listening", |l| l.starts_with("listening tcp ")));
    (p, addr)
}

fn all_good(img: &Image) -> bool {
    img.di.iter().all(|c| c.sample().quality == Quality::Good)
}

fn all_bad(img: &Image) -> bool {
    img.di.iter().all(|c| c.sample().quality == Quality::Bad)
}

/// Injects `cmd` into a healthy link, expects a fault event matching `kind`, then clears it
/// with `clear` and expects recovery.
fn inject(
    sim: &mut Proc,
    img: &Arc<Image>,
    events: &Receiver<LinkEvent>,
    cmd: &str,
    clear: &str,
    kind: impl Fn(&FaultKind) -> bool,
) -> LinkEvent {
    wait_until("healthy", || all_good(img));
    sim.send(cmd);
    let e = wait_link_event(events, |e| e.fault.as_ref().is_some_and(&kind));
    wait_until("points bad", || all_bad(img));
    sim.send(clear);
    wait_link_event(events, |e| e.fault.is_none());
    wait_until("healthy again", || all_good(img));
    e
}

#[test]
fn exceptions_timeouts_and_garbled_answers_are_reported_distinctly_and_recover() {
    let (mut sim, addr) = tcp_sim();
    let u = panel(1);
    let img = u.image.clone();
    let link = format!("tcp:{addr}");
    let ev = run_link(&link, Endpoint::Tcp(addr.clone()), vec![u]);
    wait_until("first poll", || all_good(&img));
    assert_eq!(img.di[1].sample().value, 1.0);

    let e = inject(&mut sim, &img, &ev, "exception 4", "exception 0", |f| {
        *f == FaultKind::Exception(4)
    });
    assert_eq!(
        (e.link.as_str(), e.unit, e.device.as_str()),
        (link.as_str(), 1, "panel")
    );
    assert_eq!(e.points, ["a", "b"]);
    assert_eq!(e.critical, ["b"]);
    assert!(
        e.message().contains("exception 4 (server device failure)"),
        "{}",
        e.message()
    );

    // No answer at all, and an answer slower than the timeout: both are timeouts.
    inject(&mut sim, &img, &ev, "drop on", "drop off", |f| {
        *f == FaultKind::Timeout
    });
    let slow = inject(&mut sim, &img, &ev, "delay 1000", "delay 0", |f| {
        *f == FaultKind::Timeout
    });
    assert!(
        slow.message().contains("timeout; points bad: a, b"),
        "{}",
        slow.message()
    );
    // An answer for another unit, and a cut answer: protocol errors or timeouts (a cut frame
    // is waited for until the timeout), never a good value.
    inject(&mut sim, &img, &ev, "garble unit", "garble none", |f| {
        matches!(f, FaultKind::Protocol(_) | FaultKind::Disconnected(_))
    });
    inject(&mut sim, &img, &ev, "garble short", "garble none", |f| {
        matches!(
            f,
            FaultKind::Timeout | FaultKind::Protocol(_) | FaultKind::Disconnected(_)
        )
    });
    // The connection closed by the server: reconnected.
    inject(&mut sim, &img, &ev, "close", "dump", |f| {
        matches!(f, FaultKind::Disconnected(_))
    });
    // Outputs still reach the device after all that.
    img.dout[0].command(1.0);
    sim.expect_line("out lamp 1");
}

/// Well-formed frames whose content does not fit the request: fewer items than asked for
/// (bits and registers), another function code. `tokio-modbus` does not check the item
/// count (a `debug_assert` in its readers): the poller must, and must not panic.
#[test]
fn answers_with_fewer_items_or_another_function_are_protocol_errors() {
    let (mut sim, addr) = tcp_sim();
    let u = unit(
        r#"
        name = "panel"
        backend = "modbus_tcp"
        address = "127.0.0.1:1"
        digital_inputs = [{ name = "a" }, { name = "b" }]
        analog_inputs = [{ name = "load", type = "u16" }]
        "#,
    );
    let img = u.image.clone();
    let ev = run_link("garbled-content", Endpoint::Tcp(addr), vec![u]);
    let load_good = || img.ai[0].sample().quality == Quality::Good;
    wait_until("first poll", || all_good(&img) && load_good());
    for (garble, says) in [("count", "short response"), ("function", "")] {
        let e = inject(
            &mut sim,
            &img,
            &ev,
            &format!("garble {garble}"),
            "garble none",
            |f| matches!(f, FaultKind::Protocol(_)),
        );
        assert!(e.message().contains(says), "{garble}: {}", e.message());
        wait_until("the register good again", load_good);
    }
}

/// A write answered with an echo that does not match the request (`tokio-modbus`'s writers
/// `debug_assert` the echo): a protocol error naming the output, then recovery.
#[test]
fn a_write_echoing_another_address_is_a_protocol_error() {
    let (mut sim, addr) = tcp_sim();
    let u = panel(1);
    let img = u.image.clone();
    let ev = run_link("bad-echo", Endpoint::Tcp(addr), vec![u]);
    wait_until("healthy", || all_good(&img));
    sim.send("garble echo");
    img.dout[0].command(1.0);
    let e = wait_link_event(&ev, |e| e.fault.is_some());
    assert!(
        matches!(e.fault, Some(FaultKind::Protocol(_))),
        "{}",
        e.message()
    );
    assert!(e.message().contains("echoes"), "{}", e.message());
    assert!(e.points.contains(&"lamp".to_string()), "{:?}", e.points);
    sim.send("garble none");
    wait_link_event(&ev, |e| e.fault.is_none());
    wait_until("the lamp written", || {
        img.dout[0].quality() == Quality::Good
    });
    sim.expect_line("out lamp 1");
}

#[test]
fn a_wrong_unit_id_is_an_exception_from_the_gateway_not_a_value() {
    let (_sim, addr) = tcp_sim();
    let u = panel(9);
    let img = u.image.clone();
    let ev = run_link("wrong-unit", Endpoint::Tcp(addr), vec![u]);
    let e = wait_link_event(&ev, |e| e.fault.is_some());
    assert_eq!(e.fault, Some(FaultKind::Exception(11)), "{}", e.message());
    assert_eq!(e.unit, 9);
    wait_until("the inputs bad", || all_bad(&img));
}

#[test]
fn rtu_crc_errors_wrong_units_short_answers_and_silence_are_reported() {
    let dir = tempfile::tempdir().unwrap();
    let Some((_socat, a, b)) = pty_pair(dir.path()) else {
        return;
    };
    let map = script("map.toml").display().to_string();
    let b = b.display().to_string();
    let mut sim = modbus_sim(&["--map", &map, "--rtu", &b, "--exec", "set b 1"], 1);
    let rtu = Endpoint::Rtu {
        path: a.display().to_string(),
        baud: 19200,
        parity: tokio_serial::Parity::None,
        stop_bits: tokio_serial::StopBits::One,
    };
    let u = panel(1);
    let img = u.image.clone();
    let ev = run_link("rtu", rtu, vec![u]);
    wait_until("first poll", || all_good(&img));
    inject(&mut sim, &img, &ev, "garble crc", "garble none", |f| {
        matches!(
            f,
            FaultKind::Timeout | FaultKind::Protocol(_) | FaultKind::Disconnected(_)
        )
    });
    // An answer from another unit (valid CRC) and a well-formed answer with fewer items.
    inject(&mut sim, &img, &ev, "garble unit", "garble none", |f| {
        matches!(f, FaultKind::Timeout | FaultKind::Protocol(_))
    });
    let e = inject(&mut sim, &img, &ev, "garble count", "garble none", |f| {
        matches!(f, FaultKind::Protocol(_))
    });
    assert!(e.message().contains("short response"), "{}", e.message());
    inject(&mut sim, &img, &ev, "exception 2", "exception 0", |f| {
        *f == FaultKind::Exception(2)
    });
    inject(&mut sim, &img, &ev, "drop on", "drop off", |f| {
        *f == FaultKind::Timeout
    });
}

#[test]
fn the_simulator_survives_malformed_frames() {
    let (mut sim, addr) = tcp_sim();
    for garbage in [
        &[0u8, 1, 0, 9, 0, 6, 1, 3, 0, 0, 0, 1][..], // protocol id 9
        &[0, 1, 0, 0, 0xFF, 0xFF, 1][..],            // length 65535
        &[0, 1, 0, 0, 0, 2, 1, 0x2B][..],            // unknown function
        &[0, 1, 0, 0, 0, 3, 1, 3, 0][..],            // truncated read request
    ] {
        let mut s = std::net::TcpStream::connect(&addr).unwrap();
        s.set_read_timeout(Some(Duration::from_secs(60))).unwrap();
        s.write_all(garbage).unwrap();
        let mut answer = Vec::new();
        // Either an exception answer or the connection closed: never a hang.
        let mut buf = [0u8; 64];
        if let Ok(n) = s.read(&mut buf) {
            answer.extend_from_slice(&buf[..n]);
        }
        if answer.len() >= 9 {
            assert!(answer[7] & 0x80 != 0, "an exception answer: {answer:?}");
        }
    }
    // Still serving.
    sim.send("get b");
    sim.expect_line("b 1");
    let u = panel(1);
    let img = u.image.clone();
    let _ev = run_link("after-garbage", Endpoint::Tcp(addr), vec![u]);
    wait_until("a good poll after the garbage", || all_good(&img));
}

#[test]
fn an_output_refused_with_an_exception_is_reported_once_and_retried_at_the_poll_rate() {
    let (mut sim, addr) = tcp_sim();
    let u = panel(1);
    let img = u.image.clone();
    let ev = run_link("refused-output", Endpoint::Tcp(addr), vec![u]);
    wait_until("healthy", || all_good(&img));
    sim.send("exception 4");
    wait_link_event(&ev, |e| {
        e.fault == Some(FaultKind::Exception(4)) && e.points == ["a", "b"]
    });
    img.dout[0].command(1.0);
    let first = wait_link_event(&ev, |e| e.points == ["lamp"]);
    assert_eq!(first.fault, Some(FaultKind::Exception(4)));
    // A few polls later (each poll reads the inputs again), the refusal is still one report.
    std::thread::sleep(Duration::from_millis(100));
    sim.send("exception 0");
    let mut lamp_reports = 0;
    loop {
        let e = wait_link_event(&ev, |_| true);
        if e.points == ["lamp"] && e.fault.is_some() {
            lamp_reports += 1;
        }
        if e.fault.is_none() && e.points == ["a", "b"] {
            break;
        }
    }
    assert_eq!(lamp_reports, 0, "the refused output was reported again");
    sim.expect_line("out lamp 1");
}
