//! The [`MachineApi`] of a deployed machine: status, e-stop, homing, jogging, MDI, jobs,
//! overrides, task introspection, SDO access and simulated faults. Why one file: it is the operator
//! surface the control socket and the Zenoh bridge serve.

use super::events::{describe_trip, internal_operation};
use super::{lock, sdo_error, Machine, ACCEPT_TIMEOUT};
use crate::config::IoKind;
use crate::gcode::SourceLoc;
use crate::machine::api::*;
use crate::machine::job;
use crate::machine::job::PreparedJob;
use crate::machine::servo::machine_task::MachineCmd;
use crate::motion;
use serde_json::Value;
use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::time::{Duration, Instant};
use tokio::sync::broadcast;

impl MachineApi for Machine {
    fn plc(&self) -> Option<&crate::plc::online::PlcOnline> {
        self.plc_online.as_deref()
    }

    fn scripts(&self) -> Option<&crate::script::ScriptHosts> {
        Some(self.scripts.hosts())
    }

    fn status(&self) -> Status {
        // One read: every value below belongs to servo cycle `st.cycle`.
        let (st, job, mut faults) = self.consistent_view();
        let (snap, sp, mon) = (&st.machine, &st.setpoints, &st.monitor);
        let axes = self
            .axes()
            .into_iter()
            .map(|(c, i)| {
                let f = st.feedback[i];
                AxisStatus {
                    name: c.to_string(),
                    commanded: sp.joints[i],
                    actual: f.actual,
                    velocity: f.velocity,
                    following_error: mon.following_error[i],
                    max_following_error: mon.max_following_error[i],
                    homed: f.homed,
                    drive_state: f.state.to_string(),
                    fault: f.fault.map(|c| format!("0x{c:04X}")),
                }
            })
            .collect();
        let threads = lock(&self.runtime)
            .as_ref()
            .map(|rt| crate::machine::task_api::thread_timings(&rt.threads()))
            .unwrap_or_default();
        let (inputs, outputs) = (st.inputs, st.outputs);
        let map = &self.io_map;
        let mut in_map = std::collections::BTreeMap::new();
        for (i, c) in map.di.iter().enumerate() {
            in_map.insert(c.point.name.clone(), f64::from(u8::from(inputs.di(i))));
        }
        for (i, c) in map.ai.iter().enumerate() {
            in_map.insert(c.point.name.clone(), inputs.analog[i]);
        }
        let mut out_map = std::collections::BTreeMap::new();
        for (i, c) in map.dout.iter().enumerate() {
            let on = outputs.digital & (1 << i) != 0;
            out_map.insert(c.point.name.clone(), f64::from(u8::from(on)));
        }
        for (i, c) in map.ao.iter().enumerate() {
            out_map.insert(c.point.name.clone(), outputs.analog[i]);
        }
        if matches!(snap.mode, Mode::Fault | Mode::Estop) {
            if let Some(t) = snap.last_trip {
                let msg = describe_trip(&t, 0);
                if !faults.iter().any(|f| f.starts_with(&msg)) {
                    faults.push(msg);
                }
            }
        } else {
            faults.clear();
        }
        Status {
            machine: self.name.clone(),
            mode: snap.mode,
            realtime: self.servo.realtime(),
            servo_cycle: st.cycle,
            axes,
            job,
            overrides: Overrides {
                feed: snap.feed_override,
                rapid: snap.rapid_override,
                spindle: snap.spindle_override,
            },
            spindle_rpm: snap.spindle_rpm,
            faults,
            threads,
            inputs: in_map,
            outputs: out_map,
            probe: ProbeStatus {
                count: snap.probe.seq,
                line: snap.probe.line,
                tripped: snap.probe.tripped,
                position: self
                    .axes()
                    .iter()
                    .map(|&(c, i)| (c.to_string(), snap.probe.probed_mm[i]))
                    .collect(),
            },
            optional_stop: snap.optional_stop,
            plc: self
                .plc_stats
                .as_deref()
                .map(crate::plc::task::PlcStats::status),
        }
    }

