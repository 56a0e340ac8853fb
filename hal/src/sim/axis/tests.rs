//! Behaviour tests of the simulated axis, through the HAL traits.

use super::*;
use crate::error::{Error, ErrorKind};

const DT: Duration = Duration::from_millis(1);
const DT_S: f64 = 0.001;

fn config() -> SimAxisConfig {
    SimAxisConfig {
        max_velocity: 100.0,
        max_acceleration: 1000.0,
        lag_s: 0.005,
        quick_stop_deceleration: 4000.0,
        ..SimAxisConfig::default()
    }
}

fn ticks(axis: &mut SimAxis, n: usize) {
    for _ in 0..n {
        axis.tick(DT);
    }
}

fn enabled(config: SimAxisConfig) -> SimAxis {
    let mut axis = SimAxis::new(config).unwrap();
    axis.tick(DT);
    axis.enable().unwrap();
    ticks(&mut axis, 3);
    assert_eq!(axis.drive_state().unwrap(), DriveState::OperationEnabled);
    axis
}

/// Streams targets at constant `speed` for `seconds` (CSP), returning the last target.
fn stream(axis: &mut SimAxis, speed: f64, seconds: f64) -> f64 {
    let mut target = axis.target_position();
    for _ in 0..(seconds / DT_S).round() as usize {
        target += speed * DT_S;
        axis.set_target_position(target).unwrap();
        axis.tick(DT);
    }
    target
}

fn home_params(method: HomingMethod) -> HomingParams {
    HomingParams {
        method,
        search_velocity: 50.0,
        latch_velocity: 5.0,
        home_position: 300.0,
    }
}

#[test]
fn boots_into_switch_on_disabled() {
    let mut axis = SimAxis::new(config()).unwrap();
    assert_eq!(axis.drive_state().unwrap(), DriveState::NotReadyToSwitchOn);
    axis.tick(DT);
    assert_eq!(axis.drive_state().unwrap(), DriveState::SwitchOnDisabled);
    assert_eq!(axis.fault_code().unwrap(), None);
    assert_eq!(axis.homing_status().unwrap(), HomingStatus::NotHomed);
}

#[test]
fn enable_walks_the_state_machine_one_state_per_tick() {
    let mut axis = SimAxis::new(config()).unwrap();
    axis.tick(DT);
    axis.enable().unwrap();
    let mut seen = Vec::new();
    for _ in 0..4 {
        axis.tick(DT);
        seen.push(axis.drive_state().unwrap());
    }
    assert_eq!(
        seen,
        [
            DriveState::ReadyToSwitchOn,
            DriveState::SwitchedOn,
            DriveState::OperationEnabled,
            DriveState::OperationEnabled
        ]
    );
    assert!(axis.is_operational().unwrap());
}

#[test]
fn targets_are_refused_until_operational() {
    let mut axis = SimAxis::new(config()).unwrap();
    axis.tick(DT);
    let err = axis.set_target_position(1.0).unwrap_err();
    assert_eq!(
        err,
        SimAxisError::NotOperational(DriveState::SwitchOnDisabled)
    );
    assert_eq!(err.kind(), ErrorKind::NotReady);
}

#[test]
fn disable_switches_off_and_the_motor_coasts_to_rest() {
    let mut axis = enabled(config());
    stream(&mut axis, 50.0, 0.2);
    axis.disable().unwrap();
    assert_eq!(axis.drive_state().unwrap(), DriveState::SwitchOnDisabled);
    ticks(&mut axis, 200);
    assert_eq!(axis.actual_velocity().unwrap(), 0.0);
    assert!(axis.set_target_position(0.0).is_err());
}

#[test]
fn follows_a_step_without_overshoot() {
    let mut axis = enabled(config());
    axis.set_target_position(10.0).unwrap();
    let mut max_pos: f64 = 0.0;
    for _ in 0..1000 {
        axis.tick(DT);
        max_pos = max_pos.max(axis.actual_position().unwrap());
    }
    assert!((axis.actual_position().unwrap() - 10.0).abs() < 1e-3);
    assert!(max_pos <= 10.0 + 1e-9, "overshoot to {max_pos}");
    assert_eq!(axis.actual_velocity().unwrap(), 0.0);
}

