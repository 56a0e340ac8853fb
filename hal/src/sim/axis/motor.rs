//! The motor model: pure functions from a demanded velocity to the next velocity, kept apart
//! from the drive state machine so that each can be read and tested on its own.

/// The velocity the drive's position loop demands for a position error `error`.
///
/// A first-order lag: `error / lag_s`, so that at constant speed `v` the error settles at
/// `v * lag_s` (the following error a real drive without feed-forward shows). When the
/// target stands still the demand is also capped by the discrete braking curve (the speed
/// from which braking at `decel`, one step `dt` at a time, stops within `|error|`), so a step
/// in the target ends without overshoot. The demand
/// never exceeds `max_velocity`, nor the speed that would cover the error within one step
/// `dt` (which keeps the discrete loop stable for any `lag_s`, including zero).
pub(crate) fn position_loop(
    error: f64,
    lag_s: f64,
    dt: f64,
    max_velocity: f64,
    decel: f64,
    target_moving: bool,
) -> f64 {
    let deadbeat = error.abs() / dt;
    let mut speed = if lag_s > 0.0 {
        (error.abs() / lag_s).min(deadbeat)
    } else {
        deadbeat
    };
    if !target_moving {
        // Braking from n * decel * dt covers decel * dt² * n(n+1)/2; solve for n.
        let step = decel * dt;
        let n = (0.25 + 2.0 * error.abs() / (step * dt)).sqrt() - 0.5;
        speed = speed.min(n * step);
    }
    speed.min(max_velocity).copysign(error)
}

/// Moves `velocity` toward `demand` within one step `dt`: at most `accel * dt` when speeding
/// up, at most `decel * dt` when slowing down or reversing. Lands exactly on `demand` when
/// it is within reach, so "stopped" is an exact zero.
pub(crate) fn ramp(velocity: f64, demand: f64, accel: f64, decel: f64, dt: f64) -> f64 {
    let slowing = demand.abs() < velocity.abs() || demand * velocity < 0.0;
    let rate = if slowing { decel } else { accel };
    let max_step = rate * dt;
    let diff = demand - velocity;
    if diff.abs() <= max_step {
        demand
    } else {
        velocity + max_step.copysign(diff)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lag_demands_error_over_time_constant() {
        let v = position_loop(0.5, 0.01, 0.001, 100.0, 1000.0, true);
        assert!((v - 50.0).abs() < 1e-9, "{v}");
        let v = position_loop(-0.5, 0.01, 0.001, 100.0, 1000.0, true);
        assert!((v + 50.0).abs() < 1e-9, "{v}");
    }

    #[test]
    fn demand_is_capped_by_max_velocity_and_braking_curve() {
        assert_eq!(position_loop(100.0, 0.01, 0.001, 80.0, 1000.0, true), 80.0);
        // Standing target 0.021 away: braking 1 mm/s per step from 6 mm/s covers
        // 0.001 * (6+5+4+3+2+1) = 0.021 exactly.
        let v = position_loop(0.021, 0.001, 0.001, 80.0, 1000.0, false);
        assert!((v - 6.0).abs() < 1e-9, "{v}");
    }

    #[test]
    fn zero_lag_covers_the_error_in_one_step() {
        assert!((position_loop(0.01, 0.0, 0.001, 100.0, 1e6, true) - 10.0).abs() < 1e-9);
    }

    #[test]
    fn ramp_limits_acceleration_and_deceleration_separately() {
        assert_eq!(ramp(0.0, 10.0, 1000.0, 5000.0, 0.001), 1.0);
        assert_eq!(ramp(10.0, 0.0, 1000.0, 5000.0, 0.001), 5.0);
        assert_eq!(ramp(1.0, -1.0, 1000.0, 5000.0, 0.001), -1.0);
        assert_eq!(ramp(0.5, 0.0, 1000.0, 5000.0, 0.001), 0.0);
    }
}
