//! The machine task's operations ([`MachineCmd`]) and their descriptors for the generic command
//! interface. Why apart: the control socket and scripts see only this table, not the task.

use crate::rt::prelude::*;

/// The machine's operations.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum MachineCmd {
    /// Trip the e-stop.
    Estop,
    /// Release the e-stop.
    EstopReset,
    /// Enable the drives.
    On,
    /// Stop, then disable the drives.
    Off,
    /// Home the axes in `mask` (bit i = axis i of the pose; 0 = every axis).
    Home {
        /// Axes to home.
        mask: u32,
    },
    /// Run queued job `job` of `items` queue items (jog and MDI are jobs too).
    Run {
        /// Job id stamped on its queue items.
        job: u32,
        /// Queue items of the job.
        items: u64,
        /// Manual (jog) rather than automatic (job, MDI).
        manual: bool,
    },
    /// Feed hold.
    Pause,
    /// Resume after a hold or an M0.
    Resume,
    /// Controlled stop; the rest of the job is dropped.
    Abort,
    /// Single block: run to the end of the current source line, then hold (resuming first
    /// if held). Watched in the servo cycle: the hold starts in the cycle the next line
    /// begins.
    Step,
    /// The next piece of a probing job (interpreted with the probe's result) is queued:
    /// `items` more queue items for job `job`, which waits at the end of its probe move.
    Continue {
        /// Job id.
        job: u32,
        /// Queue items added.
        items: u64,
    },
    /// Optional stop on or off: whether M1 stops the job (M0 always does).
    OptionalStop {
        /// On: M1 holds like M0.
        on: bool,
    },
    /// Overrides (fractions).
    Overrides {
        /// Feed, 0..=max.
        feed: f64,
        /// Rapid, 0..=1.
        rapid: f64,
        /// Spindle, 0..=2.
        spindle: f64,
    },
}

const NO_PARAMS: &[ParamDescriptor] = &[];

static OPERATIONS: [OperationDescriptor; 13] = [
    OperationDescriptor {
        name: "estop",
        doc: "Trip the e-stop: every drive quick-stops this cycle, outputs go safe.",
        params: NO_PARAMS,
        next: NextCommand::AfterAcceptance,
    },
    OperationDescriptor {
        name: "estop_reset",
        doc: "Release the e-stop (refused while the e-stop input is active).",
        params: NO_PARAMS,
        next: NextCommand::AfterAcceptance,
    },
    OperationDescriptor {
        name: "machine_on",
        doc: "Enable the drives; done when every drive is operational.",
        params: NO_PARAMS,
        next: NextCommand::AfterAcceptance,
    },
    OperationDescriptor {
        name: "machine_off",
        doc: "Every output to its safe state, stop under control, then disable the drives.",
        params: NO_PARAMS,
        next: NextCommand::AfterAcceptance,
    },
    OperationDescriptor {
        name: "home",
        doc: "Home the axes in the bit mask (0 = all), group by group; done when homed.",
        params: &[ParamDescriptor {
            name: "axis_mask",
            ty: ArgType::Int,
        }],
        next: NextCommand::AfterAcceptance,
    },
    OperationDescriptor {
        name: "run",
        doc: "Run queued job `job` of `items` items; done at its end.",
        params: &[
            ParamDescriptor {
                name: "job",
                ty: ArgType::Int,
            },
            ParamDescriptor {
                name: "items",
                ty: ArgType::Int,
            },
            ParamDescriptor {
                name: "manual",
                ty: ArgType::Bool,
            },
        ],
        next: NextCommand::AfterAcceptance,
    },
    OperationDescriptor {
        name: "pause",
        doc: "Feed hold; done when motion has stopped on the path.",
        params: NO_PARAMS,
        next: NextCommand::AfterAcceptance,
    },
    OperationDescriptor {
        name: "resume",
        doc: "Resume after a feed hold or M0.",
        params: NO_PARAMS,
        next: NextCommand::AfterAcceptance,
    },
    OperationDescriptor {
        name: "abort",
        doc: "Controlled stop within the axis limits, spindle and coolant off (not for a \
              jog); the rest of the job is dropped.",
        params: NO_PARAMS,
        next: NextCommand::AfterAcceptance,
    },
    OperationDescriptor {
        name: "set_overrides",
        doc: "Feed (0..max), rapid (0..1) and spindle (0..2) overrides.",
        params: &[
            ParamDescriptor {
                name: "feed",
                ty: ArgType::Float,
            },
            ParamDescriptor {
                name: "rapid",
                ty: ArgType::Float,
            },
            ParamDescriptor {
                name: "spindle",
                ty: ArgType::Float,
            },
        ],
        next: NextCommand::AfterAcceptance,
    },
    OperationDescriptor {
        name: "step",
        doc: "Run to the end of the current source line, then hold (resumes a hold first).",
        params: NO_PARAMS,
        next: NextCommand::AfterAcceptance,
    },
    OperationDescriptor {
        name: "continue",
        doc: "Job `job` waits after a probe move: `items` more queue items (the next piece \
              of the program, interpreted with the probe's result) are queued.",
        params: &[
            ParamDescriptor {
                name: "job",
                ty: ArgType::Int,
            },
            ParamDescriptor {
                name: "items",
                ty: ArgType::Int,
            },
        ],
        next: NextCommand::AfterAcceptance,
    },
    OperationDescriptor {
        name: "set_optional_stop",
        doc: "Optional stop on or off: whether M1 holds the job as M0 does (off at start).",
        params: &[ParamDescriptor {
            name: "on",
            ty: ArgType::Bool,
        }],
        next: NextCommand::AfterAcceptance,
    },
];

impl Commands for MachineCmd {
    fn operations() -> &'static [OperationDescriptor] {
        &OPERATIONS
    }

    fn operation_index(&self) -> usize {
        match self {
            MachineCmd::Estop => 0,
            MachineCmd::EstopReset => 1,
            MachineCmd::On => 2,
            MachineCmd::Off => 3,
            MachineCmd::Home { .. } => 4,
            MachineCmd::Run { .. } => 5,
            MachineCmd::Pause => 6,
            MachineCmd::Resume => 7,
            MachineCmd::Abort => 8,
            MachineCmd::Overrides { .. } => 9,
            MachineCmd::Step => 10,
            MachineCmd::Continue { .. } => 11,
            MachineCmd::OptionalStop { .. } => 12,
        }
    }

    fn from_args(operation: &str, args: &[ArgValue]) -> Result<Self, ArgError> {
        let a = Args::new(Self::operations(), operation, args)?;
        Ok(match a.operation() {
            "estop" => MachineCmd::Estop,
            "estop_reset" => MachineCmd::EstopReset,
            "machine_on" => MachineCmd::On,
            "machine_off" => MachineCmd::Off,
            "home" => MachineCmd::Home {
                mask: a.int(0)? as u32,
            },
            "run" => MachineCmd::Run {
                job: a.int(0)? as u32,
                items: a.int(1)?.max(0) as u64,
                manual: a.bool(2)?,
            },
            "pause" => MachineCmd::Pause,
            "resume" => MachineCmd::Resume,
            "abort" => MachineCmd::Abort,
            "step" => MachineCmd::Step,
            "set_optional_stop" => MachineCmd::OptionalStop { on: a.bool(0)? },
            "continue" => MachineCmd::Continue {
                job: a.int(0)? as u32,
                items: a.int(1)?.max(0) as u64,
            },
            _ => MachineCmd::Overrides {
                feed: a.float(0)?,
                rapid: a.float(1)?,
                spindle: a.float(2)?,
            },
        })
    }
}
