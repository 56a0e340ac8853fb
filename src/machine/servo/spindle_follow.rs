//! Spindle-synchronised moves in the servo cycle (G33, each G76 pass, G33.1), run by the
//! `interpolator` task in place of the velocity-locked segments the planner made for them.
//!
//! The plan marks each such move with [`AuxKind::SpindleSync`](crate::motion::AuxKind) (a
//! barrier: the axes are at rest there). The interpolator stops at it; this follower then
//! waits for the spindle's index pulse and moves the tool along the straight line so that
//! its progress follows the *measured* spindle position ([`SpindleLock`]), so that every
//! pass of a thread cuts the same groove whatever the spindle speed does. G33.1 asks for
//! the spindle reversal at the depth ([`SpindleFollower::reversed`]) and follows the
//! spindle back out. When the move is over, the interpolator skips the planned segments
//! and goes on from their end, which is where the follower left the tool.
//!
//! As in LinuxCNC, feed override and feed hold do not act on a synchronised move (the
//! thread would be cut wrong). An abort, or an error of the lock (the spindle turns too fast
//! for the axes at this pitch), stops the tool on the line within the acceleration limit.
//!
//! The spindle position comes from the simulated spindle ([`SimSpindle`]: a speed ramp
//! toward the commanded speed, a position, an index pulse), stepped each cycle with the
//! commanded speed. A machine without one has no spindle position: its G33 and G76 passes
//! run velocity-locked as planned, and G33.1 is refused (without a reversal in the plan it
//! would strip the thread).
//!
//! Fixed-size state, constant work per cycle, no allocation: it runs on the servo thread.

use crate::gcode::NUM_AXES;
use crate::machine::sim_spindle::{SimSpindle, SimSpindleParams};
use crate::motion::spindle_lock::{LockError, LockMode, SpindleLock, SpindleSample};
use crate::motion::MotionConfig;

/// Shortest synchronised move that is run (shorter ones are done at once).
const MIN_LENGTH_MM: f64 = 1e-9;

/// What the follower did in one cycle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FollowStep {
    /// Commanded pose.
    pub pose_mm: [f64; NUM_AXES],
    /// Distance left along the move, mm.
    pub to_go_mm: f64,
    /// The move ended normally this cycle: the interpolator goes on.
    pub done: bool,
    /// After an abort or an error: the tool came to rest this cycle, at `pose_mm`.
    pub stopped: bool,
    /// The lock failed this cycle (the tool is stopping).
    pub error: Option<LockError>,
}

/// Why a move could not start.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum StartOutcome {
    /// Following (or waiting for the index).
    Following,
    /// Nothing to follow: run the planned segments (no spindle position, not a tap), or a
    /// move of zero length.
    RunPlanned,
}

/// One synchronised move in progress.
#[derive(Debug, Clone)]
struct SyncMove {
    lock: SpindleLock,
    start: [f64; NUM_AXES],
    unit: [f64; NUM_AXES],
    length: f64,
    amax: f64,
    /// Position and velocity along the move in the last cycle.
    s: f64,
    v: f64,
    /// Stopping (abort, or the lock failed): brake to rest on the line.
    stopping: bool,
}

impl SyncMove {
    fn pose(&self) -> [f64; NUM_AXES] {
        let mut p = self.start;
        for (q, u) in p.iter_mut().zip(self.unit) {
            *q += u * self.s;
        }
        p
    }

    /// One braking cycle: the speed along the line toward 0 within the acceleration limit.
    /// True once at rest.
    fn brake(&mut self, dt: f64) -> bool {
        let v0 = self.v;
        let dv = self.amax * dt;
        self.v = if v0 > 0.0 {
            (v0 - dv).max(0.0)
        } else {
            (v0 + dv).min(0.0)
        };
        self.s += 0.5 * (v0 + self.v) * dt;
        self.v == 0.0
    }
}

/// Where a thread move that ended normally left off, for the next one to continue its
/// synchronisation (see [`SpindleLock::continuing`]).
#[derive(Debug, Clone, Copy)]
struct ChainEnd {
    /// Where the tool stopped.
    pose: [f64; NUM_AXES],
    /// The revolution at which its target reached the end, and the spindle direction.
    rev_end: f64,
    dir: f64,
    /// Servo cycles since it ended.
    age: u32,
}

/// Cycles within which a synchronised move starting where the last one ended continues it:
/// the interpolator reaches the next move's barrier one or two cycles after the end item.
const CHAIN_CYCLES: u32 = 4;

