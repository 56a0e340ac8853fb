//! Interpreting a program in pieces, for probing.
//!
//! A G38.x probe ends where the probe input changes, which only the machine knows, and the
//! lines after it may use the result (#5061–#5070) or simply start from where the machine
//! stopped. LinuxCNC's interpreter therefore stops reading after a probe ("queue buster"),
//! waits until motion has finished, reads the result and goes on. A [`Session`] does the
//! same: [`Session::next_piece`] returns the canonical commands up to and including the
//! line that probes, the machine runs them, and [`Session::probe_result`] hands the
//! measurement back before the next piece.
//!
//! Whole-program checking still happens before anything moves: a job is first interpreted
//! in one go with simulated probes ([`super::load_file`], which trips at the programmed
//! end as `rs274` does), so syntax errors and everything that does not depend on a measured
//! value are refused before motion. What depends on a measurement can only be checked when
//! it is known; the machine is then standing still at the probe.

use super::canon::ProbeKind;
use super::interp::{Interp, Sink};
use super::{read_program, Canon, GcodeError, InterpOptions, SourceLoc};
use std::borrow::Cow;
use std::path::Path;

/// Why a piece ended.
#[derive(Debug, Clone, PartialEq)]
pub enum PieceEnd {
    /// The last line of the piece probes; call [`Session::probe_result`] before the next
    /// piece.
    Probe {
        /// G38.2 .. G38.5.
        kind: ProbeKind,
        /// Where the G38 block is.
        loc: SourceLoc,
    },
    /// The last line of the piece waits for an input (M66): call [`Session::wait_result`]
    /// with what the machine read before the next piece.
    Wait {
        /// Where the M66 block is.
        loc: SourceLoc,
    },
    /// The program ended (M2/M30, closing `%`, end of MDI text).
    End,
}

/// What the machine measured during a probe move, in the program frame and units in
/// effect at the probe (the caller converts from machine coordinates with the offsets the
/// canonical stream set: see `motion::from_canon::Frame::to_program`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProbeResult {
    /// The probe input changed as the G38 variant expected.
    pub tripped: bool,
    /// X Y Z A B C where it changed (where the move ended if it did not).
    pub probed: [f64; 6],
    /// X Y Z A B C where the machine came to rest (after decelerating past the trip).
    pub stopped: [f64; 6],
}

/// A program being interpreted piece by piece (see the module doc).
pub struct Session {
    it: Interp<'static>,
}

impl Session {
    /// Opens a program file (subroutines are also searched in its directory).
    pub fn open_file(path: &Path, opts: &InterpOptions) -> Result<Session, GcodeError> {
        let (name, text, o) = read_program(path, opts)?;
        Session::open(&name, text, o)
    }

    /// Opens program text; `name` is used as the file name in locations and errors.
    pub fn open_str(name: &str, text: &str, opts: &InterpOptions) -> Result<Session, GcodeError> {
        Session::open(name, text.to_string(), opts.clone())
    }

    fn open(name: &str, text: String, opts: InterpOptions) -> Result<Session, GcodeError> {
        let mut it = Interp::new(Cow::Owned(opts))?;
        it.live_probe = true;
        it.load(name, text)?;
        Ok(Session { it })
    }

    /// Interprets up to the end of the next line that probes, or to the end of the program.
    /// The commands after the probe on its own line (e.g. an M2 after the motion) belong to
    /// this piece. Returns an error if a probe result is still owed.
    pub fn next_piece(&mut self) -> Result<(Vec<Canon>, PieceEnd), GcodeError> {
        if let Some(p) = &self.it.pending_probe {
            return Err(GcodeError {
                file: p.loc.file.to_string(),
                line: p.loc.line,
                col: p.loc.col,
                message: "internal: the probe result of this line was not given".into(),
            });
        }
        if let Some(loc) = &self.it.pending_wait {
            return Err(GcodeError {
                file: loc.file.to_string(),
                line: loc.line,
                col: loc.col,
                message: "internal: the M66 result of this line was not given".into(),
            });
        }
        if !self.it.ended() {
            self.it.resume()?;
        }
        let canon = match &mut self.it.out {
            Sink::Canon(v) => std::mem::take(v),
            Sink::Trace { .. } => Vec::new(),
        };
        let end = match &self.it.pending_probe {
            Some(p) => PieceEnd::Probe {
                kind: p.kind,
                loc: p.loc.clone(),
            },
            None => match &self.it.pending_wait {
                Some(loc) => PieceEnd::Wait { loc: loc.clone() },
                None => PieceEnd::End,
            },
        };
        Ok((canon, end))
    }

