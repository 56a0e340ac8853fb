//! Client subcommands: talk to a running daemon over the control socket. Each maps to one
//! control method (see `src/control/methods/`); `--json` prints the raw reply.

use super::interrupt::{Interrupts, EXIT_INTERRUPTED};
use super::wait::{self, Motion, WaitError};
use crate::control::client::Client;
use anyhow::Context;
use serde_json::{json, Value};
use std::path::PathBuf;
use std::process::ExitCode;

/// Socket option shared by the client subcommands.
#[derive(Debug, Clone, clap::Args)]
pub struct SocketArg {
    /// Control socket of the daemon.
    /// Default: the daemon's default path for this user (/run/hytask/control.sock for
    /// root, $XDG_RUNTIME_DIR/hytask/control.sock otherwise).
    #[arg(
        long,
        env = "HYTASK_SOCKET",
        default_value_os_t = crate::control::listen::default_socket_path()
    )]
    pub socket: PathBuf,
    /// Print the daemon's JSON reply as is.
    #[arg(long)]
    pub json: bool,
}

/// `--no-wait` of the commands that start a motion.
#[derive(Debug, Clone, Copy, clap::Args)]
pub struct NoWait {
    /// Return as soon as the daemon has accepted the command (the motion goes on; the
    /// next command may find the machine busy).
    #[arg(long)]
    pub no_wait: bool,
}

/// Client subcommands.
#[derive(Debug, clap::Subcommand)]
pub enum ClientCommand {
    /// Print the machine status (mode, positions, job, faults, thread timing).
    Status(SocketArg),
    /// Trip the e-stop (`--reset` releases it).
    Estop {
        /// Release the e-stop instead.
        #[arg(long)]
        reset: bool,
        #[command(flatten)]
        sock: SocketArg,
    },
    /// Switch the machine on (enable drives; also clears a fault).
    On(SocketArg),
    /// Switch the machine off after a controlled stop.
    Off(SocketArg),
    /// Home one axis, or all axes; waits until homing has ended (per-axis progress on a
    /// terminal; Ctrl-C stops it).
    Home {
        /// Axis letter (all axes when absent).
        axis: Option<String>,
        #[command(flatten)]
        wait: NoWait,
        #[command(flatten)]
        sock: SocketArg,
    },
    /// Jog an axis: continuous until `hytask jog-stop`, or by `--distance` (waits until the
    /// axis stops; Ctrl-C stops it).
    Jog {
        /// Axis letter.
        axis: String,
        /// Signed velocity, mm/s (deg/s for rotary axes).
        #[arg(allow_hyphen_values = true)]
        velocity: f64,
        /// Incremental distance.
        #[arg(long)]
        distance: Option<f64>,
        #[command(flatten)]
        wait: NoWait,
        #[command(flatten)]
        sock: SocketArg,
    },
    /// Stop a continuous jog.
    JogStop(SocketArg),
    /// Execute one line of G-code; waits until its motion has ended (Ctrl-C stops it).
    Mdi {
        /// The G-code line.
        line: String,
        #[command(flatten)]
        wait: NoWait,
        #[command(flatten)]
        sock: SocketArg,
    },
    /// Feed hold.
    Pause(SocketArg),
    /// Resume after a feed hold.
    Resume(SocketArg),
    /// Abort the job with a controlled stop.
    Abort(SocketArg),
    /// Set overrides (fractions: feed 0–2, rapid 0–1, spindle 0–2).
    Override {
        /// Feed override.
        #[arg(long)]
        feed: Option<f64>,
        /// Rapid override.
        #[arg(long)]
        rapid: Option<f64>,
        /// Spindle override.
        #[arg(long)]
        spindle: Option<f64>,
        #[command(flatten)]
        sock: SocketArg,
    },
    /// List the tasks with their operations, events and ports.
    Tasks(SocketArg),
    /// Call a task operation by name, with JSON arguments.
    Call {
        /// Task name.
        task: String,
        /// Operation name.
        operation: String,
        /// Arguments as a JSON object.
        #[arg(default_value = "{}")]
        args: String,
        #[command(flatten)]
        sock: SocketArg,
    },
    /// Set a simulated input (sim backends only).
    SimInput {
        /// Input name from the config.
        name: String,
        /// Value (0/1 for digital inputs).
        #[arg(allow_hyphen_values = true)]
        value: f64,
        #[command(flatten)]
        sock: SocketArg,
    },
    /// Read an object of a CANopen drive by SDO (`drive.sdo_read`).
    SdoRead {
        /// Drive name from the config.
        drive: String,
        /// Object index, e.g. 0x6064.
        index: String,
        /// Sub-index.
        #[arg(default_value_t = 0)]
        sub: u8,
        #[command(flatten)]
        sock: SocketArg,
    },
    /// Write an object of a CANopen drive by SDO (`drive.sdo_write`).
    SdoWrite {
        /// Drive name from the config.
        drive: String,
        /// Object index, e.g. 0x1017.
        index: String,
        /// Sub-index.
        sub: u8,
        /// Integer value.
        #[arg(allow_hyphen_values = true)]
        value: i64,
        /// Bytes to write (1, 2 or 4).
        #[arg(long, default_value_t = 4)]
        size: u8,
        #[command(flatten)]
        sock: SocketArg,
    },
}

