//! Proves that the machine's own realtime tasks (io, machine, interpolator, axis.X/Y/Z,
//! monitor) allocate nothing in steady state: the whole servo cycle runs on the stepped
//! runtime on this thread, under a counting global allocator, through motion, a feed hold,
//! a resume, aux commands and an e-stop.
#![allow(clippy::unwrap_used)]

use hytask::gcode::{Canon, CanonCmd, SourceLoc, NUM_AXES};
use hytask::machine::runtime::{build, Built};
use hytask::machine::servo::machine_task::MachineCmd;
use hytask::machine::servo::{ports, AxisFeedback, QueueItem};
use hytask::rt::prelude::*;
use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::Arc;

struct Counting;

thread_local! {
    static ALLOCS: Cell<u64> = const { Cell::new(0) };
}

// SAFETY: forwards to the system allocator; only counts, per thread, so the harness's other
// threads do not disturb the count.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let _ = ALLOCS.try_with(|c| c.set(c.get() + 1));
        // SAFETY: same contract as ours.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        let _ = ALLOCS.try_with(|c| c.set(c.get() + 1));
        // SAFETY: same contract as ours.
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        let _ = ALLOCS.try_with(|c| c.set(c.get() + 1));
        // SAFETY: same contract as ours.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

fn allocations() -> u64 {
    ALLOCS.with(Cell::get)
}

fn until_done(rt: &mut hytask::rt::deploy::SteppedRuntime, h: &CommandHandle, max: u64) {
    for _ in 0..max {
        rt.run_cycles(1);
        if h.status() == CommandStatus::Done {
            return;
        }
    }
    panic!("not done: {:?}", h.status());
}

#[test]
fn the_servo_cycle_of_the_machine_allocates_nothing() {
    let path =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/sim-fast.toml");
    let cfg = hytask::config::load(&path).unwrap();
    let Built {
        mut app,
        machine,
        queue,
        motion_cfg,
        sim_io,
        ..
    } = build(&cfg).unwrap();
    app.configure().unwrap();
    let mut rt = app.start_stepped(SimClock::new(0)).unwrap();
    let mut fb: Vec<DataReader<AxisFeedback>> = ['X', 'Y', 'Z']
        .iter()
        .map(|&c| rt.reader(&ports::feedback(c)).unwrap())
        .collect();
    for cmd in [
        MachineCmd::EstopReset,
        MachineCmd::On,
        MachineCmd::Home { mask: 0 },
    ] {
        let h = machine.send(cmd).unwrap();
        until_done(&mut rt, &h, 20_000);
    }

    // A job with spindle and coolant (aux items) and a long feed move, queued up front.
    let mut start = [0.0; NUM_AXES];
    for (i, s) in start.iter_mut().take(3).enumerate() {
        *s = fb[i].latest().unwrap().actual;
    }
    let mut end = start;
    end[..3].copy_from_slice(&[100.0, 150.0, -30.0]);
    let loc = SourceLoc {
        file: Arc::from("t"),
        line: 1,
        col: 1,
    };
    let c = |cmd| Canon {
        loc: loc.clone(),
        cmd,
    };
    let canon = [
        c(CanonCmd::SetSpindleSpeed(8000.0)),
        c(CanonCmd::StartSpindle(
            hytask::gcode::canon::SpindleDir::Clockwise,
        )),
        c(CanonCmd::FloodOn),
        c(CanonCmd::SetFeedRate(3000.0)),
        c(CanonCmd::StraightFeed(end)),
    ];
    let plan = hytask::motion::plan_from(&canon, &motion_cfg, start).unwrap();
    for &item in &plan.items {
        queue.try_push(QueueItem { job: 1, item }).unwrap();
    }
    let run = MachineCmd::Run {
        job: 1,
        items: plan.items.len() as u64,
        manual: false,
    };
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
