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

    /// Number of values.
    pub fn len(&self) -> usize {
        self.map.len()
    }

    /// No values.
    pub fn is_empty(&self) -> bool {
        self.map.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
