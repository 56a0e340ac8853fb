//! A job too large to keep its queue items (more than `machine::job::KEEP_ITEMS_MAX`) is
//! planned again by its feeder while it runs (issue 8, job memory): through the real daemon,
//! it runs to the end, reaches its last line and its programmed end pose.

mod support;

use serde_json::{json, Value};
use std::time::Duration;
use support::*;

#[test]
fn a_job_larger_than_the_kept_queue_is_planned_again_and_runs_to_its_end() {
    // Spindle-speed changes ride in the queue without stopping motion: a job of 70,000 of
    // them has more queue items than a prepared job keeps, yet needs no long motion (the
    // machine takes about one per servo period: ~70 s).
    let n = hytask::machine::job::KEEP_ITEMS_MAX + 4_464;
    let mut text = String::from("G21 G90\nG0 X290 Y290 Z-5\n");
    for i in 0..n {
        text.push_str(if i % 2 == 0 { "S1000\n" } else { "S1200\n" });
    }
    text.push_str("G1 X280 Y285 F1200\nM2\n");
    let lines = n as u64 + 4;

    let d = Daemon::start(&fast_sim());
    let mut c = d.client();
    ready(&mut c);
    let info = ok(
        &mut c,
        "job.load",
        json!({"text": text, "name": "long.ngc"}),
    );
    assert_eq!(info["lines"], json!(lines));
    ok(&mut c, "job.run", Value::Null);
    let s = wait_job_end(&mut c, "the job's end", Duration::from_secs(600));
    assert_eq!(s["job"]["state"], json!("done"), "{}", s["job"]);
    let x = axis(&s, "X")["actual"].as_f64().unwrap();
    let y = axis(&s, "Y")["actual"].as_f64().unwrap();
    assert!(
        (x - 280.0).abs() < 0.01 && (y - 285.0).abs() < 0.01,
        "X {x} Y {y}"
    );
    assert_eq!(s["job"]["progress"], json!(1.0), "{}", s["job"]);
}
