//! `machine.on` and `machine.off`.
//!
//! ```text
//! → {"id":1,"method":"machine.on"}    ← {"id":1,"result":{"ok":true}}   (mode "idle")
//! → {"id":2,"method":"machine.off"}   ← {"id":2,"result":{"ok":true}}   (mode "off")
//! ```
//! `machine.on` enables the drives; it is rejected in e-stop. It also clears a fault once
//! its cause is gone. `machine.off` stops motion under control, then disables the drives.

use super::{no_params, ok, ControlError};
use crate::machine::api::MachineApi;
use serde_json::Value;

pub(super) fn handle_on(m: &dyn MachineApi, params: Value) -> Result<Value, ControlError> {
    no_params(&params)?;
    m.machine_on()?;
    Ok(ok())
}

pub(super) fn handle_off(m: &dyn MachineApi, params: Value) -> Result<Value, ControlError> {
    no_params(&params)?;
    m.machine_off()?;
    Ok(ok())
}
