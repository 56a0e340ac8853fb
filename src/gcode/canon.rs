//! Canonical machining commands: the interpreter's only output.
//!
//! The vocabulary follows LinuxCNC's canonical machining functions (the calls `rs274 -g`
//! prints), so a hytask trace can be diffed against LinuxCNC's line by line. Coordinates are
//! in the *program* frame and the *current length units*, exactly as the interpreter hands
//! them to canon in LinuxCNC; the offsets that map them to the machine frame arrive as their
//! own commands (`SetG5xOffset`, `SetG92Offset`, `UseToolLengthOffset`, `SetXyRotation`,
//! `UseLengthUnits`). The motion side (`motion::from_canon`) folds those into machine-frame
//! millimetres. Keeping the interpreter this thin is what lets it stay a pure front end:
//! text in, canonical commands out.

use std::sync::Arc;

/// Number of axes a pose carries: X Y Z A B C U V W.
pub const NUM_AXES: usize = 9;

/// A pose in the program frame, current units (linear) and degrees (rotary): X Y Z A B C U V W.
pub type Pose = [f64; NUM_AXES];

/// Where a canonical command came from. Every command carries one so progress, faults and
/// errors can name the G-code line that caused them.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SourceLoc {
    /// File the block was read from (the main program or a subroutine file).
    pub file: Arc<str>,
    /// 1-based line number in that file.
    pub line: u32,
    /// 1-based column of the word that produced the command (1 when not word-specific).
    pub col: u32,
}

/// Length units of the program (G20/G21).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LengthUnits {
    /// G20.
    Inches,
    /// G21.
    Millimeters,
}

impl LengthUnits {
    /// Millimetres per program unit.
    pub fn mm_per_unit(self) -> f64 {
        match self {
            LengthUnits::Inches => 25.4,
            LengthUnits::Millimeters => 1.0,
        }
    }
}

/// Active plane (G17/G18/G19 and the .1 variants).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Plane {
    /// G17: arcs in X/Y, helix along Z.
    Xy,
    /// G18: arcs in Z/X (first axis Z, second X), helix along Y.
    Xz,
    /// G19: arcs in Y/Z, helix along X.
    Yz,
    /// G17.1: U/V.
    Uv,
    /// G18.1: W/U.
    Uw,
    /// G19.1: V/W.
    Vw,
}

/// Feed-rate interpretation (G93/G94/G95).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FeedMode {
    /// G94: units per minute.
    UnitsPerMinute,
    /// G93: the F word is 1/minutes for the move.
    InverseTime,
    /// G95: units per spindle revolution.
    UnitsPerRevolution,
}

/// Path control mode (G61/G61.1/G64).
///
/// LinuxCNC maps G61 to `CANON_EXACT_PATH` and G61.1 to `CANON_EXACT_STOP` (and canned
/// cycles switch to exact path around their moves); the interpreter follows it exactly.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum MotionControl {
    /// G61.1: stop exactly at every corner.
    ExactStop,
    /// G61: exact path, slow down at corners but do not stop unless needed.
    ExactPath,
    /// G64 [P tolerance]: blend, deviating at most `tolerance` (program units, 0 = as fast as possible).
    Continuous {
        /// G64 P: path tolerance, program units; 0 means "no tolerance given".
        tolerance: f64,
    },
}

/// Spindle direction.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SpindleDir {
    /// M3.
    Clockwise,
    /// M4.
    CounterClockwise,
}

/// What a `Wait` (M66) waits for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum WaitKind {
    /// L0: return immediately, just sample.
    Immediate,
    /// L1: rising edge.
    Rise,
    /// L2: falling edge.
    Fall,
    /// L3: input high.
    High,
    /// L4: input low.
    Low,
}

/// Which kind of input a `Wait` samples.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum InputKind {
    /// M66 P: digital input.
    Digital,
    /// M66 E: analog input.
    Analog,
}

/// Probe variant (G38.2–G38.5).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ProbeKind {
    /// G38.2: toward the workpiece, error if no contact.
    TowardErr,
    /// G38.3: toward the workpiece, no error if no contact.
    Toward,
    /// G38.4: away from the workpiece, error if contact is not lost.
    AwayErr,
    /// G38.5: away from the workpiece, no error.
    Away,
}

