//! Building a machine's tasks from its configuration: the HAL backends, the io, machine,
//! interpolator, axis and monitor tasks on the servo thread, and the handles the non-realtime side
//! keeps ([`Built`]). Why apart from [`Machine::deploy`]: tests start the same tasks on the stepped
//! runtime with simulated time.

use super::{axis_letter, Built, DeployError, QUEUE_CAPACITY};
use crate::config::{IoKind, MachineConfig};
use crate::machine::devices;
use crate::machine::job;
use crate::machine::safety::AxisGuard;
use crate::machine::servo::axis_task::AxisTask;
use crate::machine::servo::can_bus::{CanRxTask, CanTxTask};
use crate::machine::servo::interp_task::InterpolatorTask;
use crate::machine::servo::io_task::{IoTask, SimPlate, SimSpindle};
use crate::machine::servo::machine_task::{MachineSetup, MachineTask, SpindleIo};
use crate::machine::servo::monitor_task::MonitorTask;
use crate::machine::servo::QueueItem;
use crate::rt::prelude::{buffer, Deployment, FullPolicy, OverrunPolicy, Schedule};
use std::sync::atomic::AtomicU32;
use std::sync::Arc;

/// Builds the backends and adds the machine's tasks to a new deployment, in start order
/// io → machine → interpolator → axis.* → monitor, all on the servo thread.
pub fn build(config: &MachineConfig) -> Result<Built, DeployError> {
    let devs = devices::build(config)?;
    let motion_cfg = job::motion_config(config);
    let servo = config
        .servo_thread()
        .ok_or_else(|| DeployError::Invalid("motion.servo_thread names no [[thread]]".into()))?
        .clone();
    let schedule = Schedule {
        priority: i32::from(servo.priority),
        period_ns: u64::from(servo.period_us) * 1000,
        cpu: servo.cpu.map(|c| c as usize),
    };
    let period_s = f64::from(servo.period_us) * 1e-6;
    let axes: Vec<(char, usize)> = config
        .axes
        .iter()
        .map(|a| (axis_letter(a.name as usize), a.name as usize))
        .collect();
    let di = |name: &str| devs.io_map.index(IoKind::DigitalInput, name);
    let dout = |name: &str| devs.io_map.index(IoKind::DigitalOutput, name);
    let aout = |name: &str| devs.io_map.index(IoKind::AnalogOutput, name);
    let estop_input = di(&config.safety.estop_input).ok_or_else(|| {
        DeployError::Invalid(format!(
            "safety.estop_input: no digital input '{}'",
            config.safety.estop_input
        ))
    })?;
    let spindle = config.spindle.as_ref().and_then(|s| {
        Some(SpindleIo {
            enable: dout(&s.enable_output)?,
            direction: s.direction_output.as_deref().and_then(dout),
            speed: s.speed_output.as_deref().and_then(aout),
            at_speed: s.at_speed_input.as_deref().and_then(di),
            max_rpm: s.max_rpm,
        })
    });
    // The simulated plant's spindle: at speed `spin_up_s` after enable, on sim I/O.
    let sim_spindle = config.spindle.as_ref().and_then(|s| {
        let name = s.at_speed_input.as_deref()?;
        let r = config.find_io(name)?;
        let handle = devs.sim_io.get(r.device)?.clone()?;
        let invert = config.io[r.device].digital_inputs[r.channel].invert;
        Some(SimSpindle::new(
            spindle?.enable,
            (handle, r.channel, invert),
            (s.spin_up_s / period_s).ceil() as u32,
        ))
    });
    // Simulated touch plates: the input follows the axis position.
    let plates: Vec<SimPlate> = config
        .io
        .iter()
        .enumerate()
        .filter_map(|(d, dev)| {
            let t = dev.touch_plate.as_ref()?;
            let r = config.find_io(&t.input)?;
            let handle = devs.sim_io.get(d)?.clone()?;
            let invert = dev.digital_inputs.get(r.channel)?.invert;
            Some(SimPlate::new(
                axis_letter(t.axis as usize),
                t.top,
                (handle, r.channel, invert),
            ))
        })
        .collect();
    let homing_groups: Vec<u32> = config
        .homing_order()
        .iter()
        .map(|g| g.iter().fold(0u32, |m, a| m | 1 << (*a as usize)))
        .collect();
    let setup = MachineSetup {
        axes: axes.clone(),
        homing_groups,
        estop_input,
        probe_input: config.motion.probe_input.as_deref().and_then(di),
        spindle,
        flood_output: config.coolant.flood_output.as_deref().and_then(dout),
        mist_output: config.coolant.mist_output.as_deref().and_then(dout),
        safe_outputs: devs.io_map.safe_outputs(),
        max_feed_override: config.motion.max_feed_override,
        max_stale_io_cycles: (0.02 / period_s).ceil() as u32,
        enable_timeout_cycles: (2.0 / period_s) as u32,
        spindle_timeout_cycles: (20.0 / period_s) as u32,
        overrun_event: format!("rt-p{}-{}us.overrun", servo.priority, servo.period_us),
        period_s,
        in_position_window: 0.001,
        settle_timeout_cycles: (1.0 / period_s) as u32,
    };

    let plc = crate::plc::deploy::prepare(config, &devs.io_map, period_s)
        .map_err(DeployError::Invalid)?;
    let (queue_w, queue_r) = buffer::<QueueItem>(QUEUE_CAPACITY, FullPolicy::DropNewest);
    let mut app = Deployment::new();
    app.set_overrun_policy(OverrunPolicy {
        storm_threshold: u64::from(config.safety.overrun_storm_count),
    });
    let devices::Devices {
        axes: axis_devices,
        io,
        io_map,
        sim_axes,
        sim_io,
        can,
        link_events,
    } = devs;
    let crate::machine::servo::can_setup::CanDrives {
        buses: can_buses,
        sdo: can_sdo,
        sim_buses: can_sim_buses,
        ..
    } = can;
    let mut can_tx = Vec::new();
    // CANopen bus owners: rx first of all, tx right after the axis tasks (cycle order).
    for b in can_buses {
        app.add_periodic(&format!("can.{}.rx", b.iface), CanRxTask(b.rx), schedule)?;
        can_tx.push((format!("can.{}.tx", b.iface), CanTxTask(b.tx)));
    }
    let overrun_injection = Arc::new(AtomicU32::new(0));
    let mut io_task = IoTask::new(io, io_map.clone(), sim_spindle).with_plates(plates);
    if sim_io.iter().all(Option::is_some) {
        io_task = io_task.with_overrun_injection(overrun_injection.clone());
    }
    app.add_periodic("io", io_task, schedule)?;
    let estop_request = Arc::new(AtomicU32::new(0));
    let mut machine_task = MachineTask::new(setup).with_estop_request(estop_request.clone());
    if let Some(p) = &plc {
        machine_task = machine_task.with_plc(p.link);
    }
    let machine = app.add_periodic("machine", machine_task, schedule)?;
    app.add_periodic(
        "interpolator",
        InterpolatorTask::new(motion_cfg.clone(), axes.clone(), queue_r),
        schedule,
    )?;
    let mut guards = Vec::new();
    let mut delays = Vec::new();
    for ((name, dev), cfg) in axis_devices.into_iter().zip(&config.axes) {
        let i = name as usize;
        if matches!(dev, devices::AxisDevice::Can(_)) {
            delays.push((i, crate::machine::servo::can_delay::CAN_FEEDBACK_DELAY));
        }
        let letter = axis_letter(i);
        let homing = cfg.home.params();
        app.add_periodic(
            &format!("axis.{letter}"),
            AxisTask::new(letter, i, dev, homing),
            schedule,
        )?;
        guards.push((
            letter,
            i,
            AxisGuard {
                min: cfg.min_limit,
                max: cfg.max_limit,
                following_error_limit: cfg.following_error_limit,
                max_stale_cycles: (0.01 / period_s).ceil() as u32,
            },
        ));
    }
    for (name, task) in can_tx {
        app.add_periodic(&name, task, schedule)?;
    }
    let monitor = delays
        .into_iter()
        .fold(MonitorTask::new(guards), |m, (i, d)| {
            m.with_feedback_delay(i, d)
        });
    app.add_periodic("monitor", monitor, schedule)?;
    // The PLC on its own thread, after the servo tasks (the servo thread stays first).
    let plc_stats = plc.as_ref().map(|p| p.stats.clone());
    let plc_online = plc.as_ref().map(|p| p.online.clone());
    if let Some(p) = plc {
        app.add_periodic("plc", p.task, p.schedule)?;
    }
    Ok(Built {
        plc_stats,
        plc_online,
        app,
        machine,
        queue: queue_w,
        motion_cfg,
        axes,
        sim_io,
        io_map,
        sim_axes: sim_axes
            .into_iter()
            .map(|(n, h)| (axis_letter(n as usize), h))
            .collect(),
        overrun_injection,
        estop_request,
        can_sdo,
        can_sim_buses,
        link_events,
    })
}
