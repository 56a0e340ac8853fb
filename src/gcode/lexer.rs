//! Character level of RS274/NGC: a cursor over one line that skips blanks and folds case.
//!
//! LinuxCNC removes spaces and tabs everywhere outside comments and reads letters
//! case-insensitively, so `g 0 1 x 1 . 5` is `G01 X1.5`. Doing that on the fly (rather
//! than building a normalised copy of the line) keeps lexing allocation-free and lets every
//! token keep the column it had in the file, which errors report.

/// A position in one source line. Columns are 1-based byte offsets into the original text.
#[derive(Debug, Clone)]
pub struct Cursor<'a> {
    bytes: &'a [u8],
    pos: usize,
}

impl<'a> Cursor<'a> {
    /// A cursor at the start of `line` (which excludes the line terminator).
    pub fn new(line: &'a str) -> Self {
        Cursor {
            bytes: line.as_bytes(),
            pos: 0,
        }
    }

    fn skip_blanks(&mut self) {
        while let Some(&b) = self.bytes.get(self.pos) {
            if b == b' ' || b == b'\t' || b == b'\r' {
                self.pos += 1;
            } else {
                break;
            }
        }
    }

    /// The next significant character, lower-cased, without consuming it.
    pub fn peek(&mut self) -> Option<u8> {
        self.skip_blanks();
        self.bytes.get(self.pos).map(|b| b.to_ascii_lowercase())
    }

    /// Consumes and returns the next significant character, lower-cased.
    pub fn next_char(&mut self) -> Option<u8> {
        let c = self.peek()?;
        self.pos += 1;
        Some(c)
    }

    /// Consumes `c` if it is next; true if it was.
    pub fn eat(&mut self, c: u8) -> bool {
        if self.peek() == Some(c) {
            self.pos += 1;
            true
        } else {
            false
        }
    }

    /// 1-based column of the next significant character (or one past the end).
    pub fn col(&mut self) -> u32 {
        self.skip_blanks();
        u32::try_from(self.pos + 1).unwrap_or(u32::MAX)
    }

    /// 1-based column of the current position, without skipping blanks (after a `peek`).
    pub fn col_here(&self) -> u32 {
        u32::try_from(self.pos + 1).unwrap_or(u32::MAX)
    }

    /// Consumes one byte unconditionally (after a `peek` has shown it).
    pub fn bump(&mut self) {
        self.pos += 1;
    }

    /// Fast path for a word value: an optionally signed plain number. None (position
    /// unchanged) when the value is anything else or needs the general reader.
    pub fn signed_number_fast(&mut self) -> Option<f64> {
        self.skip_blanks();
        let save = self.pos;
        let neg = match self.bytes.get(self.pos) {
            Some(b'-') => {
                self.pos += 1;
                true
            }
            Some(b'+') => {
                self.pos += 1;
                false
            }
            _ => false,
        };
        match self.number_fast() {
            Some(v) => Some(if neg { -v } else { v }),
            None => {
                self.pos = save;
                None
            }
        }
    }

    /// True when only blanks remain.
    pub fn at_end(&mut self) -> bool {
        self.peek().is_none()
    }

