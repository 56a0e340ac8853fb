//! The PLC task: one scan per period of its thread. Reads the input image (I/O inputs, the
//! machine's requests and state), runs the program, writes the output image (the PLC's
//! outputs and its answers to the machine). A runtime fault or a watchdog trip puts the PLC
//! in fault: every bound output takes its safe value and a `fault` event names the cause.
//!
//! Nothing here allocates after `configure`: the value arrays are sized at construction.

use super::bind::{Bindings, InSignal, OutSignal};
use super::link::{ports, PlcCommand, PlcRequest, RequestKind};
use super::online::{OnlineRt, Running};
use super::{Fault, Program, Value};
use crate::machine::api::Mode;
use crate::machine::servo::{ports as servo_ports, Inputs, MachineSnapshot};
use crate::rt::prelude::*;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;

/// Why the PLC is in fault (event `plc.fault`).
#[derive(Debug, Clone, PartialEq)]
pub enum PlcFault {
    /// The program faulted (division by zero, index, budget) at its file:line:col.
    Program(Fault),
    /// The scan overran its period this many times in a row.
    Watchdog {
        /// Consecutive overruns.
        consecutive: u32,
    },
}

impl std::fmt::Display for PlcFault {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            PlcFault::Program(e) => e.fmt(f),
            PlcFault::Watchdog { consecutive } => write!(
                f,
                "PLC watchdog: the scan overran its period {consecutive} times in a row"
            ),
        }
    }
}

/// Scan statistics, shared with the non-realtime side (atomics only).
#[derive(Debug, Default)]
pub struct PlcStats {
    /// Scans run.
    pub scans: AtomicU64,
    /// Scans that took longer than the period.
    pub overruns: AtomicU64,
    /// Longest scan, ns.
    pub max_ns: AtomicU64,
    /// Last scan, ns.
    pub last_ns: AtomicU64,
    /// Scan-time histogram: bucket i counts scans of [2^i, 2^(i+1)) ns.
    pub histogram: [AtomicU64; 32],
    /// In fault.
    pub faulted: AtomicBool,
    /// Variables forced (online), as of the last scan.
    pub forced: AtomicU64,
    /// Program versions loaded online since start.
    pub reloads: AtomicU64,
}

impl PlcStats {
    fn record(&self, ns: u64, overrun: bool) {
        self.scans.fetch_add(1, Ordering::Relaxed);
        if overrun {
            self.overruns.fetch_add(1, Ordering::Relaxed);
        }
        self.max_ns.fetch_max(ns, Ordering::Relaxed);
        self.last_ns.store(ns, Ordering::Relaxed);
        let b = (63 - ns.max(1).leading_zeros() as usize).min(self.histogram.len() - 1);
        self.histogram[b].fetch_add(1, Ordering::Relaxed);
    }

    /// The statistics as `status` shows them.
    pub fn status(&self) -> crate::machine::api::PlcStatus {
        let us = |ns: u64| ns as f64 / 1000.0;
        crate::machine::api::PlcStatus {
            scans: self.scans.load(Ordering::Relaxed),
            p50_us: us(self.quantile_ns(0.5)),
            max_us: us(self.max_ns.load(Ordering::Relaxed)),
            overruns: self.overruns.load(Ordering::Relaxed),
            fault: self.faulted.load(Ordering::Relaxed),
            forced: self.forced.load(Ordering::Relaxed),
            reloads: self.reloads.load(Ordering::Relaxed),
        }
    }

    /// Upper bound of the bucket holding the `q` quantile (0..=1) of scan times, ns.
    pub fn quantile_ns(&self, q: f64) -> u64 {
        let counts: Vec<u64> = self
            .histogram
            .iter()
            .map(|c| c.load(Ordering::Relaxed))
            .collect();
        let total: u64 = counts.iter().sum();
        if total == 0 {
            return 0;
        }
        let want = ((total as f64) * q).ceil().max(1.0) as u64;
        let mut seen = 0;
        for (i, c) in counts.iter().enumerate() {
            seen += c;
            if seen >= want {
                return (2u64 << i) - 1;
            }
        }
        u64::MAX
    }
}

/// Setup of the PLC task, from `[plc]`.
#[derive(Debug, Clone, Copy)]
pub struct PlcSetup {
    /// Consecutive overruns that trip the watchdog (0: no watchdog).
    pub watchdog_overruns: u32,
    /// Every configured axis, bit i = axis i.
    pub axes_mask: u32,
}

