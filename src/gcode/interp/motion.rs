//! Straight motion and the state that shapes it: end points (G90/G91/G53), G0/G1, G38.x
//! probing, units (G20/G21), tool length offsets (G43/G43.1/G49), coordinate systems
//! (G54–G59.3, G10 L2/L20) and axis offsets (G92 family), G28/G30 homes.

use super::frame;
use super::Interp;
use crate::gcode::canon::{CanonCmd, FeedMode, LengthUnits, Pose, ProbeKind};
use crate::gcode::modal::Block;
use crate::gcode::params::{self, g5x_base};
use crate::gcode::GcodeError;

const AXES: &[u8; 6] = b"xyzabc";

/// Full 9-axis pose from six values (U V W stay 0: hytask interprets XYZABC, as rs274).
pub(crate) fn pose6(v: &[f64; 6]) -> Pose {
    let mut p = [0.0; 9];
    p[..6].copy_from_slice(v);
    p
}

impl Interp<'_> {
    /// End point of a move from the axis words (LinuxCNC `find_ends`).
    pub(crate) fn find_ends(&self, b: &Block) -> [f64; 6] {
        let mut from = self.s.pos;
        if self.comp.measures_from_program() {
            // With compensation on, moves are measured from the programmed point.
            from[..3].copy_from_slice(&self.comp.prog);
        }
        self.find_ends_from(b, from)
    }

    /// End point of a move from the axis words, measured from `from` (the axes not named
    /// keep its values).
    pub(crate) fn find_ends_from(&self, b: &Block, from: [f64; 6]) -> [f64; 6] {
        let mut end = from;
        let base = end;
        let g53 = b.gcode(0) == Some(530);
        if g53 && self.s.rotation != 0.0 {
            // G53 names machine coordinates, which the XY rotation does not turn: the axes
            // not named keep their machine position.
            let mut m = self.machine_of_program(&self.s.pos, true);
            for (i, &c) in AXES.iter().enumerate() {
                if let Some(v) = b.get(c) {
                    m[i] = v;
                }
            }
            return self.program_of_machine(&m, true);
        }
        for (i, &c) in AXES.iter().enumerate() {
            if let Some(v) = b.get(c) {
                end[i] = if g53 {
                    v - self.s.g5x[i] - self.s.g92[i] - self.s.tool_offset[i]
                } else if self.s.absolute {
                    v
                } else {
                    base[i] + v
                };
            }
        }
        if b.has_polar() {
            (end[0], end[1]) = super::polar::polar_point(b, self.s.absolute, base[0], base[1]);
        }
        end
    }

    /// Performs the motion of group 1 (explicit or modal), if the block calls for one.
    pub(super) fn motion(&mut self, b: &Block) -> Result<(), GcodeError> {
        let explicit = b.g[1];
        let g0_axes =
            matches!(b.gcode(0), Some(100 | 280 | 300 | 520 | 920)) || b.gcode(8) == Some(431);
        let (m, col) = match explicit {
            Some((m, col)) => (m, col),
            None => {
                if !b.has_axis() || g0_axes {
                    return Ok(());
                }
                (self.s.motion, 1)
            }
        };
        self.loc.col = col;
        if !matches!(m, 52 | 53) {
            // Another motion ends a G5.2 block without G5.3: rs274 drops its points.
            self.s.nurbs = None;
        }
        match m {
            0 | 10 => self.straight(m, b),
            20 | 30 => self.arc(m, b),
            50 | 51 => self.spline(m, b),
            52 => self.nurbs_point(b),
            330 => self.spindle_synced_feed(b),
            331 => self.rigid_tap(b),
            760 => self.threading_cycle(b),
            700 | 710..=712 | 720..=722 => self.profile_cycle(m, b),
            53 => self.nurbs_end(b),
            382..=385 => self.probe(m, b),
            800 => {
                self.s.motion = 800;
                self.emit(CanonCmd::Comment(
                    "interpreter: motion mode set to none".into(),
                ))
            }
            730 | 810 | 820 | 830 | 840 | 850 | 860 | 880 | 890 => self.cycle(m, b),
            _ => Err(self.err(
                col,
                super::unsupported::g_code(m)
                    .map(str::to_string)
                    .unwrap_or_else(|| format!("G{} is not supported by hytask", fmt_g(m))),
            )),
        }
    }

    pub(super) fn straight(&mut self, m: u16, b: &Block) -> Result<(), GcodeError> {
        if m == 10 {
            match self.s.feed_mode {
                FeedMode::UnitsPerMinute | FeedMode::UnitsPerRevolution => {
                    if self.s.feed_rate == 0.0 {
                        return Err(self.err(self.loc.col, "Cannot do g1 with zero feed rate"));
                    }
                }
                FeedMode::InverseTime => {
                    if !b.has(b'f') {
                        return Err(
                            self.err(self.loc.col, "F word missing with inverse time g1 move")
                        );
                    }
                }
            }
        }
        self.s.motion = m;
        self.comp.arc_not_allowed = false;
        let end = self.find_ends(b);
        if self.comp.active() {
            if m == 10 && self.s.feed_mode == FeedMode::InverseTime {
                let mut from = self.s.pos;
                if self.comp.measures_from_program() {
                    from[..3].copy_from_slice(&self.comp.prog);
                }
                self.inverse_time_straight(&from, &end, b.get(b'f').unwrap_or(0.0))?;
            }
            return self.comp_straight(m, b, end);
        }
        if m == 0 {
            self.emit(CanonCmd::StraightTraverse(pose6(&end)))?;
        } else {
            if self.s.feed_mode == FeedMode::InverseTime {
                let from = self.s.pos;
                self.inverse_time_straight(&from, &end, b.get(b'f').unwrap_or(0.0))?;
            }
            self.emit(CanonCmd::StraightFeed(pose6(&end)))?;
        }
        self.s.pos = end;
        Ok(())
    }

    fn inverse_time_straight(
        &mut self,
        p: &[f64; 6],
        end: &[f64; 6],
        f: f64,
    ) -> Result<(), GcodeError> {
        let mut len =
            ((end[0] - p[0]).powi(2) + (end[1] - p[1]).powi(2) + (end[2] - p[2]).powi(2)).sqrt();
        if len == 0.0 {
            len = ((end[3] - p[3]).powi(2) + (end[4] - p[4]).powi(2) + (end[5] - p[5]).powi(2))
                .sqrt();
        }
        let rate = (len * f).max(0.1);
        self.s.feed_rate = rate;
        self.emit(CanonCmd::SetFeedRate(rate))
    }

    fn probe(&mut self, m: u16, b: &Block) -> Result<(), GcodeError> {
        self.refuse_with_comp(self.loc.col, "Cannot probe")?;
        if !b.has_axis() {
            return Err(self.err(
                self.loc.col,
                "X, Y, Z, A, B, and C words all missing with G38.2",
            ));
        }
        if self.s.feed_mode == FeedMode::InverseTime {
            return Err(self.err(self.loc.col, "Cannot probe in inverse time feed mode"));
        }
        if self.s.feed_mode == FeedMode::UnitsPerRevolution {
            return Err(self.err(self.loc.col, "Cannot probe with feed per rev mode"));
        }
        if self.s.feed_rate == 0.0 {
            return Err(self.err(self.loc.col, "Cannot probe with zero feed rate"));
        }
        let end = self.find_ends(b);

        // The probe starts where canon last put the tool: a tool length offset applied
        // since the last move has not moved it.
        let mut start = self.s.pos;
        let d = self.program_shift_of_tool(std::array::from_fn(|i| {
            self.s.tool_offset[i] - self.s.tlo_at_motion[i]
        }));
        for (v, d) in start.iter_mut().zip(d) {
            *v += d;
        }
        let kind = match m {
            382 => ProbeKind::TowardErr,
            383 => ProbeKind::Toward,
            384 => ProbeKind::AwayErr,
            _ => ProbeKind::Away,
        };
        self.s.motion = m;
        self.emit(CanonCmd::Probe { on: true })?;
        self.emit(CanonCmd::StraightProbe {
            end: pose6(&end),
            kind,
        })?;
        self.emit(CanonCmd::Probe { on: false })?;
        // Without a machine, rs274's canon reports the probe position as the programmed end
        // and leaves the tool 0.01 inch short of it, back toward the start (not tripped); the
        // interpreter then continues from there. hytask's dry run reproduces that model.
        let d = [end[0] - start[0], end[1] - start[1], end[2] - start[2]];
        let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        let mut stop = end;
        if len > 0.0 {
            let back = 0.01 * 25.4 / self.s.units.mm_per_unit();
            for i in 0..3 {
                stop[i] = end[i] - back * d[i] / len;
            }
        }
        let simulated = (end, stop);
        if self.live_probe {
            // The machine measures: the interpreter stops after this line and continues
            // with the result (`Interp::probe_result`), as LinuxCNC's does.
            self.pending_probe = Some(super::PendingProbe {
                kind,
                loc: self.loc.clone(),
                simulated,
            });
        } else {
            self.probe_result(false, &simulated.0, &simulated.1);
        }
        Ok(())
    }

    /// Takes the machine's result of the pending probe (LinuxCNC's `set_probe_data`): the
    /// position becomes where the machine stopped, #5061–#5069 the probed position and
    /// #5070 whether the probe tripped. Both poses are in the program frame and units in
    /// effect at the probe.
    pub(crate) fn probe_result(&mut self, tripped: bool, probed: &[f64; 6], stopped: &[f64; 6]) {
        self.pending_probe = None;
        for (i, v) in probed.iter().enumerate() {
            self.p.numbered[5061 + i] = *v;
        }
        for i in 6..9 {
            self.p.numbered[5061 + i] = 0.0;
        }
        self.p.numbered[5070] = if tripped { 1.0 } else { 0.0 };
        self.s.pos = *stopped;
        self.s.tlo_at_motion = self.s.tool_offset;
    }

    /// G20/G21: converts every stored length to the new units, as LinuxCNC does.
    pub(super) fn set_units(&mut self, g: u16) -> Result<(), GcodeError> {
        let new = if g == 200 {
            LengthUnits::Inches
        } else {
            LengthUnits::Millimeters
        };
        self.emit(CanonCmd::UseLengthUnits(new))?;
        if new == self.s.units {
            return Ok(());
        }
        let k = self.s.units.mm_per_unit() / new.mm_per_unit();
        self.s.units = new;
        for i in 0..3 {
            self.s.pos[i] *= k;
            self.s.g5x[i] *= k;
            self.s.g92[i] *= k;
        }
        self.comp.scale(k);
        // LinuxCNC 2.9 keeps the tool length offset's number unchanged across G20/G21 (it
        // is not converted until the next G43); hytask reproduces that.
        // Stored offsets (parameters) stay in machine units, as in LinuxCNC.
        Ok(())
    }

    /// G43 / G43.1 / G49.
    pub(super) fn tool_length(&mut self, g: u16, b: &Block) -> Result<(), GcodeError> {
        self.refuse_with_comp(self.loc.col, "Cannot change tool offset")?;
        let mut off: Pose = [0.0; 9];
        match g {
            430 => {
                let entry = match b.get(b'h') {
                    Some(h) => {
                        if h < 0.0 || h.fract() != 0.0 {
                            return Err(self.err(
                                b.col_of(b'h'),
                                "Negative H word tool length offset index used",
                            ));
                        }
                        let tool = h as u32;
                        if tool == 0 {
                            // H0 is rs274's pocket 0: the spindle's copy of the tool loaded
                            // by the last M6 (none: no offset).
                            self.s.spindle_tool.clone()
                        } else {
                            let slot = self.tools.slot_of(tool).ok_or_else(|| {
                                self.err(
                                    self.loc.col,
                                    format!(
                                        "Invalid tool number {tool} in G43 (not in the tool table)"
                                    ),
                                )
                            })?;
                            self.tools.at_slot(slot).cloned()
                        }
                    }
                    // In the block of an M6/M61 the change is still in progress and rs274
                    // reads the new tool's own table entry (its `toolchange_flag`); on later
                    // lines the spindle's copy, which M61 does not update.
                    None if self.s.synch_pending => self.tools.at_slot(self.s.tool_slot).cloned(),
                    None => self.s.spindle_tool.clone(),
                };
                if let Some(t) = entry {
                    for (i, (o, v)) in off.iter_mut().zip(t.offset.iter()).enumerate() {
                        *o = self.s.user_len(i, *v);
                    }
                }
            }
            431 => {
                // Axes not named keep their current offset.
                off = self.s.tool_offset;
                for (i, &c) in AXES.iter().enumerate() {
                    if let Some(v) = b.get(c) {
                        off[i] = v;
                    }
                }
            }
            432 => {
                // G43.2 H: the tool's offset is added to the active one (LinuxCNC 2.9). The
                // axis-word form is refused, as this rs274 refuses it.
                let axes = AXES.iter().any(|&c| b.has(c));
                let h = match (b.get(b'h'), axes) {
                    (Some(_), true) => {
                        return Err(
                            self.err(self.loc.col, "G43.2: Can not have both H and axis words")
                        )
                    }
                    (None, false) => {
                        return Err(
                            self.err(self.loc.col, "G43.2: No axes specified and H word missing")
                        )
                    }
                    (None, true) => return Err(self.err(
                        self.loc.col,
                        "G43.2 with axis words is not supported (as in rs274): use G43.2 H<tool>",
                    )),
                    (Some(h), false) => h,
                };
                if h < 0.0 || h.fract() != 0.0 {
                    return Err(self.err(
                        b.col_of(b'h'),
                        "Negative H word tool length offset index used",
                    ));
                }
                let tool = h as u32;
                // H0: the spindle's copy of the tool, as for G43 H0.
                let entry = if tool == 0 {
                    self.s.spindle_tool.clone()
                } else {
                    let slot = self.tools.slot_of(tool).ok_or_else(|| {
                        self.err(
                            self.loc.col,
                            format!("Requested tool {tool} not found in the tool table"),
                        )
                    })?;
                    self.tools.at_slot(slot).cloned()
                };
                off = self.s.tool_offset;
                if let Some(t) = entry {
                    for (i, (o, v)) in off.iter_mut().zip(t.offset.iter()).enumerate() {
                        *o += self.s.user_len(i, *v);
                    }
                }
            }
            _ => {}
        }
        self.s.tlo_active = g != 490;
        self.use_tool_offset(off)
    }

    /// Makes `off` the active tool length offset (the program position moves with it).
    fn use_tool_offset(&mut self, off: Pose) -> Result<(), GcodeError> {
        let d = self.program_shift_of_tool(std::array::from_fn(|i| self.s.tool_offset[i] - off[i]));
        for (p, d) in self.s.pos.iter_mut().zip(d) {
            *p += d;
        }
        self.s.tool_offset = off;
        self.emit(CanonCmd::UseToolLengthOffset(off))
    }

    /// M72's tool length offset: rs274 restores the mode only, as a plain `G43` (the
    /// spindle's tool) or `G49`, and only when one of the two is off.
    pub(super) fn restore_tool_offset_mode(&mut self, active: bool) -> Result<(), GcodeError> {
        let mut off: Pose = [0.0; 9];
        if active {
            if let Some(t) = &self.s.spindle_tool {
                for (i, (o, v)) in off.iter_mut().zip(t.offset.iter()).enumerate() {
                    *o = self.s.user_len(i, *v);
                }
            }
        }
        self.s.tlo_active = active;
        self.use_tool_offset(off)
    }

    pub(super) fn load_g5x(&self, index: u8) -> ([f64; 6], f64) {
        let base = g5x_base(index);
        let mut o = [0.0; 6];
        for (i, v) in o.iter_mut().enumerate() {
            *v = self.s.user_len(i, self.p.numbered[base + i]);
        }
        (o, self.p.numbered[base + 9])
    }

    /// Makes `index`'s stored offset the active one and reports it to canon.
    pub(super) fn activate_g5x(&mut self, index: u8) -> Result<(), GcodeError> {
        let (o, rot) = self.load_g5x(index);
        if rot != 0.0 || self.s.rotation != 0.0 {
            // The tool stays where it is on the machine; its program position is that
            // machine position seen through the new (rotated) frame.
            // (Without the tool length offset, which cancels: LinuxCNC's order.)
            let m = self.machine_of_program(&self.s.pos, false);
            self.s.g5x = o;
            self.s.rotation = rot;
            self.s.pos = self.program_of_machine(&m, false);
        } else {
            for (i, v) in o.iter().enumerate() {
                self.s.pos[i] += self.s.g5x[i] - v;
            }
            self.s.g5x = o;
            self.s.rotation = rot;
        }
        self.s.origin_index = index;
        self.p.numbered[params::COORD_INDEX] = f64::from(index);
        self.emit(CanonCmd::SetG5xOffset {
            index,
            offset: pose6(&o),
        })
    }

    /// G54…G59.3.
    pub(super) fn select_coord_system(&mut self, index: u8) -> Result<(), GcodeError> {
        self.refuse_with_comp(self.loc.col, "Cannot change coordinate systems")?;
        if index == self.s.origin_index {
            return self.emit(CanonCmd::Comment(
                "interpreter: continuing to use same coordinate system".into(),
            ));
        }
        self.activate_g5x(index)?;
        self.emit(CanonCmd::SetG92Offset(pose6(&self.s.g92)))?;
        self.emit(CanonCmd::SetXyRotation(self.s.rotation))
    }

    /// Group 0 codes other than G4 and G53.
    pub(super) fn non_modal(&mut self, g: u16, b: &Block) -> Result<(), GcodeError> {
        if matches!(g, 520 | 920) {
            self.refuse_with_comp(self.loc.col, "Cannot change axis offsets")?;
        }
        if matches!(g, 921..=923) && self.comp.side.is_some() {
            // rs274 2.9 ignores G92.1/G92.2/G92.3 while compensation is on (no call, the
            // offsets unchanged); so does hytask, to keep the same path.
            return Ok(());
        }
        match g {
            100 => self.g10(b),
            280 | 300 => self.go_home(g, b),
            281 | 301 => {
                self.refuse_with_comp(self.loc.col, "Cannot set the G28.1/G30.1 reference point")?;
                let base = if g == 281 {
                    params::G28_BASE
                } else {
                    params::G30_BASE
                };
                let m = if self.s.rotation != 0.0 {
                    self.machine_of_program(&self.s.pos, true)
                } else {
                    std::array::from_fn(|i| {
                        self.s.pos[i] + self.s.g5x[i] + self.s.g92[i] + self.s.tool_offset[i]
                    })
                };
                for (i, v) in m.iter().enumerate() {
                    self.p.numbered[base + i] = self.s.prog_len(i, *v);
                }
                Ok(())
            }
            520 => {
                // G52: local offset, kept in the G92 offset as LinuxCNC does.
                for (i, &c) in AXES.iter().enumerate() {
                    if let Some(v) = b.get(c) {
                        self.s.pos[i] += self.s.g92[i] - v;
                        self.s.g92[i] = v;
                        self.p.numbered[params::G92_BASE + i] = self.s.prog_len(i, v);
                    }
                }
                self.p.numbered[params::G92_ENABLED] = 1.0;
                self.emit(CanonCmd::SetG92Offset(pose6(&self.s.g92)))
            }
            920 => {
                if !b.has_axis() {
                    return Err(self.err(self.loc.col, "All axes missing with G92"));
                }
                for (i, &c) in AXES.iter().enumerate() {
                    if let Some(v) = b.get(c) {
                        let new = self.s.pos[i] + self.s.g92[i] - v;
                        self.s.pos[i] = v;
                        self.s.g92[i] = new;
                    }
                }
                for i in 0..6 {
                    self.p.numbered[params::G92_BASE + i] = self.s.prog_len(i, self.s.g92[i]);
                }
                self.p.numbered[params::G92_ENABLED] = 1.0;
                self.emit(CanonCmd::SetG92Offset(pose6(&self.s.g92)))
            }
            921 | 922 => self.g92_off(g == 921),
            923 => self.g92_apply_stored(),
            _ => Ok(()),
        }
    }

    /// G92.1 (`clear`: the stored offsets too) and G92.2: the G92 offsets off.
    pub(super) fn g92_off(&mut self, clear: bool) -> Result<(), GcodeError> {
        for i in 0..6 {
            self.s.pos[i] += self.s.g92[i];
            self.s.g92[i] = 0.0;
            if clear {
                self.p.numbered[params::G92_BASE + i] = 0.0;
            }
        }
        self.p.numbered[params::G92_ENABLED] = 0.0;
        self.emit(CanonCmd::SetG92Offset([0.0; 9]))
    }

    /// G92.3: the offsets stored in #5211… applied again.
    pub(super) fn g92_apply_stored(&mut self) -> Result<(), GcodeError> {
        for i in 0..6 {
            let v = self.s.user_len(i, self.p.numbered[params::G92_BASE + i]);
            self.s.pos[i] += self.s.g92[i] - v;
            self.s.g92[i] = v;
        }
        self.p.numbered[params::G92_ENABLED] = 1.0;
        self.emit(CanonCmd::SetG92Offset(pose6(&self.s.g92)))
    }

    fn go_home(&mut self, g: u16, b: &Block) -> Result<(), GcodeError> {
        self.refuse_with_comp(self.loc.col, "Cannot use G28 or G30")?;
        let base = if g == 280 {
            params::G28_BASE
        } else {
            params::G30_BASE
        };
        let mid = self.find_ends(b);
        self.emit(CanonCmd::StraightTraverse(pose6(&mid)))?;
        self.s.pos = mid;
        let any = b.has_axis();
        let mut end = mid;
        // The stored home is a machine position: seen through a rotated frame, X and Y of
        // the home both depend on the rotation (LinuxCNC then moves the named axes to it).
        let home_prog = (self.s.rotation != 0.0).then(|| {
            let h: [f64; 6] =
                std::array::from_fn(|i| self.s.user_len(i, self.p.numbered[base + i]));
            self.program_of_machine(&h, true)
        });
        for (i, &c) in AXES.iter().enumerate() {
            if !any || b.has(c) {
                end[i] = match home_prog {
                    Some(h) => h[i],
                    None => {
                        self.s.user_len(i, self.p.numbered[base + i])
                            - self.s.g5x[i]
                            - self.s.g92[i]
                            - self.s.tool_offset[i]
                    }
                };
            }
        }
        self.emit(CanonCmd::StraightTraverse(pose6(&end)))?;
        self.s.pos = end;
        Ok(())
    }

    fn g10(&mut self, b: &Block) -> Result<(), GcodeError> {
        let l = b.get(b'l').ok_or_else(|| {
            self.err(
                self.loc.col,
                "Line with G10 does not have L1, L10, L11, L2, or L20",
            )
        })?;
        let l = l.round() as i64;
        let p = b.get(b'p').ok_or_else(|| {
            self.err(
                self.loc.col,
                "P word (coordinate system or tool) missing with G10",
            )
        })?;
        if p.fract() != 0.0 {
            return Err(self.err(b.col_of(b'p'), "P value not an integer with G10"));
        }
        match l {
            2 | 20 => {
                if !(0.0..=9.0).contains(&p) {
                    return Err(self.err(b.col_of(b'p'), "P value out of range with G10 L2"));
                }
                let index = if p == 0.0 {
                    self.s.origin_index
                } else {
                    p as u8
                };
                if l == 20 && b.has(b'r') {
                    return Err(self.err(b.col_of(b'r'), "R not allowed in G10 L20"));
                }
                if index == self.s.origin_index {
                    self.refuse_with_comp(
                        self.loc.col,
                        "Cannot change the active coordinate system",
                    )?;
                }
                let base = g5x_base(index);
                let target_rot = self.p.numbered[base + 9];
                let rotated = l == 20 && (target_rot != 0.0 || self.s.rotation != 0.0);
                for (i, &c) in AXES.iter().enumerate() {
                    if let Some(v) = b.get(c) {
                        let prog = if l == 2 {
                            v
                        } else {
                            self.s.pos[i] + self.s.g5x[i] - v
                        };
                        self.p.numbered[base + i] = self.s.prog_len(i, prog);
                    }
                }
                if rotated && (b.has(b'x') || b.has(b'y')) {
                    // L20 with a rotation: the origin is where the tool is on the machine
                    // less the wanted position turned by the system's rotation; X and Y
                    // both change even if only one is named, as in LinuxCNC.
                    let m = self.machine_of_program(&self.s.pos, false);
                    let want = |c: u8, i: usize| b.get(c).unwrap_or(self.s.pos[i]) + self.s.g92[i];
                    let (wx, wy) = frame::rotate(want(b'x', 0), want(b'y', 1), target_rot);
                    self.p.numbered[base] = self.s.prog_len(0, m[0] - wx);
                    self.p.numbered[base + 1] = self.s.prog_len(1, m[1] - wy);
                }
                if let Some(r) = b.get(b'r') {
                    self.p.numbered[base + 9] = r;
                }
                if index == self.s.origin_index {
                    self.activate_g5x(index)?;
                    self.emit(CanonCmd::SetXyRotation(self.s.rotation))
                } else {
                    self.emit(CanonCmd::Comment(
                        "interpreter: setting coordinate system origin".into(),
                    ))
                }
            }
            1 | 10 | 11 => self.g10_tool(l, p, b),
            _ => Err(self.err(
                b.col_of(b'l'),
                "Line with G10 does not have L1, L10, L11, L2, or L20",
            )),
        }
    }
}

