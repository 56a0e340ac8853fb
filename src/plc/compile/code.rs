//! Code generation for places and expressions: loads, stores and addresses, assignment,
//! implicit conversions, literals, operators.

use super::*;
use crate::plc::builtins;
use crate::plc::diag::Span;
use crate::plc::expr::{BinOp, Expr, ExprKind, Ident, Lit, UnOp};
use crate::plc::types::{common, elementary, implicit, IntKind, Ty};
use crate::plc::vm::{Cmp, Op};

impl Compiler<'_> {
    pub(crate) fn emit(&mut self, op: Op, span: Span) -> usize {
        self.ops.push(op);
        self.spans.push(span);
        self.ops.len() - 1
    }

    pub(super) fn here(&self) -> u32 {
        self.ops.len() as u32
    }

    pub(super) fn patch(&mut self, at: usize, target: u32) {
        match &mut self.ops[at] {
            Op::Jmp(t) | Op::Jz(t) | Op::Jnz(t) => *t = target,
            _ => unreachable!("patching a non-jump"),
        }
    }

    pub(super) fn body(&mut self, pou: usize, members: &[Member]) -> u32 {
        let p = &self.unit.pous[pou];
        self.enter_scope(pou, members);
        let entry = self.here();
        self.stmts(&p.body);
        self.emit(Op::Ret, p.name.span);
        entry
    }

    /// Makes the members of POU `pou` the local symbols of the code emitted next.
    pub(super) fn enter_scope(&mut self, pou: usize, members: &[Member]) {
        self.cur_pou = pou;
        self.locals.clear();
        self.peek_cache.clear();
        for m in members {
            let sym = Sym {
                ty: m.ty,
                place: Place::L(m.off),
                constant: m.constant,
                inout: m.section == Section::InOut,
                cval: m.cval,
            };
            self.locals.insert(m.name.to_ascii_uppercase(), sym);
        }
    }

    pub(super) fn lookup(&self, key: &str) -> Option<Sym> {
        self.locals
            .get(key)
            .or_else(|| self.globals.get(key))
            .cloned()
    }

    pub(crate) fn load(&mut self, p: Place, span: Span) {
        let op = match p {
            Place::L(o) => Op::LoadL(o),
            Place::G(a) => Op::LoadG(a),
            Place::Dyn(k) => Op::LoadInd(k),
        };
        self.emit(op, span);
    }

    pub(crate) fn store(&mut self, p: Place, span: Span) {
        let op = match p {
            Place::L(o) => Op::StoreL(o),
            Place::G(a) => Op::StoreG(a),
            Place::Dyn(k) => Op::StoreInd(k),
        };
        self.emit(op, span);
    }

    pub(crate) fn addr(&mut self, p: Place, span: Span) {
        match p {
            Place::L(o) => {
                self.emit(Op::AddrL(o), span);
            }
            Place::G(a) => {
                self.emit(Op::AddrG(a), span);
            }
            Place::Dyn(0) => {}
            Place::Dyn(k) => {
                self.emit(Op::Push(k as u64), span);
                self.emit(Op::Add(IntKind::LInt), span);
            }
        }
    }

    /// Resolves a variable reference. Emits code for dynamic parts (address on the stack).
    /// Returns the place, the type, and whether it is read-only.
    pub(super) fn place(&mut self, e: &Expr) -> Option<(Place, Ty, bool)> {
        match &e.kind {
            ExprKind::Name(id) => {
                let Some(sym) = self.lookup(&id.key()) else {
                    self.unknown_name(id);
                    return None;
                };
                if sym.inout {
                    self.load(sym.place, e.span);
                    return Some((Place::Dyn(0), sym.ty, sym.constant));
                }
                Some((sym.place, sym.ty, sym.constant))
            }
            ExprKind::Member(base, m) => {
                let (p, t, ro) = self.place(base)?;
                let (Ty::Struct(c) | Ty::Fb(c)) = t else {
                    let n = self.ty_name(t);
                    self.err(m.span, format!("{n} has no members (.{})", m.name));
                    return None;
                };
                let comp = &self.comps[c as usize];
                let found = comp
                    .members
                    .iter()
                    .find(|x| !x.hidden && x.name.eq_ignore_ascii_case(&m.name))
                    .cloned();
                let is_fb = matches!(t, Ty::Fb(_));
                match found {
                    Some(x) if !is_fb || matches!(x.section, Section::Input | Section::Output) => {
                        // Outputs of a block are read-only from outside it.
                        let ro = ro || (is_fb && x.section == Section::Output);
                        Some((p.offset(x.off), x.ty, ro))
                    }
                    Some(_) => {
                        let cn = comp.name.clone();
                        self.err(
                            m.span,
                            format!(
                                "{}.{} is internal to the block {cn}",
                                base_name(base),
                                m.name
                            ),
                        );
                        None
                    }
                    None => {
                        let cn = comp.name.clone();
                        self.err(m.span, format!("{cn} has no member {}", m.name));
                        None
                    }
                }
            }
            ExprKind::Index(base, idx) => {
                let (mut p, t, ro) = self.place(base)?;
                let Ty::Array(a) = t else {
                    let n = self.ty_name(t);
                    self.err(e.span, format!("{n} is not an array"));
                    return None;
                };
                let arr = self.arrays[a as usize].clone();
                if idx.len() != arr.dims.len() {
                    self.err(
                        e.span,
                        format!(
                            "array has {} dimensions, {} indexes given",
                            arr.dims.len(),
                            idx.len()
                        ),
                    );
                    return None;
                }
                // Strides: the last index varies fastest.
                let mut stride = arr.elem_size;
                let mut strides = vec![0; arr.dims.len()];
                for (i, d) in arr.dims.iter().enumerate().rev() {
                    strides[i] = stride;
                    stride *= d.1;
                }
                for (i, ix) in idx.iter().enumerate() {
                    let (lo, len) = arr.dims[i];
                    if let Some(CVal::Int(v)) = self.const_eval(ix) {
                        if v < lo as i128 || v >= lo as i128 + len as i128 {
                            self.err(
                                ix.span,
                                format!("index {v} is outside {lo}..{}", lo + len as i64 - 1),
                            );
                            return None;
                        }
                        p = p.offset((v as i64 - lo) as u32 * strides[i]);
                        continue;
                    }
                    if !matches!(p, Place::Dyn(_)) {
                        self.addr(p, e.span);
                        p = Place::Dyn(0);
                    }
                    let t = self.expr(ix, Some(Ty::Int(IntKind::DInt)));
                    if t.int().is_none() && !is_void(t) {
                        let n = self.ty_name(t);
                        self.err(
                            ix.span,
                            format!("array index must be an integer, found {n}"),
                        );
                    }
                    self.emit(
                        Op::Index {
                            lo: lo as i32,
                            len,
                            stride: strides[i],
                        },
                        ix.span,
                    );
                }
                Some((p, arr.elem, ro))
            }
            _ => {
                self.err(e.span, "expected a variable");
                None
            }
        }
    }

    pub(super) fn unknown_name(&mut self, id: &Ident) {
        let key = id.key();
        let msg = if self.pous.contains_key(&key) || builtins::is_builtin(&key) {
            format!("{} is a function or block, not a variable", id.name)
        } else {
            format!("unknown variable {}", id.name)
        };
        self.err(id.span, msg);
    }

    pub(super) fn assign(&mut self, lhs: &Expr, rhs: &Expr, span: Span) {
        // `F := x` inside FUNCTION F sets the result.
        if let ExprKind::Name(id) = &lhs.kind {
            if let Some(f) = self.funcs.values().find(|f| f.pou == self.cur_pou) {
                if f.name.eq_ignore_ascii_case(&id.name) {
                    let (ret, res) = (f.ret, f.result);
                    let t = self.expr(rhs, Some(ret));
                    self.coerce(t, ret, rhs.span);
                    self.emit(Op::StoreL(res), span);
                    return;
                }
            }
        }
        if let ExprKind::Bit(base, n) = &lhs.kind {
            let Some((p, t, ro)) = self.place(base) else {
                return;
            };
            self.check_bit(t, *n, lhs.span);
            if ro {
                self.err(lhs.span, "cannot assign to a constant or a block output");
            }
            let t = self.expr(rhs, Some(Ty::Bool));
            self.coerce(t, Ty::Bool, rhs.span);
            let op = match p {
                Place::L(o) => Op::SetBitL(o, *n),
                Place::G(a) => Op::SetBitG(a, *n),
                Place::Dyn(k) => Op::SetBitInd(k, *n),
            };
            self.emit(op, span);
            return;
        }
        let Some((p, t, ro)) = self.place(lhs) else {
            return;
        };
        if ro {
            self.err(
                lhs.span,
                format!(
                    "cannot assign to {}: it is a constant or a block output",
                    base_name(lhs)
                ),
            );
        }
        if t.scalar() {
            let rt = self.expr(rhs, Some(t));
            self.coerce(rt, t, rhs.span);
            self.store(p, span);
            return;
        }
        if is_void(t) {
            return;
        }
        // Whole structures and arrays: copy cells.
        if matches!(t, Ty::Fb(_)) {
            self.err(span, "function block instances cannot be assigned");
            return;
        }
        self.addr(p, span);
        let Some((q, rt, _)) = self.place(rhs) else {
            return;
        };
        if rt != t && !self.same_shape(rt, t) {
            let (a, b) = (self.ty_name(t), self.ty_name(rt));
            self.err(rhs.span, format!("type mismatch: cannot assign {b} to {a}"));
        }
        self.addr(q, span);
        let n = self.size_of(t);
        self.emit(Op::Copy(n), span);
    }

    pub(super) fn same_shape(&self, a: Ty, b: Ty) -> bool {
        match (a, b) {
            (Ty::Array(x), Ty::Array(y)) => {
                let (x, y) = (&self.arrays[x as usize], &self.arrays[y as usize]);
                x.dims == y.dims && (x.elem == y.elem || self.same_shape(x.elem, y.elem))
            }
            _ => a == b,
        }
    }

    pub(super) fn check_bit(&mut self, t: Ty, n: u8, span: Span) {
        match t.int() {
            Some(k) if (n as u32) < k.bits() => {}
            Some(k) => self.err(
                span,
                format!("bit {n} is outside {} ({} bits)", k.name(), k.bits()),
            ),
            None if is_void(t) => {}
            None => {
                let tn = self.ty_name(t);
                self.err(
                    span,
                    format!("bit access needs a bit string or integer, found {tn}"),
                );
            }
        }
    }

    /// Emits the conversion of a value of `from` to `to`, or reports the mismatch.
    pub(crate) fn coerce(&mut self, from: Ty, to: Ty, span: Span) {
        if from == to || is_void(from) || is_void(to) {
            return;
        }
        if implicit(from, to) {
            match (from, to) {
                (Ty::Int(_), Ty::Real) => {
                    self.emit(Op::IToF(true), span);
                }
                (Ty::Int(_), Ty::LReal) => {
                    self.emit(Op::IToF(false), span);
                }
                _ => {}
            }
            return;
        }
        let (f, t) = (self.ty_name(from), self.ty_name(to));
        let hint =
            if from.scalar() && to.scalar() && from != Ty::Time && !matches!(from, Ty::Enum(_)) {
                format!(" (convert explicitly with {f}_TO_{t})")
            } else {
                String::new()
            };
        self.err(
            span,
            format!("type mismatch: expected {t}, found {f}{hint}"),
        );
    }

    /// The type of `e` without emitting code (compiled speculatively and discarded).
    pub(crate) fn peek(&mut self, e: &Expr) -> Ty {
        if let Some(&t) = self.peek_cache.get(&(e as *const Expr)) {
            return t;
        }
        let (n, d, p) = (self.ops.len(), self.diags.len(), self.patches.len());
        let t = self.expr(e, None);
        self.ops.truncate(n);
        self.spans.truncate(n);
        self.diags.truncate(d);
        self.patches.truncate(p);
        self.peek_cache.insert(e as *const Expr, t);
        t
    }

    /// The common type of two operands, typing untyped literals by the other operand (or by
    /// `hint` when both are literals).
    pub(super) fn operand_type(&mut self, a: &Expr, b: &Expr, hint: Option<Ty>) -> Option<Ty> {
        let lit_fits = |l: LitClass, t: Ty| match l {
            LitClass::Int(_) => t.int().is_some() || t.float(),
            LitClass::Real => t.float(),
        };
        let default = |l: LitClass| match l {
            LitClass::Int(v) if v >= i32::MIN as i128 && v <= i32::MAX as i128 => {
                Ty::Int(IntKind::DInt)
            }
            LitClass::Int(v) if v <= u64::MAX as i128 && v > i64::MAX as i128 => {
                Ty::Int(IntKind::ULInt)
            }
            LitClass::Int(_) => Ty::Int(IntKind::LInt),
            LitClass::Real => Ty::LReal,
        };
        match (lit_class(a), lit_class(b)) {
            (Some(la), Some(lb)) => match hint {
                Some(h) if lit_fits(la, h) && lit_fits(lb, h) => Some(h),
                _ => common(default(la), default(lb)),
            },
            (Some(l), None) | (None, Some(l)) => {
                let other = if lit_class(a).is_some() { b } else { a };
                let t = self.peek(other);
                // A literal next to a TIME, BOOL or enumeration keeps that type, so the
                // mismatch is reported against the variable's type.
                let keeps = t == Ty::Time || t == Ty::Bool || matches!(t, Ty::Enum(_));
                if lit_fits(l, t) || keeps {
                    Some(t)
                } else {
                    common(default(l), t)
                }
            }
            (None, None) => {
                let (ta, tb) = (self.peek(a), self.peek(b));
                if is_void(ta) || is_void(tb) {
                    return Some(Ty::Void);
                }
                common(ta, tb)
            }
        }
    }

    /// Compiles an expression leaving one cell on the stack; returns its type (`Void` after
    /// an error). `hint` types untyped literals.
    pub(crate) fn expr(&mut self, e: &Expr, hint: Option<Ty>) -> Ty {
        let t = self.expr_inner(e, hint);
        if hint.is_none() {
            self.peek_cache.insert(e as *const Expr, t);
        }
        t
    }

    pub(super) fn dummy(&mut self, span: Span) -> Ty {
        self.emit(Op::Push(0), span);
        Ty::Void
    }

    pub(super) fn expr_inner(&mut self, e: &Expr, hint: Option<Ty>) -> Ty {
        let span = e.span;
        match &e.kind {
            ExprKind::Lit(l) => self.literal(l, hint, span),
            ExprKind::Name(id) => {
                let key = id.key();
                if self.lookup(&key).is_none() {
                    if let Some(&(en, v)) = self.enum_values.get(&key) {
                        if en == u32::MAX {
                            self.err(
                                span,
                                format!(
                                    "{} is a value of several enumerations: qualify it (Type#{})",
                                    id.name, id.name
                                ),
                            );
                            return self.dummy(span);
                        }
                        self.emit(Op::Push(v as u64), span);
                        return Ty::Enum(en);
                    }
                }
                self.value_of(e)
            }
            ExprKind::Member(base, m) => {
                if let ExprKind::Name(tn) = &base.kind {
                    if self.lookup(&tn.key()).is_none() {
                        if let Some(TypeState::Done(Ty::Enum(id))) =
                            self.type_state.get(&tn.key()).copied()
                        {
                            let v = self.enums[id as usize]
                                .values
                                .iter()
                                .find(|(n, _)| n.eq_ignore_ascii_case(&m.name))
                                .map(|x| x.1);
                            return match v {
                                Some(v) => {
                                    self.emit(Op::Push(v as u64), span);
                                    Ty::Enum(id)
                                }
                                None => {
                                    self.err(
                                        m.span,
                                        format!("{} has no value {}", tn.name, m.name),
                                    );
                                    self.dummy(span)
                                }
                            };
                        }
                    }
                }
                self.value_of(e)
            }
            ExprKind::Index(..) => self.value_of(e),
            ExprKind::Bit(base, n) => {
                let Some((p, t, _)) = self.place(base) else {
                    return self.dummy(span);
                };
                self.check_bit(t, *n, span);
                self.load(p, span);
                self.emit(Op::GetBit(*n), span);
                Ty::Bool
            }
            ExprKind::Unary(op, x) => {
                let t = self.expr(x, hint);
                match (op, t) {
                    (_, Ty::Void) => {}
                    (UnOp::Neg, Ty::Int(k)) if !k.bitstring() => {
                        self.emit(Op::Neg(k), span);
                    }
                    (UnOp::Neg, Ty::Time) => {
                        self.emit(Op::Neg(IntKind::LInt), span);
                    }
                    (UnOp::Neg, t) if t.float() => {
                        self.emit(Op::FNeg, span);
                    }
                    (UnOp::Not, Ty::Bool) => {
                        self.emit(Op::NotB, span);
                    }
                    (UnOp::Not, Ty::Int(k)) => {
                        self.emit(Op::NotW(k), span);
                    }
                    _ => {
                        let n = self.ty_name(t);
                        let o = if *op == UnOp::Neg { "-" } else { "NOT" };
                        self.err(span, format!("operator {o} does not apply to {n}"));
                        return Ty::Void;
                    }
                }
                t
            }
            ExprKind::Binary(op, a, b) => self.binary(*op, a, b, hint, span),
            ExprKind::Call(callee, args) => {
                let ExprKind::Name(id) = &callee.kind else {
                    self.err(span, "only functions can be called in an expression");
                    return self.dummy(span);
                };
                self.call_function(id, args, hint, span)
            }
        }
    }

    pub(super) fn value_of(&mut self, e: &Expr) -> Ty {
        let Some((p, t, _)) = self.place(e) else {
            return self.dummy(e.span);
        };
        if !t.scalar() {
            if !is_void(t) {
                let n = self.ty_name(t);
                self.err(e.span, format!("{n} is not an elementary value here"));
            }
            return self.dummy(e.span);
        }
        self.load(p, e.span);
        t
    }

    pub(super) fn literal(&mut self, l: &Lit, hint: Option<Ty>, span: Span) -> Ty {
        let (cell, t) = match l {
            Lit::Bool(b) => (*b as u64, Ty::Bool),
            Lit::Time(ns) => (*ns as u64, Ty::Time),
            Lit::Str(_) => {
                self.err(span, "STRING is not supported by this PLC");
                return self.dummy(span);
            }
            Lit::Int(v, prefix) => {
                let t = match prefix {
                    Some(p) => match elementary(p.trim_start_matches('-')) {
                        Some(t @ (Ty::Int(_) | Ty::Real | Ty::LReal)) => t,
                        _ => {
                            self.err(span, format!("unknown literal type {p}#"));
                            return self.dummy(span);
                        }
                    },
                    None => match hint {
                        Some(h) if h.int().is_some() || h.float() => h,
                        _ if *v >= i32::MIN as i128 && *v <= i32::MAX as i128 => {
                            Ty::Int(IntKind::DInt)
                        }
                        _ if *v > i64::MAX as i128 => Ty::Int(IntKind::ULInt),
                        _ => Ty::Int(IntKind::LInt),
                    },
                };
                match self.const_cell(CVal::Int(*v), t, span) {
                    Some(c) => (c, t),
                    None => return self.dummy(span),
                }
            }
            Lit::Real(v, prefix) => {
                let t = match prefix.as_deref().map(|p| p.trim_start_matches('-')) {
                    Some("REAL") => Ty::Real,
                    Some("LREAL") => Ty::LReal,
                    Some(p) => {
                        self.err(span, format!("{p}# does not fit a real literal"));
                        return self.dummy(span);
                    }
                    None if hint == Some(Ty::Real) => Ty::Real,
                    None => Ty::LReal,
                };
                let c = if t == Ty::Real {
                    (*v as f32 as f64).to_bits()
                } else {
                    v.to_bits()
                };
                (c, t)
            }
        };
        self.emit(Op::Push(cell), span);
        t
    }

    pub(crate) fn binary(
        &mut self,
        op: BinOp,
        a: &Expr,
        b: &Expr,
        hint: Option<Ty>,
        span: Span,
    ) -> Ty {
        use BinOp::*;
        // TIME scaling: TIME * ANY_INT, TIME / ANY_INT (IEC 61131-3 table 30).
        if matches!(op, Mul | Div) {
            let (ta, tb) = (self.peek(a), self.peek(b));
            if ta == Ty::Time && tb != Ty::Time || (op == Mul && tb == Ty::Time && ta != Ty::Time) {
                let (t, n) = if ta == Ty::Time { (a, b) } else { (b, a) };
                self.expr(t, None);
                let nt = self.peek(n);
                if nt.float() {
                    // Scale through LREAL and round back to nanoseconds.
                    self.emit(Op::IToF(false), span);
                    let nt = self.expr(n, Some(Ty::LReal));
                    self.coerce(nt, Ty::LReal, n.span);
                    self.emit(
                        if op == Mul {
                            Op::FMul(false)
                        } else {
                            Op::FDiv(false)
                        },
                        span,
                    );
                    self.emit(Op::FToI(IntKind::LInt), span);
                    return Ty::Time;
                }
                let nt = self.expr(n, Some(Ty::Int(IntKind::LInt)));
                self.coerce(nt, Ty::Int(IntKind::LInt), n.span);
                self.emit(
                    if op == Mul {
                        Op::Mul(IntKind::LInt)
                    } else {
                        Op::Div(IntKind::LInt)
                    },
                    span,
                );
                return Ty::Time;
            }
        }
        let ct = match self.operand_type(a, b, hint) {
            // `**` is computed in floating point (EXPT).
            Some(Ty::Int(_)) if op == Pow => Ty::LReal,
            Some(t) => t,
            None => {
                let (ta, tb) = (self.peek(a), self.peek(b));
                let (na, nb) = (self.ty_name(ta), self.ty_name(tb));
                self.err(span, format!("operands of different types: {na} and {nb}"));
                self.expr(a, None);
                self.expr(b, None);
                self.emit(Op::Pop, span);
                return Ty::Void;
            }
        };
        let ta = self.expr(a, Some(ct));
        self.coerce(ta, ct, a.span);
        let tb = self.expr(b, Some(ct));
        self.coerce(tb, ct, b.span);
        if is_void(ct) {
            self.emit(Op::Pop, span);
            return Ty::Void;
        }
        let bad = |c: &mut Self| {
            let n = c.ty_name(ct);
            c.err(span, format!("operator {op:?} does not apply to {n}"));
            c.emit(Op::Pop, span);
            Ty::Void
        };
        let cmp_op = |c: Cmp| match ct {
            t if t.float() => Op::CmpF(c),
            Ty::Int(k) if k.bits() == 64 && !k.signed() => Op::CmpU(c),
            _ => Op::CmpI(c),
        };
        let single = ct == Ty::Real;
        let o = match op {
            Eq | Ne | Lt | Le | Gt | Ge => {
                let c = match op {
                    Eq => Cmp::Eq,
                    Ne => Cmp::Ne,
                    Lt => Cmp::Lt,
                    Le => Cmp::Le,
                    Gt => Cmp::Gt,
                    _ => Cmp::Ge,
                };
                if !ct.scalar() {
                    return bad(self);
                }
                self.emit(cmp_op(c), span);
                return Ty::Bool;
            }
            And | Or | Xor => {
                if !(ct == Ty::Bool || ct.int().is_some()) {
                    return bad(self);
                }
                match op {
                    And => Op::And,
                    Or => Op::Or,
                    _ => Op::Xor,
                }
            }
            Add | Sub if ct == Ty::Time => {
                if op == Add {
                    Op::Add(IntKind::LInt)
                } else {
                    Op::Sub(IntKind::LInt)
                }
            }
            Add | Sub | Mul | Div | Mod => match ct {
                Ty::Int(k) => match op {
                    Add => Op::Add(k),
                    Sub => Op::Sub(k),
                    Mul => Op::Mul(k),
                    Div => Op::Div(k),
                    _ => Op::Mod(k),
                },
                t if t.float() && op != Mod => match op {
                    Add => Op::FAdd(single),
                    Sub => Op::FSub(single),
                    Mul => Op::FMul(single),
                    _ => Op::FDiv(single),
                },
                _ => return bad(self),
            },
            Pow => {
                // Both operands are of `ct`; make them floats.
                match ct {
                    t if t.float() => Op::FPow(single),
                    _ => return bad(self),
                }
            }
        };
        self.emit(o, span);
        ct
    }
}