/// Runs a client subcommand.
pub fn run(cmd: ClientCommand) -> anyhow::Result<ExitCode> {
    use ClientCommand as C;
    // A client printing into a closed pipe (`hytask status | head -1`) should end quietly,
    // as other command-line tools do, instead of panicking on EPIPE. Only the client does
    // this: the daemon keeps ignoring SIGPIPE and handles broken sockets as errors.
    // SAFETY: restoring the default disposition installs no handler code.
    let _ = unsafe {
        nix::sys::signal::signal(
            nix::sys::signal::Signal::SIGPIPE,
            nix::sys::signal::SigHandler::SigDfl,
        )
    };
    // The motion a command starts and waits for (unless --no-wait).
    let mut wait_for: Option<(Motion, Vec<String>)> = None;
    let (sock, method, params) = match cmd {
        C::Status(s) => (s, "status", Value::Null),
        C::Estop { reset, sock } => (
            sock,
            if reset { "estop.reset" } else { "estop" },
            Value::Null,
        ),
        C::On(s) => (s, "machine.on", Value::Null),
        C::Off(s) => (s, "machine.off", Value::Null),
        C::Home { axis, wait, sock } => {
            if !wait.no_wait {
                wait_for = Some((Motion::Home, axis.iter().cloned().collect()));
            }
            (sock, "home", json!({ "axis": axis }))
        }
        C::Jog {
            axis,
            velocity,
            distance,
            wait,
            sock,
        } => {
            // A continuous jog runs until jog-stop: nothing to wait for.
            if distance.is_some() && !wait.no_wait {
                wait_for = Some((Motion::Jog, vec![]));
            }
            (
                sock,
                "jog",
                json!({"axis": axis, "velocity": velocity, "distance": distance}),
            )
        }
        C::JogStop(s) => (s, "jog.stop", Value::Null),
        C::Mdi { line, wait, sock } => {
            if !wait.no_wait {
                wait_for = Some((Motion::Mdi, vec![]));
            }
            (sock, "mdi", json!({ "line": line }))
        }
        C::Pause(s) => (s, "job.pause", Value::Null),
        C::Resume(s) => (s, "job.resume", Value::Null),
        C::Abort(s) => (s, "job.abort", Value::Null),
        C::Override {
            feed,
            rapid,
            spindle,
            sock,
        } => (
            sock,
            "override",
            json!({"feed": feed, "rapid": rapid, "spindle": spindle}),
        ),
        C::Tasks(s) => (s, "tasks", Value::Null),
        C::Call {
            task,
            operation,
            args,
            sock,
        } => {
            let args: Value = serde_json::from_str(&args).context("arguments must be JSON")?;
            (
                sock,
                "call",
                json!({"task": task, "operation": operation, "args": args}),
            )
        }
        C::SimInput { name, value, sock } => {
            (sock, "sim.input", json!({"name": name, "value": value}))
        }
        C::SdoRead {
            drive,
            index,
            sub,
            sock,
        } => (
            sock,
            "drive.sdo_read",
            json!({"drive": drive, "index": index, "sub": sub}),
        ),
        C::SdoWrite {
            drive,
            index,
            sub,
            value,
            size,
            sock,
        } => (
            sock,
            "drive.sdo_write",
            json!({"drive": drive, "index": index, "sub": sub, "value": value, "size": size}),
        ),
    };
    let params = strip_nulls(params);
    let mut client = Client::connect(&sock.socket)
        .with_context(|| format!("cannot reach the daemon at {}", sock.socket.display()))?;
    let mut intr = match &wait_for {
        Some(_) => {
            wait::subscribe(&mut client)?;
            Some(Interrupts::install()?)
        }
        None => None,
    };
    let reply = client.call(method, params)?;
    if let (Some((motion, axes)), Some(intr)) = (&wait_for, &mut intr) {
        if sock.json {
            println!("{reply}");
        }
        return match wait::until_idle(&mut client, *motion, axes, intr) {
            Ok(()) => Ok(ExitCode::SUCCESS),
            Err(WaitError::Interrupted(what)) => {
                eprintln!("hytask: {what} stopped by Ctrl-C");
                Ok(ExitCode::from(EXIT_INTERRUPTED))
            }
            Err(e) => Err(e.into()),
        };
    }
    if sock.json {
        println!("{reply}");
    } else if method == "status" {
        print_status(&reply);
    } else if method == "tasks" {
        print_tasks(&reply);
    } else if reply != json!({"ok": true}) {
        println!("{}", serde_json::to_string_pretty(&reply)?);
    }
    Ok(ExitCode::SUCCESS)
}