/// The PLC task.
pub struct PlcTask {
    program: Program,
    bindings: Bindings,
    setup: PlcSetup,
    stats: Arc<PlcStats>,
    in_vals: Vec<Value>,
    out_vals: Vec<Value>,
    inputs_in: Option<DataReader<Inputs>>,
    request_in: Option<DataReader<PlcRequest>>,
    snapshot_in: Option<DataReader<MachineSnapshot>>,
    command_out: Option<DataWriter<PlcCommand>>,
    fault_ev: Option<EventSource<PlcFault>>,
    inputs: Inputs,
    request: PlcRequest,
    snap: MachineSnapshot,
    cmd: PlcCommand,
    reset_seen: u32,
    overrun_streak: u32,
    watchdog: bool,
    reported: bool,
    retain: Option<super::retain::Retain>,
    online: Option<OnlineRt>,
}

/// Binds `program`'s process image to `bindings` (allocates: at load, off the scan).
pub fn bind_program(program: &mut Program, bindings: &Bindings) {
    let ins: Vec<_> = bindings.inputs.iter().map(|(v, _)| *v).collect();
    let outs: Vec<_> = bindings.outputs.iter().map(|(v, _, s)| (*v, *s)).collect();
    program.bind(&ins, &outs);
}

impl PlcTask {
    /// A task scanning `program` with `bindings` (already bound to the program).
    pub fn new(mut program: Program, bindings: Bindings, setup: PlcSetup) -> Self {
        bind_program(&mut program, &bindings);
        let mut cmd = PlcCommand::default();
        for (_, s, _) in &bindings.outputs {
            match *s {
                OutSignal::DigitalOutput(i) => cmd.digital_mask |= 1 << i,
                OutSignal::AnalogOutput(i) => cmd.analog_mask |= 1 << i,
                _ => {}
            }
        }
        PlcTask {
            in_vals: vec![Value::Bool(false); bindings.inputs.len()],
            out_vals: bindings.outputs.iter().map(|(_, _, s)| *s).collect(),
            program,
            bindings,
            setup,
            stats: Arc::new(PlcStats::default()),
            inputs_in: None,
            request_in: None,
            snapshot_in: None,
            command_out: None,
            fault_ev: None,
            inputs: Inputs::default(),
            request: PlcRequest::default(),
            snap: MachineSnapshot::default(),
            cmd,
            reset_seen: 0,
            overrun_streak: 0,
            watchdog: false,
            reported: false,
            retain: None,
            online: None,
        }
    }

    /// Takes online writes, forces and new program versions from `online` at scan
    /// boundaries, and answers its reads.
    pub fn with_online(mut self, online: OnlineRt) -> Self {
        self.online = Some(online);
        self
    }

    /// The program (before the task starts: for the online channel's first version).
    pub fn program(&self) -> &Program {
        &self.program
    }

    /// The RETAIN writer, if any.
    pub fn retain(&self) -> Option<&super::retain::Retain> {
        self.retain.as_ref()
    }

    /// Publishes the RETAIN variables after every scan for the state-file writer.
    pub fn with_retain(mut self, retain: super::retain::Retain) -> Self {
        self.retain = Some(retain);
        self
    }

    /// The statistics the task keeps.
    pub fn stats(&self) -> Arc<PlcStats> {
        self.stats.clone()
    }

    fn input(&self, s: InSignal, reset: bool) -> Value {
        let r = &self.request;
        let mode = self.snap.mode;
        let pending = |k| r.kind == k && self.cmd.done_seq != r.seq;
        match s {
            InSignal::DigitalInput(i) => Value::Bool(self.inputs.di(i)),
            InSignal::AnalogInput(i) => {
                Value::Real(self.inputs.analog.get(i).copied().unwrap_or(0.0))
            }
            InSignal::RequestedDigital(i) => {
                Value::Bool(i < 64 && r.outputs.digital & (1 << i) != 0)
            }
            InSignal::RequestedAnalog(i) => {
                Value::Real(r.outputs.analog.get(i).copied().unwrap_or(0.0))
            }
            InSignal::Estop => Value::Bool(mode == Mode::Estop),
            InSignal::On => Value::Bool(!matches!(mode, Mode::Estop | Mode::Off)),
            InSignal::Mode => Value::Int(mode_number(mode)),
            InSignal::Homed => Value::Bool(
                self.setup.axes_mask != 0
                    && self.snap.homed_mask & self.setup.axes_mask == self.setup.axes_mask,
            ),
            InSignal::AxisHomed(a) => Value::Bool(self.snap.homed_mask & (1 << a) != 0),
            InSignal::InPosition => Value::Bool(r.in_position),
            InSignal::Fault => Value::Bool(mode == Mode::Fault),
            InSignal::EstopReset => Value::Bool(reset),
            InSignal::JobRunning => Value::Bool(matches!(mode, Mode::Running | Mode::Holding)),
            InSignal::FeedHold => Value::Bool(mode == Mode::Holding),
            InSignal::M6Request => Value::Bool(pending(RequestKind::ToolChange)),
            InSignal::M6Tool => Value::Int(i64::from(r.tool)),
            InSignal::McodeRequest => Value::Bool(pending(RequestKind::UserMcode)),
            InSignal::McodeNumber => Value::Int(i64::from(r.mcode)),
            InSignal::McodeP => Value::Real(r.p),
            InSignal::McodeQ => Value::Real(r.q),
        }
    }

