//! Online access to the running PLC (issue 11, section 2): read every variable, write one,
//! force and unforce, and load a new program version that takes over at a scan boundary.
//!
//! The scan never waits for the operator and never allocates for them:
//! - writes and forces travel to the scan through a lock-free queue ([`OnlineOp`]) and are
//!   applied at the start of the next scan;
//! - reads are answered by the scan copying the variables into shared atomics when asked
//!   (a request counter), under a sequence counter, so the reader gets one scan's values;
//! - a new program version, compiled and bound here off the realtime thread, is moved to the
//!   scan in a box through a one-slot queue; the scan swaps it in between two scans, copies
//!   the values it keeps, and hands the old version back through another queue, so it is
//!   dropped here, never on the realtime thread.
//!
//! Every operation names its program version (`generation`): one meant for a version that
//! was replaced meanwhile is ignored by the scan rather than applied to the wrong variable.

use super::bind::{self, Bindings};
use super::retain::{self, Retain};
use super::task::PlcStats;
use super::{compile, Options, Program, VarId};
use crate::config::{MachineConfig, PlcConfig};
use crate::machine::devices::IoMap;
use crate::rt::buffer::{buffer, BufferReader, BufferWriter, FullPolicy};
use serde::Serialize;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};

/// Queued writes and forces the scan takes at once (more are refused as busy).
const OP_QUEUE: usize = 64;

/// How long an operator's call waits for the scan to act on it.
const SCAN_WAIT: Duration = Duration::from_secs(5);

/// What the operator asks of the scan (applied at the start of the next scan).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum OnlineOp {
    /// Write a raw cell of a variable once.
    Write {
        /// Program version.
        generation: u64,
        /// Variable.
        var: VarId,
        /// Raw cell.
        cell: u64,
    },
    /// Force a variable to a raw cell, every scan until unforced.
    Force {
        /// Program version.
        generation: u64,
        /// Variable.
        var: VarId,
        /// Raw cell.
        cell: u64,
    },
    /// Release the force on a variable (`None`: on every variable).
    Unforce {
        /// Program version.
        generation: u64,
        /// Variable.
        var: Option<VarId>,
    },
}

/// One scan's copy of every variable, per program version (variable-table order).
#[derive(Debug)]
struct View {
    seq: AtomicU64,
    cells: Vec<AtomicU64>,
    forced: Vec<AtomicBool>,
    /// The read request this copy answers.
    served: AtomicU64,
}

impl View {
    fn new(program: &Program) -> Arc<View> {
        let n = program.vars().len();
        Arc::new(View {
            seq: AtomicU64::new(0),
            cells: (0..n).map(|_| AtomicU64::new(0)).collect(),
            forced: (0..n).map(|_| AtomicBool::new(false)).collect(),
            served: AtomicU64::new(0),
        })
    }

    /// Realtime: stores only.
    fn publish(&self, program: &Program, request: u64) {
        self.seq.fetch_add(1, Ordering::AcqRel);
        for (i, (c, f)) in self.cells.iter().zip(&self.forced).enumerate() {
            let id = VarId(i as u32);
            c.store(program.cell(id), Ordering::Relaxed);
            f.store(program.is_forced(id), Ordering::Relaxed);
        }
        self.seq.fetch_add(1, Ordering::AcqRel);
        self.served.store(request, Ordering::Release);
    }

    fn read(&self) -> Vec<(u64, bool)> {
        loop {
            let s0 = self.seq.load(Ordering::Acquire);
            let v: Vec<(u64, bool)> = self
                .cells
                .iter()
                .zip(&self.forced)
                .map(|(c, f)| (c.load(Ordering::Relaxed), f.load(Ordering::Relaxed)))
                .collect();
            if s0.is_multiple_of(2) && self.seq.load(Ordering::Acquire) == s0 {
                return v;
            }
            std::thread::yield_now();
        }
    }
}

/// A program version on its way into the scan (and, swapped, the old one on its way out).
pub struct Swap {
    generation: u64,
    program: Program,
    bindings: Bindings,
    /// (old cell, new cell) of every variable whose name and type are unchanged.
    keep: Vec<(u32, u32)>,
    view: Arc<View>,
    retain: Option<Retain>,
}

/// Counters shared by both sides.
#[derive(Debug, Default)]
struct Shared {
    /// Read requests made.
    want: AtomicU64,
    /// The version the scan runs.
    active: AtomicU64,
}

/// The scan's side, owned by the PLC task.
pub struct OnlineRt {
    ops: BufferReader<OnlineOp>,
    loads: BufferReader<Box<Swap>>,
    retired: BufferWriter<Box<Swap>>,
    /// An old version the return queue had no room for yet (kept, never dropped here).
    retiring: Option<Box<Swap>>,
    shared: Arc<Shared>,
    view: Arc<View>,
    generation: u64,
    served: u64,
}

