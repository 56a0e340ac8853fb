//! The paper's positional-control chain on hytask's realtime core: sensor → interpolator →
//! PID → effector, four periodic tasks on one 1 kHz thread connected by data objects, driving
//! a simulated plant (a 1 kg mass with viscous friction). A monitor task on the same thread
//! raises `monitor.tracking_error` when |setpoint − position| exceeds a limit, and the
//! interpolator's `move_to` command completes when the position is reached.
//!
//! Run: `cargo run --release --example position_control` (as root for SCHED_FIFO; otherwise
//! it runs with ordinary scheduling and says so). `tests/rt_position_control.rs` runs the same
//! tasks on the stepped activity.

use hytask::rt::prelude::*;

/// Data object names.
pub mod names {
    /// Raw plant position (written by the effector's plant simulation), m.
    pub const PLANT_POSITION: &str = "plant.position_m";
    /// Measured position (sensor), m.
    pub const POSITION: &str = "sensor.position_m";
    /// Interpolated setpoint, m.
    pub const SETPOINT: &str = "interpolator.setpoint_m";
    /// Control effort, N.
    pub const EFFORT: &str = "pid.effort_n";
    /// Tracking-error event.
    pub const TRACKING_ERROR: &str = "monitor.tracking_error";
}

/// Payload of the tracking-error event.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct TrackingError {
    /// Setpoint − position when raised, m.
    pub error_m: f64,
    /// Cycle at which it was raised.
    pub cycle: u64,
}

fn period_s(ctx: &StepContext) -> f64 {
    ctx.period_ns as f64 * 1e-9
}

/// Reads the plant's position (one cycle old, like a real encoder) and publishes it.
#[derive(Default)]
pub struct Sensor {
    raw: Option<DataReader<f64>>,
    out: Option<DataWriter<f64>>,
    position_m: f64,
}

impl Task for Sensor {
    type Command = NoCommands;
    fn configure(&mut self, ctx: &mut Configure<'_>) -> Result<(), TaskError> {
        self.raw = Some(ctx.input(names::PLANT_POSITION));
        self.out = Some(ctx.output(names::POSITION));
        Ok(())
    }
    fn read_inputs(&mut self, _: &StepContext) {
        if let Some(r) = &mut self.raw {
            r.get(&mut self.position_m);
        }
    }
    fn update(&mut self, _: &StepContext) -> Result<(), TaskError> {
        if let Some(o) = &mut self.out {
            o.set(self.position_m);
        }
        Ok(())
    }
}

/// Commands of the interpolator.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum InterpolatorCmd {
    /// Move to `target_m` at `speed_m_s`.
    MoveTo {
        /// Target, m.
        target_m: f64,
        /// Speed, m/s.
        speed_m_s: f64,
    },
}

impl Commands for InterpolatorCmd {
    fn operations() -> &'static [OperationDescriptor] {
        &[OperationDescriptor {
            name: "move_to",
            doc: "Ramp the setpoint to a target at a speed; done when the position is reached.",
            params: &[
                ParamDescriptor {
                    name: "target_m",
                    ty: ArgType::Float,
                },
                ParamDescriptor {
                    name: "speed_m_s",
                    ty: ArgType::Float,
                },
            ],
            next: NextCommand::AfterCompletion,
        }]
    }
    fn operation_index(&self) -> usize {
        0
    }
    fn from_args(operation: &str, args: &[ArgValue]) -> Result<Self, ArgError> {
        let a = Args::new(Self::operations(), operation, args)?;
        Ok(Self::MoveTo {
            target_m: a.float(0)?,
            speed_m_s: a.float(1)?,
        })
    }
}

/// Ramps the setpoint towards the commanded target.
pub struct Interpolator {
    position: Option<DataReader<f64>>,
    out: Option<DataWriter<f64>>,
    position_m: f64,
    setpoint_m: f64,
    target_m: f64,
    speed_m_s: f64,
    /// Position tolerance of "reached", m.
    pub tolerance_m: f64,
    /// Largest speed accepted, m/s.
    pub max_speed_m_s: f64,
    /// Consecutive cycles the position must stay within tolerance to count as reached.
    pub settle_cycles: u32,
    in_tolerance: u32,
}

impl Default for Interpolator {
    fn default() -> Self {
        Self {
            position: None,
            out: None,
            position_m: 0.0,
            setpoint_m: 0.0,
            target_m: 0.0,
            speed_m_s: 0.0,
            tolerance_m: 1e-4,
            max_speed_m_s: 100.0,
            settle_cycles: 20,
            in_tolerance: 0,
        }
    }
}

