//! `jog` and `jog.stop`.
//!
//! ```text
//! → {"id":1,"method":"jog","params":{"axis":"X","velocity":10.0,"distance":5.0}}  incremental
//! → {"id":2,"method":"jog","params":{"axis":"Y","velocity":-20.0}}               continuous
//! → {"id":3,"method":"jog.stop"}
//! ← {"id":n,"result":{"ok":true}}
//! ```
//! A continuous jog runs until `jog.stop` or the soft limit, whichever comes first; the
//! velocity is clamped to the axis limit. Rejected unless the machine is idle or jogging.

use super::{no_params, ok, parse, ControlError};
use crate::machine::api::{JogRequest, MachineApi};
use serde_json::Value;

pub(super) fn handle(m: &dyn MachineApi, params: Value) -> Result<Value, ControlError> {
    let req: JogRequest = parse(params)?;
    if !req.velocity.is_finite() || req.velocity == 0.0 {
        return Err(ControlError::params("velocity must be a non-zero number"));
    }
    if let Some(d) = req.distance {
        if !d.is_finite() || d <= 0.0 {
            return Err(ControlError::params("distance must be > 0"));
        }
    }
    m.jog(&req)?;
    Ok(ok())
}

pub(super) fn handle_stop(m: &dyn MachineApi, params: Value) -> Result<Value, ControlError> {
    no_params(&params)?;
    m.jog_stop()?;
    Ok(ok())
}
