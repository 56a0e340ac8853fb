//! The interpreter proper: modal state, the execution of one block in LinuxCNC's order, and
//! the program loop over files, subroutines and loops.
//!
//! A program is run to its end before anything is returned, and the first error aborts the
//! whole run: the caller gets either a complete program or an error, never a prefix. That is
//! what lets the planner validate a job as a unit before any motion starts.

mod arcs;
mod block;
mod cutter_comp;
mod cycles;
mod fanuc;
mod frame;
mod lathe;
mod mcodes;
mod motion;
mod ocode;
mod param_comment;
mod persistent;
mod polar;
mod pycall;
mod roughing;
mod roughing_comp;
mod roughing_geom;
mod roughing_steps;
mod splines;
mod state;
mod thread_cycle;
mod threading;
mod unsupported;

use super::canon::{Canon, CanonCmd, SourceLoc};
use super::expr::{self, ParamSource};
use super::modal::Block;
use super::params::{self, Params};
use super::parser::{self, Line, OKind, OStmt, Target};
use super::tooltable::ToolTable;
use super::{GcodeError, InterpOptions};
use std::borrow::Cow;
use std::collections::HashMap;
use std::path::PathBuf;

/// Most canonical commands one block may produce. The streaming passes take the output
/// between blocks, so this bounds what is held at once: a `G83 … Q0.0000001` drilling 100 mm
/// made a billion pecks in one block and held up to `max_canon` (50 M, 5 GB) of them before
/// any check. About 100 MB; far beyond any real block.
pub(crate) const MAX_BLOCK_CANON: usize = 1_000_000;
use std::sync::atomic::Ordering;
use std::sync::Arc;

pub(crate) use state::Settings;

/// One loaded source file, split into lines, with its O-word lines indexed.
#[derive(Debug)]
pub(crate) struct Source {
    /// Display name (path or the name given to `load_str`).
    pub name: Arc<str>,
    text: String,
    /// Byte ranges of the lines.
    lines: Vec<(usize, usize)>,
    /// First line after the program (a closing `%`, or the end of the file).
    end: usize,
    /// The program is delimited by `%` lines.
    percent: bool,
    /// The closing `%` was found.
    closed: bool,
    /// Per line: 0 plain, 1 O-word statement, 2 a `%` line.
    kind: Vec<u8>,
    /// O-word statements by line.
    olines: HashMap<usize, OStmt>,
    /// Lines of each O label, in file order.
    by_label: HashMap<Box<str>, Vec<usize>>,
    /// O-word lines whose label is computed (`o[#1*10] sub`): their label is known only
    /// when evaluated, so label searches evaluate them (they are rare).
    computed: Vec<usize>,
}

