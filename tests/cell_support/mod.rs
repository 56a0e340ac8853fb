//! Shared by the cell's end-to-end tests: deploy the cell on the stepped runtime (simulated
//! time, deterministic) and drive it through its operations and events only.
#![allow(dead_code, clippy::unwrap_used)]

use hytask::cell::config::CellConfig;
use hytask::cell::deploy::{deploy, Cell};
use hytask::cell::names;
use hytask::cell::selection::{SelectionCmd, SelectionState, SelectionStatus};
use hytask::cell::types::{Container, RunDone, WorldTally};
use hytask::cell::world::object_sequence;
use hytask::rt::deploy::SteppedRuntime;
use hytask::rt::prelude::*;

/// Simulated seconds in servo cycles (1 ms).
pub const SECOND: u64 = 1000;

/// A started cell on simulated time.
pub struct Rig {
    pub rt: SteppedRuntime,
    pub cell_selection: TaskHandle<SelectionCmd>,
    pub hw: TaskHandle<hytask::cell::hw::HwCmd>,
    pub robot: TaskHandle<hytask::cell::robot::RobotCmd>,
    pub status: DataReader<SelectionStatus>,
    pub tally: DataReader<WorldTally>,
    pub done: EventReceiver<RunDone>,
}

impl Rig {
    pub fn start(cfg: &CellConfig) -> Rig {
        let Cell {
            deployment,
            selection,
            robot,
            hw,
            ..
        } = deploy(cfg).unwrap();
        let done = deployment
            .event::<RunDone>(names::RUN_DONE_EVENT)
            .unwrap()
            .subscribe(64);
        let rt = deployment.start_stepped(SimClock::new(0)).unwrap();
        let status = rt.reader(names::SELECTION_STATUS).unwrap();
        let tally = rt.reader(names::WORLD).unwrap();
        Rig {
            rt,
            cell_selection: selection,
            hw,
            robot,
            status,
            tally,
            done,
        }
    }

    pub fn state(&mut self) -> SelectionStatus {
        self.status.latest().unwrap_or_default()
    }

    pub fn tally(&mut self) -> WorldTally {
        self.tally.latest().unwrap_or_default()
    }

    /// Runs until `until` holds (checked every 10 ms) or `max_cycles` pass; returns the
    /// cycles run.
    pub fn run_until(&mut self, max_cycles: u64, mut until: impl FnMut(&mut Rig) -> bool) -> u64 {
        let mut n = 0;
        while n < max_cycles {
            if until(self) {
                return n;
            }
            self.rt.run_cycles(10);
            n += 10;
        }
        n
    }

    /// Waits until the selection is homed and idle.
    /// Subscribes to the cell's event `name` (a fault the test then checks was raised).
    pub fn subscribe<T: Clone + Send + 'static>(&self, name: &str) -> EventReceiver<T> {
        self.rt.event::<T>(name).unwrap().subscribe(8)
    }

    pub fn until_homed(&mut self) {
        let n = self.run_until(10 * SECOND, |r| {
            let s = r.state();
            s.state == SelectionState::Homed && s.entered
        });
        assert!(n < 10 * SECOND, "not homed: {:?}", self.state());
    }
}

/// Objects per container a correct selection sorts from the first `n` of `seed`.
pub fn expected_counts(seed: u64, n: usize) -> [u32; 3] {
    let mut c = [0; 3];
    for k in object_sequence(seed, n) {
        c[k.container().index()] += 1;
    }
    c
}

pub fn container_counts(done: &mut EventReceiver<RunDone>) -> ([u32; 3], Vec<RunDone>) {
    let mut c = [0; 3];
    let mut all = Vec::new();
    done.drain(|d| {
        c[d.container.index()] += 1;
        all.push(d);
    });
    (c, all)
}

pub fn _unused(_: Container) {}
