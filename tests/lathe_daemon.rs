//! Spindle-synchronised jobs through the daemon's machine API on the simulated mill (its
//! spindle is simulated with a position and an index): a G33.1 rigid tap runs to `done`
//! and leaves the tool where it started, a G76 thread runs to `done`, and a spindle too fast
//! for the axis at the programmed pitch fails the job with the rpm and both speeds.
//!
//! Simulated clock, unpaced; the waits are hang guards of a minute, never timings.
#![allow(clippy::unwrap_used)]

mod support;

use hytask::machine::api::{JobSource, MachineApi, Mode, Status};
use hytask::machine::Machine;
use std::sync::Arc;

fn wait(m: &Machine, what: &str, pred: impl Fn(&Status) -> bool) -> Status {
    support::wait_machine(m, what, pred)
}

fn deploy(config: &std::path::Path) -> Arc<Machine> {
    support::deploy_homed(config)
}

/// Runs `program` to its end (whatever it is); returns the status then.
fn run(m: &Machine, program: &str) -> Status {
    m.job_load(&JobSource {
        path: None,
        text: Some(program.into()),
        name: Some("thread.ngc".into()),
    })
    .unwrap();
    m.job_run().unwrap();
    wait(m, "the job's end", |s| {
        matches!(s.job.state.as_str(), "done" | "failed" | "aborted") && s.mode == Mode::Idle
    })
}

#[test]
fn taps_and_threads_run_to_done_and_a_spindle_too_fast_for_the_axis_fails_the_job() {
    let dir = tempfile::tempdir().unwrap();
    let config = support::sim_clock_config(dir.path(), 0, None);
    let m = deploy(&config);

    let s = run(
        &m,
        "G21 G90\nG0 X100 Y100 Z-5\nM3 S600\nG33.1 Z-20 K1\nM5\nM2\n",
    );
    assert_eq!(s.job.state, "done", "{:?}", s.job.reason);
    // Idle, the command tracks the drive: within its following error of the start.
    let z = s.axes[2].commanded;
    assert!((z + 5.0).abs() < 0.005, "after the tap Z is {z}");

    let s = run(
        &m,
        "G21 G90 G18\nG0 X150 Y150 Z-5\nM3 S1000\n\
         G76 P1.5 Z-30 I-1 J0.2 K1 R2 Q29.5 H1\nM5\nM2\n",
    );
    assert_eq!(s.job.state, "done", "{:?}", s.job.reason);

    // 2400 rpm × 1.5 mm = 60 mm/s along Z, which allows 50.
    let s = run(
        &m,
        "G21 G90 G18\nG0 X150 Y150 Z-5\nM3 S2400\nG33 Z-35 K1.5\nM5\nM2\n",
    );
    assert_eq!(s.job.state, "failed");
    let reason = s.job.reason.unwrap_or_default();
    assert!(
        reason.contains("line 4")
            && reason.contains("2400 rpm")
            && reason.contains("60.00 mm/s")
            && reason.contains("50.00 mm/s"),
        "{reason}"
    );
    hytask::daemon::Deployed::shutdown(&*m).unwrap();
}