/// What the scan's owner exchanges with a swap: its program, bindings and RETAIN writer.
pub struct Running<'a> {
    /// The program.
    pub program: &'a mut Program,
    /// Its bindings.
    pub bindings: &'a mut Bindings,
    /// Its RETAIN writer.
    pub retain: &'a mut Option<Retain>,
}

impl OnlineRt {
    /// At a scan boundary, before the input image: takes a new program version if one
    /// waits (and the previous old one has left), then applies queued writes and forces.
    /// Returns true when the program was swapped. Never allocates, never blocks.
    pub fn before_scan(&mut self, run: Running<'_>) -> bool {
        if let Some(old) = self.retiring.take() {
            if let Err(back) = self.retired.try_push(old) {
                self.retiring = Some(back);
            }
        }
        let mut swapped = false;
        if self.retiring.is_none() {
            if let Some(mut s) = self.loads.pop() {
                std::mem::swap(run.program, &mut s.program);
                std::mem::swap(run.bindings, &mut s.bindings);
                std::mem::swap(run.retain, &mut s.retain);
                std::mem::swap(&mut self.view, &mut s.view);
                run.program.take_cells(&s.program, &s.keep);
                self.generation = s.generation;
                self.shared.active.store(s.generation, Ordering::Release);
                if let Err(back) = self.retired.try_push(s) {
                    self.retiring = Some(back);
                }
                swapped = true;
            }
        }
        let generation = self.generation;
        let program = run.program;
        self.ops.drain(|op| match op {
            OnlineOp::Write {
                generation: g,
                var,
                cell,
            } if g == generation => program.set_cell(var, cell),
            OnlineOp::Force {
                generation: g,
                var,
                cell,
            } if g == generation => program.force_cell(var, cell),
            OnlineOp::Unforce { generation: g, var } if g == generation => match var {
                Some(v) => program.unforce(v),
                None => program.unforce_all(),
            },
            _ => {}
        });
        swapped
    }

    /// After the scan: answers a pending read request with this scan's values.
    pub fn after_scan(&mut self, program: &Program) {
        let want = self.shared.want.load(Ordering::Acquire);
        if want != self.served {
            self.served = want;
            self.view.publish(program, want);
        }
    }
}

/// Online access refused or failed.
#[derive(Debug, thiserror::Error)]
pub enum OnlineError {
    /// No such variable.
    #[error("no PLC variable {0:?}")]
    UnknownVar(String),
    /// A value that does not parse or fit.
    #[error("{value:?} is not a value of {name} ({ty})")]
    BadValue {
        /// Variable.
        name: String,
        /// What was given.
        value: String,
        /// Its type.
        ty: String,
    },
    /// A CONSTANT cannot be written or forced.
    #[error("{0} is a CONSTANT")]
    Constant(String),
    /// The new version does not compile (every error, file:line:col); the old one runs on.
    #[error("{0}\nthe running program is unchanged")]
    Compile(String),
    /// The new version's interface does not fit the machine's bindings.
    #[error("the new program's interface does not fit the bindings: {0}; the running program is unchanged")]
    Interface(String),
    /// The scan did not answer in time.
    #[error("the PLC task did not {0} within {1:?} (is it scanning?)")]
    Timeout(&'static str, Duration),
    /// Too many operations queued.
    #[error("the PLC task is busy ({0} queued); try again")]
    Busy(&'static str),
}

/// One variable as `plc.vars` shows it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct VarValue {
    /// Full name.
    pub name: String,
    /// IEC type name.
    pub r#type: String,
    /// Value as an IEC literal.
    pub value: String,
    /// Forced.
    pub forced: bool,
    /// RETAIN.
    pub retain: bool,
}

/// What a program load kept and reset.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LoadReport {
    /// The new version's number (the configured program is 1).
    pub generation: u64,
    /// Variables whose name and type are unchanged: their values were kept.
    pub kept: Vec<String>,
    /// New variables, or ones whose type changed: initialised.
    pub reset: Vec<String>,
    /// Variables of the old version the new one does not have.
    pub removed: Vec<String>,
    /// Forces released by the load.
    pub unforced: usize,
}

/// What a reload needs to compile and bind a new version as the machine did at start.
pub struct ReloadContext {
    /// `[plc]`.
    pub plc: PlcConfig,
    /// The machine (for signal names).
    pub machine: MachineConfig,
    /// Its channel numbering.
    pub map: IoMap,
}

struct Current {
    generation: u64,
    /// A copy of the running version, for its variable table and value formats.
    program: Program,
    view: Arc<View>,
    retain: Option<Arc<retain::RetainShared>>,
}

