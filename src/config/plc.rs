//! `[plc]`: the PLC task (issue 11): its Structured Text program, the thread it scans on,
//! and the bindings of its variables to the machine's signals by name.
//!
//! Bindings map an ST variable (a `VAR_GLOBAL`, or a program's `VAR_INPUT`/`VAR_OUTPUT`
//! written `Main.x`, or just `x` when one program declares it) to a signal name:
//! - an I/O point of the machine's `[[io]]` devices (`estop`, `spindle_on`, ...);
//! - machine state, read only: `machine.estop`, `machine.on`, `machine.mode` (DINT),
//!   `machine.homed`, `machine.in_position`, `machine.fault`, `machine.estop_reset` (true
//!   for one scan after `estop.reset`), `job.running`, `job.feed_hold`, `axis.X.homed`;
//! - the machine's output image (what G-code asked for: M3–M5, M7–M9, M62–M68):
//!   `request.<output name>`;
//! - G-code requests: `m6.request`, `m6.tool` (inputs), `m6.done` (output); `mcode.request`,
//!   `mcode.number`, `mcode.p`, `mcode.q` (inputs), `mcode.done` (output) for M100–M199;
//! - PLC commands to the machine (outputs): `machine.feed_hold` (hold feed while true),
//!   `machine.start_inhibit` (refuse cycle start while true), `machine.estop` (e-stop when
//!   it rises).
//!
//! The names are checked against the program and the machine when the machine is deployed
//! (`plc::machine::bind`); this module checks what needs no program.

use super::error::Issues;
use crate::plc::{M66_ANALOG_MAX, M66_DIGITAL_MAX};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::PathBuf;

/// `[plc]`. Equality compares what the file says, not where it was read from.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct PlcConfig {
    /// The program file (relative to the configuration file's directory), or
    /// `builtin:plc/mill.st` for the program compiled into the binary (the built-in mill's,
    /// so that config/sim.toml works wherever it is copied).
    pub program: PathBuf,
    /// The `[[thread]]` the PLC scans on, one scan per period.
    #[serde(default = "default_thread")]
    pub thread: String,
    /// A PLC fault stops the machine (controlled stop, mode `fault`).
    #[serde(default)]
    pub safety_relevant: bool,
    /// Where RETAIN variables are kept between runs (absent: not kept).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub retain_file: Option<PathBuf>,
    /// Seconds an M6 waits for `m6.done` before the job is aborted with its line.
    #[serde(default = "default_timeout")]
    pub tool_change_timeout_s: f64,
    /// Seconds an M100–M199 waits for `mcode.done` before the job is aborted.
    #[serde(default = "default_timeout")]
    pub mcode_timeout_s: f64,
    /// The user M codes (100..=199) the PLC handles: G-code accepts them, and each waits for
    /// `mcode.done` (bind it) or `mcode_timeout_s`.
    #[serde(default)]
    pub mcodes: Vec<u16>,
    /// Instructions one scan may execute (runaway loops fault instead of overrunning).
    #[serde(default = "default_budget")]
    pub instruction_budget: u64,
    /// PLC variables M66 P0, P1, ... wait on (BOOL outputs or globals of the program), as
    /// LinuxCNC's `motion.digital-in-NN`: `M66 P0 L3 Q5` waits up to 5 s for the first one
    /// to be TRUE. A number listed here shadows the physical input of the same number.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub m66_digital: Vec<String>,
    /// PLC variables M66 E0, E1, ... sample (REAL/LREAL outputs or globals).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub m66_analog: Vec<String>,
    /// Variable ← signal, copied into the program before each scan.
    #[serde(default)]
    pub inputs: BTreeMap<String, String>,
    /// Variable → signal, taken from the program after each scan.
    #[serde(default)]
    pub outputs: BTreeMap<String, String>,
    /// The directory of the configuration file: relative paths are relative to it.
    #[serde(skip)]
    pub base_dir: Option<PathBuf>,
}

impl PartialEq for PlcConfig {
    fn eq(&self, o: &Self) -> bool {
        (
            &self.program,
            &self.thread,
            self.safety_relevant,
            &self.retain_file,
            self.tool_change_timeout_s,
            self.mcode_timeout_s,
            &self.mcodes,
            self.instruction_budget,
            &self.inputs,
            &self.outputs,
            &self.m66_digital,
            &self.m66_analog,
        ) == (
            &o.program,
            &o.thread,
            o.safety_relevant,
            &o.retain_file,
            o.tool_change_timeout_s,
            o.mcode_timeout_s,
            &o.mcodes,
            o.instruction_budget,
            &o.inputs,
            &o.outputs,
            &o.m66_digital,
            &o.m66_analog,
        )
    }
}

fn default_thread() -> String {
    "plc".into()
}
fn default_timeout() -> f64 {
    30.0
}
fn default_budget() -> u64 {
    1_000_000
}

impl PlcConfig {
    /// `path` made relative to the configuration file's directory.
    pub fn resolve_path(&self, path: &std::path::Path) -> PathBuf {
        match &self.base_dir {
            Some(dir) if path.is_relative() => dir.join(path),
            _ => path.to_path_buf(),
        }
    }

    /// Checks the values that need no program (thread and signal names are checked by the
    /// caller and at deployment).
    pub(super) fn validate(&self, issues: &mut Issues) {
        issues.positive("plc.tool_change_timeout_s", self.tool_change_timeout_s);
        issues.positive("plc.mcode_timeout_s", self.mcode_timeout_s);
        for m in &self.mcodes {
            if !(100..=199).contains(m) {
                issues.push(
                    "plc.mcodes",
                    format!("M{m} is not a user M code (100..=199)"),
                );
            }
        }
        if self.m66_digital.len() > M66_DIGITAL_MAX {
            issues.push(
                "plc.m66_digital",
                format!("at most {M66_DIGITAL_MAX} variables"),
            );
        }
        if self.m66_analog.len() > M66_ANALOG_MAX {
            issues.push(
                "plc.m66_analog",
                format!("at most {M66_ANALOG_MAX} variables"),
            );
        }
        if self.instruction_budget == 0 {
            issues.push("plc.instruction_budget", "must be at least 1");
        }
        for (var, sig) in &self.outputs {
            if let Some((other, _)) = self.outputs.iter().find(|(v, s)| *s == sig && *v < var) {
                issues.push(
                    format!("plc.outputs.{var}"),
                    format!("signal {sig:?} is already written by plc.outputs.{other}"),
                );
            }
        }
    }
}
