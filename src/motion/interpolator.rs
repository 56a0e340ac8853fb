//! The realtime interpolator: each servo period it advances along the segment queue and
//! produces axis setpoints. No allocation, no lock, bounded work per cycle (at most
//! [`MAX_ITEMS_PER_STEP`] queue items are consumed per call).
//!
//! Overrides, feed hold and abort are applied by *time scaling*: the planned trajectory
//! `p(σ)` is followed with `dσ/dt = k`, where `k` follows its target (override, 0 for hold)
//! with bounded `k̇` and `k̈`. The axis velocity is `p'k`, the acceleration `p''k² + p'k̇`,
//! the jerk `p'''k³ + 3p''k·k̇ + p'k̈`. The planner kept a reserve of acceleration and jerk
//! for the `k̇`/`k̈` terms and capped `k` per segment ([`Segment::override_cap`]), so no
//! override change, hold or abort can exceed a limit, and the tool never leaves the path.
//!
//! A stop (hold, abort, probe trip) whose fastest stop from the current speed and
//! acceleration ends within the lines, arcs and corner blends joined tangentially ahead of
//! the tool follows that stop instead ([`super::line_stop`], [`super::path_stop`]): along
//! them any speed profile keeps the path, so it needs no rate of `k` from the planner, only
//! the axes' full limits (less what the curves' turning takes).

use super::config::KinematicsConfig;
use super::config::MotionConfig;
use super::fifo::Fifo;
use super::kinematics::{Kinematics, Machine};
use super::limits::{override_rates, scale_jerk_at, scale_rate_at, AxisMax};
use super::line_stop::LineStop;
use super::path_stop::{self, plan as plan_stop, Reach};
use super::segment::{AuxItem, AuxKind, Item, Segment, SegmentKind};
use super::KinematicsError;
use crate::gcode::canon::ProbeKind;
use crate::gcode::NUM_AXES;

/// Most queue items consumed in one servo period (bounds the work of a cycle).
pub const MAX_ITEMS_PER_STEP: usize = 256;
/// Auxiliary items that can wait to be reported (one is reported per cycle).
const AUX_RING: usize = 64;
/// Queue items a stop may look ahead into (the pieces of path it may run along).
const AHEAD: usize = path_stop::MAX_PIECES - 1;

/// Where the interpolator takes its segments from: a `Vec` in tests, the realtime core's
/// lock-free ring buffer in the daemon.
pub trait SegmentSource {
    /// Next item, or `None` if the queue is (for now) empty.
    fn pop(&mut self) -> Option<Item>;
}

/// A queue in a plain slice (tests, tools, simulation).
#[derive(Debug, Clone)]
pub struct SliceSource<'a> {
    items: &'a [Item],
    next: usize,
}

impl<'a> SliceSource<'a> {
    /// Pops from `items` in order.
    pub fn new(items: &'a [Item]) -> Self {
        SliceSource { items, next: 0 }
    }
}

impl SegmentSource for SliceSource<'_> {
    fn pop(&mut self) -> Option<Item> {
        let it = self.items.get(self.next).copied();
        self.next += usize::from(it.is_some());
        it
    }
}

/// Any iterator of items (e.g. a channel's `try_iter`, or `plan.items.into_iter()`).
#[derive(Debug, Clone)]
pub struct IterSource<I>(pub I);

impl<I: Iterator<Item = Item>> SegmentSource for IterSource<I> {
    fn pop(&mut self) -> Option<Item> {
        self.0.next()
    }
}

impl SegmentSource for std::collections::VecDeque<Item> {
    fn pop(&mut self) -> Option<Item> {
        self.pop_front()
    }
}

/// What the interpolator is doing.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum InterpState {
    /// Nothing queued, nothing run since start or the last abort.
    Idle,
    /// Moving (or dwelling).
    Running,
    /// Stopped on the path by a feed hold; `resume` continues.
    Holding,
    /// Stopped at a command that needs motion stopped (M0, M6, M66, ...): the machine runs
    /// it and calls `aux_done`.
    Waiting,
    /// The queue ran dry after motion (program finished, or the planner is behind).
    Done,
}

