//! `hytask script ...`: load, start, pause, resume, step, stop, unload and list the programs
//! and state machines of a running daemon's script host tasks (control methods
//! `script.*`), and `check` a script file offline.

use super::client::SocketArg;
use crate::control::client::Client;
use anyhow::Context;
use serde_json::{json, Value};
use std::path::PathBuf;
use std::process::ExitCode;

/// Arguments of `hytask script`.
#[derive(Debug, clap::Args)]
pub struct ScriptArgs {
    /// What to do.
    #[command(subcommand)]
    pub cmd: ScriptCmd,
}

/// Which program or machine.
#[derive(Debug, Clone, clap::Args)]
pub struct Target {
    /// Program or state machine name.
    pub name: String,
    /// Script slot (as printed by `load` and `list`).
    #[arg(long)]
    pub slot: Option<usize>,
    /// Or the file it was loaded from.
    #[arg(long)]
    pub file: Option<String>,
    /// Host task (needed when the machine has several).
    #[arg(long)]
    pub task: Option<String>,
}

/// The script subcommands.
#[derive(Debug, clap::Subcommand)]
pub enum ScriptCmd {
    /// Compile a script file offline: print its programs and machines, or every error.
    Check {
        /// The script file.
        file: PathBuf,
    },
    /// Load a script file into a host task (the file is read here and sent).
    Load {
        /// The script file.
        file: PathBuf,
        /// Host task.
        #[arg(long)]
        task: Option<String>,
        #[command(flatten)]
        sock: SocketArg,
    },
    /// Start (or restart) a program or state machine.
    Start {
        #[command(flatten)]
        t: Target,
        #[command(flatten)]
        sock: SocketArg,
    },
    /// Pause.
    Pause {
        #[command(flatten)]
        t: Target,
        #[command(flatten)]
        sock: SocketArg,
    },
    /// Resume after a pause.
    Resume {
        #[command(flatten)]
        t: Target,
        #[command(flatten)]
        sock: SocketArg,
    },
    /// Run one statement (program) or up to one transition (machine), then pause.
    Step {
        #[command(flatten)]
        t: Target,
        #[command(flatten)]
        sock: SocketArg,
    },
    /// Stop.
    Stop {
        #[command(flatten)]
        t: Target,
        #[command(flatten)]
        sock: SocketArg,
    },
    /// Unload a script.
    Unload {
        /// Script slot.
        #[arg(long)]
        slot: Option<usize>,
        /// Or the file it was loaded from.
        #[arg(long)]
        file: Option<String>,
        /// Host task.
        #[arg(long)]
        task: Option<String>,
        #[command(flatten)]
        sock: SocketArg,
    },
    /// List loaded programs and machines: status, state, current line.
    List {
        #[command(flatten)]
        sock: SocketArg,
    },
}

fn target(t: Target) -> Value {
    json!({"task": t.task, "slot": t.slot, "file": t.file, "name": t.name})
}

/// Runs `hytask script`.
pub fn run(a: ScriptArgs) -> anyhow::Result<ExitCode> {
    use ScriptCmd as S;
    let (sock, verb, params) = match a.cmd {
        S::Check { file } => {
            let script = crate::script::load_file(&file)?;
            for (name, machine) in script.items() {
                let kind = if machine { "STATE_MACHINE" } else { "PROGRAM" };
                println!("{kind} {name}");
            }
            for (peer, op) in script.operations() {
                println!("  calls {peer}.{op}");
            }
            for e in script.events() {
                println!("  waits for {e}");
            }
            return Ok(ExitCode::SUCCESS);
        }
        S::Load { file, task, sock } => {
            let source = std::fs::read_to_string(&file)
                .with_context(|| format!("cannot read {}", file.display()))?;
            let name = file.display().to_string();
            (
                sock,
                "load",
                json!({"task": task, "file": name, "source": source}),
            )
        }
        S::Start { t, sock } => (sock, "start", target(t)),
        S::Pause { t, sock } => (sock, "pause", target(t)),
        S::Resume { t, sock } => (sock, "resume", target(t)),
        S::Step { t, sock } => (sock, "step", target(t)),
        S::Stop { t, sock } => (sock, "stop", target(t)),
        S::Unload {
            slot,
            file,
            task,
            sock,
        } => (
            sock,
            "unload",
            json!({"task": task, "slot": slot, "file": file}),
        ),
        S::List { sock } => (sock, "list", Value::Null),
    };
    let params = match params {
        Value::Object(o) => Value::Object(o.into_iter().filter(|(_, v)| !v.is_null()).collect()),
        other => other,
    };
    let mut client = Client::connect(&sock.socket)
        .with_context(|| format!("cannot reach the daemon at {}", sock.socket.display()))?;
    let reply = client.call(&format!("script.{verb}"), params)?;
    if sock.json {
        println!("{reply}");
    } else if verb == "list" {
        for s in reply.as_array().into_iter().flatten() {
            println!("{}", describe(s));
        }
    } else if reply != json!({"ok": true}) {
        println!("{}", serde_json::to_string_pretty(&reply)?);
    }
    Ok(ExitCode::SUCCESS)
}

/// One line per program or machine: `task slot name [status] state line`.
pub(super) fn describe(s: &Value) -> String {
    let mut out = format!(
        "{} #{} {} {} [{}]",
        s["task"].as_str().unwrap_or(""),
        s["slot"],
        s["kind"].as_str().unwrap_or(""),
        s["name"].as_str().unwrap_or(""),
        s["status"].as_str().unwrap_or("")
    );
    if let Some(st) = s["state"].as_str() {
        out.push_str(&format!(" state {st}"));
    }
    if let Some(l) = s["line"].as_u64().filter(|l| *l > 0) {
        out.push_str(&format!(" at {}:{l}", s["file"].as_str().unwrap_or("")));
    }
    if let Some(e) = s["error"].as_str() {
        out.push_str(&format!(" error: {e}"));
    }
    out
}
