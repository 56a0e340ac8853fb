//! The interpreter's modal state (LinuxCNC's `setup` struct, the parts hytask implements)
//! and the predefined read-only named parameters computed from it.

use super::Interp;
use crate::gcode::canon::{FeedMode, LengthUnits, MotionControl, Plane, Pose};
use crate::gcode::InterpOptions;

/// Modal state. Lengths are in the current program units.
#[derive(Debug, Clone)]
pub(crate) struct Settings {
    /// Current position X Y Z A B C in the program frame.
    pub pos: [f64; 6],
    /// G20/G21.
    pub units: LengthUnits,
    /// Machine (tool table) units.
    pub machine_units: LengthUnits,
    /// G17…
    pub plane: Plane,
    /// G90 (true) / G91.
    pub absolute: bool,
    /// G90.1 (true) / G91.1.
    pub ijk_absolute: bool,
    /// G93/G94/G95.
    pub feed_mode: FeedMode,
    /// F, current units per minute (0 after G94/G95 switch).
    pub feed_rate: f64,
    /// S.
    pub speed: f64,
    /// Active motion G code in tenths; 800 = G80 (none).
    pub motion: u16,
    /// Active coordinate system 1..=9.
    pub origin_index: u8,
    /// Active work offset X…C.
    pub g5x: [f64; 6],
    /// G92 offset X…C.
    pub g92: [f64; 6],
    /// XY rotation of the active coordinate system, degrees.
    pub rotation: f64,
    /// Tool length offset X Y Z A B C U V W.
    pub tool_offset: Pose,
    /// Tool length offset when the last move was sent to canon (see `Interp::synch`).
    pub tlo_at_motion: Pose,
    /// A tool change happened: re-read the position before the next block.
    pub synch_pending: bool,
    /// Where G40 left the tool (X Y Z) when no move has been sent since: the program
    /// position is then the programmed point, but canon's (which a re-read after M6, M61
    /// or a probe returns, as in LinuxCNC) is the compensated one.
    pub comp_tool_left: Option<[f64; 3]>,
    /// P and Q of the last G5 (program units): a G5 without I and J starts in the
    /// direction the previous one ended (I, J = -P, -Q).
    pub last_g5_pq: [f64; 2],
    /// The NURBS block being collected between G5.2 and G5.3.
    pub nurbs: Option<super::splines::NurbsBlock>,
    /// G98 (true, back to the old Z) / G99 (R plane). Starts in G99, as LinuxCNC's
    /// interpreter does (`#<_retract_r_plane>` is 1 in rs274 before any G98/G99).
    pub retract_old_z: bool,
    /// In a state saved by M70/M73: whether the G92 offsets were applied (#5210), which M72
    /// restores. Not kept up to date in the live state (#5210 is the live flag).
    pub g92_enabled: bool,
    /// G43/G43.1/G43.2 in effect (not G49), whatever the offset's value.
    pub tlo_active: bool,
    /// G61/G61.1/G64.
    pub control: MotionControl,
    /// G64 Q.
    pub naive_tol: f64,
    /// Spindle: 0 stopped, 1 CW, -1 CCW.
    pub spindle: i8,
    /// G96 D limit, 0 in G97.
    pub css_max: f64,
    /// G96 active.
    pub css: bool,
    /// G7 (X words are diameters) rather than G8.
    pub diameter_mode: bool,
    /// M7.
    pub mist: bool,
    /// M8.
    pub flood: bool,
    /// M50 state.
    pub feed_override: bool,
    /// M51 state.
    pub speed_override: bool,
    /// M52 state.
    pub adaptive_feed: bool,
    /// M53 state.
    pub feed_hold: bool,
    /// Tool in spindle (number) and its table slot (0 = none).
    pub tool: u32,
    /// Slot of the tool in the spindle.
    pub tool_slot: usize,
    /// Copy of the table entry of the tool loaded by M6 (LinuxCNC's pocket 0). M61 changes
    /// the tool number but not this copy, and G43 without H reads it.
    pub spindle_tool: Option<crate::gcode::tooltable::Tool>,
    /// T word: prepared tool number and slot.
    pub selected: Option<(u32, usize)>,
    /// Canned cycle: Z before the current series of contiguous cycles (G98 retracts to it).
    pub cycle_start_z: f64,
    /// Canned cycle: the R plane height of the last cycle block (absolute).
    pub cycle_r_abs: f64,
    /// Canned cycle: Z of the last cycle block (sticky).
    pub cycle_z: f64,
    /// Canned cycle: R of the last cycle block (sticky).
    pub cycle_r: f64,
    /// Canned cycle: Q of the last cycle block (sticky).
    pub cycle_q: f64,
    /// Canned cycle: P of the last cycle block (sticky).
    pub cycle_p: f64,
    /// `#<_value>` from the last return/endsub.
    pub value: f64,
    /// `#<_value_returned>`.
    pub value_returned: f64,
    /// M70/M73 saved state stack depth marker (states saved per call level).
    pub saved: Vec<Option<Box<Settings>>>,
    /// Per call level: the saved state was taken by M73 and is restored on return.
    pub auto_restore: Vec<bool>,
}

