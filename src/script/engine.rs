//! The script engine: runs loaded programs and state machines a bounded amount per step,
//! inside the host task's step, without allocation, lock or blocking call.
//!
//! Per step ([`Engine::step_state_machines`], then [`Engine::step_programs`], called from the
//! task's `state_machines` and `programs` hooks, the DESIGN's order), every running item
//! executes script instructions until it blocks (a `DO` whose command is not final, a
//! `WAIT` not yet satisfied), ends, takes a transition (a machine takes at most one per
//! step) or has executed [`Limits::ops_per_step`] instructions. One instruction is one ST
//! statement, one condition or one script statement; an ST loop inside one statement is
//! bounded by the PLC's instruction budget (it faults beyond it, as in the PLC).
//!
//! Commands go through the peers' command queues ([`DynCommandSender::send_args`] with an
//! argument vector preallocated at bind, overwritten in place); the engine polls the
//! [`CommandHandle`] on later steps. Events are seen through their emission counters.

use super::bind::Loaded;
use super::code::{CallArg, ItemCode, SOp, NONE};
use crate::plc::diag::Span;
use crate::plc::vm::{FaultKind, Vm};
use crate::plc::{Program, Ty, Value};
use crate::rt::command::{ArgValue, CommandHandle, CommandStatus, RejectReason, SendError};
use std::sync::atomic::Ordering;
use std::sync::Arc;

/// Bounds of the engine.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Limits {
    /// Script instructions one program or machine may execute per step.
    pub ops_per_step: u32,
    /// Scripts loaded at once (slots are preallocated).
    pub max_scripts: usize,
}

impl Default for Limits {
    fn default() -> Self {
        Limits {
            ops_per_step: 64,
            max_scripts: 8,
        }
    }
}

/// Run status of a program or state machine.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum RunStatus {
    /// Loaded, never started.
    Idle,
    /// Running.
    Running,
    /// Paused: runs only when stepped.
    Paused,
    /// Reached its end (a program) or its final state (a machine).
    Finished,
    /// Stopped from outside.
    Stopped,
    /// Stopped by a runtime error.
    Error,
}

/// What went wrong at runtime.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ScriptErrorKind {
    /// A DO's command was rejected.
    Rejected(RejectReason),
    /// A DO's command failed.
    Failed(&'static str),
    /// The peer's command queue was full.
    QueueFull,
    /// The arguments did not fit the operation.
    BadArguments,
    /// A WAIT timed out.
    Timeout,
    /// An ST fault (division by zero, index out of range, budget).
    Fault(FaultKind),
    /// A state's precondition was false and the machine has no ERROR STATE.
    Precondition,
    /// The host's machine went into e-stop (every running item is stopped there).
    Estop,
}

impl std::fmt::Display for ScriptErrorKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Rejected(r) => write!(f, "command rejected: {r}"),
            Self::Failed(w) => write!(f, "command failed: {w}"),
            Self::QueueFull => write!(f, "command queue of the peer is full"),
            Self::BadArguments => write!(f, "arguments do not fit the operation"),
            Self::Timeout => write!(f, "WAIT timed out"),
            Self::Fault(k) => write!(f, "{k}"),
            Self::Precondition => write!(f, "precondition violated (no ERROR STATE)"),
            Self::Estop => write!(f, "stopped by the e-stop"),
        }
    }
}

/// A runtime error with its place in the source.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{file}:{line}:{col}: {kind}")]
pub struct ScriptError {
    /// What.
    pub kind: ScriptErrorKind,
    /// The script file.
    pub file: Arc<str>,
    /// Line.
    pub line: u32,
    /// Column.
    pub col: u32,
}