    /// Applies the output image to the command for the machine.
    fn output(&mut self) {
        let c = &mut self.cmd;
        c.feed_hold = false;
        c.start_inhibit = false;
        c.estop = false;
        for ((_, s, _), v) in self.bindings.outputs.iter().zip(&self.out_vals) {
            let on = matches!(v, Value::Bool(true));
            match *s {
                OutSignal::DigitalOutput(i) => {
                    if on {
                        c.digital |= 1 << i;
                    } else {
                        c.digital &= !(1 << i);
                    }
                }
                OutSignal::AnalogOutput(i) => {
                    if let (Some(a), Value::Real(x)) = (c.analog.get_mut(i), v) {
                        *a = *x;
                    }
                }
                OutSignal::M6Done if on && self.request.kind == RequestKind::ToolChange => {
                    c.done_seq = self.request.seq;
                }
                OutSignal::McodeDone if on && self.request.kind == RequestKind::UserMcode => {
                    c.done_seq = self.request.seq;
                }
                OutSignal::M6Done | OutSignal::McodeDone => {}
                OutSignal::M66Digital(i) => {
                    if on {
                        c.m66_digital |= 1 << i;
                    } else {
                        c.m66_digital &= !(1 << i);
                    }
                }
                OutSignal::M66Analog(i) => {
                    if let (Some(a), Value::Real(x)) = (c.m66_analog.get_mut(i), v) {
                        *a = *x;
                    }
                }
                OutSignal::FeedHold => c.feed_hold |= on,
                OutSignal::StartInhibit => c.start_inhibit |= on,
                OutSignal::Estop => c.estop |= on,
            }
        }
    }

    fn fault(&mut self, f: PlcFault) {
        self.cmd.fault = true;
        self.stats.faulted.store(true, Ordering::Relaxed);
        if !self.reported {
            self.reported = true;
            if let Some(ev) = &mut self.fault_ev {
                ev.emit(f);
            }
        }
    }
}

/// `machine.mode` as a number.
pub fn mode_number(m: Mode) -> i64 {
    match m {
        Mode::Estop => 0,
        Mode::Off => 1,
        Mode::Idle => 2,
        Mode::Homing => 3,
        Mode::Manual => 4,
        Mode::Running => 5,
        Mode::Holding => 6,
        Mode::Fault => 7,
    }
}

impl Task for PlcTask {
    type Command = NoCommands;

    fn configure(&mut self, ctx: &mut Configure<'_>) -> Result<(), TaskError> {
        self.inputs_in = Some(ctx.input(servo_ports::INPUTS));
        self.snapshot_in = Some(ctx.input(servo_ports::SNAPSHOT));
        self.request_in = Some(ctx.input(ports::REQUEST));
        self.command_out = Some(ctx.output(ports::COMMAND));
        self.fault_ev = Some(ctx.event("fault"));
        Ok(())
    }

    fn read_inputs(&mut self, _ctx: &StepContext) {
        if let Some(r) = &mut self.inputs_in {
            r.get(&mut self.inputs);
        }
        if let Some(r) = &mut self.snapshot_in {
            r.get(&mut self.snap);
        }
        if let Some(r) = &mut self.request_in {
            r.get(&mut self.request);
        }
    }

