//! The realtime rule, checked: the simulated backends allocate nothing per servo cycle,
//! not even on error paths or behind the erasing adapter. A counting global allocator
//! counts allocations made by the measuring thread only.
#![allow(clippy::unwrap_used)]

use hytask_hal::sim::{SimAxis, SimAxisConfig, SimCanBus, SimIo, SwitchRange};
use hytask_hal::{
    dyn_axis, AnalogInputs, AnalogOutputs, AxisDrive, AxisFeedback, CanBus, CanFrame, CanId,
    DigitalInputs, DigitalOutputs, FaultCode, Homing, HomingMethod, HomingParams,
};
use std::time::Duration;

mod counting_alloc;

use counting_alloc::allocations_during;

#[test]
fn servo_cycles_of_the_sim_backends_do_not_allocate() {
    let dt = Duration::from_millis(1);
    let mut axis = SimAxis::new(SimAxisConfig {
        home_switch: Some(SwitchRange { min: 5.0, max: 8.0 }),
        positive_limit: Some(50.0),
        following_error_window: Some(5.0),
        ..SimAxisConfig::default()
    })
    .unwrap();
    let handle = axis.handle();
    let mut erased = dyn_axis(SimAxis::new(SimAxisConfig::default()).unwrap());
    let mut io = SimIo::new(4, 4, 2, 2);
    let io_handle = io.handle();
    let (_bus, mut ports) = SimCanBus::new(2, 64).unwrap();
    let (mut a, mut b) = {
        let b = ports.pop().unwrap();
        (ports.pop().unwrap(), b)
    };
    let frame = CanFrame::new(CanId::standard(0x181).unwrap(), &[1, 2, 3, 4]).unwrap();
    let params = HomingParams {
        method: HomingMethod::HomeSwitch,
        search_velocity: 20.0,
        latch_velocity: 2.0,
        home_position: 0.0,
    };

    let n = allocations_during(|| {
        axis.tick(dt);
        axis.enable().unwrap();
        let mut target = 0.0;
        for cycle in 0..3000 {
            // Drive: CSP targets, feedback, homing, faults, error paths.
            match cycle {
                500 => axis.start_homing(&params).unwrap(),
                1500 => handle.inject_fault(FaultCode::OVERCURRENT),
                1700 => {
                    axis.fault_reset().unwrap();
                    axis.enable().unwrap();
                }
                2000 => axis.quick_stop().unwrap(),
                2100 => axis.enable().unwrap(),
                _ => {}
            }
            target += 0.01;
            if axis.set_target_position(target).is_err() {
                // Refused (homing, fault, quick stop): resume from where the drive is.
                target = axis.actual_position().unwrap();
            }
            axis.tick(dt);
            let _ = axis.status().unwrap();
            let _ = axis.homing_status().unwrap();
            let _ = axis.following_error(target).unwrap();
            // The erased axis refuses targets (never enabled): the error path, formatted.
            let err = erased.set_target_position(1.0).unwrap_err();
            assert!(!err.message().is_empty());
            // I/O both ways.
            io_handle
                .set_digital_input(cycle % 4, cycle % 2 == 0)
                .unwrap();
            let _ = io.read_digital_input(cycle % 4).unwrap();
            io.write_digital_output(cycle % 4, true).unwrap();
            io.write_analog_output(1, cycle as f64).unwrap();
            let _ = io.read_analog_input(0).unwrap();
            let _ = io.read_digital_input(99).unwrap_err();
            // CAN: a SYNC-like exchange each cycle.
            a.try_send(&frame).unwrap();
            let mut buf = [frame; 4];
            assert_eq!(b.recv_into(&mut buf).unwrap(), 1);
        }
    });
    assert_eq!(n, 0, "allocations in the servo loop");
    assert!(axis.is_homed().unwrap(), "the loop exercised homing");
}