/// What a program or machine is doing, for status displays.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Status {
    /// Its name.
    pub name: String,
    /// True for a state machine.
    pub machine: bool,
    /// Run status.
    pub status: RunStatus,
    /// Current state (machines).
    pub state: Option<String>,
    /// Line of the current statement (0 when not inside a block).
    pub line: u32,
    /// The error that stopped it.
    pub error: Option<ScriptError>,
    /// Transitions taken so far (machines).
    pub transitions: u64,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Phase {
    /// About to enter `state` (check preconditions, run ENTRY).
    Enter,
    Entry,
    /// Between blocks: check transitions, then RUN.
    In,
    Run,
    /// Running EXIT, then entering `target`.
    Exit,
}

/// Runtime state of one program or machine (allocated at bind).
pub(crate) struct Inst {
    status: RunStatus,
    pc: u32,
    /// The instruction at `pc` has begun (command sent, wait timer running).
    started: bool,
    handle: Option<CommandHandle>,
    since: u64,
    timeout: u64,
    error: Option<(ScriptErrorKind, Span)>,
    step: bool,
    state: u32,
    target: u32,
    phase: Phase,
    /// Emissions of each event seen (consumed) so far: a WAIT or an `ON` needs a newer one.
    marks: Vec<u64>,
    transitions: u64,
}

impl Inst {
    pub(crate) fn new(events: usize) -> Self {
        Inst {
            status: RunStatus::Idle,
            pc: 0,
            started: false,
            handle: None,
            since: 0,
            timeout: 0,
            error: None,
            step: false,
            state: 0,
            target: 0,
            phase: Phase::Enter,
            marks: vec![0; events],
            transitions: 0,
        }
    }
    fn reset(&mut self, pc: u32, state: u32) {
        self.status = RunStatus::Running;
        self.pc = pc;
        self.started = false;
        self.handle = None;
        self.error = None;
        self.step = false;
        self.state = state;
        self.phase = Phase::Enter;
    }
    fn halt(&mut self, status: RunStatus) {
        self.status = status;
        self.handle = None;
        self.started = false;
    }
}

/// How a block's execution stopped this step.
enum Flow {
    /// Budget spent or waiting: continue next step.
    Blocked,
    /// Reached `End`.
    Ended,
    /// Stopped in error (recorded in the instance).
    Error,
}

/// Errors of the engine's control calls.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum EngineError {
    /// Every slot is taken.
    #[error("{0} scripts are loaded already (the engine's limit)")]
    Full(usize),
    /// No script in that slot.
    #[error("no script loaded in slot {0}")]
    NoScript(usize),
    /// No program or machine of that name.
    #[error("no PROGRAM or STATE_MACHINE '{0}' in the script")]
    NoItem(String),
    /// No variable of that name.
    #[error("no variable '{0}' in the script")]
    NoVar(String),
    /// The value does not fit the variable.
    #[error("{0}")]
    Type(#[from] crate::plc::value::TypeMismatch),
}

/// A control request on one program or machine.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Ctl {
    /// Start from the beginning (the initial state).
    Start,
    /// Pause.
    Pause,
    /// Resume after a pause.
    Resume,
    /// One statement (program) or up to one transition (machine), then paused.
    Step,
    /// Stop.
    Stop,
}

/// Runs the loaded scripts of one task.
pub struct Engine {
    limits: Limits,
    slots: Vec<Option<Box<Loaded>>>,
}

/// Runs fragment `f` of `p` with base `base`. A fault is returned with its place.
fn run_frag(
    p: &mut Program,
    entries: &[u32],
    f: u32,
    base: u32,
    now: u64,
) -> Result<(), (ScriptErrorKind, Span)> {
    let entry = entries[f as usize];
    let mut vm = Vm {
        ops: &p.ops,
        mem: &mut p.mem,
        stack: &mut p.stack,
        frames: &mut p.frames,
        now: now as i64,
        fuel: p.budget,
    };
    vm.run(entry, base).map_err(|(k, pc)| {
        (
            ScriptErrorKind::Fault(k),
            p.spans.get(pc as usize).copied().unwrap_or_default(),
        )
    })
}

