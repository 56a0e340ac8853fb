//! Fanuc-style numbered subprograms, as LinuxCNC 2.9 runs them: a program `O100` (an
//! O-number alone on its line) ending with `M99`, called with `M98 P100 [L<repeats>]`.
//!
//! They differ from `o<name> sub` subroutines in what rs274 does, and hytask follows it:
//! - `M98` must begin its line; its P and L words belong to it, other words on the line are
//!   checked but not executed (rs274 treats the line as an O-word line).
//! - The subprogram shares `#1`–`#30` with its caller (no arguments, nothing restored);
//!   named parameters set inside are local to the call.
//! - `L` repeats the call (`L0`: not at all); `M99` at the start of a line returns, or runs
//!   the subprogram again while repeats are left.
//! - `M99` in the main program ends it like `M2` (rs274's preview; LinuxCNC's task loops
//!   back to the start instead, which a job that must be checked before it moves cannot do).
//! - Mixing styles is refused with rs274's messages: `o100 call` of a numbered program,
//!   `M98` of an `o100 sub`, and `endsub`/`return` inside a numbered program.

use super::{Frame, Interp};
use crate::gcode::expr;
use crate::gcode::modal::Block;
use crate::gcode::parser::{Line, OKind};
use crate::gcode::GcodeError;
use std::collections::HashMap;

/// The repeat state of an `M98 … L` call.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Repeat {
    /// The `O<n>` line of the subprogram.
    start: (usize, usize),
    /// Runs still to do after the current one.
    left: u64,
}

/// `v` as an integer the way rs274 reads integer words (within 0.0001, or rounded up
/// from within 0.0001 below the next integer).
fn integer(v: f64) -> Option<i64> {
    let n = v.floor();
    if v - n > 0.9999 {
        Some(v.ceil() as i64)
    } else if v - n > 0.0001 {
        None
    } else {
        Some(n as i64)
    }
}

impl Interp<'_> {
    /// True when the innermost call is a Fanuc-style `M98` call.
    pub(super) fn in_m98_call(&self) -> bool {
        self.frames.last().is_some_and(|f| f.fanuc.is_some())
    }

    /// Handles a line beginning with `M98`, or with `M99` inside an `M98` call. Returns
    /// false when the line is an ordinary block.
    pub(super) fn fanuc_line(&mut self, line: &Line) -> Result<bool, GcodeError> {
        let Some(first) = line.words.first() else {
            return Ok(false);
        };
        if first.letter != b'm' {
            return Ok(false);
        }
        self.loc.col = first.col;
        let m = expr::eval(&first.value, &*self).map_err(|e| self.err(first.col, e))?;
        if m == 98.0 {
            self.m98(line, first.col)?;
            Ok(true)
        } else if m == 99.0 && self.in_m98_call() {
            self.m99_return()?;
            Ok(true)
        } else {
            Ok(false)
        }
    }

    fn m98(&mut self, line: &Line, col: u32) -> Result<(), GcodeError> {
        if let Some(a) = line.assigns.first() {
            return Err(self.err(
                a.col,
                "Parameter settings on an M98 line are not supported: set them on a line before",
            ));
        }
        let mut b = self.block_of(&line.words[1..])?;
        let word = |b: &Block, c: u8| -> Result<Option<i64>, GcodeError> {
            match b.get(c) {
                None => Ok(None),
                Some(v) => integer(v)
                    .map(Some)
                    .ok_or_else(|| self.err(b.col_of(c), "Non integer value for integer")),
            }
        };
        let program =
            word(&b, b'p')?.ok_or_else(|| self.err(col, "Found 'm98' code with no P-word"))?;
        let repeats = word(&b, b'l')?.unwrap_or(1);
        // P and L belong to M98; the other words are checked as rs274 checks them.
        b.val[usize::from(b'p' - b'a')] = None;
        b.val[usize::from(b'l' - b'a')] = None;
        self.check_block(&b)?;
        let label: Box<str> = format!("{}", program.max(0)).into();
        if program < 0 {
            return Err(self.err(b.col_of(b'p'), "Negative P word used with M98"));
        }
        if repeats <= 0 {
            return Ok(());
        }
        let start = self.numbered_program(&label)?;
        if self.frames.len() >= self.opts.limits.max_call_depth {
            return Err(self.err(
                col,
                format!(
                    "Subroutine calls nested too deeply (limit {})",
                    self.opts.limits.max_call_depth
                ),
            ));
        }
        self.frames.push(Frame {
            ret: self.pc,
            saved: [0.0; 30],
            label,
            fanuc: Some(Repeat {
                start,
                left: u64::try_from(repeats - 1).unwrap_or(0),
            }),
        });
        self.p.locals.push(HashMap::new());
        self.s.saved.push(None);
        self.s.auto_restore.push(false);
        self.pc = (start.0, start.1 + 1);
        Ok(())
    }

    /// Where numbered program `label` starts, in any loaded file.
    ///
    /// Errors are where rs274's search stops: at an `O… sub` definition of the label (the
    /// wrong kind), else at the end of the calling file.
    fn numbered_program(&self, label: &str) -> Result<(usize, usize), GcodeError> {
        let mut sub_def = None;
        for (fi, src) in self.files.iter().enumerate() {
            for &l in src.by_label.get(label).map(Vec::as_slice).unwrap_or(&[]) {
                match src.olines.get(&l).map(|o| o.kind) {
                    Some(OKind::ProgramNumber) => return Ok((fi, l)),
                    Some(OKind::Sub) => sub_def = sub_def.or(Some((fi, l))),
                    _ => {}
                }
            }
        }
        let call = self.loc.line;
        Err(match sub_def {
            Some((fi, l)) => self.err_at(
                fi,
                l,
                format!("'O.... sub' subroutine must be called with 'O.... call' (O{label} is called by M98 P{label} at line {call})"),
            ),
            None => {
                let f = self.pc.0;
                self.err_at(
                    f,
                    self.search_end_line(f),
                    format!("Failed to find subprogram O{label} before the end of the file (called by M98 P{label} at line {call})"),
                )
            }
        })
    }

    /// `M99` in an `M98` call: runs the subprogram again while repeats are left, else
    /// returns to the line after the `M98`.
    fn m99_return(&mut self) -> Result<(), GcodeError> {
        if let Some(r) = self.frames.last_mut().and_then(|f| f.fanuc.as_mut()) {
            if r.left > 0 {
                r.left -= 1;
                self.pc = (r.start.0, r.start.1 + 1);
                return Ok(());
            }
        }
        self.leave_frame()
    }

    /// The error for an `M99` that does not return from an `M98` call, or `None` for an
    /// `M99` in the main program (which ends it, as `M2`).
    pub(super) fn m99_misplaced(&self) -> Option<&'static str> {
        match self.frames.last() {
            None => None,
            Some(f) if f.fanuc.is_some() => {
                Some("M99 must begin its line to return from a Fanuc-style subprogram")
            }
            Some(_) => Some(
                "'O.... endsub' or 'O.... return' must follow 'O.... sub' subroutine definition",
            ),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::integer;

    #[test]
    fn integers_are_read_as_rs274_reads_them() {
        assert_eq!(integer(10.0), Some(10));
        assert_eq!(integer(10.00005), Some(10));
        assert_eq!(integer(9.99995), Some(10));
        assert_eq!(integer(2.5), None);
    }
}