/// The operator's side: the control methods call it.
pub struct PlcOnline {
    ops: BufferWriter<OnlineOp>,
    loads: BufferWriter<Box<Swap>>,
    retired: Mutex<BufferReader<Box<Swap>>>,
    shared: Arc<Shared>,
    current: Mutex<Current>,
    stats: Arc<PlcStats>,
    reload: ReloadContext,
}

/// Polls `done` until it holds, or fails after [`SCAN_WAIT`] naming `what` the scan did not do.
fn wait_until(what: &'static str, done: impl Fn() -> bool) -> Result<(), OnlineError> {
    let t0 = Instant::now();
    while !done() {
        if t0.elapsed() > SCAN_WAIT {
            return Err(OnlineError::Timeout(what, SCAN_WAIT));
        }
        std::thread::sleep(Duration::from_micros(500));
    }
    Ok(())
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|p| p.into_inner())
}

/// Creates both sides for `program` (the configured version, generation 1).
pub fn channel(
    program: &Program,
    retain: Option<&Retain>,
    stats: Arc<PlcStats>,
    reload: ReloadContext,
) -> (Arc<PlcOnline>, OnlineRt) {
    let (ops_w, ops_r) = buffer(OP_QUEUE, FullPolicy::DropNewest);
    let (loads_w, loads_r) = buffer(1, FullPolicy::DropNewest);
    let (ret_w, ret_r) = buffer(2, FullPolicy::DropNewest);
    let shared = Arc::new(Shared {
        want: AtomicU64::new(0),
        active: AtomicU64::new(1),
    });
    let view = View::new(program);
    let online = PlcOnline {
        ops: ops_w,
        loads: loads_w,
        retired: Mutex::new(ret_r),
        shared: shared.clone(),
        current: Mutex::new(Current {
            generation: 1,
            program: program.clone(),
            view: view.clone(),
            retain: retain.map(|r| r.shared.clone()),
        }),
        stats,
        reload,
    };
    let rt = OnlineRt {
        ops: ops_r,
        loads: loads_r,
        retired: ret_w,
        retiring: None,
        shared,
        view,
        generation: 1,
        served: 0,
    };
    (Arc::new(online), rt)
}

impl PlcOnline {
    /// The scan statistics.
    pub fn stats(&self) -> &Arc<PlcStats> {
        &self.stats
    }

    /// Every variable with its type, value (one scan's) and forced state; `filter` keeps the
    /// names containing it (case-insensitive).
    pub fn vars(&self, filter: Option<&str>) -> Result<Vec<VarValue>, OnlineError> {
        let cur = lock(&self.current);
        let want = self.shared.want.fetch_add(1, Ordering::AcqRel) + 1;
        wait_until("answer a read", || {
            cur.view.served.load(Ordering::Acquire) >= want
        })?;
        let cells = cur.view.read();
        let filter = filter.map(str::to_ascii_uppercase);
        Ok(cur
            .program
            .vars()
            .iter()
            .zip(cells)
            .enumerate()
            .filter(|(_, (v, _))| {
                filter
                    .as_deref()
                    .is_none_or(|f| v.name.to_ascii_uppercase().contains(f))
            })
            .map(|(i, (v, (cell, forced)))| VarValue {
                name: v.name.clone(),
                r#type: v.type_name.clone(),
                value: cur.program.format_value(VarId(i as u32), cell),
                forced,
                retain: v.retain,
            })
            .collect())
    }

    /// One variable by name (full, or without its program prefix).
    pub fn get(&self, name: &str) -> Result<VarValue, OnlineError> {
        let full = {
            let cur = lock(&self.current);
            let id = cur
                .program
                .var(name)
                .ok_or_else(|| OnlineError::UnknownVar(name.into()))?;
            cur.program.info(id).name.clone()
        };
        self.vars(Some(&full))?
            .into_iter()
            .find(|v| v.name == full)
            .ok_or(OnlineError::UnknownVar(full))
    }

    /// Resolves `name` and parses `value` for it: (version, variable, cell).
    fn target(&self, name: &str, value: Option<&str>) -> Result<(u64, VarId, u64), OnlineError> {
        let cur = lock(&self.current);
        let p = &cur.program;
        let id = p
            .var(name)
            .ok_or_else(|| OnlineError::UnknownVar(name.into()))?;
        let info = p.info(id);
        if info.constant {
            return Err(OnlineError::Constant(info.name.clone()));
        }
        let cell = match value {
            None => 0,
            Some(text) => p
                .parse(id, text)
                .and_then(|v| v.to_cell(info.ty))
                .ok_or_else(|| OnlineError::BadValue {
                    name: info.name.clone(),
                    value: text.into(),
                    ty: info.type_name.clone(),
                })?,
        };
        Ok((cur.generation, id, cell))
    }

    /// Queues `op` and waits until a scan started after it was queued has finished.
    fn send(&self, op: OnlineOp) -> Result<(), OnlineError> {
        let before = self.stats.scans.load(Ordering::Acquire);
        self.ops
            .try_push(op)
            .map_err(|_| OnlineError::Busy("writes"))?;
        self.wait_scans(before + 2, "apply the write")
    }

