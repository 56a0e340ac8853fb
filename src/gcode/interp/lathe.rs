//! Lathe modes: G7 (diameter mode) and G8 (radius mode), and M19 spindle orientation.
//!
//! In diameter mode every X word of a block is a diameter, so the interpreter halves it as
//! soon as the block is read, before any code uses it: motion end points (G0…G3, G33, cycles,
//! G53, G28/G30), G92, G10 L1/L2/L10/L20 and G43.1 all see the radius, as in rs274. The arc
//! words I and R and the parameters (#5420, `#<_x>`) stay radii.

use super::Interp;
use crate::gcode::canon::CanonCmd;
use crate::gcode::modal::{li, Block};
use crate::gcode::GcodeError;

impl Interp<'_> {
    /// Halves the X word of `b` if the block runs in diameter mode (the G7/G8 of the block
    /// itself counts).
    pub(super) fn diameter_words(&self, b: &mut Block) {
        let diameter = match b.gcode(15) {
            Some(g) => g == 70,
            None => self.s.diameter_mode,
        };
        if diameter {
            if let Some(x) = &mut b.val[li(b'x')] {
                *x /= 2.0;
            }
        }
    }

    /// G7/G8: rs274 says so only when the mode changes.
    pub(super) fn lathe_mode(&mut self, g: u16) -> Result<(), GcodeError> {
        let diameter = g == 70;
        if diameter == self.s.diameter_mode {
            return Ok(());
        }
        self.s.diameter_mode = diameter;
        self.emit(CanonCmd::Comment(
            if diameter {
                "interpreter: Lathe diameter mode changed to diameter"
            } else {
                "interpreter: Lathe diameter mode changed to radius"
            }
            .into(),
        ))
    }

    /// M19: orient the spindle to R degrees (P: 0 either way, 1 clockwise, 2
    /// counter-clockwise), and with Q wait up to Q seconds for it. The spindle counts as
    /// stopped afterwards. Without R and P nothing is commanded (rs274 emits no call).
    pub(super) fn orient_spindle(&mut self, b: &Block) -> Result<(), GcodeError> {
        let mode = match b.get(b'p') {
            None => 0,
            Some(p) if p.fract() != 0.0 => {
                return Err(self.err(b.col_of(b'p'), "P value not an integer with M19"))
            }
            Some(p) if !(0.0..=2.0).contains(&p) => {
                return Err(self.err(
                    b.col_of(b'p'),
                    format!("P value must be 0, 1 or 2 with M19 (got {p})"),
                ))
            }
            Some(p) => p as u8,
        };
        if let Some(r) = b.get(b'r') {
            if !(0.0..=360.0).contains(&r) {
                return Err(self.err(
                    b.col_of(b'r'),
                    format!("R value must be within 0..360 with M19 (got {r})"),
                ));
            }
        }
        if let Some(q) = b.get(b'q') {
            if q <= 0.0 {
                return Err(self.err(
                    b.col_of(b'q'),
                    format!("Q word with M19 requires a value > 0 (got {q})"),
                ));
            }
        }
        self.s.spindle = 0;
        if b.has(b'r') || b.has(b'p') {
            // The machine's `[RS274NGC] ORIENT_OFFSET` (the spindle's index against its
            // zero) is added as it is, unwrapped, as rs274 does.
            let offset = self
                .opts
                .ini
                .get("rs274ngc", "orient_offset")
                .unwrap_or(0.0);
            self.emit(CanonCmd::OrientSpindle {
                angle: b.get(b'r').unwrap_or(0.0) + offset,
                mode,
            })?;
        }
        if let Some(q) = b.get(b'q') {
            self.emit(CanonCmd::WaitOrientComplete(q))?;
        }
        Ok(())
    }
}
