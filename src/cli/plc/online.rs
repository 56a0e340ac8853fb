//! `hytask plc vars|get|set|force|unforce|load`: the running daemon's PLC, over the control
//! socket (methods `plc.*`). Values are IEC literals (`TRUE`, `42`, `T#1s`).

use crate::cli::client::SocketArg;
use crate::control::client::Client;
use anyhow::Context as _;
use serde_json::{json, Value};
use std::path::PathBuf;
use std::process::ExitCode;

/// The subcommands that talk to the daemon.
#[derive(Debug, clap::Subcommand)]
pub enum OnlineCommand {
    /// Print every variable (or those whose name contains FILTER): name, type, value, and
    /// `FORCED` for forced ones.
    Vars {
        /// Part of the name, case-insensitive.
        filter: Option<String>,
        #[command(flatten)]
        sock: SocketArg,
    },
    /// Print one variable.
    Get {
        /// Full name, or without the program prefix.
        name: String,
        #[command(flatten)]
        sock: SocketArg,
    },
    /// Write a variable once, at the start of the next scan (operator role).
    Set {
        /// Variable.
        name: String,
        /// Value (IEC literal).
        value: String,
        #[command(flatten)]
        sock: SocketArg,
    },
    /// Force a variable every scan until unforced (operator role).
    Force {
        /// Variable.
        name: String,
        /// Value (IEC literal).
        value: String,
        #[command(flatten)]
        sock: SocketArg,
    },
    /// Release a force (without NAME: every force) (operator role).
    Unforce {
        /// Variable.
        name: Option<String>,
        #[command(flatten)]
        sock: SocketArg,
    },
    /// Load a new program version into the running PLC at a scan boundary; refused with
    /// every compile error, the old version running on (operator role).
    Load {
        /// The Structured Text file (read here and sent).
        file: PathBuf,
        #[command(flatten)]
        sock: SocketArg,
    },
}

/// `NAME : TYPE = VALUE [FORCED]`.
fn line(v: &Value) -> String {
    let forced = if v["forced"] == json!(true) {
        " FORCED"
    } else {
        ""
    };
    format!(
        "{} : {} = {}{forced}",
        v["name"].as_str().unwrap_or(""),
        v["type"].as_str().unwrap_or(""),
        v["value"].as_str().unwrap_or("")
    )
}

/// Runs one online subcommand.
pub fn run(cmd: OnlineCommand) -> anyhow::Result<ExitCode> {
    use OnlineCommand as C;
    let (sock, method, params) = match cmd {
        C::Vars { filter, sock } => (sock, "vars", json!({ "filter": filter })),
        C::Get { name, sock } => (sock, "get", json!({ "name": name })),
        C::Set { name, value, sock } => (sock, "set", json!({"name": name, "value": value})),
        C::Force { name, value, sock } => (sock, "force", json!({"name": name, "value": value})),
        C::Unforce { name, sock } => (sock, "unforce", json!({ "name": name })),
        C::Load { file, sock } => {
            let source = std::fs::read_to_string(&file)
                .with_context(|| format!("cannot read {}", file.display()))?;
            let name = file.display().to_string();
            (sock, "load", json!({"file": name, "source": source}))
        }
    };
    let params = match params {
        Value::Object(o) => Value::Object(o.into_iter().filter(|(_, v)| !v.is_null()).collect()),
        other => other,
    };
    let mut client = Client::connect(&sock.socket)
        .with_context(|| format!("cannot reach the daemon at {}", sock.socket.display()))?;
    let reply = client.call(&format!("plc.{method}"), params)?;
    if sock.json {
        println!("{reply}");
        return Ok(ExitCode::SUCCESS);
    }
    match method {
        "vars" => {
            for v in reply.as_array().into_iter().flatten() {
                println!("{}", line(v));
            }
        }
        "get" | "set" | "force" => println!("{}", line(&reply)),
        "load" => {
            let list = |k: &str| -> String {
                let names: Vec<&str> = reply[k]
                    .as_array()
                    .into_iter()
                    .flatten()
                    .filter_map(Value::as_str)
                    .collect();
                format!("{} {k}: {}", names.len(), names.join(", "))
            };
            println!("loaded version {}", reply["generation"]);
            println!("{}", list("kept"));
            println!("{}", list("reset"));
            println!("{}", list("removed"));
            println!("{} force(s) released", reply["unforced"]);
        }
        _ => {}
    }
    Ok(ExitCode::SUCCESS)
}
