//! The var file at the start and end of a run (see [`crate::gcode::varfile`]).

use super::{GcodeError, Interp};
use crate::gcode::expr::ParamSource;
use crate::gcode::params::{COORD_INDEX, G92_BASE, G92_ENABLED};
use crate::gcode::varfile::{VarFile, FIRST_LIVE};

impl Interp<'_> {
    /// Loads the var file's values and makes its offsets the active ones, as rs274 does at
    /// start: the coordinate system of #5220 with its offsets and rotation, and the G92
    /// offsets of #5211… only when #5210 is 1. The start position is the machine position
    /// less those offsets (without the rotation, as rs274 computes it).
    pub(super) fn restore_persistent(&mut self) -> Result<(), GcodeError> {
        let Some(v) = self.opts.parameters.clone() else {
            return Ok(());
        };
        for &(n, x) in &v.values {
            if n < FIRST_LIVE {
                self.p.numbered[usize::from(n)] = x;
            }
        }
        let idx = self.p.numbered[COORD_INDEX];
        if !(1.0..=9.0).contains(&idx) || idx.fract() != 0.0 {
            return Err(self.err(
                1,
                format!("Parameter #5220 (coordinate system) from the parameter file must be 1 to 9, not {idx}"),
            ));
        }
        let index = idx as u8;
        let (o, rot) = self.load_g5x(index);
        self.s.g5x = o;
        self.s.rotation = rot;
        self.s.origin_index = index;
        if self.p.numbered[G92_ENABLED] == 1.0 {
            for i in 0..6 {
                self.s.g92[i] = self.s.user_len(i, self.p.numbered[G92_BASE + i]);
            }
        }
        for i in 0..6 {
            self.s.pos[i] -= self.s.g5x[i] + self.s.g92[i];
        }
        Ok(())
    }

    /// The persistent parameters now: every number the var file saves
    /// ([`VarFile::saved_numbers`] of the loaded file), with its current value.
    pub(crate) fn persistent(&self) -> VarFile {
        let base = self.opts.parameters.as_deref().cloned().unwrap_or_default();
        VarFile {
            values: base
                .saved_numbers()
                .into_iter()
                .map(|n| (n, self.numbered(f64::from(n)).unwrap_or(0.0)))
                .collect(),
        }
    }
}
