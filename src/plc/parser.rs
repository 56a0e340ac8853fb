//! Parser of the PLC constructs (POUs, declarations, statements) on top of the expression
//! parser. It recovers after an error by skipping to the next `;` or block keyword, so one
//! compile reports every syntax error of a file.

use super::ast::*;
use super::diag::Diag;
use super::expr::{Expr, ExprKind, Parser};
use super::lexer::{lex, Tok};

/// Parses a whole file.
pub fn parse(src: &str) -> (Unit, Vec<Diag>) {
    let mut diags = Vec::new();
    let toks = lex(src, &mut diags);
    let mut p = Parser::new(toks, diags);
    let unit = p.unit();
    (unit, p.diags)
}

/// Keywords that end a statement list (the script parser adds its own to these).
pub(crate) const BLOCK_END: &[&str] = &[
    "END_IF",
    "ELSIF",
    "ELSE",
    "END_CASE",
    "END_FOR",
    "END_WHILE",
    "UNTIL",
    "END_REPEAT",
    "END_PROGRAM",
    "END_FUNCTION_BLOCK",
    "END_FUNCTION",
];

const TOP_LEVEL: &[&str] = &[
    "PROGRAM",
    "FUNCTION_BLOCK",
    "FUNCTION",
    "TYPE",
    "VAR_GLOBAL",
];

impl Parser {
    fn at_kw_in(&self, set: &[&str]) -> bool {
        matches!(self.peek(), Tok::Kw(k) if set.contains(k))
    }

    /// After a failed parse that started at token `start`: skips to just after the next
    /// `;`, or to a keyword of `stop` (not consumed). Always consumes at least one token when
    /// the failed parse consumed none and there is no stop keyword to return to (so every
    /// loop calling it terminates).
    fn recover_from(&mut self, start: usize, stop: &[&str]) {
        self.recover(stop);
        if self.pos() == start && !self.at_eof() && !self.at_kw_in(BLOCK_END) {
            self.bump();
        }
    }

    /// Skips to just after the next `;`, or to a keyword of `stop` (not consumed).
    fn recover(&mut self, stop: &[&str]) {
        while !self.at_eof() && !self.at_kw_in(stop) && !self.at_kw_in(TOP_LEVEL) {
            if matches!(self.bump(), Tok::P(";")) {
                return;
            }
        }
    }

    fn unit(&mut self) -> Unit {
        let mut u = Unit::default();
        while !self.at_eof() {
            match self.peek() {
                Tok::Kw("PROGRAM") => u.pous.push(self.pou(PouKindTag::Program)),
                Tok::Kw("FUNCTION_BLOCK") => u.pous.push(self.pou(PouKindTag::Fb)),
                Tok::Kw("FUNCTION") => u.pous.push(self.pou(PouKindTag::Function)),
                Tok::Kw("TYPE") => self.types(&mut u.types),
                Tok::Kw("VAR_GLOBAL") => {
                    if let Some(b) = self.var_block() {
                        u.globals.push(b);
                    }
                }
                _ => {
                    let msg = format!(
                        "expected PROGRAM, FUNCTION_BLOCK, FUNCTION, TYPE or VAR_GLOBAL, found {}",
                        self.describe()
                    );
                    self.error(msg);
                    self.bump();
                    while !self.at_eof() && !self.at_kw_in(TOP_LEVEL) {
                        self.bump();
                    }
                }
            }
        }
        u
    }

    pub(crate) fn pou(&mut self, tag: PouKindTag) -> Pou {
        self.bump();
        let name = self.ident().unwrap_or_else(|| super::expr::Ident {
            name: "?".into(),
            span: self.span(),
        });
        let (kind, end) = match tag {
            PouKindTag::Program => (PouKind::Program, "END_PROGRAM"),
            PouKindTag::Fb => (PouKind::FunctionBlock, "END_FUNCTION_BLOCK"),
            PouKindTag::Function => {
                let ty = if self.expect_p(":") {
                    self.type_ref()
                } else {
                    None
                };
                let ty = ty.unwrap_or(TypeRef::Named(name.clone()));
                (PouKind::Function(ty), "END_FUNCTION")
            }
        };
        let mut vars = Vec::new();
        while matches!(self.peek(), Tok::Kw(k) if k.starts_with("VAR")) {
            if let Some(b) = self.var_block() {
                vars.push(b);
            }
        }
        let body = self.stmts();
        self.expect_kw(end);
        Pou {
            kind,
            name,
            vars,
            body,
        }
    }

