//! The shipped machine files validate, and a validated configuration builds working
//! simulated hardware.
#![allow(clippy::unwrap_used)]

use hytask::config::{
    self, AxisName, DriveBackend, HomeMethod, IoKind, IoRef, Kinematics, MachineConfig,
};
use hytask_hal::sim::SimAxis;
use hytask_hal::{AxisDrive, AxisFeedback, Homing, HomingStatus};
use std::path::Path;
use std::time::Duration;

fn shipped(name: &str) -> MachineConfig {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("config")
        .join(name);
    config::load(&path).unwrap_or_else(|e| panic!("{name}: {e}"))
}

#[test]
fn sim_toml_validates_and_describes_the_xyz_mill() {
    let m = shipped("sim.toml");
    assert_eq!(m.machine.kinematics(), Kinematics::Identity);
    let names: Vec<AxisName> = m.axes.iter().map(|a| a.name).collect();
    assert_eq!(names, [AxisName::X, AxisName::Y, AxisName::Z]);
    let x = m.axis(AxisName::X).unwrap();
    assert_eq!((x.min_limit, x.max_limit), (0.0, 300.0));
    let z = m.axis(AxisName::Z).unwrap();
    assert_eq!((z.min_limit, z.max_limit), (-100.0, 0.0));
    for a in &m.axes {
        assert!((50.0..=100.0).contains(&a.max_velocity), "{}", a.name);
        assert!((500.0..=1000.0).contains(&a.max_acceleration), "{}", a.name);
        assert_eq!(m.drive(&a.drive).unwrap().backend, DriveBackend::Sim);
    }
    let servo = m.servo_thread().unwrap();
    assert_eq!((servo.period_us, servo.priority), (1000, 80));
    assert!(m.spindle.is_some());
    assert!(m.coolant.flood_output.is_some());
    assert_eq!(
        m.find_io(&m.safety.estop_input).map(|r| r.kind),
        Some(IoKind::DigitalInput)
    );
    assert!(m.unavailable_backends().is_empty());
    config::require_available(&m).unwrap();
}

#[test]
fn builtin_sim_is_the_shipped_sim_toml() {
    assert_eq!(config::builtin_sim().unwrap(), shipped("sim.toml"));
}

#[test]
fn example_canopen_validates_and_every_backend_is_available() {
    let m = shipped("example-canopen.toml");
    assert!(m.drives.iter().all(|d| d.backend == DriveBackend::Canopen));
    // CANopen drives and Modbus I/O are both built: nothing is refused before deploying
    // (deploying needs can0 and the devices, and names what is missing).
    assert!(m.unavailable_backends().is_empty());
    config::require_available(&m).unwrap();
    // The tool table path is resolved next to the file.
    let table = &m.tool_table.as_ref().unwrap().path;
    assert!(
        table.ends_with("config/router-1.tbl"),
        "{}",
        table.display()
    );
}

#[test]
fn resolved_output_parses_back_to_the_same_machine() {
    for name in ["sim.toml", "example-canopen.toml"] {
        let m = shipped(name);
        let text = m.to_toml().unwrap();
        let again = config::parse(&text, "resolved").unwrap();
        assert_eq!(again, m, "{name}");
    }
}

#[test]
fn defaults_are_filled_in_when_resolving() {
    let m = config::builtin_sim().unwrap();
    let x = m.drive("x").unwrap().sim.clone().unwrap();
    // Not in the file: twice the axis' max_acceleration.
    assert_eq!(x.quick_stop_deceleration, Some(2000.0));
    assert_eq!(m.motion.max_feed_override, 2.0);
    let text = m.to_toml().unwrap();
    assert!(text.contains("quick_stop_deceleration = 2000.0"), "{text}");
    assert!(text.contains("spin_up_s = 1.0"), "{text}");
}

#[test]
fn channel_lookup_gives_device_kind_and_index() {
    let m = config::builtin_sim().unwrap();
    assert_eq!(
        m.find_io("coolant_flood"),
        Some(IoRef {
            device: 0,
            kind: IoKind::DigitalOutput,
            channel: 2
        })
    );
    assert_eq!(m.find_io("nope"), None);
}