/// Output of one servo period.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct InterpOutput {
    /// Cartesian setpoint, machine frame, mm (deg for A B C).
    pub pose_mm: [f64; NUM_AXES],
    /// Joint setpoints (equal to `pose_mm` for identity kinematics).
    pub joints: [f64; NUM_AXES],
    /// Source line being executed.
    pub line: u32,
    /// State after this period.
    pub state: InterpState,
    /// Path length left in the current move, mm.
    pub distance_to_go_mm: f64,
    /// An auxiliary item reached this period (at most one per period, in queue order).
    pub aux: Option<AuxItem>,
    /// Current time scale (1 = as planned).
    pub scale: f64,
    /// Kinematics failure of this period (joints then hold their last value).
    pub fault: Option<KinematicsError>,
    /// The queue ran dry while the tool was moving (the producer fell behind): motion stopped
    /// without deceleration. A plan always ends at rest, so this only happens when the
    /// thread filling the queue is late; the machine should treat it as a fault.
    pub underrun: bool,
    /// The probe input changed as the current G38 move expects, in this very period: the
    /// caller records the actual axis positions now (the interpolator knows only the
    /// command, [`Self::probe_pose_mm`]).
    pub probe_trip_now: bool,
    /// The current or last probe move tripped (cleared when the next one is armed).
    pub probe_tripped: bool,
    /// Commanded pose in the period the probe tripped.
    pub probe_pose_mm: [f64; NUM_AXES],
}

/// The servo-thread interpolator.
#[derive(Debug, Clone)]
pub struct Interpolator {
    dt_s: f64,
    k1: f64,
    k2: f64,
    /// Full axis limits, for the braking rates at the current scale ([`Self::braking`]).
    axis_max: AxisMax,
    max_override: f64,
    kin: Machine,
    seg: Option<Segment>,
    t_s: f64,
    k: f64,
    kd: f64,
    feed_override: f64,
    rapid_override: f64,
    hold: bool,
    abort: bool,
    waiting: bool,
    moved: bool,
    probe_input: bool,
    /// The G38 move being executed (between `ProbeArm` and `ProbeEnd`).
    probe: Option<ProbeKind>,
    /// The probe tripped: stopping within limits, as for an abort.
    probe_stop: bool,
    /// At rest after a trip: dropping the rest of the probe move up to its `ProbeEnd`.
    probe_flush: bool,
    /// The machine runs spindle-synchronised moves itself ([`Self::set_external_sync`]).
    external_sync: bool,
    /// Between `SpindleSync` and `SpindleSyncEnd` with `external_sync`: the planned
    /// segments are skipped (the machine has run the move).
    sync_skip: bool,
    aux: Fifo<AuxItem, AUX_RING>,
    /// Stops along lines and arcs follow [`LineStop`] (identity kinematics only: elsewhere a
    /// Cartesian profile says nothing of the joints' accelerations).
    path_stops: bool,
    /// The stop being followed along the path.
    path_stop: Option<ActiveStop>,
    /// The queue's next items, taken early to see how far a stop may run along the path;
    /// every read of the queue takes them first.
    ahead: Fifo<Item, AHEAD>,
    out: InterpOutput,
}

/// A [`LineStop`] in progress along the path.
#[derive(Debug, Clone, Copy)]
struct ActiveStop {
    stop: LineStop,
    /// Time since the stop (or its last re-planning) began, s.
    elapsed_s: f64,
    /// Distance into the current segment at which it began, mm (less the lengths of the
    /// segments passed since, so it may be negative).
    from_mm: f64,
    /// The path it runs along, and the bounds there.
    reach: Reach,
    /// Path length from the reach's origin to where the stop (or its last re-planning)
    /// began, mm.
    gone_mm: f64,
    /// Items of the ring taken ahead that it may run into.
    pieces: usize,
}