    pub(crate) fn var_block(&mut self) -> Option<VarBlock> {
        let section = match self.bump() {
            Tok::Kw("VAR") => Section::Var,
            Tok::Kw("VAR_INPUT") => Section::Input,
            Tok::Kw("VAR_OUTPUT") => Section::Output,
            Tok::Kw("VAR_IN_OUT") => Section::InOut,
            Tok::Kw("VAR_GLOBAL") => Section::Global,
            Tok::Kw("VAR_TEMP") => Section::Temp,
            Tok::Kw("VAR_EXTERNAL") => Section::External,
            _ => return None,
        };
        let (mut retain, mut constant) = (false, false);
        loop {
            if self.eat_kw("RETAIN") || self.eat_kw("PERSISTENT") {
                retain = true;
            } else if self.eat_kw("CONSTANT") {
                constant = true;
            } else if !self.eat_kw("NON_RETAIN") {
                break;
            }
        }
        let mut decls = Vec::new();
        while !self.is_kw("END_VAR") && !self.at_eof() && !self.at_kw_in(TOP_LEVEL) {
            let start = self.pos();
            match self.var_decl() {
                Some(d) => decls.push(d),
                None => self.recover_from(start, &["END_VAR"]),
            }
        }
        self.expect_kw("END_VAR");
        Some(VarBlock {
            section,
            retain,
            constant,
            decls,
        })
    }

    /// `a, b AT %IX0.0 : T := init;`
    fn var_decl(&mut self) -> Option<VarDecl> {
        let mut names = vec![self.ident()?];
        while self.eat_p(",") {
            names.push(self.ident()?);
        }
        let at = if self.eat_kw("AT") {
            match self.bump() {
                Tok::Address(a) => Some(a),
                _ => {
                    self.error("expected a located address like %IX0.0 after AT");
                    return None;
                }
            }
        } else {
            None
        };
        if !self.expect_p(":") {
            return None;
        }
        let ty = self.type_ref()?;
        let init = if self.eat_p(":=") {
            Some(self.init()?)
        } else {
            None
        };
        if !self.expect_p(";") {
            return None;
        }
        Some(VarDecl {
            names,
            ty,
            init,
            at,
        })
    }

    fn type_ref(&mut self) -> Option<TypeRef> {
        let span = self.span();
        if self.eat_kw("ARRAY") {
            self.expect_p("[");
            let mut ranges = Vec::new();
            loop {
                let lo = self.expr()?;
                self.expect_p("..");
                let hi = self.expr()?;
                ranges.push((lo, hi));
                if !self.eat_p(",") {
                    break;
                }
            }
            self.expect_p("]");
            self.expect_kw("OF");
            let elem = self.type_ref()?;
            return Some(TypeRef::Array(ranges, Box::new(elem), span));
        }
        let id = self.ident()?;
        if id.key() == "STRING" || id.key() == "WSTRING" {
            if self.eat_p("(") || self.eat_p("[") {
                self.expr();
                if !self.eat_p(")") {
                    self.expect_p("]");
                }
            }
            return Some(TypeRef::String(span));
        }
        Some(TypeRef::Named(id))
    }

    fn init(&mut self) -> Option<Init> {
        let span = self.span();
        if self.eat_p("[") {
            let mut items = Vec::new();
            if !self.is_p("]") {
                loop {
                    // `n(value)` repeats; anything else is one element.
                    let repeat = matches!(self.peek(), Tok::Int(..))
                        && matches!(self.peek_at(1), Tok::P("("));
                    if repeat {
                        let span = self.span();
                        let n = match self.bump() {
                            Tok::Int(v, t) => Expr {
                                kind: ExprKind::Lit(super::expr::Lit::Int(v, t)),
                                span,
                            },
                            _ => return None,
                        };
                        self.expect_p("(");
                        let v = self.init()?;
                        self.expect_p(")");
                        items.push((Some(n), v));
                    } else {
                        items.push((None, self.init()?));
                    }
                    if !self.eat_p(",") {
                        break;
                    }
                }
            }
            self.expect_p("]");
            return Some(Init::List(items, span));
        }
        let fields = self.is_p("(")
            && matches!(self.peek_at(1), Tok::Ident(_))
            && matches!(self.peek_at(2), Tok::P(":="));
        if fields {
            self.bump();
            let mut items = Vec::new();
            loop {
                let id = self.ident()?;
                self.expect_p(":=");
                items.push((id, self.init()?));
                if !self.eat_p(",") {
                    break;
                }
            }
            self.expect_p(")");
            return Some(Init::Fields(items, span));
        }
        Some(Init::Expr(self.expr()?))
    }

