//! Syntax tree of the script constructs. Plain ST statements stay PLC [`Stmt`]s; a
//! statement becomes a script statement only when it (or something inside it) must resume
//! across steps (DO, WAIT, TRY, START, STOP, EMIT, or an EXIT of such a loop).

use crate::plc::ast::{Stmt, Unit};
use crate::plc::diag::Span;
use crate::plc::expr::{Expr, Ident};

/// A script statement.
#[derive(Debug, Clone, PartialEq)]
pub struct SStmt {
    /// What it is.
    pub kind: SKind,
    /// Where it starts.
    pub span: Span,
}

/// The kinds of script statements.
#[derive(Debug, Clone, PartialEq)]
pub enum SKind {
    /// Ordinary ST, run to completion within one step.
    Plain(Stmt),
    /// `IF` whose branches contain script statements.
    If(Vec<(Expr, Vec<SStmt>)>, Option<Vec<SStmt>>),
    /// `WHILE` containing script statements.
    While(Expr, Vec<SStmt>),
    /// `REPEAT ... UNTIL c END_REPEAT` containing script statements.
    Repeat(Vec<SStmt>, Expr),
    /// `FOR` containing script statements (rejected by the compiler: use WHILE).
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
        body: Vec<SStmt>,
    },
    /// `EXIT` of a script loop.
    Exit,
    /// `CONTINUE` of a script loop.
    Continue,
    /// `RETURN`: ends the block.
    Return,
    /// `DO peer.op(args);`
    Do {
        /// Peer task name (may contain dots).
        peer: String,
        /// Operation.
        op: Ident,
        /// Arguments.
        args: Vec<DoArg>,
    },
    /// `TRY ... CATCH ... END_TRY`
    Try(Vec<SStmt>, Vec<SStmt>),
    /// `WAIT name [TIMEOUT t];`: an event (dotted) or a program of the file.
    Wait(String, Option<Expr>),
    /// `WAIT UNTIL c [TIMEOUT t];`
    WaitUntil(Expr, Option<Expr>),
    /// `START program;`
    Start(Ident),
    /// `STOP program;`
    Stop(Ident),
    /// `EMIT name;`
    Emit(String),
}

/// A transition of a state.
#[derive(Debug, Clone, PartialEq)]
pub struct Transition {
    /// `ON event`.
    pub event: Option<(String, Span)>,
    /// `WHEN cond`.
    pub cond: Option<Expr>,
    /// `TO state`.
    pub target: Ident,
    /// Where.
    pub span: Span,
}

/// Which kind of state.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StateKind {
    /// `STATE`
    Normal,
    /// `INITIAL STATE`
    Initial,
    /// `FINAL STATE`
    Final,
    /// `ERROR STATE`
    Error,
}

/// A state of a state machine.
#[derive(Debug, Clone, PartialEq)]
pub struct State {
    /// Name.
    pub name: Ident,
    /// Kind.
    pub kind: StateKind,
    /// `PRECONDITION e;` lines.
    pub pre: Vec<Expr>,
    /// `ENTRY ... END_ENTRY`
    pub entry: Vec<SStmt>,
    /// `RUN ... END_RUN`
    pub run: Option<Vec<SStmt>>,
    /// `EXIT ... END_EXIT`
    pub exit: Vec<SStmt>,
    /// Transitions, checked in order.
    pub transitions: Vec<Transition>,
}

/// A program or a state machine: the POU holding its variables is `unit.pous[pou]`.
#[derive(Debug, Clone, PartialEq)]
pub enum ItemKind {
    /// `PROGRAM ... END_PROGRAM`
    Program(Vec<SStmt>),
    /// `STATE_MACHINE ... END_STATE_MACHINE`
    Machine(Vec<State>),
}

/// A program or state machine.
#[derive(Debug, Clone, PartialEq)]
pub struct Item {
    /// Name.
    pub name: Ident,
    /// Index of its variables' POU in the unit.
    pub pou: usize,
    /// What it is.
    pub kind: ItemKind,
}

/// A parsed script file: the PLC unit (declarations, one empty PROGRAM per item) and the items.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ScriptFile {
    /// Declarations as the PLC compiler sees them.
    pub unit: Unit,
    /// Programs and state machines in source order.
    pub items: Vec<Item>,
}

/// An argument of `DO peer.op(...)`.
#[derive(Debug, Clone, PartialEq)]
pub enum DoArg {
    /// An ST expression, evaluated when the command is sent.
    Expr(Expr),
    /// A string literal (`'G0 X10'`), for operations with text parameters (a G-code line,
    /// a file name): constant, so sending it copies no text at runtime.
    Str(String),
}
