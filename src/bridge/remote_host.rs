//! A process hosting tasks without a machine (`hytask peer`): a started rt [`Runtime`]
//! seen through [`MachineApi`], so that the ordinary exporter ([`super::Bridge`]) serves its
//! task list, operations, ports and events; plus the liveliness token remote users watch.
//!
//! Only what a task host has is supported: `tasks`, `call`, `status` (threads, no axes),
//! ports and events by name. Machine methods (jog, jobs, homing...) answer "not supported".

use super::{Bridge, BridgeError};
use crate::config::ZenohConfig;
use crate::machine::api::*;
use crate::machine::task_api;
use crate::rt::deploy::Runtime;
use crate::rt::json::{JsonEventReceiver, JsonPortReader};
use crate::rt::prelude::CommandStatus;
use serde_json::Value;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use tokio::sync::broadcast;

/// The runtime of a peer process, as the exporter's [`MachineApi`].
pub struct PeerHost {
    name: String,
    runtime: Mutex<Option<Runtime>>,
    events: broadcast::Sender<MachineEvent>,
    /// Longest wait for an operation's final status (`[zenoh] call_timeout_s`).
    call_timeout: Duration,
}

/// A running peer: its host and exporter (which holds the liveliness token).
/// [`stop`](Self::stop) ends all.
pub struct RunningPeer {
    host: Arc<PeerHost>,
    bridge: Option<Bridge>,
}

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

impl PeerHost {
    /// Serves `runtime` as peer `name` on `session` with the settings of `cfg`.
    pub fn serve(
        session: zenoh::Session,
        runtime: Runtime,
        name: &str,
        cfg: &ZenohConfig,
    ) -> Result<RunningPeer, BridgeError> {
        let host = Arc::new(PeerHost {
            name: name.to_owned(),
            runtime: Mutex::new(Some(runtime)),
            events: broadcast::channel(64).0,
            call_timeout: Duration::from_secs_f64(cfg.call_timeout_s),
        });
        // The exporter declares the liveliness token, as for a machine.
        let bridge = Bridge::start_on(session, host.clone(), name, cfg)?;
        Ok(RunningPeer {
            host,
            bridge: Some(bridge),
        })
    }

    fn with_rt<T>(&self, f: impl FnOnce(&Runtime) -> Result<T, ApiError>) -> Result<T, ApiError> {
        match lock(&self.runtime).as_ref() {
            Some(rt) => f(rt),
            None => Err(ApiError::Rejected("the peer is stopped".into())),
        }
    }
}

impl RunningPeer {
    /// Withdraws the liveliness token, stops exporting, then stops the tasks.
    pub fn stop(mut self) {
        if let Some(b) = self.bridge.take() {
            b.stop();
        }
        if let Some(rt) = lock(&self.host.runtime).take() {
            rt.stop();
        }
    }
}

impl MachineApi for PeerHost {
    fn not_a_machine(&self) -> &'static str {
        "this is a peer process hosting tasks; use `call` on its tasks"
    }
    fn status(&self) -> Status {
        let threads = lock(&self.runtime)
            .as_ref()
            .map(|rt| task_api::thread_timings(&rt.threads()))
            .unwrap_or_default();
        Status {
            machine: self.name.clone(),
            mode: Mode::Idle,
            realtime: lock(&self.runtime).as_ref().is_some_and(Runtime::realtime),
            servo_cycle: threads.first().map_or(0, |t| t.cycles),
            axes: Vec::new(),
            job: JobStatus::default(),
            overrides: Overrides::default(),
            spindle_rpm: 0.0,
            faults: Vec::new(),
            threads,
            inputs: Default::default(),
            outputs: Default::default(),
            probe: ProbeStatus::default(),
            optional_stop: false,
            plc: None,
        }
    }
    fn estop(&self) -> Result<(), ApiError> {
        Err(self.not_a_machine_error("estop"))
    }
    fn estop_reset(&self) -> Result<(), ApiError> {
        Err(self.not_a_machine_error("estop.reset"))
    }
    fn machine_on(&self) -> Result<(), ApiError> {
        Err(self.not_a_machine_error("machine.on"))
    }
    fn machine_off(&self) -> Result<(), ApiError> {
        Err(self.not_a_machine_error("machine.off"))
    }
    fn tasks(&self) -> Vec<TaskInfo> {
        task_api::runtime_task_infos(&self.runtime)
    }
    /// Waits two cycles of every thread first: values a caller published just before its
    /// call (a proxy's forwarded ports) have then been written to the data objects by the
    /// tasks importing them. Then waits for the final status, up to `call_timeout_s`.
    fn call(&self, task: &str, operation: &str, args: &Value) -> Result<Value, ApiError> {
        let threads = self.with_rt(|rt| Ok(rt.threads()))?;
        let cycles = |t: &crate::rt::activity::ThreadInfo| t.stats.summary().wakeup.count;
        let start: Vec<u64> = threads.iter().map(|t| cycles(t)).collect();
        let t0 = Instant::now();
        while threads.iter().zip(&start).any(|(t, c0)| cycles(t) < c0 + 2)
            && t0.elapsed() < self.call_timeout
        {
            std::thread::sleep(Duration::from_millis(1));
        }
        let handle = self.with_rt(|rt| task_api::send_call(rt.tasks(), task, operation, args))?;
        match handle.wait(self.call_timeout) {
            CommandStatus::Done => Ok(serde_json::json!({"status": "done"})),
            CommandStatus::Rejected(r) => Err(ApiError::Rejected(r.to_string())),
            CommandStatus::Failed(why) => Err(ApiError::Failed(why.into())),
            CommandStatus::Pending | CommandStatus::Accepted => Err(ApiError::Timeout(format!(
                "{task}.{operation}: no final status within {:.1} s",
                self.call_timeout.as_secs_f64()
            ))),
        }
    }
    fn subscribe(&self) -> broadcast::Receiver<MachineEvent> {
        self.events.subscribe()
    }
    fn port_json(&self, name: &str) -> Result<Box<dyn JsonPortReader>, ApiError> {
        self.with_rt(|rt| {
            rt.json_reader(name)
                .map_err(|e| ApiError::NotSupported(e.to_string()))
        })
    }
    fn event_json(
        &self,
        name: &str,
        capacity: usize,
    ) -> Result<Box<dyn JsonEventReceiver>, ApiError> {
        self.with_rt(|rt| {
            rt.json_events(name, capacity)
                .map_err(|e| ApiError::NotSupported(e.to_string()))
        })
    }
    fn buffer_json(&self, name: &str) -> Result<Box<dyn JsonEventReceiver>, ApiError> {
        match lock(&self.runtime).as_mut() {
            Some(rt) => rt
                .json_buffer(name)
                .map_err(|e| ApiError::NotSupported(e.to_string())),
            None => Err(ApiError::Rejected("the peer is stopped".into())),
        }
    }
}
