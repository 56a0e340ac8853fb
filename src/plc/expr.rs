//! Expressions of Structured Text: their syntax tree and parser, and the token cursor the
//! rest of the parser builds on. Nothing here knows about POUs or variable sections, so the
//! scripted programs of issue 12 can reuse it.
//!
//! Operator precedence, highest first (IEC 61131-3 ed.3 table 71): parentheses and calls,
//! `**`, unary `-`/`NOT`, `* / MOD`, `+ -`, `< > <= >=`, `= <>`, `AND &`, `XOR`, `OR`.

use super::diag::{Diag, Span};
use super::lexer::{Tok, Token};

/// An identifier with its spelling and position.
#[derive(Debug, Clone, PartialEq)]
pub struct Ident {
    /// As written.
    pub name: String,
    /// Where.
    pub span: Span,
}

impl Ident {
    /// The case-folded name, the key of every symbol table (ST is case-insensitive).
    pub fn key(&self) -> String {
        self.name.to_ascii_uppercase()
    }
}

/// A literal value.
#[derive(Debug, Clone, PartialEq)]
pub enum Lit {
    /// TRUE / FALSE.
    Bool(bool),
    /// Integer, with its type prefix if any (`INT#5`).
    Int(i128, Option<String>),
    /// Real, with its type prefix if any.
    Real(f64, Option<String>),
    /// Duration in nanoseconds.
    Time(i64),
    /// Character string (parsed; not a supported data type).
    Str(String),
}

/// Binary operators.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BinOp {
    /// `+`
    Add,
    /// `-`
    Sub,
    /// `*`
    Mul,
    /// `/`
    Div,
    /// `MOD`
    Mod,
    /// `**`
    Pow,
    /// `=`
    Eq,
    /// `<>`
    Ne,
    /// `<`
    Lt,
    /// `<=`
    Le,
    /// `>`
    Gt,
    /// `>=`
    Ge,
    /// `AND`, `&`
    And,
    /// `OR`
    Or,
    /// `XOR`
    Xor,
}

/// Unary operators.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum UnOp {
    /// `-`
    Neg,
    /// `NOT`
    Not,
}

/// An argument of a call: positional `x`, input `IN := x`, or output `Q => y`.
#[derive(Debug, Clone, PartialEq)]
pub struct Arg {
    /// The formal parameter, if named.
    pub name: Option<Ident>,
    /// `=>`: an output assignment.
    pub output: bool,
    /// The value (for an output: where it goes).
    pub value: Expr,
}

/// An expression.
#[derive(Debug, Clone, PartialEq)]
pub struct Expr {
    /// What it is.
    pub kind: ExprKind,
    /// Where it starts.
    pub span: Span,
}

/// The kinds of expressions.
#[derive(Debug, Clone, PartialEq)]
pub enum ExprKind {
    /// A literal.
    Lit(Lit),
    /// A variable, constant or enumeration value.
    Name(Ident),
    /// `e.field`
    Member(Box<Expr>, Ident),
    /// `e.3`: a bit of a bit string.
    Bit(Box<Expr>, u8),
    /// `e[i, j]`
    Index(Box<Expr>, Vec<Expr>),
    /// `op e`
    Unary(UnOp, Box<Expr>),
    /// `a op b`
    Binary(BinOp, Box<Expr>, Box<Expr>),
    /// `f(args)`: a function, or a function block instance as a statement.
    Call(Box<Expr>, Vec<Arg>),
}

/// A token cursor that collects diagnostics instead of stopping at the first.
pub struct Parser {
    toks: Vec<Token>,
    pos: usize,
    /// Errors so far.
    pub diags: Vec<Diag>,
}

