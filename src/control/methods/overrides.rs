//! `override`: feed (0–2), rapid (0–1) and spindle (0–2) overrides, as fractions.
//!
//! ```text
//! → {"id":1,"method":"override","params":{"feed":1.5}}
//! ← {"id":1,"result":{"feed":1.5,"rapid":1.0,"spindle":1.0}}
//! ```
//! Absent fields keep their value. Changes apply smoothly, within the axis limits.

use super::{parse, ControlError};
use crate::machine::api::{MachineApi, OverrideRequest};
use serde_json::Value;

fn check(name: &str, v: Option<f64>, max: f64) -> Result<(), ControlError> {
    match v {
        Some(x) if !(0.0..=max).contains(&x) || !x.is_finite() => Err(ControlError::params(
            format!("{name} must be within 0..={max}, got {x:?}"),
        )),
        _ => Ok(()),
    }
}

pub(super) fn handle(m: &dyn MachineApi, params: Value) -> Result<Value, ControlError> {
    let req: OverrideRequest = parse(params)?;
    check("feed", req.feed, 2.0)?;
    check("rapid", req.rapid, 1.0)?;
    check("spindle", req.spindle, 2.0)?;
    let now = m.set_overrides(&req)?;
    serde_json::to_value(now)
        .map_err(|e| ControlError::new(super::ErrorCode::Failed, e.to_string()))
}
