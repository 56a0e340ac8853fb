//! RS274/NGC (LinuxCNC dialect) front end: text in, canonical commands out. No threads, no
//! planner, no socket: the interpreter is a pure function of its input files and options.
//!
//! Pipeline: [`lexer`] (characters, blanks, case) → [`parser`] (a line to words,
//! assignments, comments or an O-word statement) → [`expr`] (values) → [`modal`] (a
//! checked [`modal::Block`]) → `interp` (modal state, execution order, O-word flow) →
//! [`canon`] commands. [`canon_fmt`] prints them in `rs274 -g` layout for differential
//! testing against LinuxCNC.
//!
//! Conformance is measured, not assumed: `tests/gcode_differential.rs` diffs every program
//! of `tests/gcode/corpus/` against LinuxCNC's `rs274` (stored goldens and, when installed,
//! live), and `tests/gcode/DIFFERENCES.md` lists what differs on purpose.
//!
//! # How to add a G or M code
//! 1. Give it its modal group in [`modal::g_group`]/[`modal::m_group`] (LinuxCNC's table).
//! 2. Execute it at its place in LinuxCNC's order of execution: `interp/block.rs` calls the
//!    steps in order; motion lives in `interp/motion.rs`, arcs in `arcs.rs`, canned cycles in
//!    `cycles.rs`, M codes in `mcodes.rs`. Let the words it uses through `check_block`.
//! 3. If rs274 prints a canon call hytask does not have, add a [`CanonCmd`] variant and its
//!    text in [`canon_fmt::push_call`].
//! 4. Add a corpus program (and an `err_*.ngc` for what it must reject), run
//!    `tests/gcode/regen-golden.sh`, and make `cargo test --test gcode_differential` pass.

pub mod canon;
pub mod canon_fmt;
pub mod expr;
pub mod ini;
mod interp;
pub mod ldouble;
pub mod lexer;
pub mod modal;
pub mod params;
pub mod parser;
pub mod python;
pub mod session;
pub mod tooltable;
pub mod trace_spill;
pub mod varfile;

pub use canon::{Canon, CanonCmd, LengthUnits, Pose, ProbeKind, SourceLoc, NUM_AXES};
pub use ini::IniValues;
pub use session::{Chunked, PieceEnd, ProbeResult, Session};
pub use varfile::VarFile;

use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Resource limits. Each one turns a hostile or broken program into a clear error instead of
/// a hang or an out-of-memory kill.
#[derive(Debug, Clone)]
pub struct Limits {
    /// Largest program or subroutine file, bytes.
    pub max_file_bytes: usize,
    /// Most lines in one file.
    pub max_lines: usize,
    /// Longest line, bytes.
    pub max_line_len: usize,
    /// Deepest expression nesting (brackets, functions, parameter indirection).
    pub max_expr_depth: usize,
    /// Deepest subroutine call nesting.
    pub max_call_depth: usize,
    /// Most iterations of one loop (while, do, repeat) per entry.
    pub max_loop_iterations: u64,
    /// Most blocks executed in one run (all loops and calls together).
    pub max_blocks: u64,
    /// Most canonical commands produced.
    pub max_canon: usize,
}

impl Default for Limits {
    fn default() -> Self {
        Limits {
            max_file_bytes: 512 << 20,
            max_lines: 20_000_000,
            max_line_len: 4096,
            max_expr_depth: 64,
            max_call_depth: 64,
            max_loop_iterations: 10_000_000,
            max_blocks: 200_000_000,
            max_canon: 50_000_000,
        }
    }
}

