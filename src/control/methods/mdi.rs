//! `mdi`: execute one line of G-code.
//!
//! ```text
//! → {"id":1,"method":"mdi","params":{"line":"G0 X10 Y10"}}
//! ← {"id":1,"result":{"ok":true}}
//! ← {"id":1,"error":{"code":3,"message":"mdi:1:4: ..."}}     (G-code error, nothing moves)
//! ```
//! The line is interpreted and planned in full first; modal state persists between MDI
//! lines. Rejected unless the machine is idle and homed. Subroutines come from `[gcode]
//! subroutine_path`. Prepared as a job is: one at a time, within `[job] prepare_timeout_s`
//! (code 4 past it), cancelled (code 2) by `job.abort`, any e-stop or the client hanging up.

use super::{ok, parse, ControlError};
use crate::machine::api::MachineApi;
use serde::Deserialize;
use serde_json::Value;

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Params {
    line: String,
}

pub(super) fn handle(m: &dyn MachineApi, params: Value) -> Result<Value, ControlError> {
    let p: Params = parse(params)?;
    if p.line.contains('\n') {
        return Err(ControlError::params("mdi takes a single line"));
    }
    m.mdi(&p.line)?;
    Ok(ok())
}
