//! Text form of canonical commands, byte-compatible with `rs274 -g`.
//!
//! The trace format exists so a hytask run can be diffed line by line against LinuxCNC's
//! own interpreter. Numbers are printed like C's `%.4f` (correct rounding, `-0.0000` kept),
//! through a fast path because the formatter is on the throughput-critical path of
//! `hytask gcode canon`.

use super::canon::{
    Canon, CanonCmd, FeedMode, LengthUnits, MotionControl, OverrideKind, Plane, Pose, SpindleDir,
};
use std::fmt::Write as _;

/// Appends `v` formatted like C's `printf("%.4f", v)`.
pub fn push_f4(out: &mut String, v: f64) {
    // Fast path: exact when v*1e4 is far from a rounding tie and fits an i64.
    let scaled = v * 10_000.0;
    if v.is_finite() && scaled.abs() < 1e15 {
        let r = scaled.round();
        let frac = (scaled - scaled.trunc()).abs();
        if (frac - 0.5).abs() > 1e-6 {
            let neg = v.is_sign_negative();
            let n = r.abs() as u64;
            if neg {
                out.push('-');
            }
            let int = n / 10_000;
            let dec = n % 10_000;
            let mut buf = itoa_buf(int);
            out.push_str(buf.as_str());
            out.push('.');
            buf = itoa_buf(dec + 10_000);
            out.push_str(&buf.as_str()[1..]);
            return;
        }
    }
    let _ = write!(out, "{v:.4}");
}

/// Appends `v` formatted like C's `printf("%.6f", v)` (slow path is fine: rare calls).
pub fn push_f6(out: &mut String, v: f64) {
    let _ = write!(out, "{v:.6}");
}

/// A small stack buffer for integer formatting without allocation.
struct ItoaBuf {
    bytes: [u8; 24],
    start: usize,
}

impl ItoaBuf {
    fn as_str(&self) -> &str {
        // Only ASCII digits are ever written.
        std::str::from_utf8(&self.bytes[self.start..]).unwrap_or("")
    }
}

fn itoa_buf(mut n: u64) -> ItoaBuf {
    let mut b = ItoaBuf {
        bytes: [0; 24],
        start: 24,
    };
    loop {
        b.start -= 1;
        b.bytes[b.start] = b'0' + (n % 10) as u8;
        n /= 10;
        if n == 0 {
            break;
        }
    }
    b
}

fn push_list(out: &mut String, vals: &[f64]) {
    for (i, v) in vals.iter().enumerate() {
        if i > 0 {
            out.push_str(", ");
        }
        push_f4(out, *v);
    }
}

fn push_space_list(out: &mut String, vals: &[f64]) {
    for (i, v) in vals.iter().enumerate() {
        if i > 0 {
            out.push(' ');
        }
        push_f4(out, *v);
    }
}

fn plane_name(p: Plane) -> &'static str {
    match p {
        Plane::Xy => "CANON_PLANE_XY",
        Plane::Xz => "CANON_PLANE_XZ",
        Plane::Yz => "CANON_PLANE_YZ",
        // rs274's standalone canon prints the UVW planes as unknown.
        Plane::Uv | Plane::Uw | Plane::Vw => "CANON_PLANE_UNKNOWN",
    }
}

fn six(p: &Pose) -> &[f64] {
    &p[..6]
}

