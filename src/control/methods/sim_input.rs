//! `sim.input` and `sim.fault`: set a simulated input, inject a fault (sim backends only).
//!
//! ```text
//! → {"id":1,"method":"sim.input","params":{"name":"estop","value":1}}
//! ← {"id":1,"result":{"ok":true}}
//! ```
//! Digital inputs take 0/1 (or true/false); analog inputs take a number. Machines with real
//! I/O answer code 5 (not supported).
//!
//! ```text
//! → {"id":2,"method":"sim.fault","params":{"kind":"stall","axis":"X"}}
//! → {"id":3,"method":"sim.fault","params":{"kind":"drive_fault","axis":"Y","code":8977}}
//! → {"id":4,"method":"sim.fault","params":{"kind":"disconnect","axis":"Z","on":false}}
//! → {"id":5,"method":"sim.fault","params":{"kind":"overrun","cycles":5}}
//! ← {"id":n,"result":{"ok":true}}
//! ```
//! For trying the safety paths on the simulated machine: a stall makes the following error
//! grow, a drive fault puts the drive in Fault, a disconnect makes its calls fail, an
//! overrun makes the servo thread miss its deadline `cycles` times in a row.

use super::{ok, parse, ControlError};
use crate::machine::api::{MachineApi, SimFault};
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

pub(super) fn handle_fault(m: &dyn MachineApi, params: Value) -> Result<Value, ControlError> {
    let f: SimFault = parse(params)?;
    m.sim_fault(&f)?;
    Ok(ok())
}