impl Interpolator {
    /// An idle interpolator at `start_mm` (the plan's start pose).
    pub fn new(cfg: &MotionConfig, start_mm: [f64; NUM_AXES]) -> Self {
        let (k1, k2) = override_rates(cfg);
        let kin = Machine::new(&cfg.kinematics);
        let joints = kin.inverse(&start_mm);
        Interpolator {
            dt_s: cfg.servo_period_s,
            k1,
            k2,
            axis_max: AxisMax::new(cfg),
            max_override: cfg.max_feed_override,
            kin,
            seg: None,
            t_s: 0.0,
            k: 1.0,
            kd: 0.0,
            feed_override: 1.0,
            rapid_override: 1.0,
            hold: false,
            abort: false,
            waiting: false,
            moved: false,
            probe_input: false,
            probe: None,
            probe_stop: false,
            probe_flush: false,
            external_sync: false,
            sync_skip: false,
            aux: Fifo::new(),
            path_stops: matches!(cfg.kinematics, KinematicsConfig::Identity),
            path_stop: None,
            ahead: Fifo::new(),
            out: InterpOutput {
                pose_mm: start_mm,
                joints: joints.unwrap_or(start_mm),
                line: 0,
                state: InterpState::Idle,
                distance_to_go_mm: 0.0,
                aux: None,
                scale: 1.0,
                fault: joints.err(),
                underrun: false,
                probe_trip_now: false,
                probe_tripped: false,
                probe_pose_mm: start_mm,
            },
        }
    }

    /// Feed override factor, clamped to `[0, max_feed_override]`; applied smoothly.
    pub fn set_feed_override(&mut self, factor: f64) {
        self.feed_override = if factor.is_finite() {
            factor.clamp(0.0, self.max_override)
        } else {
            1.0
        };
    }

    /// Rapid override factor, clamped to `[0, 1]`; applied smoothly.
    pub fn set_rapid_override(&mut self, factor: f64) {
        self.rapid_override = if factor.is_finite() {
            factor.clamp(0.0, 1.0)
        } else {
            1.0
        };
    }

    /// The machine runs each spindle-synchronised move ([`AuxKind::SpindleSync`]) itself,
    /// locked to the measured spindle position: the interpolator stops at its `SpindleSync`
    /// barrier and, after `aux_done`, skips the velocity-locked segments planned for it,
    /// continuing from their end. Off (the default), it runs those segments as planned.
    pub fn set_external_sync(&mut self, on: bool) {
        self.external_sync = on;
    }

    /// Feed hold: decelerate to a stop on the path.
    pub fn hold(&mut self) {
        self.hold = true;
    }

    /// Resume after a hold.
    pub fn resume(&mut self) {
        self.hold = false;
    }

    /// Stop within limits, then drop every queued item.
    pub fn abort(&mut self) {
        self.abort = true;
    }

    /// The probe input's level this period (active = the stylus touches). Read only while a
    /// G38 move runs.
    pub fn set_probe_input(&mut self, active: bool) {
        self.probe_input = active;
    }

    /// Stopping on the path: feed hold, abort, or a tripped probe.
    fn stopping(&self) -> bool {
        self.hold || self.abort || self.probe_stop
    }

    /// The machine finished the command the interpolator is waiting for.
    pub fn aux_done(&mut self) {
        self.waiting = false;
    }

    /// The last output.
    pub fn output(&self) -> &InterpOutput {
        &self.out
    }

    /// The next queue item: the first taken ahead, else the source's.
    fn pop_item(&mut self, src: &mut impl SegmentSource) -> Option<Item> {
        self.ahead.pop().or_else(|| src.pop())
    }

    /// The `i`-th queue item after the current segment, taken ahead from the source if it
    /// was not yet (`None` past the ring's size or the source's end).
    fn peek_ahead(&mut self, i: usize, src: &mut impl SegmentSource) -> Option<Item> {
        while self.ahead.len() <= i {
            if self.ahead.is_full() {
                return None;
            }
            self.ahead.push(src.pop()?);
        }
        self.ahead.get(i)
    }

