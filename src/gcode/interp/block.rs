//! One block, executed in LinuxCNC's order of execution (comments, feed mode, F, S, T,
//! I/O, M6, spindle, coolant, overrides, user M codes, dwell, plane, units, cutter
//! compensation, tool length, coordinate system, path mode, distance mode, retract mode,
//! G10/G28/G30/G92, motion, stop), after the same consistency checks.

use super::Interp;
use crate::gcode::canon::{CanonCmd, FeedMode, MotionControl, Plane};
use crate::gcode::modal::Block;
use crate::gcode::parser::Line;
use crate::gcode::GcodeError;

/// Group-0 codes that consume axis words.
fn g0_uses_axes(g: u16) -> bool {
    matches!(g, 100 | 280 | 300 | 520 | 920)
}

impl Interp<'_> {
    pub(super) fn exec_block(&mut self, b: &Block, line: &Line) -> Result<(), GcodeError> {
        self.check_block(b)?;
        // 1. comments (only the last comment of a line counts, as in LinuxCNC)
        if let Some(c) = line.comments.last() {
            self.loc.col = c.col;
            self.comment(&c.text)?;
        }
        // 2. spindle mode (G96/G97): rs274 sets it before the feed mode
        if let Some((g, col)) = b.g[14] {
            self.loc.col = col;
            self.spindle_mode(g, b)?;
        }
        // 2a. feed mode
        if let Some((g, col)) = b.g[5] {
            self.loc.col = col;
            self.set_feed_mode(g)?;
        }
        // 3. feed rate
        if let Some(f) = b.get(b'f') {
            self.loc.col = b.col_of(b'f');
            if f < 0.0 {
                return Err(self.err(self.loc.col, "Negative F word used"));
            }
            if self.s.feed_mode != FeedMode::InverseTime {
                self.s.feed_rate = f;
                self.emit(CanonCmd::SetFeedRate(f))?;
            }
        }
        // 4. spindle speed
        if let Some(sv) = b.get(b's') {
            self.loc.col = b.col_of(b's');
            if sv < 0.0 {
                return Err(self.err(self.loc.col, "Negative spindle speed used"));
            }
            self.s.speed = sv;
            self.emit(CanonCmd::SetSpindleSpeed(sv))?;
        }
        // 5. select tool
        if let Some(t) = b.get(b't') {
            self.loc.col = b.col_of(b't');
            self.select_tool(t)?;
        }
        // 6.–12. M codes
        self.exec_mcodes_before_motion(b)?;
        // 13. dwell
        if b.gcode(0) == Some(40) {
            self.loc.col = b.g[0].map(|x| x.1).unwrap_or(1);
            let p = b
                .get(b'p')
                .ok_or_else(|| self.err(self.loc.col, "Dwell time missing with g4"))?;
            if p < 0.0 {
                return Err(self.err(self.loc.col, "Negative dwell time"));
            }
            self.emit(CanonCmd::Dwell(p))?;
        }
        // 14. plane
        if let Some((g, col)) = b.g[2] {
            self.loc.col = col;
            let plane = match g {
                170 => Plane::Xy,
                180 => Plane::Xz,
                190 => Plane::Yz,
                171 => Plane::Uv,
                181 => Plane::Uw,
                _ => Plane::Vw,
            };
            if plane != self.s.plane {
                self.refuse_with_comp(col, "Cannot change planes")?;
            }
            self.s.plane = plane;
            self.emit(CanonCmd::SelectPlane(plane))?;
        }
        // 15. units
        if let Some((g, col)) = b.g[6] {
            self.loc.col = col;
            self.set_units(g)?;
        }
        // 15a. lathe diameter/radius mode
        if let Some((g, col)) = b.g[15] {
            self.loc.col = col;
            self.lathe_mode(g)?;
        }
        // 16. cutter compensation
        if let Some((g, col)) = b.g[7] {
            self.loc.col = col;
            self.cutter_comp(g, b)?;
        }
        // 17. tool length offset
        if let Some((g, col)) = b.g[8] {
            self.loc.col = col;
            self.tool_length(g, b)?;
        }
        // 18. coordinate system
        if let Some((g, col)) = b.g[12] {
            self.loc.col = col;
            let index = match g {
                540..=590 => ((g - 540) / 10 + 1) as u8,
                591 => 7,
                592 => 8,
                _ => 9,
            };
            self.select_coord_system(index)?;
        }
        // 19. path control
        if let Some((g, col)) = b.g[13] {
            self.loc.col = col;
            self.refuse_with_comp(col, "Cannot change control mode")?;
            self.path_control(g, b)?;
        }
        // 20. distance modes
        if let Some((g, _)) = b.g[3] {
            let abs = g == 900;
            if abs != self.s.absolute {
                self.s.absolute = abs;
                self.emit(CanonCmd::Comment(
                    if abs {
                        "interpreter: distance mode changed to absolute"
                    } else {
                        "interpreter: distance mode changed to incremental"
                    }
                    .into(),
                ))?;
            }
        }
        if let Some((g, _)) = b.g[4] {
            let abs = g == 901;
            if abs != self.s.ijk_absolute {
                self.s.ijk_absolute = abs;
                self.emit(CanonCmd::Comment(
                    if abs {
                        "interpreter: IJK distance mode changed to absolute"
                    } else {
                        "interpreter: IJK distance mode changed to incremental"
                    }
                    .into(),
                ))?;
            }
        }
        // 21. retract mode
        if let Some((g, _)) = b.g[10] {
            self.set_retract_mode(g == 980)?;
        }
        // 22. G10 / G28 / G30 / G92
        if let Some((g, col)) = b.g[0] {
            if g != 40 && g != 530 {
                self.loc.col = col;
                self.non_modal(g, b)?;
            }
        }
        // 23. motion
        self.motion(b)?;
        // 24. stop
        if let Some((m, col)) = b.m[4] {
            self.loc.col = col;
            if m == 99 {
                if let Some(msg) = self.m99_misplaced() {
                    return Err(self.err(col, msg));
                }
            }
            self.stop(m)?;
        }
        Ok(())
    }

    /// LinuxCNC's block checks that do not depend on execution (check_g_codes,
    /// check_m_codes, check_other_codes).
    pub(super) fn check_block(&self, b: &Block) -> Result<(), GcodeError> {
        // An unsupported feature says its name before any word check can blame its words.
        for grp in [1, 7, 8, 15] {
            if let Some((g, col)) = b.g[grp] {
                if let Some(what) = super::unsupported::g_code(g) {
                    return Err(self.err(col, what));
                }
            }
        }
        if let Some((m, col)) = b.m[10] {
            if !self.opts.user_mcodes.contains(&m) {
                return Err(self.err(
                    col,
                    format!("Unknown m code used: M{m} (not a user M code of this machine)"),
                ));
            }
        }
        let g0 = b.gcode(0);
        let g1 = b.gcode(1);
        self.check_polar(b, g0.is_some_and(g0_uses_axes) || b.gcode(8) == Some(431))?;
        let axis = b.has_axis();
        let col = |c: u8| b.col_of(c);
        let first_axis_col = b"xyzabc"
            .iter()
            .find(|&&c| b.has(c))
            .map(|&c| col(c))
            .unwrap_or(1);
        if let Some(g) = g0 {
            if g0_uses_axes(g) && g1.is_some() && axis {
                return Err(self.err(
                    first_axis_col,
                    "Cannot use two g codes that both use axis values",
                ));
            }
            if g == 530 {
                let m = g1.unwrap_or(self.s.motion);
                if m != 0 && m != 10 {
                    return Err(self.err(
                        b.g[0].map(|x| x.1).unwrap_or(1),
                        "Must use G0 or G1 with G53",
                    ));
                }
                let incr = match b.gcode(3) {
                    Some(d) => d == 910,
                    None => !self.s.absolute,
                };
                if incr {
                    return Err(self.err(
                        b.g[0].map(|x| x.1).unwrap_or(1),
                        "Cannot use g53 incremental",
                    ));
                }
            }
        }
        if axis && !g0.is_some_and(g0_uses_axes) && b.gcode(8) != Some(431) {
            match g1 {
                Some(800) => {
                    return Err(self.err(first_axis_col, "Cannot use axis values with G80"))
                }
                None if self.s.motion == 800 => {
                    return Err(self.err(
                        first_axis_col,
                        "Cannot use axis values without a g code that uses them",
                    ))
                }
                _ => {}
            }
        }
        let motion = g1.unwrap_or(self.s.motion);
        // G2/G3 is modal: a line with only coordinates and I/J/K or R after an arc is the
        // next arc (as CAM posts write arcs), when its axis words make a move.
        let arc = match g1 {
            Some(g) => g == 20 || g == 30,
            None => {
                matches!(self.s.motion, 20 | 30)
                    && axis
                    && !g0.is_some_and(g0_uses_axes)
                    && b.gcode(8) != Some(431)
            }
        };
        let cycle = matches!(g1, Some(730 | 810..=890));
        // G5/G5.1 are not modal: only an explicit one uses I, J (and G5 P, Q).
        let spline = matches!(g1, Some(50 | 51));
        let g5 = g1 == Some(50);
        let g10 = g0 == Some(100);
        let user_m = b.m[10].is_some();
        super::threading::check_sync_words(b, motion).map_err(|(c, m)| self.err(c, m))?;
        // Lathe words: G33/G33.1 K (and G33.1 I), M19 R P Q.
        let synced = matches!(motion, 330 | 331) && (g1.is_some() || axis);
        let tap = motion == 331 && (g1.is_some() || axis);
        let m19 = b.mcode(7) == Some(19);
        let g76 = motion == 760 && (g1.is_some() || axis);
        // G70/G71/G72 (and .1): Q profile, D/E/P (G70) or D/I/R (G71, G72).
        let g7x = matches!(g1, Some(700 | 710..=712 | 720..=722));
        if !b"ijkredhpql".iter().any(|&c| b.has(c)) {
            return Ok(());
        }
        let p_ok = arc
            || g5
            || matches!(motion, 52 | 53)
            || g0 == Some(40)
            || g10
            || b.gcode(13) == Some(640)
            || matches!(motion, 820 | 840 | 860 | 880 | 890) && (cycle || axis)
            || matches!(b.mcode(9), Some(50..=53))
            || matches!(b.mcode(5), Some(62..=66))
            || user_m
            || m19
            || g76
            || g7x;
        let q_ok = g10
            || g5
            || b.gcode(13) == Some(640)
            || matches!(motion, 730 | 830) && (cycle || axis)
            || matches!(b.mcode(5), Some(66..=68))
            || b.mcode(6) == Some(61)
            || user_m
            || m19
            || g76
            || g7x;
        let l_ok = matches!(motion, 52 | 53)
            || g10
            || cycle
            || (matches!(motion, 730 | 810..=890) && axis)
            || b.mcode(5) == Some(66)
            || g76
            || matches!(b.gcode(7), Some(411 | 421));
        let checks: [(u8, bool, &str); 10] = [
            (
                b'i',
                arc || spline || g10 || motion == 870 || tap || g76 || g7x,
                "I word with no G2, G3, G5, G5.1, G10, G33.1, G76, or G87 to use it",
            ),
            (
                b'j',
                arc || spline || g10 || motion == 870 || g76,
                "J word with no G2, G3, G5, G5.1, G10, G76 or G87 to use it",
            ),
            (
                b'k',
                arc || g10 || motion == 870 || synced || g76,
                "K word with no G2, G3, G33, G33.1, G76, or G87 to use it",
            ),
            (
                b'r',
                arc || g10 || cycle || ((810..=890).contains(&motion) && b.has_axis()) || m19 || g76 || g7x,
                "R word with no G code that uses it",
            ),
            (
                b'e',
                matches!(b.mcode(5), Some(66..=68)) || g76 || g7x,
                "E word with no G70, G76, M66, M67 or M68 to use it",
            ),
            (
                b'd',
                b.gcode(14) == Some(960) || matches!(b.gcode(7), Some(410 | 411 | 420 | 421)) || g7x,
                "D word with no G41, G41.1, G42, G42.1 or G96 to use it",
            ),
            (
                b'h',
                matches!(b.gcode(8), Some(430 | 432)) || g10 || g76,
                "H word with no G43 or G43.2 to use it",
            ),
            (b'p', p_ok, "P word with no G2 G3 G4 G10 G64 G5 G5.2 G76 G82 G86 G88 G89 or M50 M51 M52 M53 M62 M63 M64 M65 M66 M98 or user M code to use it"),
            (
                b'q',
                q_ok,
                "Q word with no G5, G10, G64, G73, G83, M66, M67, M68, M61 or user M code that uses it",
            ),
            (b'l', l_ok, "L word with no G10, cycle, or M66 to use it"),
        ];
        for (c, ok, msg) in checks {
            if b.has(c) && !ok {
                return Err(self.err(col(c), msg));
            }
        }
        Ok(())
    }

    fn comment(&mut self, text: &str) -> Result<(), GcodeError> {
        let lower = text.trim_start().to_ascii_lowercase();
        let skip = text.len() - text.trim_start().len();
        if lower.starts_with("abort,") {
            // rs274 stops the program with the comment's text as the error.
            let body = self.substitute(&text[skip + 6..]);
            return Err(self.err(self.loc.col, format!("Program aborted: {}", body.trim())));
        }
        if lower.starts_with("msg,") {
            let body = &text[skip + 4..];
            return self.emit(CanonCmd::Message(body.to_string()));
        }
        if lower.starts_with("debug,") {
            // substituted (and its parameter reads checked) even when #5599 silences it
            let body = self.substitute(&text[skip + 6..]);
            if self.p.numbered[crate::gcode::params::DEBUG_FLAG] > 0.0 {
                return self.emit(CanonCmd::Message(body));
            }
            return Ok(());
        }
        if lower.starts_with("py,") {
            // LinuxCNC's `(py,…)`: the statement as written, after the `py,`
            return self.py_exec(&text[skip + 3..]);
        }
        if lower.starts_with("print,") {
            let body = self.substitute(&text[skip + 6..]);
            return self.emit(CanonCmd::Print(body));
        }
        if let Some(cmd) = self.log_comment(&lower, &text[skip..]) {
            return self.emit(cmd);
        }
        // rs274 drops the spaces a comment starts with (`( a )` is COMMENT("a ")), and
        // an empty `()` altogether (`( )` is COMMENT("")).
        if text.is_empty() {
            return Ok(());
        }
        self.emit(CanonCmd::Comment(text[skip..].to_string()))
    }

    /// LinuxCNC's log comments (`lower` is `text` in lower case): the file name of
    /// LOGOPEN/LOGAPPEND as written, LOG's text with its parameters substituted; LOGCLOSE
    /// only alone (with words after it, it is a comment, as in rs274).
    fn log_comment(&self, lower: &str, text: &str) -> Option<CanonCmd> {
        use crate::gcode::canon::LogKind;
        let (kind, text) = if lower.starts_with("logopen,") {
            (LogKind::Open, text[8..].to_string())
        } else if lower.starts_with("logappend,") {
            (LogKind::Append, text[10..].to_string())
        } else if lower.starts_with("log,") {
            (LogKind::Write, self.substitute(&text[4..]))
        } else if lower == "logclose" {
            (LogKind::Close, String::new())
        } else {
            return None;
        };
        Some(CanonCmd::Log { kind, text })
    }

    /// G98 (`old_z`) or G99.
    pub(super) fn set_retract_mode(&mut self, old_z: bool) -> Result<(), GcodeError> {
        self.s.retract_old_z = old_z;
        self.emit(CanonCmd::Comment(
            if old_z {
                "interpreter: retract mode set to old_z"
            } else {
                "interpreter: retract mode set to r_plane"
            }
            .into(),
        ))
    }

    pub(super) fn set_feed_mode(&mut self, g: u16) -> Result<(), GcodeError> {
        let (mode, text) = match g {
            930 => (
                FeedMode::InverseTime,
                "interpreter: feed mode set to inverse time",
            ),
            950 => (
                FeedMode::UnitsPerRevolution,
                "interpreter: feed mode set to units per revolution",
            ),
            _ => (
                FeedMode::UnitsPerMinute,
                "interpreter: feed mode set to units per minute",
            ),
        };
        self.emit(CanonCmd::Comment(text.into()))?;
        self.emit(CanonCmd::SetFeedMode(mode))?;
        self.s.feed_mode = mode;
        if mode != FeedMode::InverseTime {
            self.s.feed_rate = 0.0;
            self.emit(CanonCmd::SetFeedRate(0.0))?;
        }
        Ok(())
    }

    fn spindle_mode(&mut self, g: u16, b: &Block) -> Result<(), GcodeError> {
        if g == 960 {
            if !b.has(b's') {
                return Err(self.err(self.loc.col, "S word missing with G96"));
            }
            self.s.css = true;
            // Without D the speed is unlimited (rs274 hands canon 1e30).
            self.s.css_max = b.get(b'd').map_or(1e30, f64::abs);
        } else {
            self.s.css = false;
            self.s.css_max = 0.0;
        }
        self.emit(CanonCmd::SetSpindleMode {
            css_max_rpm: self.s.css_max,
        })
    }

    fn path_control(&mut self, g: u16, b: &Block) -> Result<(), GcodeError> {
        match g {
            610 => {
                self.s.control = MotionControl::ExactPath;
                self.emit(CanonCmd::SetMotionControl(MotionControl::ExactPath))
            }
            611 => {
                self.s.control = MotionControl::ExactStop;
                self.emit(CanonCmd::SetMotionControl(MotionControl::ExactStop))
            }
            _ => {
                // LinuxCNC treats negative tolerances as 0 (no tolerance).
                let p = b.get(b'p').unwrap_or(0.0).max(0.0);
                let q = b.get(b'q').unwrap_or(p).max(0.0);
                self.s.control = MotionControl::Continuous { tolerance: p };
                self.s.naive_tol = q;
                self.emit(CanonCmd::SetMotionControl(self.s.control))?;
                self.emit(CanonCmd::SetNaivecamTolerance(q))
            }
        }
    }
}
