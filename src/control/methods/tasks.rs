//! `tasks`: every task with its state, thread, operations, events and ports.
//!
//! ```text
//! → {"id":1,"method":"tasks"}
//! ← {"id":1,"result":[{"name":"interpolator","state":"running","thread":"servo",
//!     "operations":[{"name":"hold","doc":"...","params":[]}],"events":["segment_done"],
//!     "ports":["out setpoints"]}, ...]}
//! ```

use super::{no_params, ControlError};
use crate::machine::api::MachineApi;
use serde_json::Value;

pub(super) fn handle(m: &dyn MachineApi, params: Value) -> Result<Value, ControlError> {
    no_params(&params)?;
    serde_json::to_value(m.tasks())
        .map_err(|e| ControlError::new(super::ErrorCode::Failed, e.to_string()))
}