    /// Pulls items until a segment is current, a barrier is hit, the ring is full or the
    /// source is empty. Returns the number of items consumed.
    fn fetch(&mut self, src: &mut impl SegmentSource, budget: &mut usize) {
        self.seg = None;
        while *budget > 0 && !self.waiting && !self.aux.is_full() {
            *budget -= 1;
            match self.pop_item(src) {
                Some(Item::Segment(s)) if self.sync_skip => {
                    self.out.pose_mm = s.end_mm;
                    self.moved = true;
                }
                Some(Item::Segment(s)) => {
                    if s.v0_mm_s.iter().all(|v| *v == 0.0) && s.kind != SegmentKind::Dwell {
                        // Starting from rest (zero velocity and acceleration): the scale can
                        // jump to its target without any velocity or acceleration step.
                        self.k = self.target_scale(&s);
                        self.kd = 0.0;
                    }
                    self.seg = Some(s);
                    self.moved = true;
                    return;
                }
                Some(Item::Aux(a)) => {
                    match a.kind {
                        AuxKind::ProbeArm { kind } => {
                            self.probe = Some(kind);
                            self.out.probe_tripped = false;
                        }
                        AuxKind::ProbeEnd { .. } => {
                            self.probe = None;
                            self.probe_stop = false;
                        }
                        AuxKind::SpindleSync { .. } => self.sync_skip = self.external_sync,
                        AuxKind::SpindleSyncEnd => self.sync_skip = false,
                        _ => {}
                    }
                    self.aux.push(a);
                    self.out.line = a.line;
                    if a.kind.is_barrier() {
                        self.waiting = true;
                    }
                }
                None => return,
            }
        }
    }

    fn target_scale(&self, s: &Segment) -> f64 {
        if self.stopping() {
            return 0.0;
        }
        let ramp = self.k1 * (s.duration_s - self.t_s).max(0.0) / self.max_override;
        let cap = s.override_cap.min(s.end_override_cap + ramp);
        match s.kind {
            SegmentKind::Feed => self.feed_override.min(cap),
            SegmentKind::Rapid => self.rapid_override.min(cap),
            SegmentKind::Dwell => self.k,
        }
    }

    /// While the scale falls (`k̇ ≤ 0`, braking toward a lower target, or `|k̇|` above the
    /// segment's planned rate), the rates this segment allows at the *current* scale:
    /// `(k̇ max, k̈ max)`, or `None` where the planned ones are at least as large.
    ///
    /// The planner's `scale_rate_max` holds for any scale up to the segment's override cap;
    /// but `p''·k²` shrinks with `k`, so once `k` has fallen the segment leaves more room for
    /// `p'·k̇` (a hold that began at scale 1 can brake harder as it goes). Valid for the whole
    /// period because `k` does not rise in it: the caller keeps `k̇ ≤ 0` (see
    /// [`Self::scale_jerk`]). The `k̈` bound is the one for that larger `|k̇|`; it is at least
    /// the floor `k2` by construction of the rate. The segment's end ramp still applies, so
    /// `|k̇|` is back within the next segment's planned rate when this one ends.
    fn braking(&self, s: &Segment, e: f64) -> Option<(f64, f64)> {
        if s.kind == SegmentKind::Dwell || self.kd > 0.0 {
            return None;
        }
        if e >= 0.0 && -self.kd <= s.scale_rate_max {
            return None;
        }
        let peaks = s.peaks();
        let rate = scale_rate_at(s, &peaks, self.k, &self.axis_max, self.k2);
        if rate <= s.scale_rate_max {
            return None;
        }
        let k2 = scale_jerk_at(s, &peaks, self.k, rate, &self.axis_max);
        Some((rate, k2))
    }

