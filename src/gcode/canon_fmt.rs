//! Text form of canonical commands, byte-compatible with `rs274 -g`.
//!
//! The trace format exists so a hytask run can be diffed line by line against LinuxCNC's
//! own interpreter. Numbers are printed like C's `%.4f` (correct rounding, `-0.0000` kept),
//! through a fast path because the formatter is on the throughput-critical path of
//! `hytask gcode canon`.

use super::canon::{
    Canon, CanonCmd, FeedMode, LengthUnits, LogKind, MotionControl, OverrideKind, Plane, Pose,
    SpindleDir,
};
use std::io::Write as _;

/// "00" "01" … "99": two digits per table lookup.
const DIGITS2: &[u8; 200] = b"0001020304050607080910111213141516171819\
2021222324252627282930313233343536373839\
4041424344454647484950515253545556575859\
6061626364656667686970717273747576777879\
8081828384858687888990919293949596979899";

fn push_str(out: &mut Vec<u8>, s: &str) {
    out.extend_from_slice(s.as_bytes());
}

/// Appends `v` formatted like C's `printf("%.4f", v)`.
pub fn push_f4(out: &mut Vec<u8>, v: f64) {
    // Zero is the most common number of a trace (the unused A/B/C of every move).
    if v == 0.0 {
        let s: &[u8; 7] = if v.is_sign_negative() {
            b"-0.0000"
        } else {
            b"0.0000 "
        };
        let len = out.len() + 6 + usize::from(v.is_sign_negative());
        out.extend_from_slice(s);
        out.truncate(len);
        return;
    }
    // Fast path: exact when v*1e4 is far from a rounding tie and fits an integer; the slow
    // path (std formatting, correctly rounded like glibc) handles ties and huge values.
    let a = (v * 10_000.0).abs();
    if a < 1e15 {
        let t = a as u64;
        let frac = a - t as f64;
        if (frac - 0.5).abs() > 1e-6 {
            let n = t + u64::from(frac > 0.5);
            let (mut k, d) = (n / 10_000, (n % 10_000) as usize);
            // Laid out left-aligned in a fixed-size buffer that is appended whole and then
            // cut to length: a copy of a constant size is a few moves, where a slice of
            // variable length costs a call to memcpy (19% of `gcode canon` in a profile).
            let neg = usize::from(v.is_sign_negative());
            let digits = k.checked_ilog10().unwrap_or(0) as usize + 1;
            let mut buf = [b'-'; 24];
            let mut i = neg + digits;
            buf[i] = b'.';
            buf[i + 1..i + 3].copy_from_slice(&DIGITS2[2 * (d / 100)..2 * (d / 100) + 2]);
            buf[i + 3..i + 5].copy_from_slice(&DIGITS2[2 * (d % 100)..2 * (d % 100) + 2]);
            while k >= 100 {
                i -= 2;
                let r = (k % 100) as usize;
                buf[i..i + 2].copy_from_slice(&DIGITS2[2 * r..2 * r + 2]);
                k /= 100;
            }
            if k >= 10 {
                i -= 2;
                let r = k as usize;
                buf[i..i + 2].copy_from_slice(&DIGITS2[2 * r..2 * r + 2]);
            } else {
                buf[i - 1] = b'0' + k as u8;
            }
            let len = out.len() + neg + digits + 5;
            out.extend_from_slice(&buf);
            out.truncate(len);
            return;
        }
    }
    let _ = write!(out, "{v:.4}");
}

/// Appends the decimal digits of `n` (a fixed-size append cut to length, as in [`push_f4`]).
fn push_u64(out: &mut Vec<u8>, mut n: u64) {
    let digits = n.checked_ilog10().unwrap_or(0) as usize + 1;
    let mut buf = [0u8; 20];
    let mut i = digits;
    loop {
        i -= 1;
        buf[i] = b'0' + (n % 10) as u8;
        n /= 10;
        if n == 0 {
            break;
        }
    }
    let len = out.len() + digits;
    out.extend_from_slice(&buf);
    out.truncate(len);
}