impl Source {
    fn new(name: Arc<str>, text: String, opts: &InterpOptions) -> Result<Source, GcodeError> {
        let mkerr = |line: usize, col: u32, message: String| GcodeError {
            file: name.to_string(),
            line: u32::try_from(line + 1).unwrap_or(u32::MAX),
            col,
            message,
        };
        if text.len() > opts.limits.max_file_bytes {
            return Err(mkerr(
                0,
                1,
                format!(
                    "Program too large: {} bytes (limit {})",
                    text.len(),
                    opts.limits.max_file_bytes
                ),
            ));
        }
        let mut lines = Vec::with_capacity(text.len() / 24 + 1);
        let mut start = 0;
        while let Some(i) = text[start..].find('\n') {
            lines.push((start, start + i));
            start += i + 1;
        }
        if start < text.len() {
            lines.push((start, text.len()));
        }
        if lines.len() > opts.limits.max_lines {
            return Err(mkerr(
                0,
                1,
                format!(
                    "Program too long: {} lines (limit {})",
                    lines.len(),
                    opts.limits.max_lines
                ),
            ));
        }
        let mut src = Source {
            name: name.clone(),
            text,
            lines,
            end: 0,
            percent: false,
            closed: false,
            kind: Vec::new(),
            olines: HashMap::new(),
            by_label: HashMap::new(),
            computed: Vec::new(),
        };
        src.kind = vec![0; src.lines.len()];
        src.end = src.lines.len();
        // `%` handling: a first non-blank line of `%` opens the program, the next closes it.
        let first = (0..src.lines.len()).find(|&i| !src.line(i).trim().is_empty());
        if let Some(f) = first {
            if src.line(f).trim() == "%" {
                src.percent = true;
                if let Some(c) = (f + 1..src.lines.len()).find(|&i| src.line(i).trim() == "%") {
                    src.end = c;
                    src.closed = true;
                }
            }
        }
        // Subroutine being defined (rs274 refuses a `sub` inside another's definition).
        let mut defining: Option<Box<str>> = None;
        for i in 0..src.end {
            let (a, b) = src.lines[i];
            let t = &src.text[a..b];
            if t.len() > opts.limits.max_line_len {
                return Err(mkerr(
                    i,
                    1,
                    format!(
                        "Line too long: {} characters (limit {})",
                        t.len(),
                        opts.limits.max_line_len
                    ),
                ));
            }
            if t.trim() == "%" {
                src.kind[i] = 2;
            } else if parser::starts_with_o(t) {
                src.kind[i] = 1;
                let l = parser::parse_line(t, opts.limits.max_expr_depth)
                    .map_err(|(c, m)| mkerr(i, c, m))?;
                if let Some(o) = l.o {
                    let computed = o.label_expr.is_some();
                    match o.kind {
                        OKind::Sub if defining.is_some() => {
                            return Err(mkerr(
                                i,
                                o.col,
                                format!(
                                    "Nested subroutine definition: o<{}> sub inside o<{}>",
                                    o.label,
                                    defining.as_deref().unwrap_or("")
                                ),
                            ));
                        }
                        OKind::Sub if computed => defining = Some("[computed]".into()),
                        OKind::Sub => defining = Some(o.label.clone()),
                        OKind::EndSub if computed || defining.as_deref() == Some(&*o.label) => {
                            defining = None
                        }
                        _ => {}
                    }
                    if computed {
                        src.computed.push(i);
                    } else {
                        src.by_label.entry(o.label.clone()).or_default().push(i);
                    }
                    src.olines.insert(i, o);
                }
            }
        }
        Ok(src)
    }

    fn line(&self, i: usize) -> &str {
        let (a, b) = self.lines[i];
        &self.text[a..b]
    }

    fn line_text(&self, i: usize) -> &str {
        if i < self.lines.len() {
            self.line(i)
        } else {
            ""
        }
    }
}

/// Where emitted commands go: a program (the library API) or directly the rs274-format
/// trace (`hytask gcode canon`, which then never holds the whole `Vec<Canon>`).
pub(crate) enum Sink<'s> {
    /// Collect the commands.
    Canon(Vec<Canon>),
    /// Format each command as it is emitted.
    Trace {
        /// The text so far (not yet spilled).
        buf: Vec<u8>,
        /// Calls printed so far.
        seq: u64,
        /// Where full chunks of the text go, if anywhere.
        spill: Option<&'s mut crate::gcode::trace_spill::Spill>,
    },
}

/// A subroutine call in progress.
#[derive(Debug)]
pub(crate) struct Frame {
    /// Where to continue after the return.
    ret: (usize, usize),
    /// The caller's `#1`–`#30`.
    saved: [f64; 30],
    /// Label of the subroutine (for endsub/return checks).
    label: Box<str>,
    /// Set for a Fanuc-style `M98` call: shares `#1`–`#30` with its caller and returns
    /// with `M99`, after its repeats.
    fanuc: Option<fanuc::Repeat>,
}