    /// Second derivative of the scale for this period: drive `k` to `target` with |k̇|
    /// within the segment's rate limit and |k̈| ≤ k2, braking early enough in discrete time
    /// not to overshoot.
    fn scale_jerk(&self, s: &Segment, target: f64) -> f64 {
        let e = target - self.k;
        let dt = self.dt_s;
        let braking = self.braking(s, e);
        let (rate_max, jerk_max) = braking.unwrap_or((s.scale_rate_max, s.scale_jerk_max));
        // k̈ this segment allows, and what every segment within one braking allows.
        let left = (s.duration_s - self.t_s).max(0.0);
        let mut k2_here = jerk_max;
        // This period may end in a later segment: respect its limit too.
        let step_sigma = (self.k + self.kd.abs() * dt + jerk_max * dt * dt) * dt;
        if left <= 2.0 * step_sigma {
            k2_here = k2_here.min(s.next_scale_jerk_max);
        }
        let k2_here = k2_here.max(self.k2);
        // Stopping `k̇` is planned at what every segment within one braking allows; at the
        // raised rates of `braking` only the floor is sure to be available in the segments
        // ahead.
        let k2 = if braking.is_some() {
            self.k2
        } else {
            s.brake_scale_jerk_max.clamp(self.k2, k2_here)
        };
        let rate = rate_max
            .min(s.end_scale_rate_max + 0.9 * self.k2 * left / self.max_override)
            .max(self.k1);
        // Largest speed toward the target at the end of this period from which a k̈ = k2
        // braking still stops at the target, counting the distance covered during the
        // period itself (trapezoid of the current and the new k̇).
        let toward = self.kd * e.signum();
        let room = (e.abs() - toward * dt / 2.0).max(0.0);
        let brake = discrete_brake_speed(room, k2, dt);
        // Above scale 1 the override caps assume |k̇| ≤ k1 (their margin covers the lag of
        // that rate only): rising, arrive at 1 no faster than k1 and stay at k1 above it.
        let rate = if e > 0.0 && target > 1.0 {
            let below = (1.0 - self.k).max(0.0);
            rate.min((self.k1 * self.k1 + 2.0 * self.k2 * below).sqrt())
                .max(self.k1)
        } else {
            rate
        };
        let vd = e.signum() * rate.min(brake);
        let kdd = ((vd - self.kd) / dt).clamp(-k2_here, k2_here);
        if braking.is_some() {
            // Keep k̇ ≤ 0 through the period: the raised rates hold only while k falls.
            kdd.min(-self.kd / dt)
        } else {
            kdd
        }
    }

    /// A stop along the path: where one is requested and the fastest stop from the current
    /// speed and acceleration ([`LineStop`]) ends within the lines and arcs joined
    /// tangentially ahead ([`Self::start_path_stop`]), it is followed instead of braking the
    /// scale (whose rates are those every segment within one braking allows). Returns the
    /// planned time to advance this period, or `None` to scale as usual. Once begun, the
    /// stop runs to rest even if the hold is released meanwhile: the resume then starts
    /// from rest, as from any hold. Where arcs are in reach, the stop is re-planned every
    /// period from the speed reached: their normal acceleration falls with the speed and
    /// leaves more to the stop.
    fn path_stop_advance(&mut self, s: &Segment, src: &mut impl SegmentSource) -> Option<f64> {
        if self.path_stop.is_none() {
            if !self.stopping() || !self.path_stops || self.sync_skip {
                return None;
            }
            self.path_stop = self.start_path_stop(s, src);
        }
        let dt = self.dt_s;
        let mut st = self.path_stop?;
        if st.reach.turns() {
            let (d, v, a) = st.stop.eval(st.elapsed_s);
            let left = st.stop.duration_s() - st.elapsed_s;
            let rest = st.stop.distance_mm() - d;
            match plan_stop(&st.reach, st.gone_mm + d, v, a, dt) {
                Some(stop) if stop.duration_s() <= left && stop.distance_mm() <= rest => {
                    st.stop = stop;
                    st.elapsed_s = 0.0;
                    st.from_mm += d;
                    st.gone_mm += d;
                }
                _ => {}
            }
        }
        st.elapsed_s += dt;
        let (d, v, _) = st.stop.eval(st.elapsed_s);
        // At rest from the period after the one that reached the end (which still moved):
        // an abort or a probe flush acts on a period that did not.
        let done = st.elapsed_s >= st.stop.duration_s() + 0.5 * dt;
        self.path_stop = Some(st);
        // The segment the stop reaches this period: the current one or one taken ahead
        // (`start_path_stop` took the stop only if it ends within them).
        let (mut seg, mut from_t, mut skip) = (*s, self.t_s, 0.0);
        let mut along = st.from_mm + d;
        let mut len = path_stop::length_of(&seg);
        let mut i = 0;
        while along >= len && i < st.pieces {
            let Some(Item::Segment(next)) = self.ahead.get(i) else {
                break;
            };
            skip += (seg.duration_s - from_t).max(0.0);
            along -= len;
            (seg, from_t) = (next, 0.0);
            len = path_stop::length_of(&seg);
            i += 1;
        }
        // The planned time at which the segment has covered `along` (a fixed amount of work,
        // during a stop only).
        let lo = path_stop::time_at(&seg, along.min(len), from_t);
        let planned = seg.speed_at(lo);
        self.kd = 0.0;
        if done {
            self.path_stop = None;
            self.k = 0.0;
        } else {
            self.k = if planned > 1e-9 { v / planned } else { 0.0 };
        }
        Some(skip + (lo - from_t).max(0.0))
    }

