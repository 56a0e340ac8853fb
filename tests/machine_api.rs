//! The operator API of a deployed machine, called in this process (no socket): what
//! `job.state` says through a feed hold, and which refusal `job.run` gives first.
//!
//! Real time, as the daemon runs the machine: the waits are hang guards of a minute, never
//! timings.
#![allow(clippy::unwrap_used)]

use hytask::machine::api::{ApiError, JobSource, MachineApi, Mode, Status};
use hytask::machine::Machine;
use std::sync::Arc;
use std::time::{Duration, Instant};

fn machine() -> Arc<Machine> {
    let path =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/sim-fast.toml");
    Machine::deploy(hytask::config::load(&path).unwrap()).unwrap()
}

fn wait(m: &Machine, what: &str, pred: impl Fn(&Status) -> bool) -> Status {
    let t0 = Instant::now();
    loop {
        let s = m.status();
        if pred(&s) {
            return s;
        }
        assert!(
            t0.elapsed() < Duration::from_secs(60),
            "timed out waiting for {what}: mode {:?}, job {:?}",
            s.mode,
            s.job
        );
        std::thread::sleep(Duration::from_millis(5));
    }
}

fn ready(m: &Machine) {
    m.estop_reset().unwrap();
    m.machine_on().unwrap();
    m.home(None).unwrap();
    wait(m, "homed and idle", |s| {
        s.mode == Mode::Idle && s.axes.iter().all(|a| a.homed)
    });
}

fn text(name: &str, program: &str) -> JobSource {
    JobSource {
        path: None,
        text: Some(program.into()),
        name: Some(name.into()),
    }
}

fn shutdown(m: &Machine) {
    hytask::daemon::Deployed::shutdown(m).unwrap();
}

#[test]
fn a_feed_hold_shows_as_holding_in_the_job_state_and_resume_as_running() {
    let m = machine();
    ready(&m);
    m.job_load(&text("hold.ngc", "G21 G90\nG1 X50 Y50 F600\nM2\n"))
        .unwrap();
    m.job_run().unwrap();
    wait(&m, "running", |s| {
        s.mode == Mode::Running && s.job.state == "running"
    });
    m.job_pause().unwrap();
    let held = wait(&m, "the hold", |s| s.mode == Mode::Holding);
    assert_eq!(held.job.state, "holding", "job state in a feed hold");
    m.job_resume().unwrap();
    let resumed = wait(&m, "the resume", |s| s.mode == Mode::Running);
    assert_eq!(resumed.job.state, "running", "job state after resume");
    m.job_abort().unwrap();
    wait(&m, "the abort", |s| s.mode == Mode::Idle);
    shutdown(&m);
}

#[test]
fn job_run_reports_the_machine_state_before_anything_about_the_job() {
    let m = machine();
    // Loaded where the machine stands at power-up; homing then moves every axis away.
    m.job_load(&text("old.ngc", "G21 G90\nG1 X10 Y10 F600\nM2\n"))
        .unwrap();
    ready(&m);
    m.estop().unwrap();
    wait(&m, "e-stop", |s| s.mode == Mode::Estop);
    match m.job_run() {
        Err(ApiError::Rejected(why)) => assert!(why.contains("e-stop"), "{why}"),
        other => panic!("job.run in e-stop: {other:?}"),
    }
    m.estop_reset().unwrap();
    match m.job_run() {
        Err(ApiError::Rejected(why)) => assert!(why.contains("machine is off"), "{why}"),
        other => panic!("job.run with the machine off: {other:?}"),
    }
    shutdown(&m);
}
