//! Hosting scripts in a task and controlling them from outside.
//!
//! [`ScriptHost`] is the realtime half: it owns the [`Engine`], applies requests queued by
//! the control half at the start of the task's `state_machines` hook, runs the machines
//! there and the programs in `programs`, and publishes a small status snapshot per item
//! through data objects. [`ScriptControl`] is the non-realtime half (control socket, CLI,
//! tests): it compiles and binds scripts (allocation happens here), queues them with their
//! control requests through a lock-free buffer, reads the snapshots, and drops unloaded
//! scripts handed back by the host (so the realtime side never frees memory).
//! [`ScriptTask`] is a task that only hosts scripts; a task with its own algorithm and
//! operations (the cell's selection task) embeds a [`ScriptHost`] and calls its three
//! methods from its hooks.

use super::bind::{Bindings, Loaded};
use super::engine::{Ctl, Engine, EngineError, Limits, RunStatus, ScriptErrorKind};
use crate::plc::diag::Span;
use crate::plc::{Value, VarId};
use crate::rt::buffer::{buffer, BufferReader, BufferWriter, FullPolicy};
use crate::rt::command::NoCommands;
use crate::rt::data_object::{DataObject, DataReader};
use crate::rt::deploy::Configure;
use crate::rt::event::EventReceiver;
use crate::rt::runner::TaskInfo;
use crate::rt::task::{StepContext, Task, TaskError, TaskState};
use std::sync::Mutex;

/// A status snapshot of one item, published every step (plain data: no allocation).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Snap {
    /// Run status (`None` before the first step after loading).
    pub status: Option<RunStatus>,
    /// Current state index (machines).
    pub state: u32,
    /// Current line.
    pub line: u32,
    /// Transitions taken.
    pub transitions: u64,
    /// The error, with its place.
    pub error: Option<(ScriptErrorKind, Span)>,
}

enum Request {
    Load(usize, Box<Loaded>),
    Unload(usize),
    /// Names are resolved by the control half: nothing here owns heap memory, so nothing
    /// is freed on the realtime side.
    Ctl(usize, usize, Ctl),
    Set(usize, VarId, Value),
}

/// The realtime half: owns the engine.
pub struct ScriptHost {
    engine: Engine,
    rx: BufferReader<Request>,
    garbage: BufferWriter<Box<Loaded>>,
}

/// Requests queued between two steps.
const QUEUE: usize = 64;

impl ScriptHost {
    /// A host and its control half.
    pub fn new(task: &str, limits: Limits) -> (ScriptHost, ScriptControl) {
        let (tx, rx) = buffer(QUEUE, FullPolicy::DropNewest);
        let (gtx, grx) = buffer(limits.max_scripts.max(1) * 2, FullPolicy::DropNewest);
        let host = ScriptHost {
            engine: Engine::new(limits),
            rx,
            garbage: gtx,
        };
        let control = ScriptControl {
            task: task.to_owned(),
            tx,
            garbage: Mutex::new(grx),
            inner: Mutex::new(ControlState {
                slots: (0..limits.max_scripts).map(|_| None).collect(),
                info: None,
            }),
        };
        (host, control)
    }

    /// The engine (for hosts that drive it directly).
    pub fn engine(&mut self) -> &mut Engine {
        &mut self.engine
    }

    /// Applies queued requests, then runs the state machines. Call from
    /// `Task::state_machines`.
    pub fn state_machines(&mut self, now_ns: u64) {
        while let Some(r) = self.rx.pop() {
            // Errors are prevented by the control half's own bookkeeping (names and slots
            // are checked before queueing), so a failing request is ignored here.
            let e = &mut self.engine;
            let _ = match r {
                Request::Load(slot, l) => e.load_boxed(slot, l).map_err(|_| ()),
                Request::Unload(slot) => match e.unload_boxed(slot) {
                    // Freed by the control half; if its queue is full, keep the script
                    // loaded (stopped) rather than free memory here.
                    Some(l) => self.garbage.try_push(l).map_err(|l| {
                        let _ = e.load_boxed(slot, l);
                    }),
                    None => Err(()),
                },
                Request::Ctl(s, i, c) => e.ctl(s, i, c).map_err(|_| ()),
                Request::Set(s, id, v) => {
                    e.set_id(s, id, v);
                    Ok(())
                }
            };
        }
        self.engine.step_state_machines(now_ns);
    }

