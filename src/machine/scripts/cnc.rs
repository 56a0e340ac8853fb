//! Task `cnc`: the machine's operator operations as a peer scripts can command (`DO
//! cnc.home();`, `DO cnc.run('jobs/part.ngc');`), and the machine's news as events scripts
//! can wait for (`WAIT cnc.job_done;`).
//!
//! Why a task of its own and not the `machine` task itself: what an operator asks for
//! (run this file, this MDI line) is non-realtime work (reading, interpreting and planning
//! G-code, a feeder thread per job), done by [`MachineApi`](crate::machine::api::MachineApi)
//! on the non-realtime side. This task only hands each accepted command to the operator
//! worker ([`super::worker`]) through a lock-free buffer and reports the worker's result as
//! the command's completion condition, so its step neither allocates nor blocks. Its events
//! are the machine task's `machine.job`, `machine.mode` and `machine.fault` boiled down to
//! what a script waits for.

use crate::machine::api::Mode;
use crate::machine::servo::{FaultEvent, JobEvent, JobNews, ModeEvent};
use crate::rt::prelude::*;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, OnceLock};

/// Longest text argument (G-code line, file name, output name), bytes.
pub const MAX_TEXT: usize = 200;

/// A text argument stored inline: a command carries it without a heap allocation.
#[derive(Clone, Copy)]
pub struct Text {
    bytes: [u8; MAX_TEXT],
    len: u8,
    /// The argument was longer than [`MAX_TEXT`] (rejected at acceptance).
    too_long: bool,
}

impl Text {
    fn new(s: &str) -> Self {
        let mut t = Text {
            bytes: [0; MAX_TEXT],
            len: 0,
            too_long: s.len() > MAX_TEXT,
        };
        if !t.too_long {
            t.bytes[..s.len()].copy_from_slice(s.as_bytes());
            t.len = s.len() as u8;
        }
        t
    }

    /// The text.
    pub fn as_str(&self) -> &str {
        // Built from a &str of at most MAX_TEXT bytes: always valid UTF-8.
        std::str::from_utf8(&self.bytes[..usize::from(self.len)]).unwrap_or("")
    }
}

impl std::fmt::Debug for Text {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{:?}", self.as_str())
    }
}

/// The operations of task `cnc`.
#[derive(Debug, Clone, Copy)]
pub enum CncCmd {
    /// Release the e-stop.
    EstopReset,
    /// Enable the drives.
    On,
    /// Disable the drives.
    Off,
    /// Home every axis; done when all are homed.
    Home,
    /// Run one MDI line; done when it finished.
    Mdi(Text),
    /// Load and run a G-code file; done when the job finished.
    Run(Text),
    /// Set a digital output by name (M64/M65 as MDI); done when set.
    Output(Text, bool),
}

/// The operator's commands run one after the other: the next waits for the current one.
const NEXT: NextCommand = NextCommand::AfterCompletion;

type Op = OperationDescriptor;
type Param = ParamDescriptor;

static OPERATIONS: [OperationDescriptor; 7] = [
    Op::new("estop_reset", "release the e-stop", &[], NEXT),
    Op::new("on", "enable the drives", &[], NEXT),
    Op::new("off", "disable the drives", &[], NEXT),
    Op::new(
        "home",
        "home every axis; done when all are homed",
        &[],
        NEXT,
    ),
    Op::new(
        "mdi",
        "run one MDI line; done when it finished, failed if the job failed",
        &[Param::new("line", ArgType::Str)],
        NEXT,
    ),
    Op::new(
        "run",
        "load and run a G-code file (path as the daemon sees it); done when the job finished",
        &[Param::new("file", ArgType::Str)],
        NEXT,
    ),
    Op::new(
        "output",
        "set digital output `name` (M64/M65); done when set",
        &[
            Param::new("name", ArgType::Str),
            Param::new("on", ArgType::Bool),
        ],
        NEXT,
    ),
];

impl Commands for CncCmd {
    fn operations() -> &'static [OperationDescriptor] {
        &OPERATIONS
    }
    fn operation_index(&self) -> usize {
        match self {
            Self::EstopReset => 0,
            Self::On => 1,
            Self::Off => 2,
            Self::Home => 3,
            Self::Mdi(_) => 4,
            Self::Run(_) => 5,
            Self::Output(..) => 6,
        }
    }
    fn from_args(operation: &str, args: &[ArgValue]) -> Result<Self, ArgError> {
        let a = Args::new(&OPERATIONS, operation, args)?;
        Ok(match a.operation() {
            "estop_reset" => Self::EstopReset,
            "on" => Self::On,
            "off" => Self::Off,
            "home" => Self::Home,
            "mdi" => Self::Mdi(Text::new(a.str(0)?)),
            "run" => Self::Run(Text::new(a.str(0)?)),
            _ => Self::Output(Text::new(a.str(0)?), a.bool(1)?),
        })
    }
}