fn arg_value(ty: Ty, cell: u64, out: &mut ArgValue) {
    *out = match (Value::from_cell(ty, cell), &*out) {
        (Value::Bool(b), _) => ArgValue::Bool(b),
        (Value::Real(v), ArgValue::Int(_)) => ArgValue::Int(v.round() as i64),
        (Value::Real(v), _) => ArgValue::Float(v),
        (Value::Int(v) | Value::Time(v), ArgValue::Float(_)) => ArgValue::Float(v as f64),
        (Value::Int(v) | Value::Time(v), _) => ArgValue::Int(v),
    };
}

/// Executes instructions of item `i` from its `pc`.
fn exec(l: &mut Loaded, i: usize, base: u32, now: u64, budget: &mut u32) -> Flow {
    let Loaded {
        script,
        senders,
        args,
        events,
        emits,
        insts,
        ..
    } = l;
    macro_rules! fail {
        ($kind:expr, $span:expr, $catch:expr) => {{
            let inst = &mut insts[i];
            inst.started = false;
            inst.handle = None;
            if $catch != NONE {
                inst.pc = $catch;
                continue;
            }
            inst.error = Some(($kind, $span));
            inst.halt(RunStatus::Error);
            return Flow::Error;
        }};
    }
    macro_rules! frag {
        ($f:expr) => {
            if let Err((k, sp)) = run_frag(&mut script.program, &script.entries, $f, base, now) {
                fail!(k, sp, NONE)
            }
        };
    }
    loop {
        if *budget == 0 {
            return Flow::Blocked;
        }
        *budget -= 1;
        let pc = insts[i].pc as usize;
        let span = script.spans[pc];
        let mut next = pc as u32 + 1;
        // A run of plain statements the budget covers: its merged fragment, one VM entry.
        // (Single-stepping has a budget of 1: statement by statement.)
        let (run, n) = script.runs[pc];
        if n > 1 && n - 1 <= *budget {
            *budget -= n - 1;
            frag!(run);
            insts[i].pc = pc as u32 + n;
            continue;
        }
        match script.ops[pc] {
            SOp::Exec(f) => frag!(f),
            SOp::JumpIfNot { frag, cell, target } => {
                frag!(frag);
                if script.program.mem[cell as usize] == 0 {
                    next = target;
                }
            }
            SOp::Jump(t) => next = t,
            SOp::Do { call, catch } => {
                if !insts[i].started {
                    let c = &script.calls[call as usize];
                    for (k, a) in c.args.iter().enumerate() {
                        // String literals were put in place at bind time.
                        let CallArg::Value(f, slot) = *a else {
                            continue;
                        };
                        frag!(f);
                        let cell = script.program.mem[slot.addr as usize];
                        arg_value(slot.ty, cell, &mut args[call as usize][k]);
                    }
                    match senders[call as usize].send_args(&c.op, &args[call as usize]) {
                        Ok(h) => {
                            insts[i].handle = Some(h);
                            insts[i].started = true;
                        }
                        Err(SendError::QueueFull(_)) => {
                            fail!(ScriptErrorKind::QueueFull, span, catch)
                        }
                        Err(SendError::Args(_)) => {
                            fail!(ScriptErrorKind::BadArguments, span, catch)
                        }
                    }
                }
                let st = insts[i]
                    .handle
                    .as_ref()
                    .map_or(CommandStatus::Done, |h| h.status());
                match st {
                    CommandStatus::Pending | CommandStatus::Accepted => return Flow::Blocked,
                    CommandStatus::Done => {
                        insts[i].handle = None;
                        insts[i].started = false;
                    }
                    CommandStatus::Rejected(r) => fail!(ScriptErrorKind::Rejected(r), span, catch),
                    CommandStatus::Failed(w) => fail!(ScriptErrorKind::Failed(w), span, catch),
                }
            }
            SOp::WaitEvent {
                event,
                timeout,
                catch,
            } => {
                let count = events[event as usize].count();
                if !insts[i].started {
                    let t = match timeout {
                        Some((f, cell)) => {
                            frag!(f);
                            script.program.mem[cell as usize]
                        }
                        None => u64::MAX,
                    };
                    let inst = &mut insts[i];
                    (inst.started, inst.since, inst.timeout) = (true, now, t);
                }
                let inst = &mut insts[i];
                let seen = &mut inst.marks[event as usize];
                if count > *seen {
                    // Consumes every emission so far: the next WAIT needs a new one.
                    *seen = count;
                    inst.started = false;
                } else if now.saturating_sub(inst.since) >= inst.timeout {
                    fail!(ScriptErrorKind::Timeout, span, catch)
                } else {
                    return Flow::Blocked;
                }
            }
            SOp::WaitUntil {
                frag,
                cell,
                timeout,
                catch,
            } => {
                if !insts[i].started {
                    let t = match timeout {
                        Some((f, c)) => {
                            frag!(f);
                            script.program.mem[c as usize]
                        }
                        None => u64::MAX,
                    };
                    let inst = &mut insts[i];
                    (inst.started, inst.since, inst.timeout) = (true, now, t);
                }
                frag!(frag);
                let inst = &mut insts[i];
                if script.program.mem[cell as usize] != 0 {
                    inst.started = false;
                } else if now.saturating_sub(inst.since) >= inst.timeout {
                    fail!(ScriptErrorKind::Timeout, span, catch)
                } else {
                    return Flow::Blocked;
                }
            }
            SOp::WaitProgram(j) => {
                if matches!(
                    insts[j as usize].status,
                    RunStatus::Running | RunStatus::Paused
                ) {
                    return Flow::Blocked;
                }
            }
            SOp::Start(j) => {
                if let ItemCode::Program(start) = script.items[j as usize].code {
                    insts[j as usize].reset(start, 0);
                    mark_all(&mut insts[j as usize], events);
                }
            }
            SOp::Stop(j) => {
                if matches!(
                    insts[j as usize].status,
                    RunStatus::Running | RunStatus::Paused
                ) {
                    insts[j as usize].halt(RunStatus::Stopped);
                }
            }
            SOp::Emit(e) => {
                emits[e as usize].fetch_add(1, Ordering::Release);
            }
            SOp::End => return Flow::Ended,
        }
        insts[i].pc = next;
        if insts[i].status != RunStatus::Running && insts[i].status != RunStatus::Paused {
            // STOP of itself.
            return Flow::Error;
        }
    }
}

