//! Modal groups: which G and M codes exclude each other on one line, as LinuxCNC defines
//! them, and the [`Block`] a line becomes once its values are known.
//!
//! G and M numbers are kept as integers in tenths (`G38.2` = 382, `G1` = 10) so group
//! lookups are exact.

/// Number of G groups tracked (LinuxCNC numbering, 0..=15).
pub const G_GROUPS: usize = 16;
/// Number of M groups tracked (LinuxCNC numbering 4..=10, plus 11 for M70–M73).
pub const M_GROUPS: usize = 12;

/// G modal group of `g` (tenths), or None if LinuxCNC has no such G code.
pub fn g_group(g: u16) -> Option<usize> {
    Some(match g {
        40 | 100 | 280 | 281 | 300 | 301 | 520 | 530 | 920 | 921 | 922 | 923 => 0,
        0
        | 10
        | 20
        | 30
        | 50
        | 51
        | 52
        | 53
        | 330
        | 331
        | 382..=385
        | 700
        | 710
        | 711
        | 712
        | 720
        | 721
        | 722
        | 730
        | 760
        | 800..=890 => 1,
        170 | 171 | 180 | 181 | 190 | 191 => 2,
        900 | 910 => 3,
        901 | 911 => 4,
        930 | 940 | 950 => 5,
        200 | 210 => 6,
        400 | 410 | 411 | 420 | 421 => 7,
        430 | 431 | 432 | 490 => 8,
        980 | 990 => 10,
        540 | 550 | 560 | 570 | 580 | 590 | 591 | 592 | 593 => 12,
        610 | 611 | 640 => 13,
        960 | 970 => 14,
        70 | 80 => 15,
        _ => return None,
    })
}

/// M modal group of `m`, or None if LinuxCNC has no such M code.
pub fn m_group(m: u16) -> Option<usize> {
    Some(match m {
        // M99 outside a Fanuc-style subprogram ends the program, as M2 (rs274).
        0 | 1 | 2 | 30 | 60 | 99 => 4,
        62..=68 => 5,
        6 | 61 => 6,
        3..=5 | 19 => 7,
        7..=9 => 8,
        48..=53 => 9,
        100..=199 => 10,
        70..=73 => 11,
        _ => return None,
    })
}

/// A line with all values evaluated and all codes sorted into their groups.
#[derive(Debug, Clone)]
pub struct Block {
    /// G code per group (tenths) and its column.
    pub g: [Option<(u16, u32)>; G_GROUPS],
    /// M code per group and its column.
    pub m: [Option<(u16, u32)>; M_GROUPS],
    /// Value of each non-G/M letter (index: [`li`]), then the polar words `@` and `^`.
    pub val: [Option<f64>; WORD_SLOTS],
    /// Column of each letter.
    pub col: [u32; WORD_SLOTS],
    /// Number of M words on the line.
    pub m_count: usize,
}

impl Default for Block {
    fn default() -> Self {
        Block {
            g: [None; G_GROUPS],
            m: [None; M_GROUPS],
            val: [None; WORD_SLOTS],
            col: [1; WORD_SLOTS],
            m_count: 0,
        }
    }
}

/// The polar distance word (`@`, LinuxCNC's polar coordinates in G17).
pub const POLAR_R: u8 = b'@';
/// The polar angle word (`^`, degrees counter-clockwise from +X).
pub const POLAR_A: u8 = b'^';
/// Letters a–z, then `@` and `^`.
pub const WORD_SLOTS: usize = 28;

/// Letter index for `Block::val`: a–z, then the polar words.
pub const fn li(c: u8) -> usize {
    match c {
        POLAR_R => 26,
        POLAR_A => 27,
        _ => (c - b'a') as usize,
    }
}

impl Block {
    /// Value of letter `c`, if present.
    pub fn get(&self, c: u8) -> Option<f64> {
        self.val[li(c)]
    }

    /// True if letter `c` is present.
    pub fn has(&self, c: u8) -> bool {
        self.val[li(c)].is_some()
    }

    /// Column of letter `c` (1 if absent).
    pub fn col_of(&self, c: u8) -> u32 {
        self.col[li(c)]
    }