    /// Reads raw text up to (not including) `end`, consuming `end`. Returns None when the
    /// line ends first. Used for comment bodies, whose case and spaces are kept.
    pub fn raw_until(&mut self, end: u8) -> Option<&'a str> {
        let start = self.pos;
        let rel = self.bytes[start..].iter().position(|&b| b == end)?;
        self.pos = start + rel + 1;
        std::str::from_utf8(&self.bytes[start..start + rel]).ok()
    }

    /// The rest of the line, raw, consumed.
    pub fn rest(&mut self) -> &'a str {
        let start = self.pos.min(self.bytes.len());
        self.pos = self.bytes.len();
        std::str::from_utf8(&self.bytes[start..]).unwrap_or("")
    }

    /// Reads an unsigned decimal number with blanks allowed between its characters
    /// (`1 2 . 5`). None when no digit was found.
    pub fn number(&mut self) -> Option<f64> {
        if let Some(v) = self.number_fast() {
            return Some(v);
        }
        self.number_general()
    }

    /// The common case, a number written without inner blanks and with few digits, read
    /// straight from the bytes. None (position unchanged) hands over to the general reader.
    fn number_fast(&mut self) -> Option<f64> {
        self.skip_blanks();
        let b = self.bytes;
        let start = self.pos;
        let mut i = start;
        let mut m: u64 = 0;
        let mut digits = 0u32;
        while i < b.len() && b[i].is_ascii_digit() {
            m = m * 10 + u64::from(b[i] - b'0');
            digits += 1;
            i += 1;
            if digits > 15 {
                return None;
            }
        }
        let mut frac_digits = 0u32;
        if i < b.len() && b[i] == b'.' {
            i += 1;
            while i < b.len() && b[i].is_ascii_digit() {
                m = m * 10 + u64::from(b[i] - b'0');
                digits += 1;
                frac_digits += 1;
                i += 1;
                if digits > 15 {
                    return None;
                }
            }
        }
        if digits == 0 {
            return None;
        }
        // A blank followed by more of the number needs the general reader.
        let mut j = i;
        while j < b.len() && (b[j] == b' ' || b[j] == b'\t' || b[j] == b'\r') {
            j += 1;
        }
        if j > i && j < b.len() && (b[j].is_ascii_digit() || b[j] == b'.') {
            return None;
        }
        self.pos = i;
        const POW10: [f64; 16] = [
            1.0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10, 1e11, 1e12, 1e13, 1e14, 1e15,
        ];
        // m < 10^16 < 2^53·2: m is exact when < 2^53, and one division by an exact power of
        // ten rounds correctly, as strtod does.
        if m >= (1u64 << 53) {
            self.pos = start;
            return None;
        }
        Some(m as f64 / POW10[frac_digits as usize])
    }

    fn number_general(&mut self) -> Option<f64> {
        let mut int: u64 = 0;
        let mut digits = 0usize;
        let mut big = false;
        let start = self.pos;
        while let Some(c) = self.peek() {
            if c.is_ascii_digit() {
                if int < 100_000_000_000_000_000 {
                    int = int * 10 + u64::from(c - b'0');
                } else {
                    big = true;
                }
                digits += 1;
                self.pos += 1;
            } else {
                break;
            }
        }
        let mut frac_digits = 0i32;
        let mut frac: u64 = 0;
        if self.peek() == Some(b'.') {
            self.pos += 1;
            while let Some(c) = self.peek() {
                if c.is_ascii_digit() {
                    if frac < 100_000_000_000_000_000 {
                        frac = frac * 10 + u64::from(c - b'0');
                        frac_digits += 1;
                    } else {
                        big = true;
                    }
                    digits += 1;
                    self.pos += 1;
                } else {
                    break;
                }
            }
        }
        if digits == 0 {
            self.pos = start;
            return None;
        }
        if big || frac_digits > 15 {
            // Rare: fall back to the exact decimal parser on the blank-free text.
            let text: String = std::str::from_utf8(&self.bytes[start..self.pos])
                .unwrap_or("0")
                .chars()
                .filter(|c| !c.is_whitespace())
                .collect();
            return text.parse::<f64>().ok().or(Some(0.0));
        }
        if frac_digits == 0 {
            return Some(int as f64);
        }
        // Exact when both parts fit 2^53, as `strtod` would give (correctly rounded):
        // an integer divided by a power of ten is one correctly rounded operation only if the
        // combined mantissa is exact, so combine first.
        let pow = 10u64.pow(frac_digits as u32);
        if let Some(m) = int.checked_mul(pow).and_then(|v| v.checked_add(frac)) {
            if m < (1u64 << 53) {
                return Some(m as f64 / pow as f64);
            }
        }
        let text: String = std::str::from_utf8(&self.bytes[start..self.pos])
            .unwrap_or("0")
            .chars()
            .filter(|c| !c.is_whitespace())
            .collect();
        Some(text.parse::<f64>().unwrap_or(0.0))
    }

    /// Reads a run of letters (lower-cased), e.g. an operator or function name.
    pub fn word(&mut self) -> String {
        let mut s = String::new();
        while let Some(c) = self.peek() {
            if c.is_ascii_alphabetic() {
                s.push(c as char);
                self.pos += 1;
            } else {
                break;
            }
        }
        s
    }

    /// Looks ahead for the letters of `kw` (blanks allowed between them) and consumes them
    /// if they are all there.
    pub fn eat_keyword(&mut self, kw: &str) -> bool {
        let save = self.pos;
        for k in kw.bytes() {
            if self.next_char() != Some(k) {
                self.pos = save;
                return false;
            }
        }
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_allow_inner_blanks() {
        let mut c = Cursor::new(" 1 2 . 5x");
        assert_eq!(c.number(), Some(12.5));
        assert_eq!(c.peek(), Some(b'x'));
    }

    #[test]
    fn decimal_parse_is_correctly_rounded() {
        for t in ["0.1", "123.456", "1.0005", "99999.99999", ".5", "7."] {
            let mut c = Cursor::new(t);
            let want: f64 = if t.ends_with('.') {
                t.trim_end_matches('.').parse().unwrap_or(0.0)
            } else {
                format!("0{t}").parse().unwrap_or(0.0)
            };
            assert_eq!(c.number(), Some(want), "{t}");
        }
    }

    #[test]
    fn case_folds_and_tracks_columns() {
        let mut c = Cursor::new("  G1");
        assert_eq!(c.col(), 3);
        assert_eq!(c.next_char(), Some(b'g'));
    }
}
