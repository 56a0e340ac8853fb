//! `hytask plc`: PLC program tools that need no machine. `check` compiles a Structured Text
//! file and prints its errors (file:line:col, all of them) or its interface; `run` scans it
//! offline in simulated time and prints the variables that changed, per scan: how a machine
//! builder tests logic at a desk. `vars`, `get`, `set`, `force`, `unforce` and `load` talk
//! to the running daemon ([`online`]).

mod online;

use crate::plc::{self, ast::Section, Options, Program, VarId};
use anyhow::{bail, Context as _};
use std::io::Write as _;
use std::path::PathBuf;
use std::process::ExitCode;

/// Arguments of `hytask plc`.
#[derive(Debug, clap::Args)]
pub struct PlcArgs {
    /// What to do.
    #[command(subcommand)]
    pub command: PlcCommand,
}

/// The `plc` subcommands.
#[derive(Debug, clap::Subcommand)]
pub enum PlcCommand {
    /// Compile a program; print every error, or its interface.
    Check {
        /// The Structured Text file.
        file: PathBuf,
    },
    /// Run a program offline in simulated time and print what changed per scan.
    Run(RunArgs),
    #[command(flatten)]
    Online(online::OnlineCommand),
}

/// Arguments of `hytask plc run`.
#[derive(Debug, clap::Args)]
pub struct RunArgs {
    /// The Structured Text file.
    pub file: PathBuf,
    /// Scan period in simulated time (`10ms`, `T#1s`, `500us`).
    #[arg(long, default_value = "10ms")]
    pub period: String,
    /// Number of scans.
    #[arg(long)]
    pub scans: u64,
    /// Set a variable before a scan: `VAR=VALUE@SCAN` (scans count from 1; without `@SCAN`,
    /// before the first). Repeatable.
    #[arg(long = "set", value_name = "VAR=VALUE@SCAN")]
    pub set: Vec<String>,
    /// Print only these variables (full name, or without the program prefix; a block
    /// instance or structure name covers its members). Repeatable; default: all.
    #[arg(long, value_name = "VAR")]
    pub watch: Vec<String>,
    /// Print one JSON document instead of `scan N: VAR=VALUE` lines.
    #[arg(long)]
    pub json: bool,
    /// Instructions one scan may execute before it faults.
    #[arg(long, default_value_t = Options::default().budget)]
    pub budget: u64,
}

/// Runs the subcommand.
pub fn run(args: PlcArgs) -> anyhow::Result<ExitCode> {
    match args.command {
        PlcCommand::Check { file } => check(&file),
        PlcCommand::Run(a) => run_offline(&a),
        PlcCommand::Online(c) => online::run(c),
    }
}

fn load(file: &std::path::Path, opts: Options) -> anyhow::Result<Result<Program, plc::Diags>> {
    match plc::load_file(file, opts) {
        Ok(p) => Ok(Ok(p)),
        Err(plc::LoadError::Compile(d)) => Ok(Err(d)),
        Err(e) => Err(e.into()),
    }
}

fn report(d: &plc::Diags) -> ExitCode {
    eprintln!("{d}");
    eprintln!("{}: {} error(s)", d.file, d.list.len());
    ExitCode::FAILURE
}

fn section_name(s: Section) -> &'static str {
    match s {
        Section::Var => "VAR",
        Section::Input => "VAR_INPUT",
        Section::Output => "VAR_OUTPUT",
        Section::InOut => "VAR_IN_OUT",
        Section::Global => "VAR_GLOBAL",
        Section::Temp => "VAR_TEMP",
        Section::External => "VAR_EXTERNAL",
    }
}

fn check(file: &std::path::Path) -> anyhow::Result<ExitCode> {
    let prog = match load(file, Options::default())? {
        Ok(p) => p,
        Err(d) => return Ok(report(&d)),
    };
    let mut out = std::io::stdout().lock();
    writeln!(out, "{}: OK", prog.file())?;
    let mut pou = "";
    for e in prog.interface() {
        if e.pou != pou {
            pou = &e.pou;
            writeln!(out, "{pou}")?;
        }
        let mut flags = String::new();
        if e.retain {
            flags.push_str(" RETAIN");
        }
        if e.constant {
            flags.push_str(" CONSTANT");
        }
        writeln!(
            out,
            "  {}{flags} {} : {}",
            section_name(e.section),
            e.name,
            e.type_name
        )?;
    }
    writeln!(
        out,
        "{} instructions, {} memory cells, {} variables",
        prog.code_len(),
        prog.memory_cells(),
        prog.vars().len()
    )?;
    Ok(ExitCode::SUCCESS)
}

/// Parses a period: `10ms`, `T#10ms`, `1.5s`, `250us`.
fn parse_period(s: &str) -> anyhow::Result<i64> {
    let low = s.trim().to_ascii_lowercase();
    let body = low
        .strip_prefix("t#")
        .or_else(|| low.strip_prefix("time#"))
        .unwrap_or(&low);
    match plc::lexer::parse_duration(&body.replace('_', "")) {
        Some(ns) if ns > 0 => Ok(ns),
        _ => bail!("--period must be a positive duration like 10ms or T#1s, not {s:?}"),
    }
}

struct SetOp {
    scan: u64,
    var: VarId,
    value: plc::Value,
}

