//! A compiled PLC program: code, its memory laid out at load, the variable table, and the
//! scan. Everything a scan touches is allocated here at load, so [`Program::scan`] allocates
//! nothing, takes no lock and cannot panic on program input; a runtime fault is returned as
//! a [`Fault`] with file, line and column, the outputs go to their safe values and the
//! program stays in fault until [`Program::reset_fault`].

use super::ast::Section;
use super::diag::Span;
use super::types::Ty;
use super::value::{format_cell, parse_value, TypeMismatch, Value};
use super::vm::{Code, FaultKind, Op, Vm};
use std::collections::HashMap;
use std::sync::Arc;

/// Index of a variable in the program's variable table.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct VarId(pub u32);

/// Which kind of variable an entry of the variable table is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum VarKind {
    /// `VAR_GLOBAL`
    Global,
    /// A program's `VAR_INPUT`.
    Input,
    /// A program's `VAR_OUTPUT`.
    Output,
    /// A program's `VAR` (or a member of a structure or block inside one).
    Local,
}

/// One elementary variable of the variable table (structures, arrays and block instances
/// are flattened: `Main.axis.pos`, `Main.buf[3]`, `Main.t1.Q`).
#[derive(Debug, Clone, PartialEq)]
pub struct VarInfo {
    /// Full name as declared (`Main.t1.Q`; globals have no prefix).
    pub name: String,
    /// Its type.
    pub ty: Ty,
    /// Its IEC type name (`INT`, `TIME`, an enumeration's name).
    pub type_name: String,
    /// Which kind.
    pub kind: VarKind,
    /// Declared RETAIN (or inside a RETAIN block).
    pub retain: bool,
    /// Declared CONSTANT.
    pub constant: bool,
    /// Memory cell.
    pub addr: u32,
}

/// A runtime fault: what, and where in the source.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{file}:{line}:{col}: PLC fault: {kind}")]
pub struct Fault {
    /// What went wrong.
    pub kind: FaultKind,
    /// The program file.
    pub file: Arc<str>,
    /// Line of the faulting statement.
    pub line: u32,
    /// Column of the faulting expression.
    pub col: u32,
}

/// One declaration of the program's interface, for `hytask plc check`.
#[derive(Debug, Clone, PartialEq)]
pub struct InterfaceEntry {
    /// `PROGRAM Main`, `FUNCTION_BLOCK Pump`, `GLOBAL`.
    pub pou: String,
    /// Section.
    pub section: Section,
    /// Variable name.
    pub name: String,
    /// Type as text.
    pub type_name: String,
    /// RETAIN.
    pub retain: bool,
    /// CONSTANT.
    pub constant: bool,
}

/// An enumeration type, for formatting and parsing values.
#[derive(Debug, Clone, PartialEq)]
pub struct EnumInfo {
    /// Type name.
    pub name: String,
    /// Values in declaration order.
    pub values: Vec<(String, i64)>,
}

/// A compiled program, ready to scan.
#[derive(Debug, Clone)]
pub struct Program {
    pub(crate) file: Arc<str>,
    pub(crate) ops: Code,
    pub(crate) spans: Vec<Span>,
    pub(crate) mem: Vec<u64>,
    pub(crate) init: Vec<u64>,
    pub(crate) stack: Vec<u64>,
    pub(crate) frames: Vec<(u32, u32)>,
    /// (entry, base) of each PROGRAM, run in declaration order every scan.
    pub(crate) programs: Vec<(u32, u32)>,
    pub(crate) vars: Vec<VarInfo>,
    pub(crate) by_name: HashMap<String, VarId>,
    pub(crate) enums: Vec<EnumInfo>,
    pub(crate) interface: Vec<InterfaceEntry>,
    pub(crate) budget: u64,
    inputs: Vec<VarId>,
    outputs: Vec<(VarId, Value)>,
    fault: Option<Fault>,
    last_used: u64,
    /// Forced variables: (cell, value), applied after the input image is copied in and
    /// again after the program ran, so a forced value overrides inputs, online writes and
    /// the program's own assignments. Capacity for every variable is reserved in
    /// [`Program::bind`], so forcing in the scan never allocates.
    forces: Vec<(u32, u64)>,
}

impl Program {
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn new(
        file: Arc<str>,
        ops: Code,
        spans: Vec<Span>,
        init: Vec<u64>,
        stack: usize,
        frames: usize,
        programs: Vec<(u32, u32)>,
        vars: Vec<VarInfo>,
        enums: Vec<EnumInfo>,
        interface: Vec<InterfaceEntry>,
        budget: u64,
    ) -> Self {
        let by_name = vars
            .iter()
            .enumerate()
            .map(|(i, v)| (v.name.to_ascii_uppercase(), VarId(i as u32)))
            .collect();
        Program {
            file,
            ops,
            spans,
            mem: init.clone(),
            init,
            stack: vec![0; stack],
            frames: vec![(0, 0); frames],
            programs,
            vars,
            by_name,
            enums,
            interface,
            budget,
            inputs: Vec::new(),
            outputs: Vec::new(),
            fault: None,
            last_used: 0,
            forces: Vec::new(),
        }
    }

