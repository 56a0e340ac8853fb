//! Runs a plan through the [`Interpolator`] at the servo period, as the servo thread would,
//! and measures the sampled trace: per-axis peak velocity, acceleration and jerk by finite
//! differences (which never exceed the true peaks of a C² trajectory), and path deviation.
//! Used by `hytask plan`, the tests and the benchmarks.

use super::config::MotionConfig;
use super::interpolator::{InterpState, Interpolator, SliceSource};
use super::segment::AuxItem;
use super::Plan;
use crate::gcode::NUM_AXES;

/// The sampled trajectory.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Trace {
    /// Servo period, s.
    pub dt_s: f64,
    /// Cartesian setpoint of every period.
    pub poses_mm: Vec<[f64; NUM_AXES]>,
    /// Source line of every period.
    pub lines: Vec<u32>,
    /// Auxiliary items and the period they were reported in.
    pub aux: Vec<(usize, AuxItem)>,
    /// State of every period.
    pub states: Vec<InterpState>,
}

impl Trace {
    /// Time from the first period to the end of motion, s.
    pub fn duration_s(&self) -> f64 {
        self.poses_mm.len().saturating_sub(1) as f64 * self.dt_s
    }

    /// Per-axis peak |velocity|, |acceleration|, |jerk| by finite differences.
    pub fn peaks(&self) -> Peaks {
        let p = &self.poses_mm;
        let dt = self.dt_s;
        let mut pk = Peaks::default();
        for i in 0..p.len() {
            for a in 0..NUM_AXES {
                if i + 1 < p.len() {
                    pk.vel[a] = pk.vel[a].max(((p[i + 1][a] - p[i][a]) / dt).abs());
                }
                if i + 2 < p.len() {
                    let d2 = p[i + 2][a] - 2.0 * p[i + 1][a] + p[i][a];
                    pk.acc[a] = pk.acc[a].max((d2 / (dt * dt)).abs());
                }
                if i + 3 < p.len() {
                    let d3 = p[i + 3][a] - 3.0 * p[i + 2][a] + 3.0 * p[i + 1][a] - p[i][a];
                    pk.jerk[a] = pk.jerk[a].max((d3 / (dt * dt * dt)).abs());
                }
            }
        }
        pk
    }
}

/// Unit of axis `a`'s position: mm, deg for the rotary axes A B C.
pub fn axis_unit(a: usize) -> &'static str {
    if (3..6).contains(&a) {
        "deg"
    } else {
        "mm"
    }
}

impl Trace {
    /// Velocity, acceleration and jerk of axis `a` at period `i` by backward differences
    /// (the same differences as [`Trace::peaks`]; 0 where the trace has too few periods
    /// before `i`).
    pub fn derivatives(&self, i: usize, a: usize) -> [f64; 3] {
        let p = |k: usize| self.poses_mm[i - k][a];
        let dt = self.dt_s;
        let mut d = [0.0; 3];
        if i >= 1 {
            d[0] = (p(0) - p(1)) / dt;
        }
        if i >= 2 {
            d[1] = (p(0) - 2.0 * p(1) + p(2)) / (dt * dt);
        }
        if i >= 3 {
            d[2] = (p(0) - 3.0 * p(1) + 3.0 * p(2) - p(3)) / (dt * dt * dt);
        }
        d
    }

    /// XYZ path speed at period `i` (backward difference), mm/s.
    pub fn speed_mm_s(&self, i: usize) -> f64 {
        (0..3)
            .map(|a| self.derivatives(i, a)[0].powi(2))
            .sum::<f64>()
            .sqrt()
    }

    /// The axes a CSV shows: X Y Z, and every other axis that moves.
    pub fn shown_axes(&self) -> Vec<usize> {
        let first = self.poses_mm.first().copied().unwrap_or([0.0; NUM_AXES]);
        (0..NUM_AXES)
            .filter(|&a| a < 3 || self.poses_mm.iter().any(|p| p[a] != first[a]))
            .collect()
    }

    /// Writes the trace as CSV: a header naming every column with its unit (`t_s`, then
    /// per axis `X_mm,X_vel_mm_s,X_acc_mm_s2,X_jerk_mm_s3`, deg for A B C), then one row per
    /// servo period with the setpoint and its [`derivatives`](Self::derivatives), numbers
    /// in Rust's shortest round-trip form (a reader gets the planner's exact values).
    pub fn write_csv(&self, out: &mut impl std::io::Write) -> std::io::Result<()> {
        let axes = self.shown_axes();
        write!(out, "t_s")?;
        for &a in &axes {
            let (n, u) = (super::AXIS_NAMES[a], axis_unit(a));
            write!(out, ",{n}_{u},{n}_vel_{u}_s,{n}_acc_{u}_s2,{n}_jerk_{u}_s3")?;
        }
        writeln!(out)?;
        for i in 0..self.poses_mm.len() {
            write!(out, "{}", i as f64 * self.dt_s)?;
            for &a in &axes {
                let [v, acc, j] = self.derivatives(i, a);
                write!(out, ",{},{v},{acc},{j}", self.poses_mm[i][a])?;
            }
            writeln!(out)?;
        }
        Ok(())
    }
}

/// Per-axis peaks of a trace.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Peaks {
    /// mm/s.
    pub vel: [f64; NUM_AXES],
    /// mm/s².
    pub acc: [f64; NUM_AXES],
    /// mm/s³.
    pub jerk: [f64; NUM_AXES],
}