/// The interpreter.
pub(crate) struct Interp<'a> {
    /// Borrowed for a one-shot run, owned by a [`crate::gcode::Session`].
    pub(crate) opts: Cow<'a, InterpOptions>,
    pub(crate) out: Sink<'a>,
    /// Commands emitted so far.
    count: usize,
    /// `count` when the current block began (see [`MAX_BLOCK_CANON`]).
    block_start: usize,
    pub(crate) loc: SourceLoc,
    pub(crate) p: Params,
    pub(crate) s: Settings,
    pub(crate) tools: ToolTable,
    files: Vec<Source>,
    /// Scratch line reused by every plain block.
    scratch: Line,
    subs: HashMap<Box<str>, (usize, usize)>,
    frames: Vec<Frame>,
    /// Repeat counters, keyed by (file, line of the `repeat`, call depth).
    repeats: HashMap<(usize, usize, usize), u64>,
    /// Loop iterations, keyed like `repeats`, for the iteration limit.
    loop_iters: HashMap<(usize, usize, usize), u64>,
    pc: (usize, usize),
    /// Cutter radius compensation and its queue of held calls.
    pub(crate) comp: cutter_comp::Comp,
    /// Axis indices (first, second, drilling) of the canned cycle being generated.
    cycle_axes: (usize, usize, usize),
    ended: bool,
    steps: u64,
    /// Probing is live (a [`crate::gcode::Session`]): a G38.x line ends the piece and the
    /// interpreter waits for the machine's result. Otherwise the probe is simulated as
    /// `rs274` does (it trips at the programmed end).
    pub(crate) live_probe: bool,
    /// The probe of the line just executed, waiting for its result (live probing only).
    pub(crate) pending_probe: Option<PendingProbe>,
    /// The M66 of the line just executed, waiting for the input's value or the timeout
    /// (live sessions only): #5399 is set from the machine's answer.
    pub(crate) pending_wait: Option<SourceLoc>,
    /// M66 ends a piece (a live session whose machine answers with the input's value).
    pub(crate) live_wait: bool,
    /// Streaming hook ([`crate::gcode::session::Chunked`]): `resume` returns once this many
    /// commands are collected, so a long program never holds all its commands at once.
    pub(crate) yield_after: usize,
    /// The embedded-Python child process, once started (see [`crate::gcode::python`]).
    py: Option<crate::gcode::python::Bridge>,
    /// Text Python has printed that does not end a line yet.
    py_out: String,
    /// A Python O-word procedure is running (it counts as a call level).
    py_in_call: bool,
}

/// A probe move the interpreter has emitted and whose result it needs before going on.
#[derive(Debug, Clone)]
pub(crate) struct PendingProbe {
    /// G38.2 .. G38.5.
    pub kind: crate::gcode::canon::ProbeKind,
    /// Where the G38 word is.
    pub loc: SourceLoc,
    /// What `rs274` without a machine would report: (probed, stopped) positions.
    pub simulated: ([f64; 6], [f64; 6]),
}

impl<'a> Interp<'a> {
    pub(crate) fn new(opts: Cow<'a, InterpOptions>) -> Result<Self, GcodeError> {
        let tools = match &opts.tool_table {
            Some(p) => ToolTable::load(p).map_err(|(line, message)| GcodeError {
                file: p.display().to_string(),
                line: line.max(1),
                col: 1,
                message,
            })?,
            None => ToolTable::default(),
        };
        let mut s = Settings::new(&opts);
        s.units = opts.initial_units;
        if let Some(p) = opts.initial_position {
            // Offsets are zero at start: the program frame is the machine frame, in the
            // program's units for the linear axes.
            let per_unit = s.units.mm_per_unit();
            for (i, v) in p.iter().enumerate() {
                s.pos[i] = if i < 3 { v / per_unit } else { *v };
            }
        }
        let mut it = Interp {
            opts,
            out: Sink::Canon(Vec::new()),
            count: 0,
            block_start: 0,
            loc: SourceLoc {
                file: Arc::from(""),
                line: 0,
                col: 1,
            },
            p: Params::default(),
            s,
            tools,
            files: Vec::new(),
            scratch: Line::default(),
            subs: HashMap::new(),
            frames: Vec::new(),
            repeats: HashMap::new(),
            loop_iters: HashMap::new(),
            pc: (0, 0),
            comp: cutter_comp::Comp::default(),
            cycle_axes: (0, 1, 2),
            ended: false,
            steps: 0,
            live_probe: false,
            pending_probe: None,
            pending_wait: None,
            live_wait: false,
            yield_after: usize::MAX,
            py: None,
            py_out: String::new(),
            py_in_call: false,
        };
        it.restore_persistent()?;
        Ok(it)
    }

