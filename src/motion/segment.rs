//! The time-parameterised segment queue: the only link between the planner (ordinary thread)
//! and the interpolator (servo thread). Every item is `Copy` and fixed-size, with no heap
//! pointer inside, so it can travel through a lock-free ring buffer.

use super::line_marks::LineMarks;
use super::profile::Shape;
use crate::gcode::canon::{InputKind, LogKind, OverrideKind, ProbeKind, SpindleDir, WaitKind};
use crate::gcode::NUM_AXES;

/// What a segment does, for overrides and display.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SegmentKind {
    /// A feed move (G1/G2/G3 or a blend into one): scaled by the feed override.
    Feed,
    /// A rapid move (G0): scaled by the rapid override.
    Rapid,
    /// A dwell (G4): no motion, runs in real time.
    Dwell,
}

/// One velocity transition of the tool (see [`super::profile`]): starts at `start_mm` with
/// velocity `v0_mm_s`, ends with `v1_mm_s` after `duration_s`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Segment {
    /// Machine-frame pose at the start, mm (deg for A B C).
    pub start_mm: [f64; NUM_AXES],
    /// Pose at the end, exact (the next segment starts here), mm.
    pub end_mm: [f64; NUM_AXES],
    /// Velocity at the start, mm/s.
    pub v0_mm_s: [f64; NUM_AXES],
    /// Velocity at the end, mm/s.
    pub v1_mm_s: [f64; NUM_AXES],
    /// Duration at 100% override, s.
    pub duration_s: f64,
    /// Jerk-phase length of the S-curve, s.
    pub jerk_s: f64,
    /// Feed, rapid or dwell.
    pub kind: SegmentKind,
    /// Source line of the move this segment belongs to.
    pub line: u32,
    /// Path length of this segment, mm.
    pub length_mm: f64,
    /// Length of the move left after this segment ends, mm (for distance-to-go).
    pub move_rest_mm: f64,
    /// Largest time-scaling factor this segment tolerates within all limits (≥ 1): the
    /// cap on the feed override here.
    pub override_cap: f64,
    /// Largest time scale allowed when this segment ends (what the segments after it
    /// tolerate, ramped back at the interpolator's scale rate): the interpolator brings the
    /// scale down in time for it.
    pub end_override_cap: f64,
    /// Largest rate of change of the time scale in this segment, 1/s: what the segment's
    /// acceleration and jerk leave free for the `p'·k̇` and `p''·k·k̇` terms (so a hold in
    /// a cruise decelerates at nearly the full axis acceleration).
    pub scale_rate_max: f64,
    /// Largest scale rate allowed when this segment ends (what follows tolerates, ramped
    /// back at the interpolator's `k̈` limit).
    pub end_scale_rate_max: f64,
    /// Largest second derivative of the time scale in this segment, 1/s²: the jerk this
    /// segment leaves free for the `p'·k̈` term (so a hold in a cruise is nearly as quick as
    /// the fastest S-curve stop).
    pub scale_jerk_max: f64,
    /// Smallest `scale_jerk_max` of the segments that follow within one braking of the
    /// scale: what the interpolator may count on when it plans to bring `k̇` to zero.
    pub brake_scale_jerk_max: f64,
    /// Smallest `scale_jerk_max` of the segments a servo period starting near the end of
    /// this one can reach: used on the last stretch of the segment.
    pub next_scale_jerk_max: f64,
    /// Signed curvature of the path in the XY plane, 1/mm (> 0 turns left): 0 for a straight
    /// segment or a corner blend, else the segment runs along a circular arc (fitted over
    /// dense chords, see [`super::arcfit`]) starting with heading `heading_rad`.
    pub curvature_per_mm: f64,
    /// Heading of the path tangent at the start of an arc segment (XY plane), rad.
    pub heading_rad: f64,
    /// Jerk that the acceleration step at this segment's ends (a curvature step where two
    /// tangent arcs, or an arc and a line, meet) shows on the servo-period trace, mm/s³:
    /// counted in [`Segment::peaks`] so override and hold headroom allow for it.
    pub step_jerk_mm_s3: f64,
    /// Where the segment passes the vertices of the source lines after `line` (an arc
    /// fitted over several G1 lines, issue 14): the reported line advances at each.
    pub line_marks: LineMarks,
    /// Set when the segment is a piece of a longer speed transition (one S-curve across a
    /// run of tangent moves, issue 14): the acceleration then carries across the segment's
    /// ends instead of falling to zero at each of them. [`Window::NONE`] otherwise.
    pub window: Window,
}

