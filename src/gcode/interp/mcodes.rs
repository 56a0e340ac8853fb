//! M codes and the T word: tool selection and change (M6, M61), spindle (M3–M5), coolant
//! (M7–M9), overrides (M48–M53), I/O (M62–M68), modal state (M70–M73), user commands
//! (M100–M199) and program stops (M0, M1, M2, M30, M60).

use super::Interp;
use crate::gcode::canon::{
    CanonCmd, FeedMode, InputKind, OverrideKind, Plane, SpindleDir, WaitKind,
};
use crate::gcode::modal::Block;
use crate::gcode::params;
use crate::gcode::GcodeError;

fn int_word(v: f64) -> Option<u32> {
    if v >= 0.0 && v.fract() == 0.0 && v < 1e9 {
        Some(v as u32)
    } else {
        None
    }
}

impl Interp<'_> {
    /// T word.
    pub(super) fn select_tool(&mut self, t: f64) -> Result<(), GcodeError> {
        let col = self.loc.col;
        let Some(n) = int_word(t) else {
            return Err(self.err(col, "Negative or non-integer tool number used"));
        };
        let slot = if n == 0 {
            0
        } else {
            self.tools.slot_of(n).ok_or_else(|| {
                self.err(
                    col,
                    format!("Requested tool {n} not found in the tool table"),
                )
            })?
        };
        self.s.selected = Some((n, slot));
        self.emit(CanonCmd::SelectTool(n))
    }

    fn load_tool_params(&mut self, copy_to_spindle: bool) {
        // Tool parameters are in machine units, as the table.
        self.p.numbered[params::TOOL_NUMBER] = f64::from(self.s.tool);
        let t = self.tools.at_slot(self.s.tool_slot).cloned();
        for i in 0..9 {
            self.p.numbered[params::TOOL_BASE + i] = t.as_ref().map(|t| t.offset[i]).unwrap_or(0.0);
        }
        self.p.numbered[params::TOOL_BASE + 9] = t.as_ref().map(|t| t.diameter).unwrap_or(0.0);
        if copy_to_spindle {
            self.s.spindle_tool = t;
        }
    }

    pub(super) fn exec_mcodes_before_motion(&mut self, b: &Block) -> Result<(), GcodeError> {
        // I/O
        if let Some((m, col)) = b.m[5] {
            self.loc.col = col;
            self.io(m, b)?;
        }
        // tool change
        if let Some((m, col)) = b.m[6] {
            self.loc.col = col;
            if m == 6 {
                // Without a T word LinuxCNC changes to the empty slot 0.
                let (n, slot) = self.s.selected.unwrap_or((0, 0));
                self.refuse_with_comp(col, "Cannot change tools")?;
                self.emit(CanonCmd::StartChange)?;
                self.emit(CanonCmd::StopSpindle)?;
                self.s.spindle = 0;
                self.emit(CanonCmd::ChangeTool(
                    u32::try_from(slot).unwrap_or(u32::MAX),
                ))?;
                self.s.tool = n;
                self.s.tool_slot = slot;
                self.load_tool_params(true);
                self.s.synch_pending = true;
            } else {
                let q = b
                    .get(b'q')
                    .ok_or_else(|| self.err(col, "Q word missing with M61"))?;
                let Some(n) = int_word(q) else {
                    return Err(self.err(b.col_of(b'q'), "Invalid tool number in M61 Q word"));
                };
                let slot = if n == 0 {
                    0
                } else {
                    self.tools.slot_of(n).ok_or_else(|| {
                        self.err(col, format!("M61 tool {n} not found in the tool table"))
                    })?
                };
                self.emit(CanonCmd::ChangeToolNumber(
                    u32::try_from(slot).unwrap_or(u32::MAX),
                ))?;
                self.s.tool = n;
                self.s.tool_slot = slot;
                self.load_tool_params(false);
                self.s.synch_pending = true;
            }
        }
        // spindle
        if let Some((m, col)) = b.m[7] {
            self.loc.col = col;
            match m {
                3 => {
                    self.s.spindle = 1;
                    self.emit(CanonCmd::StartSpindle(SpindleDir::Clockwise))?;
                }
                4 => {
                    self.s.spindle = -1;
                    self.emit(CanonCmd::StartSpindle(SpindleDir::CounterClockwise))?;
                }
                19 => self.orient_spindle(b)?,
                _ => {
                    self.s.spindle = 0;
                    self.emit(CanonCmd::StopSpindle)?;
                }
            }
        }
        // modal state save/restore
        if let Some((m, col)) = b.m[11] {
            self.loc.col = col;
            self.modal_state(m)?;
        }
        // coolant
        if let Some((m, col)) = b.m[8] {
            self.loc.col = col;
            match m {
                7 => {
                    self.s.mist = true;
                    self.emit(CanonCmd::MistOn)?;
                }
                8 => {
                    self.s.flood = true;
                    self.emit(CanonCmd::FloodOn)?;
                }
                _ => {
                    self.s.mist = false;
                    self.s.flood = false;
                    self.emit(CanonCmd::MistOff)?;
                    self.emit(CanonCmd::FloodOff)?;
                }
            }
        }
        // overrides
        if let Some((m, col)) = b.m[9] {
            self.loc.col = col;
            self.refuse_with_comp(col, "Cannot change overrides (M48-M53)")?;
            let on = b.get(b'p').map(|p| p != 0.0).unwrap_or(true);
            let ov = |which, on| CanonCmd::OverrideEnable { which, on };
            match m {
                48 | 49 => {
                    let on = m == 48;
                    self.s.feed_override = on;
                    self.s.speed_override = on;
                    self.emit(ov(OverrideKind::Feed, on))?;
                    self.emit(ov(OverrideKind::Spindle, on))?;
                }
                50 => {
                    self.s.feed_override = on;
                    self.emit(ov(OverrideKind::Feed, on))?;
                }
                51 => {
                    self.s.speed_override = on;
                    self.emit(ov(OverrideKind::Spindle, on))?;
                }
                52 => {
                    let on = b.get(b'p').map(|p| p > 0.0).unwrap_or(false);
                    self.s.adaptive_feed = on;
                    self.emit(ov(OverrideKind::AdaptiveFeed, on))?;
                }
                _ => {
                    self.s.feed_hold = on;
                    self.emit(ov(OverrideKind::FeedHold, on))?;
                }
            }
        }
        // user M codes
        if let Some((m, col)) = b.m[10] {
            self.loc.col = col;
            self.emit(CanonCmd::UserMcode {
                code: u32::from(m),
                p: b.get(b'p').unwrap_or(0.0),
                q: b.get(b'q').unwrap_or(0.0),
            })?;
        }
        Ok(())
    }

    /// Takes the machine's answer to the pending M66: the input's value (0/1 for a digital
    /// input, the reading for an analog one) or -1 after a timeout, into #5399.
    pub(crate) fn wait_result(&mut self, value: f64) {
        self.pending_wait = None;
        self.p.numbered[params::M66_RESULT] = value;
    }

    fn io(&mut self, m: u16, b: &Block) -> Result<(), GcodeError> {
        let col = self.loc.col;
        self.refuse_with_comp(col, "Cannot set outputs or wait for inputs (M62-M68)")?;
        match m {
            62..=65 => {
                let p = b
                    .get(b'p')
                    .and_then(int_word)
                    .ok_or_else(|| self.err(col, "Invalid or missing P word with M62 to M65"))?;
                self.emit(CanonCmd::DigitalOutput {
                    index: p,
                    on: m == 62 || m == 64,
                    synced: m <= 63,
                })
            }
            66 => {
                let (index, input) = match (b.get(b'p'), b.get(b'e')) {
                    (Some(_), Some(_)) => {
                        return Err(self.err(col, "Both digital and analog input selected with M66"))
                    }
                    (Some(p), None) => (p, InputKind::Digital),
                    (None, Some(e)) => (e, InputKind::Analog),
                    (None, None) => return Err(self.err(col, "Missing P or E word with M66")),
                };
                let index = int_word(index)
                    .ok_or_else(|| self.err(col, "Invalid input number with M66"))?;
                let l = b.get(b'l').unwrap_or(0.0);
                let kind = match l as i64 {
                    0 => WaitKind::Immediate,
                    1 => WaitKind::Rise,
                    2 => WaitKind::Fall,
                    3 => WaitKind::High,
                    4 => WaitKind::Low,
                    _ => {
                        return Err(self.err(b.col_of(b'l'), "Invalid wait type (L word) with M66"))
                    }
                };
                if input == InputKind::Analog && kind != WaitKind::Immediate {
                    return Err(self.err(
                        col,
                        "Can't select analog input with wait type != immediate return",
                    ));
                }
                let q = b.get(b'q').unwrap_or(0.0);
                if kind != WaitKind::Immediate && q <= 0.0 {
                    return Err(self.err(
                        col,
                        "Q word (timeout) must be positive with M66 wait type other than L0",
                    ));
                }
                self.emit(CanonCmd::Wait {
                    index,
                    input,
                    kind,
                    timeout_s: q,
                })?;
                // LinuxCNC's M66 is a queue buster: the interpreter stops after the line and
                // reads the input (or -1 after a timeout) into #5399 before the next one. In
                // a live session the machine answers (`Session::wait_result`); without one
                // #5399 keeps its value, as rs274's GET_EXTERNAL_*_INPUT returns the default.
                if self.live_wait {
                    self.pending_wait = Some(self.loc.clone());
                }
                Ok(())
            }
            _ => {
                let e = b
                    .get(b'e')
                    .and_then(int_word)
                    .ok_or_else(|| self.err(col, "Invalid or missing E word with M67/M68"))?;
                // LinuxCNC's default for a missing Q word is -1.
                let q = b.get(b'q').unwrap_or(-1.0);
                self.emit(CanonCmd::AnalogOutput {
                    index: e,
                    value: q,
                    synced: m == 67,
                })
            }
        }
    }

    fn modal_state(&mut self, m: u16) -> Result<(), GcodeError> {
        let level = self.call_level();
        match m {
            70 | 73 => {
                let mut snap = self.s.clone();
                snap.g92_enabled = self.p.numbered[params::G92_ENABLED] != 0.0;
                snap.saved = Vec::new();
                snap.auto_restore = Vec::new();
                if let Some(slot) = self.s.saved.get_mut(level) {
                    *slot = Some(Box::new(snap));
                }
                if let Some(a) = self.s.auto_restore.get_mut(level) {
                    *a = m == 73;
                }
                Ok(())
            }
            71 => {
                if let Some(slot) = self.s.saved.get_mut(level) {
                    *slot = None;
                }
                Ok(())
            }
            _ => {
                let snap = self.s.saved.get(level).cloned().flatten();
                match snap {
                    Some(s) => self.restore_modal(&s),
                    None => Err(self.err(
                        self.loc.col,
                        "Cannot restore context from invalid stack frame - missing M70/M73?",
                    )),
                }
            }
        }
    }

    /// Restores the modal state saved by M70/M73, reporting each change to canon in rs274's
    /// observed order: units, feed mode, feed, spindle speed and direction, (coolant), plane,
    /// tool length offset mode, coordinate system, path control, distance mode, retract
    /// mode, the G92 offsets' on/off state, (coolant). The coolant comes before the plane
    /// unless the spindle's state changes too; then it comes last (M72 and M73 alike).
    pub(super) fn restore_modal(&mut self, s: &super::Settings) -> Result<(), GcodeError> {
        use crate::gcode::canon::{FeedMode, LengthUnits, MotionControl};
        let coolant_first = s.spindle == self.s.spindle;
        if s.units != self.s.units {
            self.set_units(if s.units == LengthUnits::Inches {
                200
            } else {
                210
            })?;
        }
        if s.feed_mode != self.s.feed_mode {
            self.set_feed_mode(match s.feed_mode {
                FeedMode::InverseTime => 930,
                FeedMode::UnitsPerRevolution => 950,
                FeedMode::UnitsPerMinute => 940,
            })?;
        }
        if s.feed_rate != self.s.feed_rate {
            self.s.feed_rate = s.feed_rate;
            self.emit(CanonCmd::SetFeedRate(s.feed_rate))?;
        }
        if s.speed != self.s.speed {
            self.s.speed = s.speed;
            self.emit(CanonCmd::SetSpindleSpeed(s.speed))?;
        }
        if s.spindle != self.s.spindle {
            self.s.spindle = s.spindle;
            self.emit(match s.spindle {
                1 => CanonCmd::StartSpindle(SpindleDir::Clockwise),
                -1 => CanonCmd::StartSpindle(SpindleDir::CounterClockwise),
                _ => CanonCmd::StopSpindle,
            })?;
        }
        if coolant_first {
            self.restore_coolant(s)?;
        }
        if s.plane != self.s.plane {
            self.s.plane = s.plane;
            self.emit(CanonCmd::SelectPlane(s.plane))?;
        }
        if s.tlo_active != self.s.tlo_active {
            self.restore_tool_offset_mode(s.tlo_active)?;
        }
        if s.origin_index != self.s.origin_index {
            self.select_coord_system(s.origin_index)?;
        }
        if s.control != self.s.control || s.naive_tol != self.s.naive_tol {
            self.s.control = s.control;
            self.s.naive_tol = s.naive_tol;
            self.emit(CanonCmd::SetMotionControl(s.control))?;
            if matches!(s.control, MotionControl::Continuous { .. }) {
                self.emit(CanonCmd::SetNaivecamTolerance(s.naive_tol))?;
            }
        }
        if s.absolute != self.s.absolute {
            self.s.absolute = s.absolute;
            self.emit(CanonCmd::Comment(
                if s.absolute {
                    "interpreter: distance mode changed to absolute"
                } else {
                    "interpreter: distance mode changed to incremental"
                }
                .into(),
            ))?;
        }
        self.s.ijk_absolute = s.ijk_absolute;
        if s.retract_old_z != self.s.retract_old_z {
            self.set_retract_mode(s.retract_old_z)?;
        }
        // The G92 offsets come back on (G92.3, from #5211…) or go off (G92.2) as they were;
        // their values are not part of the saved state.
        let g92_on = self.p.numbered[params::G92_ENABLED] != 0.0;
        if s.g92_enabled != g92_on {
            if s.g92_enabled {
                self.g92_apply_stored()?;
            } else {
                self.g92_off(false)?;
            }
        }
        if !coolant_first {
            self.restore_coolant(s)?;
        }
        Ok(())
    }

    fn restore_coolant(&mut self, s: &super::Settings) -> Result<(), GcodeError> {
        if s.mist != self.s.mist || s.flood != self.s.flood {
            self.s.mist = s.mist;
            self.s.flood = s.flood;
            if !s.mist && !s.flood {
                self.emit(CanonCmd::MistOff)?;
                self.emit(CanonCmd::FloodOff)?;
            } else {
                if s.mist {
                    self.emit(CanonCmd::MistOn)?;
                }
                if s.flood {
                    self.emit(CanonCmd::FloodOn)?;
                }
            }
        }
        Ok(())
    }

    /// M0, M1, M2, M30, M60.
    pub(super) fn stop(&mut self, m: u16) -> Result<(), GcodeError> {
        self.comp_at_stop(matches!(m, 2 | 30))?;
        match m {
            0 => self.emit(CanonCmd::ProgramStop),
            1 => self.emit(CanonCmd::OptionalProgramStop),
            60 => {
                self.emit(CanonCmd::PalletShuttle)?;
                self.emit(CanonCmd::ProgramStop)
            }
            _ => {
                // LinuxCNC's reset on program end: back to G54 (through its rotation).
                self.activate_g5x(1)?;
                self.emit(CanonCmd::SetXyRotation(self.s.rotation))?;
                if self.s.plane != Plane::Xy {
                    self.s.plane = Plane::Xy;
                    self.emit(CanonCmd::SelectPlane(Plane::Xy))?;
                }
                self.s.absolute = true;
                self.s.feed_mode = FeedMode::UnitsPerMinute;
                self.emit(CanonCmd::SetFeedMode(FeedMode::UnitsPerMinute))?;
                self.s.feed_rate = 0.0;
                self.emit(CanonCmd::SetFeedRate(0.0))?;
                if !self.s.feed_override {
                    self.s.feed_override = true;
                    self.emit(CanonCmd::OverrideEnable {
                        which: OverrideKind::Feed,
                        on: true,
                    })?;
                }
                self.s.speed_override = true;
                self.s.spindle = 0;
                self.emit(CanonCmd::StopSpindle)?;
                self.s.css = false;
                self.s.css_max = 0.0;
                self.emit(CanonCmd::SetSpindleMode { css_max_rpm: 0.0 })?;
                self.s.motion = 10;
                if self.s.mist {
                    self.s.mist = false;
                    self.emit(CanonCmd::MistOff)?;
                }
                if self.s.flood {
                    self.s.flood = false;
                    self.emit(CanonCmd::FloodOff)?;
                }
                if m == 30 {
                    self.emit(CanonCmd::PalletShuttle)?;
                }
                self.emit(CanonCmd::ProgramEnd)?;
                if self.percent_unclosed() {
                    self.emit(CanonCmd::Comment(
                        "interpreter: percent sign missing from end of file".into(),
                    ))?;
                }
                self.emit(CanonCmd::OnReset)?;
                self.emit(CanonCmd::OnReset)?;
                self.end_program();
                Ok(())
            }
        }
    }
}

