//! Shared helpers of the motion tests: canonical streams built in code (the interpreter is
//! developed in parallel), and trace checks. Included by the `motion_*` tests with `mod`.
#![allow(dead_code, clippy::unwrap_used)]

use hytask::gcode::canon::MotionControl;
use hytask::gcode::{Canon, CanonCmd, SourceLoc};
use hytask::motion::trace::{self, Trace};
use hytask::motion::{MotionConfig, Plan};

/// Relative tolerance on limit checks: finite differences of an f64 trace.
pub const LIMIT_TOL: f64 = 1e-6;

/// Builds canon streams with increasing line numbers.
#[derive(Default)]
pub struct Prog {
    /// The stream built so far.
    pub canon: Vec<Canon>,
    line: u32,
}

impl Prog {
    /// An empty program.
    pub fn new() -> Self {
        Self::default()
    }
    /// Appends a command on the next line.
    pub fn cmd(&mut self, cmd: CanonCmd) -> &mut Self {
        self.line += 1;
        self.canon.push(Canon {
            loc: SourceLoc {
                file: "test.ngc".into(),
                line: self.line,
                col: 1,
            },
            cmd,
        });
        self
    }
    /// Line number of the last command.
    pub fn line(&self) -> u32 {
        self.line
    }
    /// `F`, mm/min.
    pub fn feed(&mut self, f_mm_min: f64) -> &mut Self {
        self.cmd(CanonCmd::SetFeedRate(f_mm_min))
    }
    /// `G64 P`.
    pub fn g64(&mut self, p: f64) -> &mut Self {
        self.cmd(CanonCmd::SetMotionControl(MotionControl::Continuous {
            tolerance: p,
        }))
    }
    /// `G1 X Y Z`.
    pub fn g1(&mut self, x: f64, y: f64, z: f64) -> &mut Self {
        self.cmd(CanonCmd::StraightFeed(pose(x, y, z)))
    }
    /// `G0 X Y Z`.
    pub fn g0(&mut self, x: f64, y: f64, z: f64) -> &mut Self {
        self.cmd(CanonCmd::StraightTraverse(pose(x, y, z)))
    }
}

/// A pose with X Y Z set.
pub fn pose(x: f64, y: f64, z: f64) -> [f64; 9] {
    let mut p = [0.0; 9];
    p[0] = x;
    p[1] = y;
    p[2] = z;
    p
}

/// Runs a plan without intervention.
pub fn run(plan: &Plan, cfg: &MotionConfig) -> Trace {
    trace::run(plan, cfg, max_periods(plan, cfg), |_, _| {})
}

/// Generous bound on the periods a plan needs.
pub fn max_periods(plan: &Plan, cfg: &MotionConfig) -> usize {
    (plan.duration_s * 20.0 / cfg.servo_period_s) as usize + 20_000
}

/// Asserts every axis' peak velocity, acceleration and jerk is within its limit.
pub fn assert_within_limits(tr: &Trace, cfg: &MotionConfig) {
    let pk = tr.peaks();
    for (a, l) in cfg.axes.iter().enumerate() {
        let t = 1.0 + LIMIT_TOL;
        assert!(
            pk.vel[a] <= l.max_vel_mm_s * t,
            "axis {a}: velocity {} > {}",
            pk.vel[a],
            l.max_vel_mm_s
        );
        assert!(
            pk.acc[a] <= l.max_acc_mm_s2 * t,
            "axis {a}: acceleration {} > {}",
            pk.acc[a],
            l.max_acc_mm_s2
        );
        assert!(
            pk.jerk[a] <= l.max_jerk_mm_s3 * t,
            "axis {a}: jerk {} > {}",
            pk.jerk[a],
            l.max_jerk_mm_s3
        );
    }
}

/// Largest distance of the trace from the programmed polyline (XYZ).
pub fn max_deviation(tr: &Trace, path: &[[f64; 9]]) -> f64 {
    tr.poses_mm
        .iter()
        .map(|p| trace::distance_to_polyline_mm(p, path))
        .fold(0.0, f64::max)
}

/// Last pose of a trace.
pub fn last(tr: &Trace) -> [f64; 9] {
    *tr.poses_mm.last().unwrap()
}

/// One feed hold measured by [`hold_stops`].
#[derive(Debug, Clone, Copy)]
pub struct Stop {
    /// Period of the request.
    pub period: usize,
    /// Path speed when the hold was requested, mm/s.
    pub speed_mm_s: f64,
    /// Path length from the request to standing still, mm.
    pub dist_mm: f64,
    /// Time from the request to standing still, s.
    pub time_s: f64,
    /// Worst peak/limit ratio of the stop's trace (with the four periods before it).
    pub peak_ratio: f64,
}

/// Runs `p` nominally and, at every period `n` from the fifth where `at(n)`, hands `branch`
/// a clone of the interpolator and its source as they stand after that period, with a trace
/// seeded with the last four nominal poses (the branch's finite differences start from
/// them): one nominal run serves every request point.
pub fn branch_at_periods<'a>(
    p: &'a Plan,
    cfg: &MotionConfig,
    at: impl Fn(usize) -> bool,
    mut branch: impl FnMut(usize, hytask::motion::Interpolator, hytask::motion::SliceSource<'a>, Trace),
) {
    use hytask::motion::{InterpState, Interpolator, SliceSource};
    let mut it = Interpolator::new(cfg, p.start_mm);
    let mut src = SliceSource::new(&p.items);
    let mut hist = [p.start_mm; 4];
    for n in 0.. {
        let out = *it.step(&mut src);
        hist.rotate_left(1);
        hist[3] = out.pose_mm;
        if out.state == InterpState::Done {
            break;
        }
        if n < 4 || !at(n) {
            continue;
        }
        let mut tr = Trace {
            dt_s: cfg.servo_period_s,
            ..Trace::default()
        };
        tr.poses_mm.extend_from_slice(&hist);
        branch(n, it.clone(), src.clone(), tr);
    }
}

/// A feed hold requested at every period `n` of a nominal run of `p` where `at(n)`.
pub fn hold_stops(p: &Plan, cfg: &MotionConfig, at: impl Fn(usize) -> bool) -> Vec<Stop> {
    use hytask::motion::InterpState;
    let dist =
        |a: &[f64; 9], b: &[f64; 9]| (0..9).map(|i| (a[i] - b[i]).powi(2)).sum::<f64>().sqrt();
    let mut stops = Vec::new();
    branch_at_periods(p, cfg, at, |n, mut h, mut hs, mut tr| {
        let speed_mm_s = dist(&tr.poses_mm[3], &tr.poses_mm[2]) / cfg.servo_period_s;
        h.hold();
        let mut d = 0.0;
        for _ in 0..20_000 {
            let o = *h.step(&mut hs);
            d += dist(&o.pose_mm, tr.poses_mm.last().unwrap());
            tr.poses_mm.push(o.pose_mm);
            if o.state != InterpState::Running {
                break;
            }
        }
        stops.push(Stop {
            period: n,
            speed_mm_s,
            dist_mm: d,
            time_s: (tr.poses_mm.len() - 4) as f64 * cfg.servo_period_s,
            peak_ratio: tr.peaks().worst_ratio(cfg),
        });
    });
    stops
}
