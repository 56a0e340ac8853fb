//! Zero allocation in the cell's realtime steps: the servo chain (sensor, robot, PID,
//! effector, simulated hardware), the selection state machine (the script, the default) and
//! the camera's detection,
//! counted by the counting allocator over whole pick-and-place runs on simulated time.
#![allow(clippy::unwrap_used)]

mod cell_support;
mod counting_alloc;

use cell_support::{Rig, SECOND};
use hytask::cell::config::CellConfig;
use hytask::cell::selection::SelectionCmd;
use hytask::rt::prelude::*;

#[test]
fn no_allocation_in_any_step_of_a_sorting_run() {
    let mut rig = Rig::start(&CellConfig::with_seed(42));
    rig.until_homed();
    // A first run exercises every path once (first emits pick up their subscribers).
    let warm = rig.cell_selection.send(SelectionCmd::Run(1)).unwrap();
    rig.run_until(20 * SECOND, |_| warm.status().is_final());
    assert_eq!(warm.status(), CommandStatus::Done);

    let before = counting_alloc::in_rt_steps();
    let run = rig.cell_selection.send(SelectionCmd::Run(3)).unwrap();
    let mut cycles = 0;
    while !run.status().is_final() && cycles < 60 * SECOND {
        rig.rt.run_cycles(100);
        cycles += 100;
    }
    assert_eq!(run.status(), CommandStatus::Done);
    let n = counting_alloc::in_rt_steps() - before;
    assert_eq!(
        n,
        0,
        "allocations inside realtime steps over 3 runs ({cycles} servo cycles); first at:\n{}",
        counting_alloc::first_rt_backtrace().unwrap_or_default()
    );
}
