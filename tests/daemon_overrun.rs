//! Safety path: an overrun storm on the servo thread stops the machine under control.
//!
//! In its own test binary on purpose: the injected overruns burn 1.5 servo periods of CPU per
//! cycle at SCHED_FIFO priority, which would starve the servo threads of daemons in other
//! tests running in parallel (cargo runs test binaries one after another).
//!
//! A real-time test by nature: it runs the fixture's real-time servo thread (a simulated
//! clock has no overruns). Its waits are hang guards only.
#![allow(clippy::unwrap_used)]

mod support;

use serde_json::{json, Value};
use std::time::Duration;
use support::*;

#[test]
fn an_overrun_storm_on_the_servo_thread_stops_the_machine() {
    let d = Daemon::start(&fast_sim());
    let mut c = d.client();
    ok(&mut c, "subscribe", Value::Null);
    ready(&mut c);
    run_job(&mut c, "jobs/long.ngc");
    wait_status(&mut c, "job moving", Duration::from_secs(60), |s| {
        s["job"]["line"].as_u64().unwrap() >= 6
    });
    // The fixture's storm threshold is 50 consecutive overruns.
    ok(
        &mut c,
        "sim.fault",
        json!({"kind": "overrun", "cycles": 60}),
    );
    let events = wait_event(&mut c, "fault event", Duration::from_secs(60), |e| {
        e.topic == "fault"
    });
    let f = &events.last().unwrap().data;
    assert!(f["message"].as_str().unwrap().contains("overran"), "{f}");
    assert!(
        f["message"].as_str().unwrap().contains("50 times in a row"),
        "{f}"
    );
    let s = wait_status(&mut c, "stopped", Duration::from_secs(60), |s| {
        s["mode"] == json!("fault") && at_rest(s, 1e-3)
    });
    assert!(s["threads"][0]["overruns"].as_u64().unwrap() >= 50);
    assert_eq!(s["job"]["state"], json!("failed"));
}
