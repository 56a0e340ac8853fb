//! The compiler: lays out all storage (globals, program instances, function block instances
//! nested inside them, static frames of functions), type-checks, and emits bytecode. Errors
//! are collected, never fatal: a bad declaration gets type `Void`, a bad expression pushes a
//! dummy value, so one run reports every error of a file.
//!
//! Functions get one static frame each (IEC 61131-3 forbids recursion, which is checked), so
//! a call copies the frame's initial image, stores the arguments and jumps: no allocation.

use super::ast::*;
use super::builtins;
use super::diag::{Diag, Diags, Span};
use super::expr::{Expr, ExprKind, Ident, Lit};
use super::program::{EnumInfo, InterfaceEntry, Program, VarKind};
use super::stdfb::StdFb;
use super::types::{elementary, Ty};
use super::vm::{Cmp, Code, Op};
use std::collections::{HashMap, HashSet};
use std::sync::Arc;

mod call;
mod code;
pub(crate) mod fragment;
mod layout;
mod stmt;

/// Compiler options.
#[derive(Debug, Clone, Copy)]
pub struct Options {
    /// Instructions one scan may execute before it faults.
    pub budget: u64,
}

impl Default for Options {
    fn default() -> Self {
        // ~5 ms of interpretation on the build machine: far above any sane scan, far below
        // a watchdog.
        Options { budget: 1_000_000 }
    }
}

/// Compiles `src` (the contents of `file`). Returns every error found.
pub fn compile(file: &str, src: &str, opts: Options) -> Result<Program, Diags> {
    compile_with(file, src, opts, true)
}

/// [`compile`] without the peephole pass: the plain code generator's output, the reference
/// the fused code is tested against (`tests/plc_fusion.rs`).
#[doc(hidden)]
pub fn compile_unfused(file: &str, src: &str, opts: Options) -> Result<Program, Diags> {
    compile_with(file, src, opts, false)
}

fn compile_with(file: &str, src: &str, opts: Options, fuse: bool) -> Result<Program, Diags> {
    let (unit, mut diags) = super::parser::parse(src);
    let mut c = Compiler::new(&unit);
    c.fuse = fuse;
    c.diags.append(&mut diags);
    let prog = c.run(file, opts);
    if c.diags.is_empty() {
        if let Some(p) = prog {
            return Ok(p);
        }
    }
    let mut list = c.diags;
    list.sort_by_key(|d| d.span);
    list.dedup();
    Err(Diags {
        file: file.to_string(),
        list,
    })
}

/// A compile-time constant.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum CVal {
    Bool(bool),
    Int(i128),
    Real(f64),
    Time(i64),
    Enum(u32, i64),
}

/// Where a variable lives: relative to the current base, or absolute.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Place {
    L(u32),
    G(u32),
    /// Address on the stack, plus an offset.
    Dyn(u32),
}

impl Place {
    fn offset(self, k: u32) -> Place {
        match self {
            Place::L(o) => Place::L(o + k),
            Place::G(a) => Place::G(a + k),
            Place::Dyn(d) => Place::Dyn(d + k),
        }
    }
}

#[derive(Debug, Clone)]
pub(crate) struct Member {
    pub name: String,
    pub ty: Ty,
    pub off: u32,
    pub section: Section,
    pub hidden: bool,
    pub constant: bool,
    pub retain: bool,
    pub cval: Option<CVal>,
}

#[derive(Debug, Clone)]
enum CompKind {
    Struct,
    Fb(usize),
    Std(StdFb),
    Program,
}

#[derive(Debug, Clone)]
struct Comp {
    name: String,
    members: Vec<Member>,
    size: u32,
    image: Vec<u64>,
    kind: CompKind,
}

#[derive(Debug, Clone)]
struct ArrayTy {
    elem: Ty,
    /// (lower bound, length) per dimension.
    dims: Vec<(i64, u32)>,
    elem_size: u32,
}

#[derive(Debug, Clone)]
pub(crate) struct Func {
    pub name: String,
    pub pou: usize,
    pub ret: Ty,
    pub frame: u32,
    pub image: u32,
    pub size: u32,
    pub members: Vec<Member>,
    pub result: u32,
}

#[derive(Debug, Clone)]
struct Sym {
    ty: Ty,
    place: Place,
    constant: bool,
    inout: bool,
    cval: Option<CVal>,
}

#[derive(Default)]
struct Loop {
    exits: Vec<usize>,
    conts: Vec<usize>,
}

#[derive(Clone, Copy, PartialEq)]
enum TypeState {
    Busy,
    Done(Ty),
}

/// The literal shape of an expression, for typing untyped literals by context.
pub(crate) fn lit_class(e: &Expr) -> Option<LitClass> {
    match &e.kind {
        ExprKind::Lit(Lit::Int(v, None)) => Some(LitClass::Int(*v)),
        ExprKind::Lit(Lit::Real(_, None)) => Some(LitClass::Real),
        _ => None,
    }
}