/// Whether every precondition of the current state holds; the first false one's place.
fn preconditions(
    l: &mut Loaded,
    i: usize,
    base: u32,
    now: u64,
) -> Result<(), (ScriptErrorKind, Span)> {
    let ItemCode::Machine { states, .. } = &l.script.items[i].code else {
        return Ok(());
    };
    let st = &states[l.insts[i].state as usize];
    for &(f, cell, span) in &st.pre {
        run_frag(&mut l.script.program, &l.script.entries, f, base, now)?;
        if l.script.program.mem[cell as usize] == 0 {
            return Err((ScriptErrorKind::Precondition, span));
        }
    }
    Ok(())
}

/// One step of machine `i`.
fn step_machine(l: &mut Loaded, i: usize, now: u64, ops: u32) {
    let item = &l.script.items[i];
    let base = item.base;
    let ItemCode::Machine { error, final_, .. } = item.code else {
        return;
    };
    let mut budget = ops;
    let mut took = false;
    loop {
        let phase = l.insts[i].phase;
        if matches!(phase, Phase::Entry | Phase::In | Phase::Run) || phase == Phase::Enter {
            let in_error = Some(l.insts[i].state) == error;
            if !in_error {
                if let Err((kind, span)) = preconditions(l, i, base, now) {
                    let inst = &mut l.insts[i];
                    match error {
                        Some(e) if kind == ScriptErrorKind::Precondition => {
                            inst.handle = None;
                            inst.started = false;
                            inst.state = e;
                            inst.phase = Phase::Enter;
                            inst.transitions += 1;
                            took = true;
                            // Enter the error state now, skipping its own preconditions.
                            enter(l, i);
                            continue;
                        }
                        _ => {
                            inst.error = Some((kind, span));
                            inst.halt(RunStatus::Error);
                            return;
                        }
                    }
                }
            }
        }
        let ItemCode::Machine { states, .. } = &l.script.items[i].code else {
            return;
        };
        let st = &states[l.insts[i].state as usize];
        match l.insts[i].phase {
            Phase::Enter => enter(l, i),
            Phase::Entry => match exec(l, i, base, now, &mut budget) {
                Flow::Blocked | Flow::Error => return,
                Flow::Ended => {
                    if l.insts[i].state == final_ {
                        l.insts[i].halt(RunStatus::Finished);
                        return;
                    }
                    l.insts[i].phase = Phase::In;
                    if took {
                        return;
                    }
                }
            },
            Phase::In => {
                let mut fired = None;
                for t in &st.transitions {
                    if let Some(e) = t.event {
                        if l.events[e as usize].count() <= l.insts[i].marks[e as usize] {
                            continue;
                        }
                    }
                    if let Some((f, cell)) = t.cond {
                        if let Err((k, sp)) =
                            run_frag(&mut l.script.program, &l.script.entries, f, base, now)
                        {
                            l.insts[i].error = Some((k, sp));
                            l.insts[i].halt(RunStatus::Error);
                            return;
                        }
                        if l.script.program.mem[cell as usize] == 0 {
                            continue;
                        }
                    }
                    fired = Some(t.target);
                    break;
                }
                let inst = &mut l.insts[i];
                if let Some(target) = fired {
                    took = true;
                    inst.transitions += 1;
                    inst.target = target;
                    inst.pc = st.exit;
                    inst.phase = Phase::Exit;
                } else if let Some(run) = st.run {
                    inst.pc = run;
                    inst.phase = Phase::Run;
                } else {
                    return;
                }
            }
            Phase::Run => match exec(l, i, base, now, &mut budget) {
                Flow::Blocked | Flow::Error => return,
                Flow::Ended => {
                    l.insts[i].phase = Phase::In;
                    return;
                }
            },
            Phase::Exit => match exec(l, i, base, now, &mut budget) {
                Flow::Blocked | Flow::Error => return,
                Flow::Ended => {
                    let inst = &mut l.insts[i];
                    inst.state = inst.target;
                    inst.phase = Phase::Enter;
                }
            },
        }
    }
}