#[test]
fn respects_velocity_and_acceleration_limits() {
    let mut axis = enabled(config());
    axis.set_target_position(1000.0).unwrap();
    let mut last_v = 0.0;
    for _ in 0..500 {
        axis.tick(DT);
        let v = axis.actual_velocity().unwrap();
        assert!(v <= 100.0 + 1e-9, "velocity {v}");
        assert!((v - last_v) <= 1000.0 * DT_S + 1e-9, "acceleration");
        last_v = v;
    }
    assert!((last_v - 100.0).abs() < 1e-9, "reaches max velocity");
}

#[test]
fn following_error_grows_with_speed() {
    let error_at = |speed: f64| {
        let mut axis = enabled(config());
        let target = stream(&mut axis, speed, 0.5);
        axis.following_error(target).unwrap()
    };
    let slow = error_at(20.0);
    let fast = error_at(60.0);
    // First-order lag: error = v * lag (0.1 mm at 20 mm/s with lag 5 ms).
    assert!((slow - 20.0 * 0.005).abs() < 0.02, "slow error {slow}");
    assert!((fast / slow - 3.0).abs() < 0.1, "{fast} vs {slow}");
}

#[test]
fn zero_lag_follows_exactly() {
    let mut axis = enabled(SimAxisConfig {
        lag_s: 0.0,
        ..config()
    });
    let target = stream(&mut axis, 20.0, 0.5);
    assert!(axis.following_error(target).unwrap().abs() < 1e-9);
}

#[test]
fn positive_limit_switch_trips_and_blocks_motion_into_it() {
    let mut axis = enabled(SimAxisConfig {
        positive_limit: Some(20.0),
        ..config()
    });
    let mut target = 0.0;
    let mut refused = None;
    for _ in 0..2000 {
        target += 30.0 * DT_S;
        if let Err(e) = axis.set_target_position(target) {
            refused = Some(e);
            break;
        }
        axis.tick(DT);
    }
    let err = refused.expect("limit switch must refuse the target");
    assert_eq!(err, SimAxisError::LimitSwitch("positive"));
    assert_eq!(err.kind(), ErrorKind::LimitReached);
    ticks(&mut axis, 100);
    assert_eq!(axis.actual_velocity().unwrap(), 0.0);
    let pos = axis.actual_position().unwrap();
    assert!((20.0..20.5).contains(&pos), "stopped at {pos}");
    assert!(axis.switches().unwrap().positive_limit);
    // Moving away is allowed and releases the switch.
    axis.set_target_position(10.0).unwrap();
    ticks(&mut axis, 1000);
    assert!(!axis.switches().unwrap().positive_limit);
    assert!((axis.actual_position().unwrap() - 10.0).abs() < 1e-3);
}

#[test]
fn negative_limit_switch_trips() {
    let mut axis = enabled(SimAxisConfig {
        negative_limit: Some(-5.0),
        ..config()
    });
    axis.set_target_position(-50.0).unwrap();
    ticks(&mut axis, 1000);
    let pos = axis.actual_position().unwrap();
    // Overtravel of the quick-stop ramp: 100² / (2 * 4000) = 1.25 mm past the switch.
    assert!((-6.3..=-5.0).contains(&pos), "stopped at {pos}");
    assert!(axis.switches().unwrap().negative_limit);
    assert_eq!(
        axis.set_target_position(-60.0).unwrap_err(),
        SimAxisError::LimitSwitch("negative")
    );
}