impl Task for Interpolator {
    type Command = InterpolatorCmd;
    fn configure(&mut self, ctx: &mut Configure<'_>) -> Result<(), TaskError> {
        self.position = Some(ctx.input(names::POSITION));
        self.out = Some(ctx.output(names::SETPOINT));
        Ok(())
    }
    fn read_inputs(&mut self, _: &StepContext) {
        if let Some(r) = &mut self.position {
            r.get(&mut self.position_m);
        }
    }
    fn update(&mut self, ctx: &StepContext) -> Result<(), TaskError> {
        let step = self.speed_m_s * period_s(ctx);
        self.setpoint_m += (self.target_m - self.setpoint_m).clamp(-step, step);
        if let Some(o) = &mut self.out {
            o.set(self.setpoint_m);
        }
        Ok(())
    }
    fn accept(&mut self, c: &InterpolatorCmd, _: &StepContext) -> Result<(), RejectReason> {
        let InterpolatorCmd::MoveTo {
            target_m,
            speed_m_s,
        } = *c;
        if !target_m.is_finite() {
            return Err(RejectReason::BadParameters("target_m must be finite"));
        }
        if !(speed_m_s > 0.0 && speed_m_s <= self.max_speed_m_s) {
            return Err(RejectReason::BadParameters("speed_m_s out of range"));
        }
        self.target_m = target_m;
        self.speed_m_s = speed_m_s;
        self.in_tolerance = 0;
        Ok(())
    }
    /// Completion condition: the setpoint is at the target and the measured position has
    /// stayed within tolerance of it for `settle_cycles` cycles (reached, not passing through).
    fn progress(&mut self, c: &InterpolatorCmd, _: &StepContext) -> Progress {
        let InterpolatorCmd::MoveTo { target_m, .. } = *c;
        if self.setpoint_m == target_m && (self.position_m - target_m).abs() <= self.tolerance_m {
            self.in_tolerance += 1;
        } else {
            self.in_tolerance = 0;
        }
        if self.in_tolerance >= self.settle_cycles {
            Progress::Done
        } else {
            Progress::Running
        }
    }
}

/// PID position controller.
pub struct Pid {
    setpoint: Option<DataReader<f64>>,
    position: Option<DataReader<f64>>,
    out: Option<DataWriter<f64>>,
    setpoint_m: f64,
    position_m: f64,
    integral: f64,
    last_error_m: f64,
    /// Gains (N/m, N/(m·s), N·s/m).
    pub kp: f64,
    /// Integral gain.
    pub ki: f64,
    /// Derivative gain.
    pub kd: f64,
}

impl Default for Pid {
    fn default() -> Self {
        Self {
            setpoint: None,
            position: None,
            out: None,
            setpoint_m: 0.0,
            position_m: 0.0,
            integral: 0.0,
            last_error_m: 0.0,
            kp: 900.0,
            ki: 500.0,
            kd: 60.0,
        }
    }
}

impl Task for Pid {
    type Command = NoCommands;
    fn configure(&mut self, ctx: &mut Configure<'_>) -> Result<(), TaskError> {
        self.setpoint = Some(ctx.input(names::SETPOINT));
        self.position = Some(ctx.input(names::POSITION));
        self.out = Some(ctx.output(names::EFFORT));
        Ok(())
    }
    fn read_inputs(&mut self, _: &StepContext) {
        if let Some(r) = &mut self.setpoint {
            r.get(&mut self.setpoint_m);
        }
        if let Some(r) = &mut self.position {
            r.get(&mut self.position_m);
        }
    }
    fn update(&mut self, ctx: &StepContext) -> Result<(), TaskError> {
        let dt = period_s(ctx);
        let e = self.setpoint_m - self.position_m;
        self.integral += e * dt;
        let d = (e - self.last_error_m) / dt;
        self.last_error_m = e;
        let u = self.kp * e + self.ki * self.integral + self.kd * d;
        if let Some(o) = &mut self.out {
            o.set(u.clamp(-200.0, 200.0));
        }
        Ok(())
    }
}

/// Applies the effort to the simulated plant (mass, viscous friction) and publishes its
/// position.
pub struct Effector {
    effort: Option<DataReader<f64>>,
    out: Option<DataWriter<f64>>,
    effort_n: f64,
    position_m: f64,
    velocity_m_s: f64,
    /// Mass, kg.
    pub mass_kg: f64,
    /// Viscous friction, N·s/m.
    pub friction_n_s_m: f64,
}

impl Default for Effector {
    fn default() -> Self {
        Self {
            effort: None,
            out: None,
            effort_n: 0.0,
            position_m: 0.0,
            velocity_m_s: 0.0,
            mass_kg: 1.0,
            friction_n_s_m: 2.0,
        }
    }
}

