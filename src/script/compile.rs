//! Lowering of a parsed script file: plain statements and expressions become PLC fragments
//! (compiled by the PLC compiler, one per statement so stepping and status go statement by
//! statement), script statements become [`SOp`]s that sequence them across steps.

use super::ast::*;
use super::code::*;
use crate::plc::ast::Stmt;
use crate::plc::compile::fragment::Fragments;
use crate::plc::diag::{Diags, Span};
use crate::plc::expr::Expr;
use crate::plc::{Options, Ty};
use std::collections::HashMap;
use std::sync::Arc;

/// Compiles script `src` (the contents of `file`) with the default PLC options (the
/// per-statement instruction budget). Every error of the file, with line and column.
pub fn compile(file: &str, src: &str) -> Result<Script, Diags> {
    compile_with(file, src, Options::default())
}

/// As [`compile`] with explicit PLC options.
pub fn compile_with(file: &str, src: &str, opts: Options) -> Result<Script, Diags> {
    let (parsed, diags) = super::parser::parse(src);
    let mut fr = Fragments::new(&parsed.unit, diags);
    let mut l = Lower {
        fr: &mut fr,
        ops: Vec::new(),
        spans: Vec::new(),
        calls: Vec::new(),
        events: Vec::new(),
        emits: Vec::new(),
        names: HashMap::new(),
        scope: 0,
        loops: Vec::new(),
        tries: Vec::new(),
        runs: Vec::new(),
    };
    for (i, it) in parsed.items.iter().enumerate() {
        let prog = matches!(it.kind, ItemKind::Program(_));
        if l.names.insert(it.name.key(), (i as u32, prog)).is_some() {
            l.fr.err(it.name.span, format!("{} declared twice", it.name.name));
        }
    }
    if parsed.items.is_empty() {
        l.fr.err(
            Span { line: 1, col: 1 },
            "no PROGRAM or STATE_MACHINE in the file",
        );
    }
    let mut items = Vec::new();
    for it in &parsed.items {
        let (scope, base) = l.fr.scope(it.pou).unwrap_or((0, 0));
        l.scope = scope;
        let code = match &it.kind {
            ItemKind::Program(body) => ItemCode::Program(l.block(body)),
            ItemKind::Machine(states) => l.machine(&it.name.name, it.name.span, states),
        };
        items.push(ItemDef {
            name: it.name.name.clone(),
            base,
            code,
        });
    }
    let Lower {
        ops,
        spans,
        calls,
        events,
        emits,
        runs: run_list,
        ..
    } = l;
    let mut runs = vec![(NONE, 0u32); ops.len()];
    for (pc, f, n) in run_list {
        runs[pc] = (f, n);
    }
    let compiled = fr.finish(file, opts)?;
    Ok(Script {
        file: Arc::from(file),
        program: compiled.program,
        entries: compiled.entries,
        ops,
        spans,
        runs,
        items,
        calls,
        events,
        emits,
    })
}

struct LoopL {
    top: u32,
    exits: Vec<usize>,
    conts: Vec<usize>,
}

struct Lower<'a, 'u> {
    fr: &'a mut Fragments<'u>,
    ops: Vec<SOp>,
    spans: Vec<Span>,
    calls: Vec<Call>,
    events: Vec<(String, Span)>,
    emits: Vec<(String, Span)>,
    /// Item names (upper case) -> (index, is a program).
    names: HashMap<String, (u32, bool)>,
    scope: usize,
    loops: Vec<LoopL>,
    /// Per enclosing TRY: the ops whose catch target is its CATCH.
    tries: Vec<Vec<usize>>,
    /// Runs of consecutive plain statements: (first op, merged fragment, statements).
    runs: Vec<(usize, u32, u32)>,
}