/// The part of a speed transition that one segment runs (see [`Segment::window`]): the
/// segment's speed is `s0 + dv·(f(offset + t) − f(offset))` for `t` in `[0, duration]`,
/// where `f` is the transition's shape (duration `full_s`, the segment's `jerk_s`) and `s0`
/// the segment's start speed. Only straight pieces and arcs carry a window, never a blend.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Window {
    /// Time into the whole transition at which the segment starts, s.
    pub offset_s: f64,
    /// Duration of the whole transition, s (0: no window).
    pub full_s: f64,
    /// Speed change of the whole transition, mm/s (signed).
    pub dv_mm_s: f64,
}

impl Window {
    /// Not a piece of a longer transition.
    pub const NONE: Window = Window {
        offset_s: 0.0,
        full_s: 0.0,
        dv_mm_s: 0.0,
    };

    /// True for a piece of a longer transition.
    pub fn is_some(&self) -> bool {
        self.full_s > 0.0
    }
}

impl Segment {
    /// The S-curve shape (of the whole transition for a windowed piece).
    pub fn shape(&self) -> Shape {
        Shape {
            duration_s: if self.window.is_some() {
                self.window.full_s
            } else {
                self.duration_s
            },
            jerk_s: self.jerk_s,
        }
    }

    /// Speed (mm/s) and distance travelled (mm) along a windowed piece at `t` (clamped).
    fn window_speed_distance(&self, t_s: f64) -> (f64, f64) {
        let w = &self.window;
        let sh = self.shape();
        let t = t_s.clamp(0.0, self.duration_s);
        let (f0, cap_f0) = sh.eval(w.offset_s);
        let (f, cap_f) = sh.eval(w.offset_s + t);
        let s0 = norm(&self.v0_mm_s);
        (
            s0 + w.dv_mm_s * (f - f0),
            s0 * t + w.dv_mm_s * (cap_f - cap_f0 - f0 * t),
        )
    }

    /// Unit direction of a straight windowed piece.
    fn window_direction(&self) -> [f64; NUM_AXES] {
        let (s0, s1) = (norm(&self.v0_mm_s), norm(&self.v1_mm_s));
        let (v, s) = if s1 >= s0 {
            (&self.v1_mm_s, s1)
        } else {
            (&self.v0_mm_s, s0)
        };
        if s > 0.0 {
            v.map(|c| c / s)
        } else {
            [0.0; NUM_AXES]
        }
    }

    /// Pose of a windowed piece after `d_mm` along it.
    fn window_pose(&self, d_mm: f64) -> [f64; NUM_AXES] {
        if self.curvature_per_mm != 0.0 {
            return self.arc_pose(d_mm);
        }
        let u = self.window_direction();
        let mut p = self.start_mm;
        for (p, u) in p.iter_mut().zip(u) {
            *p += u * d_mm;
        }
        p
    }

    /// Path speed at time `t_s` into the segment, mm/s (the norm of the velocity).
    pub fn speed_at(&self, t_s: f64) -> f64 {
        if self.window.is_some() {
            return self.window_speed_distance(t_s).0;
        }
        let (f, _) = self.shape().eval(t_s.clamp(0.0, self.duration_s.max(0.0)));
        if self.curvature_per_mm != 0.0 {
            // Along the arc: the speeds change, not the vectors (whose mean is a chord's).
            let (s0, s1) = (norm(&self.v0_mm_s), norm(&self.v1_mm_s));
            return s0 + (s1 - s0) * f;
        }
        let mut v = [0.0; NUM_AXES];
        for (i, v) in v.iter_mut().enumerate() {
            *v = self.v0_mm_s[i] + (self.v1_mm_s[i] - self.v0_mm_s[i]) * f;
        }
        norm(&v)
    }