/// Appends the call text of `cmd` (no sequence prefix, no newline). Returns false when the
/// command has no `rs274 -g` text (`WAIT` is silent in rs274's canon) so nothing was written.
pub fn push_call(out: &mut String, cmd: &CanonCmd) -> bool {
    match cmd {
        CanonCmd::UseLengthUnits(u) => out.push_str(match u {
            LengthUnits::Millimeters => "USE_LENGTH_UNITS(CANON_UNITS_MM)",
            LengthUnits::Inches => "USE_LENGTH_UNITS(CANON_UNITS_INCHES)",
        }),
        CanonCmd::SetG5xOffset { index, offset } => {
            let _ = write!(out, "SET_G5X_OFFSET({index}, ");
            push_list(out, six(offset));
            out.push(')');
        }
        CanonCmd::SetG92Offset(p) => {
            out.push_str("SET_G92_OFFSET(");
            push_list(out, six(p));
            out.push(')');
        }
        CanonCmd::SetXyRotation(r) => {
            out.push_str("SET_XY_ROTATION(");
            push_f4(out, *r);
            out.push(')');
        }
        CanonCmd::UseToolLengthOffset(p) => {
            out.push_str("USE_TOOL_LENGTH_OFFSET(");
            push_space_list(out, &p[0..3]);
            out.push_str(", ");
            push_space_list(out, &p[3..6]);
            out.push_str(", ");
            push_space_list(out, &p[6..9]);
            out.push(')');
        }
        CanonCmd::SelectPlane(p) => {
            let _ = write!(out, "SELECT_PLANE({})", plane_name(*p));
        }
        CanonCmd::SetFeedRate(f) => {
            out.push_str("SET_FEED_RATE(");
            push_f4(out, *f);
            out.push(')');
        }
        CanonCmd::SetFeedMode(m) => out.push_str(match m {
            FeedMode::UnitsPerRevolution => "SET_FEED_MODE(0, 1)",
            // LinuxCNC handles inverse time in the interpreter; canon sees units/minute.
            FeedMode::UnitsPerMinute | FeedMode::InverseTime => "SET_FEED_MODE(0, 0)",
        }),
        CanonCmd::SetMotionControl(m) => match m {
            MotionControl::ExactStop => out.push_str("SET_MOTION_CONTROL_MODE(CANON_EXACT_STOP)"),
            MotionControl::ExactPath => out.push_str("SET_MOTION_CONTROL_MODE(CANON_EXACT_PATH)"),
            MotionControl::Continuous { tolerance } => {
                out.push_str("SET_MOTION_CONTROL_MODE(CANON_CONTINUOUS, ");
                push_f6(out, *tolerance);
                out.push(')');
            }
        },
        CanonCmd::SetNaivecamTolerance(t) => {
            out.push_str("SET_NAIVECAM_TOLERANCE(");
            push_f4(out, *t);
            out.push(')');
        }
        CanonCmd::StraightTraverse(p) => {
            out.push_str("STRAIGHT_TRAVERSE(");
            push_list(out, six(p));
            out.push(')');
        }
        CanonCmd::StraightFeed(p) => {
            out.push_str("STRAIGHT_FEED(");
            push_list(out, six(p));
            out.push(')');
        }
        CanonCmd::ArcFeed {
            first_end,
            second_end,
            first_center,
            second_center,
            rotation,
            axis_end,
            end,
            ..
        } => {
            out.push_str("ARC_FEED(");
            push_list(
                out,
                &[*first_end, *second_end, *first_center, *second_center],
            );
            let _ = write!(out, ", {rotation}, ");
            push_list(out, &[*axis_end, end[3], end[4], end[5]]);
            out.push(')');
        }
        CanonCmd::Dwell(s) => {
            out.push_str("DWELL(");
            push_f4(out, *s);
            out.push(')');
        }
        CanonCmd::SetSpindleSpeed(s) => {
            out.push_str("SET_SPINDLE_SPEED(0, ");
            push_f4(out, *s);
            out.push(')');
        }
        CanonCmd::StartSpindle(d) => out.push_str(match d {
            SpindleDir::Clockwise => "START_SPINDLE_CLOCKWISE(0)",
            SpindleDir::CounterClockwise => "START_SPINDLE_COUNTERCLOCKWISE(0)",
        }),
        CanonCmd::StopSpindle => out.push_str("STOP_SPINDLE_TURNING(0)"),
        CanonCmd::MistOn => out.push_str("MIST_ON()"),
        CanonCmd::MistOff => out.push_str("MIST_OFF()"),
        CanonCmd::FloodOn => out.push_str("FLOOD_ON()"),
        CanonCmd::FloodOff => out.push_str("FLOOD_OFF()"),
        CanonCmd::SelectTool(t) => {
            let _ = write!(out, "SELECT_TOOL({t})");
        }
        CanonCmd::StartChange => out.push_str("START_CHANGE()"),
        CanonCmd::ChangeTool(s) => {
            let _ = write!(out, "CHANGE_TOOL({s})");
        }
        CanonCmd::ChangeToolNumber(t) => {
            let _ = write!(out, "CHANGE_TOOL_NUMBER({t})");
        }
        CanonCmd::DigitalOutput { index, on, synced } => {
            let name = match (synced, on) {
                (true, true) => "SET_MOTION_OUTPUT_BIT",
                (true, false) => "CLEAR_MOTION_OUTPUT_BIT",
                (false, true) => "SET_AUX_OUTPUT_BIT",
                (false, false) => "CLEAR_AUX_OUTPUT_BIT",
            };
            let _ = write!(out, "{name}({index})");
        }
        CanonCmd::AnalogOutput {
            index,
            value,
            synced,
        } => {
            let name = if *synced {
                "SET_MOTION_OUTPUT_VALUE"
            } else {
                "SET_AUX_OUTPUT_VALUE"
            };
            let _ = write!(out, "{name}({index},");
            push_f6(out, *value);
            out.push(')');
        }
        CanonCmd::Wait { .. } => return false,
        CanonCmd::StraightProbe { end, .. } => {
            out.push_str("STRAIGHT_PROBE(");
            push_list(out, six(end));
            out.push(')');
        }
        CanonCmd::OverrideEnable { which, on } => {
            let pre = if *on { "ENABLE_" } else { "DISABLE_" };
            let what = match which {
                OverrideKind::Feed | OverrideKind::FeedAndSpindle => "FEED_OVERRIDE()",
                OverrideKind::Spindle => "SPEED_OVERRIDE(0)",
                OverrideKind::AdaptiveFeed => "ADAPTIVE_FEED()",
                OverrideKind::FeedHold => "FEED_HOLD()",
            };
            out.push_str(pre);
            out.push_str(what);
        }
        CanonCmd::Message(m) => {
            let _ = write!(out, "MESSAGE(\"{m}\")");
        }
        CanonCmd::Print(m) => out.push_str(m),
        CanonCmd::Comment(m) => {
            let _ = write!(out, "COMMENT(\"{m}\")");
        }
        CanonCmd::ProgramStop => out.push_str("PROGRAM_STOP()"),
        CanonCmd::OptionalProgramStop => out.push_str("OPTIONAL_PROGRAM_STOP()"),
        CanonCmd::ProgramEnd => out.push_str("PROGRAM_END()"),
        CanonCmd::PalletShuttle => out.push_str("PALLET_SHUTTLE()"),
        CanonCmd::OnReset => out.push_str("ON_RESET()"),
        CanonCmd::SetFeedReference => out.push_str("SET_FEED_REFERENCE(CANON_XYZ)"),
        CanonCmd::SetSpindleMode { css_max_rpm } => {
            out.push_str("SET_SPINDLE_MODE(0 ");
            push_f4(out, *css_max_rpm);
            out.push(')');
        }
        CanonCmd::Probe { on } => out.push_str(if *on {
            "TURN_PROBE_ON()"
        } else {
            "TURN_PROBE_OFF()"
        }),
        CanonCmd::SetToolTableEntry {
            pocket,
            tool,
            offset,
            front_angle,
            back_angle,
            orientation,
            ..
        } => {
            // rs274 prints no diameter in this call.
            let _ = write!(out, "SET_TOOL_TABLE_ENTRY({pocket}, {tool}, ");
            push_space_list(out, offset);
            out.push_str(", ");
            push_list(out, &[*front_angle, *back_angle]);
            let _ = write!(out, ", {orientation})");
        }
        CanonCmd::Finish => out.push_str("FINISH()"),
        CanonCmd::UserMcode { code, p, q } => {
            let _ = write!(out, "USER_MCODE({code}, ");
            push_list(out, &[*p, *q]);
            out.push(')');
        }
    }
    true
}

