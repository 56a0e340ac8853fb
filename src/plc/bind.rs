//! Bindings of PLC variables to machine signals (`[plc] inputs/outputs`), resolved against
//! the compiled program and the machine's I/O numbering when the machine is deployed. Every
//! bad binding is reported, each naming its key and its variable.

use super::{Program, Ty, Value, VarId, VarKind};
use crate::config::{IoKind, MachineConfig, PlcConfig};
use crate::machine::devices::IoMap;

/// A signal the PLC reads.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum InSignal {
    /// Digital input (machine-wide index).
    DigitalInput(usize),
    /// Analog input.
    AnalogInput(usize),
    /// A digital output as the machine (G-code) asks for it: `request.<name>`.
    RequestedDigital(usize),
    /// An analog output as the machine asks for it.
    RequestedAnalog(usize),
    /// Mode is e-stop.
    Estop,
    /// Mode is neither e-stop nor off.
    On,
    /// Mode as a number (0 estop, 1 off, 2 idle, 3 homing, 4 manual, 5 running, 6 holding,
    /// 7 fault).
    Mode,
    /// Every axis homed.
    Homed,
    /// Axis `i` homed.
    AxisHomed(u32),
    /// No motion commanded, or settled.
    InPosition,
    /// Mode is fault.
    Fault,
    /// True for one scan after each accepted `estop.reset`.
    EstopReset,
    /// A job runs (running or holding).
    JobRunning,
    /// The job holds (feed hold or M0).
    FeedHold,
    /// An M6 waits for the PLC.
    M6Request,
    /// Its tool.
    M6Tool,
    /// An M100–M199 waits for the PLC.
    McodeRequest,
    /// Its number.
    McodeNumber,
    /// Its P word.
    McodeP,
    /// Its Q word.
    McodeQ,
}

/// A signal the PLC writes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum OutSignal {
    /// Digital output (machine-wide index).
    DigitalOutput(usize),
    /// Analog output.
    AnalogOutput(usize),
    /// Finishes the pending M6.
    M6Done,
    /// Finishes the pending M100–M199.
    McodeDone,
    /// Holds feed while true.
    FeedHold,
    /// Refuses cycle start while true.
    StartInhibit,
    /// E-stop when it rises.
    Estop,
    /// What M66 P`i` waits on (`plc.m66_digital[i]`).
    M66Digital(usize),
    /// What M66 E`i` samples (`plc.m66_analog[i]`).
    M66Analog(usize),
}

/// What a signal carries, for the type check.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Carrier {
    Bool,
    Int,
    Real,
}

impl Carrier {
    fn accepts(self, ty: Ty) -> bool {
        match self {
            Carrier::Bool => ty == Ty::Bool,
            Carrier::Int => matches!(ty, Ty::Int(_)),
            Carrier::Real => matches!(ty, Ty::Real | Ty::LReal),
        }
    }
    fn name(self) -> &'static str {
        match self {
            Carrier::Bool => "BOOL",
            Carrier::Int => "an integer type",
            Carrier::Real => "REAL or LREAL",
        }
    }
}

/// Resolved bindings: in the order they are copied.
#[derive(Debug, Clone, Default)]
pub struct Bindings {
    /// Inputs, copied into the program before each scan.
    pub inputs: Vec<(VarId, InSignal)>,
    /// Outputs, taken after each scan, with the value they take when the PLC is in fault.
    pub outputs: Vec<(VarId, OutSignal, Value)>,
}

/// Every problem found, one line each (`plc.inputs.X: ...`).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{}", .0.join("; "))]
pub struct BindError(pub Vec<String>);