/// Marks every event's emissions so far as seen.
fn mark_all(inst: &mut Inst, events: &[crate::rt::event::EventCounter]) {
    for (m, c) in inst.marks.iter_mut().zip(events) {
        *m = c.count();
    }
}

/// Enters the current state: event marks, ENTRY from its start.
fn enter(l: &mut Loaded, i: usize) {
    let ItemCode::Machine { states, .. } = &l.script.items[i].code else {
        return;
    };
    let inst = &mut l.insts[i];
    mark_all(inst, &l.events);
    inst.pc = states[inst.state as usize].entry;
    inst.started = false;
    inst.phase = Phase::Entry;
}

impl Engine {
    /// An engine with its slots preallocated.
    pub fn new(limits: Limits) -> Self {
        let mut slots = Vec::with_capacity(limits.max_scripts);
        slots.resize_with(limits.max_scripts, || None);
        Engine { limits, slots }
    }

    /// The limits.
    pub fn limits(&self) -> Limits {
        self.limits
    }

    /// Puts a bound script into a free slot; returns the slot. Nothing runs until started.
    pub fn load(&mut self, script: Loaded) -> Result<usize, EngineError> {
        let s = self
            .slots
            .iter()
            .position(Option::is_none)
            .ok_or(EngineError::Full(self.limits.max_scripts))?;
        self.slots[s] = Some(Box::new(script));
        Ok(s)
    }