/// Writes a whole trace in `rs274 -g` layout: `%5d N..... CALL` per command, numbered from
/// one. The `N.....` column is printed as rs274 prints it for blocks without an N word; the
/// differential test strips the prefix columns before comparing (see
/// tests/gcode/DIFFERENCES.md). `PRINT` lines are bare text, without number, as rs274 writes them.
pub fn write_trace(out: &mut String, canon: &[Canon]) {
    let mut seq: u64 = 0;
    for c in canon {
        if let CanonCmd::Print(m) = &c.cmd {
            out.push_str(m);
            out.push('\n');
            continue;
        }
        let mark = out.len();
        seq += 1;
        let b = itoa_buf(seq);
        for _ in b.as_str().len()..5 {
            out.push(' ');
        }
        out.push_str(b.as_str());
        out.push_str(" N..... ");
        if push_call(out, &c.cmd) {
            out.push('\n');
        } else {
            out.truncate(mark);
            seq -= 1;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn f4(v: f64) -> String {
        let mut s = String::new();
        push_f4(&mut s, v);
        s
    }

    #[test]
    fn f4_matches_std_formatting() {
        for v in [
            0.0, -0.0, 1.0, -1.0, 0.00005, 0.00015, 1.23456, -6.1e-17, 25.4, 1e9, -123.45675,
            0.99995, 2.5e-5,
        ] {
            assert_eq!(f4(v), format!("{v:.4}"), "value {v}");
        }
        assert_eq!(f4(-6.1e-17), "-0.0000");
    }
}
