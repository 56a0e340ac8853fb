//! Spindle-synchronised motion: G33 (a straight move whose feed is locked to the spindle,
//! K units per revolution) and G33.1 (rigid tapping: in to the end point and back out on the
//! same helix). Both are bracketed by `START_SPEED_FEED_SYNC(K, 0)` /
//! `STOP_SPEED_FEED_SYNCH()`, as rs274 emits them.

use super::motion::pose6;
use super::Interp;
use crate::gcode::canon::CanonCmd;
use crate::gcode::modal::Block;
use crate::gcode::GcodeError;

/// Static checks of a G33/G33.1 block (rs274's, before anything executes): K on every
/// line (G33 is modal, but its pitch is not), no F word.
pub(super) fn check_sync_words(b: &Block, motion: u16) -> Result<(), (u32, &'static str)> {
    if !matches!(motion, 330 | 331) {
        return Ok(());
    }
    let uses = b.g[1].is_some() || b.has_axis();
    if !uses {
        return Ok(());
    }
    if b.has(b'f') {
        return Err((
            b.col_of(b'f'),
            "F word used with a G33/G33.1 (the feed is K per spindle revolution)",
        ));
    }
    if !b.has(b'k') {
        return Err((
            b.g[1].map(|g| g.1).unwrap_or(1),
            "K word (pitch per revolution) missing with G33/G33.1",
        ));
    }
    Ok(())
}

impl Interp<'_> {
    fn sync_start(&mut self, m: u16, b: &Block) -> Result<(f64, [f64; 6]), GcodeError> {
        let name = if m == 330 { "G33" } else { "G33.1" };
        if !b.has_axis() {
            return Err(self.err(
                self.loc.col,
                format!("All axes missing with motion code {name}"),
            ));
        }
        if self.s.spindle == 0 {
            return Err(self.err(
                self.loc.col,
                format!("Spindle not turning in {name} (start it with M3 or M4 first)"),
            ));
        }
        let k = b.get(b'k').unwrap_or(0.0);
        self.s.motion = m;
        let end = self.find_ends(b);
        self.emit(CanonCmd::StartSpeedFeedSync { pitch: k })?;
        Ok((k, end))
    }

    /// G33: one straight feed locked to the spindle.
    pub(super) fn spindle_synced_feed(&mut self, b: &Block) -> Result<(), GcodeError> {
        let (_, end) = self.sync_start(330, b)?;
        self.emit(CanonCmd::StraightFeed(pose6(&end)))?;
        self.emit(CanonCmd::StopSpeedFeedSync)?;
        self.s.pos = end;
        Ok(())
    }

    /// G33.1: rigid tap to the end point; the tool comes back to where it started.
    pub(super) fn rigid_tap(&mut self, b: &Block) -> Result<(), GcodeError> {
        let (_, end) = self.sync_start(331, b)?;
        self.emit(CanonCmd::RigidTap { end: pose6(&end) })?;
        self.emit(CanonCmd::StopSpeedFeedSync)
    }
}