    /// Runs the programs and publishes the status. Call from `Task::programs`.
    pub fn programs(&mut self, now_ns: u64) {
        self.engine.step_programs(now_ns);
        self.engine.publish();
    }

    /// Stops every running program and machine in error `kind` (the host's machine
    /// e-stopped) and publishes it.
    pub fn fail_all(&mut self, kind: ScriptErrorKind) {
        self.engine.fail_all(kind);
        self.engine.publish();
    }

    /// Stops every program and machine. Call from `Task::stop`.
    pub fn stop(&mut self) {
        self.engine.stop_all();
        self.engine.publish();
    }
}

/// What the control half knows of a loaded script.
struct SlotInfo {
    file: String,
    items: Vec<(String, bool)>,
    states: Vec<Vec<String>>,
    snaps: Vec<DataReader<Snap>>,
    /// Full variable names (upper case) and handles.
    vars: Vec<(String, VarId)>,
}

struct ControlState {
    slots: Vec<Option<SlotInfo>>,
    info: Option<TaskInfo>,
}

/// The non-realtime half: load, control and observe scripts of one host task.
pub struct ScriptControl {
    task: String,
    tx: BufferWriter<Request>,
    garbage: Mutex<BufferReader<Box<Loaded>>>,
    inner: Mutex<ControlState>,
}

/// Errors of script control.
#[derive(Debug, thiserror::Error)]
pub enum ControlError {
    /// Compiling or binding failed (every error, `file:line:col: ...`).
    #[error("{0}")]
    Compile(String),
    /// The host task is not running: scripts follow their task's lifecycle.
    #[error("task '{task}' is {state}, not running: scripts start only while their task runs")]
    NotRunning {
        /// Task.
        task: String,
        /// Its state.
        state: String,
    },
    /// An engine error (slot, name, value).
    #[error(transparent)]
    Engine(#[from] EngineError),
    /// The request queue is full (the task does not step).
    #[error("request queue of task '{0}' is full")]
    QueueFull(String),
}

/// Status of one program or machine as seen from outside.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct ItemStatus {
    /// Script slot.
    pub slot: usize,
    /// Script file.
    pub file: String,
    /// Name.
    pub name: String,
    /// `program` or `state_machine`.
    pub kind: &'static str,
    /// `loading` until the host has stepped once, then the run status.
    pub status: String,
    /// Current state (machines).
    pub state: Option<String>,
    /// Current line.
    pub line: u32,
    /// Transitions taken.
    pub transitions: u64,
    /// The error, `file:line:col: what`.
    pub error: Option<String>,
}

