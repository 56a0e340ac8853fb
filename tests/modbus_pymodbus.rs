//! Interoperability with an independent implementation, pymodbus (venv made by
//! tests/install-deps): our poller against a pymodbus server over TCP and over RTU on a
//! socat pty pair, and our simulator against pymodbus' client over TCP and RTU.
//!
//! Real processes: every wait is a hang guard, never a timing.
#![allow(clippy::unwrap_used)]

mod modbus_support;

use hytask::modbus::{Endpoint, UnitConfig};
use hytask_hal::modbus::Quality;
use modbus_support::{
    listen_addr, modbus_sim, pty_pair, python, run_link, script, unit, wait_until, Proc,
};
use std::process::Command;

/// Our map of the pymodbus server's unit 1 (see tests/modbus/pymodbus_server.py).
fn server_unit() -> UnitConfig {
    unit(
        r#"
        name = "py"
        backend = "modbus_tcp"
        address = "127.0.0.1:1"
        unit_id = 1
        digital_inputs = [
            { name = "d0", register = 0 }, { name = "d1", register = 1 }, { name = "d2", register = 2 },
            { name = "b3", table = "holding_register", register = 5, bit = 3 },
        ]
        digital_outputs = [
            { name = "c2", register = 2 },
            { name = "hb0", table = "holding_register", register = 5, bit = 0 },
        ]
        analog_inputs = [
            { name = "u", register = 0 },
            { name = "s", register = 1, type = "i16" },
            { name = "f", register = 2, type = "f32", word_order = "low_first" },
        ]
        analog_outputs = [{ name = "w", register = 7 }]
        "#,
    )
}

/// Starts tests/modbus/pymodbus_server.py with `args`; returns it once serving, with what
/// its `ready` line says after the word (the TCP port it listens on; empty over RTU).
fn pymodbus_server(py: &std::path::Path, args: &[&str]) -> (Proc, String) {
    let mut cmd = Command::new(py);
    cmd.arg(script("pymodbus_server.py")).args(args);
    let p = Proc::spawn(cmd);
    let ready = p.expect("ready", |l| l == "ready" || l.starts_with("ready "));
    let rest = ready["ready".len()..].trim().to_string();
    (p, rest)
}

/// Reads the inputs, writes the outputs, checks both ends.
fn exchange_with_pymodbus(server: &mut Proc, endpoint: Endpoint) {
    let u = server_unit();
    let img = u.image.clone();
    let _events = run_link("py", endpoint, vec![u]);
    wait_until("every input read", || {
        img.di
            .iter()
            .chain(img.ai.iter())
            .all(|c| c.sample().quality == Quality::Good)
    });
    let di: Vec<f64> = img.di.iter().map(|c| c.sample().value).collect();
    assert_eq!(
        di,
        [1.0, 0.0, 1.0, 1.0],
        "discrete inputs and bit 3 of 0b1010"
    );
    let ai: Vec<f64> = img.ai.iter().map(|c| c.sample().value).collect();
    assert_eq!(ai, [4660.0, -2.0, 12.5]);
    img.dout[0].command(1.0);
    img.dout[1].command(1.0);
    img.ao[0].command(321.0);
    wait_until("outputs written", || {
        img.dout
            .iter()
            .chain(img.ao.iter())
            .all(|o| o.pending().is_none())
    });
    for (ask, want) in [
        ("get co 2", "co 2 True"),
        ("get hr 5", "hr 5 11"),
        ("get hr 7", "hr 7 321"),
    ] {
        server.send(ask);
        let got = server.expect(want, |l| l.starts_with(&ask[4..]));
        assert_eq!(got, want);
    }
}

#[test]
fn our_poller_against_a_pymodbus_tcp_server() {
    let Some(py) = python() else { return };
    // Port 0: the server reports the port it got (a port picked here and released could be
    // taken by another test binary before the server binds it).
    let (mut server, port) = pymodbus_server(&py, &["tcp", "0"]);
    assert!(port.parse::<u16>().is_ok_and(|p| p > 0), "ready {port}");
    exchange_with_pymodbus(&mut server, Endpoint::Tcp(format!("127.0.0.1:{port}")));
}

#[test]
fn our_poller_against_a_pymodbus_rtu_server_on_a_pty_pair() {
    let Some(py) = python() else { return };
    let dir = tempfile::tempdir().unwrap();
    let Some((_socat, a, b)) = pty_pair(dir.path()) else {
        return;
    };
    let (mut server, _) = pymodbus_server(&py, &["rtu", b.to_str().unwrap()]);
    exchange_with_pymodbus(
        &mut server,
        Endpoint::Rtu {
            path: a.display().to_string(),
            baud: 19200,
            parity: tokio_serial::Parity::None,
            stop_bits: tokio_serial::StopBits::One,
        },
    );
}

const SIM_INIT: [&str; 8] = [
    "--exec",
    "set a 1",
    "--exec",
    "set c 1",
    "--exec",
    "set load 4660",
    "--exec",
    "set temp -2.5",
];

fn check_pymodbus_client(sim: &mut Proc, client_args: &[&str], py: &std::path::Path) {
    let out = Command::new(py)
        .arg(script("pymodbus_client.py"))
        .args(client_args)
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{text}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_str(text.trim()).unwrap();
    assert_eq!(v["di"], serde_json::json!([true, false, true]));
    // load 0x1234; -2.5 as f32 low word first: 0x0000, 0xC020.
    assert_eq!(v["ir"], serde_json::json!([4660, 0, 0, 0xC020]));
    assert_eq!(v["co"], serde_json::json!([false, true]));
    assert_eq!(v["hr"], serde_json::json!([0x4148, 0]));
    assert_eq!(v["exception"], serde_json::json!(2), "illegal data address");
    sim.send("get speed");
    sim.expect_line("speed 12.5");
    sim.send("get horn");
    sim.expect_line("horn 1");
}

#[test]
fn pymodbus_client_against_our_simulator_over_tcp() {
    let Some(py) = python() else { return };
    let map = script("map.toml").display().to_string();
    let mut args = vec!["--map", &map, "--listen", "127.0.0.1:0"];
    args.extend(SIM_INIT);
    let mut sim = Proc::spawn({
        let mut c = Command::new(env!("CARGO_BIN_EXE_hytask"));
        c.arg("modbus-sim").args(&args);
        c
    });
    let addr = listen_addr(&sim.expect("listening", |l| l.starts_with("listening tcp ")));
    let (host, port) = addr.rsplit_once(':').unwrap();
    check_pymodbus_client(&mut sim, &["tcp", host, port], &py);
}

#[test]
fn pymodbus_client_against_our_simulator_over_rtu() {
    let Some(py) = python() else { return };
    let dir = tempfile::tempdir().unwrap();
    let Some((_socat, a, b)) = pty_pair(dir.path()) else {
        return;
    };
    let map = script("map.toml").display().to_string();
    let b = b.display().to_string();
    let mut args = vec!["--map", &map, "--rtu", &b];
    args.extend(SIM_INIT);
    let mut sim = modbus_sim(&args, 1);
    check_pymodbus_client(&mut sim, &["rtu", a.to_str().unwrap()], &py);
}
