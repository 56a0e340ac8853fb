//! `hytask run-cell CELL.toml --runs N`: run the pick-and-place cell and report.
//!
//! Without `--socket`, an embedded daemon serves the cell of the file on a private socket
//! (like `hytask run`); with it, the daemon already serving a cell there
//! (`hytask serve --config config/pickplace.toml`) is used. Either way the same client flow
//! drives it over the control socket: wait until the selection is homed (recovering from an
//! earlier error with `selection.stop`), `call selection run {"n": N}`, show one line per
//! sorted object from the `selection.operation_n_done` events, then print the objects per
//! container (as the selection decided and as they landed in the simulated world) and the
//! cycle time. Exits non-zero if the selection detects an error or the world's counts differ
//! from the selection's.
//!
//! `hytask serve` hands a cell file to [`serve`] here.

use crate::cell::config::{self as cell_config, CellFile};
use crate::cell::daemon::CellDaemon;
use crate::control::client::Client;
use anyhow::{bail, Context};
use serde_json::{json, Value};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::{Duration, Instant};

/// Arguments of `hytask run-cell`.
#[derive(Debug, clap::Args)]
pub struct RunCellArgs {
    /// The cell's configuration (e.g. config/pickplace.toml).
    pub config: PathBuf,
    /// Objects to sort.
    #[arg(long, default_value_t = 20)]
    pub runs: u32,
    /// Use the daemon serving a cell on this socket instead of an embedded one.
    #[arg(long)]
    pub socket: Option<PathBuf>,
}

fn load(path: &Path) -> anyhow::Result<CellFile> {
    cell_config::load(path).with_context(|| format!("loading the cell {}", path.display()))
}

/// Runs the subcommand.
pub fn run(args: RunCellArgs) -> anyhow::Result<ExitCode> {
    let file = load(&args.config)?;
    if let Some(socket) = &args.socket {
        let client = Client::connect(socket)
            .with_context(|| format!("cannot reach the daemon at {}", socket.display()))?;
        return follow(client, args.runs);
    }
    if std::env::var_os("RUST_LOG").is_none() {
        std::env::set_var("RUST_LOG", "warn");
    }
    super::serve::init_logging();
    let daemon = crate::daemon::Embedded::start_with(&file.control, || {
        let d: std::sync::Arc<dyn crate::daemon::Deployed> = CellDaemon::deploy(&file)?;
        Ok(d)
    })
    .context("starting the embedded cell")?;
    eprintln!(
        "hytask: cell '{}' on an embedded daemon{}",
        daemon.machine_name(),
        match (file.cell.sim_speed, daemon.realtime()) {
            (Some(s), _) => format!(" (simulated time at {s}x real time)"),
            (None, true) => String::new(),
            (None, false) => " (not realtime: no SCHED_FIFO privilege)".into(),
        }
    );
    let client = Client::connect(daemon.socket())?;
    let code = follow(client, args.runs);
    daemon.shutdown()?;
    code
}

/// `hytask serve --config CELL.toml`: the daemon serving a cell.
pub fn serve(path: &Path, socket: Option<PathBuf>) -> anyhow::Result<ExitCode> {
    use crate::control::{listen, server::ServerOptions};
    let file = load(path)?;
    let socket = listen::SocketOptions::from_config(&file.control, socket);
    let options = ServerOptions::from_config(&file.control)?;
    let claim = listen::claim(&socket)?;
    let cell = CellDaemon::deploy(&file)?;
    let listener = claim.bind()?;
    tracing::info!(
        "cell '{}': control socket at {}",
        file.cell.name,
        socket.path.display()
    );
    crate::daemon::run_with(cell, listener, options, std::future::pending())?;
    tracing::info!("cell stopped; exiting");
    Ok(ExitCode::SUCCESS)
}

fn job_state(status: &Value) -> String {
    status["job"]["state"].as_str().unwrap_or("").to_string()
}

fn world_counts(status: &Value) -> [u64; 4] {
    let o = &status["outputs"];
    let n = |k: &str| o[k].as_f64().unwrap_or(0.0) as u64;
    [
        n("container.A"),
        n("container.B"),
        n("container.reject"),
        n("floor"),
    ]
}

