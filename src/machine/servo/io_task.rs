//! The `io` task: first on the servo thread. Reads every input of every I/O device into one
//! [`Inputs`] value, and writes the [`Outputs`] the machine task asked for (one cycle of
//! output latency, which keeps the reads at the very start of the cycle).
//!
//! When the task stops (daemon shutdown), it writes every output's configured safe state.
//!
//! A device that cannot be read keeps its last values and counts stale cycles; the machine
//! task treats a stale e-stop input as pressed (fail-safe).
//!
//! On simulated I/O the task also plays the spindle's part of the plant: the at-speed input
//! turns on `spin_up_s` after the spindle enable output, so M3 waits as it would on a real
//! machine; and a touch plate (`touch_plate`) switches the probe input from the axis position.

use super::{ports, AxisFeedback, Inputs, Outputs};
use crate::machine::devices::{DynIo, IoMap};
use crate::rt::prelude::*;
use hytask_hal::sim::SimIoHandle;

/// The simulated spindle's at-speed signal.
pub struct SimSpindle {
    /// Machine-wide index of the enable output.
    pub enable_output: usize,
    /// Device handle and channel of the at-speed input, and its inversion.
    pub at_speed: (SimIoHandle, usize, bool),
    /// Cycles from enable to at speed.
    pub spin_up_cycles: u32,
    on_cycles: u32,
}

impl SimSpindle {
    /// A spindle that reaches speed `spin_up_cycles` after being enabled.
    pub fn new(
        enable_output: usize,
        at_speed: (SimIoHandle, usize, bool),
        spin_up_cycles: u32,
    ) -> Self {
        SimSpindle {
            enable_output,
            at_speed,
            spin_up_cycles,
            on_cycles: 0,
        }
    }

    fn update(&mut self, outputs: &Outputs) {
        let on = outputs.digital & (1 << self.enable_output) != 0;
        self.on_cycles = if on {
            self.on_cycles.saturating_add(1)
        } else {
            0
        };
        let at_speed = on && self.on_cycles >= self.spin_up_cycles;
        let (handle, channel, invert) = &self.at_speed;
        let _ = handle.set_digital_input(*channel, at_speed != *invert);
    }
}

/// The simulated touch plate (`[[io]] touch_plate`): drives a simulated digital input from
/// an axis' actual position of the previous cycle.
pub struct SimPlate {
    /// Axis letter whose feedback is read.
    pub axis: char,
    /// The input is active at or below this position.
    pub top: f64,
    /// Device handle and channel of the input, and its inversion.
    pub input: (SimIoHandle, usize, bool),
    feedback: Option<DataReader<AxisFeedback>>,
    last: AxisFeedback,
}

impl SimPlate {
    /// A plate at `top` under `axis`, switching `input`.
    pub fn new(axis: char, top: f64, input: (SimIoHandle, usize, bool)) -> Self {
        SimPlate {
            axis,
            top,
            input,
            feedback: None,
            last: AxisFeedback::default(),
        }
    }

    fn update(&mut self) {
        if let Some(r) = &mut self.feedback {
            r.get(&mut self.last);
        }
        let touching = self.last.valid && self.last.actual <= self.top;
        let (handle, channel, invert) = &self.input;
        let _ = handle.set_digital_input(*channel, touching != *invert);
    }
}

/// The I/O task.
pub struct IoTask {
    devices: Vec<DynIo>,
    map: IoMap,
    inputs: Option<DataWriter<Inputs>>,
    outputs: Option<DataReader<Outputs>>,
    current: Inputs,
    written: Option<Outputs>,
    /// Every output in its configured safe state: written until the machine task has
    /// published outputs, and again when the task stops (daemon shutdown).
    safe: Outputs,
    spindle: Option<SimSpindle>,
    plates: Vec<SimPlate>,
    overrun: Option<std::sync::Arc<std::sync::atomic::AtomicU32>>,
}

impl IoTask {
    /// A task over `devices`, numbered by `map`.
    pub fn new(devices: Vec<DynIo>, map: IoMap, spindle: Option<SimSpindle>) -> Self {
        IoTask {
            overrun: None,
            safe: map.safe_outputs(),
            devices,
            map,
            inputs: None,
            outputs: None,
            current: Inputs::default(),
            written: None,
            spindle,
            plates: Vec::new(),
        }
    }

