//! Binding a compiled script to a task's surroundings: every peer operation, event and
//! EMIT name is resolved once, off the realtime path, to the rt handle the engine uses
//! (command senders, event counters, emit flags). Unknown names are errors with
//! `file:line:col`; after binding nothing is looked up by name again.

use super::code::{CallArg, Script};
use super::engine::Inst;
use crate::plc::diag::{Diag, Diags};
use crate::rt::command::{ArgType, ArgValue, DynCommandSender};
use crate::rt::event::EventCounter;
use crate::rt::runner::TaskInfo;
use std::collections::HashMap;
use std::sync::atomic::AtomicU64;
use std::sync::Arc;

/// Names a script may use, mapped to rt handles. Built by the host (non-realtime).
#[derive(Default, Clone)]
pub struct Bindings {
    peers: HashMap<String, Arc<dyn DynCommandSender>>,
    events: HashMap<String, EventCounter>,
    emits: HashMap<String, Arc<AtomicU64>>,
}

impl std::fmt::Debug for Bindings {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Bindings")
            .field("peers", &self.peers.keys().collect::<Vec<_>>())
            .field("events", &self.events.keys().collect::<Vec<_>>())
            .field("emits", &self.emits.keys().collect::<Vec<_>>())
            .finish()
    }
}

impl Bindings {
    /// Makes peer `name` callable with `DO name.op(...)`.
    pub fn peer(&mut self, name: &str, sender: Arc<dyn DynCommandSender>) -> &mut Self {
        self.peers.insert(name.to_owned(), sender);
        self
    }
    /// Makes a deployed task callable under its own name.
    pub fn peer_task(&mut self, task: &TaskInfo) -> &mut Self {
        self.peer(task.name(), task.shared.sender.clone())
    }
    /// Makes event `name` (full name, `task.event`) usable in WAIT and TRANSITION ON.
    pub fn event(&mut self, name: &str, counter: EventCounter) -> &mut Self {
        self.events.insert(name.to_owned(), counter);
        self
    }
    /// Makes `EMIT name;` raise `flag` (incremented per EMIT; the host turns it into an event
    /// or anything else).
    pub fn emit(&mut self, name: &str, flag: Arc<AtomicU64>) -> &mut Self {
        self.emits.insert(name.to_owned(), flag);
        self
    }
}

/// Binding failed: every unknown name, with where it is used.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct BindError(pub Diags);

/// A script bound to its handles, with its runtime state allocated: ready for
/// [`Engine::load`](super::Engine::load).
pub struct Loaded {
    pub(crate) script: Script,
    pub(crate) senders: Vec<Arc<dyn DynCommandSender>>,
    pub(crate) args: Vec<Vec<ArgValue>>,
    pub(crate) events: Vec<EventCounter>,
    pub(crate) emits: Vec<Arc<AtomicU64>>,
    pub(crate) insts: Vec<Inst>,
    /// Status snapshot writers, one per item (set by the control half; may be empty).
    pub(crate) publish: Vec<crate::rt::data_object::DataWriter<super::host::Snap>>,
}

impl std::fmt::Debug for Loaded {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Loaded")
            .field("file", &self.script.file)
            .finish_non_exhaustive()
    }
}

impl Loaded {
    /// The script.
    pub fn script(&self) -> &Script {
        &self.script
    }
}

impl Script {
    /// Resolves every name against `b`. Operation names and argument counts are checked
    /// against the peer's descriptors.
    pub fn bind(self, b: &Bindings) -> Result<Loaded, BindError> {
        let mut errs = Vec::new();
        let mut senders = Vec::new();
        let mut args = Vec::new();
        for c in &self.calls {
            let Some(s) = b.peers.get(&c.peer) else {
                errs.push(Diag::new(c.span, format!("unknown peer task '{}'", c.peer)));
                continue;
            };
            match s.operations().iter().find(|o| o.name == c.op) {
                None => errs.push(Diag::new(
                    c.span,
                    format!("task '{}' has no operation '{}'", c.peer, c.op),
                )),
                Some(o) if o.params.len() != c.args.len() => errs.push(Diag::new(
                    c.span,
                    format!(
                        "operation '{}.{}' takes {} argument(s), got {}",
                        c.peer,
                        c.op,
                        o.params.len(),
                        c.args.len()
                    ),
                )),
                Some(o) => {
                    // Preallocated argument vector: the step overwrites the values in place;
                    // string literals are set here, once.
                    let mut v = Vec::with_capacity(o.params.len());
                    for (k, (p, a)) in o.params.iter().zip(&c.args).enumerate() {
                        v.push(match (p.ty, a) {
                            (ArgType::Str, CallArg::Str(s)) => ArgValue::Str(s.clone()),
                            (ArgType::Str, CallArg::Value(..)) | (_, CallArg::Str(_)) => {
                                let want = if p.ty == ArgType::Str {
                                    "a string literal"
                                } else {
                                    "a value, not a string"
                                };
                                errs.push(Diag::new(
                                    c.span,
                                    format!(
                                        "argument {} ('{}') of '{}.{}' must be {want}",
                                        k + 1,
                                        p.name,
                                        c.peer,
                                        c.op
                                    ),
                                ));
                                ArgValue::Bool(false)
                            }
                            (ArgType::Bool, _) => ArgValue::Bool(false),
                            (ArgType::Int, _) => ArgValue::Int(0),
                            (ArgType::Float, _) => ArgValue::Float(0.0),
                        });
                    }
                    args.push(v);
                    senders.push(s.clone());
                }
            }
        }
        let mut events = Vec::new();
        for (name, span) in &self.events {
            match b.events.get(name) {
                Some(c) => events.push(c.clone()),
                None => errs.push(Diag::new(*span, format!("unknown event '{name}'"))),
            }
        }
        let mut emits = Vec::new();
        for (name, span) in &self.emits {
            match b.emits.get(name) {
                Some(f) => emits.push(f.clone()),
                None => errs.push(Diag::new(
                    *span,
                    format!("EMIT {name}: the host task declares no such event"),
                )),
            }
        }
        for c in &self.calls {
            for a in &c.args {
                if matches!(a, CallArg::Value(_, slot) if !slot.ty.scalar()) {
                    errs.push(Diag::new(c.span, "arguments must be elementary values"));
                }
            }
        }
        if !errs.is_empty() {
            errs.sort_by_key(|d| d.span);
            return Err(BindError(Diags {
                file: self.file.to_string(),
                list: errs,
            }));
        }
        let insts = self
            .items
            .iter()
            .map(|_| Inst::new(self.events.len()))
            .collect();
        Ok(Loaded {
            script: self,
            senders,
            args,
            events,
            emits,
            insts,
            publish: Vec::new(),
        })
    }
}