#[test]
fn homing_finds_the_home_switch_and_sets_the_position() {
    let mut axis = enabled(SimAxisConfig {
        home_switch: Some(SwitchRange {
            min: 100.0,
            max: 110.0,
        }),
        positive_limit: Some(120.0),
        ..config()
    });
    axis.start_homing(&home_params(HomingMethod::HomeSwitch))
        .unwrap();
    assert_eq!(axis.homing_status().unwrap(), HomingStatus::InProgress);
    assert_eq!(
        axis.set_target_position(1.0).unwrap_err(),
        SimAxisError::HomingInProgress
    );
    for _ in 0..10_000 {
        axis.tick(DT);
        if axis.homing_status().unwrap() != HomingStatus::InProgress {
            break;
        }
    }
    assert!(axis.is_homed().unwrap());
    // The switch edge at physical 100 is now reported as 300; the axis rests next to it.
    let pos = axis.actual_position().unwrap();
    assert!((pos - 300.0).abs() < 0.05, "position after homing {pos}");
    assert_eq!(axis.actual_velocity().unwrap(), 0.0);
    // Targets are accepted again, in the new coordinates.
    axis.set_target_position(310.0).unwrap();
    ticks(&mut axis, 1000);
    assert!(
        axis.switches().unwrap().home,
        "physical 110 is on the switch"
    );
}

#[test]
fn homing_on_a_limit_switch() {
    let mut axis = enabled(SimAxisConfig {
        negative_limit: Some(-10.0),
        ..config()
    });
    let params = HomingParams {
        search_velocity: -40.0,
        home_position: 0.0,
        ..home_params(HomingMethod::LimitSwitch)
    };
    axis.start_homing(&params).unwrap();
    ticks(&mut axis, 5000);
    assert_eq!(axis.homing_status().unwrap(), HomingStatus::Homed);
    assert!(axis.actual_position().unwrap().abs() < 0.05);
    assert!(!axis.switches().unwrap().negative_limit);
}

#[test]
fn homing_fails_when_a_limit_comes_before_the_home_switch() {
    let mut axis = enabled(SimAxisConfig {
        home_switch: Some(SwitchRange {
            min: -20.0,
            max: -15.0,
        }),
        positive_limit: Some(30.0),
        ..config()
    });
    axis.start_homing(&home_params(HomingMethod::HomeSwitch))
        .unwrap();
    ticks(&mut axis, 5000);
    assert_eq!(
        axis.homing_status().unwrap(),
        HomingStatus::Failed(HomingFailure::LimitReached)
    );
    assert!(!axis.is_homed().unwrap());
    assert_eq!(axis.actual_velocity().unwrap(), 0.0);
}

#[test]
fn homing_without_the_needed_switch_is_unsupported() {
    let mut axis = enabled(config());
    let err = axis
        .start_homing(&home_params(HomingMethod::HomeSwitch))
        .unwrap_err();
    assert_eq!(err.kind(), ErrorKind::Unsupported);
    let err = axis
        .start_homing(&HomingParams {
            search_velocity: 0.0,
            ..home_params(HomingMethod::LimitSwitch)
        })
        .unwrap_err();
    assert_eq!(err.kind(), ErrorKind::InvalidArgument);
}

#[test]
fn homing_on_the_current_position_needs_no_motion() {
    let mut axis = enabled(SimAxisConfig {
        initial_position: 42.0,
        ..config()
    });
    axis.start_homing(&home_params(HomingMethod::CurrentPosition))
        .unwrap();
    assert!(axis.is_homed().unwrap());
    assert_eq!(axis.actual_position().unwrap(), 300.0);
    assert_eq!(axis.target_position(), 300.0);
}

#[test]
fn homing_can_be_aborted() {
    let mut axis = enabled(SimAxisConfig {
        home_switch: Some(SwitchRange {
            min: 100.0,
            max: 110.0,
        }),
        ..config()
    });
    axis.start_homing(&home_params(HomingMethod::HomeSwitch))
        .unwrap();
    ticks(&mut axis, 100);
    axis.abort_homing().unwrap();
    assert_eq!(
        axis.homing_status().unwrap(),
        HomingStatus::Failed(HomingFailure::Aborted)
    );
    ticks(&mut axis, 200);
    assert_eq!(axis.actual_velocity().unwrap(), 0.0);
    let here = axis.actual_position().unwrap();
    axis.set_target_position(here).unwrap();
}

