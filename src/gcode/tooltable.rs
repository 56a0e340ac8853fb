//! LinuxCNC tool table files (`.tbl`): one tool per line, `T<n> P<pocket> [X Y Z A B C U V W
//! D I J Q]<value>` words and a `;` comment.
//!
//! The interpreter needs the table for M6/M61 (which index the changer uses) and G43 (the
//! offsets). As in LinuxCNC with a non-random changer, the pocket reported to canon is the
//! line's position in the table (1-based), not the P word.

use super::canon::Pose;
use std::path::Path;

/// One tool.
#[derive(Debug, Clone, PartialEq)]
pub struct Tool {
    /// T number.
    pub number: u32,
    /// P word (physical pocket).
    pub pocket: u32,
    /// Offsets X Y Z A B C U V W, in machine units.
    pub offset: Pose,
    /// D word.
    pub diameter: f64,
    /// I word.
    pub front_angle: f64,
    /// J word.
    pub back_angle: f64,
    /// Q word.
    pub orientation: i32,
    /// Comment after `;`.
    pub comment: String,
}

/// A whole table, in file order.
#[derive(Debug, Clone, Default)]
pub struct ToolTable {
    /// Tools; index + 1 is the changer slot.
    pub tools: Vec<Tool>,
}

impl ToolTable {
    /// Reads a table file; errors name the line.
    pub fn load(path: &Path) -> Result<ToolTable, (u32, String)> {
        let text = std::fs::read_to_string(path).map_err(|e| {
            (
                0,
                format!("Unable to open tool table file {}: {e}", path.display()),
            )
        })?;
        Self::parse(&text)
    }

    /// Parses table text.
    pub fn parse(text: &str) -> Result<ToolTable, (u32, String)> {
        let mut tools = Vec::new();
        for (i, raw) in text.lines().enumerate() {
            let ln = u32::try_from(i + 1).unwrap_or(u32::MAX);
            let (body, comment) = match raw.split_once(';') {
                Some((b, c)) => (b, c.trim().to_string()),
                None => (raw, String::new()),
            };
            if body.trim().is_empty() {
                continue;
            }
            let mut t = Tool {
                number: 0,
                pocket: 0,
                offset: [0.0; 9],
                diameter: 0.0,
                front_angle: 0.0,
                back_angle: 0.0,
                orientation: 0,
                comment,
            };
            let mut have_t = false;
            for w in body.split_whitespace() {
                let mut ch = w.chars();
                let letter = ch.next().map(|c| c.to_ascii_uppercase()).unwrap_or(' ');
                let v: f64 = ch
                    .as_str()
                    .parse()
                    .map_err(|_| (ln, format!("Bad value in tool table word '{w}'")))?;
                let axis = "XYZABCUVW".find(letter);
                match (letter, axis) {
                    (_, Some(a)) => t.offset[a] = v,
                    ('T', _) => {
                        t.number = v as u32;
                        have_t = true;
                    }
                    ('P', _) => t.pocket = v as u32,
                    ('D', _) => t.diameter = v,
                    ('I', _) => t.front_angle = v,
                    ('J', _) => t.back_angle = v,
                    ('Q', _) => t.orientation = v as i32,
                    _ => return Err((ln, format!("Unknown word '{w}' in tool table"))),
                }
            }
            if !have_t {
                return Err((ln, "Tool table line without T word".into()));
            }
            tools.push(t);
        }
        Ok(ToolTable { tools })
    }

    /// Slot (1-based index) of tool `n`.
    pub fn slot_of(&self, n: u32) -> Option<usize> {
        self.tools.iter().position(|t| t.number == n).map(|i| i + 1)
    }

    /// Tool at slot `s` (1-based).
    pub fn at_slot(&self, s: usize) -> Option<&Tool> {
        s.checked_sub(1).and_then(|i| self.tools.get(i))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_linuxcnc_lines() {
        let t = ToolTable::parse("T1 P1 Z1.5 D0.25 ;first\n\nT3 P5 Z2 D0.5\n").unwrap_or_default();
        assert_eq!(t.tools.len(), 2);
        assert_eq!(t.tools[0].offset[2], 1.5);
        assert_eq!(t.tools[0].comment, "first");
        assert_eq!(t.slot_of(3), Some(2));
        assert!(ToolTable::parse("T1 K3").is_err());
    }
}