    /// Not a queued command: the machine task reads the request counter every cycle, so an
    /// e-stop is taken in the next cycle even when its command slots are all busy.
    fn estop(&self) -> Result<(), ApiError> {
        self.estop_request.fetch_add(1, Ordering::AcqRel);
        crate::machine::job_cancel::cancel_current(
            self.preparation_owner(),
            crate::machine::job_cancel::Why::Estop,
        );
        let t0 = Instant::now();
        loop {
            self.wait_for_cycle_end();
            if self.snapshot().machine.mode == Mode::Estop {
                return Ok(());
            }
            if !self.servo.running() || t0.elapsed() > ACCEPT_TIMEOUT {
                return Err(ApiError::Timeout(
                    "the machine task did not enter e-stop".into(),
                ));
            }
        }
    }

    fn estop_reset(&self) -> Result<(), ApiError> {
        lock(&self.book).faults.clear();
        self.command_done(MachineCmd::EstopReset, ACCEPT_TIMEOUT)
    }

    fn machine_on(&self) -> Result<(), ApiError> {
        lock(&self.book).faults.clear();
        self.command_done(MachineCmd::On, Duration::from_secs(5))
    }

    fn machine_off(&self) -> Result<(), ApiError> {
        self.command_done(MachineCmd::Off, Duration::from_secs(30))
    }

    fn home(&self, axis: Option<&str>) -> Result<(), ApiError> {
        let mask = match axis {
            None => 0,
            Some(a) => {
                let up = a.to_ascii_uppercase();
                let (_, i) = self
                    .axes()
                    .into_iter()
                    .find(|(c, _)| up.len() == 1 && up.starts_with(*c))
                    .ok_or_else(|| ApiError::InvalidParams(format!("no axis '{a}'")))?;
                1u32 << i
            }
        };
        self.command(MachineCmd::Home { mask }).map(|_| ())
    }

    fn jog(&self, req: &JogRequest) -> Result<(), ApiError> {
        self.check_can_run(true)?;
        let up = req.axis.to_ascii_uppercase();
        let (_, i) = self
            .axes()
            .into_iter()
            .find(|(c, _)| up.len() == 1 && up.starts_with(*c))
            .ok_or_else(|| ApiError::InvalidParams(format!("no axis '{}'", req.axis)))?;
        let lim = self.motion_cfg.axes[i];
        let speed = req.velocity.abs().min(lim.max_vel_mm_s);
        let start = self.actual_pose();
        let mut end = start;
        end[i] = match req.distance {
            Some(d) => start[i] + d.copysign(req.velocity),
            None if req.velocity > 0.0 => lim.max_mm,
            None => lim.min_mm,
        };
        if (end[i] - start[i]).abs() < 1e-9 {
            return Err(ApiError::Rejected(format!(
                "axis {} is already at its soft limit",
                up
            )));
        }
        let loc = SourceLoc {
            file: Arc::from("jog"),
            line: 1,
            col: 1,
        };
        let plan = motion::plan_straight_feed(start, end, speed * 60.0, loc, &self.motion_cfg)
            .map_err(|e| ApiError::Rejected(format!("jog: {e}")))?;
        let job = Arc::new(PreparedJob {
            name: "jog".into(),
            total_lines: 1,
            commands: 2, // SetFeedRate + StraightFeed
            plan,
            probing: None,
            replay: None,
            parameters: None,
        });
        self.start_job(job, true)
    }

    fn jog_stop(&self) -> Result<(), ApiError> {
        self.command(MachineCmd::Abort).map(|_| ())
    }

    fn mdi(&self, line: &str) -> Result<(), ApiError> {
        self.check_can_run(false)?;
        let job = crate::machine::job_cancel::with_owner(self.preparation_owner(), || {
            job::prepare_mdi_within(
                line,
                &self.interp_opts_now(),
                &self.motion_cfg,
                self.actual_pose(),
                self.config.job.prepare_timeout(),
            )
        })?;
        self.start_job(Arc::new(job), false)
    }

