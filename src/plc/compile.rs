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
use super::expr::{Arg, BinOp, Expr, ExprKind, Ident, Lit, UnOp};
use super::program::{EnumInfo, InterfaceEntry, Program, VarInfo, VarKind};
use super::stdfb::StdFb;
use super::types::{common, elementary, implicit, IntKind, Ty};
use super::vm::{Cmp, Op};
use std::collections::{HashMap, HashSet};
use std::sync::Arc;

pub(crate) mod fragment;

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
    let (unit, mut diags) = super::parser::parse(src);
    let mut c = Compiler::new(&unit);
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
            super::peephole::optimize(&mut self.ops, &mut self.spans, &mut entries);
        }
        let stack = super::stack::max_depth(
            &self.ops,
            self.entries.values().chain(extra.iter()).copied(),
        );
        let depth = unit.pous.len() + 2;
        Some(Program::new(
            Arc::from(file),
            std::mem::take(&mut self.ops),
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

    // ---------------------------------------------------------------- types and layout

    fn alloc(&mut self, image: &[u64]) -> u32 {
        let a = self.init.len() as u32;
        self.init.extend_from_slice(image);
        a
    }

    fn named_type(&mut self, id: &Ident) -> Ty {
        let key = id.key();
        if let Some(t) = elementary(&key) {
            return t;
        }
        if let Some(fb) = StdFb::by_name(&key) {
            return self.std_type(fb);
        }
        match self.type_state.get(&key) {
            Some(TypeState::Done(t)) => return *t,
            Some(TypeState::Busy) => {
                self.err(id.span, format!("type {} contains itself", id.name));
                return Ty::Void;
            }
            None => {}
        }
        if let Some(&i) = self.type_decls.get(&key) {
            self.type_state.insert(key.clone(), TypeState::Busy);
            let t = self.type_decl(&self.unit.types[i]);
            self.type_state.insert(key, TypeState::Done(t));
            return t;
        }
        if let Some(&i) = self.pous.get(&key) {
            if self.unit.pous[i].kind == PouKind::FunctionBlock {
                return self.fb_type(i, id.span);
            }
            self.err(
                id.span,
                format!("{} is not a data type or function block", id.name),
            );
            return Ty::Void;
        }
        let hint = if key == "STRING" || key == "WSTRING" {
            " (strings are not supported)"
        } else {
            ""
        };
        self.err(id.span, format!("unknown type {}{hint}", id.name));
        Ty::Void
    }

    fn std_type(&mut self, fb: StdFb) -> Ty {
        if let Some(&c) = self.std_comp.get(fb.name()) {
            return Ty::Fb(c);
        }
        let members = fb
            .members()
            .iter()
            .enumerate()
            .map(|(i, &(name, ty, section))| Member {
                name: name.to_string(),
                ty,
                off: i as u32,
                section,
                hidden: name.starts_with('_'),
                constant: false,
                retain: false,
                cval: None,
            })
            .collect::<Vec<_>>();
        let n = members.len();
        let c = self.comps.len() as u32;
        self.comps.push(Comp {
            name: fb.name().into(),
            members,
            size: n as u32,
            image: vec![0; n],
            kind: CompKind::Std(fb),
        });
        self.std_comp.insert(fb.name(), c);
        Ty::Fb(c)
    }

    fn type_decl(&mut self, t: &TypeDecl) -> Ty {
        match t {
            TypeDecl::Alias(_, r) => self.type_ref(r),
            TypeDecl::Enum(name, values) => {
                let id = self.enums.len() as u32;
                let mut next = 0i64;
                let mut list = Vec::new();
                for (v, init) in values {
                    if let Some(e) = init {
                        match self.const_eval(e) {
                            Some(CVal::Int(x)) => next = x as i64,
                            _ => self.err(e.span, "enumeration value must be an integer constant"),
                        }
                    }
                    list.push((v.name.clone(), next));
                    if self.enum_values.insert(v.key(), (id, next)).is_some() {
                        // Ambiguous unqualified use is reported where it happens.
                        self.enum_values.insert(v.key(), (u32::MAX, 0));
                    }
                    next += 1;
                }
                self.enums.push(EnumInfo {
                    name: name.name.clone(),
                    values: list,
                });
                Ty::Enum(id)
            }
            TypeDecl::Struct(name, fields) => {
                let block = VarBlock {
                    section: Section::Var,
                    retain: false,
                    constant: false,
                    decls: fields.clone(),
                };
                let (members, image) = self.layout(std::slice::from_ref(&block), false);
                let c = self.comps.len() as u32;
                self.comps.push(Comp {
                    name: name.name.clone(),
                    size: image.len() as u32,
                    members,
                    image,
                    kind: CompKind::Struct,
                });
                Ty::Struct(c)
            }
        }
    }

    fn fb_type(&mut self, pou: usize, span: Span) -> Ty {
        match self.fb_comp.get(&pou) {
            Some(TypeState::Done(t)) => return *t,
            Some(TypeState::Busy) => {
                self.err(span, "function block contains an instance of itself");
                return Ty::Void;
            }
            None => {}
        }
        self.fb_comp.insert(pou, TypeState::Busy);
        let p = &self.unit.pous[pou];
        let (members, image) = self.layout(&p.vars, true);
        self.describe_pou("FUNCTION_BLOCK", p, &members);
        let c = self.comps.len() as u32;
        self.comps.push(Comp {
            name: p.name.name.clone(),
            size: image.len() as u32,
            members,
            image,
            kind: CompKind::Fb(pou),
        });
        self.fb_comp.insert(pou, TypeState::Done(Ty::Fb(c)));
        Ty::Fb(c)
    }

    fn describe_pou(&mut self, what: &str, p: &Pou, members: &[Member]) {
        for m in members.iter().filter(|m| !m.hidden) {
            let type_name = self.ty_name(m.ty);
            self.interface.push(InterfaceEntry {
                pou: format!("{what} {}", p.name.name),
                section: m.section,
                name: m.name.clone(),
                type_name,
                retain: m.retain,
                constant: m.constant,
            });
        }
    }

    fn type_ref(&mut self, r: &TypeRef) -> Ty {
        match r {
            TypeRef::Named(id) => self.named_type(id),
            TypeRef::String(span) => {
                self.err(*span, "STRING is not supported by this PLC");
                Ty::Void
            }
            TypeRef::Array(ranges, elem, span) => {
                let elem = self.type_ref(elem);
                let mut dims = Vec::new();
                for (lo, hi) in ranges {
                    match (self.const_eval(lo), self.const_eval(hi)) {
                        (Some(CVal::Int(l)), Some(CVal::Int(h)))
                            if h >= l
                                && h - l < 1 << 24
                                && l >= i32::MIN as i128
                                && h <= i32::MAX as i128 =>
                        {
                            dims.push((l as i64, (h - l + 1) as u32))
                        }
                        _ => {
                            self.err(
                                *span,
                                "array bounds must be integer constants with lo <= hi",
                            );
                            return Ty::Void;
                        }
                    }
                }
                let elem_size = self.size_of(elem);
                let total: u64 =
                    dims.iter().map(|d| d.1 as u64).product::<u64>() * elem_size as u64;
                if total > 1 << 24 {
                    self.err(*span, format!("array of {total} cells is too large"));
                    return Ty::Void;
                }
                let id = self.arrays.len() as u32;
                self.arrays.push(ArrayTy {
                    elem,
                    dims,
                    elem_size,
                });
                Ty::Array(id)
            }
        }
    }

    fn size_of(&self, t: Ty) -> u32 {
        match t {
            Ty::Array(a) => {
                let a = &self.arrays[a as usize];
                a.dims.iter().map(|d| d.1).product::<u32>() * a.elem_size
            }
            Ty::Struct(c) | Ty::Fb(c) => self.comps[c as usize].size,
            _ => 1,
        }
    }

    fn default_cells(&self, t: Ty) -> Vec<u64> {
        match t {
            Ty::Array(a) => {
                let n: u32 = self.arrays[a as usize].dims.iter().map(|d| d.1).product();
                self.default_cells(self.arrays[a as usize].elem)
                    .repeat(n as usize)
            }
            Ty::Struct(c) | Ty::Fb(c) => self.comps[c as usize].image.clone(),
            Ty::Enum(e) => vec![self.enums[e as usize].values.first().map_or(0, |v| v.1) as u64],
            _ => vec![0],
        }
    }

    /// Lays out variable blocks one after the other: members with offsets, and the image
    /// of initial values.
    fn layout(&mut self, blocks: &[VarBlock], allow_io: bool) -> (Vec<Member>, Vec<u64>) {
        let mut members: Vec<Member> = Vec::new();
        let mut image = Vec::new();
        for b in blocks {
            if !allow_io && b.section != Section::Var {
                continue;
            }
            for d in &b.decls {
                let ty = self.type_ref(&d.ty);
                for n in &d.names {
                    if members.iter().any(|m| m.name.eq_ignore_ascii_case(&n.name)) {
                        self.err(n.span, format!("{} declared twice", n.name));
                        continue;
                    }
                    if b.section == Section::External {
                        if !self.globals.contains_key(&n.key()) {
                            self.err(
                                n.span,
                                format!("no VAR_GLOBAL {} for this VAR_EXTERNAL", n.name),
                            );
                        }
                        continue;
                    }
                    let off = image.len() as u32;
                    let mut cval = None;
                    if b.section == Section::InOut {
                        image.push(0);
                        if d.init.is_some() {
                            self.err(n.span, "VAR_IN_OUT cannot have an initial value");
                        }
                    } else {
                        image.extend(self.default_cells(ty));
                        if let Some(init) = &d.init {
                            cval = self.write_init(&mut image, off, ty, init);
                        }
                    }
                    if b.constant && (d.init.is_none() || !ty.scalar()) && !is_void(ty) {
                        self.err(
                            n.span,
                            format!("CONSTANT {} needs an elementary initial value", n.name),
                        );
                    }
                    members.push(Member {
                        name: n.name.clone(),
                        ty,
                        off,
                        section: b.section,
                        hidden: false,
                        constant: b.constant,
                        retain: b.retain,
                        cval: if b.constant { cval } else { None },
                    });
                }
            }
        }
        (members, image)
    }

    /// Writes an initial value into `image` at `off`; returns it if it is a scalar constant.
    fn write_init(&mut self, image: &mut [u64], off: u32, ty: Ty, init: &Init) -> Option<CVal> {
        match (init, ty) {
            (_, Ty::Void) => None,
            (Init::Expr(e), t) if t.scalar() => {
                let v = self.const_eval(e);
                let Some(v) = v else {
                    self.err(e.span, "initial value must be a constant expression");
                    return None;
                };
                let c = self.const_cell(v, t, e.span)?;
                image[off as usize] = c;
                Some(v)
            }
            (Init::List(items, span), Ty::Array(a)) => {
                let arr = self.arrays[a as usize].clone();
                let n: u32 = arr.dims.iter().map(|d| d.1).product();
                let mut i = 0u32;
                for (rep, item) in items {
                    let count = match rep {
                        None => 1,
                        Some(e) => match self.const_eval(e) {
                            Some(CVal::Int(k)) if k >= 0 => k as u32,
                            _ => {
                                self.err(e.span, "repeat count must be a non-negative integer");
                                0
                            }
                        },
                    };
                    for _ in 0..count {
                        if i >= n {
                            self.err(
                                *span,
                                format!("too many initial values for an array of {n}"),
                            );
                            return None;
                        }
                        self.write_init(image, off + i * arr.elem_size, arr.elem, item);
                        i += 1;
                    }
                }
                None
            }
            (Init::Fields(items, _), Ty::Struct(c) | Ty::Fb(c)) => {
                let comp = self.comps[c as usize].clone();
                for (name, item) in items {
                    let m = comp
                        .members
                        .iter()
                        .find(|m| !m.hidden && m.name.eq_ignore_ascii_case(&name.name));
                    match m {
                        Some(m) => {
                            self.write_init(image, off + m.off, m.ty, item);
                        }
                        None => self.err(
                            name.span,
                            format!("{} has no member {}", comp.name, name.name),
                        ),
                    }
                }
                None
            }
            (Init::Expr(e), _) => {
                self.err(
                    e.span,
                    format!("a {} needs a [..] or (..) initial value", self.ty_name(ty)),
                );
                None
            }
            (Init::List(_, s) | Init::Fields(_, s), _) => {
                self.err(
                    *s,
                    format!("this initial value does not fit type {}", self.ty_name(ty)),
                );
                None
            }
        }
    }

    fn const_cell(&mut self, v: CVal, t: Ty, span: Span) -> Option<u64> {
        let c = match (v, t) {
            (CVal::Bool(b), Ty::Bool) => b as u64,
            (CVal::Int(x), Ty::Int(k)) => {
                if x < k.min() || x > k.max() {
                    self.err(span, format!("{x} is out of the range of {}", k.name()));
                    return None;
                }
                x as i64 as u64
            }
            (CVal::Int(x), Ty::Real) => (x as f32 as f64).to_bits(),
            (CVal::Int(x), Ty::LReal) => (x as f64).to_bits(),
            (CVal::Real(x), Ty::Real) => (x as f32 as f64).to_bits(),
            (CVal::Real(x), Ty::LReal) => x.to_bits(),
            (CVal::Time(x), Ty::Time) => x as u64,
            (CVal::Enum(e, x), Ty::Enum(f)) if e == f => x as u64,
            _ => {
                let tn = self.ty_name(t);
                self.err(span, format!("initial value does not fit type {tn}"));
                return None;
            }
        };
        Some(c)
    }

    /// Evaluates a constant expression: literals, CONSTANT variables, enumeration values,
    /// arithmetic on them.
    pub(crate) fn const_eval(&mut self, e: &Expr) -> Option<CVal> {
        Some(match &e.kind {
            ExprKind::Lit(Lit::Bool(b)) => CVal::Bool(*b),
            ExprKind::Lit(Lit::Int(v, _)) => CVal::Int(*v),
            ExprKind::Lit(Lit::Real(v, _)) => CVal::Real(*v),
            ExprKind::Lit(Lit::Time(v)) => CVal::Time(*v),
            ExprKind::Name(id) => {
                let key = id.key();
                if let Some(s) = self.locals.get(&key).or_else(|| self.globals.get(&key)) {
                    return s.cval;
                }
                let (e, v) = self.enum_values.get(&key).copied()?;
                (e != u32::MAX).then_some(CVal::Enum(e, v))?
            }
            ExprKind::Member(b, m) => {
                let ExprKind::Name(t) = &b.kind else {
                    return None;
                };
                let Ty::Enum(id) = self.type_state.get(&t.key()).and_then(|s| match s {
                    TypeState::Done(t) => Some(*t),
                    TypeState::Busy => None,
                })?
                else {
                    return None;
                };
                let v = self.enums[id as usize]
                    .values
                    .iter()
                    .find(|(n, _)| n.eq_ignore_ascii_case(&m.name))?
                    .1;
                CVal::Enum(id, v)
            }
            ExprKind::Unary(UnOp::Neg, x) => match self.const_eval(x)? {
                CVal::Int(v) => CVal::Int(-v),
                CVal::Real(v) => CVal::Real(-v),
                CVal::Time(v) => CVal::Time(-v),
                _ => return None,
            },
            ExprKind::Unary(UnOp::Not, x) => match self.const_eval(x)? {
                CVal::Bool(b) => CVal::Bool(!b),
                _ => return None,
            },
            ExprKind::Binary(op, a, b) => {
                let (a, b) = (self.const_eval(a)?, self.const_eval(b)?);
                match (a, b) {
                    (CVal::Int(a), CVal::Int(b)) => CVal::Int(match op {
                        BinOp::Add => a.checked_add(b)?,
                        BinOp::Sub => a.checked_sub(b)?,
                        BinOp::Mul => a.checked_mul(b)?,
                        BinOp::Div if b != 0 => a / b,
                        BinOp::Mod if b != 0 => a % b,
                        _ => return None,
                    }),
                    (CVal::Real(a), CVal::Real(b)) => CVal::Real(match op {
                        BinOp::Add => a + b,
                        BinOp::Sub => a - b,
                        BinOp::Mul => a * b,
                        BinOp::Div => a / b,
                        _ => return None,
                    }),
                    (CVal::Time(a), CVal::Time(b)) => CVal::Time(match op {
                        BinOp::Add => a.checked_add(b)?,
                        BinOp::Sub => a.checked_sub(b)?,
                        _ => return None,
                    }),
                    _ => return None,
                }
            }
            _ => return None,
        })
    }

    fn declare_globals(&mut self) {
        let unit = self.unit;
        for b in &unit.globals {
            let (members, image) = self.layout(std::slice::from_ref(b), true);
            let base = self.alloc(&image);
            for m in members {
                let key = m.name.to_ascii_uppercase();
                if self.globals.contains_key(&key) {
                    self.err(Span::default(), format!("global {} declared twice", m.name));
                }
                let type_name = self.ty_name(m.ty);
                self.interface.push(InterfaceEntry {
                    pou: "GLOBAL".into(),
                    section: Section::Global,
                    name: m.name.clone(),
                    type_name,
                    retain: m.retain,
                    constant: m.constant,
                });
                self.global_list
                    .push((m.name.clone(), m.ty, base + m.off, m.retain, m.constant));
                self.globals.insert(
                    key,
                    Sym {
                        ty: m.ty,
                        place: Place::G(base + m.off),
                        constant: m.constant,
                        inout: false,
                        cval: m.cval,
                    },
                );
            }
        }
    }

    fn declare_function(&mut self, pou: usize, ret: &TypeRef) {
        let p = &self.unit.pous[pou];
        let ret = self.type_ref(ret);
        if !is_void(ret) && !ret.scalar() {
            self.err(p.name.span, "a function returns an elementary type here");
        }
        let (mut members, mut image) = self.layout(&p.vars, true);
        for m in &members {
            if matches!(m.ty, Ty::Fb(_)) {
                self.err(
                    p.name.span,
                    format!(
                        "function {} cannot contain the block instance {} (IEC 61131-3)",
                        p.name.name, m.name
                    ),
                );
            }
        }
        let result = image.len() as u32;
        image.push(0);
        members.push(Member {
            name: p.name.name.clone(),
            ty: ret,
            off: result,
            section: Section::Var,
            hidden: true,
            constant: false,
            retain: false,
            cval: None,
        });
        self.describe_pou("FUNCTION", p, &members);
        let frame = self.alloc(&image);
        let img = self.alloc(&image);
        self.funcs.insert(
            p.name.key(),
            Func {
                name: p.name.name.clone(),
                pou,
                ret,
                frame,
                image: img,
                size: image.len() as u32,
                members,
                result,
            },
        );
    }

    pub(crate) fn ty_name(&self, t: Ty) -> String {
        match t {
            Ty::Bool => "BOOL".into(),
            Ty::Int(k) => k.name().into(),
            Ty::Real => "REAL".into(),
            Ty::LReal => "LREAL".into(),
            Ty::Time => "TIME".into(),
            Ty::Enum(e) => self.enums[e as usize].name.clone(),
            Ty::Array(a) => {
                let a = &self.arrays[a as usize];
                let dims: Vec<String> = a
                    .dims
                    .iter()
                    .map(|(lo, n)| format!("{lo}..{}", lo + *n as i64 - 1))
                    .collect();
                format!("ARRAY[{}] OF {}", dims.join(", "), self.ty_name(a.elem))
            }
            Ty::Struct(c) | Ty::Fb(c) => self.comps[c as usize].name.clone(),
            Ty::Void => "(error)".into(),
        }
    }

    #[allow(clippy::too_many_arguments)]
    fn flatten(
        &self,
        name: &str,
        ty: Ty,
        addr: u32,
        kind: VarKind,
        retain: bool,
        constant: bool,
        out: &mut Vec<VarInfo>,
    ) {
        match ty {
            Ty::Array(a) => {
                let arr = &self.arrays[a as usize];
                let n: u32 = arr.dims.iter().map(|d| d.1).product();
                for i in 0..n {
                    // Row-major: the last index varies fastest.
                    let mut rest = i;
                    let mut idx = Vec::new();
                    for &(lo, len) in arr.dims.iter().rev() {
                        idx.push((lo + (rest % len) as i64).to_string());
                        rest /= len;
                    }
                    idx.reverse();
                    let n = format!("{name}[{}]", idx.join(","));
                    self.flatten(
                        &n,
                        arr.elem,
                        addr + i * arr.elem_size,
                        kind,
                        retain,
                        constant,
                        out,
                    );
                }
            }
            Ty::Struct(c) | Ty::Fb(c) => {
                for m in &self.comps[c as usize].members {
                    if m.hidden || m.section == Section::InOut {
                        continue;
                    }
                    let n = format!("{name}.{}", m.name);
                    self.flatten(
                        &n,
                        m.ty,
                        addr + m.off,
                        kind,
                        retain || m.retain,
                        constant,
                        out,
                    );
                }
            }
            Ty::Void => {}
            _ => out.push(VarInfo {
                name: name.to_string(),
                ty,
                type_name: self.ty_name(ty),
                kind,
                retain,
                constant,
                addr,
            }),
        }
    }

    fn check_recursion(&mut self) {
        // Depth-first search for a cycle in the function call graph.
        let n = self.unit.pous.len();
        let mut state = vec![0u8; n];
        let edges: Vec<(usize, usize)> = self.calls.iter().copied().collect();
        fn visit(v: usize, edges: &[(usize, usize)], state: &mut [u8]) -> Option<usize> {
            state[v] = 1;
            for &(_, b) in edges.iter().filter(|e| e.0 == v) {
                if state[b] == 1 {
                    return Some(b);
                }
                if state[b] == 0 {
                    if let Some(x) = visit(b, edges, state) {
                        return Some(x);
                    }
                }
            }
            state[v] = 2;
            None
        }
        for v in 0..n {
            if state[v] == 0 {
                if let Some(f) = visit(v, &edges, &mut state) {
                    let p = &self.unit.pous[f];
                    let msg = format!(
                        "{} calls itself (recursion is not allowed in IEC 61131-3)",
                        p.name.name
                    );
                    self.err(p.name.span, msg);
                    return;
                }
            }
        }
    }

    // ---------------------------------------------------------------- code

    pub(crate) fn emit(&mut self, op: Op, span: Span) -> usize {
        self.ops.push(op);
        self.spans.push(span);
        self.ops.len() - 1
    }

    fn here(&self) -> u32 {
        self.ops.len() as u32
    }

    fn patch(&mut self, at: usize, target: u32) {
        match &mut self.ops[at] {
            Op::Jmp(t) | Op::Jz(t) | Op::Jnz(t) => *t = target,
            _ => unreachable!("patching a non-jump"),
        }
    }

    fn body(&mut self, pou: usize, members: &[Member]) -> u32 {
        let p = &self.unit.pous[pou];
        self.enter_scope(pou, members);
        let entry = self.here();
        self.stmts(&p.body);
        self.emit(Op::Ret, p.name.span);
        entry
    }

    /// Makes the members of POU `pou` the local symbols of the code emitted next.
    fn enter_scope(&mut self, pou: usize, members: &[Member]) {
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

    fn stmts(&mut self, list: &[Stmt]) {
        for s in list {
            self.stmt(s);
        }
    }

    fn stmt(&mut self, s: &Stmt) {
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

    fn close_loop(&mut self, l: Loop, cont: u32, end: u32) {
        for j in l.exits {
            self.patch(j, end);
        }
        for j in l.conts {
            self.patch(j, cont);
        }
    }

    /// A BOOL condition.
    fn cond(&mut self, c: &Expr) {
        let t = self.expr(c, Some(Ty::Bool));
        self.coerce(t, Ty::Bool, c.span);
    }

    fn temp(&mut self) -> u32 {
        self.alloc(&[0])
    }

    fn case(
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

    fn case_value(&mut self, e: &Expr, st: Ty) -> Option<i128> {
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

    fn for_loop(
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

    fn lookup(&self, key: &str) -> Option<Sym> {
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
    fn place(&mut self, e: &Expr) -> Option<(Place, Ty, bool)> {
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

    fn unknown_name(&mut self, id: &Ident) {
        let key = id.key();
        let msg = if self.pous.contains_key(&key) || builtins::is_builtin(&key) {
            format!("{} is a function or block, not a variable", id.name)
        } else {
            format!("unknown variable {}", id.name)
        };
        self.err(id.span, msg);
    }

    fn assign(&mut self, lhs: &Expr, rhs: &Expr, span: Span) {
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

    fn same_shape(&self, a: Ty, b: Ty) -> bool {
        match (a, b) {
            (Ty::Array(x), Ty::Array(y)) => {
                let (x, y) = (&self.arrays[x as usize], &self.arrays[y as usize]);
                x.dims == y.dims && (x.elem == y.elem || self.same_shape(x.elem, y.elem))
            }
            _ => a == b,
        }
    }

    fn check_bit(&mut self, t: Ty, n: u8, span: Span) {
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
    fn operand_type(&mut self, a: &Expr, b: &Expr, hint: Option<Ty>) -> Option<Ty> {
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

    fn dummy(&mut self, span: Span) -> Ty {
        self.emit(Op::Push(0), span);
        Ty::Void
    }

    fn expr_inner(&mut self, e: &Expr, hint: Option<Ty>) -> Ty {
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

    fn value_of(&mut self, e: &Expr) -> Ty {
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

    fn literal(&mut self, l: &Lit, hint: Option<Ty>, span: Span) -> Ty {
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

    fn call_stmt(&mut self, callee: &Expr, args: &[Arg], span: Span) {
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

    fn call_function(&mut self, id: &Ident, args: &[Arg], hint: Option<Ty>, span: Span) -> Ty {
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

    fn call_user_function(&mut self, f: &Func, args: &[Arg], span: Span) -> Ty {
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
