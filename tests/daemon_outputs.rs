//! The daemon's shutdown (what SIGTERM runs) leaves every output of the machine in its safe
//! state: the daemon of `hytask serve` runs in this process on a machine deployed here, so
//! that the simulated I/O device can be read once the daemon has returned.
//!
//! Real time, as a daemon runs: the waits are hang guards of a minute, never timings.
#![allow(clippy::unwrap_used)]

mod support;

use hytask::control::client::Client;
use hytask::machine::Machine;
use serde_json::{json, Value};
use std::sync::Arc;
use std::time::Duration;
use support::{fast_sim, ok, ready, wait_status};

#[test]
fn shutdown_puts_the_spindle_coolant_and_every_output_in_the_safe_state() {
    let cfg = hytask::config::load(&fast_sim()).unwrap();
    let machine = Machine::deploy(cfg.clone()).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let socket = dir.path().join("control.sock");
    let listener = hytask::control::server::bind(
        &hytask::control::server::SocketOptions::from_config(&cfg.control, Some(socket.clone())),
    )
    .unwrap();
    let (stop_tx, stop_rx) = tokio::sync::oneshot::channel::<()>();
    let (done_tx, done_rx) = std::sync::mpsc::channel();
    let deployed: Arc<dyn hytask::daemon::Deployed> = machine.clone();
    std::thread::spawn(move || {
        let r = hytask::daemon::run(deployed, listener, async move {
            let _ = stop_rx.await;
        });
        let _ = done_tx.send(r.map_err(|e| e.to_string()));
    });

    let mut c = Client::connect(&socket).unwrap();
    ready(&mut c);
    // The spindle and the flood coolant on, left on by an MDI line (no M5/M9/M2).
    ok(&mut c, "mdi", json!({"line": "M3 S12000 M8"}));
    wait_status(
        &mut c,
        "spindle and coolant on",
        Duration::from_secs(60),
        |s| {
            s["outputs"]["spindle_on"] == json!(1.0)
                && s["outputs"]["coolant_flood"] == json!(1.0)
                && s["job"]["state"] == json!("done")
        },
    );
    // The status shows the machine's output image; the I/O task writes it to the device at
    // the start of the next servo cycle, so the device may be a cycle behind the reply.
    let io = machine.sim_io(0).unwrap();
    let t0 = std::time::Instant::now();
    while !(io.digital_output(0).unwrap() && io.digital_output(2).unwrap()) {
        assert!(
            t0.elapsed() < Duration::from_secs(60),
            "spindle and coolant outputs never reached the device"
        );
        std::thread::sleep(Duration::from_millis(1));
    }
    drop(c);

    stop_tx.send(()).unwrap();
    let result = done_rx
        .recv_timeout(Duration::from_secs(60))
        .expect("the daemon did not return after its shutdown");
    result.unwrap();
    let digital: Vec<bool> = (0..4).map(|i| io.digital_output(i).unwrap()).collect();
    assert_eq!(
        digital, [false; 4],
        "spindle_on, spindle_ccw, coolant_flood, coolant_mist after shutdown"
    );
    assert_eq!(io.analog_output(0).unwrap(), 0.0, "spindle speed reference");
    let status: Value =
        serde_json::to_value(hytask::machine::api::MachineApi::status(&*machine)).unwrap();
    assert_eq!(status["mode"], json!("off"), "{status}");
}
