//! M66 in a live job on the stepped runtime (issue 11): the machine and interpolator tasks
//! with the real piece runner's thread. The machine runs to the M66 and holds there, waits
//! for the simulated input or the timeout in servo cycles (simulated time), publishes what it
//! read, and the program goes on with #5399 set: the branch it takes shows in where it ends.

use super::machine_task::MachineCmd;
use super::probe_tests::{start_live, Live};
use super::tests::Rig;
use super::MachineSnapshot;
use crate::machine::api::Mode;
use crate::machine::probing::RunnerEnd;
use crate::rt::prelude::*;
use std::sync::atomic::Ordering;

/// Digital input of the M66s below (`probe` in tests/fixtures/sim-fast.toml: these jobs do
/// not probe, and the rig has no simulated plate, so only the test drives it; the simulated
/// spindle drives `spindle_at_speed`).
const DI: usize = 1;

/// Cycles at most for a job (hang guard; a job below needs a few thousand).
const GUARD_CYCLES: u32 = 400_000;

/// Times out (`#5399 LT 0`: X20) or is satisfied (X30 + #5399).
const BRANCH: &str = "G21 G90\nG0 X10 Y10\nM66 P1 L3 Q0.5\n\
    O100 if [#5399 LT 0]\n  G0 X20\nO100 else\n  G0 X[30 + #5399]\nO100 endif\nM2\n";

struct Outcome {
    status: CommandStatus,
    runner: RunnerEnd,
    /// M66 results published, in order: (servo cycle, line, #5399).
    answers: Vec<(u64, u32, f64)>,
    /// Servo cycles in which the machine waited for the input.
    pending_cycles: u64,
    x: f64,
}

/// Runs `text` as job 1; `drive` sees each cycle's snapshot and sets the inputs (it may
/// also send commands). Every interleaving of the runner thread with the stepped cycles is
/// legal: the machine holds at the M66 however long the runner takes.
fn run(r: &mut Rig, text: &str, mut drive: impl FnMut(&mut Rig, &MachineSnapshot)) -> Outcome {
    let io = r.sim_io[0].clone().expect("sim io");
    io.set_digital_input(DI, false).expect("input");
    let Live {
        h, cancel, thread, ..
    } = start_live(r, "m66.ngc", text);
    let (mut answers, mut seq, mut pending_cycles) = (Vec::new(), 0, 0);
    for cycle in 0..u64::from(GUARD_CYCLES) {
        r.rt.run_cycles(1);
        let snap = r.snap.latest().expect("snapshot");
        if snap.wait.seq != seq {
            seq = snap.wait.seq;
            answers.push((cycle, snap.wait.line, snap.wait.value));
        }
        pending_cycles += u64::from(snap.wait.pending);
        if !matches!(h.status(), CommandStatus::Pending | CommandStatus::Accepted) {
            break;
        }
        drive(r, &snap);
        if snap.wait.waiting {
            // Held after the M66 for the next piece: give the runner time to read it.
            std::thread::yield_now();
        }
    }
    cancel.store(true, Ordering::Release);
    Outcome {
        status: h.status(),
        runner: thread.join().expect("runner"),
        answers,
        pending_cycles,
        x: r.feedback(0).actual,
    }
}

#[test]
fn a_timed_out_m66_sets_5399_to_minus_one_after_the_timeout_in_machine_time() {
    let mut r = Rig::new();
    r.ready();
    let out = run(&mut r, BRANCH, |_, _| {});
    assert_eq!(out.status, CommandStatus::Done, "{:?}", out.runner);
    assert_eq!(out.runner, RunnerEnd::Done);
    assert_eq!(out.answers.len(), 1, "{:?}", out.answers);
    assert_eq!((out.answers[0].1, out.answers[0].2), (3, -1.0));
    // Q0.5 at 1 kHz: 500 servo cycles, whatever the host's load.
    assert!(
        (500..=502).contains(&out.pending_cycles),
        "waited {} cycles",
        out.pending_cycles
    );
    assert!((out.x - 20.0).abs() < 1e-3, "timeout branch: X {}", out.x);
    assert_eq!(r.mode(), Mode::Idle);
}

