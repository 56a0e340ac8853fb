//! Syntax tree of the PLC constructs: program organisation units, declarations, statements.

use super::diag::Span;
use super::expr::{Arg, Expr, Ident};

/// A reference to a type in a declaration.
#[derive(Debug, Clone, PartialEq)]
pub enum TypeRef {
    /// `INT`, `TON`, `MyStruct`.
    Named(Ident),
    /// `ARRAY[lo..hi, ...] OF elem`.
    Array(Vec<(Expr, Expr)>, Box<TypeRef>, Span),
    /// `STRING(n)`: parsed so files using it get a clear error.
    String(Span),
}

/// An initial value.
#[derive(Debug, Clone, PartialEq)]
pub enum Init {
    /// `:= expr`
    Expr(Expr),
    /// `[a, b, n(c)]` for arrays: each element with its repeat count.
    List(Vec<(Option<Expr>, Init)>, Span),
    /// `(x := 1, y := 2)` for structures and function blocks.
    Fields(Vec<(Ident, Init)>, Span),
}

/// `a, b : T := init;`
#[derive(Debug, Clone, PartialEq)]
pub struct VarDecl {
    /// The names declared.
    pub names: Vec<Ident>,
    /// Their type.
    pub ty: TypeRef,
    /// Initial value.
    pub init: Option<Init>,
    /// `AT %IX0.0`, kept verbatim.
    pub at: Option<String>,
}

/// The kind of a variable section.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Section {
    /// `VAR`
    Var,
    /// `VAR_INPUT`
    Input,
    /// `VAR_OUTPUT`
    Output,
    /// `VAR_IN_OUT`
    InOut,
    /// `VAR_GLOBAL`
    Global,
    /// `VAR_TEMP`
    Temp,
    /// `VAR_EXTERNAL`: a declaration of a global used here.
    External,
}

/// One `VAR... END_VAR` block.
#[derive(Debug, Clone, PartialEq)]
pub struct VarBlock {
    /// Which section.
    pub section: Section,
    /// `RETAIN` / `PERSISTENT`.
    pub retain: bool,
    /// `CONSTANT`.
    pub constant: bool,
    /// The declarations.
    pub decls: Vec<VarDecl>,
}

/// Kinds of program organisation units.
#[derive(Debug, Clone, PartialEq)]
pub enum PouKind {
    /// `PROGRAM`
    Program,
    /// `FUNCTION_BLOCK`
    FunctionBlock,
    /// `FUNCTION name : T`
    Function(TypeRef),
}

/// A program organisation unit.
#[derive(Debug, Clone, PartialEq)]
pub struct Pou {
    /// Which kind.
    pub kind: PouKind,
    /// Its name.
    pub name: Ident,
    /// Its variable blocks.
    pub vars: Vec<VarBlock>,
    /// Its body.
    pub body: Vec<Stmt>,
}

/// `TYPE ... END_TYPE` entries.
#[derive(Debug, Clone, PartialEq)]
pub enum TypeDecl {
    /// `Name : STRUCT ... END_STRUCT`
    Struct(Ident, Vec<VarDecl>),
    /// `Name : (A, B := 5, C)`
    Enum(Ident, Vec<(Ident, Option<Expr>)>),
    /// `Name : T`
    Alias(Ident, TypeRef),
}

/// One source file.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Unit {
    /// Data types.
    pub types: Vec<TypeDecl>,
    /// Global variable blocks.
    pub globals: Vec<VarBlock>,
    /// POUs in source order.
    pub pous: Vec<Pou>,
}

/// A CASE label.
#[derive(Debug, Clone, PartialEq)]
pub enum CaseLabel {
    /// `5`
    One(Expr),
    /// `1..4`
    Range(Expr, Expr),
}

/// A statement.
#[derive(Debug, Clone, PartialEq)]
pub struct Stmt {
    /// What it is.
    pub kind: StmtKind,
    /// Where it starts.
    pub span: Span,
}

/// The kinds of statements.
#[derive(Debug, Clone, PartialEq)]
pub enum StmtKind {
    /// `a := b;`
    Assign(Expr, Expr),
    /// `fb(args);` or `f(args);`
    Call(Expr, Vec<Arg>),
    /// `IF c THEN ... ELSIF ... ELSE ... END_IF`
    If(Vec<(Expr, Vec<Stmt>)>, Option<Vec<Stmt>>),
    /// `CASE e OF labels: ... ELSE ... END_CASE`
    Case(Expr, Vec<(Vec<CaseLabel>, Vec<Stmt>)>, Option<Vec<Stmt>>),
    /// `FOR v := a TO b BY c DO ... END_FOR`
    For {
        /// Loop variable.
        var: Ident,
        /// Start value.
        from: Expr,
        /// End value.
        to: Expr,
        /// Step.
        by: Option<Expr>,
        /// Body.
        body: Vec<Stmt>,
    },
    /// `WHILE c DO ... END_WHILE`
    While(Expr, Vec<Stmt>),
    /// `REPEAT ... UNTIL c END_REPEAT`
    Repeat(Vec<Stmt>, Expr),
    /// `EXIT`
    Exit,
    /// `CONTINUE` (ed.3)
    Continue,
    /// `RETURN`
    Return,
}
