//! G76, LinuxCNC's threading cycle: a series of spindle-synchronised passes from the
//! current position to the Z (and X) of the block, each deeper than the last.
//!
//! Words: P pitch (units per revolution), I thread peak offset from the current X
//! (negative: external thread, positive: internal), J first cut depth, K full thread depth,
//! R depth degression (pass n cuts at J·n^(1/R), default 1), Q compound slide angle in
//! degrees (the passes shift along Z by depth·tan Q), H spring passes at full depth, E taper
//! length along Z and L which ends taper (0 none, 1 entry, 2 exit, 3 both). Every pass is
//! traverse back, traverse in (or a synchronised entry taper), a synchronised feed over
//! the thread (and the exit taper), a traverse out, with feed override off while cutting,
//! exactly the calls rs274 emits. The tool ends at the block's end point.

use super::motion::pose6;
use super::Interp;
use crate::gcode::canon::{CanonCmd, OverrideKind};
use crate::gcode::modal::Block;
use crate::gcode::GcodeError;

/// The geometry of one G76 block, in program units (radii).
struct Thread {
    start: [f64; 6],
    end_z: f64,
    pitch: f64,
    /// I: peak offset; its sign says external (-1) or internal (+1).
    peak: f64,
    side: f64,
    first: f64,
    full: f64,
    /// tan of the compound angle, signed for the direction of the cut.
    slant: f64,
    /// +1 when the thread runs toward +Z, else -1.
    dir: f64,
    taper_len: f64,
    entry_taper: bool,
    exit_taper: bool,
}

impl Thread {
    fn x_in(&self, depth: f64) -> f64 {
        self.start[0] + self.peak + self.side * depth
    }
    fn x_out(&self, depth: f64) -> f64 {
        self.start[0] - self.side * (self.full - depth)
    }
    fn at(&self, x: f64, z: f64) -> [f64; 6] {
        let mut p = self.start;
        p[0] = x;
        p[2] = z;
        p
    }
    /// Taper feeds move K across over E along: their pitch along the path.
    fn taper_pitch(&self) -> f64 {
        self.pitch * self.taper_len.hypot(self.full) / self.taper_len
    }
}

/// A G76 word that must be a whole number (H, L).
fn whole(b: &Block, c: u8, what: &str) -> Result<Option<i64>, (u32, String)> {
    match b.get(c) {
        None => Ok(None),
        Some(v) if v.fract() != 0.0 => Err((
            b.col_of(c),
            format!("{what} must be a whole number in G76 (got {v})"),
        )),
        Some(v) => Ok(Some(v as i64)),
    }
}

