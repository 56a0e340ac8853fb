//! The operator API of a deployed machine, called in this process (no socket): what
//! `job.state` says through a feed hold, and which refusal `job.run` gives first.
//!
//! Real time, as the daemon runs the machine: the waits are hang guards of a minute, never
//! timings.
#![allow(clippy::unwrap_used)]

mod support;

use hytask::machine::api::{ApiError, JobSource, MachineApi, Mode, Status};
use hytask::machine::Machine;
use std::sync::Arc;
use std::time::{Duration, Instant};

fn machine() -> Arc<Machine> {
    let path =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/sim-fast.toml");
    Machine::deploy(hytask::config::load(&path).unwrap()).unwrap()
}

/// The same mill on the simulated clock (unpaced), for tests about behaviour.
fn sim_machine() -> (Arc<Machine>, tempfile::TempDir) {
    let dir = tempfile::tempdir().unwrap();
    let config = support::sim_clock_config(dir.path(), 0, None);
    let m = Machine::deploy(hytask::config::load(&config).unwrap()).unwrap();
    (m, dir)
}

fn wait(m: &Machine, what: &str, pred: impl Fn(&Status) -> bool) -> Status {
    support::wait_machine(m, what, pred)
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

/// `status` sampled all through a job: the commanded position and the job progress of each
/// reply must come from the same servo cycle. On the cruise of a long straight feed the
/// commanded X runs at exactly the feed rate, so `X + v · t_done` (t_done = progress ×
/// planned time) is the same in every cycle; a reply whose progress is one cycle off its
/// position is off by v × 1 ms = 0.05 mm.
#[test]
fn status_shows_position_and_progress_of_one_servo_cycle() {
    let m = machine();
    ready(&m);
    let v = 50.0; // F3000, mm/s
    let info = m
        .job_load(&text("cruise.ngc", "G21 G90\nG1 X100 F3000\nM2\n"))
        .unwrap();
    let planned = info.planned_time_s;
    m.job_run().unwrap();
    let t0 = Instant::now();
    let mut samples = Vec::new();
    loop {
        let s = m.status();
        if s.job.state != "running" && s.job.state != "loaded" {
            assert_eq!(s.job.state, "done", "{:?}", s.job);
            break;
        }
        let done = s.job.progress * planned;
        // The cruise, well clear of the ramps at both ends.
        if done > 0.3 && done < planned - 0.3 {
            let x = s.axes.iter().find(|a| a.name == "X").unwrap().commanded;
            samples.push((s.servo_cycle, done, x + v * done));
        }
        assert!(t0.elapsed() < Duration::from_secs(120), "the job hangs");
        std::thread::sleep(Duration::from_micros(200));
    }
    assert!(
        samples.len() > 100,
        "{} samples on the cruise",
        samples.len()
    );
    let mut sums: Vec<f64> = samples.iter().map(|s| s.2).collect();
    sums.sort_by(f64::total_cmp);
    let median = sums[sums.len() / 2];
    let torn: Vec<_> = samples
        .iter()
        .filter(|s| (s.2 - median).abs() > 1e-3)
        .collect();
    assert!(
        torn.is_empty(),
        "{} of {} replies mix cycles (servo cycle, t_done, X + v·t_done; median {median}): {:?}",
        torn.len(),
        samples.len(),
        &torn[..torn.len().min(5)]
    );
    shutdown(&m);
}

fn x(s: &Status) -> f64 {
    s.axes.iter().find(|a| a.name == "X").unwrap().actual
}

/// M0 holds the job (mode `Holding`, job "holding"); `job_resume` goes on with the next line.
/// M1 is passed over until optional stop is switched on.
#[test]
fn job_resume_continues_after_an_m0_and_m1_stops_with_optional_stop_on() {
    let (m, _dir) = sim_machine();
    ready(&m);
    let program = "G21 G90\nG0 X100 Y100 Z-5\nM0\nG0 X110\nM1\nG0 X120\nM2\n";
    m.job_load(&text("m0.ngc", program)).unwrap();
    m.job_run().unwrap();
    let held = wait(&m, "the M0 stop", |s| s.job.state == "holding");
    assert_eq!(held.mode, Mode::Holding, "{:?}", held.job);
    assert_eq!(held.job.line, 3);
    m.job_resume().unwrap();
    let done = wait(&m, "the end", |s| s.job.state == "done");
    assert_eq!(done.mode, Mode::Idle);
    assert!((x(&done) - 120.0).abs() < 0.002, "{}", x(&done));

    assert_eq!(m.set_optional_stop(true), Ok(true));
    m.mdi("G0 X100").unwrap();
    wait(&m, "back at X100", |s| {
        s.mode == Mode::Idle && (x(s) - 100.0).abs() < 0.002
    });
    m.job_load(&text("m0.ngc", program)).unwrap();
    m.job_run().unwrap();
    wait(&m, "the M0 stop", |s| s.job.state == "holding");
    m.job_resume().unwrap();
    let held = wait(&m, "the M1 stop", |s| {
        s.job.state == "holding" && s.job.line == 5
    });
    assert_eq!(held.mode, Mode::Holding);
    assert!(held.optional_stop);
    assert!((x(&held) - 110.0).abs() < 0.002, "{}", x(&held));
    m.job_resume().unwrap();
    wait(&m, "the end", |s| s.job.state == "done");
    shutdown(&m);
}

/// `call` reaches task operations by name, but not the job machinery's own `machine.run` and
/// `machine.continue`: a hand-made run of a job nothing feeds would hold the machine in
/// `running` until an abort.
#[test]
fn call_refuses_the_job_machinerys_own_operations() {
    let (m, _dir) = sim_machine();
    ready(&m);
    for (op, args) in [
        (
            "run",
            serde_json::json!({"job": 99, "items": 5, "manual": false}),
        ),
        ("continue", serde_json::json!({"job": 99, "items": 5})),
    ] {
        match m.call("machine", op, &args) {
            Err(ApiError::Rejected(why)) => assert!(why.contains("use job.run"), "{why}"),
            other => panic!("machine.{op}: {other:?}"),
        }
    }
    let s = m.status();
    assert_eq!(s.mode, Mode::Idle);
    // Other operations stay callable.
    assert!(m
        .call(
            "machine",
            "set_optional_stop",
            &serde_json::json!({"on": true})
        )
        .is_ok());
    assert!(m.status().optional_stop);
    shutdown(&m);
}

/// Benchmark defect: about one `mdi M8` / `mdi M9` in 250 hung in `running` without
/// applying its M-code. Many alternating coolant lines, each sent as soon as the previous
/// one's coil is seen (retrying while the machine is still busy with the last one), as the
/// Modbus latency benchmark does; each must apply its output and end `done`.
#[test]
fn many_mdi_coolant_lines_each_apply_their_output_and_end() {
    let (m, _dir) = sim_machine();
    ready(&m);
    for k in 0..600 {
        let on = k % 2 == 0;
        let line = if on { "M8" } else { "M9" };
        let t0 = Instant::now();
        loop {
            match m.mdi(line) {
                Ok(()) => break,
                Err(ApiError::Rejected(_)) => {
                    assert!(t0.elapsed() < Duration::from_secs(60), "mdi {k} refused");
                    std::thread::yield_now();
                }
                Err(e) => panic!("mdi {k} {line}: {e}"),
            }
        }
        let level = f64::from(u8::from(on));
        let what = format!("mdi {k} {line} applied");
        wait(&m, &what, |s| s.outputs["coolant_flood"] == level);
    }
    let s = wait(&m, "the last mdi done", |s| s.job.state != "running");
    assert_eq!(s.job.state, "done");
    shutdown(&m);
}

/// A feed hold on a circle (G2, fitted into arcs: the hold runs along them as a path stop,
/// `motion::path_stop`) stops on the circle, and the job resumes to its end.
#[test]
fn a_feed_hold_on_a_circle_stops_on_it_and_the_job_resumes() {
    let (m, _dir) = sim_machine();
    ready(&m);
    // Forty circles: on the unpaced simulated clock they run in about a quarter of a
    // second, so the pause, sent once the first has begun, lands on one of them.
    let mut program = String::from("G21 G90 G64 P0.01\nG0 X160 Y150 Z-1\nF3000\n");
    for _ in 0..40 {
        program.push_str("G2 X160 Y150 I-10 J0\n");
    }
    program.push_str("G0 Z0\nM2\n");
    m.job_load(&text("circles.ngc", &program)).unwrap();
    m.job_run().unwrap();
    let xy = |s: &Status| {
        let c = |n: &str| s.axes.iter().find(|a| a.name == n).unwrap().commanded;
        (c("X") - 150.0, c("Y") - 150.0)
    };
    wait(&m, "the first circle", |s| s.job.line >= 4);
    m.job_pause().unwrap();
    let held = wait(&m, "the hold", |s| s.mode == Mode::Holding);
    assert_eq!(held.job.state, "holding");
    assert!((4..44).contains(&held.job.line), "{:?}", held.job);
    let (x, y) = xy(&held);
    let r = x.hypot(y);
    assert!((r - 10.0).abs() < 0.011, "held at ({x}, {y}), radius {r}");
    m.job_resume().unwrap();
    let done = wait(&m, "the end", |s| s.job.state == "done");
    let (x, y) = xy(&done);
    assert!((x - 10.0).abs() < 0.002 && y.abs() < 0.002, "({x}, {y})");
    shutdown(&m);
}
