//! Deploying a [`Machine`]: configure and check the built tasks, subscribe the non-realtime
//! receivers, start the servo thread; and the accessors to its simulated hardware. Why here: the
//! one place a `Machine` value is made.

use super::events::{bridge_loop, Receivers};
use super::{build, lock, Built, DeployError, JobBook, Machine, Readers};
use crate::config::MachineConfig;
use crate::gcode::InterpOptions;
use crate::machine::api::*;
use crate::machine::job;
use crate::machine::servo::can_setup::CanSdo;
use crate::machine::servo::{ports, FaultEvent, JobNews, ModeEvent};
use hytask_hal::sim::{SimAxisHandle, SimIoHandle};
use std::sync::atomic::{AtomicBool, AtomicU32};
use std::sync::{Arc, Mutex};
use tokio::sync::broadcast;

impl Machine {
    /// The interpreter options with the persistent parameters as they are now.
    pub(super) fn interp_opts_now(&self) -> InterpOptions {
        let mut o = self.interp_opts.clone();
        o.parameters = self.params.as_ref().map(|p| p.snapshot());
        o
    }

    /// Deploys `config`: builds backends and tasks, checks the topology, starts the servo
    /// thread. The machine starts in e-stop.
    pub fn deploy(config: MachineConfig) -> Result<Arc<Machine>, DeployError> {
        // Exporters (the Zenoh bridge) read the servo tasks' ports and events as JSON.
        crate::machine::servo::json_views::register();
        let params = match &config.gcode.var_file {
            Some(p) => Some(Arc::new(
                crate::gcode::varfile::ParamStore::load(p)
                    .map_err(|e| DeployError::Invalid(format!("gcode.var_file: {e}")))?,
            )),
            None => None,
        };
        if crate::rt::system::lock_memory().is_err() {
            crate::rt::system::warn_not_realtime(
                "mlockall failed (no CAP_IPC_LOCK or RLIMIT_MEMLOCK too low)",
            );
        }
        let Built {
            mut app,
            machine,
            queue: queue_w,
            motion_cfg,
            axes: _,
            sim_io,
            io_map,
            sim_axes,
            overrun_injection,
            estop_request,
            can_sdo,
            can_sim_buses,
            link_events,
            plc_stats,
            plc_online,
        } = build(&config)?;
        let script_tasks = crate::machine::scripts::add(&mut app, &config)?;
        let report = app.configure()?;
        let scripts = script_tasks.bind(&app, io_map.clone())?;
        for w in &report.warnings {
            tracing::warn!("topology: {w}");
        }
        let mode_rx = app.event::<ModeEvent>("machine.mode")?.subscribe(256);
        let job_rx = app.event::<JobNews>("machine.job")?.subscribe(1024);
        let fault_rx = app.event::<FaultEvent>("machine.fault")?.subscribe(256);
        let plc_rx = match plc_stats {
            Some(_) => Some(
                app.event::<crate::plc::task::PlcFault>("plc.fault")?
                    .subscribe(16),
            ),
            None => None,
        };
        let readers = Readers {
            status: app.reader(ports::STATUS)?,
        };
        let runtime = match config.servo_thread() {
            Some(t) if t.clock == crate::config::ThreadClock::Simulated => {
                app.start_simulated(match t.sim_speed {
                    None | Some(0) => crate::rt::activity::SimPace::Unpaced,
                    Some(x) => crate::rt::activity::SimPace::Speed(f64::from(x)),
                })?
            }
            _ => app.start()?,
        };
        let servo_info = runtime
            .threads()
            .first()
            .cloned()
            .ok_or_else(|| DeployError::Invalid("no servo thread started".into()))?;
        let (events, _) = broadcast::channel(1024);
        let m = Arc::new(Machine {
            name: config.machine.name.clone(),
            interp_opts: job::interp_options(&config),
            params,
            motion_cfg,
            config,
            runtime: Mutex::new(Some(runtime)),
            machine,
            queue: queue_w,
            readers: Mutex::new(readers),
            book: Arc::new(Mutex::new(JobBook::default())),
            events,
            sim_io,
            io_map,
            overrun_injection,
            estop_request,
            sim_axes,
            can_sdo,
            can_sim_buses,
            next_job: AtomicU32::new(1),
            servo: servo_info,
            bridge_stop: Arc::new(AtomicBool::new(false)),
            bridge: Mutex::new(None),
            receivers: Mutex::new(Some(Receivers {
                mode: mode_rx,
                job: job_rx,
                fault: fault_rx,
                plc: plc_rx,
                job_lost: 0,
            })),
            link_events: Mutex::new(link_events),
            plc_stats,
            plc_online,
            scripts,
        });
        let api: std::sync::Weak<dyn MachineApi + Send + Sync> =
            Arc::downgrade(&m) as std::sync::Weak<Machine>;
        m.scripts.start(api).map_err(|e| {
            DeployError::Invalid(format!("cannot start the script operator worker: {e}"))
        })?;
        let weak = Arc::downgrade(&m);
        let stop = m.bridge_stop.clone();
        let bridge = std::thread::Builder::new()
            .name("event-bridge".into())
            .spawn(move || bridge_loop(weak, stop))
            .map_err(|e| DeployError::Invalid(format!("cannot start the event bridge: {e}")))?;
        *lock(&m.bridge) = Some(bridge);
        Ok(m)
    }

    /// The servo thread's shared information (timing statistics, realtime flag).
    pub fn servo_thread(&self) -> &Arc<crate::rt::activity::ThreadInfo> {
        &self.servo
    }

    /// Fault-injection handles of the simulated drives (tests, demos).
    pub fn sim_axis(&self, axis: char) -> Option<&SimAxisHandle> {
        self.sim_axes
            .iter()
            .find(|(c, _)| *c == axis)
            .map(|(_, h)| h)
    }

    /// Runtime SDO access to the CANopen drives (non-realtime; one request per interface
    /// at a time).
    pub fn can_sdo(&self) -> &CanSdo {
        &self.can_sdo
    }

    /// The in-memory bus of the `index`-th `sim` CAN interface (tests take it off).
    pub fn sim_can_bus(&self, index: usize) -> Option<&hytask_hal::sim::SimCanBus> {
        self.can_sim_buses.get(index)
    }

    /// The simulated I/O device `device` (config order), if it is simulated: what the
    /// outputs were told, for tests and demos.
    pub fn sim_io(&self, device: usize) -> Option<&SimIoHandle> {
        self.sim_io.get(device).and_then(Option::as_ref)
    }
}