    /// The stop along the path from the current state, if the current segment is a line, an
    /// arc or a blend and the stop ends within it or within the queue items after it that continue
    /// it tangentially (up to [`AHEAD`] of them; [`Reach`]), and (begun while still
    /// accelerating) stays within the axes' velocity.
    fn start_path_stop(&mut self, s: &Segment, src: &mut impl SegmentSource) -> Option<ActiveStop> {
        let t = self.t_s;
        let planned = s.speed_at(t);
        let v = self.k * planned;
        let a = self.k * self.k * path_stop::tangential_acc(s, t) + self.kd * planned;
        let from_mm = path_stop::travelled(s, t);
        let mut reach = Reach::new(s, from_mm, &self.axis_max)?;
        let mut pieces = 0;
        loop {
            let stop = plan_stop(&reach, 0.0, v, a, self.dt_s)?;
            if stop.distance_mm() < reach.room_mm * (1.0 - 1e-9) {
                return Some(ActiveStop {
                    stop,
                    elapsed_s: 0.0,
                    from_mm,
                    reach,
                    gone_mm: 0.0,
                    pieces,
                });
            }
            match self.peek_ahead(pieces, src) {
                Some(Item::Segment(next)) if reach.extend(&next) => pieces += 1,
                _ => return None,
            }
        }
    }

