//! The PLC: IEC 61131-3 Structured Text compiled at load to bytecode with all storage laid
//! out in advance, scanned without allocation (issue 11).
//!
//! Layers, each usable alone:
//! - [`lexer`], [`expr`], [`types`]: tokens, expressions and their typing rules. They know
//!   nothing of POUs, so other front ends (issue 12's scripted programs) can reuse them.
//! - [`ast`], [`parser`]: PROGRAM / FUNCTION_BLOCK / FUNCTION, declarations, statements.
//! - [`compile`] (with `builtins`, `peephole`, `stack`): layout, type checking, code
//!   generation, fusion of instruction pairs, stack sizing.
//! - [`vm`], [`stdfb`]: the interpreter and the standard function blocks.
//! - [`program`], [`value`]: the loaded program, its variable table and its scan.
//! - [`bind`], [`link`], [`task`]: the PLC in the machine: bindings of variables to the
//!   machine's signals, the data exchanged with the machine task, the realtime scan task.
//! - [`online`]: reads, writes, forces and program loads while the PLC runs.

pub mod ast;
#[cfg(not(loom))]
pub mod bind;
mod builtins;
pub mod compile;
#[cfg(not(loom))]
pub mod deploy;
pub mod diag;
pub mod expr;
pub mod lexer;
#[cfg(not(loom))]
pub mod link;
#[cfg(not(loom))]
pub mod online;
pub mod op;
pub mod parser;
mod peephole;
pub mod program;
pub mod retain;
mod stack;
pub mod stdfb;
mod superop;
#[cfg(not(loom))]
pub mod task;
pub mod types;
pub mod value;
pub mod vm;

pub use compile::{compile, Options};
pub use diag::{Diag, Diags, Span};
pub use program::{Fault, InterfaceEntry, Program, VarId, VarInfo, VarKind};
pub use types::{IntKind, Ty};
pub use value::Value;
pub use vm::FaultKind;

/// Most variables `[plc] m66_digital` may list (M66 P0..P63, a 64-bit image).
pub const M66_DIGITAL_MAX: usize = 64;
/// Most variables `[plc] m66_analog` may list (M66 E0..E15).
pub const M66_ANALOG_MAX: usize = 16;

/// Reads and compiles a program file.
pub fn load_file(path: &std::path::Path, opts: Options) -> Result<Program, LoadError> {
    let src = std::fs::read_to_string(path).map_err(|e| LoadError::Read {
        path: path.display().to_string(),
        source: e,
    })?;
    Ok(compile(&path.display().to_string(), &src, opts)?)
}

/// Loading a program file failed.
#[derive(Debug, thiserror::Error)]
pub enum LoadError {
    /// The file could not be read.
    #[error("cannot read {path}: {source}")]
    Read {
        /// The file.
        path: String,
        /// Why.
        source: std::io::Error,
    },
    /// It did not compile.
    #[error("{0}")]
    Compile(#[from] Diags),
}