    pub(crate) fn types(&mut self, out: &mut Vec<TypeDecl>) {
        self.bump();
        while !self.is_kw("END_TYPE") && !self.at_eof() && !self.at_kw_in(TOP_LEVEL) {
            let start = self.pos();
            match self.type_decl() {
                Some(t) => out.push(t),
                None => self.recover_from(start, &["END_TYPE", "END_STRUCT"]),
            }
            if self.eat_kw("END_STRUCT") {
                self.eat_p(";");
            }
        }
        self.expect_kw("END_TYPE");
    }

    fn type_decl(&mut self) -> Option<TypeDecl> {
        let name = self.ident()?;
        self.expect_p(":");
        if self.eat_kw("STRUCT") {
            let mut fields = Vec::new();
            while !self.is_kw("END_STRUCT")
                && !self.at_eof()
                && !self.is_kw("END_TYPE")
                && !self.at_kw_in(TOP_LEVEL)
            {
                let start = self.pos();
                match self.var_decl() {
                    Some(d) => fields.push(d),
                    None => self.recover_from(start, &["END_STRUCT", "END_TYPE"]),
                }
            }
            self.expect_kw("END_STRUCT");
            self.eat_p(";");
            return Some(TypeDecl::Struct(name, fields));
        }
        if self.eat_p("(") {
            let mut values = Vec::new();
            loop {
                let v = self.ident()?;
                let init = if self.eat_p(":=") {
                    Some(self.expr()?)
                } else {
                    None
                };
                values.push((v, init));
                if !self.eat_p(",") {
                    break;
                }
            }
            self.expect_p(")");
            // TwinCAT allows a base type after the list: `(A, B) INT`.
            if matches!(self.peek(), Tok::Ident(_)) {
                self.bump();
            }
            self.expect_p(";");
            return Some(TypeDecl::Enum(name, values));
        }
        let ty = self.type_ref()?;
        if self.eat_p(":=") {
            self.init();
        }
        self.expect_p(";");
        Some(TypeDecl::Alias(name, ty))
    }

    /// Statements up to a block-ending keyword.
    pub fn stmts(&mut self) -> Vec<Stmt> {
        let mut out = Vec::new();
        while !self.at_eof() && !self.at_kw_in(BLOCK_END) && !self.at_kw_in(TOP_LEVEL) {
            if self.eat_p(";") {
                continue;
            }
            let start = self.pos();
            match self.stmt() {
                Some(s) => out.push(s),
                None => self.recover_from(start, BLOCK_END),
            }
        }
        out
    }

    fn end_stmt(&mut self) -> Option<()> {
        self.expect_p(";").then_some(())
    }

