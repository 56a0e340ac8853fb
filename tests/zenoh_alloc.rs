//! Proves that the servo thread allocates nothing while the Zenoh bridge exports the machine
//! (issue 15: "the realtime side never touches the network"): the fast simulated mill
//! deployed on its real periodic thread, the bridge subscribed to every realtime event of
//! its tasks (deferred subscriptions: the emitter only queues) and publishing every output
//! port at 1 kHz, a remote Zenoh peer subscribed to all of it and operating the machine
//! through the bridge's calls (reset, on, home, a job, a task operation). A counting global
//! allocator counts every allocation made inside a servo cycle on any thread.
//!
//! One test function on purpose: the count is process-wide, so nothing else may run beside it.
//! Every wait is a hang guard, never a timing.
#![allow(clippy::unwrap_used)]

mod counting_alloc;
mod support;
mod zenoh_support;

use hytask::bridge::Bridge;
use hytask::machine::api::MachineApi;
use serde_json::{json, Value};
use std::collections::BTreeSet;
use std::sync::{Arc, Mutex};
use std::time::Duration;
use zenoh::Wait;

/// Hang guard of every wait: a loaded host may run the machine slower than real time.
const GUARD: Duration = Duration::from_secs(120);

/// A query through the bridge (waiting for its route); panics on an error reply.
fn call(s: &zenoh::Session, key: &str, payload: Value) -> Value {
    zenoh_support::query(s, key, Some(&payload), GUARD).unwrap_or_else(|e| panic!("{key}: {e}"))
}

fn wait_until(what: &str, machine: &dyn MachineApi, f: impl Fn(&Value) -> bool) {
    zenoh_support::wait_status(what, machine, GUARD, f)
}

#[test]
fn the_servo_thread_allocates_nothing_while_the_bridge_exports_the_machine() {
    assert_eq!(counting_alloc::in_rt_steps(), 0);
    let machine = hytask::machine::deploy_from(Some(&support::fast_sim())).unwrap();
    let (cfg, endpoint) =
        zenoh_support::bridge_config("mill", "port_rate_hz = 1000.0\nstatus_rate_hz = 50.0");
    let bridge = Bridge::start(machine.clone(), "mill", &cfg).unwrap();
    assert!(!bridge.port_keys().is_empty(), "no port exported");

    let s = zenoh_support::client(&endpoint);
    // Kinds of key seen (`port`, `event`, `status`, `events`), counted on Zenoh's thread.
    let seen = Arc::new(Mutex::new(BTreeSet::new()));
    let seen2 = seen.clone();
    let sub = s
        .declare_subscriber("hytask/mill/**")
        .callback(move |sample| {
            let key = sample.key_expr().as_str();
            let kind = match key.rsplit('/').collect::<Vec<_>>().as_slice() {
                ["status", ..] => "status".to_owned(),
                [_, kind, ..] => (*kind).to_owned(),
                _ => key.to_owned(),
            };
            seen2.lock().unwrap().insert(kind);
        })
        .wait()
        .unwrap();

    // Operated from the remote peer: every call runs on the bridge's call workers and its
    // command through the machine task's queue into servo cycles.
    call(&s, "hytask/mill/control/estop.reset", Value::Null);
    call(&s, "hytask/mill/control/machine.on", Value::Null);
    call(&s, "hytask/mill/control/home", Value::Null);
    wait_until("homed and idle", &*machine, |s| {
        s["mode"] == json!("idle")
            && s["axes"]
                .as_array()
                .unwrap()
                .iter()
                .all(|a| a["homed"] == json!(true))
    });
    let job = "G21 G90\nG0 X50 Y60 Z-5\nG1 X80 Y70 F3000\nG0 Z-2\nM2\n";
    call(
        &s,
        "hytask/mill/control/job.load",
        json!({"text": job, "name": "z.ngc"}),
    );
    call(&s, "hytask/mill/control/job.run", Value::Null);
    wait_until("the job done", &*machine, |s| {
        s["job"]["state"] == json!("done") && s["mode"] == json!("idle")
    });
    let r = call(
        &s,
        "hytask/mill/machine/op/set_optional_stop",
        json!({"on": true}),
    );
    assert_eq!(r["status"], "done", "{r}");
    wait_until("port, event and status publications", &*machine, |_| {
        let seen = seen.lock().unwrap();
        ["port", "event", "status"]
            .iter()
            .all(|k| seen.contains(*k))
    });
    assert!(
        machine.servo_cycles() > 1000,
        "the servo thread ran ({} cycles)",
        machine.servo_cycles()
    );

    drop(sub);
    let _ = s.close().wait();
    bridge.stop();
    machine.shutdown().unwrap();
    let n = counting_alloc::in_rt_steps();
    assert_eq!(
        n,
        0,
        "allocations inside servo cycles with the bridge running; first one at:\n{}",
        counting_alloc::first_rt_backtrace().unwrap_or_default()
    );
}