impl Peaks {
    /// Largest ratio peak/limit over all axes and the three quantities (≤ 1 means within).
    pub fn worst_ratio(&self, cfg: &MotionConfig) -> f64 {
        let mut r = 0.0f64;
        for (a, l) in cfg.axes.iter().enumerate() {
            r = r.max(self.vel[a] / l.max_vel_mm_s);
            r = r.max(self.acc[a] / l.max_acc_mm_s2);
            r = r.max(self.jerk[a] / l.max_jerk_mm_s3);
        }
        r
    }
}

/// Runs `plan` to completion; `control(period, interp)` is called before every period (to
/// change overrides, hold, resume, abort). Commands that need the machine are acknowledged
/// at once. Stops when the interpolator is done or idle after motion, or after `max_periods`.
pub fn run(
    plan: &Plan,
    cfg: &MotionConfig,
    max_periods: usize,
    mut control: impl FnMut(usize, &mut Interpolator),
) -> Trace {
    let mut interp = Interpolator::new(cfg, plan.start_mm);
    let mut src = SliceSource::new(&plan.items);
    let mut tr = Trace {
        dt_s: cfg.servo_period_s,
        ..Trace::default()
    };
    tr.poses_mm.push(plan.start_mm);
    tr.lines.push(0);
    tr.states.push(InterpState::Idle);
    for n in 0..max_periods {
        control(n, &mut interp);
        let out = *interp.step(&mut src);
        tr.poses_mm.push(out.pose_mm);
        tr.lines.push(out.line);
        tr.states.push(out.state);
        if let Some(a) = out.aux {
            tr.aux.push((n + 1, a));
        }
        match out.state {
            InterpState::Waiting => interp.aux_done(),
            InterpState::Done | InterpState::Idle if n > 0 && out.aux.is_none() => break,
            _ => {}
        }
    }
    tr
}

/// Runs `plan` to its end without intervention, with room for ten times its planned
/// duration (a runaway trace stops there instead of filling memory).
pub fn run_all(plan: &Plan, cfg: &MotionConfig) -> Trace {
    run(plan, cfg, max_periods(plan, cfg), |_, _| {})
}

/// Period budget of a trace of `plan`.
pub fn max_periods(plan: &Plan, cfg: &MotionConfig) -> usize {
    (plan.duration_s * 10.0 / cfg.servo_period_s) as usize + 100_000
}

/// Peaks of a whole job measured on the fly (constant memory, for long programs).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Measured {
    /// Per-axis peaks, as [`Trace::peaks`] would give.
    pub peaks: Peaks,
    /// Servo periods run (including the initial pose).
    pub periods: usize,
    /// Time from the first period to the end of motion, s.
    pub duration_s: f64,
}

/// Runs `plan` to completion like [`run`] without intervention, keeping only the last four
/// poses: the finite-difference peaks of a job of any length in constant memory.
pub fn measure(plan: &Plan, cfg: &MotionConfig, max_periods: usize) -> Measured {
    let mut interp = Interpolator::new(cfg, plan.start_mm);
    let mut src = SliceSource::new(&plan.items);
    let dt = cfg.servo_period_s;
    let mut m = Measured::default();
    let mut w: [[f64; NUM_AXES]; 4] = [plan.start_mm; 4];
    let mut count = 1usize;
    let mut push = |p: [f64; NUM_AXES], m: &mut Measured, count: &mut usize| {
        w.rotate_left(1);
        w[3] = p;
        *count += 1;
        for a in 0..NUM_AXES {
            m.peaks.vel[a] = m.peaks.vel[a].max(((w[3][a] - w[2][a]) / dt).abs());
            if *count >= 3 {
                let d2 = w[3][a] - 2.0 * w[2][a] + w[1][a];
                m.peaks.acc[a] = m.peaks.acc[a].max((d2 / (dt * dt)).abs());
            }
            if *count >= 4 {
                let d3 = w[3][a] - 3.0 * w[2][a] + 3.0 * w[1][a] - w[0][a];
                m.peaks.jerk[a] = m.peaks.jerk[a].max((d3 / (dt * dt * dt)).abs());
            }
        }
    };
    for n in 0..max_periods {
        let out = *interp.step(&mut src);
        push(out.pose_mm, &mut m, &mut count);
        match out.state {
            InterpState::Waiting => interp.aux_done(),
            InterpState::Done | InterpState::Idle if n > 0 && out.aux.is_none() => break,
            _ => {}
        }
    }
    m.periods = count;
    m.duration_s = (count - 1) as f64 * dt;
    m
}

/// Distance from `p` to the polyline `path` (XYZ), mm.
pub fn distance_to_polyline_mm(p: &[f64; NUM_AXES], path: &[[f64; NUM_AXES]]) -> f64 {
    let mut best = f64::INFINITY;
    for w in path.windows(2) {
        let (a, b) = (&w[0], &w[1]);
        let mut ab2 = 0.0;
        let mut t = 0.0;
        for i in 0..3 {
            ab2 += (b[i] - a[i]) * (b[i] - a[i]);
            t += (p[i] - a[i]) * (b[i] - a[i]);
        }
        let t = if ab2 > 0.0 {
            (t / ab2).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let d2: f64 = (0..3)
            .map(|i| (p[i] - (a[i] + t * (b[i] - a[i]))).powi(2))
            .sum();
        best = best.min(d2.sqrt());
    }
    best
}