/// Literal shape of an expression, for typing untyped literals by context.
#[derive(Clone, Copy)]
pub(crate) enum LitClass {
    Int(i128),
    Real,
}

pub(crate) struct Compiler<'u> {
    unit: &'u Unit,
    pub(crate) diags: Vec<Diag>,
    type_decls: HashMap<String, usize>,
    type_state: HashMap<String, TypeState>,
    pous: HashMap<String, usize>,
    fb_comp: HashMap<usize, TypeState>,
    comps: Vec<Comp>,
    arrays: Vec<ArrayTy>,
    enums: Vec<EnumInfo>,
    enum_values: HashMap<String, (u32, i64)>,
    std_comp: HashMap<&'static str, u32>,
    pub(crate) funcs: HashMap<String, Func>,
    globals: HashMap<String, Sym>,
    global_list: Vec<(String, Ty, u32, bool, bool)>,
    init: Vec<u64>,
    pub(crate) ops: Vec<Op>,
    spans: Vec<Span>,
    /// Calls to patch with their callee's entry: (op index, POU index).
    patches: Vec<(usize, usize)>,
    /// Run the peephole pass (off only for the fusion tests' reference).
    fuse: bool,
    entries: HashMap<usize, u32>,
    calls: HashSet<(usize, usize)>,
    // Current body.
    locals: HashMap<String, Sym>,
    cur_pou: usize,
    loops: Vec<Loop>,
    peek_cache: HashMap<*const Expr, Ty>,
    interface: Vec<InterfaceEntry>,
}

fn is_void(t: Ty) -> bool {
    t == Ty::Void
}

impl<'u> Compiler<'u> {
    fn new(unit: &'u Unit) -> Self {
        Compiler {
            unit,
            diags: Vec::new(),
            type_decls: HashMap::new(),
            type_state: HashMap::new(),
            pous: HashMap::new(),
            fb_comp: HashMap::new(),
            comps: Vec::new(),
            arrays: Vec::new(),
            enums: Vec::new(),
            enum_values: HashMap::new(),
            std_comp: HashMap::new(),
            funcs: HashMap::new(),
            globals: HashMap::new(),
            global_list: Vec::new(),
            init: Vec::new(),
            ops: Vec::new(),
            spans: Vec::new(),
            patches: Vec::new(),
            fuse: true,
            entries: HashMap::new(),
            calls: HashSet::new(),
            locals: HashMap::new(),
            cur_pou: usize::MAX,
            loops: Vec::new(),
            peek_cache: HashMap::new(),
            interface: Vec::new(),
        }
    }

    pub(crate) fn err(&mut self, span: Span, msg: impl Into<String>) {
        self.diags.push(Diag::new(span, msg));
    }

    fn run(&mut self, file: &str, opts: Options) -> Option<Program> {
        let instances = self.declare();
        if instances.is_empty() && self.diags.is_empty() {
            self.err(Span { line: 1, col: 1 }, "no PROGRAM in the file");
        }
        let mut programs = self.bodies(&instances);
        self.finish(file, opts, &mut programs, &instances, &mut [])
    }

    /// Declares every name, type, global, block and function, and lays out one instance of
    /// every PROGRAM: (POU index, component, base address) per PROGRAM.
    pub(crate) fn declare(&mut self) -> Vec<(usize, u32, u32)> {
        let unit = self.unit;
        // Names first, so declarations can refer to types and blocks declared later.
        for (i, t) in unit.types.iter().enumerate() {
            let id = type_decl_name(t);
            if self.type_decls.insert(id.key(), i).is_some() {
                self.err(id.span, format!("type {} declared twice", id.name));
            }
        }
        for (i, p) in unit.pous.iter().enumerate() {
            let key = p.name.key();
            if self.pous.insert(key.clone(), i).is_some() || self.type_decls.contains_key(&key) {
                self.err(p.name.span, format!("{} declared twice", p.name.name));
            }
            if elementary(&key).is_some()
                || StdFb::by_name(&key).is_some()
                || builtins::is_builtin(&key)
            {
                self.err(
                    p.name.span,
                    format!(
                        "{} is a standard name and cannot be redeclared",
                        p.name.name
                    ),
                );
            }
        }
        for t in &unit.types {
            let id = type_decl_name(t);
            self.named_type(id);
        }
        self.declare_globals();
        for (i, p) in unit.pous.iter().enumerate() {
            match &p.kind {
                PouKind::FunctionBlock => {
                    self.fb_type(i, p.name.span);
                }
                PouKind::Function(ret) => self.declare_function(i, ret),
                PouKind::Program => {}
            }
        }
        let mut instances = Vec::new();
        for (i, p) in unit.pous.iter().enumerate() {
            if p.kind == PouKind::Program {
                let (members, image) = self.layout(&p.vars, true);
                let size = image.len() as u32;
                let base = self.alloc(&image);
                self.describe_pou("PROGRAM", p, &members);
                let cid = self.comps.len() as u32;
                self.comps.push(Comp {
                    name: p.name.name.clone(),
                    members,
                    size,
                    image,
                    kind: CompKind::Program,
                });
                instances.push((i, cid, base));
            }
        }
        instances
    }

