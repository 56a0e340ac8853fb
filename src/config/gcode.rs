//! `[gcode]`: what the G-code interpreter takes from the machine configuration besides the
//! tool table: the var file (LinuxCNC's `PARAMETER_FILE`), the subroutine search path
//! (`SUBROUTINE_PATH`), the directory of the log comments' files and the values of
//! `#<_ini[section]name>`.
//!
//! LinuxCNC programs read their machine's ini file through `#<_ini[section]name>`. hytask
//! has a TOML configuration instead, so the names are mapped ([`GcodeConfig::ini_values`]):
//!
//! | `#<_ini[…]…>`                       | hytask configuration                   |
//! |-------------------------------------|----------------------------------------|
//! | `[axis_x]max_velocity` (Y Z A B C)  | `[[axis]] name = "X"` `max_velocity`   |
//! | `[axis_x]max_acceleration`          | the axis' `max_acceleration`           |
//! | `[axis_x]min_limit`, `max_limit`    | the axis' `min_limit`, `max_limit`     |
//! | `[joint_0]…` (0 = X, 1 = Y, …)      | the same four values of the axis       |
//! | `[<section>]<name>`                 | `[gcode.ini.<section>] <name> = value` |
//!
//! Values come in the configuration's units (mm, mm/s, mm/s², degrees), as LinuxCNC's
//! are in its machine units. Names are case-insensitive (LinuxCNC upper-cases them), and an
//! entry of `[gcode.ini]` replaces a mapped one of the same name. A name that is neither is
//! an error naming it ("Named parameter #<_ini[axis_x]nope> not defined"), as in LinuxCNC.

use super::axis::AxisConfig;
use super::error::Issues;
use crate::gcode::IniValues;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::PathBuf;

/// `[gcode]`.
#[derive(Debug, Clone, Default, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct GcodeConfig {
    /// The var file (LinuxCNC format: `number<TAB>value` lines) holding the persistent
    /// parameters: work offsets, active coordinate system, G92, G28/G30 positions. Loaded
    /// when the daemon starts, saved (atomically) when a job has run to its end and when
    /// the daemon stops. A relative path is relative to the configuration file's directory.
    /// Absent: offsets start at zero in G54 and are not kept.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub var_file: Option<PathBuf>,
    /// Directories searched for `o<name> call` subroutine files (`name.ngc`), in order, before
    /// the program's own directory (LinuxCNC's `[RS274NGC] SUBROUTINE_PATH`); the only place
    /// an MDI line finds subroutines. Relative paths are relative to the configuration file's
    /// directory.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub subroutine_path: Vec<PathBuf>,
    /// Where LinuxCNC's log comments write: `(LOGOPEN,name)` and `(LOGAPPEND,name)` open
    /// `name` under this directory (a relative name, without `..`). Absent: log comments
    /// write nothing and the operator is told. A relative path is relative to the
    /// configuration file's directory.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub log_dir: Option<PathBuf>,
    /// Free values for programs: `[gcode.ini.<section>] <name> = <number>`, read as
    /// `#<_ini[<section>]<name>>`.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub ini: BTreeMap<String, BTreeMap<String, f64>>,
}

impl GcodeConfig {
    /// True when nothing is set (the section is then left out of the resolved output).
    pub fn is_default(&self) -> bool {
        *self == GcodeConfig::default()
    }

    /// Checks the values.
    pub fn validate(&self, issues: &mut Issues) {
        for (section, values) in &self.ini {
            for (name, v) in values {
                if !v.is_finite() {
                    issues.push(
                        format!("gcode.ini.{section}.{name}"),
                        "must be a finite number",
                    );
                }
                if section.contains(']') || name.contains('>') {
                    issues.push(
                        format!("gcode.ini.{section}.{name}"),
                        "cannot be named in #<_ini[section]name> (contains ']' or '>')",
                    );
                }
            }
        }
        if self
            .var_file
            .as_ref()
            .is_some_and(|p| p.as_os_str().is_empty())
        {
            issues.push("gcode.var_file", "must not be empty");
        }
        if self
            .log_dir
            .as_ref()
            .is_some_and(|p| p.as_os_str().is_empty())
        {
            issues.push("gcode.log_dir", "must not be empty");
        }
        for (i, p) in self.subroutine_path.iter().enumerate() {
            if p.as_os_str().is_empty() {
                issues.push(format!("gcode.subroutine_path[{i}]"), "must not be empty");
            }
        }
    }

    /// The `#<_ini[…]…>` values of this machine (see the module doc for the mapping).
    pub fn ini_values(&self, axes: &[AxisConfig]) -> IniValues {
        let mut v = IniValues::default();
        for a in axes {
            let letter = format!("{:?}", a.name).to_ascii_lowercase();
            let joint = format!("joint_{}", a.name as usize);
            for section in [format!("axis_{letter}"), joint] {
                v.insert(&section, "max_velocity", a.max_velocity);
                v.insert(&section, "max_acceleration", a.max_acceleration);
                v.insert(&section, "min_limit", a.min_limit);
                v.insert(&section, "max_limit", a.max_limit);
            }
        }
        for (section, values) in &self.ini {
            for (name, x) in values {
                v.insert(section, name, *x);
            }
        }
        v
    }
}