    /// Simulated touch plates to drive before the inputs are read.
    pub fn with_plates(mut self, plates: Vec<SimPlate>) -> Self {
        self.plates = plates;
        self
    }

    fn read_all(&mut self) -> bool {
        let mut ok = true;
        for (i, ch) in self.map.di.iter().enumerate() {
            match self.devices[ch.device].read_digital_input(ch.channel) {
                Ok(level) => {
                    let bit = 1u64 << i;
                    if ch.point.active(level) {
                        self.current.digital |= bit;
                    } else {
                        self.current.digital &= !bit;
                    }
                }
                Err(_) => ok = false,
            }
        }
        for (i, ch) in self.map.ai.iter().enumerate() {
            match self.devices[ch.device].read_analog_input(ch.channel) {
                Ok(raw) => self.current.analog[i] = ch.point.to_engineering(raw),
                Err(_) => ok = false,
            }
        }
        ok
    }

    fn write_all(&mut self, out: &Outputs) {
        let last = self.written;
        let mut ok = true;
        for (i, ch) in self.map.dout.iter().enumerate() {
            let active = out.digital & (1 << i) != 0;
            let changed = last.is_none_or(|l| (l.digital & (1 << i) != 0) != active);
            if changed {
                ok &= self.devices[ch.device]
                    .write_digital_output(ch.channel, ch.point.level(active))
                    .is_ok();
            }
        }
        for (i, ch) in self.map.ao.iter().enumerate() {
            let changed = last.is_none_or(|l| l.analog[i] != out.analog[i]);
            if changed {
                ok &= self.devices[ch.device]
                    .write_analog_output(ch.channel, ch.point.to_raw(out.analog[i]))
                    .is_ok();
            }
        }
        // A failed write is retried next cycle: remember nothing as written.
        self.written = ok.then_some(*out);
    }
}

impl IoTask {
    /// Simulation only: each time the counter is above zero, the task burns 1.5 periods of
    /// CPU (and decrements it), so the servo thread overruns: the overrun-storm path of the
    /// machine can be tried for real.
    pub fn with_overrun_injection(
        mut self,
        counter: std::sync::Arc<std::sync::atomic::AtomicU32>,
    ) -> Self {
        self.overrun = Some(counter);
        self
    }

    fn burn(&self, period_ns: u64) {
        use std::sync::atomic::Ordering;
        let Some(c) = &self.overrun else {
            return;
        };
        if c.load(Ordering::Acquire) == 0 {
            return;
        }
        c.fetch_sub(1, Ordering::AcqRel);
        let t0 = std::time::Instant::now();
        let d = std::time::Duration::from_nanos(period_ns * 3 / 2);
        while t0.elapsed() < d {
            std::hint::spin_loop();
        }
    }
}

impl Task for IoTask {
    type Command = NoCommands;

    fn configure(&mut self, ctx: &mut Configure<'_>) -> Result<(), TaskError> {
        self.inputs = Some(ctx.output(ports::INPUTS));
        self.outputs = Some(ctx.input(ports::OUTPUTS));
        for p in &mut self.plates {
            p.feedback = Some(ctx.input(&ports::feedback(p.axis)));
        }
        Ok(())
    }

    fn read_inputs(&mut self, _ctx: &StepContext) {
        for p in &mut self.plates {
            p.update();
        }
        let ok = self.read_all();
        self.current.link_ok = ok;
        self.current.stale_cycles = if ok {
            0
        } else {
            self.current.stale_cycles.saturating_add(1)
        };
        if let Some(w) = &mut self.inputs {
            w.set(self.current);
        }
    }

    fn update(&mut self, ctx: &StepContext) -> Result<(), TaskError> {
        self.burn(ctx.period_ns);
        let mut out = self.safe;
        if let Some(r) = &mut self.outputs {
            r.get(&mut out);
        }
        self.write_all(&out);
        if let Some(s) = &mut self.spindle {
            s.update(&out);
        }
        Ok(())
    }

    /// The last act of the servo thread (shutdown, or a stopped deployment): every output to
    /// its safe state, whatever the machine task asked last, each channel written again.
    fn stop(&mut self) {
        self.written = None;
        let safe = self.safe;
        self.write_all(&safe);
        if let Some(s) = &mut self.spindle {
            s.update(&safe);
        }
    }
}