#[test]
fn homing_requires_operation_enabled() {
    let mut axis = SimAxis::new(config()).unwrap();
    axis.tick(DT);
    let err = axis
        .start_homing(&home_params(HomingMethod::CurrentPosition))
        .unwrap_err();
    assert_eq!(err.kind(), ErrorKind::NotReady);
}

#[test]
fn injected_drive_fault_brakes_into_fault_and_reset_recovers() {
    let mut axis = enabled(config());
    stream(&mut axis, 50.0, 0.2);
    axis.handle().inject_fault(FaultCode::OVERCURRENT);
    axis.tick(DT);
    assert_eq!(axis.drive_state().unwrap(), DriveState::FaultReactionActive);
    assert_eq!(axis.fault_code().unwrap(), Some(FaultCode::OVERCURRENT));
    ticks(&mut axis, 100);
    assert_eq!(axis.drive_state().unwrap(), DriveState::Fault);
    assert_eq!(axis.actual_velocity().unwrap(), 0.0);

    let err = axis.set_target_position(0.0).unwrap_err();
    assert_eq!(err, SimAxisError::Faulted(FaultCode::OVERCURRENT));
    assert_eq!(err.kind(), ErrorKind::DeviceFault);
    assert!(!err.kind().is_link_failure());
    assert_eq!(axis.enable().unwrap_err().kind(), ErrorKind::DeviceFault);

    axis.fault_reset().unwrap();
    assert_eq!(axis.drive_state().unwrap(), DriveState::SwitchOnDisabled);
    assert_eq!(axis.fault_code().unwrap(), None);
    axis.enable().unwrap();
    ticks(&mut axis, 3);
    assert!(axis.is_operational().unwrap());
}

#[test]
fn scheduled_drive_fault_fires_at_its_time() {
    let mut axis = enabled(SimAxisConfig {
        faults: FaultInjection {
            drive_fault_at_s: Some(0.1),
            drive_fault_code: FaultCode(0x5441),
            stall_at_s: None,
        },
        ..config()
    });
    ticks(&mut axis, 90);
    assert!(axis.is_operational().unwrap());
    ticks(&mut axis, 20);
    assert_eq!(axis.drive_state().unwrap(), DriveState::Fault);
    assert_eq!(axis.fault_code().unwrap(), Some(FaultCode(0x5441)));
    // Fires once: after a reset the drive stays healthy.
    axis.fault_reset().unwrap();
    axis.enable().unwrap();
    ticks(&mut axis, 100);
    assert!(axis.is_operational().unwrap());
}

#[test]
fn stall_stops_the_position_and_the_following_error_grows() {
    let mut axis = enabled(config());
    stream(&mut axis, 30.0, 0.2);
    let handle = axis.handle();
    handle.set_stalled(true);
    let stuck = axis.actual_position().unwrap();
    let target = stream(&mut axis, 30.0, 0.5);
    assert_eq!(axis.actual_position().unwrap(), stuck);
    assert!(axis.following_error(target).unwrap() > 14.0);
    handle.set_stalled(false);
    stream(&mut axis, 0.0, 1.0);
    assert!(axis.following_error(target).unwrap().abs() < 1e-3);
}

#[test]
fn scheduled_stall_trips_the_drive_following_error_window() {
    let mut axis = enabled(SimAxisConfig {
        following_error_window: Some(2.0),
        faults: FaultInjection {
            stall_at_s: Some(0.1),
            ..FaultInjection::default()
        },
        ..config()
    });
    let mut target = 0.0;
    for _ in 0..500 {
        target += 30.0 * DT_S;
        if axis.set_target_position(target).is_err() {
            break;
        }
        axis.tick(DT);
    }
    assert!(axis.time_s() < 0.3, "faulted soon after the stall");
    axis.tick(DT);
    assert_eq!(axis.drive_state().unwrap(), DriveState::Fault);
    assert_eq!(axis.fault_code().unwrap(), Some(FaultCode::FOLLOWING_ERROR));
}

