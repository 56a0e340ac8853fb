//! Compiled form of a script: the script-level instructions that sequence PLC fragments
//! across steps, and the tables of peers, events and states they refer to. Produced by
//! [`super::compile`], bound to the rt handles by [`super::bind`], run by [`super::engine`].

use crate::plc::compile::fragment::Slot;
use crate::plc::diag::Span;
use crate::plc::Program;
use std::sync::Arc;

/// "No target" for jumps that are absent (no enclosing TRY).
pub(crate) const NONE: u32 = u32::MAX;

/// A script instruction. `frag` is a fragment index (into `Script::entries`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum SOp {
    /// Run a plain ST fragment.
    Exec(u32),
    /// Evaluate a BOOL fragment; jump to `target` when false.
    JumpIfNot { frag: u32, cell: u32, target: u32 },
    /// Jump.
    Jump(u32),
    /// Send command `call` and wait for a final status; errors go to `catch`.
    Do { call: u32, catch: u32 },
    /// Wait for event `event` (an emission after the wait began).
    WaitEvent {
        event: u32,
        timeout: Option<(u32, u32)>,
        catch: u32,
    },
    /// Wait until a BOOL fragment holds.
    WaitUntil {
        frag: u32,
        cell: u32,
        timeout: Option<(u32, u32)>,
        catch: u32,
    },
    /// Wait until program `item` is no longer running.
    WaitProgram(u32),
    /// Start program `item` (from its beginning).
    Start(u32),
    /// Stop program `item`.
    Stop(u32),
    /// Raise emit flag `emit`.
    Emit(u32),
    /// End of a block.
    End,
}

/// A `DO peer.op(args)` site.
#[derive(Debug, Clone)]
pub(crate) struct Call {
    pub peer: String,
    pub op: String,
    /// One argument per parameter.
    pub args: Vec<CallArg>,
    pub span: Span,
}

/// An argument of a `DO` site.
#[derive(Debug, Clone)]
pub(crate) enum CallArg {
    /// The value fragment computing it and the slot it leaves the value in.
    Value(u32, Slot),
    /// A string literal.
    Str(String),
}

/// A transition.
#[derive(Debug, Clone)]
pub(crate) struct TransCode {
    pub event: Option<u32>,
    pub cond: Option<(u32, u32)>,
    pub target: u32,
}

/// A state.
#[derive(Debug, Clone)]
pub(crate) struct StateCode {
    pub name: String,
    /// (fragment, cell, where) of each precondition.
    pub pre: Vec<(u32, u32, Span)>,
    pub entry: u32,
    pub run: Option<u32>,
    pub exit: u32,
    pub transitions: Vec<TransCode>,
}

/// What an item is.
#[derive(Debug, Clone)]
pub(crate) enum ItemCode {
    /// A program starting at this instruction.
    Program(u32),
    /// A state machine.
    Machine {
        states: Vec<StateCode>,
        initial: u32,
        final_: u32,
        error: Option<u32>,
    },
}

/// A program or state machine.
#[derive(Debug, Clone)]
pub(crate) struct ItemDef {
    pub name: String,
    /// Base address of its variables.
    pub base: u32,
    pub code: ItemCode,
}

/// A compiled script file, not yet bound to a task's peers and events.
#[derive(Debug, Clone)]
pub struct Script {
    pub(crate) file: Arc<str>,
    pub(crate) program: Program,
    pub(crate) entries: Vec<u32>,
    pub(crate) ops: Vec<SOp>,
    pub(crate) spans: Vec<Span>,
    /// Per op: `(fragment, n)` when a run of `n` plain statements starts there whose
    /// merged fragment may replace them (`(NONE, 0)` elsewhere).
    pub(crate) runs: Vec<(u32, u32)>,
    pub(crate) items: Vec<ItemDef>,
    pub(crate) calls: Vec<Call>,
    /// Event names (full) and where first used.
    pub(crate) events: Vec<(String, Span)>,
    /// EMIT names and where first used.
    pub(crate) emits: Vec<(String, Span)>,
}

impl Script {
    /// The source file name.
    pub fn file(&self) -> &str {
        &self.file
    }
    /// Names of the programs and state machines, in source order, with `true` for a state
    /// machine.
    pub fn items(&self) -> impl Iterator<Item = (&str, bool)> {
        self.items
            .iter()
            .map(|i| (i.name.as_str(), matches!(i.code, ItemCode::Machine { .. })))
    }
    /// Peers and operations called (`peer.op`), for checking a deployment.
    pub fn operations(&self) -> impl Iterator<Item = (&str, &str)> {
        self.calls.iter().map(|c| (c.peer.as_str(), c.op.as_str()))
    }
    /// Events waited for or transitioned on.
    pub fn events(&self) -> impl Iterator<Item = &str> {
        self.events.iter().map(|e| e.0.as_str())
    }
    /// State names of every item (empty for programs).
    pub(crate) fn state_names(&self) -> Vec<Vec<String>> {
        self.items
            .iter()
            .map(|i| match &i.code {
                ItemCode::Program(_) => Vec::new(),
                ItemCode::Machine { states, .. } => states.iter().map(|s| s.name.clone()).collect(),
            })
            .collect()
    }
    /// Names raised by EMIT.
    pub fn emits(&self) -> impl Iterator<Item = &str> {
        self.emits.iter().map(|e| e.0.as_str())
    }
}
