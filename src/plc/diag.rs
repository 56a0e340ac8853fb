//! Compile diagnostics: where (line, column) and what is wrong. The file name is attached
//! when diagnostics are reported ([`Diags`]), so the front end stays file-agnostic.

use std::fmt;

/// A position in the source, 1-based.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Default)]
pub struct Span {
    /// Line, from 1.
    pub line: u32,
    /// Column (characters), from 1.
    pub col: u32,
}

/// One compile error.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Diag {
    /// Where.
    pub span: Span,
    /// What is wrong.
    pub msg: String,
}

impl Diag {
    /// A diagnostic at `span`.
    pub fn new(span: Span, msg: impl Into<String>) -> Self {
        Diag {
            span,
            msg: msg.into(),
        }
    }
}

/// Every error found in one file, in source order: compiling does not stop at the first.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub struct Diags {
    /// The file (as given to the compiler).
    pub file: String,
    /// The errors, sorted by position.
    pub list: Vec<Diag>,
}

impl fmt::Display for Diags {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (i, d) in self.list.iter().enumerate() {
            if i > 0 {
                writeln!(f)?;
            }
            write!(f, "{}:{}:{}: {}", self.file, d.span.line, d.span.col, d.msg)?;
        }
        Ok(())
    }
}