    /// Emits one canonical command at the current location.
    pub(crate) fn emit(&mut self, cmd: CanonCmd) -> Result<(), GcodeError> {
        if self.comp.holding() && cutter_comp::deferred(&cmd) {
            // Behind a compensated move whose end is not known yet (LinuxCNC's queue).
            self.comp.hold(self.loc.clone(), cmd);
            return Ok(());
        }
        if self.count >= self.opts.limits.max_canon {
            return Err(self.err(
                1,
                format!(
                    "Program produces too many canonical commands (limit {})",
                    self.opts.limits.max_canon
                ),
            ));
        }
        if self.count.saturating_sub(self.block_start) >= MAX_BLOCK_CANON {
            return Err(self.err(
                1,
                format!(
                    "One block produces more than {MAX_BLOCK_CANON} canonical commands (a \
                     canned cycle's L or Q, a lathe cycle's passes)"
                ),
            ));
        }
        if matches!(
            cmd,
            CanonCmd::StraightTraverse(_)
                | CanonCmd::StraightFeed(_)
                | CanonCmd::ArcFeed { .. }
                | CanonCmd::NurbsFeed { .. }
                | CanonCmd::StraightProbe { .. }
        ) {
            self.s.tlo_at_motion = self.s.tool_offset;
            self.s.comp_tool_left = None;
        }
        self.count += 1;
        match &mut self.out {
            Sink::Canon(v) => v.push(Canon {
                loc: self.loc.clone(),
                cmd,
            }),
            Sink::Trace { buf, seq, spill } => {
                crate::gcode::canon_fmt::write_call(buf, &cmd, seq);
                if let Some(s) = spill {
                    s.take_chunk(buf);
                }
            }
        }
        Ok(())
    }

    /// An error at column `col` of the current line.
    pub(crate) fn err(&self, col: u32, message: impl Into<String>) -> GcodeError {
        GcodeError {
            file: self.loc.file.to_string(),
            line: self.loc.line.max(1),
            col,
            message: message.into(),
        }
    }

    /// An error on another line than the current one: rs274 names the line its search for a
    /// subroutine stopped at (the definition it found, or the end of the file).
    pub(crate) fn err_at(
        &self,
        file: usize,
        line: usize,
        message: impl Into<String>,
    ) -> GcodeError {
        GcodeError {
            file: self
                .files
                .get(file)
                .map_or_else(|| self.loc.file.to_string(), |s| s.name.to_string()),
            line: u32::try_from(line + 1).unwrap_or(u32::MAX),
            col: 1,
            message: message.into(),
        }
    }

    /// The line (0-based) where rs274's forward search of file `f` ends: its closing `%`,
    /// else its last line.
    pub(crate) fn search_end_line(&self, f: usize) -> usize {
        let src = &self.files[f];
        if src.closed {
            src.end
        } else {
            src.end.saturating_sub(1)
        }
    }

    /// Runs the program in `text` to its end.
    pub(crate) fn run(&mut self, name: &str, text: String) -> Result<(), GcodeError> {
        self.load(name, text)?;
        self.resume()
    }

    /// Loads the program in `text` and emits the start-up calls.
    pub(crate) fn load(&mut self, name: &str, text: String) -> Result<(), GcodeError> {
        let name: Arc<str> = Arc::from(name);
        let src = Source::new(name.clone(), text, &self.opts)?;
        // Most programs produce about one command per line.
        let expect = (src.lines.len() + 32).min(self.opts.limits.max_canon);
        match &mut self.out {
            Sink::Canon(v) => v.reserve(expect.min(self.yield_after)),
            // About 75 bytes per call of a CAM program's trace: no regrowth on the way.
            Sink::Trace { buf, spill, .. } => match spill {
                // Written out in chunks: one chunk's worth stays in the cache.
                Some(_) => buf.reserve(2 * crate::gcode::trace_spill::CHUNK),
                None => buf.reserve(expect * 80),
            },
        }
        self.files.push(src);
        self.loc = SourceLoc {
            file: name,
            line: 0,
            col: 1,
        };
        self.preamble()?;
        self.pc = (0, 0);
        Ok(())
    }

    /// True once the program has ended (M2/M30, closing `%`, end of MDI text).
    pub(crate) fn ended(&self) -> bool {
        self.ended
    }