impl Task for Effector {
    type Command = NoCommands;
    fn configure(&mut self, ctx: &mut Configure<'_>) -> Result<(), TaskError> {
        self.effort = Some(ctx.input(names::EFFORT));
        self.out = Some(ctx.output(names::PLANT_POSITION));
        Ok(())
    }
    fn read_inputs(&mut self, _: &StepContext) {
        if let Some(r) = &mut self.effort {
            r.get(&mut self.effort_n);
        }
    }
    fn update(&mut self, ctx: &StepContext) -> Result<(), TaskError> {
        let dt = period_s(ctx);
        let a = (self.effort_n - self.friction_n_s_m * self.velocity_m_s) / self.mass_kg;
        self.velocity_m_s += a * dt;
        self.position_m += self.velocity_m_s * dt;
        if let Some(o) = &mut self.out {
            o.set(self.position_m);
        }
        Ok(())
    }
}

/// Watches the tracking error and raises an event when it exceeds the limit (once per
/// excursion).
pub struct Monitor {
    setpoint: Option<DataReader<f64>>,
    position: Option<DataReader<f64>>,
    event: Option<EventSource<TrackingError>>,
    setpoint_m: f64,
    position_m: f64,
    over: bool,
    /// Limit, m.
    pub limit_m: f64,
}

impl Default for Monitor {
    fn default() -> Self {
        Self {
            setpoint: None,
            position: None,
            event: None,
            setpoint_m: 0.0,
            position_m: 0.0,
            over: false,
            limit_m: 0.005,
        }
    }
}

impl Task for Monitor {
    type Command = NoCommands;
    fn configure(&mut self, ctx: &mut Configure<'_>) -> Result<(), TaskError> {
        self.setpoint = Some(ctx.input(names::SETPOINT));
        self.position = Some(ctx.input(names::POSITION));
        self.event = Some(ctx.event("tracking_error"));
        Ok(())
    }
    fn read_inputs(&mut self, _: &StepContext) {
        if let Some(r) = &mut self.setpoint {
            r.get(&mut self.setpoint_m);
        }
        if let Some(r) = &mut self.position {
            r.get(&mut self.position_m);
        }
    }
    fn update(&mut self, ctx: &StepContext) -> Result<(), TaskError> {
        let e = self.setpoint_m - self.position_m;
        let over = e.abs() > self.limit_m;
        if over && !self.over {
            if let Some(ev) = &mut self.event {
                ev.emit(TrackingError {
                    error_m: e,
                    cycle: ctx.cycle,
                });
            }
        }
        self.over = over;
        Ok(())
    }
}

/// Builds the chain on one thread (start order = data-flow order) with the monitor last.
pub fn deploy(
    period_ns: u64,
    priority: i32,
) -> Result<(Deployment, TaskHandle<InterpolatorCmd>), DeployError> {
    let mut app = Deployment::new();
    let s = Schedule {
        priority,
        period_ns,
        cpu: None,
    };
    app.add_periodic("sensor", Sensor::default(), s)?;
    let interp = app.add_periodic("interpolator", Interpolator::default(), s)?;
    app.add_periodic("pid", Pid::default(), s)?;
    app.add_periodic("effector", Effector::default(), s)?;
    app.add_periodic("monitor", Monitor::default(), s)?;
    app.configure()?;
    Ok((app, interp))
}

#[allow(dead_code)]
fn main() -> Result<(), Box<dyn std::error::Error>> {
    let caps = hytask::rt::deploy::check_realtime();
    if caps.fifo_scheduling {
        let _ = hytask::rt::system::lock_memory();
    }
    let (app, interp) = deploy(1_000_000, 80)?;
    let mut errors = app
        .event::<TrackingError>(names::TRACKING_ERROR)?
        .subscribe(64);
    let rt = app.start()?;
    let mut position = rt.reader::<f64>(names::POSITION)?;
    println!("realtime: {}", rt.realtime());

    let timeout = std::time::Duration::from_secs(10);
    let c = interp.send(InterpolatorCmd::MoveTo {
        target_m: 0.1,
        speed_m_s: 0.2,
    })?;
    println!("move_to 0.1 m at 0.2 m/s: {:?}", c.wait(timeout));
    println!("position: {:.6} m", position.latest().unwrap_or_default());

    // Same operation called by name with dynamic arguments, too fast to track.
    let c = rt
        .task("interpolator")
        .ok_or("no interpolator")?
        .commands()
        .send_args("move_to", &[ArgValue::Float(0.0), ArgValue::Float(20.0)])?;
    println!("move_to 0.0 m at 20 m/s: {:?}", c.wait(timeout));
    while let Some(e) = errors.pop() {
        println!(
            "tracking error event: {:.4} m at cycle {}",
            e.error_m, e.cycle
        );
    }
    let status = rt.status();
    println!("{}", serde_json::to_string_pretty(&status)?);
    rt.stop();
    Ok(())
}