fn parse_set(prog: &Program, s: &str) -> anyhow::Result<SetOp> {
    let (assign, scan) = match s.rsplit_once('@') {
        Some((a, n)) => {
            let n: u64 = n
                .trim()
                .parse()
                .with_context(|| format!("--set {s}: scan number {n:?} is not a number"))?;
            (a, n)
        }
        None => (s, 1),
    };
    let Some((name, value)) = assign.split_once('=') else {
        bail!("--set {s}: expected VAR=VALUE@SCAN");
    };
    let Some(var) = prog.var(name.trim()) else {
        bail!("--set {s}: no variable {name:?} in {}", prog.file());
    };
    let info = prog.info(var);
    if info.constant {
        bail!("--set {s}: {} is CONSTANT", info.name);
    }
    let Some(value) = prog.parse(var, value) else {
        bail!(
            "--set {s}: {value:?} is not a value of type {} (variable {})",
            info.type_name,
            info.name
        );
    };
    if scan == 0 {
        bail!("--set {s}: scans count from 1");
    }
    Ok(SetOp { scan, var, value })
}

fn json_value(prog: &Program, id: VarId) -> serde_json::Value {
    match prog.get(id) {
        plc::Value::Bool(b) => b.into(),
        plc::Value::Int(v) if prog.info(id).ty.int().is_some_and(|k| !k.bitstring()) => {
            if prog
                .info(id)
                .ty
                .int()
                .is_some_and(|k| k.bits() == 64 && !k.signed())
            {
                (v as u64).into()
            } else {
                v.into()
            }
        }
        plc::Value::Real(r) => {
            // REAL prints at single precision (0.1 not 0.10000000149).
            let text = prog.format(id);
            text.parse::<f64>()
                .ok()
                .and_then(serde_json::Number::from_f64)
                .or_else(|| serde_json::Number::from_f64(r))
                .map_or(serde_json::Value::String(text), serde_json::Value::Number)
        }
        _ => prog.format(id).into(),
    }
}

fn run_offline(a: &RunArgs) -> anyhow::Result<ExitCode> {
    let period = parse_period(&a.period)?;
    let mut prog = match load(&a.file, Options { budget: a.budget })? {
        Ok(p) => p,
        Err(d) => return Ok(report(&d)),
    };
    let mut sets = a
        .set
        .iter()
        .map(|s| parse_set(&prog, s))
        .collect::<anyhow::Result<Vec<_>>>()?;
    sets.sort_by_key(|s| s.scan);
    let watch: Vec<String> = a.watch.iter().map(|w| w.to_ascii_uppercase()).collect();
    let watched = |name: &str| {
        let n = name.to_ascii_uppercase();
        let short = n.split_once('.').map_or(n.as_str(), |(_, s)| s);
        watch.is_empty()
            || watch.iter().any(|w| {
                [n.as_str(), short].iter().any(|x| {
                    x == w
                        || x.strip_prefix(w.as_str())
                            .is_some_and(|r| r.starts_with(['.', '[']))
                })
            })
    };
    for w in &a.watch {
        let up = w.to_ascii_uppercase();
        if !prog.vars().iter().any(|v| {
            let n = v.name.to_ascii_uppercase();
            n == up || n.contains(&format!(".{up}")) || n.starts_with(&format!("{up}."))
        }) {
            bail!("--watch {w}: no such variable in {}", prog.file());
        }
    }
    let ids: Vec<VarId> = (0..prog.vars().len() as u32)
        .map(VarId)
        .filter(|&i| watched(&prog.info(i).name))
        .collect();
    let mut last: Vec<u64> = ids.iter().map(|&i| prog.cell(i)).collect();
    let mut out = std::io::stdout().lock();
    let mut scans_json = Vec::new();
    let mut fault = None;
    for n in 1..=a.scans {
        for s in sets.iter().filter(|s| s.scan == n) {
            prog.set(s.var, s.value)
                .map_err(|e| anyhow::anyhow!("--set before scan {n}: {e}"))?;
        }
        let now = (n as i64 - 1).saturating_mul(period);
        let result = prog.scan(&[], &mut [], now);
        let mut changed = serde_json::Map::new();
        for (&id, old) in ids.iter().zip(last.iter_mut()) {
            let c = prog.cell(id);
            if c != *old {
                *old = c;
                let name = &prog.info(id).name;
                if a.json {
                    changed.insert(name.clone(), json_value(&prog, id));
                } else {
                    writeln!(out, "scan {n}: {name}={}", prog.format(id))?;
                }
            }
        }
        if let Err(f) = result {
            if !a.json {
                writeln!(out, "scan {n}: FAULT {f}")?;
            }
            fault = Some((n, f));
        }
        if a.json {
            scans_json.push(serde_json::json!({
                "scan": n,
                "time_ns": now,
                "changed": changed,
            }));
        }
        if fault.is_some() {
            break;
        }
    }
    if a.json {
        let doc = serde_json::json!({
            "file": prog.file(),
            "period_ns": period,
            "scans": scans_json,
            "fault": fault.as_ref().map(|(n, f)| serde_json::json!({
                "scan": n,
                "kind": f.kind.to_string(),
                "file": &*f.file,
                "line": f.line,
                "col": f.col,
            })),
        });
        writeln!(out, "{}", serde_json::to_string_pretty(&doc)?)?;
    }
    match fault {
        Some((n, f)) => {
            eprintln!("hytask: scan {n}: {f}");
            Ok(ExitCode::from(3))
        }
        None => Ok(ExitCode::SUCCESS),
    }
}