impl Settings {
    pub(crate) fn new(opts: &InterpOptions) -> Settings {
        Settings {
            pos: [0.0; 6],
            units: LengthUnits::Millimeters,
            machine_units: opts.machine_units,
            plane: Plane::Xy,
            absolute: true,
            ijk_absolute: false,
            feed_mode: FeedMode::UnitsPerMinute,
            feed_rate: 0.0,
            speed: 0.0,
            motion: 800,
            origin_index: 1,
            g5x: [0.0; 6],
            g92: [0.0; 6],
            rotation: 0.0,
            tool_offset: [0.0; 9],
            tlo_at_motion: [0.0; 9],
            synch_pending: false,
            comp_tool_left: None,
            last_g5_pq: [0.0; 2],
            nurbs: None,
            retract_old_z: false,
            g92_enabled: false,
            tlo_active: false,
            control: MotionControl::Continuous { tolerance: 0.0 },
            naive_tol: 0.0,
            spindle: 0,
            css_max: 0.0,
            css: false,
            diameter_mode: false,
            mist: false,
            flood: false,
            feed_override: true,
            speed_override: true,
            adaptive_feed: false,
            feed_hold: true,
            tool: 0,
            tool_slot: opts.start_pocket,
            spindle_tool: None,
            selected: None,
            cycle_start_z: 0.0,
            cycle_z: 0.0,
            cycle_r_abs: 0.0,
            cycle_r: 0.0,
            cycle_q: 0.0,
            cycle_p: 0.0,
            value: 0.0,
            value_returned: 0.0,
            saved: vec![None],
            auto_restore: vec![false],
        }
    }
}

fn b(v: bool) -> f64 {
    if v {
        1.0
    } else {
        0.0
    }
}

/// The predefined named parameters of LinuxCNC that hytask maintains.
pub(crate) fn predefined(it: &Interp<'_>, name: &str) -> Option<f64> {
    let s = &it.s;
    let axis = |i: usize| s.pos[i];
    // The machine position, through the XY rotation of `G10 L2 … R` as canon moves the
    // machine (rs274's `#<_abs_x>`: `machine = rotate(program + G92) + G5x + tool`).
    let abs = |i: usize| it.machine_of_program(&s.pos, true)[i];
    Some(match name {
        // LinuxCNC 2.9's interpreter reports its version as major 2.9, minor 0.
        "_vmajor" => 2.9,
        "_vminor" => 0.0,
        "_line" => f64::from(it.loc.line),
        "_motion_mode" => f64::from(s.motion),
        "_plane" => match s.plane {
            crate::gcode::canon::Plane::Xy => 170.0,
            crate::gcode::canon::Plane::Xz => 180.0,
            crate::gcode::canon::Plane::Yz => 190.0,
            crate::gcode::canon::Plane::Uv => 171.0,
            crate::gcode::canon::Plane::Uw => 181.0,
            crate::gcode::canon::Plane::Vw => 191.0,
        },
        "_ccomp" => 400.0,
        "_metric" => b(s.units == LengthUnits::Millimeters),
        "_imperial" => b(s.units == LengthUnits::Inches),
        "_absolute" => b(s.absolute),
        "_incremental" => b(!s.absolute),
        "_inverse_time" => b(s.feed_mode == FeedMode::InverseTime),
        "_units_per_minute" => b(s.feed_mode == FeedMode::UnitsPerMinute),
        "_units_per_rev" => b(s.feed_mode == FeedMode::UnitsPerRevolution),
        "_coord_system" => match s.origin_index {
            1..=6 => 530.0 + 10.0 * f64::from(s.origin_index),
            i => 590.0 + f64::from(i - 6),
        },
        "_tool_offset" => b(s.tool_offset.iter().any(|v| *v != 0.0)),
        "_retract_r_plane" => b(!s.retract_old_z),
        "_retract_old_z" => b(s.retract_old_z),
        "_spindle_rpm_mode" => b(!s.css),
        "_spindle_css_mode" => b(s.css),
        "_ijk_absolute_mode" => b(s.ijk_absolute),
        "_lathe_diameter_mode" => b(s.diameter_mode),
        "_lathe_radius_mode" => b(!s.diameter_mode),
        "_spindle_on" => b(s.spindle != 0),
        "_spindle_cw" => b(s.spindle > 0),
        "_mist" => b(s.mist),
        "_flood" => b(s.flood),
        "_speed_override" => b(s.speed_override),
        "_feed_override" => b(s.feed_override),
        "_adaptive_feed" => b(s.adaptive_feed),
        "_feed_hold" => b(s.feed_hold),
        "_feed" => s.feed_rate,
        "_rpm" => s.speed,
        "_x" => axis(0),
        "_y" => axis(1),
        "_z" => axis(2),
        "_a" => axis(3),
        "_b" => axis(4),
        "_c" => axis(5),
        "_u" | "_v" | "_w" | "_abs_u" | "_abs_v" | "_abs_w" => 0.0,
        "_abs_x" => abs(0),
        "_abs_y" => abs(1),
        "_abs_z" => abs(2),
        "_abs_a" => abs(3),
        "_abs_b" => abs(4),
        "_abs_c" => abs(5),
        "_current_tool" => f64::from(s.tool),
        "_current_pocket" => s.tool_slot as f64,
        // rs274 reports tool 0 (and pocket -1) before any T word.
        "_selected_tool" => s.selected.map(|t| f64::from(t.0)).unwrap_or(0.0),
        "_selected_pocket" => s.selected.map(|t| t.1 as f64).unwrap_or(-1.0),
        "_value" => s.value,
        "_value_returned" => s.value_returned,
        "_task" => 0.0,
        "_call_level" => it.call_level() as f64,
        "_remap_level" => 0.0,
        _ => return None,
    })
}