    /// One servo period.
    pub fn step(&mut self, src: &mut impl SegmentSource) -> &InterpOutput {
        let mut budget = MAX_ITEMS_PER_STEP;
        self.out.fault = None;
        self.out.underrun = false;
        self.out.probe_trip_now = false;
        if self.abort && self.seg.is_none() {
            self.finish_abort(src, &mut budget);
        }
        if self.probe_flush {
            self.flush_probe(src, &mut budget);
        }
        if let Some(kind) = self.probe {
            // The input as read this period shows where the tool was at the end of the last
            // one: the commanded pose of that period is where it tripped.
            if !self.waiting && !self.probe_stop && self.probe_input == kind.toward() {
                self.probe_stop = true;
                self.out.probe_trip_now = true;
                self.out.probe_tripped = true;
                self.out.probe_pose_mm = self.out.pose_mm;
            }
        }
        if self.seg.is_none() && !self.waiting && !self.probe_flush {
            self.fetch(src, &mut budget);
        }
        if let Some(mut s) = self.seg {
            let dt = self.dt_s;
            let advance = if s.kind == SegmentKind::Dwell {
                if self.stopping() {
                    0.0
                } else {
                    dt
                }
            } else if let Some(advance) = (self.path_stop.is_some() || self.stopping())
                .then(|| self.path_stop_advance(&s, src))
                .flatten()
            {
                advance
            } else {
                let kdd = self.scale_jerk(&s, self.target_scale(&s));
                let a = self.k * dt + self.kd * dt * dt / 2.0 + kdd * dt * dt * dt / 6.0;
                self.k += self.kd * dt + kdd * dt * dt / 2.0;
                self.kd += kdd * dt;
                if self.k < 0.0 {
                    self.k = 0.0;
                    self.kd = self.kd.max(0.0);
                }
                if self.stopping() {
                    // Settle exactly at rest once the remainder is far below anything
                    // measurable (a 1e-9 scale step is a nm/s-level velocity step).
                    if self.k < 1e-9 && self.kd.abs() < 1e-6 {
                        self.k = 0.0;
                        self.kd = 0.0;
                    }
                }
                a.max(0.0)
            };
            self.t_s += advance;
            while self.t_s >= s.duration_s {
                let rest = self.t_s - s.duration_s;
                self.out.pose_mm = s.end_mm;
                if let Some(st) = &mut self.path_stop {
                    // A stop running on into the next segment (one of its pieces).
                    st.from_mm -= path_stop::length_of(&s);
                    st.pieces = st.pieces.saturating_sub(1);
                }
                self.fetch(src, &mut budget);
                match self.seg {
                    Some(n) => {
                        s = n;
                        self.t_s = rest;
                    }
                    None => {
                        self.out.underrun = !self.waiting && s.v1_mm_s.iter().any(|v| *v != 0.0);
                        self.t_s = 0.0;
                        break;
                    }
                }
            }
            if let Some(s) = self.seg {
                self.out.pose_mm = s.pose_at(self.t_s);
                let travelled = s.travelled_mm(self.t_s);
                self.out.line = s.line_at(travelled);
                self.out.distance_to_go_mm = (s.length_mm - travelled).max(0.0) + s.move_rest_mm;
            } else {
                self.out.distance_to_go_mm = 0.0;
            }
            // A path stop is at rest only once it has ended (see `path_stop_advance`).
            let at_rest =
                self.path_stop.is_none() && self.k == 0.0 && self.kd.abs() <= self.k2 * dt;
            // The tool stands still during a dwell whatever the scale: an abort ends it now
            // (else a `G4 P100000` ran to its end after `job.abort`).
            let dwelling = self.seg.is_some_and(|s| s.kind == SegmentKind::Dwell);
            if self.abort && (at_rest || dwelling) {
                self.kd = 0.0;
                self.seg = None;
                self.finish_abort(src, &mut budget);
            } else if self.probe_stop && self.seg.is_some() && at_rest {
                self.kd = 0.0;
                self.seg = None;
                self.probe_flush = true;
                self.flush_probe(src, &mut budget);
            }
        }
        match self.kin.inverse(&self.out.pose_mm) {
            Ok(j) => self.out.joints = j,
            Err(e) => self.out.fault = Some(e),
        }
        self.out.aux = self.aux.pop();
        self.out.scale = self.k;
        self.out.state = if self.waiting {
            InterpState::Waiting
        } else if self.seg.is_some() || self.probe_flush {
            if self.hold && self.k == 0.0 && self.path_stop.is_none() {
                InterpState::Holding
            } else {
                InterpState::Running
            }
        } else if self.moved {
            InterpState::Done
        } else {
            InterpState::Idle
        };
        &self.out
    }