    /// The G code of group `grp`, if any.
    pub fn gcode(&self, grp: usize) -> Option<u16> {
        self.g[grp].map(|x| x.0)
    }

    /// The M code of group `grp`, if any.
    pub fn mcode(&self, grp: usize) -> Option<u16> {
        self.m[grp].map(|x| x.0)
    }

    /// True if any of X Y Z A B C is present.
    pub fn has_axis(&self) -> bool {
        b"xyzabc".iter().any(|&c| self.has(c)) || self.has_polar()
    }

    /// True if the block gives a polar coordinate (`@` distance or `^` angle).
    pub fn has_polar(&self) -> bool {
        self.has(POLAR_R) || self.has(POLAR_A)
    }

    /// Adds one evaluated word, enforcing LinuxCNC's one-per-group and one-per-letter rules.
    pub fn add(&mut self, letter: u8, v: f64, col: u32) -> Result<(), (u32, String)> {
        match letter {
            b'g' => {
                let t = (v * 10.0).round();
                if (v * 10.0 - t).abs() > 0.0001 || !(0.0..10000.0).contains(&t) {
                    return Err((col, format!("Unknown g code used: G{}", fmt_code(v))));
                }
                let code = t as u16;
                let grp = g_group(code)
                    .ok_or_else(|| (col, format!("Unknown g code used: G{}", fmt_code(v))))?;
                if let Some((prev, _)) = self.g[grp] {
                    // G80 beside another motion code (`G00 X1 G80`, as some CAM posts write
                    // it) is dropped and the other code kept, as LinuxCNC does.
                    if grp == 1 && code == 800 {
                        return Ok(());
                    }
                    if !(grp == 1 && prev == 800) {
                        return Err((col, "Two g codes used from same modal group".into()));
                    }
                }
                self.g[grp] = Some((code, col));
            }
            b'm' => {
                if v.fract() != 0.0 || !(0.0..10000.0).contains(&v) {
                    return Err((col, format!("Unknown m code used: M{}", fmt_code(v))));
                }
                let code = v as u16;
                let grp =
                    m_group(code).ok_or_else(|| (col, format!("Unknown m code used: M{code}")))?;
                if self.m[grp].is_some() {
                    return Err((col, "Two m codes used from same modal group".into()));
                }
                self.m_count += 1;
                if self.m_count > 5 {
                    return Err((col, "Too many m codes on line".into()));
                }
                self.m[grp] = Some((code, col));
            }
            _ => {
                let i = li(letter);
                if self.val[i].is_some() {
                    return Err((
                        col,
                        format!(
                            "Multiple {} words on one line",
                            (letter as char).to_ascii_uppercase()
                        ),
                    ));
                }
                self.val[i] = Some(v);
                self.col[i] = col;
            }
        }
        Ok(())
    }
}

fn fmt_code(v: f64) -> String {
    let s = format!("{v:.4}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    s.to_string()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn groups_reject_two_codes() {
        let mut b = Block::default();
        assert!(b.add(b'g', 17.0, 1).is_ok());
        assert!(b.add(b'g', 18.0, 5).is_err());
        assert!(b.add(b'g', 38.2, 9).is_ok());
        assert!(b.add(b'g', 1.5, 9).is_err());
        assert!(b.add(b'm', 7.0, 1).is_ok());
        assert!(b.add(b'm', 8.0, 1).is_err());
        assert!(b.add(b'x', 1.0, 1).is_ok());
        assert!(b.add(b'x', 1.0, 1).is_err());
    }

    #[test]
    fn g80_beside_a_motion_code_is_dropped() {
        let mut b = Block::default();
        assert!(b.add(b'g', 0.0, 1).is_ok());
        assert!(b.add(b'g', 80.0, 5).is_ok());
        assert_eq!(b.gcode(1), Some(0));
        let mut b = Block::default();
        assert!(b.add(b'g', 80.0, 1).is_ok());
        assert!(b.add(b'g', 1.0, 5).is_ok());
        assert_eq!(b.gcode(1), Some(10));
        assert!(b.add(b'g', 0.0, 9).is_err());
    }
}