    fn wait_scans(&self, target: u64, what: &'static str) -> Result<(), OnlineError> {
        wait_until(what, || self.stats.scans.load(Ordering::Acquire) >= target)
    }

    /// Writes `value` (an IEC literal) to `name` once, at the start of the next scan; the
    /// program (or the input image, or a force) may change it afterwards.
    pub fn set(&self, name: &str, value: &str) -> Result<VarValue, OnlineError> {
        let (generation, var, cell) = self.target(name, Some(value))?;
        self.send(OnlineOp::Write {
            generation,
            var,
            cell,
        })?;
        self.get(name)
    }

    /// Forces `name` to `value` every scan until [`PlcOnline::unforce`].
    pub fn force(&self, name: &str, value: &str) -> Result<VarValue, OnlineError> {
        let (generation, var, cell) = self.target(name, Some(value))?;
        self.send(OnlineOp::Force {
            generation,
            var,
            cell,
        })?;
        self.get(name)
    }

    /// Releases the force on `name` (`None`: every force).
    pub fn unforce(&self, name: Option<&str>) -> Result<(), OnlineError> {
        let (generation, var) = match name {
            Some(n) => {
                let (g, v, _) = self.target(n, None)?;
                (g, Some(v))
            }
            None => (lock(&self.current).generation, None),
        };
        self.send(OnlineOp::Unforce { generation, var })
    }

    /// Compiles `source` (named `file` in errors), binds it as the configured program was,
    /// and swaps it in at a scan boundary. Variables whose name and type are unchanged keep
    /// their values (RETAIN or not); the others start at their initial values; forces are
    /// released. On any error the running program is untouched.
    pub fn load(&self, file: &str, source: &str) -> Result<LoadReport, OnlineError> {
        let mut cur = lock(&self.current);
        self.collect_retired();
        let opts = Options {
            budget: self.reload.plc.instruction_budget,
        };
        let mut program =
            compile(file, source, opts).map_err(|e| OnlineError::Compile(e.to_string()))?;
        let r = &self.reload;
        let bindings = bind::resolve(&r.plc, &program, &r.machine, &r.map)
            .map_err(|e| OnlineError::Interface(e.to_string()))?;
        super::task::bind_program(&mut program, &bindings);
        let old = &cur.program;
        let mut report = LoadReport {
            generation: cur.generation + 1,
            kept: Vec::new(),
            reset: Vec::new(),
            removed: Vec::new(),
            unforced: 0,
        };
        let mut keep = Vec::new();
        for v in program.vars() {
            match old.var(&v.name).map(|id| old.info(id)) {
                Some(o) if o.name.eq_ignore_ascii_case(&v.name) && o.type_name == v.type_name => {
                    keep.push((o.addr, v.addr));
                    report.kept.push(v.name.clone());
                }
                _ => report.reset.push(v.name.clone()),
            }
        }
        for v in old.vars() {
            if program
                .var(&v.name)
                .is_none_or(|id| !program.info(id).name.eq_ignore_ascii_case(&v.name))
            {
                report.removed.push(v.name.clone());
            }
        }
        if bindings.inputs.len() != r.plc.inputs.len()
            || bindings.outputs.len() != r.plc.outputs.len()
        {
            return Err(OnlineError::Interface("not every binding resolved".into()));
        }
        let retain = self
            .reload
            .plc
            .retain_file
            .as_ref()
            .map(|f| retain::follow(&program, &self.reload.plc.resolve_path(f)));
        let retain_shared = retain.as_ref().map(|r| r.shared.clone());
        let view = View::new(&program);
        let meta = program.clone();
        let swap = Box::new(Swap {
            generation: report.generation,
            program,
            bindings,
            keep,
            view: view.clone(),
            retain,
        });
        let forced_before = self.stats.forced.load(Ordering::Acquire);
        if self.loads.try_push(swap).is_err() {
            return Err(OnlineError::Busy("program versions"));
        }
        // From here on the new version is the one operators address: once queued it takes
        // over at the next scan (on a timeout, when the PLC scans again).
        let old = std::mem::replace(
            &mut *cur,
            Current {
                generation: report.generation,
                program: meta,
                view,
                retain: retain_shared,
            },
        );
        wait_until("take the new program", || {
            self.shared.active.load(Ordering::Acquire) == report.generation
        })?;
        if let Some(r) = &old.retain {
            r.retire();
        }
        report.unforced = forced_before as usize;
        self.collect_retired();
        Ok(report)
    }

    /// Drops the old versions the scan handed back (here, off the realtime thread).
    fn collect_retired(&self) {
        lock(&self.retired).drain(drop);
    }
}