    /// Hands the result of the probe that ended the last piece to the interpreter.
    pub fn probe_result(&mut self, r: &ProbeResult) {
        self.it.probe_result(r.tripped, &r.probed, &r.stopped);
    }

    /// Makes every M66 end a piece ([`PieceEnd::Wait`]), so that the lines after it see
    /// the machine's answer in #5399 (off by default: the M66 is then passed on and #5399
    /// keeps its value, as in the whole-program dry run).
    pub fn live_waits(&mut self, on: bool) {
        self.it.live_wait = on;
    }

    /// Hands the machine's answer to the M66 that ended the last piece to the interpreter:
    /// #5399 becomes `value` (the input, or -1 when the wait timed out).
    pub fn wait_result(&mut self, value: f64) {
        self.it.wait_result(value);
    }

    /// The result `rs274` reports without a machine for the pending probe (not tripped;
    /// probed at the programmed end; stopped 0.01 inch short of it): what the whole-program
    /// dry run before motion uses. `None` when no probe is pending.
    pub fn simulated_result(&self) -> Option<ProbeResult> {
        self.it.pending_probe.as_ref().map(|p| ProbeResult {
            tripped: false,
            probed: p.simulated.0,
            stopped: p.simulated.1,
        })
    }

    /// The persistent parameters as the program has left them so far (the var file to save
    /// once the job has run).
    pub fn parameters(&self) -> super::VarFile {
        self.it.persistent()
    }

    /// True once the program has ended.
    pub fn finished(&self) -> bool {
        self.it.ended() && self.it.pending_probe.is_none() && self.it.pending_wait.is_none()
    }
}

/// A whole program interpreted a chunk of commands at a time, with probes simulated as in
/// the one-shot run ([`super::load_str`]): the same commands in the same order, cut into
/// pieces, so that a long program is checked and planned without ever holding all its
/// commands (see `machine::job`).
pub struct Chunked {
    it: Interp<'static>,
}

impl Chunked {
    /// Opens program text; `name` is used as the file name in locations and errors. Each
    /// [`Chunked::next_chunk`] returns at least `chunk` commands (fewer at the end), a line's
    /// commands never split.
    pub fn open_str(
        name: &str,
        text: String,
        opts: &InterpOptions,
        chunk: usize,
    ) -> Result<Chunked, GcodeError> {
        let mut it = Interp::new(Cow::Owned(opts.clone()))?;
        it.yield_after = chunk.max(1);
        it.load(name, text)?;
        Ok(Chunked { it })
    }

    /// Moves the next commands into `out` (cleared first); false once the program has ended
    /// (`out` then holds the last ones, possibly none).
    pub fn next_chunk(&mut self, out: &mut Vec<Canon>) -> Result<bool, GcodeError> {
        out.clear();
        if !self.it.ended() {
            self.it.resume()?;
        }
        if let Sink::Canon(v) = &mut self.it.out {
            std::mem::swap(v, out);
        }
        Ok(!self.it.ended())
    }