/// Appends `v` formatted like C's `printf("%.6f", v)` (slow path is fine: rare calls).
pub fn push_f6(out: &mut Vec<u8>, v: f64) {
    let _ = write!(out, "{v:.6}");
}

fn push_list(out: &mut Vec<u8>, vals: &[f64]) {
    for (i, v) in vals.iter().enumerate() {
        if i > 0 {
            push_str(out, ", ");
        }
        push_f4(out, *v);
    }
}

fn push_space_list(out: &mut Vec<u8>, vals: &[f64]) {
    for (i, v) in vals.iter().enumerate() {
        if i > 0 {
            out.push(b' ');
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
pub fn push_call(out: &mut Vec<u8>, cmd: &CanonCmd) -> bool {
    match cmd {
        CanonCmd::UseLengthUnits(u) => push_str(
            out,
            match u {
                LengthUnits::Millimeters => "USE_LENGTH_UNITS(CANON_UNITS_MM)",
                LengthUnits::Inches => "USE_LENGTH_UNITS(CANON_UNITS_INCHES)",
            },
        ),
        CanonCmd::SetG5xOffset { index, offset } => {
            let _ = write!(out, "SET_G5X_OFFSET({index}, ");
            push_list(out, six(offset));
            out.push(b')');
        }
        CanonCmd::SetG92Offset(p) => {
            push_str(out, "SET_G92_OFFSET(");
            push_list(out, six(p));
            out.push(b')');
        }
        CanonCmd::SetXyRotation(r) => {
            push_str(out, "SET_XY_ROTATION(");
            push_f4(out, *r);
            out.push(b')');
        }
        CanonCmd::UseToolLengthOffset(p) => {
            push_str(out, "USE_TOOL_LENGTH_OFFSET(");
            push_space_list(out, &p[0..3]);
            push_str(out, ", ");
            push_space_list(out, &p[3..6]);
            push_str(out, ", ");
            push_space_list(out, &p[6..9]);
            out.push(b')');
        }
        CanonCmd::SelectPlane(p) => {
            let _ = write!(out, "SELECT_PLANE({})", plane_name(*p));
        }
        CanonCmd::SetFeedRate(f) => {
            push_str(out, "SET_FEED_RATE(");
            push_f4(out, *f);
            out.push(b')');
        }
        CanonCmd::SetFeedMode(m) => push_str(
            out,
            match m {
                FeedMode::UnitsPerRevolution => "SET_FEED_MODE(0, 1)",
                // LinuxCNC handles inverse time in the interpreter; canon sees units/minute.
                FeedMode::UnitsPerMinute | FeedMode::InverseTime => "SET_FEED_MODE(0, 0)",
            },
        ),
        CanonCmd::SetMotionControl(m) => match m {
            MotionControl::ExactStop => push_str(out, "SET_MOTION_CONTROL_MODE(CANON_EXACT_STOP)"),
            MotionControl::ExactPath => push_str(out, "SET_MOTION_CONTROL_MODE(CANON_EXACT_PATH)"),
            MotionControl::Continuous { tolerance } => {
                push_str(out, "SET_MOTION_CONTROL_MODE(CANON_CONTINUOUS, ");
                push_f6(out, *tolerance);
                out.push(b')');
            }
        },
        CanonCmd::SetNaivecamTolerance(t) => {
            push_str(out, "SET_NAIVECAM_TOLERANCE(");
            push_f4(out, *t);
            out.push(b')');
        }
        CanonCmd::StraightTraverse(p) => {
            push_str(out, "STRAIGHT_TRAVERSE(");
            push_list(out, six(p));
            out.push(b')');
        }
        CanonCmd::StraightFeed(p) => {
            push_str(out, "STRAIGHT_FEED(");
            push_list(out, six(p));
            out.push(b')');
        }
        CanonCmd::NurbsFeed { points, .. } => {
            // rs274's standalone canon prints only the number of control points.
            let _ = write!(out, "NURBS_FEED({}, ...)", points.len());
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
            push_str(out, "ARC_FEED(");
            push_list(
                out,
                &[*first_end, *second_end, *first_center, *second_center],
            );
            let _ = write!(out, ", {rotation}, ");
            push_list(out, &[*axis_end, end[3], end[4], end[5]]);
            out.push(b')');
        }
        CanonCmd::Dwell(s) => {
            push_str(out, "DWELL(");
            push_f4(out, *s);
            out.push(b')');
        }
        CanonCmd::SetSpindleSpeed(s) => {
            push_str(out, "SET_SPINDLE_SPEED(0, ");
            push_f4(out, *s);
            out.push(b')');
        }
        CanonCmd::StartSpindle(d) => push_str(
            out,
            match d {
                SpindleDir::Clockwise => "START_SPINDLE_CLOCKWISE(0)",
                SpindleDir::CounterClockwise => "START_SPINDLE_COUNTERCLOCKWISE(0)",
            },
        ),
        CanonCmd::StopSpindle => push_str(out, "STOP_SPINDLE_TURNING(0)"),
        CanonCmd::MistOn => push_str(out, "MIST_ON()"),
        CanonCmd::MistOff => push_str(out, "MIST_OFF()"),
        CanonCmd::FloodOn => push_str(out, "FLOOD_ON()"),
        CanonCmd::FloodOff => push_str(out, "FLOOD_OFF()"),
        CanonCmd::SelectTool(t) => {
            let _ = write!(out, "SELECT_TOOL({t})");
        }
        CanonCmd::StartChange => push_str(out, "START_CHANGE()"),
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
            out.push(b')');
        }
        CanonCmd::Wait { .. } => return false,
        CanonCmd::StraightProbe { end, .. } => {
            push_str(out, "STRAIGHT_PROBE(");
            push_list(out, six(end));
            out.push(b')');
        }
        CanonCmd::OverrideEnable { which, on } => {
            let pre = if *on { "ENABLE_" } else { "DISABLE_" };
            let what = match which {
                OverrideKind::Feed | OverrideKind::FeedAndSpindle => "FEED_OVERRIDE()",
                OverrideKind::Spindle => "SPEED_OVERRIDE(0)",
                OverrideKind::AdaptiveFeed => "ADAPTIVE_FEED()",
                OverrideKind::FeedHold => "FEED_HOLD()",
            };
            push_str(out, pre);
            push_str(out, what);
        }
        CanonCmd::Message(m) => {
            let _ = write!(out, "MESSAGE(\"{m}\")");
        }
        CanonCmd::Print(m) => push_str(out, m),
        CanonCmd::Log { kind, text } => {
            let _ = match kind {
                LogKind::Open => write!(out, "LOGOPEN(\"{text}\")"),
                LogKind::Append => write!(out, "LOGAPPEND(\"{text}\")"),
                LogKind::Write => write!(out, "LOG(\"{text}\")"),
                LogKind::Close => write!(out, "LOGCLOSE()"),
            };
        }
        CanonCmd::Comment(m) => {
            let _ = write!(out, "COMMENT(\"{m}\")");
        }
        CanonCmd::ProgramStop => push_str(out, "PROGRAM_STOP()"),
        CanonCmd::OptionalProgramStop => push_str(out, "OPTIONAL_PROGRAM_STOP()"),
        CanonCmd::ProgramEnd => push_str(out, "PROGRAM_END()"),
        CanonCmd::PalletShuttle => push_str(out, "PALLET_SHUTTLE()"),
        CanonCmd::OnReset => push_str(out, "ON_RESET()"),
        CanonCmd::SetFeedReference => push_str(out, "SET_FEED_REFERENCE(CANON_XYZ)"),
        CanonCmd::SetSpindleMode { css_max_rpm } => {
            push_str(out, "SET_SPINDLE_MODE(0 ");
            push_f4(out, *css_max_rpm);
            out.push(b')');
        }
        CanonCmd::OrientSpindle { angle, mode } => {
            push_str(out, "ORIENT_SPINDLE(0, ");
            push_f4(out, *angle);
            let _ = write!(out, ", {mode})");
        }
        CanonCmd::WaitOrientComplete(t) => {
            push_str(out, "SPINDLE.0.WAIT_ORIENT_COMPLETE(");
            push_f4(out, *t);
            out.push(b')');
        }
        CanonCmd::StartSpeedFeedSync { pitch } => {
            let _ = write!(out, "START_SPEED_FEED_SYNC({pitch:.6},0)");
        }
        CanonCmd::StopSpeedFeedSync => push_str(out, "STOP_SPEED_FEED_SYNCH()"),
        CanonCmd::RigidTap { end } => {
            push_str(out, "RIGID_TAP(");
            push_f4(out, end[0]);
            push_str(out, ", ");
            push_f4(out, end[1]);
            push_str(out, ", ");
            push_f4(out, end[2]);
            out.push(b')');
        }
        CanonCmd::Probe { on } => push_str(
            out,
            if *on {
                "TURN_PROBE_ON()"
            } else {
                "TURN_PROBE_OFF()"
            },
        ),
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
            push_str(out, ", ");
            push_list(out, &[*front_angle, *back_angle]);
            let _ = write!(out, ", {orientation})");
        }
        CanonCmd::Finish => push_str(out, "FINISH()"),
        CanonCmd::UserMcode { code, p, q } => {
            let _ = write!(out, "USER_MCODE({code}, ");
            push_list(out, &[*p, *q]);
            out.push(b')');
        }
    }
    true
}

/// Writes a whole trace in `rs274 -g` layout: `%5d N..... CALL` per command, numbered from
/// one. The `N.....` column is printed as rs274 prints it for blocks without an N word; the
/// differential test strips the prefix columns before comparing (see
/// tests/gcode/DIFFERENCES.md). `PRINT` lines are bare text, without number, as rs274 writes them.
pub fn write_trace(out: &mut Vec<u8>, canon: &[Canon]) {
    write_trace_from(out, canon, 0);
}

/// [`write_trace`] for one chunk of a longer trace: numbering continues after `seq` (the
/// number of calls already printed); returns the new count.
pub fn write_trace_from(out: &mut Vec<u8>, canon: &[Canon], mut seq: u64) -> u64 {
    for c in canon {
        write_call(out, &c.cmd, &mut seq);
    }
    seq
}

/// Appends one command as a trace line (numbered `seq + 1` unless it is a bare `PRINT` line
/// or prints nothing) and advances `seq`.
pub fn write_call(out: &mut Vec<u8>, cmd: &CanonCmd, seq: &mut u64) {
    if let CanonCmd::StraightFeed(_) | CanonCmd::StraightTraverse(_) | CanonCmd::ArcFeed { .. } =
        cmd
    {
        if write_motion(out, cmd, *seq + 1) {
            *seq += 1;
            return;
        }
    }
    if let CanonCmd::Print(m) = cmd {
        push_str(out, m);
        out.push(b'\n');
        return;
    }
    let mark = out.len();
    let n = *seq + 1;
    let digits = n.checked_ilog10().unwrap_or(0) + 1;
    for _ in digits..5 {
        out.push(b' ');
    }
    push_u64(out, n);
    push_str(out, " N..... ");
    if push_call(out, cmd) {
        out.push(b'\n');
        *seq = n;
    } else {
        out.truncate(mark);
    }
}

/// The most a motion line of the fast path takes: the sequence number (at most 20 digits),
/// ` N..... `, the call's name, nine numbers of at most 17 characters (the fast path prints
/// only those below 1e11), the rotation, separators and the newline.
const MOTION_LINE_MAX: usize = 256;

/// The trace line of a move (`STRAIGHT_TRAVERSE`, `STRAIGHT_FEED`, `ARC_FEED`), numbered `n`,
/// laid out in place: the output grows by [`MOTION_LINE_MAX`] once, the line is written
/// into that space by index and the output is cut back to the line's length (the text is
/// [`push_call`]'s, byte for byte). One capacity check and no per-number copy instead of
/// one of each per number and separator: these lines are nearly the whole trace of a CAM
/// program. Returns false, with `out` unchanged, for any other command or when a number
/// needs `push_f4`'s slow path (a rounding tie, a huge value).
fn write_motion(out: &mut Vec<u8>, cmd: &CanonCmd, n: u64) -> bool {
    let mark = out.len();
    out.resize(mark + MOTION_LINE_MAX, 0);
    match motion_line(&mut out[mark..], cmd, n) {
        Some(len) => {
            out.truncate(mark + len);
            true
        }
        None => {
            out.truncate(mark);
            false
        }
    }
}

fn motion_line(buf: &mut [u8], cmd: &CanonCmd, n: u64) -> Option<usize> {
    // `%5d`: right-aligned in five columns.
    let digits = n.checked_ilog10().unwrap_or(0) as usize + 1;
    let mut i = 5usize.saturating_sub(digits);
    buf.get_mut(..i)?.fill(b' ');
    i = put_u64(buf, i, n, digits)?;
    i = put(buf, i, b" N..... ")?;
    match cmd {
        CanonCmd::StraightTraverse(p) => {
            i = put(buf, i, b"STRAIGHT_TRAVERSE(")?;
            i = put_list(buf, i, six(p))?;
        }
        CanonCmd::StraightFeed(p) => {
            i = put(buf, i, b"STRAIGHT_FEED(")?;
            i = put_list(buf, i, six(p))?;
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
            i = put(buf, i, b"ARC_FEED(")?;
            i = put_list(
                buf,
                i,
                &[*first_end, *second_end, *first_center, *second_center],
            )?;
            i = put(buf, i, b", ")?;
            if *rotation < 0 {
                i = put(buf, i, b"-")?;
            }
            let r = u64::from(rotation.unsigned_abs());
            i = put_u64(buf, i, r, r.checked_ilog10().unwrap_or(0) as usize + 1)?;
            i = put(buf, i, b", ")?;
            i = put_list(buf, i, &[*axis_end, end[3], end[4], end[5]])?;
        }
        _ => return None,
    }
    put(buf, i, b")\n")
}

/// Copies `s` to `buf[i..]`; the index after it.
fn put(buf: &mut [u8], i: usize, s: &[u8]) -> Option<usize> {
    let e = i + s.len();
    buf.get_mut(i..e)?.copy_from_slice(s);
    Some(e)
}

/// The `digits` decimal digits of `n` at `buf[i..]`; the index after them.
fn put_u64(buf: &mut [u8], i: usize, mut n: u64, digits: usize) -> Option<usize> {
    let e = i + digits;
    for b in buf.get_mut(i..e)?.iter_mut().rev() {
        *b = b'0' + (n % 10) as u8;
        n /= 10;
    }
    Some(e)
}

/// `vals` separated by `, ` at `buf[i..]`; the index after them.
fn put_list(buf: &mut [u8], mut i: usize, vals: &[f64]) -> Option<usize> {
    for (k, v) in vals.iter().enumerate() {
        if k > 0 {
            i = put(buf, i, b", ")?;
        }
        i = put_f4(buf, i, *v)?;
    }
    Some(i)
}

/// `v` as C's `%.4f` at `buf[i..]` (the digits written right to left in place), or None
/// when it needs [`push_f4`]'s slow path: the same test and the same digits as its fast
/// path.
fn put_f4(buf: &mut [u8], i: usize, v: f64) -> Option<usize> {
    if v == 0.0 {
        return put(
            buf,
            i,
            if v.is_sign_negative() {
                b"-0.0000"
            } else {
                b"0.0000"
            },
        );
    }
    let a = (v * 10_000.0).abs();
    if a >= 1e15 {
        return None;
    }
    let t = a as u64;
    let frac = a - t as f64;
    if (frac - 0.5).abs() <= 1e-6 {
        return None;
    }
    let n = t + u64::from(frac > 0.5);
    let (mut k, d) = (n / 10_000, (n % 10_000) as usize);
    let neg = usize::from(v.is_sign_negative());
    let digits = k.checked_ilog10().unwrap_or(0) as usize + 1;
    let e = i + neg + digits + 5;
    let out = buf.get_mut(i..e)?;
    let m = out.len();
    out[m - 2..].copy_from_slice(&DIGITS2[2 * (d % 100)..2 * (d % 100) + 2]);
    out[m - 4..m - 2].copy_from_slice(&DIGITS2[2 * (d / 100)..2 * (d / 100) + 2]);
    out[m - 5] = b'.';
    let mut j = m - 5;
    while k >= 100 {
        let r = (k % 100) as usize;
        out[j - 2..j].copy_from_slice(&DIGITS2[2 * r..2 * r + 2]);
        j -= 2;
        k /= 100;
    }
    if k >= 10 {
        let r = k as usize;
        out[j - 2..j].copy_from_slice(&DIGITS2[2 * r..2 * r + 2]);
    } else {
        out[j - 1] = b'0' + k as u8;
    }
    if neg == 1 {
        out[0] = b'-';
    }
    Some(e)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn f4(v: f64) -> String {
        let mut s = Vec::new();
        push_f4(&mut s, v);
        String::from_utf8(s).unwrap_or_default()
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
        // Pseudo-random values over many magnitudes agree with std's exact formatting.
        let mut x: u64 = 0x9e37_79b9_7f4a_7c15;
        for _ in 0..20_000 {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            let mag = 10f64.powi((x % 16) as i32 - 5);
            let v = ((x >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * mag;
            assert_eq!(f4(v), format!("{v:.4}"), "value {v:e}");
        }
    }

    /// The in-place motion lines are `push_call`'s text with the `%5d N..... ` prefix, for
    /// values on the fast path and off it (ties, huge values, negative zeros).
    #[test]
    fn motion_lines_in_place_match_push_call() {
        let mut x: u64 = 0x2545_f491_4f6c_dd1d;
        let mut next = || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            let v = match x % 9 {
                0 => 0.0,
                1 => -0.0,
                2 => -1e-9,
                3 => 1.00005,
                4 => 3e14,
                _ => {
                    ((x >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 10f64.powi((x % 13) as i32 - 4)
                }
            };
            (v, x)
        };
        for seq in [0u64, 8, 9, 98, 9_998, 99_998, 99_999, 1_234_567] {
            for _ in 0..300 {
                let mut p: Pose = [0.0; crate::gcode::canon::NUM_AXES];
                for c in p.iter_mut() {
                    *c = next().0;
                }
                let (v, r) = next();
                let arc = CanonCmd::ArcFeed {
                    first_end: p[0],
                    second_end: p[1],
                    first_center: p[2],
                    second_center: v,
                    rotation: (r % 7) as i32 - 3,
                    axis_end: p[3],
                    plane: Plane::Xy,
                    end: p,
                };
                for cmd in [
                    CanonCmd::StraightFeed(p),
                    CanonCmd::StraightTraverse(p),
                    arc,
                ] {
                    let mut fast = Vec::new();
                    let mut s = seq;
                    write_call(&mut fast, &cmd, &mut s);
                    assert_eq!(s, seq + 1);
                    let mut slow = format!("{:5} N..... ", seq + 1).into_bytes();
                    assert!(push_call(&mut slow, &cmd));
                    slow.push(b'\n');
                    assert_eq!(
                        String::from_utf8_lossy(&fast),
                        String::from_utf8_lossy(&slow)
                    );
                }
            }
        }
    }
}
