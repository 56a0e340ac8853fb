//! Statements: code generation of assignments, calls, IF, CASE, FOR, WHILE, REPEAT,
//! EXIT/CONTINUE/RETURN. Split out of the compiler so that statement lowering can be read
//! (and reused by the script fragments) apart from layout and expressions.

use super::*;

impl Compiler<'_> {
    pub(super) fn stmts(&mut self, list: &[Stmt]) {
        for s in list {
            self.stmt(s);
        }
    }

    pub(super) fn stmt(&mut self, s: &Stmt) {
        let span = s.span;
        match &s.kind {
            StmtKind::Assign(lhs, rhs) => self.assign(lhs, rhs, span),
            StmtKind::Call(callee, args) => self.call_stmt(callee, args, span),
            StmtKind::If(arms, els) => {
                let mut ends = Vec::new();
                for (c, body) in arms {
                    self.cond(c);
                    let jz = self.emit(Op::Jz(0), c.span);
                    self.stmts(body);
                    ends.push(self.emit(Op::Jmp(0), span));
                    let h = self.here();
                    self.patch(jz, h);
                }
                if let Some(b) = els {
                    self.stmts(b);
                }
                let h = self.here();
                for e in ends {
                    self.patch(e, h);
                }
            }
            StmtKind::Case(sel, arms, els) => self.case(sel, arms, els.as_deref(), span),
            StmtKind::For {
                var,
                from,
                to,
                by,
                body,
            } => self.for_loop(var, from, to, by.as_ref(), body, span),
            StmtKind::While(c, body) => {
                let top = self.here();
                self.cond(c);
                let jz = self.emit(Op::Jz(0), c.span);
                self.loops.push(Loop::default());
                self.stmts(body);
                self.emit(Op::Jmp(top), span);
                let l = self.loops.pop().unwrap_or_default();
                let end = self.here();
                self.patch(jz, end);
                self.close_loop(l, top, end);
            }
            StmtKind::Repeat(body, c) => {
                let top = self.here();
                self.loops.push(Loop::default());
                self.stmts(body);
                let cont = self.here();
                self.cond(c);
                self.emit(Op::Jz(top), c.span);
                let l = self.loops.pop().unwrap_or_default();
                let end = self.here();
                self.close_loop(l, cont, end);
            }
            StmtKind::Exit | StmtKind::Continue => {
                let j = self.emit(Op::Jmp(0), span);
                let exit = matches!(s.kind, StmtKind::Exit);
                match self.loops.last_mut() {
                    Some(l) if exit => l.exits.push(j),
                    Some(l) => l.conts.push(j),
                    None => self.err(
                        span,
                        format!("{} outside a loop", if exit { "EXIT" } else { "CONTINUE" }),
                    ),
                }
            }
            StmtKind::Return => {
                self.emit(Op::Ret, span);
            }
        }
    }

    pub(super) fn close_loop(&mut self, l: Loop, cont: u32, end: u32) {
        for j in l.exits {
            self.patch(j, end);
        }
        for j in l.conts {
            self.patch(j, cont);
        }
    }

    /// A BOOL condition.
    pub(super) fn cond(&mut self, c: &Expr) {
        let t = self.expr(c, Some(Ty::Bool));
        self.coerce(t, Ty::Bool, c.span);
    }

    pub(super) fn temp(&mut self) -> u32 {
        self.alloc(&[0])
    }

    pub(super) fn case(
        &mut self,
        sel: &Expr,
        arms: &[(Vec<CaseLabel>, Vec<Stmt>)],
        els: Option<&[Stmt]>,
        span: Span,
    ) {
        let st = self.expr(sel, None);
        if !(st.int().is_some() || matches!(st, Ty::Enum(_)) || is_void(st)) {
            let n = self.ty_name(st);
            self.err(
                sel.span,
                format!("CASE selector must be an integer or enumeration, found {n}"),
            );
        }
        let t = self.temp();
        self.emit(Op::StoreG(t), sel.span);
        let cmp_u = st.int().is_some_and(|k| k.bits() == 64 && !k.signed());
        let mut seen: Vec<(i128, i128, Span)> = Vec::new();
        let mut ends = Vec::new();
        for (labels, body) in arms {
            let mut to_body = Vec::new();
            for l in labels {
                let (lo, hi, lspan) = match l {
                    CaseLabel::One(e) => {
                        let v = self.case_value(e, st);
                        (v, v, e.span)
                    }
                    CaseLabel::Range(a, b) => {
                        (self.case_value(a, st), self.case_value(b, st), a.span)
                    }
                };
                let (Some(lo), Some(hi)) = (lo, hi) else {
                    continue;
                };
                if let Some(prev) = seen.iter().find(|(a, b, _)| lo <= *b && *a <= hi) {
                    let msg = format!("CASE label overlaps the label at line {}", prev.2.line);
                    self.err(lspan, msg);
                }
                seen.push((lo, hi, lspan));
                let cmp = |c| if cmp_u { Op::CmpU(c) } else { Op::CmpI(c) };
                if lo == hi {
                    self.emit(Op::LoadG(t), lspan);
                    self.emit(Op::Push(lo as i64 as u64), lspan);
                    self.emit(cmp(Cmp::Eq), lspan);
                } else {
                    self.emit(Op::LoadG(t), lspan);
                    self.emit(Op::Push(lo as i64 as u64), lspan);
                    self.emit(cmp(Cmp::Ge), lspan);
                    self.emit(Op::LoadG(t), lspan);
                    self.emit(Op::Push(hi as i64 as u64), lspan);
                    self.emit(cmp(Cmp::Le), lspan);
                    self.emit(Op::And, lspan);
                }
                to_body.push(self.emit(Op::Jnz(0), lspan));
            }
            let skip = self.emit(Op::Jmp(0), span);
            let h = self.here();
            for j in to_body {
                self.patch(j, h);
            }
            self.stmts(body);
            ends.push(self.emit(Op::Jmp(0), span));
            let h = self.here();
            self.patch(skip, h);
        }
        if let Some(b) = els {
            self.stmts(b);
        }
        let h = self.here();
        for e in ends {
            self.patch(e, h);
        }
    }

    pub(super) fn case_value(&mut self, e: &Expr, st: Ty) -> Option<i128> {
        match (self.const_eval(e), st) {
            (Some(CVal::Int(v)), Ty::Int(k)) => {
                if v < k.min() || v > k.max() {
                    self.err(
                        e.span,
                        format!("CASE label {v} is out of the range of {}", k.name()),
                    );
                }
                Some(v)
            }
            (Some(CVal::Enum(a, v)), Ty::Enum(b)) if a == b => Some(v as i128),
            (_, Ty::Void) => None,
            _ => {
                self.err(
                    e.span,
                    "CASE label must be a constant of the selector's type",
                );
                None
            }
        }
    }

    pub(super) fn for_loop(
        &mut self,
        var: &Ident,
        from: &Expr,
        to: &Expr,
        by: Option<&Expr>,
        body: &[Stmt],
        span: Span,
    ) {
        let Some(sym) = self.lookup(&var.key()) else {
            self.err(var.span, format!("unknown variable {}", var.name));
            return;
        };
        let Some(k) = sym.ty.int().filter(|_| !sym.inout && !sym.constant) else {
            self.err(
                var.span,
                format!(
                    "FOR variable {} must be a writable integer variable",
                    var.name
                ),
            );
            return;
        };
        let ty = sym.ty;
        let place = sym.place;
        let t = self.expr(from, Some(ty));
        self.coerce(t, ty, from.span);
        self.store(place, span);
        let end = self.temp();
        let t = self.expr(to, Some(ty));
        self.coerce(t, ty, to.span);
        self.emit(Op::StoreG(end), to.span);
        let step_const = match by {
            None => Some(1),
            Some(e) => match self.const_eval(e) {
                Some(CVal::Int(v)) if v != 0 => Some(v),
                Some(CVal::Int(_)) => {
                    self.err(e.span, "FOR step must not be zero");
                    Some(1)
                }
                _ => None,
            },
        };
        let step = self.temp();
        if let Some(e) = by {
            let t = self.expr(e, Some(ty));
            self.coerce(t, ty, e.span);
            self.emit(Op::StoreG(step), e.span);
        } else {
            self.emit(Op::Push(1), span);
            self.emit(Op::StoreG(step), span);
        }
        let cmp = |c| {
            if k.bits() == 64 && !k.signed() {
                Op::CmpU(c)
            } else {
                Op::CmpI(c)
            }
        };
        let top = self.here();
        let mut exits = Vec::new();
        match step_const {
            Some(s) => {
                self.load(place, span);
                self.emit(Op::LoadG(end), span);
                self.emit(cmp(if s > 0 { Cmp::Gt } else { Cmp::Lt }), span);
                exits.push(self.emit(Op::Jnz(0), span));
            }
            None => {
                // Direction by the sign of the step, known only at run time.
                self.emit(Op::LoadG(step), span);
                self.emit(Op::Push(0), span);
                self.emit(Op::CmpI(Cmp::Lt), span);
                let neg = self.emit(Op::Jnz(0), span);
                self.load(place, span);
                self.emit(Op::LoadG(end), span);
                self.emit(cmp(Cmp::Gt), span);
                exits.push(self.emit(Op::Jnz(0), span));
                let to_body = self.emit(Op::Jmp(0), span);
                let h = self.here();
                self.patch(neg, h);
                self.load(place, span);
                self.emit(Op::LoadG(end), span);
                self.emit(cmp(Cmp::Lt), span);
                exits.push(self.emit(Op::Jnz(0), span));
                let h = self.here();
                self.patch(to_body, h);
            }
        }
        self.loops.push(Loop::default());
        self.stmts(body);
        let cont = self.here();
        self.load(place, span);
        self.emit(Op::LoadG(step), span);
        self.emit(Op::Add(k), span);
        self.store(place, span);
        self.emit(Op::Jmp(top), span);
        let l = self.loops.pop().unwrap_or_default();
        let end_pc = self.here();
        for j in exits {
            self.patch(j, end_pc);
        }
        self.close_loop(l, cont, end_pc);
    }
}
