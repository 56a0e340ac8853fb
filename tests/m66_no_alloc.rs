//! An M66 in a live job allocates nothing on the realtime path (issue 11): the stepped
//! machine (io, machine, interpolator, axes, monitor) under a counting global allocator,
//! through the move to the M66, the wait for the input, its rising edge, the answer and the
//! hold, and then the next piece (interpreted off the realtime path with #5399 set) to the
//! end of the job. The same discipline for probing is in `tests/machine_no_alloc.rs`.
#![allow(clippy::unwrap_used)]

use hytask::machine::probing::{first_piece, ProbingSource};
use hytask::machine::servo::machine_task::MachineCmd;
use hytask::machine::servo::{ports, MachineSnapshot, QueueItem};
use hytask::rt::prelude::*;

mod counting_alloc;

use counting_alloc::so_far as allocations;

mod machine_rig;
use machine_rig::{queue_next_piece, until_done, Homed};

/// The `probe` input of tests/fixtures/sim-fast.toml (nothing else drives it on this rig).
const DI: usize = 1;

#[test]
fn an_m66_its_answer_and_the_next_piece_allocate_nothing() {
    let path =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/sim-fast.toml");
    let Homed {
        mut rt,
        machine,
        queue,
        motion_cfg,
        sim_io,
        mut fb,
        start,
    } = machine_rig::homed(&hytask::config::load(&path).unwrap());
    let mut snap: DataReader<MachineSnapshot> = rt.reader(ports::SNAPSHOT).unwrap();
    let src = ProbingSource {
        name: "w.ngc".into(),
        text: "G21 G91\nG1 X-5 F3000\nM66 P1 L1 Q100\nG1 X[-10 * #5399]\nM2\n".into(),
        opts: hytask::gcode::InterpOptions::default(),
    };
    let first = first_piece(&src, &motion_cfg, start).unwrap();
    let mut session = first.session;
    for &item in &first.plan.items {
        queue.try_push(QueueItem { job: 1, item }).unwrap();
    }
    let run = machine
        .send(MachineCmd::Run {
            job: 1,
            items: first.plan.items.len() as u64,
            manual: false,
        })
        .unwrap();
    let io = sim_io[0].clone().unwrap();
    io.set_digital_input(DI, false).unwrap();

    // Window 1: the move, the wait (the input rises 100 cycles into it), the answer, the hold.
    let before = allocations();
    let (mut cycles, mut pending) = (0, 0);
    while !snap.latest().unwrap().wait.waiting {
        rt.run_cycles(1);
        pending += u32::from(snap.latest().unwrap().wait.pending);
        if pending == 100 {
            io.set_digital_input(DI, true).unwrap();
        }
        cycles += 1;
        assert!(cycles < 20_000, "the M66 never answered");
    }
    let window1 = allocations() - before;

    // Off the realtime path: #5399 = the answer, the next piece planned from the M66.
    let w = snap.latest().unwrap().wait;
    assert_eq!((w.line, w.value), (3, 1.0));
    session.wait_result(w.value);
    let (canon, _) = session.next_piece().unwrap();
    let state = first.plan.end_state.clone();
    let next = queue_next_piece(&queue, &motion_cfg, &canon, w.stopped_mm, state);

    // Window 2: continue, and the next piece to the end of the job.
    let before = allocations();
    let cont = machine.send(next).unwrap();
    until_done(&mut rt, &run, 20_000);
    let window2 = allocations() - before;

    assert_eq!(cont.status(), CommandStatus::Done);
    let x = fb[0].latest().unwrap().actual;
    assert!(
        (x - (start[0] - 15.0)).abs() < 0.01,
        "X {x}: -5, then -10 * #5399"
    );
    assert_eq!(
        (window1, window2),
        (0, 0),
        "allocations in the M66's cycles"
    );
}