fn fmt_g(m: u16) -> String {
    if m.is_multiple_of(10) {
        format!("{}", m / 10)
    } else {
        format!("{}.{}", m / 10, m % 10)
    }
}

impl super::Settings {
    /// A length in machine units (tool table, stored offsets) in program units, rounded as
    /// rs274's `USER_TO_PROGRAM_LEN`: divided by the machine's units per mm, then by the
    /// program's mm per unit. rs274's standalone canon gives 0.03937007874016 per mm for an
    /// inch machine (not 1/25.4), which moves the last bits of converted values.
    pub(crate) fn user_to_prog(&self, v: f64) -> f64 {
        v / ext_units_per_mm(self.machine_units) / self.units.mm_per_unit()
    }

    /// Axis `i`'s (X Y Z A B C [U V W]) stored value in program units: lengths converted
    /// as [`Self::user_to_prog`], angles (A B C) as they are.
    pub(crate) fn user_len(&self, i: usize, v: f64) -> f64 {
        if (3..6).contains(&i) {
            v
        } else {
            self.user_to_prog(v)
        }
    }

    /// The inverse of [`Self::user_len`] (rs274's `PROGRAM_TO_USER_LEN` for lengths).
    pub(crate) fn prog_len(&self, i: usize, v: f64) -> f64 {
        if (3..6).contains(&i) {
            v
        } else {
            v * self.units.mm_per_unit() * ext_units_per_mm(self.machine_units)
        }
    }

    /// rs274's `PROGRAM_TO_USER_LEN` and `USER_TO_PROGRAM_LEN` for the units now in force,
    /// as plain functions (to use while the tool table is borrowed).
    pub(crate) fn unit_conversions(&self) -> (impl Fn(f64) -> f64, impl Fn(f64) -> f64) {
        let (pm, ext) = (
            self.units.mm_per_unit(),
            ext_units_per_mm(self.machine_units),
        );
        (move |v: f64| v * pm * ext, move |v: f64| v / ext / pm)
    }
}

/// rs274's `GET_EXTERNAL_LENGTH_UNITS` (machine units per mm) for the machine units.
fn ext_units_per_mm(u: crate::gcode::canon::LengthUnits) -> f64 {
    match u {
        crate::gcode::canon::LengthUnits::Inches => 0.039_370_078_740_16,
        crate::gcode::canon::LengthUnits::Millimeters => 1.0,
    }
}