impl Parser {
    /// A parser over `toks` (which ends with [`Tok::Eof`]).
    pub fn new(toks: Vec<Token>, diags: Vec<Diag>) -> Self {
        Parser {
            toks,
            pos: 0,
            diags,
        }
    }
    /// The current token.
    pub fn peek(&self) -> &Tok {
        self.peek_at(0)
    }
    /// The token `k` ahead.
    pub fn peek_at(&self, k: usize) -> &Tok {
        let i = (self.pos + k).min(self.toks.len() - 1);
        &self.toks[i].tok
    }
    /// Where the current token starts.
    pub fn span(&self) -> Span {
        self.toks[self.pos.min(self.toks.len() - 1)].span
    }
    /// Consumes the current token.
    pub fn bump(&mut self) -> Tok {
        let t = self.peek().clone();
        if self.pos < self.toks.len() - 1 {
            self.pos += 1;
        }
        t
    }
    /// Index of the current token (to check that error recovery made progress).
    pub fn pos(&self) -> usize {
        self.pos
    }
    /// At the end of input.
    pub fn at_eof(&self) -> bool {
        matches!(self.peek(), Tok::Eof)
    }
    /// The current token is punctuation `p`.
    pub fn is_p(&self, p: &str) -> bool {
        matches!(self.peek(), Tok::P(q) if *q == p)
    }
    /// The current token is keyword `k`.
    pub fn is_kw(&self, k: &str) -> bool {
        matches!(self.peek(), Tok::Kw(q) if *q == k)
    }
    /// Consumes punctuation `p` if it is next.
    pub fn eat_p(&mut self, p: &str) -> bool {
        let y = self.is_p(p);
        if y {
            self.bump();
        }
        y
    }
    /// Consumes keyword `k` if it is next.
    pub fn eat_kw(&mut self, k: &str) -> bool {
        let y = self.is_kw(k);
        if y {
            self.bump();
        }
        y
    }
    /// Records an error at the current token.
    pub fn error(&mut self, msg: impl Into<String>) {
        let span = self.span();
        self.error_at(span, msg);
    }
    /// Records an error at `span` (one per position: recovery may revisit a spot).
    pub fn error_at(&mut self, span: Span, msg: impl Into<String>) {
        if self.diags.last().is_some_and(|d| d.span == span) {
            return;
        }
        self.diags.push(Diag::new(span, msg));
    }
    /// Describes the current token for messages.
    pub fn describe(&self) -> String {
        describe(self.peek())
    }
    /// Expects punctuation `p`; records an error if it is missing.
    pub fn expect_p(&mut self, p: &str) -> bool {
        if self.eat_p(p) {
            return true;
        }
        let msg = format!("expected '{p}', found {}", self.describe());
        self.error(msg);
        false
    }
    /// Expects keyword `k`; records an error if it is missing.
    pub fn expect_kw(&mut self, k: &str) -> bool {
        if self.eat_kw(k) {
            return true;
        }
        let msg = format!("expected {k}, found {}", self.describe());
        self.error(msg);
        false
    }
    /// Expects an identifier.
    pub fn ident(&mut self) -> Option<Ident> {
        let span = self.span();
        if let Tok::Ident(name) = self.peek() {
            let name = name.clone();
            self.bump();
            return Some(Ident { name, span });
        }
        let msg = format!("expected a name, found {}", self.describe());
        self.error(msg);
        None
    }

    /// Parses an expression.
    pub fn expr(&mut self) -> Option<Expr> {
        self.binary(0)
    }

    fn binary(&mut self, level: usize) -> Option<Expr> {
        // Levels from loosest: OR, XOR, AND, equality, relational, additive, multiplicative.
        const LEVELS: &[&[(&str, BinOp)]] = &[
            &[("OR", BinOp::Or)],
            &[("XOR", BinOp::Xor)],
            &[("AND", BinOp::And), ("&", BinOp::And)],
            &[("=", BinOp::Eq), ("<>", BinOp::Ne)],
            &[
                ("<", BinOp::Lt),
                ("<=", BinOp::Le),
                (">", BinOp::Gt),
                (">=", BinOp::Ge),
            ],
            &[("+", BinOp::Add), ("-", BinOp::Sub)],
            &[("*", BinOp::Mul), ("/", BinOp::Div), ("MOD", BinOp::Mod)],
        ];
        if level == LEVELS.len() {
            return self.unary();
        }
        let mut lhs = self.binary(level + 1)?;
        loop {
            let op = LEVELS[level].iter().find(|(t, _)| match self.peek() {
                Tok::P(p) => p == t,
                Tok::Kw(k) => k == t,
                _ => false,
            });
            let Some(&(_, op)) = op else {
                return Some(lhs);
            };
            let span = self.span();
            self.bump();
            let rhs = self.binary(level + 1)?;
            lhs = Expr {
                kind: ExprKind::Binary(op, Box::new(lhs), Box::new(rhs)),
                span,
            };
        }
    }

    fn unary(&mut self) -> Option<Expr> {
        let span = self.span();
        let op = if self.eat_p("-") {
            Some(UnOp::Neg)
        } else if self.eat_kw("NOT") {
            Some(UnOp::Not)
        } else {
            self.eat_p("+");
            None
        };
        let Some(op) = op else {
            return self.power();
        };
        let e = self.unary()?;
        // Fold a minus into a literal so `-32768` is an INT, not the negation of an overflow.
        let kind = match (op, e.kind) {
            (UnOp::Neg, ExprKind::Lit(Lit::Int(v, t))) => ExprKind::Lit(Lit::Int(-v, t)),
            (UnOp::Neg, ExprKind::Lit(Lit::Real(v, t))) => ExprKind::Lit(Lit::Real(-v, t)),
            (op, kind) => ExprKind::Unary(op, Box::new(Expr { kind, span: e.span })),
        };
        Some(Expr { kind, span })
    }