/// Drops `null` members so optional parameters are simply absent.
fn strip_nulls(v: Value) -> Value {
    match v {
        Value::Object(o) => Value::Object(o.into_iter().filter(|(_, v)| !v.is_null()).collect()),
        other => other,
    }
}

fn print_status(s: &Value) {
    println!(
        "machine {}  mode {}  realtime {}",
        s["machine"].as_str().unwrap_or("?"),
        s["mode"].as_str().unwrap_or("?"),
        s["realtime"]
    );
    for a in s["axes"].as_array().into_iter().flatten() {
        println!(
            "  {:<2} cmd {:>10.4}  act {:>10.4}  ferr {:>8.4}  {}{}",
            a["name"].as_str().unwrap_or("?"),
            a["commanded"].as_f64().unwrap_or(f64::NAN),
            a["actual"].as_f64().unwrap_or(f64::NAN),
            a["following_error"].as_f64().unwrap_or(f64::NAN),
            if a["homed"] == json!(true) {
                "homed"
            } else {
                "not homed"
            },
            a["fault"]
                .as_str()
                .map(|f| format!("  FAULT {f}"))
                .unwrap_or_default()
        );
    }
    let j = &s["job"];
    if j["state"].as_str().unwrap_or("none") != "none" {
        println!(
            "  job {} {}  line {}/{}  {:.1}%",
            j["name"].as_str().unwrap_or(""),
            j["state"].as_str().unwrap_or(""),
            j["line"],
            j["total_lines"],
            j["progress"].as_f64().unwrap_or(0.0) * 100.0
        );
    }
    let w = &j["input_wait"];
    if w.is_object() {
        println!(
            "  waiting at line {}: M66 on {} input {} ({})",
            w["line"],
            w["input"].as_str().unwrap_or("?"),
            w["index"],
            w["until"].as_str().unwrap_or("?")
        );
    }
    for f in s["faults"].as_array().into_iter().flatten() {
        println!("  fault: {}", f.as_str().unwrap_or(""));
    }
    for t in s["threads"].as_array().into_iter().flatten() {
        println!(
            "  thread {} {}us prio {}: latency max {:.1}us, exec max {:.1}us, overruns {}",
            t["name"].as_str().unwrap_or(""),
            t["period_us"],
            t["priority"],
            t["latency_us"]["max"].as_f64().unwrap_or(0.0),
            t["exec_us"]["max"].as_f64().unwrap_or(0.0),
            t["overruns"]
        );
    }
}

fn print_tasks(v: &Value) {
    for t in v.as_array().into_iter().flatten() {
        println!(
            "{} [{}] on {}  step avg {:.1} µs, max {:.1} µs",
            t["name"].as_str().unwrap_or(""),
            t["state"].as_str().unwrap_or(""),
            t["thread"].as_str().unwrap_or(""),
            t["exec_us"]["avg"].as_f64().unwrap_or(0.0),
            t["exec_us"]["max"].as_f64().unwrap_or(0.0)
        );
        for op in t["operations"].as_array().into_iter().flatten() {
            let params: Vec<&str> = op["params"]
                .as_array()
                .into_iter()
                .flatten()
                .filter_map(Value::as_str)
                .collect();
            println!(
                "  op {}({}): {}",
                op["name"].as_str().unwrap_or(""),
                params.join(", "),
                op["doc"].as_str().unwrap_or("")
            );
        }
        for e in t["events"].as_array().into_iter().flatten() {
            println!("  event {}", e.as_str().unwrap_or(""));
        }
        for p in t["ports"].as_array().into_iter().flatten() {
            println!("  port {}", p.as_str().unwrap_or(""));
        }
        for s in t["scripts"].as_array().into_iter().flatten() {
            println!("  script {}", super::script::describe(s));
        }
    }
}