fn in_signal(name: &str, map: &IoMap, cfg: &MachineConfig) -> Option<(InSignal, Carrier)> {
    use Carrier::*;
    use InSignal as S;
    let fixed = match name {
        "machine.estop" => Some((S::Estop, Bool)),
        "machine.on" => Some((S::On, Bool)),
        "machine.mode" => Some((S::Mode, Int)),
        "machine.homed" => Some((S::Homed, Bool)),
        "machine.in_position" => Some((S::InPosition, Bool)),
        "machine.fault" => Some((S::Fault, Bool)),
        "machine.estop_reset" => Some((S::EstopReset, Bool)),
        "job.running" => Some((S::JobRunning, Bool)),
        "job.feed_hold" => Some((S::FeedHold, Bool)),
        "m6.request" => Some((S::M6Request, Bool)),
        "m6.tool" => Some((S::M6Tool, Int)),
        "mcode.request" => Some((S::McodeRequest, Bool)),
        "mcode.number" => Some((S::McodeNumber, Int)),
        "mcode.p" => Some((S::McodeP, Real)),
        "mcode.q" => Some((S::McodeQ, Real)),
        _ => None,
    };
    if fixed.is_some() {
        return fixed;
    }
    if let Some(axis) = name
        .strip_prefix("axis.")
        .and_then(|r| r.strip_suffix(".homed"))
    {
        let a = cfg
            .axes
            .iter()
            .find(|a| a.name.to_string().eq_ignore_ascii_case(axis))?;
        return Some((S::AxisHomed(a.name as u32), Bool));
    }
    if let Some(out) = name.strip_prefix("request.") {
        if let Some(i) = map.index(IoKind::DigitalOutput, out) {
            return Some((S::RequestedDigital(i), Bool));
        }
        return map
            .index(IoKind::AnalogOutput, out)
            .map(|i| (S::RequestedAnalog(i), Real));
    }
    if let Some(i) = map.index(IoKind::DigitalInput, name) {
        return Some((S::DigitalInput(i), Bool));
    }
    map.index(IoKind::AnalogInput, name)
        .map(|i| (S::AnalogInput(i), Real))
}

fn out_signal(name: &str, map: &IoMap) -> Option<(OutSignal, Carrier)> {
    use Carrier::*;
    use OutSignal as S;
    match name {
        "m6.done" => return Some((S::M6Done, Bool)),
        "mcode.done" => return Some((S::McodeDone, Bool)),
        "machine.feed_hold" => return Some((S::FeedHold, Bool)),
        "machine.start_inhibit" => return Some((S::StartInhibit, Bool)),
        "machine.estop" => return Some((S::Estop, Bool)),
        _ => {}
    }
    if let Some(i) = map.index(IoKind::DigitalOutput, name) {
        return Some((S::DigitalOutput(i), Bool));
    }
    map.index(IoKind::AnalogOutput, name)
        .map(|i| (S::AnalogOutput(i), Real))
}

/// Outputs the machine task drives itself: a PLC output on one of them would have two
/// owners.
fn machine_owned(cfg: &MachineConfig) -> Vec<(&'static str, &str)> {
    let mut v = Vec::new();
    if let Some(s) = &cfg.spindle {
        v.push(("spindle.enable_output", s.enable_output.as_str()));
        v.extend(
            s.direction_output
                .as_deref()
                .map(|n| ("spindle.direction_output", n)),
        );
        v.extend(
            s.speed_output
                .as_deref()
                .map(|n| ("spindle.speed_output", n)),
        );
    }
    v.extend(
        cfg.coolant
            .flood_output
            .as_deref()
            .map(|n| ("coolant.flood_output", n)),
    );
    v.extend(
        cfg.coolant
            .mist_output
            .as_deref()
            .map(|n| ("coolant.mist_output", n)),
    );
    v
}

fn lookup(
    program: &Program,
    key: &str,
    var: &str,
    dir: VarKind,
    errors: &mut Vec<String>,
) -> Option<VarId> {
    let Some(id) = program.var(var) else {
        errors.push(format!(
            "{key}: the program has no variable {var:?} (or more than one program declares it)"
        ));
        return None;
    };
    let info = program.info(id);
    let ok = matches!(info.kind, VarKind::Global) || info.kind == dir;
    if !ok {
        let want = if dir == VarKind::Input {
            "VAR_INPUT"
        } else {
            "VAR_OUTPUT"
        };
        errors.push(format!(
            "{key}: {} is not a VAR_GLOBAL or a program's {want}",
            info.name
        ));
        return None;
    }
    if info.constant {
        errors.push(format!("{key}: {} is CONSTANT", info.name));
        return None;
    }
    Some(id)
}