/// The synchronised-move runner of the `interpolator` task (see the module documentation).
#[derive(Debug, Clone)]
pub struct SpindleFollower {
    spindle: Option<SimSpindle>,
    sample: SpindleSample,
    reversed: bool,
    mv: Option<SyncMove>,
    chain: Option<ChainEnd>,
}

impl SpindleFollower {
    /// A follower with the simulated spindle `spindle` (its position feedback), or none.
    pub fn new(spindle: Option<SimSpindleParams>) -> SpindleFollower {
        SpindleFollower {
            spindle: spindle.map(|p| SimSpindle::new(p, 0.0)),
            sample: SpindleSample::default(),
            reversed: false,
            mv: None,
            chain: None,
        }
    }

    /// True when there is a spindle position to follow.
    pub fn has_spindle(&self) -> bool {
        self.spindle.is_some()
    }

    /// A synchronised move is running (or stopping).
    pub fn active(&self) -> bool {
        self.mv.is_some()
    }

    /// A rigid tap has reversed the spindle: the spindle turns against its commanded
    /// direction until the tap is out.
    pub fn reversed(&self) -> bool {
        self.reversed
    }

    /// The spindle's reading of this cycle.
    pub fn sample(&self) -> SpindleSample {
        self.sample
    }

    /// Advances the simulated spindle one cycle toward the commanded speed `rpm` (signed,
    /// negative for M4), reversed while a rigid tap comes out. Call once per cycle.
    pub fn spindle_step(&mut self, dt: f64, rpm: f64) {
        let rpm = if self.reversed { -rpm } else { rpm };
        if let Some(sp) = &mut self.spindle {
            self.sample = sp.step(dt, rpm);
        }
        if let Some(c) = &mut self.chain {
            c.age += 1;
            if c.age > CHAIN_CYCLES {
                self.chain = None;
            }
        }
    }

    /// Starts the move from `from` to `end` at `pitch_mm` per revolution (G33.1 with `tap`),
    /// within the axis limits of `cfg` along its direction.
    pub fn start(
        &mut self,
        cfg: &MotionConfig,
        from: [f64; NUM_AXES],
        end: [f64; NUM_AXES],
        pitch_mm: f64,
        tap: bool,
    ) -> Result<StartOutcome, LockError> {
        self.mv = None;
        self.reversed = false;
        // A thread move that starts where the last one ended, at once, goes on with its
        // synchronisation (no wait for the index).
        let chain = self
            .chain
            .take()
            .filter(|c| !tap && c.pose.iter().zip(&from).all(|(a, b)| (a - b).abs() <= 1e-6));
        if self.spindle.is_none() {
            return if tap {
                Err(LockError::NoSpindlePosition)
            } else {
                Ok(StartOutcome::RunPlanned)
            };
        }
        let mut unit = [0.0; NUM_AXES];
        let mut length2 = 0.0;
        for i in 0..NUM_AXES {
            unit[i] = end[i] - from[i];
            length2 += unit[i] * unit[i];
        }
        let length = length2.sqrt();
        if length <= MIN_LENGTH_MM {
            return Ok(StartOutcome::RunPlanned);
        }
        let (mut vmax, mut amax) = (f64::INFINITY, f64::INFINITY);
        for (u, lim) in unit.iter_mut().zip(&cfg.axes) {
            *u /= length;
            if u.abs() > 1e-12 {
                vmax = vmax.min(lim.max_vel_mm_s / u.abs());
                amax = amax.min(lim.max_acc_mm_s2 / u.abs());
            }
        }
        let mode = if tap {
            LockMode::RigidTap
        } else {
            LockMode::Thread
        };
        let lock = match chain {
            Some(c) => SpindleLock::continuing(pitch_mm, length, vmax, amax, c.rev_end, c.dir),
            None => SpindleLock::new(mode, pitch_mm, length, vmax, amax),
        };
        self.mv = Some(SyncMove {
            lock,
            start: from,
            unit,
            length,
            amax,
            s: 0.0,
            v: 0.0,
            stopping: false,
        });
        Ok(StartOutcome::Following)
    }

    /// Stop the move on its line within the acceleration limit (an abort).
    pub fn stop(&mut self) {
        self.chain = None;
        if let Some(m) = &mut self.mv {
            m.stopping = true;
        }
    }

    /// Drops the move at once (the axes are no longer commanded: e-stop, tracking).
    pub fn cancel(&mut self) {
        self.mv = None;
        self.reversed = false;
        self.chain = None;
    }