fn intern(list: &mut Vec<(String, Span)>, name: &str, span: Span) -> u32 {
    if let Some(i) = list.iter().position(|(n, _)| n.eq_ignore_ascii_case(name)) {
        return i as u32;
    }
    list.push((name.to_string(), span));
    (list.len() - 1) as u32
}

impl Lower<'_, '_> {
    fn here(&self) -> u32 {
        self.ops.len() as u32
    }
    fn emit(&mut self, op: SOp, span: Span) -> usize {
        self.ops.push(op);
        self.spans.push(span);
        self.ops.len() - 1
    }
    /// Emits an op that can fail into the innermost TRY (patched when its CATCH is known).
    fn emit_catching(&mut self, op: SOp, span: Span) {
        let i = self.emit(op, span);
        if let Some(t) = self.tries.last_mut() {
            t.push(i);
        }
    }
    fn patch(&mut self, at: usize, to: u32) {
        match &mut self.ops[at] {
            SOp::Jump(t) | SOp::JumpIfNot { target: t, .. } => *t = to,
            SOp::Do { catch, .. } | SOp::WaitEvent { catch, .. } | SOp::WaitUntil { catch, .. } => {
                *catch = to
            }
            _ => {}
        }
    }

    fn cond(&mut self, e: &Expr) -> (u32, u32) {
        let (f, slot) = self.fr.value(self.scope, e, Some(Ty::Bool));
        (f as u32, slot.addr)
    }
    fn timeout(&mut self, e: &Option<Expr>) -> Option<(u32, u32)> {
        let e = e.as_ref()?;
        let (f, slot) = self.fr.value(self.scope, e, Some(Ty::Time));
        Some((f as u32, slot.addr))
    }
    fn plain(&mut self, s: &Stmt) {
        let f = self.fr.stmts(self.scope, std::slice::from_ref(s), s.span);
        self.emit(SOp::Exec(f as u32), s.span);
    }
    fn program_ref(&mut self, name: &str, span: Span, what: &str) -> Option<u32> {
        match self.names.get(&name.to_ascii_uppercase()) {
            Some(&(i, true)) => Some(i),
            Some(_) => {
                self.fr.err(
                    span,
                    format!("{what} takes a PROGRAM; {name} is a STATE_MACHINE"),
                );
                None
            }
            None => {
                self.fr.err(span, format!("no PROGRAM {name} in this file"));
                None
            }
        }
    }

    /// A block: its statements then `End`; returns its first instruction.
    fn block(&mut self, list: &[SStmt]) -> u32 {
        let start = self.here();
        self.loops.clear();
        self.tries.clear();
        self.stmts(list);
        let span = list.last().map(|s| s.span).unwrap_or_default();
        self.emit(SOp::End, span);
        start
    }

    fn stmts(&mut self, list: &[SStmt]) {
        let mut k = 0;
        while k < list.len() {
            let n = list[k..]
                .iter()
                .take_while(|s| matches!(s.kind, SKind::Plain(_)))
                .count();
            if n >= 2 {
                self.plain_run(&list[k..k + n]);
                k += n;
            } else {
                self.stmt(&list[k]);
                k += 1;
            }
        }
    }

    /// Consecutive plain statements: one op (one fragment) each, for single-stepping and
    /// the current line, plus one fragment of them all that the engine runs instead when
    /// its budget covers the run: one VM entry for the run instead of one per statement.
    fn plain_run(&mut self, list: &[SStmt]) {
        let plain: Vec<Stmt> = list
            .iter()
            .filter_map(|s| match &s.kind {
                SKind::Plain(p) => Some(p.clone()),
                _ => None,
            })
            .collect();
        let start = self.here() as usize;
        let merged = self.fr.stmts(self.scope, &plain, list[0].span);
        for p in &plain {
            self.plain(p);
        }
        self.runs.push((start, merged as u32, plain.len() as u32));
    }