    /// Puts a boxed script into slot `slot` (realtime safe: moves a pointer). On error the
    /// script stays with the caller... as an error only when the slot is taken or absent.
    pub(crate) fn load_boxed(
        &mut self,
        slot: usize,
        script: Box<Loaded>,
    ) -> Result<(), Box<Loaded>> {
        match self.slots.get_mut(slot) {
            Some(s @ None) => {
                *s = Some(script);
                Ok(())
            }
            _ => Err(script),
        }
    }

    /// Removes a script (its programs and machines stop; commands in flight continue in
    /// their peers).
    pub fn unload(&mut self, slot: usize) -> Result<(), EngineError> {
        self.unload_boxed(slot)
            .map(drop)
            .ok_or(EngineError::NoScript(slot))
    }

    /// Removes a script and hands it back, so a realtime caller can pass it to a
    /// non-realtime thread to free.
    pub fn unload_boxed(&mut self, slot: usize) -> Option<Box<Loaded>> {
        self.slots.get_mut(slot).and_then(Option::take)
    }

    /// Slots in use.
    pub fn loaded(&self) -> impl Iterator<Item = (usize, &Loaded)> {
        self.slots
            .iter()
            .enumerate()
            .filter_map(|(i, s)| s.as_deref().map(|l| (i, l)))
    }

    fn slot(&mut self, slot: usize) -> Result<&mut Loaded, EngineError> {
        self.slots
            .get_mut(slot)
            .and_then(Option::as_deref_mut)
            .ok_or(EngineError::NoScript(slot))
    }

    fn item(&mut self, slot: usize, name: &str) -> Result<(&mut Loaded, usize), EngineError> {
        let l = self.slot(slot)?;
        let i = l
            .script
            .items
            .iter()
            .position(|it| it.name.eq_ignore_ascii_case(name))
            .ok_or_else(|| EngineError::NoItem(name.to_owned()))?;
        Ok((l, i))
    }

    /// Starts (or restarts from the beginning) a program or state machine.
    pub fn start(&mut self, slot: usize, name: &str) -> Result<(), EngineError> {
        self.ctl_named(slot, name, Ctl::Start)
    }
    /// Pauses: the item runs only when stepped.
    pub fn pause(&mut self, slot: usize, name: &str) -> Result<(), EngineError> {
        self.ctl_named(slot, name, Ctl::Pause)
    }
    /// Resumes a paused item.
    pub fn resume(&mut self, slot: usize, name: &str) -> Result<(), EngineError> {
        self.ctl_named(slot, name, Ctl::Resume)
    }
    /// Pauses the item if it runs, and lets it execute one instruction (a program) or up
    /// to its next transition (a machine) in the next step.
    pub fn step(&mut self, slot: usize, name: &str) -> Result<(), EngineError> {
        self.ctl_named(slot, name, Ctl::Step)
    }
    /// Stops an item.
    pub fn stop(&mut self, slot: usize, name: &str) -> Result<(), EngineError> {
        self.ctl_named(slot, name, Ctl::Stop)
    }

    fn ctl_named(&mut self, slot: usize, name: &str, c: Ctl) -> Result<(), EngineError> {
        let (_, i) = self.item(slot, name)?;
        self.ctl(slot, i, c)
    }