impl Interp<'_> {
    /// G10 L1/L10/L11: edits the tool table (kept in machine units).
    pub(super) fn g10_tool(&mut self, l: i64, p: f64, b: &Block) -> Result<(), GcodeError> {
        let col = self.loc.col;
        let Some(n) = int_word(p) else {
            return Err(self.err(
                b.col_of(b'p'),
                "Invalid tool number (P word) with G10 L1/L10/L11",
            ));
        };
        let slot = self.tools.slot_of(n).ok_or_else(|| {
            self.err(
                col,
                format!("Tool {n} not found in the tool table (G10 L{l})"),
            )
        })?;
        // to the table's machine units and back, rounded as rs274's conversions
        let (to_user, to_prog) = self.s.unit_conversions();
        const AX: &[u8; 6] = b"xyzabc";
        // L11 measures against G59.3 (system 9), whatever system is active; its stored
        // offset is in machine units.
        let g593: [f64; 6] = std::array::from_fn(|i| {
            self.s
                .user_len(i, self.p.numbered[crate::gcode::params::g5x_base(9) + i])
        });
        // rs274 copies the edit to the spindle (pocket 0) when the slot is its current pocket,
        // which is also the start pocket before any M6 (`InterpOptions::start_pocket`).
        let spindle_tool = slot == self.s.tool_slot;
        // L10 under an XY rotation (`G10 L2 … R`): the X/Y offsets that put the program
        // position at (X, Y) through the rotation, both set when either is given, as rs274
        // computes them. An axis not given keeps the program position the tool would have
        // with its table offsets in force (the offsets are machine-frame X/Y, turned
        // against the program frame, so one axis given moves both).
        let table_xy = self
            .tools
            .at_slot(slot)
            .map(|t| [to_prog(t.offset[0]), to_prog(t.offset[1])]);
        let rotated_xy =
            (l == 10 && self.s.rotation != 0.0 && (b.has(b'x') || b.has(b'y'))).then(|| {
                let s = &self.s;
                let m = self.machine_of_program(&s.pos, true);
                let [tx, ty] = table_xy.unwrap_or([0.0; 2]);
                let (px, py) =
                    super::frame::rotate(m[0] - s.g5x[0] - tx, m[1] - s.g5x[1] - ty, -s.rotation);
                // Targets with the G92 offset, which canon turns with the program position.
                let vx = b.get(b'x').map_or(px, |v| v + s.g92[0]);
                let vy = b.get(b'y').map_or(py, |v| v + s.g92[1]);
                let (rx, ry) = super::frame::rotate(vx, vy, s.rotation);
                [to_user(m[0] - s.g5x[0] - rx), to_user(m[1] - s.g5x[1] - ry)]
            });
        let Some(t) = self.tools.tools.get_mut(slot - 1) else {
            return Err(self.err(col, "Tool table slot out of range"));
        };
        if let Some([x, y]) = rotated_xy {
            (t.offset[0], t.offset[1]) = (x, y);
        }
        for (i, &c) in AX.iter().enumerate() {
            if rotated_xy.is_some() && i < 2 {
                continue;
            }
            if let Some(v) = b.get(c) {
                let lin = i < 3;
                let conv = |x: f64| if lin { to_user(x) } else { x };
                t.offset[i] = match l {
                    1 => conv(v),
                    _ => {
                        // L10/L11: offset such that the current position becomes v.
                        let cur_machine =
                            self.s.pos[i] + self.s.g5x[i] + self.s.g92[i] + self.s.tool_offset[i];
                        let base = if l == 10 {
                            cur_machine - self.s.g5x[i] - self.s.g92[i]
                        } else {
                            cur_machine - g593[i]
                        };
                        conv(base - v)
                    }
                };
            }
        }
        if let Some(r) = b.get(b'r') {
            t.diameter = to_user(r) * 2.0;
        }
        if let Some(i) = b.get(b'i') {
            t.front_angle = i;
        }
        if let Some(j) = b.get(b'j') {
            t.back_angle = j;
        }
        if let Some(q) = b.get(b'q') {
            t.orientation = q as i32;
        }
        let t = t.clone();
        let entry = |pocket: u32| CanonCmd::SetToolTableEntry {
            pocket,
            tool: t.number,
            offset: t.offset,
            diameter: t.diameter,
            front_angle: t.front_angle,
            back_angle: t.back_angle,
            orientation: t.orientation,
        };
        self.emit(entry(u32::try_from(slot).unwrap_or(u32::MAX)))?;
        if spindle_tool {
            // The spindle's copy (LinuxCNC's pocket 0) changes too: a G43 without H
            // after this uses the new offsets.
            self.s.spindle_tool = Some(t.clone());
            self.s.tool = t.number;
            self.emit(entry(0))?;
            // #5401-#5410 mirror the spindle's entry, so they show the edit at once.
            self.load_tool_params(false);
        }
        Ok(())
    }
}