    /// One cycle of the running move (call after [`Self::spindle_step`]). `None` when no
    /// move runs.
    pub fn step(&mut self, dt: f64) -> Option<FollowStep> {
        let m = self.mv.as_mut()?;
        let mut out = FollowStep {
            pose_mm: [0.0; NUM_AXES],
            to_go_mm: 0.0,
            done: false,
            stopped: false,
            error: None,
        };
        if m.stopping {
            out.stopped = m.brake(dt);
        } else {
            match m.lock.step(dt, &self.sample) {
                Ok(st) => {
                    if st.reverse_spindle {
                        self.reversed = true;
                    }
                    m.s = st.s;
                    m.v = st.v;
                    out.done = st.done;
                }
                Err(e) => {
                    out.error = Some(e);
                    m.stopping = true;
                    out.stopped = m.brake(dt);
                }
            }
        }
        out.pose_mm = m.pose();
        out.to_go_mm = (m.length - m.s).max(0.0);
        if out.done && !m.stopping && m.lock.mode() == LockMode::Thread {
            let (rev_end, dir) = m.lock.end_revolution();
            self.chain = Some(ChainEnd {
                pose: out.pose_mm,
                rev_end,
                dir,
                age: 0,
            });
        }
        if out.done || out.stopped {
            self.mv = None;
            self.reversed = false;
        }
        Some(out)
    }
}

/// The machine task's view of the follower's errors: each failed synchronised move once.
#[derive(Debug, Clone, Copy, Default)]
pub struct SyncErrors {
    seen: u32,
}

impl SyncErrors {
    /// The error of a synchronised move that failed since the last call, if any.
    pub fn take(&mut self, sp: &super::Setpoints) -> Option<LockError> {
        if sp.sync_error_seq == self.seen {
            return None;
        }
        self.seen = sp.sync_error_seq;
        sp.sync_error
    }
}

/// The simulated spindle of `config` when its spindle is `simulated` (its at-speed input is
/// on simulated I/O): it reaches `max_rpm` in `spin_up_s`, the time the simulated at-speed
/// input takes too.
pub fn sim_spindle_for(
    config: &crate::config::MachineConfig,
    simulated: bool,
) -> Option<SimSpindleParams> {
    let s = config.spindle.as_ref().filter(|_| simulated)?;
    Some(sim_spindle_params(s.max_rpm, s.spin_up_s))
}