    /// Points the error location at the line the program counter is on (column 1) and
    /// returns the counter: every line executor starts here, so errors name the right line.
    fn locate_pc(&mut self) -> (usize, usize) {
        let (f, l) = self.pc;
        if !Arc::ptr_eq(&self.loc.file, &self.files[f].name) {
            self.loc.file = self.files[f].name.clone();
        }
        self.loc.line = u32::try_from(l + 1).unwrap_or(u32::MAX);
        self.loc.col = 1;
        (f, l)
    }

    /// Executes lines until the program ends or, with live probing, until a line that
    /// probes has been executed (then [`Self::pending_probe`] is set).
    pub(crate) fn resume(&mut self) -> Result<(), GcodeError> {
        while !self.ended {
            let (f, l) = self.locate_pc();
            if l >= self.files[f].end {
                let ended = self.files[0].closed || self.opts.mdi;
                if f == 0 && ended && self.frames.is_empty() {
                    self.emit(CanonCmd::Finish)?;
                    self.emit(CanonCmd::OnReset)?;
                    self.emit(CanonCmd::OnReset)?;
                    self.ended = true;
                    return Ok(());
                }
                let last = self.files[f].end.max(1);
                self.loc.line = u32::try_from(last).unwrap_or(u32::MAX);
                self.loc.file = self.files[f].name.clone();
                return Err(self.err(1, "File ended with no percent sign or program end"));
            }
            self.count_step()?;
            self.block_start = self.count;
            self.step(f, l)?;
            if self.pending_probe.is_some() || self.pending_wait.is_some() {
                return Ok(());
            }
            if matches!(&self.out, Sink::Canon(v) if v.len() >= self.yield_after) {
                return Ok(());
            }
        }
        Ok(())
    }

    /// Counts one executed line against the block limit, and polls for cancellation.
    fn count_step(&mut self) -> Result<(), GcodeError> {
        self.steps += 1;
        if self.steps > self.opts.limits.max_blocks {
            return Err(self.err(
                1,
                format!(
                    "Program executes too many blocks (limit {}); endless loop?",
                    self.opts.limits.max_blocks
                ),
            ));
        }
        if self.steps.is_multiple_of(super::CANCEL_POLL_BLOCKS)
            && (self.opts.cancel.as_ref()).is_some_and(|c| c.load(Ordering::Relaxed))
        {
            return Err(self.err(1, "Interpretation cancelled"));
        }
        Ok(())
    }

    fn preamble(&mut self) -> Result<(), GcodeError> {
        let u = self.s.units;
        self.emit(CanonCmd::UseLengthUnits(u))?;
        self.emit(CanonCmd::SetG5xOffset {
            index: self.s.origin_index,
            offset: motion::pose6(&self.s.g5x),
        })?;
        self.emit(CanonCmd::SetG92Offset(motion::pose6(&self.s.g92)))?;
        self.emit(CanonCmd::SetXyRotation(self.s.rotation))?;
        self.emit(CanonCmd::SetFeedReference)?;
        self.emit(CanonCmd::OnReset)?;
        Ok(())
    }

    /// Executes the line at (f, l) and advances the program counter.
    fn step(&mut self, f: usize, l: usize) -> Result<(), GcodeError> {
        if self.s.synch_pending {
            self.synch();
        }
        let kind = self.files[f].kind.get(l).copied().unwrap_or(0);
        if kind == 2 {
            self.pc = (f, l + 1);
            return Ok(());
        }
        if kind == 1 {
            let Some(o) = self.files[f].olines.get(&l).cloned() else {
                return Err(self.err(1, "internal: O-word line not indexed"));
            };
            let text = self.files[f].line_text(l).to_string();
            let line = parser::parse_line(&text, self.opts.limits.max_expr_depth)
                .map_err(|(c, m)| self.err(c, m))?;
            if line.block_delete && self.opts.block_delete {
                self.pc = (f, l + 1);
                return Ok(());
            }
            self.pc = (f, l + 1);
            return self.exec_o(f, l, &o, &line);
        }
        // LinuxCNC's `;py,` comment: only at the very start of the line, as written.
        if let Some(code) = self.files[f].line_text(l).strip_prefix(";py,") {
            let code = code.trim_end_matches('\r').to_string();
            self.pc = (f, l + 1);
            return self.py_exec(&code);
        }
        let mut line = std::mem::take(&mut self.scratch);
        let parsed = {
            let text = self.files[f].line_text(l);
            parser::parse_line_into(text, self.opts.limits.max_expr_depth, &mut line)
        };
        self.pc = (f, l + 1);
        let r = match parsed {
            Err((c, m)) if self.files[f].line_text(l).contains('\u{FFFD}') => Err(self.err(
                c,
                format!("{m} (the line holds bytes that are not UTF-8 text)"),
            )),
            Err((c, m)) => Err(self.err(c, m)),
            Ok(()) if line.block_delete && self.opts.block_delete => Ok(()),
            Ok(()) => self.exec_line(&line),
        };
        self.scratch = line;
        r
    }