#[test]
fn quick_stop_decelerates_on_its_ramp_and_holds() {
    let mut axis = enabled(config());
    stream(&mut axis, 80.0, 0.3);
    let v0 = axis.actual_velocity().unwrap();
    axis.quick_stop().unwrap();
    assert_eq!(axis.drive_state().unwrap(), DriveState::QuickStopActive);
    axis.tick(DT);
    let v1 = axis.actual_velocity().unwrap();
    assert!(
        ((v0 - v1) - 4000.0 * DT_S).abs() < 1e-6,
        "decelerates at the quick stop ramp: {v0} -> {v1}"
    );
    ticks(&mut axis, 30);
    assert_eq!(axis.actual_velocity().unwrap(), 0.0);
    assert_eq!(axis.drive_state().unwrap(), DriveState::QuickStopActive);
    assert_eq!(
        axis.set_target_position(0.0).unwrap_err().kind(),
        ErrorKind::NotReady
    );
    // Enabling again resumes from where it stopped, without a jump.
    axis.enable().unwrap();
    axis.tick(DT);
    assert!(axis.is_operational().unwrap());
    let here = axis.actual_position().unwrap();
    assert_eq!(axis.target_position(), here);
}

#[test]
fn a_cut_link_is_a_link_failure_not_a_refusal() {
    let mut axis = enabled(config());
    let handle = axis.handle();
    handle.set_disconnected(true);
    let err = axis.actual_position().unwrap_err();
    assert_eq!(err.kind(), ErrorKind::Disconnected);
    assert!(err.kind().is_link_failure());
    assert!(axis.set_target_position(1.0).is_err());
    assert!(axis.drive_state().is_err());
    handle.set_disconnected(false);
    assert!(axis.set_target_position(1.0).is_ok());
}

#[test]
fn non_finite_targets_are_invalid() {
    let mut axis = enabled(config());
    let err = axis.set_target_position(f64::NAN).unwrap_err();
    assert_eq!(err.kind(), ErrorKind::InvalidArgument);
}

#[test]
fn unphysical_configs_are_rejected() {
    for bad in [
        SimAxisConfig {
            max_velocity: 0.0,
            ..config()
        },
        SimAxisConfig {
            lag_s: -1.0,
            ..config()
        },
        SimAxisConfig {
            negative_limit: Some(5.0),
            positive_limit: Some(1.0),
            ..config()
        },
    ] {
        assert_eq!(
            SimAxis::new(bad).unwrap_err().kind(),
            ErrorKind::InvalidArgument
        );
    }
}

#[test]
fn works_behind_a_trait_object() {
    let mut axis: Box<dyn crate::Axis<Error = SimAxisError>> =
        Box::new(SimAxis::new(config()).unwrap());
    assert_eq!(axis.drive_state().unwrap(), DriveState::NotReadyToSwitchOn);
}

#[test]
fn advance_to_steps_by_the_time_since_the_last_call() {
    let mut axis = SimAxis::new(config()).unwrap();
    axis.advance_to(Duration::from_millis(1));
    axis.enable().unwrap();
    for ms in 2..=4 {
        axis.advance_to(Duration::from_millis(ms));
    }
    assert!(axis.is_operational().unwrap());
    assert!((axis.time_s() - 0.004).abs() < 1e-12);
    axis.set_target_position(1.0).unwrap();
    axis.advance_to(Duration::from_millis(3)); // in the past: nothing happens
    assert!((axis.time_s() - 0.004).abs() < 1e-12);
    assert_eq!(axis.actual_position().unwrap(), 0.0);
    axis.advance_to(Duration::from_millis(504));
    assert!((axis.actual_position().unwrap() - 1.0).abs() < 1e-3);
}

#[test]
fn status_reads_the_whole_feedback_in_one_call() {
    let mut axis = enabled(SimAxisConfig {
        positive_limit: Some(0.0),
        ..config()
    });
    let status = axis.status().unwrap();
    assert_eq!(status.state, DriveState::OperationEnabled);
    assert_eq!(status.position, 0.0);
    assert_eq!(status.velocity, 0.0);
    assert_eq!(status.fault, None);
    assert!(status.switches.positive_limit);
}
