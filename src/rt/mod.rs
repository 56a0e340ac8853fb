//! The realtime core: the Orocos hybrid task model (Soetens & Bruyninckx) — activities on
//! `SCHED_FIFO` threads, data objects, buffers, events, commands, lifecycle and timing
//! statistics. It knows nothing of machines.
//!
//! # The pieces
//! - [`task::Task`]: what a task computes (`update`) and which commands it serves, with
//!   lifecycle hooks; [`runner`] documents the fixed order of one step and why.
//! - [`deploy::Deployment`]: the configuration flow — add tasks to threads (one thread per
//!   (priority, period); equal ones share a thread and run in start order), configure them
//!   ([`deploy::Configure`]: data and buffer ports, events, peers), check the topology (every
//!   error listed, naming task and port), start on real threads ([`deploy::Runtime`]) or on a
//!   stepped, simulated-time runtime for tests ([`deploy::SteppedRuntime`]).
//! - Data flow: [`data_object`] (latest value, one writer, many readers, wait-free both sides,
//!   one copy per write whatever the number of readers) and [`buffer`] (bounded lock-free FIFO
//!   with a full policy, many producers, one consumer).
//! - Execution flow: [`event`] (typed events, immediate and deferred handlers, non-realtime
//!   subscribers) and [`command`] (operations as data, typed and dynamic commands, accept /
//!   reject, completion conditions, handles pollable from realtime and waitable from
//!   non-realtime code).
//! - [`activity`]: periodic threads (absolute-deadline sleeps, wake-up latency and overrun
//!   accounting) and the stepped activity; [`clock`], [`stats`], [`system`] (`mlockall`,
//!   capability check: without privileges everything runs, warns once and reports
//!   `realtime: false`).
//!
//! Nothing called from a step allocates, locks, blocks or logs: every queue and slot is
//! allocated at configuration (`tests/rt_no_alloc.rs` proves it with a counting allocator).
//!
//! # Example
//! A task with an output port, an operation with a completion condition and an event; a
//! non-realtime caller sends a command by type and by name and reads the port.
//! ```
//! use hytask::rt::prelude::*;
//!
//! /// Moves a value towards a target by at most `step` per cycle.
//! #[derive(Default)]
//! struct Ramp { value: f64, target: f64, out: Option<DataWriter<f64>>, reached: Option<EventSource<f64>> }
//!
//! enum RampCmd { MoveTo(f64) }
//!
//! impl Commands for RampCmd {
//!     fn operations() -> &'static [OperationDescriptor] {
//!         &[OperationDescriptor {
//!             name: "move_to", doc: "Ramp to a target; done when reached.",
//!             params: &[ParamDescriptor { name: "target", ty: ArgType::Float }],
//!             next: NextCommand::AfterCompletion,
//!         }]
//!     }
//!     fn operation_index(&self) -> usize { 0 }
//!     fn from_args(op: &str, args: &[ArgValue]) -> Result<Self, ArgError> {
//!         let a = Args::new(Self::operations(), op, args)?;
//!         Ok(RampCmd::MoveTo(a.float(0)?))
//!     }
//! }
//!
//! impl Task for Ramp {
//!     type Command = RampCmd;
//!     fn configure(&mut self, ctx: &mut Configure<'_>) -> Result<(), TaskError> {
//!         self.out = Some(ctx.output("ramp.value"));
//!         self.reached = Some(ctx.event("reached"));
//!         Ok(())
//!     }
//!     fn update(&mut self, _: &StepContext) -> Result<(), TaskError> {
//!         self.value += (self.target - self.value).clamp(-1.0, 1.0);
//!         if let Some(out) = &mut self.out { out.set(self.value); }
//!         Ok(())
//!     }
//!     fn accept(&mut self, c: &RampCmd, _: &StepContext) -> Result<(), RejectReason> {
//!         let RampCmd::MoveTo(t) = *c;
//!         if !t.is_finite() { return Err(RejectReason::BadParameters("target must be finite")); }
//!         self.target = t;
//!         Ok(())
//!     }
//!     fn progress(&mut self, _: &RampCmd, _: &StepContext) -> Progress {
//!         if self.value == self.target {
//!             if let Some(ev) = &mut self.reached { ev.emit(self.value); }
//!             Progress::Done
//!         } else { Progress::Running }
//!     }
//! }
//!
//! let mut app = Deployment::new();
//! let ramp = app.add_periodic("ramp", Ramp::default(),
//!     Schedule { priority: 80, period_ns: 1_000_000, cpu: None }).unwrap();
//! app.configure().unwrap();
//! let mut reached = app.event::<f64>("ramp.reached").unwrap().subscribe(8);
//! // Tests use simulated time; a daemon calls `app.start()` for SCHED_FIFO threads.
//! let mut rt = app.start_stepped(SimClock::new(0)).unwrap();
//! let mut value = rt.reader::<f64>("ramp.value").unwrap();
//!
//! let typed = ramp.send(RampCmd::MoveTo(3.0)).unwrap();
//! rt.run_cycles(10);
//! assert_eq!(typed.status(), CommandStatus::Done);
//! assert_eq!(value.latest(), Some(3.0));
//! assert_eq!(reached.pop(), Some(3.0));
//!
//! let by_name = rt.task("ramp").unwrap().commands()
//!     .send_args("move_to", &[ArgValue::Float(-1.0)]).unwrap();
//! rt.run_cycles(10);
//! assert_eq!(by_name.status(), CommandStatus::Done);
//! assert_eq!(rt.task("ramp").unwrap().state(), TaskState::Running);
//! let deployment = rt.stop();
//! assert_eq!(deployment.tasks()[0].state(), TaskState::Stopped);
//! ```

pub mod activity;
pub mod buffer;
pub mod clock;
pub mod command;
pub mod data_object;
pub mod deploy;
pub mod event;
pub mod interface;
pub mod json;
mod ring;
pub mod runner;
pub mod stats;
mod sync;
pub mod system;
pub mod task;

/// Everything needed to write and deploy tasks, in one import.
pub mod prelude {
    pub use super::activity::{Overrun, OverrunPolicy, ThreadSpec};
    pub use super::buffer::{buffer, BufferReader, BufferWriter, FullPolicy, PushOutcome};
    pub use super::clock::{Clock, MonotonicClock, SimClock};
    pub use super::command::{
        ArgError, ArgType, ArgValue, Args, CommandHandle, CommandSender, CommandStatus, Commands,
        DynCommandSender, NextCommand, NoCommands, OperationDescriptor, ParamDescriptor, Progress,
        RejectReason, SendError,
    };
    pub use super::data_object::{DataObject, DataReader, DataWriter, FlowStatus};
    pub use super::deploy::{Configure, DeployError, Deployment, Schedule, TaskHandle};
    pub use super::event::{Event, EventCounter, EventReceiver, EventSource};
    pub use super::runner::TaskInfo;
    pub use super::task::{StepContext, Task, TaskError, TaskState};
}