/// Why a command failed, as the static text a command status carries (the details go to
/// the daemon's log).
pub const REASONS: &[&str] = &[
    "",
    "rejected by the machine (see the daemon's log)",
    "invalid parameter (see the daemon's log)",
    "G-code error (see the daemon's log)",
    "the machine failed it (see the daemon's log)",
    "the machine did not answer in time",
    "not supported by this machine",
    "the job failed",
    "the job was aborted",
    "homing did not complete",
    "no such digital output",
    "the machine is gone",
];

/// The worker's end of the request buffer: `(sequence number, command)`.
pub type Requests = BufferReader<(u32, CncCmd)>;

/// Result code of a command: 0 done, else an index into [`REASONS`].
pub type Outcome = u8;

/// What the task and the worker share.
pub struct Shared {
    /// `(seq << 8) | outcome` of the last command the worker finished.
    result: AtomicU64,
    /// The worker, to wake when a command was queued.
    pub(super) worker: OnceLock<std::thread::Thread>,
}

impl Shared {
    pub(super) fn new() -> Arc<Self> {
        Arc::new(Shared {
            result: AtomicU64::new(0),
            worker: OnceLock::new(),
        })
    }

    /// The worker finished command `seq`.
    pub(super) fn finish(&self, seq: u32, outcome: Outcome) {
        self.result
            .store(u64::from(seq) << 8 | u64::from(outcome), Ordering::Release);
    }
}

struct Ports {
    job: EventReceiver<JobNews>,
    mode: EventReceiver<ModeEvent>,
    fault: EventReceiver<FaultEvent>,
    job_done: EventSource<()>,
    job_failed: EventSource<()>,
    homed: EventSource<()>,
    estop: EventSource<()>,
    fault_out: EventSource<()>,
}

/// Task `cnc`.
pub struct CncTask {
    shared: Arc<Shared>,
    tx: BufferWriter<(u32, CncCmd)>,
    seq: u32,
    ports: Option<Ports>,
    mode: Mode,
}

/// Event names of task `cnc` (full names: `cnc.<name>`).
pub const EVENTS: [&str; 5] = ["job_done", "job_failed", "homed", "estop", "fault"];

impl CncTask {
    /// The task and the worker's end of its request buffer.
    pub(super) fn new(shared: Arc<Shared>) -> (Self, Requests) {
        let (tx, rx) = buffer(4, FullPolicy::DropNewest);
        let task = CncTask {
            shared,
            tx,
            seq: 0,
            ports: None,
            mode: Mode::Estop,
        };
        (task, rx)
    }
}

impl Task for CncTask {
    type Command = CncCmd;
    fn configure(&mut self, ctx: &mut Configure<'_>) -> Result<(), TaskError> {
        self.ports = Some(Ports {
            job: ctx.subscribe("machine.job", 64),
            mode: ctx.subscribe("machine.mode", 64),
            fault: ctx.subscribe("machine.fault", 64),
            job_done: ctx.event(EVENTS[0]),
            job_failed: ctx.event(EVENTS[1]),
            homed: ctx.event(EVENTS[2]),
            estop: ctx.event(EVENTS[3]),
            fault_out: ctx.event(EVENTS[4]),
        });
        Ok(())
    }
    fn update(&mut self, _: &StepContext) -> Result<(), TaskError> {
        Ok(())
    }
    fn accept(&mut self, c: &CncCmd, _: &StepContext) -> Result<(), RejectReason> {
        let text = match c {
            CncCmd::Mdi(t) | CncCmd::Run(t) | CncCmd::Output(t, _) => Some(t),
            _ => None,
        };
        if text.is_some_and(|t| t.too_long) {
            return Err(RejectReason::BadParameters("text longer than 200 bytes"));
        }
        let seq = self.seq.wrapping_add(1) & 0x00ff_ffff;
        // One command at a time (every operation completes before the next is taken), so
        // the buffer has room unless the worker is gone.
        self.tx
            .try_push((seq, *c))
            .map_err(|_| RejectReason::Other("the operator worker does not run"))?;
        self.seq = seq;
        if let Some(w) = self.shared.worker.get() {
            w.unpark();
        }
        Ok(())
    }
    fn progress(&mut self, _: &CncCmd, _: &StepContext) -> Progress {
        let r = self.shared.result.load(Ordering::Acquire);
        if (r >> 8) as u32 != self.seq {
            return Progress::Running;
        }
        match (r & 0xff) as usize {
            0 => Progress::Done,
            i => Progress::Failed(REASONS.get(i).copied().unwrap_or("failed")),
        }
    }
    fn process_events(&mut self, _: &StepContext) {
        let Some(p) = &mut self.ports else { return };
        while let Some(n) = p.job.pop() {
            match n.event {
                JobEvent::Finished { .. } => p.job_done.emit(()),
                JobEvent::Aborted { .. } | JobEvent::Failed { .. } | JobEvent::Error { .. } => {
                    p.job_failed.emit(());
                }
                _ => {}
            }
        }
        while let Some(m) = p.mode.pop() {
            if self.mode == Mode::Homing && m.mode == Mode::Idle {
                p.homed.emit(());
            }
            if m.mode == Mode::Estop && self.mode != Mode::Estop {
                p.estop.emit(());
            }
            self.mode = m.mode;
        }
        while p.fault.pop().is_some() {
            p.fault_out.emit(());
        }
    }
}
