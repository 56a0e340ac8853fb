//! Where a segment passes the vertices of the source lines it replaces (issue 14).
//!
//! Arc fitting ([`super::arcfit`]) replaces a run of short G1 lines by arcs, so one segment
//! can run along several source lines. The executing line the interpolator reports (status
//! `line`, job progress) must still advance line by line as the tool passes each original
//! vertex. A segment carries its first line (`Segment::line`) and these marks: the fractions
//! of its length at which the next line begins, each one line after the previous (the fitter
//! only fits runs of consecutive lines, see `lookahead::fit_arcs`). Fixed-size and `Copy`, so
//! segments stay heap-free for the realtime queue; at most [`MAX_MARKS`] per segment (the
//! fitter splits longer arcs, `arcfit::split_marked`).

/// Most vertices one segment may pass: what fits in the segment queue's item size (416 bytes).
pub const MAX_MARKS: usize = 10;

/// Quantisation of a mark: a fraction `f` of the segment length is stored as
/// `1 + round(f·SCALE)` in a byte (0 = no mark), 1/254 of the segment's length: on a fitted
/// arc of at most `MAX_MARKS + 1` chords, a small part of one chord.
const SCALE: f64 = 254.0;

/// Marks of one segment, in increasing order.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct LineMarks {
    at: [u8; MAX_MARKS],
    n: u8,
}

impl LineMarks {
    /// No marks: the segment runs along one source line.
    pub const NONE: LineMarks = LineMarks {
        at: [0; MAX_MARKS],
        n: 0,
    };

    /// Marks at the fractions `fractions` (ascending, in [0, 1]) of the segment's length;
    /// `None` if there are more than [`MAX_MARKS`].
    pub fn new(fractions: &[f64]) -> Option<LineMarks> {
        if fractions.len() > MAX_MARKS {
            return None;
        }
        let mut m = LineMarks::NONE;
        for (slot, f) in m.at.iter_mut().zip(fractions) {
            *slot = 1 + (f.clamp(0.0, 1.0) * SCALE).round() as u8;
        }
        m.n = fractions.len() as u8;
        Some(m)
    }

    /// Number of marks.
    pub fn len(&self) -> usize {
        self.n as usize
    }

    /// True without marks.
    pub fn is_empty(&self) -> bool {
        self.n == 0
    }

    /// How many marks lie at or before `fraction` of the segment's length (realtime: no
    /// allocation, at most [`MAX_MARKS`] comparisons).
    pub fn passed(&self, fraction: f64) -> u32 {
        let q = 1.0 + fraction * SCALE;
        self.at[..self.len()]
            .iter()
            .take_while(|&&a| f64::from(a) <= q + 1e-9)
            .count() as u32
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn marks_count_the_vertices_passed() {
        let m = LineMarks::new(&[0.1, 0.5, 0.9]).unwrap();
        assert_eq!(m.len(), 3);
        assert_eq!(m.passed(0.0), 0);
        assert_eq!(m.passed(0.09), 0);
        assert_eq!(m.passed(0.11), 1);
        assert_eq!(m.passed(0.5), 2);
        assert_eq!(m.passed(1.0), 3);
        assert_eq!(LineMarks::NONE.passed(1.0), 0);
        assert!(LineMarks::new(&[0.5; MAX_MARKS + 1]).is_none());
    }
}
