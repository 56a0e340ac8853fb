//! Code generation for calls: function block instances, standard and user functions.

use super::*;
use crate::plc::builtins;
use crate::plc::diag::Span;
use crate::plc::expr::{Arg, Expr, ExprKind, Ident};
use crate::plc::types::Ty;
use crate::plc::vm::Op;
use std::collections::HashSet;

impl Compiler<'_> {
    pub(super) fn call_stmt(&mut self, callee: &Expr, args: &[Arg], span: Span) {
        if let ExprKind::Name(id) = &callee.kind {
            let key = id.key();
            if self.lookup(&key).is_none()
                && (self.funcs.contains_key(&key)
                    || builtins::is_builtin(&key)
                    || self.pous.contains_key(&key))
            {
                self.call_function(id, args, None, span);
                self.emit(Op::Pop, span);
                return;
            }
        }
        let Some((p, t, _)) = self.place(callee) else {
            return;
        };
        let Ty::Fb(c) = t else {
            if !is_void(t) {
                let n = self.ty_name(t);
                self.err(
                    callee.span,
                    format!(
                        "{} is a {n}, not a function block instance",
                        base_name(callee)
                    ),
                );
            }
            if matches!(p, Place::Dyn(_)) {
                self.emit(Op::Pop, span);
            }
            return;
        };
        let comp = self.comps[c as usize].clone();
        // A dynamic instance address is kept in a temporary while arguments are stored.
        let (inst, tmp) = match p {
            Place::Dyn(k) => {
                self.addr(Place::Dyn(k), span);
                let t = self.temp();
                self.emit(Op::StoreG(t), span);
                (None, t)
            }
            p => (Some(p), 0),
        };
        let member_place = |this: &mut Self, off: u32| -> Place {
            match inst {
                Some(p) => p.offset(off),
                None => {
                    this.emit(Op::LoadG(tmp), span);
                    Place::Dyn(off)
                }
            }
        };
        let mut outs = Vec::new();
        let mut given = HashSet::new();
        for a in args {
            let Some(name) = &a.name else {
                self.err(
                    a.value.span,
                    format!(
                        "arguments of the block {} must be named (IN := x, Q => y)",
                        comp.name
                    ),
                );
                continue;
            };
            let Some(m) = comp
                .members
                .iter()
                .find(|m| !m.hidden && m.name.eq_ignore_ascii_case(&name.name))
                .cloned()
            else {
                self.err(
                    name.span,
                    format!("{} has no parameter {}", comp.name, name.name),
                );
                continue;
            };
            if !given.insert(m.name.to_ascii_uppercase()) {
                self.err(name.span, format!("parameter {} given twice", m.name));
            }
            match (a.output, m.section) {
                (false, Section::Input) => {
                    let mp = member_place(self, m.off);
                    let t = self.expr(&a.value, Some(m.ty));
                    self.coerce(t, m.ty, a.value.span);
                    self.store(mp, a.value.span);
                }
                (false, Section::InOut) => {
                    let mp = member_place(self, m.off);
                    if let Some((q, t, ro)) = self.place(&a.value) {
                        if t != m.ty && !self.same_shape(t, m.ty) {
                            let (x, y) = (self.ty_name(m.ty), self.ty_name(t));
                            self.err(
                                a.value.span,
                                format!("VAR_IN_OUT {} is {x}, found {y}", m.name),
                            );
                        }
                        if ro {
                            self.err(a.value.span, "a constant cannot be passed to VAR_IN_OUT");
                        }
                        self.addr(q, a.value.span);
                    } else {
                        self.emit(Op::Push(0), span);
                    }
                    self.store(mp, a.value.span);
                }
                (true, Section::Output) => outs.push((m, &a.value)),
                _ => self.err(
                    name.span,
                    format!(
                        "{} is not an {} of {}",
                        m.name,
                        if a.output {
                            "output (=>)"
                        } else {
                            "input (:=)"
                        },
                        comp.name
                    ),
                ),
            }
        }
        for m in comp.members.iter().filter(|m| m.section == Section::InOut) {
            if !given.contains(&m.name.to_ascii_uppercase()) {
                self.err(
                    callee.span,
                    format!("VAR_IN_OUT {} of {} must be given", m.name, comp.name),
                );
            }
        }
        // A static instance: offset from the base, or absolute (`inst` is never `Dyn`: a
        // dynamic instance is `None` and goes through the temporary).
        let static_at = inst.map(|p| match p {
            Place::L(o) => (o, true),
            Place::G(a) | Place::Dyn(a) => (a, false),
        });
        match (&comp.kind, static_at) {
            (CompKind::Std(fb), Some((at, rel))) => {
                self.emit(Op::Std { fb: *fb, at, rel }, span);
            }
            (CompKind::Std(fb), None) => {
                self.emit(Op::LoadG(tmp), span);
                self.emit(Op::StdInd(*fb), span);
            }
            (CompKind::Fb(pou), Some((at, rel))) => {
                let i = self.emit(Op::Call { entry: 0, at, rel }, span);
                self.patches.push((i, *pou));
            }
            (CompKind::Fb(pou), None) => {
                self.emit(Op::LoadG(tmp), span);
                let i = self.emit(Op::CallInd(0), span);
                self.patches.push((i, *pou));
            }
            _ => self.err(span, "not a callable block"),
        }
        for (m, target) in outs {
            let Some((q, t, ro)) = self.place(target) else {
                continue;
            };
            if ro {
                self.err(target.span, "cannot assign a block output to a constant");
            }
            let mp = member_place(self, m.off);
            self.load(mp, target.span);
            self.coerce(m.ty, t, target.span);
            self.store(q, target.span);
        }
    }

    pub(super) fn call_function(
        &mut self,
        id: &Ident,
        args: &[Arg],
        hint: Option<Ty>,
        span: Span,
    ) -> Ty {
        let key = id.key();
        if let Some(f) = self.funcs.get(&key).cloned() {
            return self.call_user_function(&f, args, span);
        }
        if let Some(t) = builtins::call(self, &key, args, hint, span) {
            return t;
        }
        let msg = match self.pous.get(&key) {
            Some(&i) if self.unit.pous[i].kind == PouKind::FunctionBlock => {
                format!(
                    "{} is a function block: declare an instance and call it as a statement",
                    id.name
                )
            }
            _ => format!("unknown function {}", id.name),
        };
        self.err(id.span, msg);
        self.dummy(span)
    }

    pub(super) fn call_user_function(&mut self, f: &Func, args: &[Arg], span: Span) -> Ty {
        self.calls.insert((self.cur_pou, f.pou));
        let params: Vec<Member> = f
            .members
            .iter()
            .filter(|m| matches!(m.section, Section::Input | Section::InOut))
            .cloned()
            .collect();
        // Match arguments to parameters: positional in order, or by name.
        let mut slot: Vec<Option<&Expr>> = vec![None; params.len()];
        let mut outs = Vec::new();
        for (i, a) in args.iter().enumerate() {
            match &a.name {
                None if i < params.len() => slot[i] = Some(&a.value),
                None => self.err(
                    a.value.span,
                    format!("{} takes {} arguments", f.name, params.len()),
                ),
                Some(n) if a.output => {
                    match f.members.iter().find(|m| {
                        m.section == Section::Output && m.name.eq_ignore_ascii_case(&n.name)
                    }) {
                        Some(m) => outs.push((m.clone(), &a.value)),
                        None => self.err(n.span, format!("{} has no output {}", f.name, n.name)),
                    }
                }
                Some(n) => match params
                    .iter()
                    .position(|m| m.name.eq_ignore_ascii_case(&n.name))
                {
                    Some(k) => slot[k] = Some(&a.value),
                    None => self.err(n.span, format!("{} has no input {}", f.name, n.name)),
                },
            }
        }
        // Evaluate every argument first (they may call this function too), then fill the
        // frame from its initial image.
        for (m, e) in params.iter().zip(&slot) {
            match (e, m.section) {
                (Some(e), Section::InOut) => match self.place(e) {
                    Some((q, _, _)) => self.addr(q, e.span),
                    None => {
                        self.emit(Op::Push(0), span);
                    }
                },
                (Some(e), _) => {
                    let t = self.expr(e, Some(m.ty));
                    self.coerce(t, m.ty, e.span);
                }
                (None, Section::InOut) => {
                    self.err(
                        span,
                        format!("VAR_IN_OUT {} of {} must be given", m.name, f.name),
                    );
                    self.emit(Op::Push(0), span);
                }
                (None, _) => {
                    // Unconnected input: its initial value.
                    self.emit(Op::LoadG(f.image + m.off), span);
                }
            }
        }
        self.emit(Op::AddrG(f.frame), span);
        self.emit(Op::AddrG(f.image), span);
        self.emit(Op::Copy(f.size), span);
        for m in params.iter().rev() {
            self.emit(Op::StoreG(f.frame + m.off), span);
        }
        let i = self.emit(
            Op::Call {
                entry: 0,
                at: f.frame,
                rel: false,
            },
            span,
        );
        self.patches.push((i, f.pou));
        for (m, target) in outs {
            if let Some((q, t, _)) = self.place(target) {
                self.emit(Op::LoadG(f.frame + m.off), span);
                self.coerce(m.ty, t, target.span);
                self.store(q, target.span);
            }
        }
        if is_void(f.ret) {
            self.emit(Op::Push(0), span);
        } else {
            self.emit(Op::LoadG(f.frame + f.result), span);
        }
        f.ret
    }
}