/// Waits until the selection is homed; recovers it with `stop` if it is in error.
fn until_homed(c: &mut Client, timeout: Duration) -> anyhow::Result<()> {
    let t0 = Instant::now();
    let mut recovering = false;
    while t0.elapsed() < timeout {
        let s = c.call("status", Value::Null)?;
        match job_state(&s).as_str() {
            "homed" => return Ok(()),
            "error_detected" if !recovering => {
                eprintln!(
                    "hytask: the selection is in error ({}); recovering with selection.stop",
                    s["job"]["reason"].as_str().unwrap_or("?")
                );
                c.call("call", json!({"task": "selection", "operation": "stop"}))?;
                recovering = true;
            }
            _ => {}
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    bail!("the selection did not reach 'homed' within {timeout:?}")
}

fn follow(mut c: Client, runs: u32) -> anyhow::Result<ExitCode> {
    if runs == 0 {
        bail!("--runs must be at least 1");
    }
    c.call("subscribe", json!({"topics": ["task", "fault"]}))?;
    until_homed(&mut c, Duration::from_secs(60))?;
    let before = world_counts(&c.call("status", Value::Null)?);
    let started = Instant::now();
    c.call(
        "call",
        json!({"task": "selection", "operation": "run", "args": {"n": runs}}),
    )?;
    let mut decided = [0u64; 3];
    let mut cycle_ms = Vec::new();
    let mut error = None;
    // Hang guard: a run takes a few seconds; a stuck cell must not hang the client.
    let guard = Duration::from_secs(60 + 30 * u64::from(runs));
    loop {
        if started.elapsed() > guard {
            bail!("no end of the selection after {guard:?}");
        }
        match c.next_event(Duration::from_millis(500))? {
            Some(ev) if ev.topic == "task" => match ev.data["event"].as_str() {
                Some("selection.operation_n_done") => {
                    let container = ev.data["container"].as_str().unwrap_or("");
                    let i = match container {
                        "a" => 0,
                        "b" => 1,
                        _ => 2,
                    };
                    decided[i] += 1;
                    let ms = ev.data["cycle_ms"].as_u64().unwrap_or(0);
                    cycle_ms.push(ms);
                    eprintln!(
                        "run {:>3}/{}: {:<6} ({:.2} s)",
                        ev.data["run"].as_u64().unwrap_or(0),
                        runs,
                        container.to_uppercase(),
                        ms as f64 / 1000.0
                    );
                }
                Some("selection.error_detected") => {
                    error = Some(ev.data["error"].as_str().unwrap_or("?").to_string());
                    break;
                }
                _ => {}
            },
            // A remote peer lost (`cell::remote`), or the selection's own faults.
            Some(ev) if ev.topic == "fault" => {
                eprintln!(
                    "hytask: fault: {}",
                    ev.data["message"].as_str().unwrap_or("?")
                );
            }
            Some(_) => {}
            None => {
                let s = c.call("status", Value::Null)?;
                let state = job_state(&s);
                if state == "error_detected" {
                    error = s["job"]["reason"].as_str().map(str::to_owned);
                    break;
                }
                if state == "homed" && s["job"]["line"].as_u64() == Some(u64::from(runs)) {
                    break;
                }
            }
        }
    }
    let elapsed = started.elapsed().as_secs_f64();
    let after = world_counts(&c.call("status", Value::Null)?);
    let landed: Vec<u64> = (0..4).map(|i| after[i] - before[i]).collect();
    let sorted: u64 = decided.iter().sum();
    println!("sorted:        {sorted} of {runs}");
    println!(
        "per container: A {}  B {}  reject {}",
        decided[0], decided[1], decided[2]
    );
    println!(
        "in the world:  A {}  B {}  reject {}  floor {}",
        landed[0], landed[1], landed[2], landed[3]
    );
    if !cycle_ms.is_empty() {
        let mean = cycle_ms.iter().sum::<u64>() as f64 / cycle_ms.len() as f64 / 1000.0;
        println!("cycle time:    {mean:.2} s per object (pick to release, cell time)");
    }
    println!(
        "wall time:     {elapsed:.1} s ({:.2} s per object)",
        elapsed / sorted.max(1) as f64
    );
    if let Some(e) = error {
        println!("error:         {e}");
        return Ok(ExitCode::FAILURE);
    }
    if landed[..3] != decided[..] || landed[3] != 0 {
        println!("error:         the world's counts differ from the selection's");
        return Ok(ExitCode::FAILURE);
    }
    Ok(ExitCode::SUCCESS)
}
