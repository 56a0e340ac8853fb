//! Fragments: the compiler's API for front ends that drive control flow themselves (the
//! scripts of `src/script/`). A fragment is a statement list or an expression compiled in
//! the scope of one PROGRAM instance into its own entry point, ending with `Ret`; an
//! expression's value is stored into a hidden cell the caller reads after running it. The
//! script engine sequences fragments across steps (waits, commands); everything inside a
//! fragment is ordinary ST with the PLC's typing rules and code generation.

use super::{Compiler, Options};
use crate::plc::ast::{Stmt, Unit};
use crate::plc::diag::{Diag, Diags, Span};
use crate::plc::expr::Expr;
use crate::plc::program::Program;
use crate::plc::types::Ty;
use crate::plc::vm::Op;

/// A hidden cell holding the value of an expression fragment.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Slot {
    /// Absolute memory address.
    pub addr: u32,
    /// Type of the value.
    pub ty: Ty,
}

/// Compiles fragments against a unit whose PROGRAMs are the scopes (their bodies, if any,
/// are compiled too but never run by a script).
pub(crate) struct Fragments<'u> {
    c: Compiler<'u>,
    instances: Vec<(usize, u32, u32)>,
    programs: Vec<(u32, u32)>,
    entries: Vec<u32>,
}

/// A compiled unit: the program (memory, code) and the entry of every fragment, by the
/// index [`Fragments`] returned.
pub(crate) struct Compiled {
    pub program: Program,
    pub entries: Vec<u32>,
}

impl<'u> Fragments<'u> {
    /// Declares everything of `unit` (parse errors `diags` are kept and reported at the end).
    pub(crate) fn new(unit: &'u Unit, diags: Vec<Diag>) -> Self {
        let mut c = Compiler::new(unit);
        c.diags = diags;
        let instances = c.declare();
        let programs = c.bodies(&instances);
        Fragments {
            c,
            instances,
            programs,
            entries: Vec::new(),
        }
    }

    /// The scope of PROGRAM `name` (its index among the unit's POUs) and its base address.
    pub(crate) fn scope(&self, pou: usize) -> Option<(usize, u32)> {
        self.instances
            .iter()
            .position(|x| x.0 == pou)
            .map(|i| (i, self.instances[i].2))
    }

    fn enter(&mut self, scope: usize) -> u32 {
        let (pou, cid, _) = self.instances[scope];
        let members = self.c.comps[cid as usize].members.clone();
        self.c.enter_scope(pou, &members);
        self.c.loops.clear();
        self.c.here()
    }

    fn close(&mut self, entry: u32, span: Span) -> usize {
        self.c.emit(Op::Ret, span);
        self.entries.push(entry);
        self.entries.len() - 1
    }

    /// Compiles `list` in `scope`; returns the fragment index.
    pub(crate) fn stmts(&mut self, scope: usize, list: &[Stmt], span: Span) -> usize {
        let entry = self.enter(scope);
        self.c.stmts(list);
        self.close(entry, span)
    }

    /// Compiles `e` (an elementary value) in `scope` into a hidden cell.
    pub(crate) fn value(&mut self, scope: usize, e: &Expr, hint: Option<Ty>) -> (usize, Slot) {
        let entry = self.enter(scope);
        let mut ty = self.c.expr(e, hint);
        if let Some(h) = hint {
            self.c.coerce(ty, h, e.span);
            ty = h;
        } else if !ty.scalar() {
            self.c.err(
                e.span,
                "expected an elementary value (BOOL, integer, REAL, TIME)",
            );
        }
        let addr = self.c.temp();
        self.c.emit(Op::StoreG(addr), e.span);
        (self.close(entry, e.span), Slot { addr, ty })
    }

    /// Records an error found by the front end.
    pub(crate) fn err(&mut self, span: Span, msg: impl Into<String>) {
        self.c.err(span, msg);
    }

    /// Links and optimises everything; every error of the file, sorted, on failure.
    pub(crate) fn finish(mut self, file: &str, opts: Options) -> Result<Compiled, Diags> {
        let instances = std::mem::take(&mut self.instances);
        let prog = self.c.finish(
            file,
            opts,
            &mut self.programs,
            &instances,
            &mut self.entries,
        );
        match prog {
            Some(program) if self.c.diags.is_empty() => Ok(Compiled {
                program,
                entries: self.entries,
            }),
            _ => {
                let mut list = std::mem::take(&mut self.c.diags);
                list.sort_by_key(|d| d.span);
                list.dedup();
                Err(Diags {
                    file: file.to_string(),
                    list,
                })
            }
        }
    }
}