    /// The source file name.
    pub fn file(&self) -> &str {
        &self.file
    }
    /// The variable table.
    pub fn vars(&self) -> &[VarInfo] {
        &self.vars
    }
    /// The declared interface (programs, blocks, functions, globals).
    pub fn interface(&self) -> &[InterfaceEntry] {
        &self.interface
    }
    /// Number of instructions of the compiled code.
    pub fn code_len(&self) -> usize {
        self.ops.len()
    }
    /// The compiled code, for inspection (what the peephole pass made of a program).
    pub fn code(&self) -> &[Op] {
        &self.ops
    }
    /// Memory cells (8 bytes each) laid out for variables.
    pub fn memory_cells(&self) -> usize {
        self.mem.len()
    }
    /// Instructions the last scan executed.
    pub fn last_scan_instructions(&self) -> u64 {
        self.last_used
    }
    /// The per-scan instruction budget.
    pub fn budget(&self) -> u64 {
        self.budget
    }
    /// Sets the per-scan instruction budget.
    pub fn set_budget(&mut self, budget: u64) {
        self.budget = budget;
    }

    /// Looks a variable up by full name, case-insensitively. A program variable may also be
    /// named without its program prefix when only one program declares that name.
    pub fn var(&self, name: &str) -> Option<VarId> {
        let key = name.to_ascii_uppercase();
        if let Some(&id) = self.by_name.get(&key) {
            return Some(id);
        }
        let suffix = format!(".{key}");
        let mut found = self
            .vars
            .iter()
            .enumerate()
            .filter(|(_, v)| {
                let n = v.name.to_ascii_uppercase();
                n.ends_with(&suffix) && !n[..n.len() - suffix.len()].contains(['.', '['])
            })
            .map(|(i, _)| VarId(i as u32));
        let first = found.next()?;
        found.next().is_none().then_some(first)
    }
    /// The entry of a variable.
    pub fn info(&self, id: VarId) -> &VarInfo {
        &self.vars[id.0 as usize]
    }
    /// Current value of a variable.
    pub fn get(&self, id: VarId) -> Value {
        let v = self.info(id);
        Value::from_cell(v.ty, self.mem[v.addr as usize])
    }
    /// Writes a variable (between scans).
    pub fn set(&mut self, id: VarId, value: Value) -> Result<(), TypeMismatch> {
        let v = &self.vars[id.0 as usize];
        match value.to_cell(v.ty) {
            Some(c) => {
                self.mem[v.addr as usize] = c;
                Ok(())
            }
            None => Err(TypeMismatch {
                value: format!("{value:?}"),
                ty: v.type_name.clone(),
            }),
        }
    }
    /// Formats the current value of a variable as an IEC literal.
    pub fn format(&self, id: VarId) -> String {
        let v = self.info(id);
        self.format_cell(v.ty, self.mem[v.addr as usize])
    }
    /// The raw cell of a variable (for change detection).
    pub fn cell(&self, id: VarId) -> u64 {
        self.mem[self.info(id).addr as usize]
    }
    fn format_cell(&self, ty: Ty, c: u64) -> String {
        format_cell(ty, c, |e, v| {
            let info = self.enums.get(e as usize)?;
            info.values
                .iter()
                .find(|(_, x)| *x == v)
                .map(|(n, _)| format!("{}#{n}", info.name))
        })
    }
    /// Parses `text` as a value for variable `id` (enumeration values by name).
    pub fn parse(&self, id: VarId, text: &str) -> Option<Value> {
        let ty = self.info(id).ty;
        parse_value(ty, text, |e, name| {
            let info = self.enums.get(e as usize)?;
            let name = name
                .rsplit_once('#')
                .map(|(_, n)| n)
                .or_else(|| name.rsplit_once('.').map(|(_, n)| n))
                .unwrap_or(name);
            info.values
                .iter()
                .find(|(n, _)| n.eq_ignore_ascii_case(name))
                .map(|(_, v)| *v)
        })
    }

    /// Binds the process image: `inputs` are written into their variables before each scan
    /// (in this order), `outputs` read after it; on a fault the outputs take their safe
    /// values. Allocates here, once, not in the scan.
    pub fn bind(&mut self, inputs: &[VarId], outputs: &[(VarId, Value)]) {
        self.inputs = inputs.to_vec();
        self.outputs = outputs.to_vec();
        self.forces = Vec::with_capacity(self.vars.len());
    }