    pub(crate) fn stmt(&mut self) -> Option<Stmt> {
        let span = self.span();
        let kind = match self.peek().clone() {
            Tok::Kw("IF") => {
                self.bump();
                let mut arms = Vec::new();
                let c = self.expr()?;
                self.expect_kw("THEN");
                arms.push((c, self.stmts()));
                let mut els = None;
                loop {
                    if self.eat_kw("ELSIF") {
                        let c = self.expr()?;
                        self.expect_kw("THEN");
                        arms.push((c, self.stmts()));
                    } else if self.eat_kw("ELSE") {
                        els = Some(self.stmts());
                    } else {
                        break;
                    }
                }
                self.expect_kw("END_IF");
                self.eat_p(";");
                return Some(Stmt {
                    kind: StmtKind::If(arms, els),
                    span,
                });
            }
            Tok::Kw("CASE") => {
                self.bump();
                let sel = self.expr()?;
                self.expect_kw("OF");
                let mut arms = Vec::new();
                let mut els = None;
                while !self.at_eof() && !self.is_kw("END_CASE") {
                    if self.eat_kw("ELSE") {
                        self.eat_p(":");
                        els = Some(self.stmts());
                        break;
                    }
                    let mut labels = Vec::new();
                    loop {
                        let lo = self.expr()?;
                        if self.eat_p("..") {
                            labels.push(CaseLabel::Range(lo, self.expr()?));
                        } else {
                            labels.push(CaseLabel::One(lo));
                        }
                        if !self.eat_p(",") {
                            break;
                        }
                    }
                    if !self.expect_p(":") {
                        return None;
                    }
                    arms.push((labels, self.case_body()));
                }
                self.expect_kw("END_CASE");
                self.eat_p(";");
                StmtKind::Case(sel, arms, els)
            }
            Tok::Kw("FOR") => {
                self.bump();
                let var = self.ident()?;
                self.expect_p(":=");
                let from = self.expr()?;
                self.expect_kw("TO");
                let to = self.expr()?;
                let by = if self.eat_kw("BY") {
                    Some(self.expr()?)
                } else {
                    None
                };
                self.expect_kw("DO");
                let body = self.stmts();
                self.expect_kw("END_FOR");
                self.eat_p(";");
                StmtKind::For {
                    var,
                    from,
                    to,
                    by,
                    body,
                }
            }
            Tok::Kw("WHILE") => {
                self.bump();
                let c = self.expr()?;
                self.expect_kw("DO");
                let body = self.stmts();
                self.expect_kw("END_WHILE");
                self.eat_p(";");
                StmtKind::While(c, body)
            }
            Tok::Kw("REPEAT") => {
                self.bump();
                let body = self.stmts();
                self.expect_kw("UNTIL");
                let c = self.expr()?;
                self.expect_kw("END_REPEAT");
                self.eat_p(";");
                StmtKind::Repeat(body, c)
            }
            Tok::Kw(k @ ("EXIT" | "CONTINUE" | "RETURN")) => {
                self.bump();
                self.end_stmt()?;
                match k {
                    "EXIT" => StmtKind::Exit,
                    "CONTINUE" => StmtKind::Continue,
                    _ => StmtKind::Return,
                }
            }
            _ => {
                let target = self.expr()?;
                if self.eat_p(":=") {
                    let value = self.expr()?;
                    self.end_stmt()?;
                    StmtKind::Assign(target, value)
                } else if let ExprKind::Call(callee, args) = target.kind {
                    self.end_stmt()?;
                    StmtKind::Call(*callee, args)
                } else {
                    let msg = format!(
                        "expected ':=' or a call after the expression, found {}",
                        self.describe()
                    );
                    self.error(msg);
                    return None;
                }
            }
        };
        Some(Stmt { kind, span })
    }

    /// The statements of a CASE arm: up to the next label (`expr :` or `expr ..`).
    fn case_body(&mut self) -> Vec<Stmt> {
        let mut out = Vec::new();
        loop {
            if self.at_eof() || self.at_kw_in(BLOCK_END) || self.at_kw_in(TOP_LEVEL) {
                return out;
            }
            if self.eat_p(";") {
                continue;
            }
            if self.at_case_label() {
                return out;
            }
            let start = self.pos();
            match self.stmt() {
                Some(s) => out.push(s),
                None => self.recover_from(start, &["END_CASE", "ELSE"]),
            }
        }
    }

    /// Looks ahead for `label [, label]* :` where a label is a (signed) literal, a name or a
    /// range; a statement never has `:` (only `:=`) at its top level.
    fn at_case_label(&self) -> bool {
        let mut k = 0;
        loop {
            match self.peek_at(k) {
                Tok::P("-") => k += 1,
                Tok::Int(..) | Tok::Ident(_) => {}
                _ => return false,
            }
            k += 1;
            while matches!(self.peek_at(k), Tok::P("."))
                && matches!(self.peek_at(k + 1), Tok::Ident(_))
            {
                k += 2;
            }
            match self.peek_at(k) {
                Tok::P(":") => return true,
                Tok::P(",") | Tok::P("..") => k += 1,
                _ => return false,
            }
        }
    }
}

pub(crate) enum PouKindTag {
    Program,
    Fb,
    Function,
}

/// The expression is a plain name (used by checks on assignment targets).
pub fn is_name(e: &Expr) -> bool {
    matches!(e.kind, ExprKind::Name(_))
}
