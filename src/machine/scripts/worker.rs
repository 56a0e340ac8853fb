//! The operator worker: a non-realtime thread that carries out task `cnc`'s commands
//! through [`MachineApi`], as an operator at the control socket would, and waits for their
//! completion (homed, job finished) by watching the machine's status.

use super::cnc::{CncCmd, Outcome, Requests, Shared};
use crate::config::IoKind;
use crate::machine::api::{ApiError, JobSource, MachineApi, Mode, Status};
use crate::machine::devices::IoMap;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Weak};
use std::time::Duration;

/// How often a waiting command looks at the machine's status.
const POLL: Duration = Duration::from_millis(5);

/// What the worker thread needs.
pub(super) struct Worker {
    pub shared: Arc<Shared>,
    pub rx: Requests,
    pub machine: Weak<dyn MachineApi + Send + Sync>,
    pub io_map: IoMap,
    pub stop: Arc<AtomicBool>,
}

fn api_outcome(op: &str, e: &ApiError) -> Outcome {
    tracing::warn!("script operation cnc.{op}: {e}");
    match e {
        ApiError::Rejected(_) => 1,
        ApiError::InvalidParams(_) => 2,
        ApiError::Gcode(_) => 3,
        ApiError::Failed(_) => 4,
        ApiError::Timeout(_) => 5,
        ApiError::NotSupported(_) => 6,
    }
}

impl Worker {
    /// Runs until `stop` is set or the machine is gone.
    pub fn run(mut self) {
        while !self.stop.load(Ordering::Acquire) {
            match self.rx.pop() {
                Some((seq, cmd)) => {
                    let outcome = self.execute(&cmd);
                    self.shared.finish(seq, outcome);
                }
                None if self.machine.strong_count() == 0 => return,
                None => std::thread::park_timeout(Duration::from_millis(100)),
            }
        }
    }

    fn stopped(&self) -> bool {
        self.stop.load(Ordering::Acquire)
    }

    fn execute(&self, cmd: &CncCmd) -> Outcome {
        let Some(m) = self.machine.upgrade() else {
            return 11;
        };
        let m = &*m;
        let r = match cmd {
            CncCmd::EstopReset => m.estop_reset().map_err(|e| api_outcome("estop_reset", &e)),
            CncCmd::On => m.machine_on().map_err(|e| api_outcome("on", &e)),
            CncCmd::Off => m.machine_off().map_err(|e| api_outcome("off", &e)),
            CncCmd::Home => match m.home(None) {
                Ok(()) => return self.wait_homed(m),
                Err(e) => Err(api_outcome("home", &e)),
            },
            CncCmd::Mdi(line) => self.job(m, "mdi", |m| m.mdi(line.as_str())),
            CncCmd::Run(file) => self.job(m, "run", |m| {
                m.job_load(&JobSource {
                    path: Some(file.as_str().to_owned()),
                    text: None,
                    name: None,
                })?;
                m.job_run()
            }),
            CncCmd::Output(name, on) => {
                match self.io_map.index(IoKind::DigitalOutput, name.as_str()) {
                    None => {
                        tracing::warn!(
                            "script operation cnc.output: no digital output '{}'",
                            name.as_str()
                        );
                        Err(10)
                    }
                    Some(i) => {
                        let line = format!("M{} P{i}", if *on { 64 } else { 65 });
                        self.job(m, "output", |m| m.mdi(&line))
                    }
                }
            }
        };
        match r {
            Ok(()) => 0,
            Err(o) => o,
        }
    }

    /// Starts a job with `start` and waits for its end.
    fn job(
        &self,
        m: &(dyn MachineApi + Send + Sync),
        op: &str,
        start: impl FnOnce(&(dyn MachineApi + Send + Sync)) -> Result<(), ApiError>,
    ) -> Result<(), Outcome> {
        start(m).map_err(|e| api_outcome(op, &e))?;
        // `start_job` sets the state to "running" before it returns.
        let s = self.wait(m, |s| {
            !matches!(s.job.state.as_str(), "running" | "holding")
        });
        match s.job.state.as_str() {
            "done" => Ok(()),
            "aborted" => Err(8),
            _ => {
                if let Some(r) = &s.job.reason {
                    tracing::warn!("script operation cnc.{op}: job {}: {r}", s.job.name);
                }
                Err(7)
            }
        }
    }

    fn wait_homed(&self, m: &(dyn MachineApi + Send + Sync)) -> Outcome {
        let s = self.wait(m, |s| s.mode != Mode::Homing);
        if s.mode == Mode::Idle && s.axes.iter().all(|a| a.homed) {
            0
        } else {
            9
        }
    }

    /// Polls the status until `done` holds (or the worker is told to stop).
    fn wait(&self, m: &(dyn MachineApi + Send + Sync), done: impl Fn(&Status) -> bool) -> Status {
        loop {
            let s = m.status();
            if done(&s) || self.stopped() {
                return s;
            }
            std::thread::sleep(POLL);
        }
    }
}
