//! Probing on the stepped runtime: the machine and interpolator tasks with the real
//! [`PieceRunner`] thread feeding a program piece by piece. The probe input is driven from
//! the simulated Z position, like a touch plate at a fixed height.

use super::machine_task::MachineCmd;
use super::tests::Rig;
use crate::gcode::NUM_AXES;
use crate::machine::api::Mode;
use crate::machine::job;
use crate::machine::probing::{first_piece, PieceRunner, ProbingSource, RunnerEnd};
use crate::rt::prelude::*;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

/// Digital input channel of the probe in tests/fixtures/sim-fast.toml (after the e-stop).
const PROBE_DI: usize = 1;

struct Outcome {
    status: CommandStatus,
    runner: RunnerEnd,
    /// Probe results published, in order: (tripped, probed Z).
    probes: Vec<(bool, f64)>,
    /// Z at the end.
    z: f64,
    x: f64,
    start_z: f64,
}

/// A live job (job 1) started on the rig: the real piece runner's thread and the `Run`.
pub(super) struct Live {
    pub(super) h: CommandHandle,
    pub(super) cancel: Arc<AtomicBool>,
    pub(super) thread: std::thread::JoinHandle<RunnerEnd>,
    pub(super) start: [f64; NUM_AXES],
}

/// Starts `text` as job 1, piece by piece, as the daemon starts a probing or M66 job.
pub(super) fn start_live(r: &mut Rig, name: &str, text: &str) -> Live {
    let cfg = crate::config::load(
        &std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/sim-fast.toml"),
    )
    .expect("config");
    let start = r.position();
    let src = ProbingSource {
        name: name.into(),
        text: text.into(),
        opts: job::interp_options(&cfg),
    };
    let first = first_piece(&src, &r.motion_cfg, start).expect("first piece");
    let items = first.plan.items.len() as u64;
    let cancel = Arc::new(AtomicBool::new(false));
    let runner = PieceRunner {
        queue: r.queue.clone(),
        machine: r.built_machine.clone(),
        snapshot: r.rt.reader(super::ports::SNAPSHOT).expect("reader"),
        cfg: r.motion_cfg.clone(),
        job: 1,
        name: src.name.clone(),
        cancel: cancel.clone(),
        seen_probe_seq: 0,
        servo: r.rt.threads()[0].clone(),
        messages: Arc::default(),
        parameters: Arc::default(),
        primer: crate::machine::feeder::Primer::none(),
    };
    let thread = std::thread::spawn(move || runner.run(first));
    let h = r
        .built_machine
        .send(MachineCmd::Run {
            job: 1,
            items,
            manual: false,
        })
        .expect("queue");
    Live {
        h,
        cancel,
        thread,
        start,
    }
}

/// Runs `text` as job 1 with a surface at `surface_z` (the probe is active while the actual
/// Z is at or below it; `None`: never).
fn run_probing(r: &mut Rig, text: &str, surface_z: Option<f64>) -> Outcome {
    let Live {
        h,
        cancel,
        thread,
        start,
    } = start_live(r, "probe.ngc", text);
    let io = r.sim_io[0].clone().expect("sim io");
    let mut probes = Vec::new();
    let mut seq = 0;
    for _ in 0..400_000 {
        let z = r.feedback(2).actual;
        io.set_digital_input(PROBE_DI, surface_z.is_some_and(|s| z <= s))
            .expect("input");
        r.rt.run_cycles(1);
        let snap = r.snap.latest().expect("snapshot");
        if snap.probe.seq != seq {
            seq = snap.probe.seq;
            probes.push((snap.probe.tripped, snap.probe.probed_mm[2]));
        }
        if !matches!(h.status(), CommandStatus::Pending | CommandStatus::Accepted) {
            break;
        }
        if r.sp
            .latest()
            .is_some_and(|sp| sp.state == crate::motion::InterpState::Done)
        {
            // Waiting for the runner between pieces: give it time to run.
            std::thread::yield_now();
        }
    }
    cancel.store(true, std::sync::atomic::Ordering::Release);
    let runner = thread.join().expect("runner");
    Outcome {
        status: h.status(),
        runner,
        probes,
        z: r.feedback(2).actual,
        x: r.feedback(0).actual,
        start_z: start[2],
    }
}

#[test]
fn a_probing_job_stops_at_the_surface_and_goes_on_with_the_measured_values() {
    let mut r = Rig::new();
    r.ready();
    // Z homes at 0. The plate is at Z-10.
    let text = "G21 G90\nF300\nG38.2 Z-30\nG0 Z[#5063 + 3]\n#<first> = #5063\n\
                G38.3 X280\nG1 X[270 + 5 * #5070] Z[#<first> + 1] F600\nM2\n";
    let out = run_probing(&mut r, text, Some(-10.0));
    assert_eq!(out.status, CommandStatus::Done, "{:?}", out.runner);
    assert_eq!(out.runner, RunnerEnd::Done);
    assert_eq!(out.probes.len(), 2, "{:?}", out.probes);
    let (tripped, probed_z) = out.probes[0];
    assert!(tripped);
    assert!(
        (-10.05..=-10.0).contains(&probed_z),
        "probed Z {probed_z}: the actual position when the input changed"
    );
    // The second probe (G38.3 along X, above the plate) never touches: #5070 = 0.
    assert!(!out.probes[1].0);
    assert!((out.x - 270.0).abs() < 0.01, "X {}", out.x);
    assert!(
        (out.z - (probed_z + 1.0)).abs() < 0.01,
        "Z {} vs probed {probed_z} + 1",
        out.z
    );
    assert_eq!(r.mode(), Mode::Idle);
}

#[test]
fn g38_2_without_contact_ends_the_job_with_an_error_but_leaves_the_drives_on() {
    let mut r = Rig::new();
    r.ready();
    let out = run_probing(&mut r, "G21 G90 F600\nG38.2 Z-5\nG0 Z0\nM2\n", None);
    assert_eq!(
        out.status,
        CommandStatus::Failed("stopped by a program error")
    );
    assert!((out.z + 5.0).abs() < 0.01, "ran to the end: {}", out.z);
    assert_eq!(
        r.mode(),
        Mode::Idle,
        "a program error is not a machine fault"
    );
    assert!(r.feedback(2).state.is_operational());
    assert!(out.probes.is_empty());
}

#[test]
fn a_probe_already_touching_is_refused_before_it_moves() {
    let mut r = Rig::new();
    r.ready();
    let out = run_probing(&mut r, "G21 G90 F600\nG38.2 Z-5\nM2\n", Some(1.0));
    assert_eq!(
        out.status,
        CommandStatus::Failed("stopped by a program error")
    );
    assert!(
        (out.z - out.start_z).abs() < 1e-6,
        "moved: {} from {}",
        out.z,
        out.start_z
    );
}

#[test]
fn an_error_that_needs_the_measurement_fails_the_job_at_the_probe() {
    let mut r = Rig::new();
    r.ready();
    // G38.3 without contact: #5070 = 0, and the next line divides by it.
    let out = run_probing(&mut r, "G21 G90 F600\nG38.3 Z-5\nG1 Z[1/#5070]\nM2\n", None);
    let RunnerEnd::Failed(msg) = &out.runner else {
        panic!("{:?}", out.runner)
    };
    assert!(msg.starts_with("probe.ngc:3:"), "{msg}");
    // The machine waits at the probe, still running the job: the daemon aborts it then.
    assert_eq!(r.mode(), Mode::Running);
    assert!(r.snap.latest().expect("snapshot").probe.waiting);
}