/// Options of one interpreter run.
#[derive(Debug, Clone)]
pub struct InterpOptions {
    /// Tool table file (LinuxCNC `.tbl` format) for M6/G43.
    pub tool_table: Option<PathBuf>,
    /// Directories searched for `o<name> call` subroutine files (`name.ngc`).
    pub subroutine_path: Vec<PathBuf>,
    /// Directory of the main program, searched after `subroutine_path` (set by `load_file`).
    pub program_dir: Option<PathBuf>,
    /// `/` block delete switch.
    pub block_delete: bool,
    /// Units of the tool table (LinuxCNC's machine units). rs274 without an INI file uses
    /// inches; a real machine configuration usually uses millimetres.
    pub machine_units: LengthUnits,
    /// Program units at start (before any G20/G21).
    pub initial_units: LengthUnits,
    /// Where the machine is when the program starts: X Y Z (mm) and A B C (deg), machine
    /// frame. LinuxCNC's interpreter reads this from the machine at start
    /// (`GET_EXTERNAL_POSITION`) so that a first move naming only some axes leaves the
    /// others where they are, and incremental moves and arcs start from the real position.
    /// `None` starts at 0, as `rs274` does standalone (the differential tests use that).
    pub initial_position: Option<[f64; 6]>,
    /// MDI: the text is a block (or a few) typed by an operator, not a program. It ends at the
    /// end of the text, with no `%` or M2 needed and none of M2's resets, as in LinuxCNC's
    /// MDI mode.
    pub mdi: bool,
    /// User M codes (M100–M199) the machine defines. Any other M1xx is refused as an unknown
    /// M code, as rs274 refuses one with no `M1xx` program on its user path: a CAM program
    /// written for another machine (`M107` fan off) must not run with the code silently
    /// doing nothing.
    pub user_mcodes: Vec<u16>,
    /// Persistent parameters at start (LinuxCNC's var file, [`varfile`]): work offsets, the
    /// active coordinate system, G92, G28/G30 positions and any user parameter the file lists.
    /// `None` starts from zeros in G54, as `rs274` without `-v` does.
    pub parameters: Option<Arc<VarFile>>,
    /// Values of `#<_ini[section]name>` (see [`IniValues`]).
    pub ini: Arc<IniValues>,
    /// Embedded Python (see [`python`]): `None` (the default, and always in the daemon) runs
    /// none, and `;py,`/`(py,…)` comments are ordinary comments, so that a G-code program
    /// cannot run code on the host. `Some` (an ini's `[PYTHON]` section given on purpose, or
    /// [`python::PythonConfig::bare`]) runs them, and the TOPLEVEL's O-word procedures.
    pub python: Option<python::PythonConfig>,
    /// The tool table slot the interpreter takes as its current pocket at start (LinuxCNC's
    /// `GET_EXTERNAL_TOOL_SLOT`) while the spindle is still empty: 0 on a machine. rs274's
    /// standalone canon says 1 ([`RS274_START_POCKET`]), so a `G10 L1`/`L10`/`L11` that
    /// edits the table's first tool before any M6 also loads it into the spindle (prints
    /// `SET_TOOL_TABLE_ENTRY(0, …)`) and `#<_current_pocket>` starts at 1; the differential
    /// runs (`hytask gcode canon` without a machine) set it to compare traces byte for byte.
    pub start_pocket: usize,
    /// Resource limits.
    pub limits: Limits,
    /// Set from another thread to stop the run (job preparation cancelled or out of time):
    /// polled every [`CANCEL_POLL_BLOCKS`] blocks, then the run ends with an error.
    pub cancel: Option<Arc<std::sync::atomic::AtomicBool>>,
}

/// [`InterpOptions::start_pocket`] of rs274's standalone canon (its simulated tool changer
/// starts at slot 1).
pub const RS274_START_POCKET: usize = 1;

/// Blocks executed between two polls of [`InterpOptions::cancel`].
pub const CANCEL_POLL_BLOCKS: u64 = 4096;