    /// Tangential acceleration (the rate of the path speed) at time `t_s`, mm/s².
    pub fn tangential_acc_at(&self, t_s: f64) -> f64 {
        let t = t_s.clamp(0.0, self.duration_s.max(0.0));
        if self.window.is_some() {
            return self.window.dv_mm_s * self.shape().rate(self.window.offset_s + t);
        }
        (norm(&self.v1_mm_s) - norm(&self.v0_mm_s)) * self.shape().rate(t)
    }

    /// Peak tangential acceleration of a windowed piece or an arc, mm/s² (the whole
    /// transition's peak for a windowed piece: an upper bound on the piece's).
    pub fn tangential_acc_peak(&self) -> f64 {
        self.tangential_dv() * self.shape().peak_rate()
    }

    /// Speed change that scales the shape's rates along the path, mm/s.
    fn tangential_dv(&self) -> f64 {
        if self.window.is_some() {
            self.window.dv_mm_s.abs()
        } else {
            (norm(&self.v1_mm_s) - norm(&self.v0_mm_s)).abs()
        }
    }

    /// Pose at time `t_s` (clamped to the segment; exactly `end_mm` at the end).
    pub fn pose_at(&self, t_s: f64) -> [f64; NUM_AXES] {
        if t_s >= self.duration_s {
            return self.end_mm;
        }
        let t = t_s.max(0.0);
        if self.window.is_some() {
            return self.window_pose(self.window_speed_distance(t).1);
        }
        let (_, cap_f) = self.shape().eval(t);
        if self.curvature_per_mm != 0.0 {
            let (s0, s1) = (norm(&self.v0_mm_s), norm(&self.v1_mm_s));
            return self.arc_pose(s0 * t + (s1 - s0) * cap_f);
        }
        let mut p = self.start_mm;
        for (i, p) in p.iter_mut().enumerate() {
            *p += self.v0_mm_s[i] * t + (self.v1_mm_s[i] - self.v0_mm_s[i]) * cap_f;
        }
        p
    }

    /// Pose after arc length `s_mm` along an arc segment.
    fn arc_pose(&self, s_mm: f64) -> [f64; NUM_AXES] {
        let d = super::arcfit::offset(self.heading_rad, self.curvature_per_mm, s_mm);
        let mut p = self.start_mm;
        p[0] += d[0];
        p[1] += d[1];
        p
    }

    /// End pose computed from the motion (equal to `end_mm` up to rounding).
    pub fn integrated_end_mm(&self) -> [f64; NUM_AXES] {
        if self.window.is_some() {
            return self.window_pose(self.window_speed_distance(self.duration_s).1);
        }
        let h = 0.5 * self.duration_s;
        if self.curvature_per_mm != 0.0 {
            return self.arc_pose((norm(&self.v0_mm_s) + norm(&self.v1_mm_s)) * h);
        }
        let mut p = self.start_mm;
        for (i, p) in p.iter_mut().enumerate() {
            *p += (self.v0_mm_s[i] + self.v1_mm_s[i]) * h;
        }
        p
    }

    /// Source line executing after `travelled_mm` of this segment: `line`, advanced by one at
    /// each vertex mark passed (realtime: no allocation).
    pub fn line_at(&self, travelled_mm: f64) -> u32 {
        if self.line_marks.is_empty() || self.length_mm <= 0.0 {
            return self.line;
        }
        self.line + self.line_marks.passed(travelled_mm / self.length_mm)
    }

    /// Path length covered after `t_s`, mm (exact for straight segments, the speed-weighted
    /// approximation for blends).
    pub fn travelled_mm(&self, t_s: f64) -> f64 {
        if self.duration_s <= 0.0 {
            return self.length_mm;
        }
        let t = t_s.clamp(0.0, self.duration_s);
        if self.window.is_some() {
            // The piece was cut where the transition's distance reaches its length, so the
            // distance is the travelled length (one evaluation per servo period, not two).
            return self.window_speed_distance(t).1.clamp(0.0, self.length_mm);
        }
        let (_, cap_f) = self.shape().eval(t);
        let s0 = norm(&self.v0_mm_s);
        let s1 = norm(&self.v1_mm_s);
        let raw = s0 * t + (s1 - s0) * cap_f;
        let full = 0.5 * (s0 + s1) * self.duration_s;
        if full > 0.0 {
            raw / full * self.length_mm
        } else {
            0.0
        }
    }

