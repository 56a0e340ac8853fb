//! Parameter storage: numbered `#1`–`#5601`, global named `#<_x>` and per-call local named
//! `#<x>`, with LinuxCNC's system parameter addresses.
//!
//! The numbered table is the interpreter's persistent memory (work offsets live in it, as
//! in LinuxCNC), so its layout constants are named here once.

use std::collections::HashMap;

/// Size of the numbered table (`#0`–`#5601`).
pub const NUM_PARAMS: usize = 5602;
/// G28 home position, X (then Y Z A B C U V W).
pub const G28_BASE: usize = 5161;
/// G30 home position, X.
pub const G30_BASE: usize = 5181;
/// G92 enabled flag.
pub const G92_ENABLED: usize = 5210;
/// G92 offset, X.
pub const G92_BASE: usize = 5211;
/// Active coordinate system, 1..=9.
pub const COORD_INDEX: usize = 5220;
/// G54 X; G55 is 20 further, … G59.3 is `5221 + 8 * 20`. The tenth entry is the rotation.
pub const G54_BASE: usize = 5221;
/// M66 result.
pub const M66_RESULT: usize = 5399;
/// Tool in spindle.
pub const TOOL_NUMBER: usize = 5400;
/// Tool offsets X … W (5401–5409), 5410 diameter.
pub const TOOL_BASE: usize = 5401;
/// Current position X … W in the active coordinate system.
pub const POS_BASE: usize = 5420;
/// `(DEBUG,…)` prints only while this is above 0; rs274 sets it to 1 at start.
pub const DEBUG_FLAG: usize = 5599;

/// Base parameter of work offset `index` (1 = G54 … 9 = G59.3).
pub fn g5x_base(index: u8) -> usize {
    G54_BASE + 20 * (usize::from(index).saturating_sub(1))
}

/// All parameter storage.
#[derive(Debug, Clone)]
pub struct Params {
    /// `#0`…`#5601`.
    pub numbered: Vec<f64>,
    /// `#<_name>` globals (user-created).
    pub globals: HashMap<Box<str>, f64>,
    /// `#<name>` locals, one map per call level (index 0 = main program).
    pub locals: Vec<HashMap<Box<str>, f64>>,
}

impl Default for Params {
    fn default() -> Self {
        let mut numbered = vec![0.0; NUM_PARAMS];
        numbered[COORD_INDEX] = 1.0;
        numbered[DEBUG_FLAG] = 1.0;
        Params {
            numbered,
            globals: HashMap::new(),
            locals: vec![HashMap::new()],
        }
    }
}

impl Params {
    /// Index check with LinuxCNC's error.
    pub fn index(v: f64) -> Result<usize, String> {
        let r = v.round();
        if (v - r).abs() > 0.0001 {
            return Err(format!("Non-integer value for parameter number: {v}"));
        }
        if r < 0.0 || r >= NUM_PARAMS as f64 {
            return Err(format!("Parameter number out of range: {r}"));
        }
        Ok(r as usize)
    }

    /// Reads a user named parameter (global if it starts with `_`, else local of the
    /// current call level).
    pub fn named(&self, name: &str) -> Option<f64> {
        if name.starts_with('_') {
            self.globals.get(name).copied()
        } else {
            self.locals.last().and_then(|m| m.get(name).copied())
        }
    }

    /// Writes a named parameter.
    pub fn set_named(&mut self, name: &str, v: f64) {
        if name.starts_with('_') {
            self.globals.insert(name.into(), v);
        } else if let Some(m) = self.locals.last_mut() {
            m.insert(name.into(), v);
        }
    }
}
