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
//! A speed below [`MIN_JOG_SPEED`] (subnormals included), a distance below
//! [`MIN_JOG_DISTANCE`] or above 1e9, or a non-finite number is refused (-32602) naming
//! the field.

use super::{no_params, ok, parse, ControlError};
use crate::machine::api::{JogRequest, MachineApi};
use serde_json::Value;

/// Slowest jog speed accepted, units/s (0.06 units/min): slower, a 1-unit jog takes over a
/// quarter of an hour, and a subnormal speed (`1e-320`) planned a move of ~1e320 s.
pub const MIN_JOG_SPEED: f64 = 1e-3;
/// Shortest incremental jog, units (1 nm): below any machine's resolution.
pub const MIN_JOG_DISTANCE: f64 = 1e-6;

/// Refuses a number that is not finite, or whose magnitude is outside `min..=max`, naming
/// `field` and the bound.
fn in_range(field: &str, v: f64, min: f64, max: f64) -> Result<(), ControlError> {
    if !v.is_finite() {
        return Err(ControlError::params(format!(
            "{field} must be a finite number, got {v:?}"
        )));
    }
    if v.abs() < min {
        return Err(ControlError::params(format!(
            "{field} {v:e} is below the smallest accepted {min:e} (a subnormal or below the \
             machine's resolution)"
        )));
    }
    if v.abs() > max {
        return Err(ControlError::params(format!(
            "{field} {v:e} is above the largest accepted {max:e}"
        )));
    }
    Ok(())
}

pub(super) fn handle(m: &dyn MachineApi, params: Value) -> Result<Value, ControlError> {
    let req: JogRequest = parse(params)?;
    // The speed is clamped to the axis limit afterwards; any finite speed above is accepted.
    in_range("velocity", req.velocity, MIN_JOG_SPEED, f64::MAX)?;
    if let Some(d) = req.distance {
        if d < 0.0 {
            return Err(ControlError::params(format!(
                "distance must be > 0 (the velocity's sign gives the direction), got {d:?}"
            )));
        }
        // Longer than any axis travel: the soft limits refuse it with the axis named.
        in_range("distance", d, MIN_JOG_DISTANCE, 1e9)?;
    }
    m.jog(&req)?;
    Ok(ok())
}

pub(super) fn handle_stop(m: &dyn MachineApi, params: Value) -> Result<Value, ControlError> {
    no_params(&params)?;
    m.jog_stop()?;
    Ok(ok())
}