    /// Per-axis peaks of velocity, acceleration and jerk at 100% override. On an arc the
    /// acceleration is `s''·T + κ·s'²·N` and the jerk `(s''' − κ²·s'³)·T + 3κ·s'·s''·N`; each
    /// X/Y component is bounded by the norm of these vectors.
    pub fn peaks(&self) -> [[f64; 3]; NUM_AXES] {
        let s = self.shape();
        let (r, j) = (s.peak_rate(), s.peak_jerk());
        let mut out = [[0.0; 3]; NUM_AXES];
        if self.curvature_per_mm != 0.0 {
            let (s0, s1) = (norm(&self.v0_mm_s), norm(&self.v1_mm_s));
            let (vm, dv, k) = (
                s0.max(s1),
                self.tangential_dv(),
                self.curvature_per_mm.abs(),
            );
            let at = dv * r;
            let acc = at.hypot(k * vm * vm);
            let jerk = dv * j + k * k * vm * vm * vm + 3.0 * k * vm * at + self.step_jerk_mm_s3;
            out[0] = [vm, acc, jerk];
            out[1] = [vm, acc, jerk];
            return out;
        }
        let window_u = self.window.is_some().then(|| self.window_direction());
        for (i, o) in out.iter_mut().enumerate() {
            let dv = match window_u {
                Some(u) => (u[i] * self.window.dv_mm_s).abs(),
                None => (self.v1_mm_s[i] - self.v0_mm_s[i]).abs(),
            };
            *o = [
                self.v0_mm_s[i].abs().max(self.v1_mm_s[i].abs()),
                dv * r,
                dv * j,
            ];
        }
        for o in &mut out[..2] {
            o[2] += self.step_jerk_mm_s3;
        }
        out
    }
}

pub(crate) fn norm(v: &[f64; NUM_AXES]) -> f64 {
    v.iter().map(|x| x * x).sum::<f64>().sqrt()
}