/// The configuration drives the simulator: the sim.toml X axis homes on its switch and ends
/// at its configured home position.
#[test]
fn sim_axis_built_from_config_homes_to_the_configured_position() {
    let m = config::builtin_sim().unwrap();
    let axis_cfg = m.axis(AxisName::X).unwrap();
    assert_eq!(axis_cfg.home.method, HomeMethod::Switch);
    let sim = m
        .drive(&axis_cfg.drive)
        .unwrap()
        .sim_axis_config(axis_cfg)
        .unwrap();
    assert_eq!(
        sim.max_velocity,
        axis_cfg.max_velocity * config::SIM_DRIVE_HEADROOM
    );
    let mut axis = SimAxis::new(sim).unwrap();
    let dt = Duration::from_millis(1);
    axis.tick(dt);
    axis.enable().unwrap();
    for _ in 0..3 {
        axis.tick(dt);
    }
    axis.start_homing(&axis_cfg.home.params()).unwrap();
    for _ in 0..60_000 {
        axis.tick(dt);
        if axis.homing_status().unwrap() != HomingStatus::InProgress {
            break;
        }
    }
    assert_eq!(axis.homing_status().unwrap(), HomingStatus::Homed);
    let pos = axis.actual_position().unwrap();
    assert!((pos - axis_cfg.home.position).abs() < 0.05, "{pos}");
}

/// The configuration builds the simulated I/O: pressing the e-stop through the outside
/// handle is seen on the configured channel.
#[test]
fn sim_io_built_from_config_has_the_named_channels() {
    use hytask_hal::{AnalogOutputs, DigitalInputs, DigitalOutputs};
    let m = config::builtin_sim().unwrap();
    let estop = m.find_io(&m.safety.estop_input).unwrap();
    let dev = &m.io[estop.device];
    let mut io = dev.sim_io().unwrap();
    assert_eq!(io.digital_input_count(), dev.digital_inputs.len());
    assert_eq!(io.digital_output_count(), dev.digital_outputs.len());
    assert_eq!(io.analog_output_count(), dev.analog_outputs.len());
    let outside = io.handle();
    outside.set_digital_input(estop.channel, true).unwrap();
    let point = &dev.digital_inputs[estop.channel];
    assert!(point.active(io.read_digital_input(estop.channel).unwrap()));
    let flood = m.find_io("coolant_flood").unwrap();
    io.set_high(flood.channel).unwrap();
    assert!(outside.digital_output(flood.channel).unwrap());
    let speed = m.find_io("spindle_speed").unwrap();
    io.write_analog_output(speed.channel, 12000.0).unwrap();
    assert_eq!(outside.analog_output(speed.channel).unwrap(), 12000.0);
}

#[test]
fn channel_inversion_and_scaling() {
    let m = shipped("example-canopen.toml");
    let cab = &m.io[0];
    assert!(cab.sim_io().is_none(), "not a sim device");
    let estop = &cab.digital_inputs[0];
    assert!(estop.invert);
    assert!(
        estop.active(false),
        "an open normally-closed chain is an active e-stop"
    );
    assert!(!estop.active(true));
    assert!(estop.level(false));
    // The VFD's frequency setpoint: 0.01 Hz counts, 24000 rpm at 400.00 Hz.
    let speed = &m.io[1].analog_outputs[0];
    assert_eq!(speed.to_engineering(40_000.0), 24_000.0);
    assert_eq!(speed.to_raw(24_000.0), 40_000.0);
}

#[test]
fn z_homes_before_x_and_y() {
    let m = config::builtin_sim().unwrap();
    assert_eq!(
        m.homing_order(),
        [vec![AxisName::Z], vec![AxisName::X, AxisName::Y]]
    );
}

/// The fault-injection keys shown commented out in sim.toml are valid and reach the
/// simulator.
#[test]
fn commented_fault_injection_in_sim_toml_works_when_enabled() {
    let text: String = config::BUILTIN_SIM_TOML
        .lines()
        .map(|l| {
            for key in [
                "fault_at_s",
                "fault_code",
                "stall_at_s",
                "following_error_window",
            ] {
                if let Some(rest) = l.strip_prefix("# ").filter(|r| r.starts_with(key)) {
                    return format!("{rest}\n");
                }
            }
            format!("{l}\n")
        })
        .collect();
    let m = config::parse(&text, "sim with faults").unwrap();
    let z = m.axis(AxisName::Z).unwrap();
    let sim = m.drive("z").unwrap().sim_axis_config(z).unwrap();
    assert_eq!(sim.faults.drive_fault_at_s, Some(30.0));
    assert_eq!(
        sim.faults.drive_fault_code,
        hytask_hal::FaultCode::OVERCURRENT
    );
    assert_eq!(sim.faults.stall_at_s, Some(30.0));
    assert_eq!(sim.following_error_window, Some(5.0));
}
