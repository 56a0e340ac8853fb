//! `call`: invoke any task operation by name (the paper's operation interface, exposed).
//!
//! ```text
//! → {"id":1,"method":"call","params":{"task":"spindle","operation":"set_speed","args":{"rpm":8000}}}
//! ← {"id":1,"result":{"status":"done"}}
//! ← {"id":1,"error":{"code":1,"message":"rejected: task 'spindle' is not running"}}
//! ```
//! The command goes through the task's command queue like any other: it is accepted or
//! rejected by the task, and the reply reports its status after acceptance.

use super::{parse, ControlError};
use crate::machine::api::MachineApi;
use serde::Deserialize;
use serde_json::Value;

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Params {
    task: String,
    operation: String,
    #[serde(default)]
    args: Value,
}

pub(super) fn handle(m: &dyn MachineApi, params: Value) -> Result<Value, ControlError> {
    let p: Params = parse(params)?;
    Ok(m.call(&p.task, &p.operation, &p.args)?)
}
