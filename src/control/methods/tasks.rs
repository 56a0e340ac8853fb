//! `tasks`: every task with its state, thread, operations, events and ports.
//!
//! ```text
//! → {"id":1,"method":"tasks"}
//! ← {"id":1,"result":[{"name":"interpolator","state":"running","thread":"servo",
//!     "operations":[{"name":"hold","doc":"...","params":[]}],"events":["segment_done"],
//!     "ports":["out setpoints"]}, ...]}
//! ```
//! A script host task also has `"scripts"`: its programs and state machines as in
//! `script.list` (status, current state, current line).

use super::{no_params, ControlError};
use crate::machine::api::MachineApi;
use serde_json::Value;

pub(super) fn handle(m: &dyn MachineApi, params: Value) -> Result<Value, ControlError> {
    no_params(&params)?;
    let mut v = serde_json::to_value(m.tasks())
        .map_err(|e| ControlError::new(super::ErrorCode::Failed, e.to_string()))?;
    // Script hosts also list their programs and machines (state, current line).
    for t in v.as_array_mut().into_iter().flatten() {
        let name = t["name"].as_str().unwrap_or_default().to_owned();
        if let Some(s) = super::script::of_task(m, &name) {
            t["scripts"] = s;
        }
    }
    Ok(v)
}