    /// Compiles every body; returns (entry, base) of each PROGRAM.
    fn bodies(&mut self, instances: &[(usize, u32, u32)]) -> Vec<(u32, u32)> {
        let unit = self.unit;
        let mut programs = Vec::new();
        // Bodies.
        for (i, p) in unit.pous.iter().enumerate() {
            let members = match &p.kind {
                PouKind::Function(_) => match self.funcs.get(&p.name.key()) {
                    Some(f) => f.members.clone(),
                    None => continue,
                },
                PouKind::FunctionBlock => match self.fb_comp.get(&i) {
                    Some(TypeState::Done(Ty::Fb(c))) => self.comps[*c as usize].members.clone(),
                    _ => continue,
                },
                PouKind::Program => match instances.iter().find(|x| x.0 == i) {
                    Some(&(_, c, _)) => self.comps[c as usize].members.clone(),
                    None => continue,
                },
            };
            let entry = self.body(i, &members);
            self.entries.insert(i, entry);
            if let Some(&(_, _, base)) = instances.iter().find(|x| x.0 == i) {
                programs.push((entry, base));
            }
        }
        programs
    }

    /// Patches calls, checks recursion, builds the variable table, optimises and sizes the
    /// stack. `extra` are further entry points (script fragments) remapped by the peephole
    /// pass like the POUs' entries.
    pub(crate) fn finish(
        &mut self,
        file: &str,
        opts: Options,
        programs: &mut [(u32, u32)],
        instances: &[(usize, u32, u32)],
        extra: &mut [u32],
    ) -> Option<Program> {
        let unit = self.unit;
        for &(at, pou) in &self.patches {
            let e = self.entries.get(&pou).copied().unwrap_or(0);
            if let Op::Call { entry, .. } | Op::CallInd(entry) = &mut self.ops[at] {
                *entry = e;
            }
        }
        self.check_recursion();
        if !self.diags.is_empty() {
            return None;
        }
        let mut vars = Vec::new();
        for (name, ty, addr, retain, constant) in self.global_list.clone() {
            self.flatten(
                &name,
                ty,
                addr,
                VarKind::Global,
                retain,
                constant,
                &mut vars,
            );
        }
        for &(pou, cid, base) in instances {
            let pname = unit.pous[pou].name.name.clone();
            for m in self.comps[cid as usize].members.clone() {
                let kind = match m.section {
                    Section::Input => VarKind::Input,
                    Section::Output => VarKind::Output,
                    _ => VarKind::Local,
                };
                if m.section == Section::InOut || m.section == Section::External {
                    continue;
                }
                let name = format!("{pname}.{}", m.name);
                self.flatten(
                    &name,
                    m.ty,
                    base + m.off,
                    kind,
                    m.retain,
                    m.constant,
                    &mut vars,
                );
            }
        }
        {
            let mut entries: Vec<&mut u32> = programs.iter_mut().map(|(e, _)| e).collect();
            entries.extend(self.entries.values_mut());
            entries.extend(extra.iter_mut());
            if self.fuse {
                super::peephole::optimize(&mut self.ops, &mut self.spans, &mut entries);
            }
        }
        let stack = super::stack::max_depth(
            &self.ops,
            self.entries.values().chain(extra.iter()).copied(),
        );
        let depth = unit.pous.len() + 2;
        let code = match Code::new(std::mem::take(&mut self.ops)) {
            Ok(code) => code,
            Err(e) => {
                self.err(
                    Span { line: 1, col: 1 },
                    format!("internal compiler error: {e}"),
                );
                return None;
            }
        };
        Some(Program::new(
            Arc::from(file),
            code,
            std::mem::take(&mut self.spans),
            std::mem::take(&mut self.init),
            stack * depth + 8,
            depth,
            programs.to_vec(),
            vars,
            self.enums.clone(),
            std::mem::take(&mut self.interface),
            opts.budget,
        ))
    }
}

fn type_decl_name(t: &TypeDecl) -> &Ident {
    match t {
        TypeDecl::Struct(n, _) | TypeDecl::Enum(n, _) | TypeDecl::Alias(n, _) => n,
    }
}

fn base_name(e: &Expr) -> String {
    match &e.kind {
        ExprKind::Name(id) => id.name.clone(),
        ExprKind::Member(b, m) => format!("{}.{}", base_name(b), m.name),
        ExprKind::Index(b, _) => format!("{}[..]", base_name(b)),
        ExprKind::Bit(b, n) => format!("{}.{n}", base_name(b)),
        _ => "expression".into(),
    }
}
