//! The `hw` task: the simulated hardware at the end of the servo thread. It applies the
//! effector's drive outputs to the [`World`], and publishes what the encoders and digital
//! inputs read (for the sensor task's next cycle), what the camera would see, and the tally
//! of sorted objects. Its operations are the simulation's fault injection: the e-stop button
//! and "the gripper loses the object".

use super::names;
use super::types::{CameraScene, DriveOutput, Feedback, WorldTally};
use super::world::World;
use crate::rt::prelude::*;

/// Fault injection into the simulated world (sim only).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum HwCmd {
    /// Press the e-stop button.
    PressEstop,
    /// Release the e-stop button.
    ReleaseEstop,
    /// The gripper loses the object it holds, now.
    DropObject,
    /// The X encoder reads garbage for one cycle (a broken cable, a glitch): a reading far
    /// outside the sensor's range, the sensor's `range_error` path.
    EncoderGlitch,
}

/// What a glitching encoder reads, mm: far outside any cell's range.
pub const GLITCH_MM: f64 = 1.0e6;

const OPS: &[OperationDescriptor] = &[
    OperationDescriptor::new(
        "press_estop",
        "Simulation: press the cell's e-stop button.",
        &[],
        NextCommand::AfterAcceptance,
    ),
    OperationDescriptor::new(
        "release_estop",
        "Simulation: release the cell's e-stop button.",
        &[],
        NextCommand::AfterAcceptance,
    ),
    OperationDescriptor::new(
        "drop_object",
        "Simulation: the gripper loses the object it holds (fails if it holds none).",
        &[],
        NextCommand::AfterAcceptance,
    ),
    OperationDescriptor::new(
        "encoder_glitch",
        "Simulation: the X encoder reads far out of range for one cycle.",
        &[],
        NextCommand::AfterAcceptance,
    ),
];

impl Commands for HwCmd {
    fn operations() -> &'static [OperationDescriptor] {
        OPS
    }
    fn operation_index(&self) -> usize {
        *self as usize
    }
    fn from_args(operation: &str, args: &[ArgValue]) -> Result<Self, ArgError> {
        let a = Args::new(OPS, operation, args)?;
        Ok(match a.operation() {
            "press_estop" => Self::PressEstop,
            "release_estop" => Self::ReleaseEstop,
            "drop_object" => Self::DropObject,
            _ => Self::EncoderGlitch,
        })
    }
}

/// The simulated hardware task.
pub struct Hardware {
    world: World,
    drive_in: Option<DataReader<DriveOutput>>,
    feedback_out: Option<DataWriter<Feedback>>,
    scene_out: Option<DataWriter<CameraScene>>,
    tally_out: Option<DataWriter<WorldTally>>,
    drive: DriveOutput,
    /// The next published reading glitches.
    glitch: bool,
}

impl Hardware {
    /// The task around `world`.
    pub fn new(world: World) -> Self {
        Self {
            world,
            drive_in: None,
            feedback_out: None,
            scene_out: None,
            tally_out: None,
            drive: DriveOutput::default(),
            glitch: false,
        }
    }

    fn publish(&mut self, fb: Feedback) {
        if let Some(o) = &mut self.feedback_out {
            o.set(fb);
        }
        if let Some(o) = &mut self.scene_out {
            o.set(self.world.scene());
        }
        if let Some(o) = &mut self.tally_out {
            o.set(self.world.tally());
        }
    }
}

impl Task for Hardware {
    type Command = HwCmd;
    fn configure(&mut self, ctx: &mut Configure<'_>) -> Result<(), TaskError> {
        self.drive_in = Some(ctx.input(names::DRIVE));
        self.feedback_out = Some(ctx.output(names::FEEDBACK));
        self.scene_out = Some(ctx.output(names::SCENE));
        self.tally_out = Some(ctx.output(names::WORLD));
        Ok(())
    }
    fn start(&mut self) -> Result<(), TaskError> {
        // The sensors read something sensible before the first cycle.
        let fb = self.world.feedback();
        self.publish(fb);
        Ok(())
    }
    fn read_inputs(&mut self, _: &StepContext) {
        if let Some(r) = &mut self.drive_in {
            r.get(&mut self.drive);
        }
    }
    fn update(&mut self, ctx: &StepContext) -> Result<(), TaskError> {
        let mut fb = self.world.step(ctx.period_ns as f64 * 1e-9, &self.drive);
        if std::mem::take(&mut self.glitch) {
            fb.position_mm[0] = GLITCH_MM;
        }
        self.publish(fb);
        Ok(())
    }
    fn accept(&mut self, c: &HwCmd, _: &StepContext) -> Result<(), RejectReason> {
        match c {
            HwCmd::PressEstop => self.world.set_estop(true),
            HwCmd::ReleaseEstop => self.world.set_estop(false),
            HwCmd::DropObject => {
                if !self.world.drop_object() {
                    return Err(RejectReason::Other("the gripper holds no object"));
                }
            }
            HwCmd::EncoderGlitch => self.glitch = true,
        }
        Ok(())
    }
}