/// Resolves `plc`'s bindings against `program` and the machine.
pub fn resolve(
    plc: &PlcConfig,
    program: &Program,
    cfg: &MachineConfig,
    map: &IoMap,
) -> Result<Bindings, BindError> {
    let mut errors = Vec::new();
    let mut b = Bindings::default();
    let type_check = |key: &str, id: VarId, c: Carrier, sig: &str, errors: &mut Vec<String>| {
        let info = program.info(id);
        let ok = c.accepts(info.ty);
        if !ok {
            errors.push(format!(
                "{key}: {} is {} but signal {sig:?} needs {}",
                info.name,
                info.type_name,
                c.name()
            ));
        }
        ok
    };
    for (var, sig) in &plc.inputs {
        let key = format!("plc.inputs.{var}");
        let id = lookup(program, &key, var, VarKind::Input, &mut errors);
        let Some((s, c)) = in_signal(sig, map, cfg) else {
            errors.push(format!("{key}: unknown signal {sig:?}"));
            continue;
        };
        if let Some(id) = id {
            if type_check(&key, id, c, sig, &mut errors) {
                b.inputs.push((id, s));
            }
        }
    }
    let owned = machine_owned(cfg);
    let mut written: Vec<(VarId, &str)> = Vec::new();
    for (var, sig) in &plc.outputs {
        let key = format!("plc.outputs.{var}");
        let id = lookup(program, &key, var, VarKind::Output, &mut errors);
        let Some((s, c)) = out_signal(sig, map) else {
            errors.push(format!("{key}: unknown signal {sig:?}"));
            continue;
        };
        if let Some((k, _)) = owned.iter().find(|(_, n)| *n == sig) {
            errors.push(format!(
                "{key}: output {sig:?} is written by two owners (the machine drives it as {k})"
            ));
            continue;
        }
        let Some(id) = id else { continue };
        if let Some((_, other)) = written.iter().find(|(w, _)| *w == id) {
            errors.push(format!(
                "{key}: {} is already bound to {other:?}",
                program.info(id).name
            ));
        }
        if !type_check(&key, id, c, sig, &mut errors) {
            continue;
        }
        written.push((id, sig));
        let safe = match s {
            OutSignal::DigitalOutput(i) => Value::Bool(map.dout[i].point.safe_state()),
            OutSignal::AnalogOutput(i) => Value::Real(map.ao[i].point.safe_value()),
            // A faulted PLC finishes nothing, holds feed and refuses starts.
            OutSignal::FeedHold | OutSignal::StartInhibit => Value::Bool(true),
            OutSignal::M6Done | OutSignal::McodeDone | OutSignal::Estop => Value::Bool(false),
            OutSignal::M66Digital(_) => Value::Bool(false),
            OutSignal::M66Analog(_) => Value::Real(0.0),
        };
        b.outputs.push((id, s, safe));
    }
    // M66 waits read these variables; a faulted PLC reads as FALSE / 0.
    let m66 = plc
        .m66_digital
        .iter()
        .enumerate()
        .map(|(i, v)| ("m66_digital", i, v, Carrier::Bool))
        .chain(
            plc.m66_analog
                .iter()
                .enumerate()
                .map(|(i, v)| ("m66_analog", i, v, Carrier::Real)),
        );
    for (table, i, var, c) in m66 {
        let key = format!("plc.{table}[{i}]");
        let Some(id) = lookup(program, &key, var, VarKind::Output, &mut errors) else {
            continue;
        };
        if !type_check(&key, id, c, var, &mut errors) {
            continue;
        }
        let (s, safe) = match c {
            Carrier::Bool => (OutSignal::M66Digital(i), Value::Bool(false)),
            _ => (OutSignal::M66Analog(i), Value::Real(0.0)),
        };
        b.outputs.push((id, s, safe));
    }
    if errors.is_empty() {
        Ok(b)
    } else {
        Err(BindError(errors))
    }
}