#[test]
fn a_satisfied_m66_sets_5399_to_the_input_and_the_program_takes_the_other_branch() {
    let mut r = Rig::new();
    r.ready();
    let io = r.sim_io[0].clone().expect("sim io");
    // The input goes high 100 cycles into the wait, well before the 500-cycle timeout.
    let mut waited = 0;
    let out = run(&mut r, BRANCH, |_, s| {
        waited += u32::from(s.wait.pending);
        if waited == 100 {
            io.set_digital_input(DI, true).expect("input");
        }
    });
    assert_eq!(out.status, CommandStatus::Done, "{:?}", out.runner);
    assert_eq!(out.answers.len(), 1, "{:?}", out.answers);
    assert_eq!(out.answers[0].2, 1.0);
    assert!(
        (100..=103).contains(&out.pending_cycles),
        "{}",
        out.pending_cycles
    );
    assert!((out.x - 31.0).abs() < 1e-3, "X[30 + #5399]: X {}", out.x);
}

#[test]
fn edges_low_levels_and_immediate_reads_answer_as_linuxcnc_does() {
    let mut r = Rig::new();
    r.ready();
    let io = r.sim_io[0].clone().expect("sim io");
    // L1 (rise): the input is toggled low→high after a while; L4 (low) while it is high
    // times out; L0 reads at once (high: 1). Each answer moves X by its own amount.
    let text = "G21 G90\nG0 X0 Y10\n\
        M66 P1 L1 Q2\nG0 X[1 + #5399]\n\
        M66 P1 L4 Q0.2\nG0 Y[20 + #5399]\n\
        M66 P1 L0\nG0 X[10 + #5399]\nM2\n";
    let mut waits = 0;
    let out = run(&mut r, text, |_, s| {
        if s.wait.pending && s.wait.line == 3 {
            waits += 1;
            io.set_digital_input(DI, waits > 50).expect("input");
        }
    });
    assert_eq!(out.status, CommandStatus::Done, "{:?}", out.runner);
    let answers: Vec<(u32, f64)> = out.answers.iter().map(|a| (a.1, a.2)).collect();
    assert_eq!(answers, [(3, 1.0), (5, -1.0), (7, 1.0)]);
    assert!((out.x - 11.0).abs() < 1e-3, "X {}", out.x);
    assert!((r.feedback(1).actual - 19.0).abs() < 1e-3);
}

#[test]
fn an_abort_while_the_machine_waits_at_an_m66_ends_the_job_cleanly() {
    let mut r = Rig::new();
    r.ready();
    let mut sent = None;
    let out = run(&mut r, BRANCH, |r, s| {
        if s.wait.pending && sent.is_none() {
            sent = Some(r.built_machine.send(MachineCmd::Abort).expect("abort"));
        }
    });
    assert!(sent.is_some());
    assert!(
        matches!(out.status, CommandStatus::Failed(_)),
        "{:?}",
        out.status
    );
    assert!(out.answers.is_empty(), "no answer after an abort");
    assert!((out.x - 10.0).abs() < 1e-3, "held at the M66: X {}", out.x);
    r.rt.run_cycles(10);
    let snap = r.snap.latest().expect("snapshot");
    assert!(!snap.wait.pending && !snap.wait.waiting);
    assert_eq!(r.mode(), Mode::Idle);
}

#[test]
fn an_estop_while_the_machine_waits_at_an_m66_ends_the_job() {
    let mut r = Rig::new();
    r.ready();
    let out = run(&mut r, BRANCH, |r, s| {
        if s.wait.pending {
            r.estop_request.fetch_add(1, Ordering::AcqRel);
        }
    });
    assert!(
        matches!(out.status, CommandStatus::Failed(_)),
        "{:?}",
        out.status
    );
    assert!(out.answers.is_empty());
    r.rt.run_cycles(10);
    assert!(!r.snap.latest().expect("snapshot").wait.pending);
    assert_eq!(r.mode(), Mode::Estop);
}