    /// After a probe trip, at rest: drops the rest of the probe move (bounded per period) up
    /// to its `ProbeEnd`, which is reported as usual (a barrier: the machine reads the
    /// result). What follows in the queue was planned from where the probe move ends, and
    /// the program is interpreted in pieces so that nothing but that marker follows it.
    fn flush_probe(&mut self, src: &mut impl SegmentSource, budget: &mut usize) {
        while *budget > 0 && !self.aux.is_full() {
            *budget -= 1;
            match self.pop_item(src) {
                Some(Item::Aux(a)) if matches!(a.kind, AuxKind::ProbeEnd { .. }) => {
                    self.probe_flush = false;
                    self.probe_stop = false;
                    self.probe = None;
                    self.aux.push(a);
                    self.out.line = a.line;
                    self.waiting = true;
                    // At rest: the next piece starts at its beginning, at the planned speed.
                    self.t_s = 0.0;
                    self.k = 1.0;
                    self.kd = 0.0;
                    self.out.distance_to_go_mm = 0.0;
                    return;
                }
                Some(_) => {}
                None => return,
            }
        }
    }

    /// Drops what is left of the queue (bounded per period), then goes idle.
    fn finish_abort(&mut self, src: &mut impl SegmentSource, budget: &mut usize) {
        while *budget > 0 {
            *budget -= 1;
            if self.pop_item(src).is_none() {
                self.abort = false;
                self.waiting = false;
                self.moved = false;
                self.probe = None;
                self.probe_stop = false;
                self.probe_flush = false;
                self.sync_skip = false;
                self.aux.clear();
                // At rest: the next job starts at the planned speed.
                self.k = 1.0;
                self.kd = 0.0;
                self.out.distance_to_go_mm = 0.0;
                return;
            }
        }
    }
}

/// The largest speed `v` toward a target at the end of this period such that `v·dt/2` (the
/// rest of this period's trapezoid) plus the distance of stopping from `v` in whole servo
/// periods, each lowering the speed by at most `k2·dt`, is at most `room`.
///
/// The continuous stopping distance `v²/(2·k2)` is short of the discrete one by up to
/// `k2·dt²/8` (when `v` is an odd number of half steps), so a law built on it overshoots its
/// target by that much and then chatters around it: resuming to scale 1 on a cruise at the
/// velocity limit went 1.4e-5 over the limit for ~40 periods. Stopping from `v = m·a + r`
/// (`a = k2·dt`, `0 ≤ r < a`) covers `dt/2·((2m+1)·r + a·m²)`; with this period's `v·dt/2` the
/// total is linear in `v` between multiples of `a`, so `v` follows in closed form.
pub(crate) fn discrete_brake_speed(room: f64, k2: f64, dt: f64) -> f64 {
    let a = k2 * dt;
    if room <= 0.0 || a <= 0.0 || dt <= 0.0 {
        return 0.0;
    }
    // Largest whole m with a·m·(m+1)·dt/2 ≤ room (the total at v = m·a).
    let m = ((-1.0 + (1.0 + 8.0 * room / (a * dt)).sqrt()) / 2.0)
        .floor()
        .max(0.0);
    (2.0 * room / dt + a * m * (m + 1.0)) / (2.0 * m + 2.0)
}

#[cfg(test)]
mod brake_tests {
    use super::discrete_brake_speed;

    /// Distance of `v·dt/2` plus the fastest stop from `v` in whole periods.
    fn covered(v: f64, k2: f64, dt: f64) -> f64 {
        let mut d = v * dt / 2.0;
        let mut v = v;
        while v > 0.0 {
            let next = (v - k2 * dt).max(0.0);
            d += (v + next) * dt / 2.0;
            v = next;
        }
        d
    }

    #[test]
    fn the_speed_stops_exactly_within_the_room_in_whole_periods() {
        let dt = 1e-3;
        for k2 in [5.0, 37.3, 199.3] {
            for i in 1..400 {
                let room = 1e-7 * f64::from(i) * f64::from(i);
                let v = discrete_brake_speed(room, k2, dt);
                let d = covered(v, k2, dt);
                assert!(
                    (d - room).abs() <= 1e-12 * room.max(1.0),
                    "{k2} {room}: {d}"
                );
                // A little faster no longer fits: v is the largest.
                assert!(covered(v * (1.0 + 1e-6) + 1e-12, k2, dt) > room);
            }
        }
        assert_eq!(discrete_brake_speed(0.0, 10.0, dt), 0.0);
    }
}
