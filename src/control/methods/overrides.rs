//! `override`: feed (0–2), rapid (0–1) and spindle (0–2) overrides, as fractions.
//!
//! ```text
//! → {"id":1,"method":"override","params":{"feed":1.5}}
//! ← {"id":1,"result":{"feed":1.5,"rapid":1.0,"spindle":1.0}}
//! ```
//! Absent fields keep their value. Changes apply smoothly, within the axis limits. A value
//! between 0 and [`MIN_OVERRIDE`] (a subnormal, say) is refused naming the field.

use super::{parse, ControlError};
use crate::machine::api::{MachineApi, OverrideRequest};
use serde_json::Value;

/// Smallest override other than 0 (0.1 %): a subnormal such as `1e-320` was accepted and
/// ran the servo thread's time scaling on subnormal arithmetic.
pub const MIN_OVERRIDE: f64 = 1e-3;

fn check(name: &str, v: Option<f64>, max: f64) -> Result<(), ControlError> {
    match v {
        Some(x) if !(0.0..=max).contains(&x) || !x.is_finite() => Err(ControlError::params(
            format!("{name} must be within 0..={max}, got {x:?}"),
        )),
        Some(x) if x != 0.0 && x < MIN_OVERRIDE => Err(ControlError::params(format!(
            "{name} must be 0 or at least {MIN_OVERRIDE}, got {x:e}"
        ))),
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
