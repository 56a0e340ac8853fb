//! Values for `#<_ini[section]name>`: LinuxCNC reads them from the machine's ini file;
//! hytask has no ini file, so the machine configuration supplies them (see
//! `config::gcode` for the mapping from the TOML configuration).
//!
//! Lookup ignores case: LinuxCNC upper-cases section and name before it searches its ini
//! file (whose sections are conventionally upper case), and the reader lower-cases every
//! named parameter, so `#<_ini[AXIS_X]MAX_VELOCITY>` and `#<_ini[axis_x]max_velocity>` are
//! the same value.

use std::collections::HashMap;

/// Numeric values by (section, name), lower-cased.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct IniValues {
    map: HashMap<(Box<str>, Box<str>), f64>,
}

impl IniValues {
    /// Sets `[section] name = value` (replacing an earlier value).
    pub fn insert(&mut self, section: &str, name: &str, value: f64) {
        self.map.insert(
            (
                section.to_ascii_lowercase().into(),
                name.to_ascii_lowercase().into(),
            ),
            value,
        );
    }

    /// `[section] name`, any case.
    pub fn get(&self, section: &str, name: &str) -> Option<f64> {
        self.map
            .get(&(
                section.to_ascii_lowercase().into(),
                name.to_ascii_lowercase().into(),
            ))
            .copied()
    }

    /// The value of the named parameter `name` if it is an `_ini[section]key` reference:
    /// `Some(None)` for one the configuration does not define.
    pub fn lookup(&self, name: &str) -> Option<Option<f64>> {
        let rest = name.strip_prefix("_ini[")?;
        let (section, key) = rest.split_once(']')?;
        Some(self.get(section, key))
    }

    /// The numeric values of a LinuxCNC ini file's text, as `#<_ini[section]name>` reads
    /// them: every `NAME = value` under its `[SECTION]` whose value is a number (a value
    /// that is not, a path or a list, cannot be read as a parameter and is left out).
    /// Lines starting with `#` or `;` are comments.
    pub fn parse(text: &str) -> IniValues {
        let mut v = IniValues::default();
        let mut section = String::new();
        for line in text.lines().map(str::trim) {
            if line.starts_with(['#', ';']) {
                continue;
            }
            if let Some(name) = line.strip_prefix('[').and_then(|l| l.strip_suffix(']')) {
                section = name.trim().to_string();
            } else if let Some((name, value)) = line.split_once('=') {
                if let Ok(x) = value.trim().parse::<f64>() {
                    v.insert(&section, name.trim(), x);
                }
            }
        }
        v
    }

    /// Number of values.
    pub fn len(&self) -> usize {
        self.map.len()
    }

    /// No values.
    pub fn is_empty(&self) -> bool {
        self.map.is_empty()
    }
}

/// The `SUBROUTINE_PATH` of an ini file's `[RS274NGC]` section: its directories, as
/// written (colon separated; relative ones are relative to where the program runs).
pub fn subroutine_path(text: &str) -> Vec<String> {
    let mut in_rs274ngc = false;
    for line in text.lines().map(str::trim) {
        if let Some(name) = line.strip_prefix('[').and_then(|l| l.strip_suffix(']')) {
            in_rs274ngc = name.trim().eq_ignore_ascii_case("RS274NGC");
        } else if let Some((name, value)) = line.split_once('=') {
            if in_rs274ngc && name.trim().eq_ignore_ascii_case("SUBROUTINE_PATH") {
                return value
                    .trim()
                    .split(':')
                    .filter(|p| !p.is_empty())
                    .map(str::to_string)
                    .collect();
            }
        }
    }
    Vec::new()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_numbers_by_section_and_the_subroutine_path() {
        let text = "# machine\n[VARS]\nTOOLCHANGE_X = 10\nNAME = mill\n; note\n\
                    [RS274NGC]\nSUBROUTINE_PATH = subs:../lib\nFEATURES = 4\n";
        let v = IniValues::parse(text);
        assert_eq!(v.lookup("_ini[vars]toolchange_x"), Some(Some(10.0)));
        assert_eq!(v.lookup("_ini[vars]name"), Some(None));
        assert_eq!(v.get("rs274ngc", "features"), Some(4.0));
        assert_eq!(v.len(), 2);
        assert_eq!(subroutine_path(text), vec!["subs", "../lib"]);
        assert!(subroutine_path("[EMC]\nSUBROUTINE_PATH = x\n").is_empty());
    }

    #[test]
    fn lookup_ignores_case_and_tells_unknown_from_not_ini() {
        let mut v = IniValues::default();
        v.insert("AXIS_X", "MAX_VELOCITY", 12.5);
        assert_eq!(v.lookup("_ini[axis_x]max_velocity"), Some(Some(12.5)));
        assert_eq!(v.lookup("_ini[Axis_X]Max_Velocity"), Some(Some(12.5)));
        assert_eq!(v.lookup("_ini[axis_x]nope"), Some(None));
        assert_eq!(v.lookup("_inix"), None);
    }
}
