//! Proves that the servo cycle allocates nothing through spindle-synchronised motion: the
//! machine's realtime tasks (io, machine, interpolator with the simulated spindle and the
//! spindle-position follower, axes, monitor) run on the stepped runtime on this thread,
//! under a counting global allocator, through a threading job (the index wait, a G33 move
//! following the spindle, a G33.1 tap with its spindle reversal and its way out) and
//! through an abort in the middle of a thread (the follower brakes on the line).
#![allow(clippy::unwrap_used)]

use hytask::gcode::canon::SpindleDir;
use hytask::gcode::{CanonCmd, NUM_AXES};
use hytask::machine::servo::machine_task::MachineCmd;
use hytask::machine::servo::{ports, Setpoints};
use hytask::rt::prelude::*;

mod counting_alloc;

use counting_alloc::so_far as allocations;

mod machine_rig;
use machine_rig::until_done;

/// Spindle on at 1000 rpm, then `moves` locked to it.
fn job(moves: &[CanonCmd]) -> Vec<CanonCmd> {
    let mut v = vec![
        CanonCmd::SetSpindleSpeed(1000.0),
        CanonCmd::StartSpindle(SpindleDir::Clockwise),
    ];
    v.extend_from_slice(moves);
    v.push(CanonCmd::StopSpindle);
    v
}

#[test]
fn a_threading_job_and_an_abort_in_mid_thread_allocate_nothing() {
    let path =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/sim-fast.toml");
    let mut h = machine_rig::homed(&hytask::config::load(&path).unwrap());
    let mut sp: DataReader<Setpoints> = h.rt.reader(ports::SETPOINTS).unwrap();
    let s = h.start;
    let at = |dz: f64| -> [f64; NUM_AXES] {
        let mut p = s;
        p[2] += dz;
        p
    };

    // Window 1: a G33 thread, back up, a G33.1 tap, to the end of the job.
    let run = h.queue_job(
        1,
        s,
        &job(&[
            CanonCmd::StartSpeedFeedSync { pitch: 1.5 },
            CanonCmd::StraightFeed(at(-20.0)),
            CanonCmd::StopSpeedFeedSync,
            CanonCmd::StraightTraverse(at(0.0)),
            CanonCmd::StartSpeedFeedSync { pitch: 1.0 },
            CanonCmd::RigidTap { end: at(-10.0) },
            CanonCmd::StopSpeedFeedSync,
        ]),
    );
    let running = h.machine.send(run).unwrap();
    h.rt.run_cycles(50);
    let before = allocations();
    let (mut reversed, mut z_min) = (false, 0.0f64);
    for _ in 0..20_000 {
        h.rt.run_cycles(1);
        let p = sp.latest().unwrap();
        reversed |= p.spindle_reversed;
        z_min = z_min.min(p.pose_mm[2] - s[2]);
        if running.status() == CommandStatus::Done {
            break;
        }
    }
    let window1 = allocations() - before;
    let mut snap: DataReader<hytask::machine::servo::MachineSnapshot> =
        h.rt.reader(ports::SNAPSHOT).unwrap();
    assert_eq!(
        running.status(),
        CommandStatus::Done,
        "{:?}",
        snap.latest().unwrap().last_trip
    );
    assert!(reversed, "the tap never reversed the spindle");
    assert!((z_min + 20.0).abs() < 1e-6, "deepest {z_min}");

    // Window 2: a thread aborted in its middle.
    let run = h.queue_job(
        2,
        s,
        &job(&[
            CanonCmd::StartSpeedFeedSync { pitch: 1.5 },
            CanonCmd::StraightFeed(at(-40.0)),
            CanonCmd::StopSpeedFeedSync,
        ]),
    );
    let running = h.machine.send(run).unwrap();
    for _ in 0..20_000 {
        h.rt.run_cycles(1);
        if h.fb[2].latest().unwrap().actual < s[2] - 10.0 {
            break;
        }
    }
    let before = allocations();
    let abort = h.machine.send(MachineCmd::Abort).unwrap();
    until_done(&mut h.rt, &abort, 5000);
    h.rt.run_cycles(100);
    let window2 = allocations() - before;
    assert_eq!(running.status(), CommandStatus::Failed("aborted"));
    let z = h.fb[2].latest().unwrap().actual - s[2];
    assert!((-39.0..-10.0).contains(&z), "stopped at {z}");

    assert_eq!(
        (window1, window2),
        (0, 0),
        "allocations in the servo cycles"
    );
}