    /// The persistent parameters as the program has left them so far (after the last chunk:
    /// the var file to save when the job has run).
    pub fn parameters(&self) -> super::VarFile {
        self.it.persistent()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gcode::CanonCmd;

    fn feeds(c: &[Canon]) -> Vec<[f64; 9]> {
        c.iter()
            .filter_map(|c| match c.cmd {
                CanonCmd::StraightFeed(p) | CanonCmd::StraightTraverse(p) => Some(p),
                _ => None,
            })
            .collect()
    }

    #[test]
    fn stops_after_the_probe_line_and_continues_with_the_measurement() {
        let prog = "G21 G90\nG0 X0 Y0 Z10\nF100\nG38.2 Z-20 M0\n\
                    G0 Z[#5063 + 5]\n(the X move needs the tripped flag)\nG1 X[#5070 * 7]\nM2\n";
        let mut s = Session::open_str("p.ngc", prog, &InterpOptions::default()).unwrap();
        let (c1, end) = s.next_piece().unwrap();
        let PieceEnd::Probe { kind, loc } = end else {
            panic!("{end:?}")
        };
        assert_eq!((kind, loc.line), (ProbeKind::TowardErr, 4));
        assert!(
            c1.iter().any(|c| matches!(c.cmd, CanonCmd::ProgramStop)),
            "the M0 on the probe's own line belongs to this piece"
        );
        assert!(matches!(
            c1.iter()
                .rev()
                .find(|c| !matches!(c.cmd, CanonCmd::ProgramStop | CanonCmd::Probe { .. }))
                .map(|c| &c.cmd),
            Some(CanonCmd::StraightProbe { .. })
        ));
        assert!(!s.finished());
        // Asking for more without the result is refused.
        assert!(s.next_piece().is_err());
        s.probe_result(&ProbeResult {
            tripped: true,
            probed: [0.0, 0.0, -3.25, 0.0, 0.0, 0.0],
            stopped: [0.0, 0.0, -3.5, 0.0, 0.0, 0.0],
        });
        let (c2, end) = s.next_piece().unwrap();
        assert_eq!(end, PieceEnd::End);
        assert!(s.finished());
        let moves = feeds(&c2);
        assert_eq!(moves[0][2], 1.75, "G0 Z[#5063 + 5] uses the measured Z");
        assert_eq!(moves[1][0], 7.0, "#5070 is 1 after a trip");
        assert_eq!(moves[1][2], 1.75);
    }

    #[test]
    fn a_chunked_run_gives_the_one_shot_commands_in_pieces() {
        let prog = "G21 G90 F100\n#1 = 0\no1 while [#1 LT 50]\nG1 X[#1] Y[#1 * 2]\n\
                    G38.2 Z-1\n#1 = [#1 + 1]\no1 endwhile\nM2\n";
        let opts = InterpOptions::default();
        let one_shot = crate::gcode::load_str("c.ngc", prog, &opts).unwrap();
        let mut run = Chunked::open_str("c.ngc", prog.into(), &opts, 7).unwrap();
        let (mut all, mut chunk, mut pieces) = (Vec::new(), Vec::new(), 0);
        loop {
            let more = run.next_chunk(&mut chunk).unwrap();
            assert!(!more || chunk.len() >= 7, "{}", chunk.len());
            all.append(&mut chunk);
            pieces += 1;
            if !more {
                break;
            }
        }
        assert!(pieces > 10, "{pieces}");
        assert_eq!(all, one_shot.canon);
    }

    #[test]
    fn a_program_without_probes_is_one_piece() {
        let prog = "G0 X1\nG1 X2 F100\nM2\n";
        let mut s = Session::open_str("p.ngc", prog, &InterpOptions::default()).unwrap();
        let (c, end) = s.next_piece().unwrap();
        assert_eq!(end, PieceEnd::End);
        let one_shot = crate::gcode::load_str("p.ngc", prog, &InterpOptions::default()).unwrap();
        assert_eq!(c, one_shot.canon);
    }

    #[test]
    fn probes_in_a_loop_pause_each_time_and_the_next_move_starts_where_the_machine_stopped() {
        let prog = "G21 G90 F50\n#1 = 0\no1 while [#1 LT 3]\nG38.3 X[10 + #1]\n#1 = [#1 + 1]\no1 endwhile\nG91 G1 Y1\nM2\n";
        let mut s = Session::open_str("loop.ngc", prog, &InterpOptions::default()).unwrap();
        let mut pieces = 0;
        loop {
            let (c, end) = s.next_piece().unwrap();
            pieces += 1;
            match end {
                PieceEnd::Probe { loc, kind } => {
                    assert_eq!((loc.line, kind), (4, ProbeKind::Toward));
                    // G38.3 without contact: the move ran to its end.
                    let x = 10.0 + f64::from(pieces - 1);
                    s.probe_result(&ProbeResult {
                        tripped: false,
                        probed: [x, 0.0, 0.0, 0.0, 0.0, 0.0],
                        stopped: [x, 0.0, 0.0, 0.0, 0.0, 0.0],
                    });
                }
                PieceEnd::End => {
                    let m = feeds(&c);
                    assert_eq!(&m[0][..2], &[12.0, 1.0], "incremental move from the stop");
                    break;
                }
                PieceEnd::Wait { loc } => panic!("no M66 in this program, yet one at {loc:?}"),
            }
        }
        assert_eq!(pieces, 4);
    }

    #[test]
    fn an_error_after_a_probe_names_its_line() {
        let prog = "G21 F50\nG38.2 Z-5\nG1 X[1/#5070]\nM2\n";
        let mut s = Session::open_str("e.ngc", prog, &InterpOptions::default()).unwrap();
        let _ = s.next_piece().unwrap();
        s.probe_result(&ProbeResult {
            tripped: false,
            probed: [0.0; 6],
            stopped: [0.0; 6],
        });
        let e = s.next_piece().unwrap_err();
        assert_eq!((e.file.as_str(), e.line), ("e.ngc", 3), "{e}");
    }
}