/// A non-motion command, ordered with motion.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum AuxKind {
    /// S word: new spindle speed. Does not stop motion (LinuxCNC issue #1813).
    SpindleSpeed {
        /// Revolutions per minute.
        rpm: f64,
    },
    /// M3/M4.
    SpindleStart(SpindleDir),
    /// M5.
    SpindleStop,
    /// M7 (true) / M9 (false).
    Mist(bool),
    /// M8 (true) / M9 (false).
    Flood(bool),
    /// T word: prepare a tool.
    SelectTool(u32),
    /// M6 begins.
    StartToolChange,
    /// M6: swap in the prepared tool (pocket/slot).
    ChangeTool(u32),
    /// M61 Q.
    ChangeToolNumber(u32),
    /// M62–M65.
    DigitalOutput {
        /// Output index.
        index: u32,
        /// New state.
        on: bool,
        /// True for M62/M63 (with motion), false for M64/M65 (immediate: motion stops).
        synced: bool,
    },
    /// M67/M68.
    AnalogOutput {
        /// Output index.
        index: u32,
        /// New value.
        value: f64,
        /// True for M67 (with motion), false for M68.
        synced: bool,
    },
    /// M66.
    Wait {
        /// Input index.
        index: u32,
        /// Digital or analog.
        input: InputKind,
        /// Edge or level.
        kind: WaitKind,
        /// Timeout, s.
        timeout_s: f64,
        /// The M66 ends a piece of a live job: the machine publishes what it read (-1 after
        /// a timeout) and holds until the next piece is queued (see
        /// `machine::servo::input_wait`). Set by the piece runner; false from the planner.
        answer: bool,
    },
    /// `(MSG, …)`: the text is `Plan::messages[id]` (items stay heap-free).
    Message {
        /// Index into `Plan::messages`.
        id: u32,
    },
    /// A log comment, `(LOGOPEN,…)`, `(LOGAPPEND,…)`, `(LOG,…)` or `(LOGCLOSE)`: the file
    /// name or the line is `Plan::messages[id]`. The machine writes it off the realtime path
    /// when the tool gets there (`machine::runtime::job_log`).
    Log {
        /// Index into `Plan::messages`.
        id: u32,
        /// Open, append, write or close.
        kind: LogKind,
    },
    /// M48–M53.
    OverrideEnable {
        /// Which override.
        which: OverrideKind,
        /// On or off.
        on: bool,
    },
    /// M0.
    ProgramStop,
    /// M1.
    OptionalProgramStop,
    /// M2/M30.
    ProgramEnd,
    /// G38.x begins: the probe move that follows stops when the probe input changes. A
    /// barrier: the machine first checks that the input is not already in the state the
    /// move waits for (LinuxCNC refuses such a probe move).
    ProbeArm {
        /// G38.2 .. G38.5.
        kind: ProbeKind,
    },
    /// G38.x ends (tripped, or the move reached its end). A barrier: the machine reads the
    /// result and the next piece of the program is interpreted with it.
    ProbeEnd {
        /// G38.2 .. G38.5.
        kind: ProbeKind,
    },
    /// A spindle-synchronised move begins (G33, a G76 pass, G33.1): the feed segments up to
    /// [`AuxKind::SpindleSyncEnd`] are the move planned locked to the commanded spindle
    /// speed (what a plot or a trace shows). A machine with a spindle position instead runs
    /// the move itself, locked to the measured spindle position
    /// ([`crate::motion::spindle_lock`]), and the interpolator skips those segments
    /// ([`crate::motion::Interpolator::set_external_sync`]). A barrier: the move starts at rest.
    SpindleSync {
        /// Where the move ends (G33.1: the bottom of the tap, from where it comes back).
        end_mm: [f64; NUM_AXES],
        /// Path length per spindle revolution, mm.
        pitch_mm: f64,
        /// G33.1: reverse the spindle at the bottom and follow it back out.
        tap: bool,
    },
    /// The spindle-synchronised move ends (see [`AuxKind::SpindleSync`]).
    SpindleSyncEnd,
    /// M100–M199.
    UserMcode {
        /// 100..=199.
        code: u32,
        /// P word.
        p: f64,
        /// Q word.
        q: f64,
    },
}

impl AuxKind {
    /// True when motion must be stopped before the command runs and stay stopped until the
    /// machine reports it done (`Interpolator::aux_done`). False for commands that ride
    /// along with motion: S changes, synchronised I/O, coolant, messages, tool preparation.
    pub fn is_barrier(&self) -> bool {
        !matches!(
            self,
            AuxKind::SpindleSpeed { .. }
                | AuxKind::Mist(_)
                | AuxKind::Flood(_)
                | AuxKind::SelectTool(_)
                | AuxKind::DigitalOutput { synced: true, .. }
                | AuxKind::AnalogOutput { synced: true, .. }
                | AuxKind::Message { .. }
                | AuxKind::Log { .. }
                | AuxKind::OverrideEnable { .. }
                | AuxKind::SpindleSyncEnd
        )
    }
}

impl AuxKind {
    /// The index into `Plan::messages` of an item that carries a text (`(MSG, …)` and the
    /// log comments): a plan made of pieces renumbers them as it appends each piece's texts.
    pub fn text_id_mut(&mut self) -> Option<&mut u32> {
        match self {
            AuxKind::Message { id } | AuxKind::Log { id, .. } => Some(id),
            _ => None,
        }
    }
}

/// A non-motion command and its source line.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AuxItem {
    /// The command.
    pub kind: AuxKind,
    /// Source line.
    pub line: u32,
}

/// One entry of the segment queue. Deliberately unboxed: items are fixed-size so they can
/// be copied through a lock-free ring without allocation.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Item {
    /// Motion (or a dwell).
    Segment(Segment),
    /// A non-motion command, reached when every item before it has been executed.
    Aux(AuxItem),
}

