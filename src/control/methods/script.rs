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
use crate::script::HostsError;
use serde_json::Value;

pub(super) fn handle(m: &dyn MachineApi, verb: &str, params: Value) -> Result<Value, ControlError> {
    let method = format!("script.{verb}");
    if !super::METHODS.contains(&method.as_str()) {
        return Err(ControlError::new(
            ErrorCode::MethodNotFound,
            format!("unknown method '{method}'"),
        ));
    }
    let hosts = m.scripts().ok_or_else(|| {
        ControlError::new(ErrorCode::Failed, "this machine has no script host task")
    })?;
    hosts.handle(verb, params).map_err(to_control)
}

/// Bad or unknown parameters (an unknown field, a task or slot that names nothing) are
/// invalid params (-32602) as for every other method; what fails while running is `Failed`.
fn to_control(e: HostsError) -> ControlError {
    match e {
        HostsError::Params(_) | HostsError::NoHost(..) => ControlError::params(e.to_string()),
        HostsError::Read(..) | HostsError::Control(_) => {
            ControlError::new(ErrorCode::Failed, e.to_string())
        }
    }
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
