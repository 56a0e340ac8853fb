//! `plc.vars`, `plc.get`, `plc.set`, `plc.force`, `plc.unforce`, `plc.load`: the running
//! PLC online (issue 11). Reads are open to observers; writes, forces and loads need the
//! operator role ([`crate::control::access`]).
//!
//! ```text
//! → {"id":1,"method":"plc.vars","params":{"filter":"door"}}
//! ← {"id":1,"result":[{"name":"Mill.door_open","type":"BOOL","value":"FALSE",
//!     "forced":false,"retain":false}]}
//! → {"id":2,"method":"plc.get","params":{"name":"lube_count"}}
//! ← {"id":2,"result":{"name":"Mill.lube_count","type":"DINT","value":"3",...}}
//! → {"id":3,"method":"plc.set","params":{"name":"lube_count","value":"0"}}
//! → {"id":4,"method":"plc.force","params":{"name":"door_open","value":"TRUE"}}
//! ← {"id":n,"result":{"name":"Mill.door_open","type":"BOOL","value":"TRUE","forced":true,...}}
//! → {"id":5,"method":"plc.unforce","params":{"name":"door_open"}}   (no name: every force)
//! ← {"id":5,"result":{"ok":true}}
//! → {"id":6,"method":"plc.load","params":{"file":"mill.st","source":"PROGRAM ..."}}
//! ← {"id":6,"result":{"generation":2,"kept":["Mill.door_open",...],"reset":[...],
//!     "removed":[...],"unforced":0}}
//! ← {"id":6,"error":{"code":1,"message":"mill.st:12:5: undeclared variable 'x'\n..."}}
//! ```
//! Values are IEC literals (`TRUE`, `42`, `1.5`, `T#1s500ms`, enumeration names). A write is
//! applied at the start of the next scan and answered after it; `plc.load` without
//! `source` reads `file` on the daemon's host.

use super::{ok, parse, ControlError, ErrorCode};
use crate::machine::api::MachineApi;
use crate::plc::online::{OnlineError, PlcOnline};
use serde::Deserialize;
use serde_json::Value;

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Vars {
    #[serde(default)]
    filter: Option<String>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Name {
    #[serde(default)]
    name: Option<String>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Write {
    name: String,
    value: Value,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Load {
    file: String,
    #[serde(default)]
    source: Option<String>,
}

fn failed(e: OnlineError) -> ControlError {
    let code = match e {
        OnlineError::UnknownVar(_) | OnlineError::BadValue { .. } | OnlineError::Constant(_) => {
            ErrorCode::InvalidParams
        }
        _ => ErrorCode::Failed,
    };
    ControlError::new(code, e.to_string())
}

fn json(v: impl serde::Serialize) -> Result<Value, ControlError> {
    serde_json::to_value(v).map_err(|e| ControlError::new(ErrorCode::Failed, e.to_string()))
}

/// A value given as a JSON boolean or number is taken as its literal.
fn literal(v: &Value) -> Result<String, ControlError> {
    match v {
        Value::String(s) => Ok(s.clone()),
        Value::Bool(b) => Ok(if *b { "TRUE" } else { "FALSE" }.into()),
        Value::Number(n) => Ok(n.to_string()),
        _ => Err(ControlError::params(
            "value must be an IEC literal (string), a number or a boolean",
        )),
    }
}

pub(super) fn handle(m: &dyn MachineApi, verb: &str, params: Value) -> Result<Value, ControlError> {
    let plc: &PlcOnline = m
        .plc()
        .ok_or_else(|| ControlError::new(ErrorCode::Failed, "this machine has no [plc]"))?;
    match verb {
        "vars" => {
            let p: Vars = parse(params)?;
            json(plc.vars(p.filter.as_deref()).map_err(failed)?)
        }
        "get" => {
            let p: Name = parse(params)?;
            let name = p.name.ok_or_else(|| ControlError::params("missing name"))?;
            json(plc.get(&name).map_err(failed)?)
        }
        "set" | "force" => {
            let p: Write = parse(params)?;
            let value = literal(&p.value)?;
            let r = if verb == "set" {
                plc.set(&p.name, &value)
            } else {
                plc.force(&p.name, &value)
            };
            json(r.map_err(failed)?)
        }
        "unforce" => {
            let p: Name = parse(params)?;
            plc.unforce(p.name.as_deref()).map_err(failed)?;
            Ok(ok())
        }
        "load" => {
            let p: Load = parse(params)?;
            let source = match p.source {
                Some(s) => s,
                None => std::fs::read_to_string(&p.file).map_err(|e| {
                    ControlError::new(ErrorCode::Failed, format!("cannot read {}: {e}", p.file))
                })?,
            };
            json(plc.load(&p.file, &source).map_err(failed)?)
        }
        other => Err(ControlError::new(
            ErrorCode::MethodNotFound,
            format!("unknown method 'plc.{other}'"),
        )),
    }
}
