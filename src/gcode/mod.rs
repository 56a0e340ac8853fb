//! RS274/NGC (LinuxCNC dialect) front end: text in, canonical commands out. No threads, no
//! planner, no socket: the interpreter is a pure function of its input files and options.

pub mod canon;

pub use canon::{Canon, CanonCmd, Pose, SourceLoc, NUM_AXES};

use std::path::{Path, PathBuf};

/// Options of one interpreter run.
#[derive(Debug, Clone, Default)]
pub struct InterpOptions {
    /// Tool table file (LinuxCNC `.tbl` format) for M6/G43.
    pub tool_table: Option<PathBuf>,
    /// Directories searched for `o<name> call` subroutine files.
    pub subroutine_path: Vec<PathBuf>,
    /// `/` block delete switch.
    pub block_delete: bool,
}

/// A whole interpreted program: validated as a unit before any motion starts.
#[derive(Debug, Clone, Default)]
pub struct Program {
    /// The canonical commands, in execution order.
    pub canon: Vec<Canon>,
}

/// An interpreter error: names file, line and column.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{file}:{line}:{col}: {message}")]
pub struct GcodeError {
    /// File the error is in.
    pub file: String,
    /// 1-based line.
    pub line: u32,
    /// 1-based column.
    pub col: u32,
    /// What is wrong, in words close to LinuxCNC's.
    pub message: String,
}

/// Interprets a program file.
pub fn load_file(path: &Path, _opts: &InterpOptions) -> Result<Program, GcodeError> {
    Err(GcodeError {
        file: path.display().to_string(),
        line: 1,
        col: 1,
        message: "G-code interpreter not built yet".into(),
    })
}

/// Interprets program text; `name` is used as the file name in locations and errors.
pub fn load_str(name: &str, _text: &str, _opts: &InterpOptions) -> Result<Program, GcodeError> {
    Err(GcodeError {
        file: name.into(),
        line: 1,
        col: 1,
        message: "G-code interpreter not built yet".into(),
    })
}
