//! `estop` and `estop.reset`.
//!
//! ```text
//! → {"id":1,"method":"estop"}         ← {"id":1,"result":{"ok":true}}
//! → {"id":2,"method":"estop.reset"}   ← {"id":2,"result":{"ok":true}}   (mode becomes "off")
//! ```
//! `estop` is accepted in every mode: all axes quick-stop within one servo cycle and outputs
//! go to their safe state. `estop.reset` is rejected while the e-stop input is still active.

use super::{no_params, ok, ControlError};
use crate::machine::api::MachineApi;
use serde_json::Value;

pub(super) fn handle(m: &dyn MachineApi, params: Value) -> Result<Value, ControlError> {
    no_params(&params)?;
    m.estop()?;
    Ok(ok())
}

pub(super) fn handle_reset(m: &dyn MachineApi, params: Value) -> Result<Value, ControlError> {
    no_params(&params)?;
    m.estop_reset()?;
    Ok(ok())
}