    fn job_load(&self, src: &JobSource) -> Result<JobInfo, ApiError> {
        let opts = self.interp_opts_now();
        let budget = self.config.job.prepare_timeout();
        let job = crate::machine::job_cancel::with_owner(self.preparation_owner(), || {
            job::prepare_within(src, &opts, &self.motion_cfg, self.actual_pose(), budget)
        })?;
        let info = JobInfo {
            name: job.name.clone(),
            lines: job.total_lines,
            commands: job.commands,
            planned_time_s: job.plan.duration_s,
            distance_mm: job.plan.distance_mm,
        };
        let mut book = lock(&self.book);
        if book.active.is_none() {
            book.status = JobStatus {
                name: job.name.clone(),
                state: "loaded".into(),
                total_lines: job.total_lines,
                planned_time_s: job.plan.duration_s,
                distance_mm: job.plan.distance_mm,
                distance_to_go_mm: job.plan.distance_mm,
                ..JobStatus::default()
            };
        }
        book.loaded = Some(Arc::new(job));
        Ok(info)
    }

    fn job_run(&self) -> Result<(), ApiError> {
        self.check_can_run(false)?;
        let job = lock(&self.book)
            .loaded
            .clone()
            .ok_or_else(|| ApiError::Rejected("no job loaded".into()))?;
        self.start_job(job, false)
    }

    fn job_pause(&self) -> Result<(), ApiError> {
        self.command(MachineCmd::Pause).map(|_| ())
    }

    fn job_resume(&self) -> Result<(), ApiError> {
        self.command(MachineCmd::Resume).map(|_| ())
    }

    fn job_abort(&self) -> Result<(), ApiError> {
        crate::machine::job_cancel::cancel_current(
            self.preparation_owner(),
            crate::machine::job_cancel::Why::Abort,
        );
        self.command(MachineCmd::Abort).map(|_| ())
    }

    fn remote_lost(&self, message: &str, critical: bool) {
        self.stop_for_lost_remote(message, critical);
    }

    fn job_step(&self) -> Result<(), ApiError> {
        self.command(MachineCmd::Step).map(|_| ())
    }

    fn set_optional_stop(&self, on: bool) -> Result<bool, ApiError> {
        self.command(MachineCmd::OptionalStop { on })?;
        Ok(self.snapshot().machine.optional_stop)
    }

    fn set_overrides(&self, req: &OverrideRequest) -> Result<Overrides, ApiError> {
        let snap = self.snapshot().machine;
        let feed = req.feed.unwrap_or(snap.feed_override);
        if feed > self.config.motion.max_feed_override {
            return Err(ApiError::InvalidParams(format!(
                "feed override above this machine's maximum {}",
                self.config.motion.max_feed_override
            )));
        }
        let cmd = MachineCmd::Overrides {
            feed,
            rapid: req.rapid.unwrap_or(snap.rapid_override),
            spindle: req.spindle.unwrap_or(snap.spindle_override),
        };
        self.command(cmd)?;
        Ok(Overrides {
            feed,
            rapid: req.rapid.unwrap_or(snap.rapid_override),
            spindle: req.spindle.unwrap_or(snap.spindle_override),
        })
    }

    fn tasks(&self) -> Vec<TaskInfo> {
        lock(&self.runtime)
            .as_ref()
            .map(|rt| crate::machine::task_api::task_infos(rt.tasks()))
            .unwrap_or_default()
    }

    fn port_json(&self, name: &str) -> Result<Box<dyn crate::rt::json::JsonPortReader>, ApiError> {
        let rt = lock(&self.runtime);
        let rt = rt
            .as_ref()
            .ok_or_else(|| ApiError::Rejected("the machine is stopped".into()))?;
        rt.json_reader(name)
            .map_err(|e| ApiError::InvalidParams(e.to_string()))
    }

