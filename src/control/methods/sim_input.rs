//! `sim.input`: set a simulated input (sim backends only).
//!
//! ```text
//! → {"id":1,"method":"sim.input","params":{"name":"estop","value":1}}
//! ← {"id":1,"result":{"ok":true}}
//! ```
//! Digital inputs take 0/1 (or true/false); analog inputs take a number. Machines with real
//! I/O answer code 5 (not supported).

use super::{ok, parse, ControlError};
use crate::machine::api::MachineApi;
use serde::Deserialize;
use serde_json::Value;

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Params {
    name: String,
    value: Value,
}

pub(super) fn handle(m: &dyn MachineApi, params: Value) -> Result<Value, ControlError> {
    let p: Params = parse(params)?;
    let v = match p.value {
        Value::Bool(b) => f64::from(u8::from(b)),
        Value::Number(n) => n
            .as_f64()
            .ok_or_else(|| ControlError::params("value out of range"))?,
        _ => return Err(ControlError::params("value must be a number or a boolean")),
    };
    m.set_sim_input(&p.name, v)?;
    Ok(ok())
}
