//! The control methods, one file per method (or per small family), each with its wire
//! format in the doc comment. [`dispatch`] maps a method name to its handler.
//!
//! `subscribe` and `unsubscribe` are per-connection and live in the server.

use super::protocol::{ControlError, ErrorCode};
use crate::machine::api::MachineApi;
use serde::de::DeserializeOwned;
use serde_json::Value;

mod call;
mod drive;
mod estop;
mod home;
mod job;
mod jog;
mod machine_power;
mod mdi;
mod overrides;
mod plc;
mod script;
mod sim_input;
mod status;
mod tasks;

/// Every method name the socket understands, for `help` and error messages.
pub const METHODS: &[&str] = &[
    "status",
    "subscribe",
    "unsubscribe",
    "estop",
    "estop.reset",
    "machine.on",
    "machine.off",
    "home",
    "jog",
    "jog.stop",
    "mdi",
    "job.load",
    "job.run",
    "job.pause",
    "job.resume",
    "job.abort",
    "job.step",
    "job.optional_stop",
    "override",
    "tasks",
    "call",
    "sim.input",
    "sim.fault",
    "drive.sdo_read",
    "drive.sdo_write",
    "script.load",
    "script.start",
    "script.pause",
    "script.resume",
    "script.step",
    "script.stop",
    "script.unload",
    "script.list",
    "plc.vars",
    "plc.get",
    "plc.set",
    "plc.force",
    "plc.unforce",
    "plc.load",
];

/// Runs one method against the machine.
pub fn dispatch(m: &dyn MachineApi, method: &str, params: Value) -> Result<Value, ControlError> {
    match method {
        "status" => status::handle(m, params),
        "estop" => estop::handle(m, params),
        "estop.reset" => estop::handle_reset(m, params),
        "machine.on" => machine_power::handle_on(m, params),
        "machine.off" => machine_power::handle_off(m, params),
        "home" => home::handle(m, params),
        "jog" => jog::handle(m, params),
        "jog.stop" => jog::handle_stop(m, params),
        "mdi" => mdi::handle(m, params),
        "job.load" => job::handle_load(m, params),
        "job.run" => job::handle_run(m, params),
        "job.pause" => job::handle_pause(m, params),
        "job.resume" => job::handle_resume(m, params),
        "job.abort" => job::handle_abort(m, params),
        "job.step" => job::handle_step(m, params),
        "job.optional_stop" => job::handle_optional_stop(m, params),
        "override" => overrides::handle(m, params),
        "tasks" => tasks::handle(m, params),
        "call" => call::handle(m, params),
        "sim.input" => sim_input::handle(m, params),
        "sim.fault" => sim_input::handle_fault(m, params),
        "drive.sdo_read" => drive::handle_read(m, params),
        "drive.sdo_write" => drive::handle_write(m, params),
        other if other.starts_with("plc.") => plc::handle(m, &other[4..], params),
        other if other.starts_with("script.") => script::handle(m, &other[7..], params),
        other => Err(ControlError::new(
            ErrorCode::MethodNotFound,
            format!("unknown method '{other}' (methods: {})", METHODS.join(", ")),
        )),
    }
}

/// Decodes `params` into a typed struct; `null` counts as `{}`.
fn parse<T: DeserializeOwned>(params: Value) -> Result<T, ControlError> {
    let params = if params.is_null() {
        Value::Object(Default::default())
    } else {
        params
    };
    serde_json::from_value(params).map_err(|e| ControlError::params(e.to_string()))
}

/// For methods without parameters: accepts `null` or `{}` only.
fn no_params(params: &Value) -> Result<(), ControlError> {
    match params {
        Value::Null => Ok(()),
        Value::Object(o) if o.is_empty() => Ok(()),
        _ => Err(ControlError::params("this method takes no parameters")),
    }
}

/// `{"ok": true}`: the reply of commands that return nothing else.
fn ok() -> Value {
    serde_json::json!({"ok": true})
}
