//! Proves that the machine's own realtime tasks (io, machine, interpolator, axis.X/Y/Z,
//! monitor) allocate nothing in steady state: the whole servo cycle runs on the stepped
//! runtime on this thread, under a counting global allocator, through motion, a feed hold,
//! a resume, aux commands and an e-stop; through an abort and a machine off with the spindle
//! and coolant on (outputs to their safe state); through a probe move, its trip, the stop and
//! the next piece of the program; and through a soft-limit trip (which the daemon cannot
//! reach: its planner refuses such moves, so a plan made with wider limits is queued here).
//! The same windows on the daemon's real servo thread are in `tests/daemon_no_alloc.rs`.
#![allow(clippy::unwrap_used)]

use hytask::gcode::{CanonCmd, SourceLoc, NUM_AXES};
use hytask::machine::servo::machine_task::MachineCmd;
use hytask::machine::servo::{ports, QueueItem};
use hytask::rt::prelude::*;
use std::sync::Arc;

mod counting_alloc;

use counting_alloc::so_far as allocations;

mod machine_rig;
use machine_rig::{queue_next_piece, until_done, Homed};

/// The simulated mill (fast homing), homed and idle.
fn homed() -> Homed {
    let path =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/sim-fast.toml");
    machine_rig::homed(&hytask::config::load(&path).unwrap())
}

#[test]
fn the_servo_cycle_of_the_machine_allocates_nothing() {
    let h = homed();
    // A job with spindle and coolant (aux items) and a long feed move, queued up front.
    let run = queue_cutting_job(&h, 1, h.start, [100.0, 150.0, -30.0]);
    let Homed {
        mut rt,
        machine,
        sim_io,
        mut fb,
        start,
        ..
    } = h;
    let _running = machine.send(run).unwrap();
    rt.run_cycles(50); // warm-up: the first cycles of a job touch everything once
    let estop = sim_io[0].clone().unwrap();

    let before = allocations();
    rt.run_cycles(1500); // spindle spin-up barrier, then motion
    let pause = machine.send(MachineCmd::Pause).unwrap();
    rt.run_cycles(500);
    let resume = machine.send(MachineCmd::Resume).unwrap();
    rt.run_cycles(500);
    estop.set_digital_input(0, true).unwrap();
    rt.run_cycles(500);
    let during = allocations() - before;

    assert_eq!(pause.status(), CommandStatus::Done);
    assert_eq!(resume.status(), CommandStatus::Done);
    assert!(
        fb[0].latest().unwrap().actual < start[0] - 1.0,
        "the machine moved"
    );
    assert_eq!(during, 0, "{during} allocations in 3000 servo cycles");
}

#[test]
fn a_probe_move_its_trip_stop_and_the_next_piece_allocate_nothing() {
    let Homed {
        mut rt,
        machine,
        queue,
        motion_cfg,
        sim_io,
        mut fb,
        start,
    } = homed();
    let mut snap: DataReader<hytask::machine::servo::MachineSnapshot> =
        rt.reader(ports::SNAPSHOT).unwrap();
    let text = "G21 G90 F600\nG38.2 Z-30\nG1 X[#5061 - 20] F3000\nM2\n";
    let mut opts = hytask::gcode::InterpOptions::default();
    let mut p = [0.0; 6];
    p.copy_from_slice(&start[..6]);
    opts.initial_position = Some(p);
    let mut session = hytask::gcode::Session::open_str("p.ngc", text, &opts).unwrap();
    let (canon, _) = session.next_piece().unwrap();
    let first = hytask::motion::plan_from(&canon, &motion_cfg, start).unwrap();
    for &item in &first.items {
        queue.try_push(QueueItem { job: 1, item }).unwrap();
    }
    let run = machine
        .send(MachineCmd::Run {
            job: 1,
            items: first.items.len() as u64,
            manual: false,
        })
        .unwrap();
    rt.run_cycles(50);
    let probe = sim_io[0].clone().unwrap();
    let plate = start[2] - 5.0;

    // Window 1: the probe move, the trip inside the servo cycle, the stop, the end marker.
    let before = allocations();
    let mut waited = 0;
    while !snap.latest().unwrap().probe.waiting {
        let z = fb[2].latest().unwrap().actual;
        probe.set_digital_input(1, z <= plate).unwrap();
        rt.run_cycles(1);
        waited += 1;
        assert!(waited < 20_000, "the probe never ended");
    }
    let window1 = allocations() - before;

    // Off the realtime path: the interpreter goes on with the result, the next piece is
    // planned from where the machine stopped (this allocates, as planning does).
    let s = snap.latest().unwrap().probe;
    assert!(s.tripped);
    let r = hytask::gcode::ProbeResult {
        tripped: true,
        probed: first.end_state.program_xyzabc(&s.probed_mm),
        stopped: first.end_state.program_xyzabc(&s.stopped_mm),
    };
    session.probe_result(&r);
    let (canon, _) = session.next_piece().unwrap();
    let state = first.end_state.clone();
    let next = queue_next_piece(&queue, &motion_cfg, &canon, s.stopped_mm, state);

    // Window 2: continue, and the next piece to the end of the job.
    let before = allocations();
    let cont = machine.send(next).unwrap();
    until_done(&mut rt, &run, 20_000);
    let window2 = allocations() - before;

    assert_eq!(cont.status(), CommandStatus::Done);
    assert!((fb[0].latest().unwrap().actual - (start[0] - 20.0)).abs() < 0.01);
    assert_eq!(
        (window1, window2),
        (0, 0),
        "allocations in the probing servo cycles"
    );
}