    fn stmt(&mut self, s: &SStmt) {
        let span = s.span;
        match &s.kind {
            SKind::Plain(p) => self.plain(p),
            SKind::If(arms, els) => {
                let mut ends = Vec::new();
                for (c, body) in arms {
                    let (frag, cell) = self.cond(c);
                    let j = self.emit(
                        SOp::JumpIfNot {
                            frag,
                            cell,
                            target: NONE,
                        },
                        c.span,
                    );
                    self.stmts(body);
                    ends.push(self.emit(SOp::Jump(NONE), span));
                    let h = self.here();
                    self.patch(j, h);
                }
                if let Some(b) = els {
                    self.stmts(b);
                }
                let h = self.here();
                for e in ends {
                    self.patch(e, h);
                }
            }
            SKind::While(c, body) => {
                let top = self.here();
                let (frag, cell) = self.cond(c);
                let j = self.emit(
                    SOp::JumpIfNot {
                        frag,
                        cell,
                        target: NONE,
                    },
                    c.span,
                );
                self.loop_body(top, body, span);
                self.emit(SOp::Jump(top), span);
                let end = self.here();
                self.patch(j, end);
                self.close_loop(top, end);
            }
            SKind::Repeat(body, c) => {
                let top = self.here();
                self.loop_body(top, body, span);
                let cont = self.here();
                let (frag, cell) = self.cond(c);
                self.emit(
                    SOp::JumpIfNot {
                        frag,
                        cell,
                        target: top,
                    },
                    c.span,
                );
                let end = self.here();
                self.close_loop(cont, end);
            }
            SKind::For { .. } => self.fr.err(
                span,
                "a FOR loop cannot contain DO/WAIT/TRY/START/STOP/EMIT: use WHILE",
            ),
            SKind::Exit | SKind::Continue => {
                let j = self.emit(SOp::Jump(NONE), span);
                let exit = matches!(s.kind, SKind::Exit);
                match self.loops.last_mut() {
                    Some(l) if exit => l.exits.push(j),
                    Some(l) => l.conts.push(j),
                    None => self.fr.err(
                        span,
                        format!("{} outside a loop", if exit { "EXIT" } else { "CONTINUE" }),
                    ),
                }
            }
            SKind::Return => {
                self.emit(SOp::End, span);
            }
            SKind::Do { peer, op, args } => {
                let mut slots = Vec::new();
                for a in args {
                    slots.push(match a {
                        DoArg::Expr(e) => {
                            let (f, slot) = self.fr.value(self.scope, e, None);
                            CallArg::Value(f as u32, slot)
                        }
                        DoArg::Str(s) => CallArg::Str(s.clone()),
                    });
                }
                self.calls.push(Call {
                    peer: peer.clone(),
                    op: op.name.clone(),
                    args: slots,
                    span,
                });
                let call = (self.calls.len() - 1) as u32;
                self.emit_catching(SOp::Do { call, catch: NONE }, span);
            }
            SKind::Try(body, catch) => {
                self.tries.push(Vec::new());
                self.stmts(body);
                let sites = self.tries.pop().unwrap_or_default();
                let j = self.emit(SOp::Jump(NONE), span);
                let c = self.here();
                for at in sites {
                    self.patch(at, c);
                }
                self.stmts(catch);
                let end = self.here();
                self.patch(j, end);
            }
            SKind::Wait(name, timeout) => {
                let is_prog = !name.contains('.')
                    && self
                        .names
                        .get(&name.to_ascii_uppercase())
                        .is_some_and(|x| x.1);
                if is_prog {
                    if timeout.is_some() {
                        self.fr
                            .err(span, "WAIT for a program takes no TIMEOUT: use WAIT UNTIL");
                    }
                    if let Some(i) = self.program_ref(name, span, "WAIT") {
                        self.emit(SOp::WaitProgram(i), span);
                    }
                } else {
                    let event = intern(&mut self.events, name, span);
                    let timeout = self.timeout(timeout);
                    self.emit_catching(
                        SOp::WaitEvent {
                            event,
                            timeout,
                            catch: NONE,
                        },
                        span,
                    );
                }
            }
            SKind::WaitUntil(c, timeout) => {
                let (frag, cell) = self.cond(c);
                let timeout = self.timeout(timeout);
                self.emit_catching(
                    SOp::WaitUntil {
                        frag,
                        cell,
                        timeout,
                        catch: NONE,
                    },
                    span,
                );
            }
            SKind::Start(n) | SKind::Stop(n) => {
                let start = matches!(s.kind, SKind::Start(_));
                let what = if start { "START" } else { "STOP" };
                if let Some(i) = self.program_ref(&n.name, n.span, what) {
                    self.emit(if start { SOp::Start(i) } else { SOp::Stop(i) }, span);
                }
            }
            SKind::Emit(n) => {
                let e = intern(&mut self.emits, n, span);
                self.emit(SOp::Emit(e), span);
            }
        }
    }