impl Interp<'_> {
    /// G76.
    pub(super) fn threading_cycle(&mut self, b: &Block) -> Result<(), GcodeError> {
        let col = self.loc.col;
        let p = match b.get(b'p') {
            Some(p) if p >= 0.0 => p,
            _ => return Err(self.err(col, "P word (thread pitch) missing with G76")),
        };
        if !b.has_axis() {
            return Err(self.err(col, "All axes missing with motion code G76"));
        }
        let (Some(i), Some(j), Some(k)) = (b.get(b'i'), b.get(b'j'), b.get(b'k')) else {
            return Err(self.err(
                col,
                "I J or K words missing with G76 (peak offset, first cut, thread depth)",
            ));
        };
        // rs274 quarters I, J and K in diameter mode (they are halved twice); reproduced.
        let scale = if self.s.diameter_mode { 0.25 } else { 1.0 };
        let (i, j, k) = (i * scale, j * scale, k * scale);
        if i == 0.0 {
            return Err(self.err(b.col_of(b'i'), "In G76, I must not be 0"));
        }
        if j <= 0.0 {
            return Err(self.err(b.col_of(b'j'), "In G76, J must be greater than 0"));
        }
        if k <= j {
            return Err(self.err(b.col_of(b'k'), "In G76, K must be greater than J"));
        }
        let degression = b.get(b'r').unwrap_or(1.0);
        if degression < 0.0 {
            // rs274 never ends: the cuts get shallower forever.
            return Err(self.err(
                b.col_of(b'r'),
                format!("In G76, R (depth degression) must not be negative (got {degression})"),
            ));
        }
        let h = whole(b, b'h', "H (spring passes)").map_err(|(c, m)| self.err(c, m))?;
        let l = whole(b, b'l', "L (taper ends)").map_err(|(c, m)| self.err(c, m))?;
        if self.s.spindle == 0 {
            return Err(self.err(
                col,
                "Spindle not turning in G76 (start it with M3 or M4 first)",
            ));
        }
        self.s.motion = 760;
        let end = self.find_ends(b);
        let start = self.s.pos;
        if (3..6).any(|a| end[a] != start[a]) {
            return Err(self.err(col, "Cannot move rotary axes with G76"));
        }
        let dir = if end[2] > start[2] { 1.0 } else { -1.0 };
        let angle = b.get(b'q').unwrap_or(0.0).to_radians();
        let taper_len = b.get(b'e').unwrap_or(0.0);
        let taper = taper_len > 0.0;
        let l = l.unwrap_or(0);
        let t = Thread {
            start,
            end_z: end[2],
            pitch: p,
            peak: i,
            side: if i > 0.0 { 1.0 } else { -1.0 },
            first: j,
            full: k,
            slant: -dir * angle.tan(),
            dir,
            taper_len,
            entry_taper: taper && (l == 1 || l == 3),
            exit_taper: taper && (l == 2 || l == 3),
        };
        let mut pass = 1.0_f64;
        let mut depth = t.first;
        while depth < t.full {
            self.thread_pass(&t, depth)?;
            pass += 1.0;
            depth = t.first * pass.powf(1.0 / degression);
        }
        for _ in 0..=h.unwrap_or(0).max(-1) {
            self.thread_pass(&t, t.full)?;
        }
        self.emit(CanonCmd::StraightTraverse(pose6(&end)))?;
        self.s.pos = end;
        Ok(())
    }

    fn thread_pass(&mut self, t: &Thread, depth: f64) -> Result<(), GcodeError> {
        let (x_in, x_out) = (t.x_in(depth), t.x_out(depth));
        let z_in = t.start[2] - depth * t.slant;
        let z_end = t.end_z - (depth - t.full) * t.slant;
        let x_taper = x_in - t.side * t.full;
        let feed_override = |on| CanonCmd::OverrideEnable {
            which: OverrideKind::Feed,
            on,
        };
        self.emit(CanonCmd::StraightTraverse(pose6(&t.at(x_out, z_in))))?;
        if t.entry_taper {
            self.emit(feed_override(false))?;
            self.emit(CanonCmd::StartSpeedFeedSync {
                pitch: t.taper_pitch(),
            })?;
            self.emit(CanonCmd::StraightFeed(pose6(&t.at(x_taper, z_in))))?;
            let z = z_in + t.dir * t.taper_len;
            self.emit(CanonCmd::StraightFeed(pose6(&t.at(x_in, z))))?;
            self.emit(CanonCmd::StartSpeedFeedSync { pitch: t.pitch })?;
        } else {
            self.emit(CanonCmd::StraightTraverse(pose6(&t.at(x_in, z_in))))?;
            self.emit(feed_override(false))?;
            self.emit(CanonCmd::StartSpeedFeedSync { pitch: t.pitch })?;
        }
        if t.exit_taper {
            let z = z_end - t.dir * t.taper_len;
            self.emit(CanonCmd::StraightFeed(pose6(&t.at(x_in, z))))?;
            self.emit(CanonCmd::StartSpeedFeedSync {
                pitch: t.taper_pitch(),
            })?;
            self.emit(CanonCmd::StraightFeed(pose6(&t.at(x_taper, z_end))))?;
        } else {
            self.emit(CanonCmd::StraightFeed(pose6(&t.at(x_in, z_end))))?;
        }
        self.emit(CanonCmd::StopSpeedFeedSync)?;
        self.emit(CanonCmd::StraightTraverse(pose6(&t.at(x_out, z_end))))?;
        self.emit(feed_override(true))
    }
}
