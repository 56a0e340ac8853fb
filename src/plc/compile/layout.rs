//! Declarations and storage: named and standard types, the layout of variable blocks and
//! their initial images, constant evaluation, globals, function frames, the flattened
//! variable table and the recursion check.

use super::*;
use crate::plc::diag::Span;
use crate::plc::expr::{BinOp, Expr, ExprKind, Ident, Lit, UnOp};
use crate::plc::program::{EnumInfo, InterfaceEntry, VarInfo, VarKind};
use crate::plc::stdfb::StdFb;
use crate::plc::types::{elementary, Ty};

impl Compiler<'_> {
    pub(super) fn alloc(&mut self, image: &[u64]) -> u32 {
        let a = self.init.len() as u32;
        self.init.extend_from_slice(image);
        a
    }

    pub(super) fn named_type(&mut self, id: &Ident) -> Ty {
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

    pub(super) fn std_type(&mut self, fb: StdFb) -> Ty {
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

    pub(super) fn type_decl(&mut self, t: &TypeDecl) -> Ty {
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

    pub(super) fn fb_type(&mut self, pou: usize, span: Span) -> Ty {
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

    pub(super) fn describe_pou(&mut self, what: &str, p: &Pou, members: &[Member]) {
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

    pub(super) fn type_ref(&mut self, r: &TypeRef) -> Ty {
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

    pub(super) fn size_of(&self, t: Ty) -> u32 {
        match t {
            Ty::Array(a) => {
                let a = &self.arrays[a as usize];
                a.dims.iter().map(|d| d.1).product::<u32>() * a.elem_size
            }
            Ty::Struct(c) | Ty::Fb(c) => self.comps[c as usize].size,
            _ => 1,
        }
    }

    pub(super) fn default_cells(&self, t: Ty) -> Vec<u64> {
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
    pub(super) fn layout(
        &mut self,
        blocks: &[VarBlock],
        allow_io: bool,
    ) -> (Vec<Member>, Vec<u64>) {
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
    pub(super) fn write_init(
        &mut self,
        image: &mut [u64],
        off: u32,
        ty: Ty,
        init: &Init,
    ) -> Option<CVal> {
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

    pub(super) fn const_cell(&mut self, v: CVal, t: Ty, span: Span) -> Option<u64> {
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

    pub(super) fn declare_globals(&mut self) {
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

    pub(super) fn declare_function(&mut self, pou: usize, ret: &TypeRef) {
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
    pub(super) fn flatten(
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

    pub(super) fn check_recursion(&mut self) {
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
}