/// The simulated spindle's dynamics for a spindle that reaches `max_rpm` in `spin_up_s`.
pub fn sim_spindle_params(max_rpm: f64, spin_up_s: f64) -> SimSpindleParams {
    let top = (max_rpm / 60.0).max(1.0);
    SimSpindleParams {
        accel_rps2: if spin_up_s > 0.0 {
            top / spin_up_s
        } else {
            top * 1000.0
        },
        ripple: 0.0,
        ripple_hz: 0.0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cfg() -> MotionConfig {
        MotionConfig::default()
    }

    #[test]
    fn without_a_spindle_position_threads_run_as_planned_and_taps_are_refused() {
        let mut f = SpindleFollower::new(None);
        let (a, b) = ([0.0; NUM_AXES], {
            let mut e = [0.0; NUM_AXES];
            e[2] = -5.0;
            e
        });
        assert_eq!(
            f.start(&cfg(), a, b, 1.0, false),
            Ok(StartOutcome::RunPlanned)
        );
        let e = f.start(&cfg(), a, b, 1.0, true).unwrap_err();
        assert!(e.to_string().contains("G33.1"), "{e}");
        assert!(!f.active());
    }

    /// Runs the follower's current move to its end at 600 rpm; returns the poses, one per
    /// cycle, and the spindle revolutions of each.
    fn run_to_end(f: &mut SpindleFollower, dt: f64) -> Vec<([f64; NUM_AXES], f64)> {
        let mut out = Vec::new();
        for _ in 0..100_000 {
            f.spindle_step(dt, 600.0);
            let st = f.step(dt).unwrap();
            assert_eq!(st.error, None);
            out.push((st.pose_mm, f.sample().revs));
            if st.done {
                return out;
            }
        }
        panic!("the move did not end");
    }

    /// G76's exit taper after its thread: the taper continues the thread's synchronisation
    /// at once (no wait of up to a revolution for the index with the tool in the cut), and
    /// once caught up its progress is locked to the spindle in phase with the thread.
    /// Acceleration stays within the limit through the corner. A move that starts somewhere
    /// else, or later, waits for the index as before.
    #[test]
    fn a_thread_move_starting_where_the_last_ended_continues_its_synchronisation() {
        let p = sim_spindle_params(6000.0, 0.2);
        let (dt, pitch) = (0.001, 1.5);
        let mut f = SpindleFollower::new(Some(p));
        for _ in 0..500 {
            f.spindle_step(dt, 600.0); // up to speed: 10 rev/s
        }
        let start = [0.0; NUM_AXES];
        let mut corner = start;
        corner[2] = -30.0;
        f.start(&cfg(), start, corner, pitch, false).unwrap();
        let thread = run_to_end(&mut f, dt);
        let rev0 = thread
            .iter()
            .find(|(p, _)| p[2] < 0.0)
            .map(|&(_, r)| r)
            .unwrap();
        let mut exit = corner;
        exit[0] = 3.0;
        exit[2] = -33.0;
        let taper_len = 18.0f64.sqrt();
        f.spindle_step(dt, 600.0); // the interpolator reaches the next barrier
        assert_eq!(
            f.start(&cfg(), corner, exit, pitch, false),
            Ok(StartOutcome::Following)
        );
        let taper = run_to_end(&mut f, dt);
        assert!(
            taper[1].0[0] > 0.0,
            "moving in its second cycle, not waiting for the index"
        );
        // Locked in phase with the thread once caught up: the taper's progress is the pitch
        // times the revolutions since the thread's target reached the corner.
        // The thread started on the index: an integer revolution, in the cycle it moved.
        let rev_index = rev0.floor();
        assert!(rev0 - rev_index < 0.02, "started on the index: {rev0}");
        let rev_corner = rev_index + 30.0 / pitch;
        let mid = taper.len() / 2;
        let (pose, revs) = taper[mid];
        let s = (pose[0].powi(2) + (pose[2] + 30.0).powi(2)).sqrt();
        assert!(s < taper_len - 0.5, "mid-taper, not braking yet: {s}");
        // The lock's own steady offset (feed-forward of this cycle's speed), mid-thread.
        let (tp, trevs) = thread[thread.len() / 2];
        let thread_offset = -tp[2] - pitch * (trevs - rev_index);
        let taper_offset = s - pitch * (revs - rev_corner);
        assert!(
            (taper_offset - thread_offset).abs() < 1e-6,
            "in phase: the taper is {taper_offset} mm off the spindle, the thread {thread_offset}"
        );
        // Acceleration of every axis through the corner within the limit.
        let poses: Vec<[f64; NUM_AXES]> = thread.iter().chain(&taper).map(|p| p.0).collect();
        for (i, lim) in cfg().axes.iter().enumerate() {
            let v: Vec<f64> = poses.windows(2).map(|w| (w[1][i] - w[0][i]) / dt).collect();
            let a = v
                .windows(2)
                .map(|w| ((w[1] - w[0]) / dt).abs())
                .fold(0.0, f64::max);
            assert!(
                a <= lim.max_acc_mm_s2 * (1.0 + 1e-9),
                "axis {i}: acceleration {a}"
            );
        }
        // From elsewhere, or after a while: the index again.
        let elsewhere = [1.0; NUM_AXES];
        let mut end = elsewhere;
        end[2] -= 5.0;
        f.start(&cfg(), elsewhere, end, pitch, false).unwrap();
        f.spindle_step(dt, 600.0);
        let first = f.step(dt).unwrap().pose_mm;
        f.spindle_step(dt, 600.0);
        let second = f.step(dt).unwrap().pose_mm;
        assert!(
            first == elsewhere || second == elsewhere,
            "waits for the index"
        );
    }

    #[test]
    fn an_abort_brakes_on_the_line_within_the_acceleration_limit() {
        let p = sim_spindle_params(6000.0, 0.2);
        let mut f = SpindleFollower::new(Some(p));
        let mut end = [0.0; NUM_AXES];
        end[2] = -30.0;
        f.start(&cfg(), [0.0; NUM_AXES], end, 1.5, false).unwrap();
        let dt = 0.001;
        let mut z = Vec::new();
        for n in 0..20_000 {
            f.spindle_step(dt, 600.0);
            if n == 1500 {
                f.stop();
            }
            let st = f.step(dt).unwrap();
            assert_eq!(st.error, None);
            z.push(st.pose_mm[2]);
            if st.stopped {
                break;
            }
        }
        assert!(!f.active());
        let v: Vec<f64> = z.windows(2).map(|w| (w[1] - w[0]) / dt).collect();
        let a = v
            .windows(2)
            .map(|w| ((w[1] - w[0]) / dt).abs())
            .fold(0.0, f64::max);
        assert!(a <= 500.0 * (1.0 + 1e-9), "acceleration {a}");
        assert!(v[1400].abs() > 10.0, "was cutting: {}", v[1400]);
        assert!(*z.last().unwrap() > -30.0, "stopped before the end");
    }
}
