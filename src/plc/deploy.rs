//! Builds the PLC task of a machine from `[plc]`: compiles the program, resolves the
//! bindings (every bad one reported, naming its key and variable), and derives what the
//! machine task needs to know (which G-code commands wait for the PLC, their timeouts).

use super::bind::{self, OutSignal};
use super::online::{self, PlcOnline};
use super::task::{PlcSetup, PlcStats, PlcTask};
use super::Program;
use super::{compile, Options};
use crate::config::{MachineConfig, PlcConfig};
use crate::machine::devices::IoMap;
use crate::machine::servo::plc_link::PlcLinkSetup;
use crate::rt::prelude::Schedule;
use std::sync::Arc;

/// The PLC task ready to add, with what the machine task and the runtime need.
pub struct PreparedPlc {
    /// The task.
    pub task: PlcTask,
    /// Its thread.
    pub schedule: Schedule,
    /// The machine task's side.
    pub link: PlcLinkSetup,
    /// Scan statistics.
    pub stats: Arc<PlcStats>,
    /// Online access (variables, forces, program loads) for the control methods.
    pub online: Arc<PlcOnline>,
}

/// Prefix of `plc.program` naming a program compiled into the binary.
pub const BUILTIN: &str = "builtin:";

/// Consecutive scan overruns that trip the watchdog.
pub const WATCHDOG_OVERRUNS: u32 = 10;

/// Compiles the program `[plc]` names (a file, or the built-in mill's). Errors say
/// `plc.program: FILE:LINE:COL: what`, one line per error found.
pub fn compile_configured(plc: &PlcConfig) -> Result<Program, String> {
    let opts = Options {
        budget: plc.instruction_budget,
    };
    let name = plc.program.display().to_string();
    let failed = |e: &dyn std::fmt::Display| format!("plc.program {name} does not compile:\n{e}");
    let program = match name.strip_prefix(BUILTIN) {
        Some("plc/mill.st") => compile("config/plc/mill.st", crate::config::BUILTIN_MILL_ST, opts)
            .map_err(|e| failed(&e))?,
        Some(other) => {
            return Err(format!(
                "plc.program: no built-in program {other:?} (there is {BUILTIN}plc/mill.st)"
            ))
        }
        None => super::load_file(&plc.resolve_path(&plc.program), opts).map_err(|e| failed(&e))?,
    };
    Ok(program)
}

/// What `hytask check` verifies of `[plc]` beyond the file's own syntax: the program
/// compiles and every binding names a variable of it and a signal of the machine, with
/// matching types. The daemon refuses to start for the same errors ([`prepare`]).
pub fn check(config: &MachineConfig) -> Result<(), String> {
    let Some(plc) = &config.plc else {
        return Ok(());
    };
    let program = compile_configured(plc)?;
    let map = IoMap::new(config)?;
    bind::resolve(plc, &program, config, &map).map_err(|e| e.to_string())?;
    Ok(())
}

/// Prepares the PLC of `config` (`None` without `[plc]`). `servo_period_s` converts the
/// timeouts to servo cycles. Errors name the file, line and column or the config key.
pub fn prepare(
    config: &MachineConfig,
    map: &IoMap,
    servo_period_s: f64,
) -> Result<Option<PreparedPlc>, String> {
    let Some(plc) = &config.plc else {
        return Ok(None);
    };
    let mut program = compile_configured(plc)?;
    let bindings = bind::resolve(plc, &program, config, map).map_err(|e| e.to_string())?;
    let thread = config
        .thread(&plc.thread)
        .ok_or_else(|| format!("plc.thread: no [[thread]] named {:?}", plc.thread))?;
    let schedule = Schedule {
        priority: i32::from(thread.priority),
        period_ns: u64::from(thread.period_us) * 1000,
        cpu: thread.cpu.map(|c| c as usize),
    };
    let bound = |s: OutSignal| bindings.outputs.iter().any(|(_, o, _)| *o == s);
    let link = PlcLinkSetup {
        handles_m6: bound(OutSignal::M6Done),
        handles_mcodes: bound(OutSignal::McodeDone),
        tool_change_timeout_cycles: (plc.tool_change_timeout_s / servo_period_s).ceil() as u64,
        mcode_timeout_cycles: (plc.mcode_timeout_s / servo_period_s).ceil() as u64,
        safety_relevant: plc.safety_relevant,
        m66_digital: plc.m66_digital.len(),
        m66_analog: plc.m66_analog.len(),
    };
    let axes_mask = config
        .axes
        .iter()
        .fold(0u32, |m, a| m | 1 << (a.name as u32));
    // RETAIN values restored before the first scan; the writer starts with them.
    let retain = match &plc.retain_file {
        Some(f) => Some(
            super::retain::start(&mut program, &plc.resolve_path(f)).map_err(|e| e.to_string())?,
        ),
        None => None,
    };
    let task = PlcTask::new(
        program,
        bindings,
        PlcSetup {
            watchdog_overruns: WATCHDOG_OVERRUNS,
            axes_mask,
        },
    );
    let task = match retain {
        Some(r) => task.with_retain(r),
        None => task,
    };
    let stats = task.stats();
    let (online, rt) = online::channel(
        task.program(),
        task.retain(),
        stats.clone(),
        online::ReloadContext {
            plc: plc.clone(),
            machine: config.clone(),
            map: map.clone(),
        },
    );
    let task = task.with_online(rt);
    Ok(Some(PreparedPlc {
        task,
        schedule,
        link,
        stats,
        online,
    }))
}