    fn event_json(
        &self,
        name: &str,
        capacity: usize,
    ) -> Result<Box<dyn crate::rt::json::JsonEventReceiver>, ApiError> {
        let rt = lock(&self.runtime);
        let rt = rt
            .as_ref()
            .ok_or_else(|| ApiError::Rejected("the machine is stopped".into()))?;
        rt.json_events(name, capacity)
            .map_err(|e| ApiError::InvalidParams(e.to_string()))
    }

    fn sdo_read(&self, drive: &str, index: u16, sub: u8) -> Result<Vec<u8>, ApiError> {
        self.can_sdo.read(drive, index, sub).map_err(sdo_error)
    }

    fn sdo_write(&self, drive: &str, index: u16, sub: u8, data: &[u8]) -> Result<(), ApiError> {
        self.can_sdo
            .write(drive, index, sub, data)
            .map_err(sdo_error)
    }

    fn call(&self, task: &str, operation: &str, args: &Value) -> Result<Value, ApiError> {
        if let Some(instead) = internal_operation(task, operation) {
            return Err(ApiError::Rejected(format!(
                "{task}.{operation} is the job machinery's own operation (it refers to queue \
                 items only a running job has): use {instead}"
            )));
        }
        let handle = {
            let rt = lock(&self.runtime);
            let rt = rt
                .as_ref()
                .ok_or_else(|| ApiError::Rejected("the machine is stopped".into()))?;
            crate::machine::task_api::send_call(rt.tasks(), task, operation, args)?
        };
        crate::machine::task_api::call_reply(&handle, task)
    }

    fn set_sim_input(&self, name: &str, value: f64) -> Result<(), ApiError> {
        let r = self
            .config
            .find_io(name)
            .ok_or_else(|| ApiError::InvalidParams(format!("no I/O channel '{name}'")))?;
        let handle = self
            .sim_io
            .get(r.device)
            .and_then(Option::as_ref)
            .ok_or_else(|| {
                ApiError::NotSupported(format!("'{name}' is not on a simulated device"))
            })?;
        let dev = &self.config.io[r.device];
        let res = match r.kind {
            IoKind::DigitalInput => {
                let level = dev.digital_inputs[r.channel].level(value != 0.0);
                handle.set_digital_input(r.channel, level)
            }
            IoKind::AnalogInput => {
                let raw = dev.analog_inputs[r.channel].to_raw(value);
                handle.set_analog_input(r.channel, raw)
            }
            _ => {
                return Err(ApiError::InvalidParams(format!(
                    "'{name}' is an output, not an input"
                )))
            }
        };
        res.map_err(|e| ApiError::Failed(e.to_string()))
    }

    fn sim_fault(&self, f: &SimFault) -> Result<(), ApiError> {
        if f.kind == "overrun" {
            if self.sim_io.iter().any(Option::is_none) {
                return Err(ApiError::NotSupported(
                    "overrun injection needs an all-simulated machine".into(),
                ));
            }
            let cycles = f.cycles.unwrap_or(5).clamp(1, 1000);
            self.overrun_injection.store(cycles, Ordering::Release);
            return Ok(());
        }
        let axis = f
            .axis
            .as_deref()
            .ok_or_else(|| ApiError::InvalidParams(format!("'{}' needs an axis", f.kind)))?;
        let letter = axis.to_ascii_uppercase().chars().next().unwrap_or('?');
        let h = self.sim_axis(letter).ok_or_else(|| {
            ApiError::NotSupported(format!("axis '{axis}' is not a simulated drive"))
        })?;
        let on = f.on.unwrap_or(true);
        match f.kind.as_str() {
            "drive_fault" => h.inject_fault(hytask_hal::axis::FaultCode(f.code.unwrap_or(0x2310))),
            "stall" => h.set_stalled(on),
            "disconnect" => h.set_disconnected(on),
            other => {
                return Err(ApiError::InvalidParams(format!(
                    "unknown fault kind '{other}' (drive_fault, stall, disconnect, overrun)"
                )))
            }
        }
        Ok(())
    }

    fn subscribe(&self) -> broadcast::Receiver<MachineEvent> {
        self.events.subscribe()
    }
}