    /// Evaluates `words` into a block of grouped codes and values (the words of an `M98`
    /// line after the `M98` go through this too).
    pub(super) fn block_of(&mut self, words: &[parser::Word]) -> Result<Block, GcodeError> {
        let mut b = Block::default();
        self.block_into(words, &mut b)?;
        Ok(b)
    }

    /// [`block_of`](Self::block_of) into a block the caller holds: the hot path of every
    /// line, where returning the block (some 700 bytes) by value cost a memcpy per line.
    fn block_into(&mut self, words: &[parser::Word], b: &mut Block) -> Result<(), GcodeError> {
        for w in words {
            self.loc.col = w.col;
            let v = expr::eval(&w.value, &*self).map_err(|m| self.err(w.col, m))?;
            b.add(w.letter, v, w.col).map_err(|(c, m)| self.err(c, m))?;
        }
        Ok(())
    }

    fn exec_line(&mut self, line: &Line) -> Result<(), GcodeError> {
        if line.words.is_empty() && line.assigns.is_empty() && line.comments.is_empty() {
            return Ok(());
        }
        if self.fanuc_line(line)? {
            return Ok(());
        }
        let mut b = Block::default();
        self.block_into(&line.words, &mut b)?;
        self.diameter_words(&mut b);
        self.assign(line)?;
        self.loc.col = 1;
        self.exec_block(&b, line)
    }

    /// The parameter assignments of `line`: every value is evaluated before any is set.
    fn assign(&mut self, line: &Line) -> Result<(), GcodeError> {
        let mut sets: Vec<(Result<usize, Box<str>>, f64)> = Vec::with_capacity(line.assigns.len());
        for a in &line.assigns {
            let t = match &a.target {
                Target::Numbered(e) => {
                    let i = expr::eval(e, &*self).map_err(|m| self.err(a.col, m))?;
                    let idx = Params::index(i).map_err(|m| self.err(a.col, m))?;
                    if idx == 0 {
                        return Err(self.err(a.col, "Parameter #0 is read-only"));
                    }
                    Ok(idx)
                }
                Target::Named(n) => {
                    // `#<_ini[…]…>` reads the machine's ini file: read-only when there is
                    // one, as in LinuxCNC (rs274 without an ini file lets it be set).
                    let ini = !self.opts.ini.is_empty() && self.opts.ini.lookup(n).is_some();
                    if ini || self.predefined(n).is_some() {
                        return Err(
                            self.err(a.col, format!("Cannot set read-only parameter #<{n}>"))
                        );
                    }
                    Err(n.clone())
                }
            };
            let v = expr::eval(&a.value, &*self).map_err(|m| self.err(a.col, m))?;
            sets.push((t, v));
        }
        for (t, v) in sets {
            match t {
                Ok(i) => self.p.numbered[i] = v,
                Err(n) => self.p.set_named(&n, v),
            }
        }
        Ok(())
    }

    /// LinuxCNC re-reads the machine position after a tool change, before the next block:
    /// the position becomes the end of the last move as canon saw it, so a tool length
    /// offset applied since that move no longer shifts the program position.
    fn synch(&mut self) {
        if let Some(tool) = self.s.comp_tool_left.take() {
            self.s.pos[..3].copy_from_slice(&tool);
        }
        let d = self.program_shift_of_tool(std::array::from_fn(|i| {
            self.s.tool_offset[i] - self.s.tlo_at_motion[i]
        }));
        for (p, d) in self.s.pos.iter_mut().zip(d) {
            *p += d;
        }
        self.s.tlo_at_motion = self.s.tool_offset;
        self.s.synch_pending = false;
    }