    /// Forces variable `id` to the raw cell `cell` until [`Program::unforce`]. Never
    /// allocates after [`Program::bind`] (one entry per variable at most).
    pub fn force_cell(&mut self, id: VarId, cell: u64) {
        let Some(addr) = self.vars.get(id.0 as usize).map(|v| v.addr) else {
            return;
        };
        if let Some(f) = self.forces.iter_mut().find(|(a, _)| *a == addr) {
            f.1 = cell;
        } else if self.forces.len() < self.forces.capacity() {
            self.forces.push((addr, cell));
        } else {
            return;
        }
        self.mem[addr as usize] = cell;
    }
    /// Releases the force on `id` (it keeps its forced value until written).
    pub fn unforce(&mut self, id: VarId) {
        if let Some(addr) = self.vars.get(id.0 as usize).map(|v| v.addr) {
            self.forces.retain(|(a, _)| *a != addr);
        }
    }
    /// Releases every force.
    pub fn unforce_all(&mut self) {
        self.forces.clear();
    }
    /// Whether `id` is forced.
    pub fn is_forced(&self, id: VarId) -> bool {
        let addr = self.info(id).addr;
        self.forces.iter().any(|(a, _)| *a == addr)
    }
    /// Number of forced variables.
    pub fn forced_count(&self) -> usize {
        self.forces.len()
    }
    /// Writes a raw cell of variable `id` (an online write, between scans).
    pub fn set_cell(&mut self, id: VarId, cell: u64) {
        if let Some(addr) = self.vars.get(id.0 as usize).map(|v| v.addr) {
            self.mem[addr as usize] = cell;
        }
    }
    /// Copies the cells `keep` names (old address, new address) from `old`: the values a
    /// new program version takes over. Out-of-range pairs are skipped.
    pub fn take_cells(&mut self, old: &Program, keep: &[(u32, u32)]) {
        for &(o, n) in keep {
            if let (Some(v), Some(c)) = (old.mem.get(o as usize), self.mem.get_mut(n as usize)) {
                *c = *v;
            }
        }
    }
    /// Formats a raw cell of variable `id` as an IEC literal.
    pub fn format_value(&self, id: VarId, cell: u64) -> String {
        self.format_cell(self.info(id).ty, cell)
    }

    fn apply_forces(&mut self) {
        for &(a, c) in &self.forces {
            if let Some(m) = self.mem.get_mut(a as usize) {
                *m = c;
            }
        }
    }

    /// The fault the program is in, if any.
    pub fn fault(&self) -> Option<&Fault> {
        self.fault.as_ref()
    }
    /// Leaves the fault state (variables keep their values).
    pub fn reset_fault(&mut self) {
        self.fault = None;
    }
    /// Restores every variable to its initial value.
    pub fn reset_memory(&mut self) {
        self.mem.copy_from_slice(&self.init);
    }

    /// One scan at PLC time `now_ns`: copy `inputs` (as bound) into their variables, run every
    /// PROGRAM once, copy the bound outputs into `outputs`. On a fault (now or in an earlier
    /// scan not yet reset) `outputs` get their safe values and the fault is returned.
    /// Input values that do not fit their variable's type are ignored.
    pub fn scan(
        &mut self,
        inputs: &[Value],
        outputs: &mut [Value],
        now_ns: i64,
    ) -> Result<(), Fault> {
        if self.fault.is_none() {
            for (id, v) in self.inputs.iter().zip(inputs) {
                let info = &self.vars[id.0 as usize];
                if let Some(c) = v.to_cell(info.ty) {
                    self.mem[info.addr as usize] = c;
                }
            }
            self.apply_forces();
            let ran = self.run(now_ns);
            self.apply_forces();
            if let Err((kind, pc)) = ran {
                let span = self.spans.get(pc as usize).copied().unwrap_or_default();
                self.fault = Some(Fault {
                    kind,
                    file: self.file.clone(),
                    line: span.line,
                    col: span.col,
                });
            }
        }
        match &self.fault {
            None => {
                for ((id, _), out) in self.outputs.iter().zip(outputs.iter_mut()) {
                    let info = &self.vars[id.0 as usize];
                    *out = Value::from_cell(info.ty, self.mem[info.addr as usize]);
                }
                Ok(())
            }
            Some(f) => {
                for ((_, safe), out) in self.outputs.iter().zip(outputs.iter_mut()) {
                    *out = *safe;
                }
                Err(f.clone())
            }
        }
    }

    fn run(&mut self, now: i64) -> Result<(), (FaultKind, u32)> {
        let mut vm = Vm {
            ops: &self.ops,
            mem: &mut self.mem,
            stack: &mut self.stack,
            frames: &mut self.frames,
            now,
            fuel: self.budget,
        };
        let mut result = Ok(());
        for &(entry, base) in &self.programs {
            result = vm.run(entry, base);
            if result.is_err() {
                break;
            }
        }
        self.last_used = self.budget - vm.fuel;
        result
    }
}