    fn power(&mut self) -> Option<Expr> {
        let mut lhs = self.postfix()?;
        while self.is_p("**") {
            let span = self.span();
            self.bump();
            let rhs = self.postfix()?;
            lhs = Expr {
                kind: ExprKind::Binary(BinOp::Pow, Box::new(lhs), Box::new(rhs)),
                span,
            };
        }
        Some(lhs)
    }

    fn postfix(&mut self) -> Option<Expr> {
        let mut e = self.primary()?;
        loop {
            let span = self.span();
            if self.eat_p("#") {
                let id = self.ident()?;
                e = Expr {
                    span: e.span,
                    kind: ExprKind::Member(Box::new(e), id),
                };
            } else if self.eat_p(".") {
                match self.peek().clone() {
                    Tok::Int(b, None) if (0..64).contains(&b) => {
                        self.bump();
                        e = Expr {
                            span: e.span,
                            kind: ExprKind::Bit(Box::new(e), b as u8),
                        };
                    }
                    _ => {
                        let id = self.ident()?;
                        e = Expr {
                            span: e.span,
                            kind: ExprKind::Member(Box::new(e), id),
                        };
                    }
                }
            } else if self.eat_p("[") {
                let mut idx = vec![self.expr()?];
                while self.eat_p(",") {
                    idx.push(self.expr()?);
                }
                self.expect_p("]");
                e = Expr {
                    span: e.span,
                    kind: ExprKind::Index(Box::new(e), idx),
                };
            } else if self.is_p("(") {
                self.bump();
                let args = self.args()?;
                let span = e.span;
                e = Expr {
                    kind: ExprKind::Call(Box::new(e), args),
                    span,
                };
            } else if self.eat_p("^") {
                self.error_at(span, "pointer dereference (^) is not supported");
            } else {
                return Some(e);
            }
        }
    }

    /// Call arguments after `(`, through `)`.
    fn args(&mut self) -> Option<Vec<Arg>> {
        let mut args = Vec::new();
        if self.eat_p(")") {
            return Some(args);
        }
        loop {
            let named = matches!(self.peek(), Tok::Ident(_))
                && matches!(self.peek_at(1), Tok::P(":=") | Tok::P("=>"));
            let (name, output) = if named {
                let id = self.ident();
                let out = matches!(self.bump(), Tok::P("=>"));
                (id, out)
            } else {
                (None, false)
            };
            let value = self.expr()?;
            args.push(Arg {
                name,
                output,
                value,
            });
            if !self.eat_p(",") {
                break;
            }
        }
        self.expect_p(")");
        Some(args)
    }

    fn primary(&mut self) -> Option<Expr> {
        let span = self.span();
        let kind = match self.peek().clone() {
            Tok::Int(v, t) => ExprKind::Lit(Lit::Int(v, t)),
            Tok::Real(v, t) => ExprKind::Lit(Lit::Real(v, t)),
            Tok::Time(v) => ExprKind::Lit(Lit::Time(v)),
            Tok::Str(s) => ExprKind::Lit(Lit::Str(s)),
            Tok::Kw("TRUE") => ExprKind::Lit(Lit::Bool(true)),
            Tok::Kw("FALSE") => ExprKind::Lit(Lit::Bool(false)),
            Tok::Ident(name) => ExprKind::Name(Ident { name, span }),
            Tok::P("(") => {
                self.bump();
                let e = self.expr()?;
                self.expect_p(")");
                return Some(e);
            }
            _ => {
                let msg = format!("expected an expression, found {}", self.describe());
                self.error(msg);
                return None;
            }
        };
        self.bump();
        Some(Expr { kind, span })
    }
}

/// A token as a message shows it.
pub fn describe(t: &Tok) -> String {
    match t {
        Tok::Ident(s) => format!("'{s}'"),
        Tok::Kw(k) => k.to_string(),
        Tok::Int(v, _) => format!("'{v}'"),
        Tok::Real(v, _) => format!("'{v}'"),
        Tok::Time(_) => "a TIME literal".into(),
        Tok::Str(_) => "a string".into(),
        Tok::Address(a) => format!("'{a}'"),
        Tok::P(p) => format!("'{p}'"),
        Tok::Eof => "end of file".into(),
    }
}