    /// Loads (once) the file that defines subroutine `label` from the search path.
    fn load_sub_file(&mut self, label: &str) -> Result<Option<(usize, usize)>, GcodeError> {
        let mut dirs: Vec<PathBuf> = self.opts.subroutine_path.clone();
        if let Some(d) = &self.opts.program_dir {
            dirs.push(d.clone());
        }
        for d in dirs {
            for cand in [
                format!("{label}.ngc"),
                format!("{}.ngc", label.to_uppercase()),
            ] {
                let path = d.join(&cand);
                if !path.is_file() {
                    continue;
                }
                let text = std::fs::read_to_string(&path).map_err(|e| {
                    self.err(1, format!("Unable to open file {}: {e}", path.display()))
                })?;
                let name: Arc<str> = Arc::from(path.display().to_string());
                let src = Source::new(name, text, &self.opts)?;
                let lines = src.by_label.get(label).cloned().unwrap_or_default();
                let def = lines
                    .iter()
                    .copied()
                    .find(|l| src.olines.get(l).map(|o| o.kind) == Some(OKind::Sub));
                self.files.push(src);
                let fi = self.files.len() - 1;
                return match def {
                    Some(l) => {
                        self.subs.insert(label.into(), (fi, l));
                        Ok(Some((fi, l)))
                    }
                    None => Err(self.err(
                        1,
                        format!("File {} does not define o<{label}> sub", path.display()),
                    )),
                };
            }
        }
        Ok(None)
    }

    /// Value of a predefined (read-only) named parameter.
    fn predefined(&self, name: &str) -> Option<f64> {
        state::predefined(self, name)
    }
}

impl ParamSource for Interp<'_> {
    fn numbered(&self, index: f64) -> Result<f64, String> {
        let i = Params::index(index)?;
        if (params::POS_BASE..params::POS_BASE + 9).contains(&i) {
            let k = i - params::POS_BASE;
            return Ok(if k < 6 { self.s.pos[k] } else { 0.0 });
        }
        Ok(self.p.numbered[i])
    }

    fn named(&self, name: &str) -> Option<f64> {
        if let Some(v) = self.p.named(name) {
            return Some(v);
        }
        if let Some(v) = self.opts.ini.lookup(name) {
            return v;
        }
        self.predefined(name)
    }
}

/// Runs a whole program; the entry point behind `load_str`/`load_file`.
pub(crate) fn interpret(
    name: &str,
    text: String,
    opts: &InterpOptions,
) -> Result<Vec<Canon>, GcodeError> {
    let mut it = Interp::new(Cow::Borrowed(opts))?;
    it.run(name, text)?;
    match it.out {
        Sink::Canon(v) => Ok(v),
        Sink::Trace { .. } => Ok(Vec::new()),
    }
}

/// Runs a whole program; also returns the persistent parameters it leaves (the var file to
/// save).
pub(crate) fn interpret_persistent(
    name: &str,
    text: String,
    opts: &InterpOptions,
) -> Result<(Vec<Canon>, crate::gcode::VarFile), GcodeError> {
    let mut it = Interp::new(Cow::Borrowed(opts))?;
    it.run(name, text)?;
    let vars = it.persistent();
    match it.out {
        Sink::Canon(v) => Ok((v, vars)),
        Sink::Trace { .. } => Ok((Vec::new(), vars)),
    }
}

/// Runs a whole program and returns its rs274-format trace (nothing on error).
pub(crate) fn interpret_trace(
    name: &str,
    text: String,
    opts: &InterpOptions,
    spill: Option<&mut crate::gcode::trace_spill::Spill>,
) -> Result<Vec<u8>, GcodeError> {
    let mut it = Interp::new(Cow::Borrowed(opts))?;
    it.out = Sink::Trace {
        buf: Vec::new(),
        seq: 0,
        spill,
    };
    it.run(name, text)?;
    match it.out {
        Sink::Trace { buf, .. } => Ok(buf),
        Sink::Canon(_) => Ok(Vec::new()),
    }
}