    fn update(&mut self, ctx: &StepContext) -> Result<(), TaskError> {
        let t0 = std::time::Instant::now();
        if let Some(o) = &mut self.online {
            let swapped = o.before_scan(Running {
                program: &mut self.program,
                bindings: &mut self.bindings,
                retain: &mut self.retain,
            });
            if swapped {
                self.stats.reloads.fetch_add(1, Ordering::Relaxed);
                // A new version starts clean, unless the watchdog holds the PLC down.
                if !self.watchdog {
                    self.cmd.fault = false;
                    self.reported = false;
                    self.stats.faulted.store(false, Ordering::Relaxed);
                }
            }
        }
        let reset = self.request.estop_reset_seq != self.reset_seen;
        self.reset_seen = self.request.estop_reset_seq;
        for i in 0..self.bindings.inputs.len() {
            self.in_vals[i] = self.input(self.bindings.inputs[i].1, reset);
        }
        let result = if self.watchdog {
            // Outputs to their safe values, as the program's own fault does.
            for (v, (_, _, s)) in self.out_vals.iter_mut().zip(&self.bindings.outputs) {
                *v = *s;
            }
            Ok(())
        } else {
            self.program
                .scan(&self.in_vals, &mut self.out_vals, ctx.now_ns as i64)
        };
        self.output();
        if let Err(f) = result {
            self.fault(PlcFault::Program(f));
        }
        if let Some(r) = &self.retain {
            r.shared.publish(&self.program, &r.ids);
        }
        if let Some(o) = &mut self.online {
            o.after_scan(&self.program);
        }
        self.stats
            .forced
            .store(self.program.forced_count() as u64, Ordering::Relaxed);
        self.cmd.scans = self.cmd.scans.wrapping_add(1);
        if let Some(w) = &mut self.command_out {
            w.set(self.cmd);
        }
        let ns = t0.elapsed().as_nanos() as u64;
        let overrun = ctx.period_ns > 0 && ns > ctx.period_ns;
        self.stats.record(ns, overrun);
        self.overrun_streak = if overrun { self.overrun_streak + 1 } else { 0 };
        let limit = self.setup.watchdog_overruns;
        if limit > 0 && self.overrun_streak >= limit && !self.watchdog {
            self.watchdog = true;
            self.fault(PlcFault::Watchdog {
                consecutive: self.overrun_streak,
            });
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plc::bind::Bindings;
    use crate::plc::{compile, Options};

    fn task() -> PlcTask {
        let src = "PROGRAM P\nVAR_OUTPUT lamp : BOOL; hold : BOOL; END_VAR\nlamp := TRUE;\nhold := FALSE;\nEND_PROGRAM\n";
        let p = compile("w.st", src, Options::default()).unwrap();
        let lamp = p.var("lamp").unwrap();
        let hold = p.var("hold").unwrap();
        let b = Bindings {
            inputs: Vec::new(),
            outputs: vec![
                (lamp, OutSignal::DigitalOutput(2), Value::Bool(false)),
                (hold, OutSignal::FeedHold, Value::Bool(true)),
            ],
        };
        PlcTask::new(
            p,
            b,
            PlcSetup {
                watchdog_overruns: 10,
                axes_mask: 0,
            },
        )
    }

    fn step(t: &mut PlcTask, cycle: u64, period_ns: u64) {
        let ctx = StepContext {
            now_ns: cycle * 10_000_000,
            period_ns,
            cycle,
        };
        t.update(&ctx).unwrap();
    }

    /// Scans that keep overrunning the period trip the watchdog: the PLC goes into fault and
    /// its outputs to their safe values (feed hold on, the lamp off). Scans within the period
    /// never do.
    #[test]
    fn the_watchdog_trips_on_consecutive_overruns() {
        let mut t = task();
        for c in 0..50 {
            step(&mut t, c, 1_000_000_000);
        }
        assert!(!t.cmd.fault);
        assert_eq!(t.cmd.digital, 1 << 2);
        assert!(!t.cmd.feed_hold);
        // A period no scan can meet: every scan overruns.
        for c in 50..59 {
            step(&mut t, c, 1);
            assert!(!t.cmd.fault, "not before 10 in a row");
        }
        step(&mut t, 59, 1);
        assert!(t.cmd.fault);
        assert!(t.stats().faulted.load(Ordering::Relaxed));
        assert_eq!(t.stats().overruns.load(Ordering::Relaxed), 10);
        step(&mut t, 60, 1_000_000_000);
        assert_eq!(t.cmd.digital & (1 << 2), 0, "lamp at its safe value");
        assert!(t.cmd.feed_hold, "feed hold at its safe value");
    }
}
