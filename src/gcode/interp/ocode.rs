//! O-word control flow: subroutines (sub/endsub/call/return, with arguments in #1–#30 and
//! per-call local named parameters, also from files on the subroutine path), if/elseif/
//! else/endif, while/endwhile, do/while, repeat/endrepeat, break and continue.
//!
//! Statements are matched by label, as LinuxCNC does: the file's O-lines are indexed by
//! label when the file is loaded, so a jump is a search in a short list.

use super::{Frame, Interp};
use crate::gcode::expr;
use crate::gcode::parser::{Line, OKind, OStmt};
use crate::gcode::GcodeError;
use std::collections::HashMap;

impl Interp<'_> {
    /// Depth of subroutine calls (0 in the main program).
    pub(crate) fn call_level(&self) -> usize {
        self.frames.len()
    }

    /// True when the main file opened with `%` but has no closing `%`.
    pub(super) fn percent_unclosed(&self) -> bool {
        self.files.first().is_some_and(|f| f.percent && !f.closed)
    }

    /// Stops the program loop (M2/M30).
    pub(super) fn end_program(&mut self) {
        self.ended = true;
    }

    /// Same-label statement lines of file `f`.
    pub(super) fn label_lines(&self, f: usize, label: &str) -> Vec<usize> {
        let src = &self.files[f];
        let mut v = src.by_label.get(label).cloned().unwrap_or_default();
        if !src.computed.is_empty() {
            // Computed labels take the parameters' values at the time of the search, as
            // rs274 evaluates them when it reads the line.
            for &l in &src.computed {
                let matches = src
                    .olines
                    .get(&l)
                    .and_then(|o| o.label_expr.as_ref().map(|e| (e, o.col)))
                    .is_some_and(|(e, col)| {
                        self.computed_label(e, col).is_ok_and(|c| &*c == label)
                    });
                if matches {
                    v.push(l);
                }
            }
            v.sort_unstable();
        }
        v
    }

    fn kind_at(&self, f: usize, l: usize) -> Option<OKind> {
        self.files[f].olines.get(&l).map(|o| o.kind)
    }

    /// Next same-label line after `l` whose kind is in `kinds`.
    fn find_next(&self, f: usize, l: usize, label: &str, kinds: &[OKind]) -> Option<usize> {
        self.label_lines(f, label)
            .into_iter()
            .find(|&x| x > l && self.kind_at(f, x).is_some_and(|k| kinds.contains(&k)))
    }

    /// Previous same-label line before `l` whose kind is in `kinds`.
    fn find_prev(&self, f: usize, l: usize, label: &str, kinds: &[OKind]) -> Option<usize> {
        self.label_lines(f, label)
            .into_iter()
            .rev()
            .find(|&x| x < l && self.kind_at(f, x).is_some_and(|k| kinds.contains(&k)))
    }

    /// An `else`, `elseif` or `endif` needs an `if` with its label before it: rs274 refuses
    /// one whose label it has not seen ("undefined O-word label") or has seen on a loop.
    fn check_opened(&self, f: usize, l: usize, label: &str, o: &OStmt) -> Result<(), GcodeError> {
        if self.find_prev(f, l, label, &[OKind::If]).is_some() {
            return Ok(());
        }
        let looped = [OKind::While, OKind::Do, OKind::Repeat];
        let why = if self.find_prev(f, l, label, &looped).is_some() {
            "no matching label: the label opens a loop, not an if"
        } else {
            "undefined O-word label: no if with this label before it"
        };
        Err(self.err(
            o.col,
            format!("o<{label}> {:?}: {why}", o.kind).to_lowercase(),
        ))
    }

    /// A `while` is the tail of a `do` loop when the nearest earlier loop statement with its
    /// label is a `do`.
    fn is_do_tail(&self, f: usize, l: usize, label: &str) -> bool {
        self.find_prev(f, l, label, &[OKind::Do, OKind::While, OKind::EndWhile])
            .is_some_and(|x| self.kind_at(f, x) == Some(OKind::Do))
    }

    fn cond(&self, o: &OStmt) -> Result<f64, GcodeError> {
        let e = o.args.first().ok_or_else(|| {
            self.err(
                o.col,
                format!("Missing [condition] after o<{}> {:?}", o.label, o.kind).to_lowercase(),
            )
        })?;
        expr::eval(e, self).map_err(|m| self.err(o.col, m))
    }

    fn count_iteration(&mut self, f: usize, l: usize, o: &OStmt) -> Result<(), GcodeError> {
        let key = (f, l, self.frames.len());
        let n = self.loop_iters.entry(key).or_insert(0);
        *n += 1;
        if *n > self.opts.limits.max_loop_iterations {
            return Err(self.err(
                o.col,
                format!(
                    "Loop o<{}> exceeded {} iterations",
                    o.label, self.opts.limits.max_loop_iterations
                ),
            ));
        }
        Ok(())
    }

    fn leave_loop(&mut self, f: usize, head: usize) {
        let key = (f, head, self.frames.len());
        self.loop_iters.remove(&key);
        self.repeats.remove(&key);
    }

    /// The label of `o[expr]`: the value as an integer label, like `o123`.
    fn computed_label(&self, e: &expr::Expr, col: u32) -> Result<Box<str>, GcodeError> {
        let v = expr::eval(e, self).map_err(|m| self.err(col, m))?;
        let n = v.round();
        if (v - n).abs() > 1e-4 || !(0.0..4.0e9).contains(&n) {
            return Err(self.err(
                col,
                format!("Computed O-word label {v} is not a non-negative integer"),
            ));
        }
        Ok(format!("{}", n as u64).into())
    }

    pub(super) fn exec_o(
        &mut self,
        f: usize,
        l: usize,
        o: &OStmt,
        line: &Line,
    ) -> Result<(), GcodeError> {
        // Comments on O lines are not executed (as in LinuxCNC).
        let _ = line;
        self.loc.col = o.col;
        let label = match &o.label_expr {
            Some(e) => self.computed_label(e, o.col)?,
            None => o.label.clone(),
        };
        let missing = |me: &Self, what: &str| me.err(o.col, format!("o<{label}> {what}"));
        match o.kind {
            OKind::Sub => {
                if self.subs.get(&label) == Some(&(f, l)) {
                    // a call found this definition ahead of the program, which now runs
                    // into it (or passes it a second time): rs274 refuses that
                    return Err(self.err(
                        o.col,
                        format!("Subroutine o<{label}> found in illegal location: the program runs into a definition it has already read (end the main program with M2 or M30 before its subroutines)"),
                    ));
                }
                self.subs.insert(label.clone(), (f, l));
                let end = self
                    .find_next(f, l, &label, &[OKind::EndSub])
                    .ok_or_else(|| missing(self, "sub has no matching endsub"))?;
                // rs274 runs the endsub while skipping the definition, as if the
                // subroutine had returned: its value (or nothing, which clears both) lands
                // in #<_value> and #<_value_returned>.
                match self.files[f]
                    .olines
                    .get(&end)
                    .and_then(|o| o.args.first().cloned())
                {
                    Some(e) => {
                        let v = expr::eval(&e, self).map_err(|m| self.err(o.col, m))?;
                        self.s.value = v;
                        self.s.value_returned = 1.0;
                    }
                    None => {
                        self.s.value = 0.0;
                        self.s.value_returned = 0.0;
                    }
                }
                self.pc = (f, end + 1);
                Ok(())
            }
            OKind::ProgramNumber => Ok(()),
            OKind::EndSub | OKind::Return => {
                let Some(top) = self.frames.last() else {
                    return Err(missing(self, "endsub/return outside of a subroutine call"));
                };
                if top.fanuc.is_some() {
                    return Err(self.err(
                        o.col,
                        "Fanuc 'O....' subroutine definition must end with 'M99'",
                    ));
                }
                // A return leaves the subroutine being executed whatever its label (CAM
                // and hand-written code write `oN return` inside `oN if`), as in rs274.
                if o.kind == OKind::EndSub && top.label != label {
                    return Err(missing(
                        self,
                        "return/endsub does not match the subroutine being executed",
                    ));
                }
                match o.args.first() {
                    Some(e) => {
                        let v = expr::eval(e, self).map_err(|m| self.err(o.col, m))?;
                        self.s.value = v;
                        self.s.value_returned = 1.0;
                    }
                    // rs274 clears #<_value> too when a subroutine returns nothing.
                    None => {
                        self.s.value = 0.0;
                        self.s.value_returned = 0.0;
                    }
                }
                self.leave_frame()
            }
            OKind::Call => {
                let mut args = Vec::with_capacity(o.args.len());
                for e in &o.args {
                    args.push(expr::eval(e, self).map_err(|m| self.err(o.col, m))?);
                }
                if args.len() > 30 {
                    return Err(missing(self, "call has more than 30 arguments"));
                }
                if self.frames.len() >= self.opts.limits.max_call_depth {
                    return Err(self.err(
                        o.col,
                        format!(
                            "Subroutine calls nested too deeply (limit {})",
                            self.opts.limits.max_call_depth
                        ),
                    ));
                }
                // A Python procedure of the ini's `oword` module comes first, as in rs274.
                if self.py_oword(&label, &args)? {
                    return Ok(());
                }
                let call = self.loc.line;
                let target = match self.subs.get(&label).copied() {
                    Some(t) => t,
                    None => {
                        // A definition later in a loaded file, else a file on the path.
                        let mut found = None;
                        for (fi, src) in self.files.iter().enumerate() {
                            if let Some(lines) = src.by_label.get(&label) {
                                if let Some(&dl) = lines
                                    .iter()
                                    .find(|x| src.olines.get(x).map(|o| o.kind) == Some(OKind::Sub))
                                {
                                    found = Some((fi, dl));
                                    break;
                                }
                            }
                        }
                        let numbered = self.files.iter().enumerate().find_map(|(fi, src)| {
                            src.by_label.get(&label).and_then(|ls| {
                                ls.iter()
                                    .find(|x| {
                                        src.olines.get(x).map(|o| o.kind)
                                            == Some(OKind::ProgramNumber)
                                    })
                                    .map(|&l| (fi, l))
                            })
                        });
                        match (found, numbered) {
                            (Some(t), _) => {
                                // rs274 registers the definition its search found, so the
                                // program must not run into it later (see OKind::Sub)
                                self.subs.insert(label.clone(), t);
                                t
                            }
                            // rs274 stops at the numbered program its search finds
                            (None, Some((fi, l))) => {
                                return Err(self.err_at(
                                    fi,
                                    l,
                                    format!("Fanuc 'O....' subroutine must be called with 'M98' (O{label} is called by 'O{label} call' at line {call})"),
                                ))
                            }
                            (None, None) => match self.load_sub_file(&label)? {
                                Some(t) => t,
                                None => {
                                    let f = self.pc.0;
                                    return Err(self.err_at(
                                        f,
                                        self.search_end_line(f),
                                        format!("Failed to find subroutine o<{label}> before the end of the file, nor a file {label}.ngc on the subroutine path (called at line {call})"),
                                    ));
                                }
                            },
                        }
                    }
                };
                self.enter_sub(label.clone(), target, &args);
                Ok(())
            }
            OKind::If => {
                let mut at = l;
                let mut c = self.cond(o)?;
                loop {
                    if c != 0.0 {
                        self.pc = (f, at + 1);
                        return Ok(());
                    }
                    let next = self
                        .find_next(f, at, &label, &[OKind::ElseIf, OKind::Else, OKind::EndIf])
                        .ok_or_else(|| missing(self, "if has no matching endif"))?;
                    match self.kind_at(f, next) {
                        Some(OKind::ElseIf) => {
                            at = next;
                            let stmt = self.files[f].olines.get(&next).cloned();
                            self.loc.line = u32::try_from(next + 1).unwrap_or(u32::MAX);
                            c = match stmt {
                                Some(s) => self.cond(&s)?,
                                None => 0.0,
                            };
                        }
                        _ => {
                            self.pc = (f, next + 1);
                            return Ok(());
                        }
                    }
                }
            }
            OKind::ElseIf | OKind::Else => {
                self.check_opened(f, l, &label, o)?;
                // Reached by falling out of a taken branch: skip to endif. rs274 still
                // evaluates an elseif condition here (its errors count).
                if o.kind == OKind::ElseIf {
                    self.cond(o)?;
                }
                let end = self
                    .find_next(f, l, &label, &[OKind::EndIf])
                    .ok_or_else(|| missing(self, "else/elseif has no matching endif"))?;
                self.pc = (f, end + 1);
                Ok(())
            }
            OKind::EndIf => self.check_opened(f, l, &label, o),
            OKind::Do => Ok(()),
            OKind::While => {
                let c = self.cond(o)?;
                if self.is_do_tail(f, l, &label) {
                    let head = self
                        .find_prev(f, l, &label, &[OKind::Do])
                        .ok_or_else(|| missing(self, "while has no do"))?;
                    if c != 0.0 {
                        self.count_iteration(f, head, o)?;
                        self.pc = (f, head + 1);
                    } else {
                        self.leave_loop(f, head);
                    }
                    return Ok(());
                }
                if c != 0.0 {
                    self.count_iteration(f, l, o)?;
                } else {
                    let end = self
                        .find_next(f, l, &label, &[OKind::EndWhile])
                        .ok_or_else(|| missing(self, "while has no matching endwhile"))?;
                    self.leave_loop(f, l);
                    self.pc = (f, end + 1);
                }
                Ok(())
            }
            OKind::EndWhile => {
                let head = self
                    .find_prev(f, l, &label, &[OKind::While])
                    .ok_or_else(|| missing(self, "endwhile has no matching while"))?;
                self.pc = (f, head);
                Ok(())
            }
            OKind::Repeat => {
                let key = (f, l, self.frames.len());
                let left = match self.repeats.get(&key) {
                    Some(&n) => n,
                    None => {
                        let n = self.cond(o)?;
                        if n <= 0.0 {
                            0
                        } else {
                            n.round() as u64
                        }
                    }
                };
                if left == 0 {
                    let end = self
                        .find_next(f, l, &label, &[OKind::EndRepeat])
                        .ok_or_else(|| missing(self, "repeat has no matching endrepeat"))?;
                    self.leave_loop(f, l);
                    self.pc = (f, end + 1);
                } else {
                    self.count_iteration(f, l, o)?;
                    self.repeats.insert(key, left - 1);
                }
                Ok(())
            }
            OKind::EndRepeat => {
                let head = self
                    .find_prev(f, l, &label, &[OKind::Repeat])
                    .ok_or_else(|| missing(self, "endrepeat has no matching repeat"))?;
                self.pc = (f, head);
                Ok(())
            }
            OKind::Break => {
                let end = self
                    .find_next(
                        f,
                        l,
                        &label,
                        &[OKind::EndWhile, OKind::EndRepeat, OKind::While],
                    )
                    .ok_or_else(|| missing(self, "break outside of a loop"))?;
                if let Some(head) =
                    self.find_prev(f, l, &label, &[OKind::While, OKind::Do, OKind::Repeat])
                {
                    self.leave_loop(f, head);
                }
                self.pc = (f, end + 1);
                Ok(())
            }
            OKind::Continue => {
                let head = self
                    .find_prev(f, l, &label, &[OKind::While, OKind::Do, OKind::Repeat])
                    .ok_or_else(|| missing(self, "continue outside of a loop"))?;
                match self.kind_at(f, head) {
                    Some(OKind::Do) => {
                        let tail = self
                            .find_next(f, l, &label, &[OKind::While])
                            .ok_or_else(|| missing(self, "do has no while"))?;
                        self.pc = (f, tail);
                    }
                    _ => self.pc = (f, head),
                }
                Ok(())
            }
        }
    }

    /// Enters subroutine `label`, defined at `target` (file, line of its `sub`), with
    /// `args`: the callee sees them in #1.. and 0 in the rest of #1-#30; it returns to the
    /// current program counter.
    pub(super) fn enter_sub(&mut self, label: Box<str>, target: (usize, usize), args: &[f64]) {
        let mut saved = [0.0; 30];
        saved.copy_from_slice(&self.p.numbered[1..31]);
        for i in 0..30 {
            self.p.numbered[1 + i] = args.get(i).copied().unwrap_or(0.0);
        }
        self.frames.push(Frame {
            ret: self.pc,
            saved,
            label,
            fanuc: None,
        });
        self.p.locals.push(HashMap::new());
        self.s.saved.push(None);
        self.s.auto_restore.push(false);
        self.pc = (target.0, target.1 + 1);
    }

    /// Returns from the innermost call: M73's auto-restore, the caller's `#1`–`#30` (not
    /// for `M98` calls, which share them), its locals and its loop state.
    pub(super) fn leave_frame(&mut self) -> Result<(), GcodeError> {
        // M73 in this subroutine: its saved modal state comes back on return.
        let level = self.frames.len();
        if self.s.auto_restore.get(level).copied().unwrap_or(false) {
            if let Some(Some(saved)) = self.s.saved.get(level).cloned() {
                self.restore_modal(&saved)?;
            }
        }
        let Some(frame) = self.frames.pop() else {
            return Ok(());
        };
        self.s.auto_restore.pop();
        if frame.fanuc.is_none() {
            self.p.numbered[1..31].copy_from_slice(&frame.saved);
        }
        self.p.locals.pop();
        self.s.saved.pop();
        let level = self.frames.len();
        self.loop_iters.retain(|k, _| k.2 <= level);
        self.repeats.retain(|k, _| k.2 <= level);
        self.pc = frame.ret;
        Ok(())
    }
}
