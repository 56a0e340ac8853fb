//! `script.load`, `script.start`, `script.pause`, `script.resume`, `script.step`,
//! `script.stop`, `script.unload`, `script.list`: programs and state machines of the
//! machine's script host tasks. Wire format: [`crate::script::hosts`].
//!
//! ```text
//! → {"id":1,"method":"script.load","params":{"task":"selection","file":"config/pick.st"}}
//! ← {"id":1,"result":{"slot":0,"items":[{"name":"sorter","kind":"state_machine"}]}}
//! → {"id":2,"method":"script.start","params":{"slot":0,"name":"sorter"}}
//! ← {"id":2,"result":{"ok":true}}
//! ← {"id":3,"error":{"code":1,"message":"pick.st:4:7: unknown event 'cam.seen'"}}
//! ```

use super::{ControlError, ErrorCode};
use crate::machine::api::MachineApi;
use serde_json::Value;

pub(super) fn handle(m: &dyn MachineApi, verb: &str, params: Value) -> Result<Value, ControlError> {
    let hosts = m.scripts().ok_or_else(|| {
        ControlError::new(ErrorCode::Failed, "this machine has no script host task")
    })?;
    hosts
        .handle(verb, params)
        .map_err(|e| ControlError::new(ErrorCode::Failed, e.to_string()))
}

/// Script status per task, for `tasks`.
pub(super) fn of_task(m: &dyn MachineApi, task: &str) -> Option<Value> {
    let list = m.scripts()?.list();
    let items: Vec<Value> = list
        .as_array()?
        .iter()
        .filter(|v| v["task"] == task)
        .cloned()
        .collect();
    (!items.is_empty()).then_some(Value::Array(items))
}