    /// Applies `c` to item `i` of `slot`. Realtime safe.
    pub fn ctl(&mut self, slot: usize, i: usize, c: Ctl) -> Result<(), EngineError> {
        let l = self.slot(slot)?;
        let n = l.insts.len();
        let inst = l
            .insts
            .get_mut(i)
            .ok_or(EngineError::NoItem(String::new()))?;
        let _ = n;
        let active = matches!(inst.status, RunStatus::Running | RunStatus::Paused);
        match c {
            Ctl::Start => match l.script.items[i].code {
                ItemCode::Program(start) => {
                    inst.reset(start, 0);
                    mark_all(inst, &l.events);
                }
                ItemCode::Machine { initial, .. } => {
                    inst.reset(0, initial);
                    inst.transitions = 0;
                }
            },
            Ctl::Pause if inst.status == RunStatus::Running => inst.status = RunStatus::Paused,
            Ctl::Resume if inst.status == RunStatus::Paused => inst.status = RunStatus::Running,
            Ctl::Step if active => {
                inst.status = RunStatus::Paused;
                inst.step = true;
            }
            Ctl::Stop if active => inst.halt(RunStatus::Stopped),
            _ => {}
        }
        Ok(())
    }

    /// Stops every item of every script (the host task stops).
    pub fn stop_all(&mut self) {
        for l in self.slots.iter_mut().flatten() {
            for inst in &mut l.insts {
                if matches!(inst.status, RunStatus::Running | RunStatus::Paused) {
                    inst.halt(RunStatus::Stopped);
                }
            }
        }
    }

    /// Stops every running or paused item in error `kind`, placed at the statement it was
    /// at: the host's machine e-stopped, and a script must not carry on with what it was
    /// doing once the e-stop is released. Realtime safe.
    pub fn fail_all(&mut self, kind: ScriptErrorKind) {
        for l in self.slots.iter_mut().flatten() {
            for inst in &mut l.insts {
                if matches!(inst.status, RunStatus::Running | RunStatus::Paused) {
                    let span = l.script.spans.get(inst.pc as usize).copied();
                    inst.error = Some((kind, span.unwrap_or_default()));
                    inst.halt(RunStatus::Error);
                }
            }
        }
    }

    /// Writes a variable (`item.var` or a global's name).
    pub fn set(&mut self, slot: usize, var: &str, value: Value) -> Result<(), EngineError> {
        let p = &mut self.slot(slot)?.script.program;
        let id = p
            .var(var)
            .ok_or_else(|| EngineError::NoVar(var.to_owned()))?;
        Ok(p.set(id, value)?)
    }

    /// Reads a variable.
    pub fn get(&mut self, slot: usize, var: &str) -> Result<Value, EngineError> {
        let p = &self.slot(slot)?.script.program;
        let id = p
            .var(var)
            .ok_or_else(|| EngineError::NoVar(var.to_owned()))?;
        Ok(p.get(id))
    }

    /// A variable's handle, for writing it every step without a name lookup.
    pub fn var(&mut self, slot: usize, var: &str) -> Result<crate::plc::VarId, EngineError> {
        let p = &self.slot(slot)?.script.program;
        p.var(var).ok_or_else(|| EngineError::NoVar(var.to_owned()))
    }

    /// Writes a variable by handle (realtime safe). Values that do not fit are ignored.
    pub fn set_id(&mut self, slot: usize, id: crate::plc::VarId, value: Value) {
        if let Some(l) = self.slots.get_mut(slot).and_then(Option::as_deref_mut) {
            let _ = l.script.program.set(id, value);
        }
    }

    /// Reads a variable by handle (realtime safe).
    pub fn get_id(&self, slot: usize, id: crate::plc::VarId) -> Option<Value> {
        let l = self.slots.get(slot)?.as_deref()?;
        Some(l.script.program.get(id))
    }

    /// Run status, current state index and whether that state's ENTRY has finished, of
    /// item `i` of `slot`: for a host task that mirrors its machine's state every step
    /// (realtime safe, unlike [`Engine::status`]).
    pub fn machine_state(&self, slot: usize, i: usize) -> Option<(RunStatus, u32, bool)> {
        let inst = self.slots.get(slot)?.as_deref()?.insts.get(i)?;
        let entered = matches!(inst.phase, Phase::In | Phase::Run | Phase::Exit);
        Some((inst.status, inst.state, entered))
    }

