//! Task `scripts`: the machine's script host. A [`ScriptHost`] whose scripts stop in error
//! ("stopped by the e-stop", at the statement they were at) when the machine e-stops, so
//! that nothing a script was doing resumes by itself once the e-stop is released.

use crate::machine::api::Mode;
use crate::machine::servo::ModeEvent;
use crate::rt::prelude::*;
use crate::script::{Limits, ScriptControl, ScriptErrorKind, ScriptHost};

/// Task `scripts`.
pub struct HostTask {
    host: ScriptHost,
    mode: Option<EventReceiver<ModeEvent>>,
}

impl HostTask {
    /// The task and its control half.
    pub fn new(limits: Limits) -> (Self, ScriptControl) {
        let (host, control) = ScriptHost::new(super::HOST, limits);
        (HostTask { host, mode: None }, control)
    }
}

impl Task for HostTask {
    type Command = NoCommands;
    fn configure(&mut self, ctx: &mut Configure<'_>) -> Result<(), TaskError> {
        self.mode = Some(ctx.subscribe("machine.mode", 64));
        Ok(())
    }
    fn update(&mut self, _: &StepContext) -> Result<(), TaskError> {
        Ok(())
    }
    fn state_machines(&mut self, ctx: &StepContext) {
        self.host.state_machines(ctx.now_ns);
    }
    fn programs(&mut self, ctx: &StepContext) {
        self.host.programs(ctx.now_ns);
    }
    fn process_events(&mut self, _: &StepContext) {
        let Some(rx) = &mut self.mode else { return };
        let mut estop = false;
        while let Some(m) = rx.pop() {
            estop |= m.mode == Mode::Estop;
        }
        if estop {
            self.host.fail_all(ScriptErrorKind::Estop);
        }
    }
    fn stop(&mut self) {
        self.host.stop();
    }
}