impl ScriptControl {
    /// Ties the control to its deployed task, whose state gates starting.
    pub fn attach(&self, info: TaskInfo) {
        self.lock().info = Some(info);
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, ControlState> {
        self.inner
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    fn send(&self, r: Request) -> Result<(), ControlError> {
        self.tx
            .try_push(r)
            .map_err(|_| ControlError::QueueFull(self.task.clone()))
    }

    fn collect_garbage(&self) {
        let mut g = self
            .garbage
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        g.drain(drop);
    }

    /// Compiles, binds and queues a script; returns its slot.
    pub fn load(&self, file: &str, src: &str, b: &Bindings) -> Result<usize, ControlError> {
        self.collect_garbage();
        let script = super::compile(file, src).map_err(|e| ControlError::Compile(e.to_string()))?;
        let mut loaded = script
            .bind(b)
            .map_err(|e| ControlError::Compile(e.to_string()))?;
        let mut st = self.lock();
        let slot = st
            .slots
            .iter()
            .position(Option::is_none)
            .ok_or(EngineError::Full(st.slots.len()))?;
        let mut snaps = Vec::new();
        let mut writers = Vec::new();
        for (name, _) in loaded.script.items() {
            let d = DataObject::<Snap>::new(&format!("{}.script.{name}", self.task), 2);
            let (Ok(w), Ok(r)) = (d.writer(), d.reader()) else {
                unreachable!("a fresh data object has its writer and a reader");
            };
            writers.push(w);
            snaps.push(r);
        }
        loaded.publish = writers;
        let info = SlotInfo {
            file: file.to_owned(),
            items: loaded
                .script
                .items()
                .map(|(n, m)| (n.to_owned(), m))
                .collect(),
            states: loaded.script.state_names(),
            snaps,
            vars: (0..loaded.script.program.vars().len())
                .map(|i| {
                    let id = VarId(i as u32);
                    (loaded.script.program.info(id).name.to_ascii_uppercase(), id)
                })
                .collect(),
        };
        self.send(Request::Load(slot, Box::new(loaded)))?;
        st.slots[slot] = Some(info);
        Ok(slot)
    }

    /// Unloads a script (stopping its items).
    pub fn unload(&self, slot: usize) -> Result<(), ControlError> {
        let mut st = self.lock();
        if st.slots.get(slot).and_then(Option::as_ref).is_none() {
            return Err(EngineError::NoScript(slot).into());
        }
        self.send(Request::Unload(slot))?;
        st.slots[slot] = None;
        drop(st);
        self.collect_garbage();
        Ok(())
    }

    fn item(&self, slot: usize, name: &str) -> Result<usize, ControlError> {
        let st = self.lock();
        let s = st
            .slots
            .get(slot)
            .and_then(Option::as_ref)
            .ok_or(EngineError::NoScript(slot))?;
        s.items
            .iter()
            .position(|(n, _)| n.eq_ignore_ascii_case(name))
            .ok_or_else(|| EngineError::NoItem(name.to_owned()).into())
    }

    /// Queues control `c` of item `name`; starting, resuming and stepping need the task
    /// running.
    pub fn control(&self, slot: usize, name: &str, c: Ctl) -> Result<(), ControlError> {
        let i = self.item(slot, name)?;
        if matches!(c, Ctl::Start | Ctl::Resume | Ctl::Step) {
            self.running()?;
        }
        self.send(Request::Ctl(slot, i, c))
    }

    fn running(&self) -> Result<(), ControlError> {
        let st = self.lock();
        let state = st.info.as_ref().map(TaskInfo::state);
        if state != Some(TaskState::Running) {
            return Err(ControlError::NotRunning {
                task: self.task.clone(),
                state: state.map_or("not deployed".to_owned(), |s| format!("{s:?}")),
            });
        }
        Ok(())
    }

    /// Writes variable `var` (`item.name` or a global's name) of a loaded script at the
    /// host's next step.
    pub fn set(&self, slot: usize, var: &str, value: Value) -> Result<(), ControlError> {
        let id = {
            let st = self.lock();
            let s = st
                .slots
                .get(slot)
                .and_then(Option::as_ref)
                .ok_or(EngineError::NoScript(slot))?;
            let key = var.to_ascii_uppercase();
            s.vars
                .iter()
                .find(|(n, _)| *n == key)
                .map(|(_, id)| *id)
                .ok_or_else(|| EngineError::NoVar(var.to_owned()))?
        };
        self.send(Request::Set(slot, id, value))
    }

    /// The slot of the script loaded from `file`, if any.
    pub fn slot_of(&self, file: &str) -> Option<usize> {
        self.lock()
            .slots
            .iter()
            .position(|s| s.as_ref().is_some_and(|s| s.file == file))
    }

    /// Status of every item of every loaded script.
    pub fn status(&self) -> Vec<ItemStatus> {
        let mut st = self.lock();
        let mut out = Vec::new();
        for (slot, s) in st.slots.iter_mut().enumerate() {
            let Some(s) = s else { continue };
            for (i, (name, machine)) in s.items.iter().enumerate() {
                let snap = s.snaps[i].latest();
                let snap = snap.unwrap_or_default();
                out.push(ItemStatus {
                    slot,
                    file: s.file.clone(),
                    name: name.clone(),
                    kind: if *machine { "state_machine" } else { "program" },
                    status: match snap.status {
                        None => "loading".into(),
                        Some(r) => serde_json::to_value(r)
                            .ok()
                            .and_then(|v| v.as_str().map(str::to_owned))
                            .unwrap_or_default(),
                    },
                    state: (*machine && snap.status.is_some_and(|r| r != RunStatus::Idle))
                        .then(|| s.states[i].get(snap.state as usize).cloned())
                        .flatten(),
                    line: snap.line,
                    transitions: snap.transitions,
                    error: snap
                        .error
                        .map(|(k, sp)| format!("{}:{}:{}: {k}", s.file, sp.line, sp.col)),
                });
            }
        }
        out
    }

    /// The host task's name.
    pub fn task(&self) -> &str {
        &self.task
    }
}

/// A task that only hosts scripts (peers and events are bound at load by the caller).
///
/// [`ScriptTask::fail_all_on`] makes it also stop every running script in error when an
/// event it subscribes to says so: the mill's `scripts` task stops them when the machine
/// e-stops, so that nothing a script was doing resumes by itself once the e-stop is
/// released. `E` is that event's type (`()`: no such event).
pub struct ScriptTask<E = ()> {
    host: ScriptHost,
    fail_on: Option<FailOn<E>>,
}

/// The event that stops every running script, and in which error.
struct FailOn<E> {
    event: String,
    when: fn(&E) -> bool,
    kind: ScriptErrorKind,
    rx: Option<EventReceiver<E>>,
}

/// Events queued for the task between two steps, enough for a burst of news on the event.
const FAIL_EVENT_QUEUE: usize = 64;

impl ScriptTask {
    /// A script task and its control half.
    pub fn new(name: &str, limits: Limits) -> (ScriptTask, ScriptControl) {
        let (host, control) = ScriptHost::new(name, limits);
        (
            ScriptTask {
                host,
                fail_on: None,
            },
            control,
        )
    }

    /// This task, subscribed (when configured) to `event` (full name): every step in
    /// which one of its events satisfies `when` stops every running script in error
    /// `kind`, at the statement it was at.
    pub fn fail_all_on<E>(
        self,
        event: &str,
        when: fn(&E) -> bool,
        kind: ScriptErrorKind,
    ) -> ScriptTask<E> {
        ScriptTask {
            host: self.host,
            fail_on: Some(FailOn {
                event: event.to_owned(),
                when,
                kind,
                rx: None,
            }),
        }
    }
}

impl<E: Clone + Send + 'static> Task for ScriptTask<E> {
    type Command = NoCommands;
    fn configure(&mut self, ctx: &mut Configure<'_>) -> Result<(), TaskError> {
        if let Some(f) = &mut self.fail_on {
            f.rx = Some(ctx.subscribe(&f.event, FAIL_EVENT_QUEUE));
        }
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
        let Some(FailOn {
            when,
            kind,
            rx: Some(rx),
            ..
        }) = &mut self.fail_on
        else {
            return;
        };
        let mut fail = false;
        while let Some(e) = rx.pop() {
            fail |= when(&e);
        }
        if fail {
            self.host.fail_all(*kind);
        }
    }
    fn stop(&mut self) {
        self.host.stop();
    }
}
