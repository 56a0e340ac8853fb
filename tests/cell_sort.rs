//! The cell end to end on simulated time: twenty objects of a seeded sequence are sorted
//! into the right containers, run by run, through the selection task's `run` operation.
#![allow(clippy::unwrap_used)]

mod cell_support;

use cell_support::{container_counts, expected_counts, Rig, SECOND};
use hytask::cell::config::CellConfig;
use hytask::cell::selection::{SelectionCmd, SelectionKind, SelectionState};
use hytask::rt::prelude::*;

#[test]
fn twenty_runs_sort_the_seeded_sequence() {
    for seed in [42, 7] {
        let mut rig = Rig::start(&CellConfig::with_seed(seed));
        rig.until_homed();
        let run = rig.cell_selection.send(SelectionCmd::Run(20)).unwrap();
        let cycles = rig.run_until(200 * SECOND, |_| run.status().is_final());
        assert_eq!(
            run.status(),
            CommandStatus::Done,
            "seed {seed}: after {cycles} cycles, {:?}",
            rig.state()
        );
        let (counts, runs) = container_counts(&mut rig.done);
        let want = expected_counts(seed, 20);
        assert_eq!(counts, want, "seed {seed}: operation_n_done per container");
        assert_eq!(runs.len(), 20);
        assert_eq!(
            runs.iter().map(|r| r.run).collect::<Vec<_>>(),
            (1..=20).collect::<Vec<_>>()
        );
        let t = rig.tally();
        assert_eq!(
            t.in_container, want,
            "seed {seed}: objects in the containers"
        );
        assert_eq!((t.missorted, t.on_floor), (0, 0), "seed {seed}");
        let s = rig.state();
        assert_eq!(
            (s.state, s.runs_done, s.error),
            (SelectionState::Homed, 20, None)
        );
        // Every run took a plausible time (pick to release), not zero and not a stall.
        assert!(
            runs.iter().all(|r| (300..5_000).contains(&r.cycle_ms)),
            "{runs:?}"
        );
    }
}

#[test]
fn run_is_rejected_while_busy_and_with_zero() {
    let mut rig = Rig::start(&CellConfig::with_seed(1));
    rig.until_homed();
    let zero = rig.cell_selection.send(SelectionCmd::Run(0)).unwrap();
    rig.rt.run_cycles(20);
    assert!(matches!(
        zero.status(),
        CommandStatus::Rejected(RejectReason::BadParameters(_))
    ));
    let first = rig.cell_selection.send(SelectionCmd::Run(2)).unwrap();
    rig.rt.run_cycles(20);
    let second = rig.cell_selection.send(SelectionCmd::Run(1)).unwrap();
    rig.rt.run_cycles(20);
    assert_eq!(second.status(), CommandStatus::Rejected(RejectReason::Busy));
    rig.run_until(30 * SECOND, |_| first.status().is_final());
    assert_eq!(first.status(), CommandStatus::Done);
}

/// The script selection (the default) and the Rust reference sort the same seeded sequence
/// into the same containers, run by run.
#[test]
fn script_and_rust_selections_sort_the_same_seed_identically() {
    let sorted = |kind: SelectionKind| {
        let mut cfg = CellConfig::with_seed(13);
        cfg.selection.kind = kind;
        let mut rig = Rig::start(&cfg);
        rig.until_homed();
        let run = rig.cell_selection.send(SelectionCmd::Run(12)).unwrap();
        rig.run_until(200 * SECOND, |_| run.status().is_final());
        assert_eq!(run.status(), CommandStatus::Done, "{kind:?}");
        let (counts, runs) = container_counts(&mut rig.done);
        let containers: Vec<_> = runs.iter().map(|r| r.container).collect();
        (counts, containers, rig.tally().in_container)
    };
    let script = sorted(SelectionKind::Script);
    let rust = sorted(SelectionKind::Rust);
    assert_eq!(script, rust);
    assert_eq!(script.0, expected_counts(13, 12));
    assert!(
        script.0.iter().all(|&n| n > 0),
        "every container used: {:?}",
        script.0
    );
}
