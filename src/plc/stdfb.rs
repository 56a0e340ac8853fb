//! The standard function blocks (IEC 61131-3 ed.3 §6.6.3.5): bistables SR/RS, edge detection
//! R_TRIG/F_TRIG, counters CTU/CTD/CTUD, timers TON/TOF/TP. Native code on the instance's
//! cells; a timer reads the scan's time stamp, so timing is in PLC (scan) time: the elapsed
//! time ET advances only when the instance is called, as on every IEC PLC.

use super::ast::Section;
use super::types::{IntKind, Ty};

/// A standard function block type.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StdFb {
    /// On-delay timer.
    Ton,
    /// Off-delay timer.
    Tof,
    /// Pulse timer.
    Tp,
    /// Rising edge.
    RTrig,
    /// Falling edge.
    FTrig,
    /// Up counter.
    Ctu,
    /// Down counter.
    Ctd,
    /// Up-down counter.
    Ctud,
    /// Set-dominant bistable.
    Sr,
    /// Reset-dominant bistable.
    Rs,
}

type Member = (&'static str, Ty, Section);

const B: Ty = Ty::Bool;
const T: Ty = Ty::Time;
const I: Ty = Ty::Int(IntKind::Int);
const IN: Section = Section::Input;
const OUT: Section = Section::Output;
const HID: Section = Section::Temp;

const TIMER: &[Member] = &[
    ("IN", B, IN),
    ("PT", T, IN),
    ("Q", B, OUT),
    ("ET", T, OUT),
    ("_START", T, HID),
    ("_PREV", B, HID),
];

/// Cells of a timer instance (TON, TOF, TP).
pub const TIMER_CELLS: usize = 6;

/// One call of the on-delay timer on its instance cells. Apart from [`StdFb::exec`] so that
/// the interpreter calls it directly on a timer's call instruction: the most common block
/// of PLC code, run without the jump on the block type and with its cells checked once.
#[inline(always)]
pub fn ton(c: &mut [u64; TIMER_CELLS], now: i64) {
    let (inp, pt) = (c[0] != 0, c[1] as i64);
    if !inp {
        c[2] = 0;
        c[3] = 0;
    } else {
        if c[5] == 0 {
            c[4] = now as u64;
        }
        let et = now.wrapping_sub(c[4] as i64).min(pt).max(0);
        c[3] = et as u64;
        c[2] = (et >= pt) as u64;
    }
    c[5] = inp as u64;
}

const _: () = assert!(TIMER.len() == TIMER_CELLS);

impl StdFb {
    /// Looks a standard block up by its upper-case name.
    pub fn by_name(name: &str) -> Option<StdFb> {
        Some(match name {
            "TON" => StdFb::Ton,
            "TOF" => StdFb::Tof,
            "TP" => StdFb::Tp,
            "R_TRIG" => StdFb::RTrig,
            "F_TRIG" => StdFb::FTrig,
            "CTU" => StdFb::Ctu,
            "CTD" => StdFb::Ctd,
            "CTUD" => StdFb::Ctud,
            "SR" => StdFb::Sr,
            "RS" => StdFb::Rs,
            _ => return None,
        })
    }
    /// Its IEC name.
    pub fn name(self) -> &'static str {
        match self {
            StdFb::Ton => "TON",
            StdFb::Tof => "TOF",
            StdFb::Tp => "TP",
            StdFb::RTrig => "R_TRIG",
            StdFb::FTrig => "F_TRIG",
            StdFb::Ctu => "CTU",
            StdFb::Ctd => "CTD",
            StdFb::Ctud => "CTUD",
            StdFb::Sr => "SR",
            StdFb::Rs => "RS",
        }
    }
    /// The instance's cells in order: name, type, and whether input, output or hidden state
    /// (hidden members are not visible to the program or the variable table).
    pub fn members(self) -> &'static [Member] {
        match self {
            StdFb::Ton | StdFb::Tof | StdFb::Tp => TIMER,
            StdFb::RTrig | StdFb::FTrig => &[("CLK", B, IN), ("Q", B, OUT), ("_M", B, HID)],
            StdFb::Ctu => &[
                ("CU", B, IN),
                ("R", B, IN),
                ("PV", I, IN),
                ("Q", B, OUT),
                ("CV", I, OUT),
                ("_M", B, HID),
            ],
            StdFb::Ctd => &[
                ("CD", B, IN),
                ("LD", B, IN),
                ("PV", I, IN),
                ("Q", B, OUT),
                ("CV", I, OUT),
                ("_M", B, HID),
            ],
            StdFb::Ctud => &[
                ("CU", B, IN),
                ("CD", B, IN),
                ("R", B, IN),
                ("LD", B, IN),
                ("PV", I, IN),
                ("QU", B, OUT),
                ("QD", B, OUT),
                ("CV", I, OUT),
                ("_MU", B, HID),
                ("_MD", B, HID),
            ],
            StdFb::Sr => &[("S1", B, IN), ("R", B, IN), ("Q1", B, OUT)],
            StdFb::Rs => &[("S", B, IN), ("R1", B, IN), ("Q1", B, OUT)],
        }
    }

    /// Runs one call on the instance cells `c` at scan time `now` (ns).
    #[inline]
    pub fn exec(self, c: &mut [u64], now: i64) {
        let b = |v: u64| v != 0;
        match self {
            StdFb::Ton => {
                if let Ok(c) = <&mut [u64; TIMER_CELLS]>::try_from(c) {
                    ton(c, now);
                }
            }
            StdFb::Tof => {
                let (inp, pt) = (b(c[0]), c[1] as i64);
                if inp {
                    c[2] = 1;
                    c[3] = 0;
                } else {
                    if b(c[5]) {
                        c[4] = now as u64;
                    }
                    if b(c[2]) {
                        let et = now.wrapping_sub(c[4] as i64).min(pt).max(0);
                        c[3] = et as u64;
                        c[2] = (et < pt) as u64;
                    }
                }
                c[5] = inp as u64;
            }
            StdFb::Tp => {
                let (inp, pt) = (b(c[0]), c[1] as i64);
                if !b(c[2]) && inp && !b(c[5]) {
                    c[4] = now as u64;
                    c[2] = 1;
                }
                if b(c[2]) {
                    let et = now.wrapping_sub(c[4] as i64).min(pt).max(0);
                    c[3] = et as u64;
                    c[2] = (et < pt) as u64;
                } else if !inp {
                    c[3] = 0;
                }
                c[5] = inp as u64;
            }
            StdFb::RTrig => {
                c[1] = (b(c[0]) && !b(c[2])) as u64;
                c[2] = c[0];
            }
            StdFb::FTrig => {
                // _M holds the previous CLK, initially FALSE: no edge on the first call.
                c[1] = (!b(c[0]) && b(c[2])) as u64;
                c[2] = c[0];
            }
            StdFb::Ctu => {
                let cv = c[4] as i64;
                if b(c[1]) {
                    c[4] = 0;
                } else if b(c[0]) && !b(c[5]) && (cv as i128) < IntKind::Int.max() {
                    c[4] = (cv + 1) as u64;
                }
                c[3] = (c[4] as i64 >= c[2] as i64) as u64;
                c[5] = c[0];
            }
            StdFb::Ctd => {
                let cv = c[4] as i64;
                if b(c[1]) {
                    c[4] = c[2];
                } else if b(c[0]) && !b(c[5]) && (cv as i128) > IntKind::Int.min() {
                    c[4] = (cv - 1) as u64;
                }
                c[3] = (c[4] as i64 <= 0) as u64;
                c[5] = c[0];
            }
            StdFb::Ctud => {
                let up = b(c[0]) && !b(c[8]);
                let down = b(c[1]) && !b(c[9]);
                let cv = c[7] as i64;
                if b(c[2]) {
                    c[7] = 0;
                } else if b(c[3]) {
                    c[7] = c[4];
                } else if up && !down && (cv as i128) < IntKind::Int.max() {
                    c[7] = (cv + 1) as u64;
                } else if down && !up && (cv as i128) > IntKind::Int.min() {
                    c[7] = (cv - 1) as u64;
                }
                c[5] = (c[7] as i64 >= c[4] as i64) as u64;
                c[6] = (c[7] as i64 <= 0) as u64;
                c[8] = c[0];
                c[9] = c[1];
            }
            StdFb::Sr => c[2] = (b(c[0]) || (!b(c[1]) && b(c[2]))) as u64,
            StdFb::Rs => c[2] = (!b(c[1]) && (b(c[0]) || b(c[2]))) as u64,
        }
    }
}
