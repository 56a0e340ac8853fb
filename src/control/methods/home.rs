//! `home`: home one axis or all of them.
//!
//! ```text
//! → {"id":1,"method":"home","params":{"axis":"X"}}   ← {"id":1,"result":{"ok":true}}
//! → {"id":2,"method":"home"}                          (all axes, in configured order)
//! ```
//! Returns once homing has started; the `mode` event reports `homing` and then `idle`, and
//! `status` shows `homed: true` per axis. Rejected unless the machine is idle.

use super::{ok, parse, ControlError};
use crate::machine::api::MachineApi;
use serde::Deserialize;
use serde_json::Value;

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Params {
    #[serde(default)]
    axis: Option<String>,
}

pub(super) fn handle(m: &dyn MachineApi, params: Value) -> Result<Value, ControlError> {
    let p: Params = parse(params)?;
    m.home(p.axis.as_deref())?;
    Ok(ok())
}
