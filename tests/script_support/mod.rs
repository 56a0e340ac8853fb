//! A small simulated arm for the script tests: a task with operations (commands with
//! completion conditions, a rejection, a failure) and events, a script host task beside it
//! on the same thread, and a stepped runtime with simulated time.
#![allow(dead_code, clippy::unwrap_used)]

use hytask::rt::prelude::*;
use hytask::script::{Bindings, Ctl, Limits, ScriptControl, ScriptTask};
use std::sync::atomic::AtomicU64;
use std::sync::Arc;

/// Period of the test thread: 1 ms.
pub const PERIOD_NS: u64 = 1_000_000;

#[derive(Default)]
pub struct Arm {
    pub pos: f64,
    target: f64,
    out: Option<DataWriter<f64>>,
    reached: Option<EventSource<f64>>,
    grabbed: Option<EventSource<()>>,
    holding: Option<DataWriter<bool>>,
    hold: bool,
}

pub enum ArmCmd {
    MoveTo(f64),
    Grab,
    Drop,
    Fail,
}

impl Commands for ArmCmd {
    fn operations() -> &'static [OperationDescriptor] {
        const X: &[ParamDescriptor] = &[ParamDescriptor::new("x_mm", ArgType::Float)];
        // A `const` item: a `const fn` call in a returned `&[..]` is not promoted to 'static.
        const OPS: &[OperationDescriptor] = &[
            OperationDescriptor::new(
                "move_to",
                "Move to x (|x| <= 100); done when there.",
                X,
                NextCommand::AfterCompletion,
            ),
            OperationDescriptor::new(
                "grab",
                "Grab (event grabbed).",
                &[],
                NextCommand::AfterCompletion,
            ),
            OperationDescriptor::new(
                "drop",
                "Drop what is held.",
                &[],
                NextCommand::AfterCompletion,
            ),
            OperationDescriptor::new(
                "fail",
                "Accepted, then fails.",
                &[],
                NextCommand::AfterCompletion,
            ),
        ];
        OPS
    }
    fn operation_index(&self) -> usize {
        match self {
            ArmCmd::MoveTo(_) => 0,
            ArmCmd::Grab => 1,
            ArmCmd::Drop => 2,
            ArmCmd::Fail => 3,
        }
    }
    fn from_args(op: &str, args: &[ArgValue]) -> Result<Self, ArgError> {
        let a = Args::new(Self::operations(), op, args)?;
        Ok(match a.operation() {
            "move_to" => ArmCmd::MoveTo(a.float(0)?),
            "grab" => ArmCmd::Grab,
            "drop" => ArmCmd::Drop,
            _ => ArmCmd::Fail,
        })
    }
}

impl Task for Arm {
    type Command = ArmCmd;
    fn configure(&mut self, ctx: &mut Configure<'_>) -> Result<(), TaskError> {
        self.out = Some(ctx.output("arm.position"));
        self.holding = Some(ctx.output("arm.holding"));
        self.reached = Some(ctx.event("reached"));
        self.grabbed = Some(ctx.event("grabbed"));
        Ok(())
    }
    fn update(&mut self, _: &StepContext) -> Result<(), TaskError> {
        self.pos += (self.target - self.pos).clamp(-1.0, 1.0);
        if let Some(o) = &mut self.out {
            o.set(self.pos);
        }
        if let Some(o) = &mut self.holding {
            o.set(self.hold);
        }
        Ok(())
    }
    fn accept(&mut self, c: &ArmCmd, _: &StepContext) -> Result<(), RejectReason> {
        match *c {
            ArmCmd::MoveTo(x) if !(-100.0..=100.0).contains(&x) => {
                Err(RejectReason::BadParameters("x_mm outside -100..100"))
            }
            ArmCmd::MoveTo(x) => {
                self.target = x;
                Ok(())
            }
            ArmCmd::Grab => {
                self.hold = true;
                if let Some(e) = &mut self.grabbed {
                    e.emit(());
                }
                Ok(())
            }
            ArmCmd::Drop => {
                self.hold = false;
                Ok(())
            }
            ArmCmd::Fail => Ok(()),
        }
    }
    fn progress(&mut self, c: &ArmCmd, _: &StepContext) -> Progress {
        match c {
            ArmCmd::MoveTo(x) if self.pos == *x => {
                if let Some(e) = &mut self.reached {
                    e.emit(self.pos);
                }
                Progress::Done
            }
            ArmCmd::MoveTo(_) => Progress::Running,
            ArmCmd::Fail => Progress::Failed("jammed"),
            _ => Progress::Done,
        }
    }
}

/// The arm and a script host ("cell") on one 1 ms thread, started on simulated time.
pub struct Cell {
    pub rt: hytask::rt::deploy::SteppedRuntime,
    pub control: Arc<ScriptControl>,
    pub bindings: Bindings,
    pub done: Arc<AtomicU64>,
}

pub fn cell() -> Cell {
    let mut app = Deployment::new();
    let sched = Schedule {
        priority: 50,
        period_ns: PERIOD_NS,
        cpu: None,
    };
    app.add_periodic("arm", Arm::default(), sched).unwrap();
    let (task, control) = ScriptTask::new("cell", Limits::default());
    app.add_periodic("cell", task, sched).unwrap();
    app.configure().unwrap();
    let rt = app.start_stepped(SimClock::new(0)).unwrap();
    control.attach(rt.task("cell").unwrap().clone());
    let mut bindings = Bindings::default();
    bindings.peer_task(rt.task("arm").unwrap());
    for e in ["arm.reached", "arm.grabbed"] {
        bindings.event(e, rt.event_counter(e).unwrap());
    }
    let done = Arc::new(AtomicU64::new(0));
    bindings.emit("done", done.clone());
    Cell {
        rt,
        control: Arc::new(control),
        bindings,
        done,
    }
}

impl Cell {
    pub fn load(&self, src: &str) -> usize {
        self.control
            .load("test.st", src, &self.bindings)
            .unwrap_or_else(|e| panic!("{e}"))
    }
    /// Loads `src` and starts its item `name`; the slot.
    pub fn start(&self, src: &str, name: &str) -> usize {
        let slot = self.load(src);
        self.control.control(slot, name, Ctl::Start).unwrap();
        slot
    }
    /// Runs `cycles` steps, then the error item `name` stopped in, if any.
    pub fn error_after(&mut self, cycles: u64, name: &str) -> Option<String> {
        self.rt.run_cycles(cycles);
        self.status(name).error
    }
    pub fn status(&self, name: &str) -> hytask::script::ItemStatus {
        self.control
            .status()
            .into_iter()
            .find(|s| s.name == name)
            .unwrap()
    }
}