    /// Status of every item of a script.
    pub fn status(&self, slot: usize) -> Result<Vec<Status>, EngineError> {
        let l = self
            .slots
            .get(slot)
            .and_then(Option::as_deref)
            .ok_or(EngineError::NoScript(slot))?;
        Ok((0..l.insts.len()).map(|i| item_status(l, i)).collect())
    }

    /// Status of one item.
    pub fn item_status(&self, slot: usize, name: &str) -> Result<Status, EngineError> {
        self.status(slot)?
            .into_iter()
            .find(|s| s.name.eq_ignore_ascii_case(name))
            .ok_or_else(|| EngineError::NoItem(name.to_owned()))
    }

    /// Runs every running (or stepped) state machine once. Realtime safe.
    pub fn step_state_machines(&mut self, now_ns: u64) {
        self.step_kind(now_ns, true);
    }

    /// Runs every running (or stepped) program once. Realtime safe.
    pub fn step_programs(&mut self, now_ns: u64) {
        self.step_kind(now_ns, false);
    }

    /// Publishes every item's status snapshot to the data objects the control half reads.
    pub(crate) fn publish(&mut self) {
        for l in self.slots.iter_mut().flatten() {
            for i in 0..l.publish.len().min(l.insts.len()) {
                let inst = &l.insts[i];
                let active = matches!(inst.status, RunStatus::Running | RunStatus::Paused);
                let line = match inst.error {
                    Some((_, sp)) => sp.line,
                    None if active => l.script.spans.get(inst.pc as usize).map_or(0, |s| s.line),
                    None => 0,
                };
                let snap = super::host::Snap {
                    status: Some(inst.status),
                    state: inst.state,
                    line,
                    transitions: inst.transitions,
                    error: inst.error,
                };
                l.publish[i].set(snap);
            }
        }
    }

    fn step_kind(&mut self, now: u64, machines: bool) {
        let ops = self.limits.ops_per_step;
        for l in self.slots.iter_mut().flatten() {
            for i in 0..l.insts.len() {
                let is_machine = matches!(l.script.items[i].code, ItemCode::Machine { .. });
                if is_machine != machines {
                    continue;
                }
                let inst = &mut l.insts[i];
                let budget = match inst.status {
                    RunStatus::Running => ops,
                    RunStatus::Paused if inst.step => {
                        inst.step = false;
                        if machines {
                            ops
                        } else {
                            1
                        }
                    }
                    _ => continue,
                };
                if machines {
                    step_machine(l, i, now, budget);
                } else {
                    let base = l.script.items[i].base;
                    let mut b = budget;
                    if let Flow::Ended = exec(l, i, base, now, &mut b) {
                        l.insts[i].halt(RunStatus::Finished);
                    }
                }
            }
        }
    }
}

fn item_status(l: &Loaded, i: usize) -> Status {
    let item = &l.script.items[i];
    let inst = &l.insts[i];
    let (machine, state) = match &item.code {
        ItemCode::Program(_) => (false, None),
        ItemCode::Machine { states, .. } => (
            true,
            (inst.status != RunStatus::Idle).then(|| states[inst.state as usize].name.clone()),
        ),
    };
    let active = matches!(inst.status, RunStatus::Running | RunStatus::Paused);
    let line = match inst.error {
        Some((_, sp)) => sp.line,
        None if active && (!machine || inst.phase != Phase::In && inst.phase != Phase::Enter) => {
            l.script.spans.get(inst.pc as usize).map_or(0, |s| s.line)
        }
        None => 0,
    };
    Status {
        name: item.name.clone(),
        machine,
        status: inst.status,
        state,
        line,
        error: inst.error.map(|(kind, sp)| ScriptError {
            kind,
            file: l.script.file.clone(),
            line: sp.line,
            col: sp.col,
        }),
        transitions: inst.transitions,
    }
}
