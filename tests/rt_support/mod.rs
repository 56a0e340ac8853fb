//! Shared by the task-semantics tests (`rt_tasks`, `rt_threads`): a logging probe task, the
//! `Op` commands and the `Worker` that serves them, hang-guarded waits and schedules.
#![allow(clippy::unwrap_used, dead_code)]

use hytask::rt::prelude::*;
use std::sync::{Arc, Mutex};
use std::time::Duration;

pub type Log = Arc<Mutex<Vec<String>>>;

pub fn log(l: &Log, s: impl Into<String>) {
    l.lock().unwrap().push(s.into());
}

pub const MS: u64 = 1_000_000;

/// Hang guard of the waits on real threads: a loaded 2-CPU host may starve them for seconds.
pub const GUARD: Duration = Duration::from_secs(60);

/// Polls until `done` holds: the tests act on what the threads did, never after a sleep.
pub fn wait_for(what: &str, done: impl Fn() -> bool) {
    let t0 = std::time::Instant::now();
    while !done() {
        assert!(t0.elapsed() < GUARD, "timed out waiting for {what}");
        std::thread::sleep(Duration::from_millis(1));
    }
}

pub fn sched(priority: i32, period_ns: u64) -> Schedule {
    Schedule {
        priority,
        period_ns,
        cpu: None,
    }
}

/// Logs every hook, to check the order of a step and of tasks.
pub struct Probe {
    pub name: &'static str,
    pub log: Log,
}

impl Task for Probe {
    type Command = Op;
    fn read_inputs(&mut self, _: &StepContext) {
        log(&self.log, format!("{}:read", self.name));
    }
    fn update(&mut self, _: &StepContext) -> Result<(), TaskError> {
        log(&self.log, format!("{}:update", self.name));
        Ok(())
    }
    fn state_machines(&mut self, _: &StepContext) {
        log(&self.log, format!("{}:sm", self.name));
    }
    fn programs(&mut self, _: &StepContext) {
        log(&self.log, format!("{}:prog", self.name));
    }
    fn accept(&mut self, _: &Op, _: &StepContext) -> Result<(), RejectReason> {
        log(&self.log, format!("{}:accept", self.name));
        Ok(())
    }
    fn process_events(&mut self, _: &StepContext) {
        log(&self.log, format!("{}:events", self.name));
    }
}

/// Commands used by the tests.
#[derive(Debug)]
pub enum Op {
    /// Completes after `cycles` evaluations; rejected if negative.
    Wait(i64),
    /// Completes at once; the next command may start right after acceptance.
    Quick,
    /// Fails on first evaluation.
    Doomed,
}

impl Commands for Op {
    fn operations() -> &'static [OperationDescriptor] {
        &[
            OperationDescriptor {
                name: "wait",
                doc: "Completes after n cycles.",
                params: &[ParamDescriptor {
                    name: "cycles",
                    ty: ArgType::Int,
                }],
                next: NextCommand::AfterCompletion,
            },
            OperationDescriptor {
                name: "quick",
                doc: "Completes at once.",
                params: &[],
                next: NextCommand::AfterAcceptance,
            },
            OperationDescriptor {
                name: "doomed",
                doc: "Always fails.",
                params: &[],
                next: NextCommand::AfterCompletion,
            },
        ]
    }
    fn operation_index(&self) -> usize {
        match self {
            Op::Wait(_) => 0,
            Op::Quick => 1,
            Op::Doomed => 2,
        }
    }
    fn from_args(op: &str, args: &[ArgValue]) -> Result<Self, ArgError> {
        let a = Args::new(Self::operations(), op, args)?;
        Ok(match a.operation() {
            "wait" => Op::Wait(a.int(0)?),
            "quick" => Op::Quick,
            _ => Op::Doomed,
        })
    }
}

/// Serves `Op`: counts completion evaluations; `busy` makes it reject.
#[derive(Default)]
pub struct Worker {
    pub busy: bool,
    pub evaluations: i64,
    pub log: Option<Log>,
}

impl Task for Worker {
    type Command = Op;
    fn update(&mut self, _: &StepContext) -> Result<(), TaskError> {
        Ok(())
    }
    fn accept(&mut self, c: &Op, ctx: &StepContext) -> Result<(), RejectReason> {
        if self.busy {
            return Err(RejectReason::Busy);
        }
        if let Op::Wait(n) = c {
            if *n < 0 {
                return Err(RejectReason::BadParameters("cycles must be >= 0"));
            }
        }
        if let Some(l) = &self.log {
            log(l, format!("accept {c:?} @{}", ctx.cycle));
        }
        self.evaluations = 0;
        Ok(())
    }
    fn progress(&mut self, c: &Op, ctx: &StepContext) -> Progress {
        if let Some(l) = &self.log {
            log(l, format!("progress {c:?} @{}", ctx.cycle));
        }
        match c {
            Op::Wait(n) => {
                self.evaluations += 1;
                if self.evaluations >= *n {
                    Progress::Done
                } else {
                    Progress::Running
                }
            }
            Op::Quick => Progress::Done,
            Op::Doomed => Progress::Failed("doomed"),
        }
    }
}

/// Emits its cycle number as an event every cycle.
#[derive(Default)]
pub struct Emitter {
    pub ev: Option<EventSource<u64>>,
}

impl Task for Emitter {
    type Command = NoCommands;
    fn configure(&mut self, ctx: &mut Configure<'_>) -> Result<(), TaskError> {
        self.ev = Some(ctx.event("tick"));
        Ok(())
    }
    fn update(&mut self, ctx: &StepContext) -> Result<(), TaskError> {
        if let Some(e) = &mut self.ev {
            e.emit(ctx.cycle);
        }
        Ok(())
    }
}