impl ProbeKind {
    /// G38.2/G38.3 stop when the probe input becomes active; G38.4/G38.5 when it becomes
    /// inactive.
    pub fn toward(self) -> bool {
        matches!(self, ProbeKind::TowardErr | ProbeKind::Toward)
    }

    /// G38.2/G38.4: a move that ends without the expected change is an error.
    pub fn needs_contact(self) -> bool {
        matches!(self, ProbeKind::TowardErr | ProbeKind::AwayErr)
    }

    /// The G code, for messages.
    pub fn gcode(self) -> &'static str {
        match self {
            ProbeKind::TowardErr => "G38.2",
            ProbeKind::Toward => "G38.3",
            ProbeKind::AwayErr => "G38.4",
            ProbeKind::Away => "G38.5",
        }
    }
}

/// The call of a LinuxCNC log comment (see [`CanonCmd::Log`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LogKind {
    /// `(LOGOPEN,file)`: open (truncate) the log file.
    Open,
    /// `(LOGAPPEND,file)`: open the log file for appending.
    Append,
    /// `(LOG,text)`: write a line.
    Write,
    /// `(LOGCLOSE)`: close the log file.
    Close,
}

/// One canonical machining command. Variants mirror LinuxCNC canon calls; the doc comment of
/// each names the call `rs274 -g` prints for it.
#[derive(Debug, Clone, PartialEq)]
pub enum CanonCmd {
    /// `USE_LENGTH_UNITS(CANON_UNITS_MM|CANON_UNITS_INCHES)`.
    UseLengthUnits(LengthUnits),
    /// `SET_G5X_OFFSET(index, x, y, z, a, b, c)`: active work offset (1 = G54 … 9 = G59.3).
    SetG5xOffset {
        /// 1..=9.
        index: u8,
        /// Offset, program units.
        offset: Pose,
    },
    /// `SET_G92_OFFSET(x, y, z, a, b, c)`.
    SetG92Offset(Pose),
    /// `SET_XY_ROTATION(degrees)` (G10 L2 R).
    SetXyRotation(f64),
    /// `USE_TOOL_LENGTH_OFFSET(x y z, a b c, u v w)`.
    UseToolLengthOffset(Pose),
    /// `SELECT_PLANE(CANON_PLANE_XY)` etc.
    SelectPlane(Plane),
    /// `SET_FEED_RATE(f)`: units per minute (or 1/min in inverse time).
    SetFeedRate(f64),
    /// `SET_FEED_MODE(spindle, mode)`.
    SetFeedMode(FeedMode),
    /// `SET_MOTION_CONTROL_MODE(CANON_EXACT_STOP|CANON_EXACT_PATH|CANON_CONTINUOUS, tol)`.
    SetMotionControl(MotionControl),
    /// `SET_NAIVECAM_TOLERANCE(q)` (G64 Q): collinear short moves within q may be merged.
    SetNaivecamTolerance(f64),
    /// `STRAIGHT_TRAVERSE(x, y, z, a, b, c)`: rapid move (G0, and the moves of G28/G30/canned cycles).
    StraightTraverse(Pose),
    /// `STRAIGHT_FEED(x, y, z, a, b, c)`: linear move at the feed rate.
    StraightFeed(Pose),
    /// `ARC_FEED(first_end, second_end, first_axis, second_axis, rotation, axis_end_point, a, b, c)`.
    ///
    /// `first`/`second` are the in-plane coordinates in plane order (G17: X,Y; G18: Z,X;
    /// G19: Y,Z); `rotation` is +n for n counter-clockwise turns and -n for clockwise
    /// (rs274's convention: 1 = CCW less than a full turn, -1 = CW); `axis_end` is the end
    /// on the helix axis. `end` is the full end pose (redundant with the above, but it saves
    /// every consumer from re-deriving the plane mapping).
    ArcFeed {
        /// End, first in-plane axis.
        first_end: f64,
        /// End, second in-plane axis.
        second_end: f64,
        /// Centre, first in-plane axis.
        first_center: f64,
        /// Centre, second in-plane axis.
        second_center: f64,
        /// Signed turns: >0 counter-clockwise, <0 clockwise.
        rotation: i32,
        /// End on the axis normal to the plane.
        axis_end: f64,
        /// Plane the arc lies in.
        plane: Plane,
        /// Full end pose (program frame).
        end: Pose,
    },
    /// `NURBS_FEED(n, ...)`: a feed move along a planar NURBS curve in the XY plane (G5
    /// cubic and G5.1 quadratic splines as Bézier curves). `points` are the `n` control
    /// points in the program frame, the current position first, each with its weight;
    /// the knot vector is uniform and clamped, of order `order` (degree + 1). The other
    /// axes do not move. The planner flattens the curve into lines within the path
    /// tolerance.
    NurbsFeed {
        /// Control points `[x, y, weight]`, starting at the current position.
        points: Vec<[f64; 3]>,
        /// Order of the curve (4: cubic, 3: quadratic).
        order: u8,
        /// Full end pose (program frame).
        end: Pose,
        /// G93: the F word (the move takes 1/F minutes), as rs274 sets no feed rate for it.
        inverse_time: Option<f64>,
    },
    /// `DWELL(seconds)`.
    Dwell(f64),
    /// `SET_SPINDLE_SPEED(spindle, rpm)`.
    SetSpindleSpeed(f64),
    /// `START_SPINDLE_CLOCKWISE(0)` / `START_SPINDLE_COUNTERCLOCKWISE(0)`.
    StartSpindle(SpindleDir),
    /// `STOP_SPINDLE_TURNING(0)`.
    StopSpindle,
    /// `MIST_ON()`.
    MistOn,
    /// `MIST_OFF()`.
    MistOff,
    /// `FLOOD_ON()`.
    FloodOn,
    /// `FLOOD_OFF()`.
    FloodOff,
    /// `SELECT_TOOL(t)`: T word, prepare the tool.
    SelectTool(u32),
    /// `START_CHANGE()`: M6 begins.
    StartChange,
    /// `CHANGE_TOOL(slot)`: M6 swaps the prepared tool in.
    ChangeTool(u32),
    /// `CHANGE_TOOL_NUMBER(t)`: M61 Q.
    ChangeToolNumber(u32),
    /// `SET_MOTION_OUTPUT_BIT(n)`/`CLEAR_MOTION_OUTPUT_BIT(n)` (M62/M63: synchronised with
    /// the next motion) and `SET_AUX_OUTPUT_BIT`/`CLEAR_AUX_OUTPUT_BIT` (M64/M65: immediate).
    DigitalOutput {
        /// Output index (P word).
        index: u32,
        /// New state.
        on: bool,
        /// True for M62/M63 (with motion), false for M64/M65 (immediate).
        synced: bool,
    },
    /// `SET_MOTION_OUTPUT_VALUE(n, v)` (M67) / `SET_AUX_OUTPUT_VALUE(n, v)` (M68).
    AnalogOutput {
        /// Output index (E word).
        index: u32,
        /// Value (Q word).
        value: f64,
        /// True for M67 (with motion), false for M68 (immediate).
        synced: bool,
    },
    /// `WAIT(index, input_type, wait_type, timeout)` (M66).
    Wait {
        /// Input index.
        index: u32,
        /// Digital or analog.
        input: InputKind,
        /// Edge/level to wait for.
        kind: WaitKind,
        /// Seconds (Q word); 0 = sample only.
        timeout_s: f64,
    },
    /// `STRAIGHT_PROBE(x, y, z, a, b, c, ...)` (G38.x).
    StraightProbe {
        /// Target pose (program frame).
        end: Pose,
        /// G38 variant.
        kind: ProbeKind,
    },
    /// `FEED_OVERRIDE_ENABLE()`/`DISABLE` and friends (M48–M53): which overrides are live.
    OverrideEnable {
        /// Which override.
        which: OverrideKind,
        /// Enabled or not.
        on: bool,
    },
    /// `MESSAGE("…")` from `(MSG,…)`; `(DEBUG,…)` also arrives here with its parameters
    /// substituted.
    Message(String),
    /// `(PRINT,…)` with parameters substituted: operator log output, not shown as a message.
    /// rs274 writes it to stdout as a bare line without a sequence number.
    Print(String),
    /// `COMMENT("…")`.
    Comment(String),
    /// LinuxCNC's log comments: `LOGOPEN("file")`, `LOGAPPEND("file")`, `LOG("…")` (its
    /// parameters substituted) and `LOGCLOSE()`. LinuxCNC's task writes the file as the
    /// call is executed (probe logs); rs274 only prints the call.
    Log {
        /// Which call.
        kind: LogKind,
        /// The file name, or the line to write (empty for `LOGCLOSE`).
        text: String,
    },
    /// `PROGRAM_STOP()` (M0).
    ProgramStop,
    /// `OPTIONAL_PROGRAM_STOP()` (M1).
    OptionalProgramStop,
    /// `PROGRAM_END()` (M2/M30).
    ProgramEnd,
    /// `PALLET_SHUTTLE()` (M60, and before `PROGRAM_END` for M30).
    PalletShuttle,
    /// `ON_RESET()`: the interpreter was (re)initialised; emitted at start-up and after the
    /// program ends, as LinuxCNC does. Consumers may reset per-program state here.
    OnReset,
    /// `SET_FEED_REFERENCE(CANON_XYZ)`: feed rates refer to the XYZ tool path (start-up).
    SetFeedReference,
    /// `SET_SPINDLE_MODE(spindle css_max)`: G97 (`css_max_rpm` = 0, constant RPM) or G96 D
    /// (constant surface speed limited to `css_max_rpm`).
    SetSpindleMode {
        /// 0 for G97 (RPM mode), else the G96 D speed limit in RPM.
        css_max_rpm: f64,
    },
    /// `TURN_PROBE_ON()`/`TURN_PROBE_OFF()` around a G38.x `StraightProbe`.
    Probe {
        /// True when probing starts.
        on: bool,
    },
    /// `SET_TOOL_TABLE_ENTRY(pocket, tool, offsets, diameter, frontangle, backangle,
    /// orientation)` from G10 L1/L10/L11: the tool table changed. Values are in machine
    /// (tool table) units, not program units, as LinuxCNC hands them to canon.
    SetToolTableEntry {
        /// Pocket (table index; 0 = the spindle's copy).
        pocket: u32,
        /// Tool number.
        tool: u32,
        /// Tool offsets X Y Z A B C U V W.
        offset: Pose,
        /// Diameter.
        diameter: f64,
        /// Lathe front angle.
        front_angle: f64,
        /// Lathe back angle.
        back_angle: f64,
        /// Lathe orientation.
        orientation: i32,
    },
    /// `ORIENT_SPINDLE(0, angle, mode)` (M19 R… P…): stop the spindle at `angle` degrees;
    /// `mode` 0 turns either way, 1 clockwise, 2 counter-clockwise.
    OrientSpindle {
        /// Degrees: M19's R (0..=360) plus the machine's `ORIENT_OFFSET`, not wrapped.
        angle: f64,
        /// 0, 1 or 2 (M19 P).
        mode: u8,
    },
    /// `SPINDLE.0.WAIT_ORIENT_COMPLETE(timeout)` (M19 Q): wait up to `timeout` seconds for
    /// the orientation to finish.
    WaitOrientComplete(f64),
    /// `START_SPEED_FEED_SYNC(pitch, 0)`: the following feed moves advance `pitch` program
    /// units along their path per spindle revolution, locked to the spindle's position
    /// (G33, G33.1, G76), until [`CanonCmd::StopSpeedFeedSync`].
    StartSpeedFeedSync {
        /// Program units per revolution (G33/G33.1 K, G76 P).
        pitch: f64,
    },
    /// `STOP_SPEED_FEED_SYNCH()`: the end of a spindle-synchronised stretch.
    StopSpeedFeedSync,
    /// `RIGID_TAP(x, y, z)` (G33.1): feed to `end` locked to the spindle, reverse the
    /// spindle, and come back to the start on the same helix; the position after it is the
    /// start.
    RigidTap {
        /// Bottom of the tap, program frame (only X Y Z move).
        end: Pose,
    },
    /// `FINISH()`: the program ended at its closing `%` rather than with M2/M30.
    Finish,
    /// M100–M199 user command with its P and Q words.
    UserMcode {
        /// 100..=199.
        code: u32,
        /// P word (0 when absent).
        p: f64,
        /// Q word (0 when absent).
        q: f64,
    },
}

/// Which override an M48–M53 word switches.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OverrideKind {
    /// M48/M49 switch feed and spindle together.
    FeedAndSpindle,
    /// M50.
    Feed,
    /// M51.
    Spindle,
    /// M52.
    AdaptiveFeed,
    /// M53.
    FeedHold,
}

/// A canonical command and the line that produced it.
#[derive(Debug, Clone, PartialEq)]
pub struct Canon {
    /// Origin in the source.
    pub loc: SourceLoc,
    /// The command.
    pub cmd: CanonCmd,
}
