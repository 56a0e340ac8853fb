//! A status is one servo cycle: its job state never runs ahead of its mode, line and
//! position. On the unpaced simulated clock hundreds of servo cycles pass while a status is
//! assembled, so a job event of a later cycle than the snapshot's is common there; the
//! status then waits for the snapshot of that cycle (`Machine::consistent_snapshot`).
#![allow(clippy::unwrap_used)]

mod support;

use hytask::machine::api::{JobSource, MachineApi, Mode, Status};
use hytask::machine::Machine;
use std::time::{Duration, Instant};

fn text(name: &str, program: &str) -> JobSource {
    JobSource {
        path: None,
        text: Some(program.into()),
        name: Some(name.into()),
    }
}

/// Polls without pause until `pred`, checking every status on the way with `check`.
fn poll(m: &Machine, what: &str, check: impl Fn(&Status), pred: impl Fn(&Status) -> bool) {
    let t0 = Instant::now();
    loop {
        let s = m.status();
        check(&s);
        if pred(&s) {
            return;
        }
        assert!(t0.elapsed() < Duration::from_secs(60), "timed out: {what}");
    }
}

/// An M0 after a rapid, run 40 times and watched by a status poll without pause: whenever
/// the job reads "holding", the mode is Holding, the line is the M0's and the tool is at
/// the rapid's end; whenever the job reads "done", the mode is Idle at the program's end.
#[test]
fn the_job_state_never_runs_ahead_of_the_mode_and_the_position() {
    let dir = tempfile::tempdir().unwrap();
    let config = support::sim_clock_config(dir.path(), 0, None);
    let m = Machine::deploy(hytask::config::load(&config).unwrap()).unwrap();
    m.estop_reset().unwrap();
    m.machine_on().unwrap();
    m.home(None).unwrap();
    support::wait_machine(&m, "homed and idle", |s| {
        s.mode == Mode::Idle && s.axes.iter().all(|a| a.homed)
    });
    let x = |s: &Status| s.axes[0].commanded;
    let program = "G21 G90\nG0 X100 Y100 Z-5\nM0\nG0 X10 Y10 Z0\nM2\n";
    let check = |s: &Status| match s.job.state.as_str() {
        "holding" => {
            assert_eq!(s.mode, Mode::Holding, "{:?}", s.job);
            assert_eq!(s.job.line, 3, "{:?}", s.job);
            assert!((x(s) - 100.0).abs() < 0.002, "x {} {:?}", x(s), s.job);
        }
        "done" => {
            assert_eq!(s.mode, Mode::Idle, "{} {:?}", s.servo_cycle, s.job);
            assert!((x(s) - 10.0).abs() < 0.002, "x {} {:?}", x(s), s.job);
        }
        _ => {}
    };
    for _ in 0..40 {
        m.job_load(&text("m0.ngc", program)).unwrap();
        m.job_run().unwrap();
        poll(&m, "the M0", check, |s| s.job.state == "holding");
        m.job_resume().unwrap();
        poll(&m, "the end", check, |s| s.job.state == "done");
    }
    hytask::daemon::Deployed::shutdown(&*m).unwrap();
}