impl Default for InterpOptions {
    fn default() -> Self {
        InterpOptions {
            tool_table: None,
            subroutine_path: Vec::new(),
            program_dir: None,
            block_delete: false,
            machine_units: LengthUnits::Millimeters,
            initial_units: LengthUnits::Millimeters,
            initial_position: None,
            mdi: false,
            user_mcodes: Vec::new(),
            parameters: None,
            ini: Arc::default(),
            python: None,
            start_pocket: 0,
            limits: Limits::default(),
            cancel: None,
        }
    }
}

/// A whole interpreted program: validated as a unit before any motion starts.
#[derive(Debug, Clone, Default)]
pub struct Program {
    /// The canonical commands, in execution order. The start-up calls (units, offsets,
    /// `ON_RESET`) carry line 0.
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

/// Interprets a program file. Subroutine files are also searched in the program's directory.
pub fn load_file(path: &Path, opts: &InterpOptions) -> Result<Program, GcodeError> {
    let (name, text, o) = read_program(path, opts)?;
    let canon = interp::interpret(&name, text, &o)?;
    Ok(Program { canon })
}

/// [`load_file`], also returning the persistent parameters as the program leaves them: the
/// var file to save after the job (the numbers [`VarFile::saved_numbers`] of the loaded one).
pub fn load_file_persistent(
    path: &Path,
    opts: &InterpOptions,
) -> Result<(Program, VarFile), GcodeError> {
    let (name, text, o) = read_program(path, opts)?;
    let (canon, vars) = interp::interpret_persistent(&name, text, &o)?;
    Ok((Program { canon }, vars))
}

/// Interprets a program file and returns its canonical trace in `rs274 -g` layout (see
/// [`canon_fmt`]), formatting each command as it is produced instead of collecting a
/// [`Program`]: the fast path of `hytask gcode canon`. Like [`load_file`], a program with
/// an error yields only the error.
pub fn trace_file(path: &Path, opts: &InterpOptions) -> Result<Vec<u8>, GcodeError> {
    let (name, text, o) = read_program(path, opts)?;
    interp::interpret_trace(&name, text, &o, None)
}

/// [`trace_file`] that writes the trace to `spill` as it goes (in large chunks) and returns
/// only the last, unwritten part; on an error the spill discards what it wrote (see
/// [`trace_spill::Spill`]), so a program with an error still yields only the error.
pub fn trace_file_spilled(
    path: &Path,
    opts: &InterpOptions,
    spill: &mut trace_spill::Spill,
) -> Result<Vec<u8>, GcodeError> {
    let (name, text, o) = read_program(path, opts)?;
    let out = interp::interpret_trace(&name, text, &o, Some(spill));
    if out.is_err() {
        spill.discard();
    }
    out
}

fn read_program(
    path: &Path,
    opts: &InterpOptions,
) -> Result<(String, String, InterpOptions), GcodeError> {
    let text = std::fs::read(path).map_err(|e| GcodeError {
        file: path.display().to_string(),
        line: 1,
        col: 1,
        message: format!("Unable to open file: {e}"),
    })?;
    let text = match String::from_utf8(text) {
        Ok(t) => t,
        Err(e) => String::from_utf8_lossy(e.as_bytes()).into_owned(),
    };
    let mut o = opts.clone();
    if o.program_dir.is_none() {
        o.program_dir = path.parent().map(Path::to_path_buf);
    }
    Ok((path.display().to_string(), text, o))
}

/// [`load_str`], also returning the persistent parameters the program leaves (see
/// [`load_file_persistent`]).
pub fn load_str_persistent(
    name: &str,
    text: &str,
    opts: &InterpOptions,
) -> Result<(Program, VarFile), GcodeError> {
    let (canon, vars) = interp::interpret_persistent(name, text.to_string(), opts)?;
    Ok((Program { canon }, vars))
}

/// Interprets program text; `name` is used as the file name in locations and errors.
pub fn load_str(name: &str, text: &str, opts: &InterpOptions) -> Result<Program, GcodeError> {
    let canon = interp::interpret(name, text.to_string(), opts)?;
    Ok(Program { canon })
}