#[cfg(test)]
impl Segment {
    /// A straight feed segment from `v0` to `v1` (mm/s) with neutral override data, for unit
    /// tests; struct update syntax sets the rest.
    pub(crate) fn for_test(
        v0: [f64; NUM_AXES],
        v1: [f64; NUM_AXES],
        duration_s: f64,
        jerk_s: f64,
        length_mm: f64,
    ) -> Segment {
        Segment {
            start_mm: [0.0; NUM_AXES],
            end_mm: [0.0; NUM_AXES],
            v0_mm_s: v0,
            v1_mm_s: v1,
            duration_s,
            jerk_s,
            kind: SegmentKind::Feed,
            line: 1,
            length_mm,
            move_rest_mm: 0.0,
            override_cap: 1.0,
            end_override_cap: 1.0,
            scale_rate_max: 1.0,
            end_scale_rate_max: 1.0,
            scale_jerk_max: 1.0,
            brake_scale_jerk_max: 1.0,
            next_scale_jerk_max: 1.0,
            curvature_per_mm: 0.0,
            heading_rad: 0.0,
            step_jerk_mm_s3: 0.0,
            line_marks: LineMarks::NONE,
            window: Window::NONE,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn realtime_safe<T: Copy + Send + Sync + 'static>() {}

    #[test]
    fn queue_items_are_copy_send_and_small() {
        realtime_safe::<Item>();
        realtime_safe::<AuxItem>();
        // Fixed size, no heap: a ring of 4096 items is about 1.7 MiB (the arc fields of
        // issue 14 added 24 bytes, the span window 24 more).
        assert!(
            std::mem::size_of::<Item>() <= 440,
            "{}",
            std::mem::size_of::<Item>()
        );
    }

    /// Along an arc the path speed is the interpolated speed, not the norm of the
    /// interpolated velocity vectors (a chord's: 2 % low on a 47 mm/s quarter circle, and
    /// the feed plot showed it); its rate is the tangential acceleration.
    #[test]
    fn an_arcs_speed_is_its_path_speed() {
        let (h0, h1) = (0.0f64, std::f64::consts::FRAC_PI_2);
        let mut v0 = [0.0; NUM_AXES];
        let mut v1 = [0.0; NUM_AXES];
        (v0[0], v0[1]) = (30.0 * h0.cos(), 30.0 * h0.sin());
        (v1[0], v1[1]) = (50.0 * h1.cos(), 50.0 * h1.sin());
        let len = 5.0 * h1;
        let s = Segment {
            curvature_per_mm: 0.2,
            heading_rad: h0,
            ..Segment::for_test(v0, v1, 2.0 * len / 80.0, 0.02, len)
        };
        let t = s.duration_s;
        assert!((s.speed_at(0.0) - 30.0).abs() < 1e-12);
        assert!(
            (s.speed_at(t / 2.0) - 40.0).abs() < 1e-9,
            "{}",
            s.speed_at(t / 2.0)
        );
        assert!((s.speed_at(t) - 50.0).abs() < 1e-12);
        // The rate integrates to the speed change, and the distance to the length.
        let n = 20_000;
        let h = t / f64::from(n);
        let (mut dv, mut d) = (0.0, 0.0);
        for i in 0..n {
            let m = (f64::from(i) + 0.5) * h;
            dv += s.tangential_acc_at(m) * h;
            d += s.speed_at(m) * h;
        }
        assert!((dv - 20.0).abs() < 1e-3, "{dv}");
        assert!((d - len).abs() < 1e-6, "{d} {len}");
    }

    #[test]
    fn barriers_are_the_commands_that_need_motion_stopped() {
        assert!(!AuxKind::SpindleSpeed { rpm: 1.0 }.is_barrier());
        assert!(!AuxKind::DigitalOutput {
            index: 0,
            on: true,
            synced: true
        }
        .is_barrier());
        assert!(AuxKind::DigitalOutput {
            index: 0,
            on: true,
            synced: false
        }
        .is_barrier());
        assert!(AuxKind::SpindleStart(SpindleDir::Clockwise).is_barrier());
        assert!(AuxKind::ProgramEnd.is_barrier());
    }
}