    fn loop_body(&mut self, top: u32, body: &[SStmt], _span: Span) {
        self.loops.push(LoopL {
            top,
            exits: Vec::new(),
            conts: Vec::new(),
        });
        self.stmts(body);
    }

    fn close_loop(&mut self, cont: u32, end: u32) {
        if let Some(l) = self.loops.pop() {
            let _ = l.top;
            for j in l.exits {
                self.patch(j, end);
            }
            for j in l.conts {
                self.patch(j, cont);
            }
        }
    }

    fn machine(&mut self, name: &str, span: Span, states: &[State]) -> ItemCode {
        let mut index = HashMap::new();
        for (i, s) in states.iter().enumerate() {
            if index.insert(s.name.key(), i as u32).is_some() {
                self.fr
                    .err(s.name.span, format!("state {} declared twice", s.name.name));
            }
        }
        let find = |k: StateKind| -> Vec<u32> {
            states
                .iter()
                .enumerate()
                .filter(|(_, s)| s.kind == k)
                .map(|(i, _)| i as u32)
                .collect()
        };
        let (initial, final_, error) = (
            find(StateKind::Initial),
            find(StateKind::Final),
            find(StateKind::Error),
        );
        for (list, what, exact) in [
            (&initial, "INITIAL STATE", true),
            (&final_, "FINAL STATE", true),
            (&error, "ERROR STATE", false),
        ] {
            if (exact && list.len() != 1) || list.len() > 1 {
                self.fr.err(
                    span,
                    format!(
                        "STATE_MACHINE {name} needs {} {what}, has {}",
                        if exact { "exactly one" } else { "at most one" },
                        list.len()
                    ),
                );
            }
        }
        let mut out = Vec::new();
        for s in states {
            let pre = s
                .pre
                .iter()
                .map(|e| {
                    let (f, c) = self.cond(e);
                    (f, c, e.span)
                })
                .collect();
            let entry = self.block(&s.entry);
            let run = s.run.as_ref().map(|r| self.block(r));
            let exit = self.block(&s.exit);
            let mut transitions = Vec::new();
            for t in &s.transitions {
                let event = t
                    .event
                    .as_ref()
                    .map(|(n, sp)| intern(&mut self.events, n, *sp));
                let cond = t.cond.as_ref().map(|c| self.cond(c));
                let target = match index.get(&t.target.key()) {
                    Some(&i) => i,
                    None => {
                        self.fr.err(
                            t.target.span,
                            format!("no state {} in {name}", t.target.name),
                        );
                        0
                    }
                };
                transitions.push(TransCode {
                    event,
                    cond,
                    target,
                });
            }
            out.push(StateCode {
                name: s.name.name.clone(),
                pre,
                entry,
                run,
                exit,
                transitions,
            });
        }
        ItemCode::Machine {
            states: out,
            initial: initial.first().copied().unwrap_or(0),
            final_: final_.first().copied().unwrap_or(0),
            error: error.first().copied(),
        }
    }
}
