//! The script hosts of a machine, by task name: what the control socket's `script.*`
//! methods and `hytask script ...` act on. Each host is a [`ScriptControl`] with the
//! [`Bindings`] of its task (the peers, events and emit flags its scripts may use), set up
//! by whoever deploys the host task (the machine, `hytask run-cell`).
//!
//! Wire format (params of `script.<verb>`; `task` may be omitted when there is one host):
//! ```text
//! → {"method":"script.load","params":{"task":"selection","file":"config/pick.st"}}
//!   (or "source": "<text>" with "file" naming it)           ← {"slot":0,"items":[...]}
//! → {"method":"script.start","params":{"task":"selection","slot":0,"name":"sorter"}}
//!   (also pause, resume, step, stop)                         ← {"ok":true}
//! → {"method":"script.unload","params":{"task":"selection","slot":0}}  ← {"ok":true}
//! → {"method":"script.list"}  ← [{"task":"selection","slot":0,"file":..,"name":"sorter",
//!     "kind":"state_machine","status":"running","state":"homed","line":12,...}]
//! ```

use super::bind::Bindings;
use super::engine::Ctl;
use super::host::{ControlError, ScriptControl};
use serde::Deserialize;
use serde_json::{json, Value};
use std::sync::Arc;

/// Script hosts by task name.
#[derive(Default)]
pub struct ScriptHosts {
    hosts: Vec<(Arc<ScriptControl>, Bindings)>,
}

/// Errors of the script methods.
#[derive(Debug, thiserror::Error)]
pub enum HostsError {
    /// No such host task.
    #[error("no script host task '{0}' (hosts: {1})")]
    NoHost(String, String),
    /// Parameters.
    #[error("bad parameters: {0}")]
    Params(String),
    /// Reading the file.
    #[error("cannot read {0}: {1}")]
    Read(String, std::io::Error),
    /// The control call failed.
    #[error(transparent)]
    Control(#[from] ControlError),
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Params {
    #[serde(default)]
    task: Option<String>,
    #[serde(default)]
    file: Option<String>,
    #[serde(default)]
    source: Option<String>,
    #[serde(default)]
    slot: Option<usize>,
    #[serde(default)]
    name: Option<String>,
}

impl ScriptHosts {
    /// Registers a host task with the names its scripts may use.
    pub fn add(&mut self, control: Arc<ScriptControl>, bindings: Bindings) {
        self.hosts.push((control, bindings));
    }

    /// The host of `task` (or the only one).
    pub fn host(&self, task: Option<&str>) -> Result<&(Arc<ScriptControl>, Bindings), HostsError> {
        let names = || {
            self.hosts
                .iter()
                .map(|h| h.0.task().to_owned())
                .collect::<Vec<_>>()
                .join(", ")
        };
        match task {
            Some(t) => self
                .hosts
                .iter()
                .find(|h| h.0.task() == t)
                .ok_or_else(|| HostsError::NoHost(t.to_owned(), names())),
            None if self.hosts.len() == 1 => Ok(&self.hosts[0]),
            None => Err(HostsError::Params(format!(
                "several script hosts: say which task ({})",
                names()
            ))),
        }
    }

    /// Status of every item of every host, with its task.
    pub fn list(&self) -> Value {
        let mut out = Vec::new();
        for (c, _) in &self.hosts {
            for s in c.status() {
                let mut v = serde_json::to_value(&s).unwrap_or(Value::Null);
                v["task"] = json!(c.task());
                out.push(v);
            }
        }
        Value::Array(out)
    }

    /// Runs `script.<verb>` with JSON params.
    pub fn handle(&self, verb: &str, params: Value) -> Result<Value, HostsError> {
        let params = if params.is_null() { json!({}) } else { params };
        let p: Params =
            serde_json::from_value(params).map_err(|e| HostsError::Params(e.to_string()))?;
        if verb == "list" {
            return Ok(self.list());
        }
        let (c, b) = self.host(p.task.as_deref())?;
        let slot = |p: &Params| -> Result<usize, HostsError> {
            match (p.slot, &p.file) {
                (Some(s), _) => Ok(s),
                (None, Some(f)) => c
                    .slot_of(f)
                    .ok_or_else(|| HostsError::Params(format!("no script loaded from {f}"))),
                _ => Err(HostsError::Params("give slot or file".into())),
            }
        };
        let ctl = match verb {
            "load" => {
                let file = p
                    .file
                    .clone()
                    .ok_or_else(|| HostsError::Params("load needs file".into()))?;
                let src = match &p.source {
                    Some(s) => s.clone(),
                    None => std::fs::read_to_string(&file)
                        .map_err(|e| HostsError::Read(file.clone(), e))?,
                };
                let slot = c.load(&file, &src, b)?;
                let items: Vec<Value> = c
                    .status()
                    .into_iter()
                    .filter(|s| s.slot == slot)
                    .map(|s| json!({"name": s.name, "kind": s.kind}))
                    .collect();
                return Ok(json!({"slot": slot, "items": items}));
            }
            "unload" => {
                c.unload(slot(&p)?)?;
                return Ok(json!({"ok": true}));
            }
            "start" => Ctl::Start,
            "pause" => Ctl::Pause,
            "resume" => Ctl::Resume,
            "step" => Ctl::Step,
            "stop" => Ctl::Stop,
            other => {
                return Err(HostsError::Params(format!(
                    "unknown script method '{other}'"
                )))
            }
        };
        let name = p
            .name
            .clone()
            .ok_or_else(|| HostsError::Params(format!("{verb} needs name")))?;
        c.control(slot(&p)?, &name, ctl)?;
        Ok(json!({"ok": true}))
    }
}
