//! The mill's script host: programs and state machines (`src/script/`) loaded at runtime
//! on the daemon, commanding the machine as an operator would.
//!
//! Two tasks on a non-servo thread (the lowest-priority `[[thread]]` other than the servo
//! thread, e.g. the PLC's; a 10 ms thread of priority 10 when there is none), after the
//! servo tasks:
//! - `cnc` ([`cnc`]): the operator operations as a peer (`DO cnc.home();`, `DO
//!   cnc.run('part.ngc');`) and the machine's news as events (`WAIT cnc.job_done;`), carried
//!   out by the operator worker thread ([`worker`]);
//! - `scripts` (a [`ScriptTask`]): hosts the scripts, stops every running one in error
//!   ("stopped by the e-stop", at the statement it was at) when the machine e-stops, so
//!   that nothing a script was doing resumes by itself once the e-stop is released.
//!
//! Registered as the machine's [`ScriptHosts`], so `script.*` on the control socket and
//! `hytask script ...` load, run and show them, and `hytask tasks` lists their state.
//! Roles: `script.*` are operator methods (`control::access`), like `job.run`.

pub mod cnc;
mod worker;

use crate::config::MachineConfig;
use crate::machine::api::MachineApi;
use crate::machine::api::Mode;
use crate::machine::devices::IoMap;
use crate::machine::servo::ModeEvent;
use crate::rt::prelude::*;
use crate::script::{Bindings, Limits, ScriptControl, ScriptErrorKind, ScriptHosts, ScriptTask};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, Weak};

/// Name of the task hosting the scripts.
pub const HOST: &str = "scripts";
/// Name of the operator task (the scripts' peer).
pub const CNC: &str = "cnc";

/// The thread the script tasks run on: the lowest-priority non-servo thread of the
/// config, or a 10 ms thread of priority 10.
fn schedule(config: &MachineConfig) -> Schedule {
    let servo = config.motion.servo_thread.as_str();
    config
        .threads
        .iter()
        .filter(|t| t.name != servo)
        .min_by_key(|t| t.priority)
        .map_or(
            Schedule {
                priority: 10,
                period_ns: 10_000_000,
                cpu: None,
            },
            |t| Schedule {
                priority: i32::from(t.priority),
                period_ns: u64::from(t.period_us) * 1000,
                cpu: t.cpu.map(|c| c as usize),
            },
        )
}

/// The script tasks added to a deployment that is not configured yet.
pub struct Added {
    control: Arc<ScriptControl>,
    cnc: TaskInfo,
    shared: Arc<cnc::Shared>,
    rx: cnc::Requests,
}

/// Adds tasks `cnc` and `scripts` to `app`.
pub fn add(app: &mut Deployment, config: &MachineConfig) -> Result<Added, DeployError> {
    let s = schedule(config);
    let shared = cnc::Shared::new();
    let (task, rx) = cnc::CncTask::new(shared.clone());
    let cnc = app.add_periodic(CNC, task, s)?.info().clone();
    let (task, control) = ScriptTask::new(HOST, Limits::default());
    let task = task.fail_all_on(
        "machine.mode",
        |m: &ModeEvent| m.mode == Mode::Estop,
        ScriptErrorKind::Estop,
    );
    let host = app.add_periodic(HOST, task, s)?;
    control.attach(host.info().clone());
    Ok(Added {
        control: Arc::new(control),
        cnc,
        shared,
        rx,
    })
}

/// The machine's script hosts and the operator worker.
pub struct Scripts {
    hosts: ScriptHosts,
    pending: Mutex<Option<(cnc::Requests, IoMap)>>,
    shared: Arc<cnc::Shared>,
    stop: Arc<AtomicBool>,
    worker: Mutex<Option<std::thread::JoinHandle<()>>>,
}

impl Added {
    /// Binds the names scripts may use, once `app` is configured (its events exist).
    pub fn bind(self, app: &Deployment, io_map: IoMap) -> Result<Scripts, DeployError> {
        let mut b = Bindings::default();
        b.peer_task(&self.cnc);
        for e in cnc::EVENTS {
            let name = format!("{CNC}.{e}");
            b.event(&name, app.event_counter(&name)?);
        }
        let mut hosts = ScriptHosts::default();
        hosts.add(self.control, b);
        Ok(Scripts {
            hosts,
            pending: Mutex::new(Some((self.rx, io_map))),
            shared: self.shared,
            stop: Arc::new(AtomicBool::new(false)),
            worker: Mutex::new(None),
        })
    }
}

impl Scripts {
    /// The hosts, for `MachineApi::scripts`.
    pub fn hosts(&self) -> &ScriptHosts {
        &self.hosts
    }

    /// Starts the operator worker on `machine` (once).
    pub fn start(&self, machine: Weak<dyn MachineApi + Send + Sync>) -> std::io::Result<()> {
        let Some((rx, io_map)) = lock(&self.pending).take() else {
            return Ok(());
        };
        let w = worker::Worker {
            shared: self.shared.clone(),
            rx,
            machine,
            io_map,
            stop: self.stop.clone(),
        };
        let h = std::thread::Builder::new()
            .name("cnc-operator".into())
            .spawn(move || w.run())?;
        let _ = self.shared.worker.set(h.thread().clone());
        *lock(&self.worker) = Some(h);
        Ok(())
    }

    /// Stops the worker (a command it carries out ends where it is).
    pub fn stop(&self) {
        self.stop.store(true, Ordering::Release);
        if let Some(h) = lock(&self.worker).take() {
            h.thread().unpark();
            let _ = h.join();
        }
    }
}

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}