/// Queues job `job`: M3 S8000, M8, then a feed to `target`; returns its `run` command.
fn queue_cutting_job(h: &Homed, job: u32, from: [f64; NUM_AXES], target: [f64; 3]) -> MachineCmd {
    let mut end = from;
    end[..3].copy_from_slice(&target);
    h.queue_job(job, from, &cutting(end))
}

/// Spindle and coolant on (aux items), then one long feed move to `end`.
fn cutting(end: [f64; NUM_AXES]) -> [CanonCmd; 5] {
    [
        CanonCmd::SetSpindleSpeed(8000.0),
        CanonCmd::StartSpindle(hytask::gcode::canon::SpindleDir::Clockwise),
        CanonCmd::FloodOn,
        CanonCmd::SetFeedRate(3000.0),
        CanonCmd::StraightFeed(end),
    ]
}

#[test]
fn an_abort_and_a_machine_off_with_spindle_and_coolant_on_allocate_nothing() {
    let mut h = homed();
    let sim_io = h.sim_io[0].clone().unwrap();
    let spindle_and_flood = |io: &hytask_hal::sim::SimIoHandle| {
        (io.digital_output(0).unwrap(), io.digital_output(2).unwrap())
    };

    // Window 1: a job cutting (spindle at speed, coolant on), aborted, to rest.
    let run = queue_cutting_job(&h, 1, h.start, [100.0, 150.0, -30.0]);
    let running = h.machine.send(run).unwrap();
    h.rt.run_cycles(1500);
    assert_eq!(spindle_and_flood(&sim_io), (true, true));
    let before = allocations();
    let abort = h.machine.send(MachineCmd::Abort).unwrap();
    until_done(&mut h.rt, &abort, 5000);
    h.rt.run_cycles(100);
    let window1 = allocations() - before;
    assert_eq!(running.status(), CommandStatus::Failed("aborted"));
    assert_eq!(spindle_and_flood(&sim_io), (false, false));

    // Window 2: the next job cutting, then machine off: stop, drives off, outputs safe.
    let mut from = h.start;
    for (i, f) in from.iter_mut().take(3).enumerate() {
        *f = h.fb[i].latest().unwrap().actual;
    }
    let run = queue_cutting_job(&h, 2, from, [50.0, 100.0, -40.0]);
    let _running = h.machine.send(run).unwrap();
    h.rt.run_cycles(1500);
    assert_eq!(spindle_and_flood(&sim_io), (true, true));
    let before = allocations();
    let off = h.machine.send(MachineCmd::Off).unwrap();
    until_done(&mut h.rt, &off, 5000);
    h.rt.run_cycles(100);
    let window2 = allocations() - before;
    assert_eq!(spindle_and_flood(&sim_io), (false, false));

    assert_eq!(
        (window1, window2),
        (0, 0),
        "allocations in the servo cycles of an abort and a machine off"
    );
}

#[test]
fn a_soft_limit_trip_and_its_stop_allocate_nothing() {
    let Homed {
        mut rt,
        machine,
        queue,
        mut motion_cfg,
        sim_io: _,
        fb: _,
        start,
    } = homed();
    let mut snap: DataReader<hytask::machine::servo::MachineSnapshot> =
        rt.reader(ports::SNAPSHOT).unwrap();
    // X's soft limit is 300; the planner is told 400, the monitor still guards 300. The
    // limit switch sits beyond 305: the soft limit trips first.
    let max_x = motion_cfg.axes[0].max_mm;
    motion_cfg.axes[0].max_mm = 400.0;
    let mut end = start;
    end[0] = max_x + 3.0;
    let loc = SourceLoc {
        file: Arc::from("t"),
        line: 1,
        col: 1,
    };
    let plan = hytask::motion::plan_straight_feed(start, end, 600.0, loc, &motion_cfg).unwrap();
    for &item in &plan.items {
        queue.try_push(QueueItem { job: 1, item }).unwrap();
    }
    let run = machine
        .send(MachineCmd::Run {
            job: 1,
            items: plan.items.len() as u64,
            manual: false,
        })
        .unwrap();
    let before = allocations();
    let mut cycles = 0;
    loop {
        rt.run_cycles(1);
        cycles += 1;
        let s = snap.latest().unwrap();
        if s.mode == hytask::machine::api::Mode::Fault {
            break;
        }
        assert!(cycles < 20_000, "no soft-limit trip: {:?}", s.mode);
    }
    rt.run_cycles(500); // the stop after the trip
    let during = allocations() - before;
    let trip = snap.latest().unwrap().last_trip;
    assert!(
        matches!(
            trip,
            Some(hytask::machine::safety::Trip::SoftLimit { axis: 0, .. })
        ),
        "{trip:?}"
    );
    assert!(
        matches!(run.status(), CommandStatus::Failed(_)),
        "{:?}",
        run.status()
    );
    assert_eq!(
        during, 0,
        "{during} allocations in {cycles} servo cycles and the stop"
    );
}
