//! `hytask run JOB.ngc`: submit a G-code job and follow it to the end.
//!
//! With a daemon reachable on the socket, the job runs there. Without one, an embedded
//! daemon is started on the built-in simulated machine (or `--config`), on a private socket,
//! and the very same client flow drives it: this is the README's main command. The flow:
//! subscribe to events, bring the machine to idle (reset e-stop, switch on, home), load the
//! job (interpreted and planned in full: errors name file:line:col and nothing moves), run
//! it, draw progress (line, percent, ETA), stream faults and messages, print a summary
//! (time, distance, max following error per axis). Exits non-zero unless the job completes.

use crate::control::client::{Client, ClientError};
use anyhow::{bail, Context};
use serde_json::{json, Value};
use std::io::{IsTerminal, Write};
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::{Duration, Instant};

/// Arguments of `hytask run`.
#[derive(Debug, clap::Args)]
pub struct RunArgs {
    /// The G-code job.
    pub job: PathBuf,
    /// Control socket of a running daemon.
    /// Default: the daemon's default path for this user (/run/hytask/control.sock for
    /// root, $XDG_RUNTIME_DIR/hytask/control.sock otherwise).
    #[arg(
        long,
        env = "HYTASK_SOCKET",
        default_value_os_t = crate::control::listen::default_socket_path()
    )]
    pub socket: PathBuf,
    /// Machine for the embedded daemon when none is reachable (default: built-in sim mill).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Never start an embedded daemon; fail if none is reachable.
    #[arg(long)]
    pub no_embedded: bool,
    /// Feed override for the run (0–2).
    #[arg(long)]
    pub feed_override: Option<f64>,
}

/// Runs the subcommand.
pub fn run(args: RunArgs) -> anyhow::Result<ExitCode> {
    let job = std::fs::canonicalize(&args.job)
        .with_context(|| format!("cannot open job {}", args.job.display()))?;
    match Client::connect(&args.socket) {
        Ok(client) => {
            eprintln!("hytask: using the daemon at {}", args.socket.display());
            follow_job(client, &job, args.feed_override)
        }
        Err(_) if !args.no_embedded => {
            if std::env::var_os("RUST_LOG").is_none() {
                // The embedded machine logs warnings and errors only; progress is ours.
                std::env::set_var("RUST_LOG", "warn");
            }
            super::serve::init_logging();
            let daemon = crate::daemon::Embedded::start(args.config.as_deref())
                .context("starting the embedded simulated machine")?;
            eprintln!(
                "hytask: no daemon at {}; running on the embedded machine '{}'{}",
                args.socket.display(),
                daemon.machine_name(),
                if daemon.realtime() {
                    ""
                } else {
                    " (not realtime: no SCHED_FIFO privilege)"
                }
            );
            let client = Client::connect(daemon.socket())?;
            let code = follow_job(client, &job, args.feed_override);
            daemon.shutdown()?;
            code
        }
        Err(e) => {
            Err(e).with_context(|| format!("cannot reach the daemon at {}", args.socket.display()))
        }
    }
}

/// Brings the machine to idle and homed, runs the job, reports. Shared by both paths.
fn follow_job(mut c: Client, job: &std::path::Path, feed: Option<f64>) -> anyhow::Result<ExitCode> {
    c.call(
        "subscribe",
        json!({"topics": ["progress", "fault", "mode", "job", "message"]}),
    )?;
    let status = c.call("status", Value::Null)?;
    match status["mode"].as_str() {
        Some("estop") => {
            c.call("estop.reset", Value::Null)?;
            c.call("machine.on", Value::Null)?;
        }
        Some("off") | Some("fault") => {
            c.call("machine.on", Value::Null)?;
        }
        Some("idle") => {}
        Some(m) => bail!("the machine is busy ({m}); try again when it is idle"),
        None => bail!("the daemon sent a status without a mode"),
    }
    let status = c.call("status", Value::Null)?;
    let unhomed: Vec<&str> = status["axes"]
        .as_array()
        .into_iter()
        .flatten()
        .filter(|a| a["homed"] != json!(true))
        .filter_map(|a| a["name"].as_str())
        .collect();
    if !unhomed.is_empty() {
        eprintln!("hytask: homing {}", unhomed.join(" "));
        c.call("home", Value::Null)?;
        wait_for_mode(&mut c, "idle", Duration::from_secs(120))?;
    }
    if let Some(f) = feed {
        c.call("override", json!({ "feed": f }))?;
    }
    let info = match c.call("job.load", json!({"path": job.display().to_string()})) {
        Ok(info) => info,
        Err(ClientError::Remote { message, .. }) => {
            eprintln!("hytask: job refused, nothing moved: {message}");
            return Ok(ExitCode::FAILURE);
        }
        Err(e) => return Err(e.into()),
    };
    eprintln!(
        "hytask: job {}: {} lines, {} commands, planned {}, {:.1} mm",
        info["name"].as_str().unwrap_or(""),
        info["lines"],
        info["commands"],
        fmt_duration(info["planned_time_s"].as_f64().unwrap_or(0.0)),
        info["distance_mm"].as_f64().unwrap_or(0.0)
    );
    let started = Instant::now();
    c.call("job.run", Value::Null)?;
    let mut bar = ProgressBar::new();
    let outcome = loop {
        match c.next_event(Duration::from_millis(500))? {
            Some(ev) => match ev.topic.as_str() {
                "progress" => bar.draw(&ev.data),
                "fault" => {
                    bar.clear();
                    eprintln!(
                        "hytask: FAULT: {}",
                        ev.data["message"].as_str().unwrap_or("(no message)")
                    );
                }
                "message" => {
                    bar.clear();
                    eprintln!(
                        "hytask: message: {}",
                        ev.data["text"].as_str().unwrap_or("")
                    );
                }
                "job" => {
                    let state = ev.data["state"].as_str().unwrap_or("").to_string();
                    if matches!(state.as_str(), "done" | "aborted" | "failed") {
                        bar.draw(&ev.data);
                        break (state, ev.data);
                    }
                }
                _ => {}
            },
            None => {
                // No event for a while: poll, so a lost event can never hang the client.
                let s = c.call("status", Value::Null)?;
                let state = s["job"]["state"].as_str().unwrap_or("").to_string();
                if matches!(state.as_str(), "done" | "aborted" | "failed") {
                    break (state, s["job"].clone());
                }
                bar.draw(&s["job"]);
            }
        }
    };
    bar.finish();
    let status = c.call("status", Value::Null)?;
    let (state, job_status) = outcome;
    println!("job:        {}", job_status["name"].as_str().unwrap_or(""));
    println!("result:     {state}");
    if let Some(reason) = job_status["reason"].as_str() {
        println!("reason:     {reason}");
    }
    println!(
        "time:       {} (planned {})",
        fmt_duration(started.elapsed().as_secs_f64()),
        fmt_duration(job_status["planned_time_s"].as_f64().unwrap_or(0.0))
    );
    println!(
        "distance:   {:.1} mm",
        job_status["distance_mm"].as_f64().unwrap_or(0.0)
    );
    println!(
        "max following error (mm): {}",
        per_axis(&status, "max_following_error")
    );
    println!("final position (machine): {}", per_axis(&status, "actual"));
    for f in status["faults"].as_array().into_iter().flatten() {
        println!("fault:      {}", f.as_str().unwrap_or(""));
    }
    Ok(if state == "done" {
        ExitCode::SUCCESS
    } else {
        ExitCode::FAILURE
    })
}

/// `X 1.2345  Y ...`: one field of every axis of a status reply.
fn per_axis(status: &Value, field: &str) -> String {
    status["axes"]
        .as_array()
        .into_iter()
        .flatten()
        .map(|a| {
            format!(
                "{} {:.4}",
                a["name"].as_str().unwrap_or("?"),
                a[field].as_f64().unwrap_or(f64::NAN)
            )
        })
        .collect::<Vec<_>>()
        .join("  ")
}

fn wait_for_mode(c: &mut Client, mode: &str, timeout: Duration) -> anyhow::Result<()> {
    let t0 = Instant::now();
    while t0.elapsed() < timeout {
        let s = c.call("status", Value::Null)?;
        match s["mode"].as_str() {
            Some(m) if m == mode => return Ok(()),
            Some("fault") | Some("estop") => {
                bail!(
                    "machine stopped while waiting: {}",
                    s["faults"].as_array().map(|f| f.len()).unwrap_or(0)
                )
            }
            _ => {}
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    bail!("machine did not become {mode} within {timeout:?}")
}

fn fmt_duration(s: f64) -> String {
    let s = s.max(0.0);
    let m = (s / 60.0).floor();
    format!("{}:{:04.1}", m as u64, s - m * 60.0)
}

/// One-line progress: a bar on a terminal, a line per 10 % otherwise (logs, CI).
struct ProgressBar {
    tty: bool,
    last_decile: i64,
    drawn: bool,
}

impl ProgressBar {
    fn new() -> Self {
        ProgressBar {
            tty: std::io::stderr().is_terminal(),
            last_decile: -1,
            drawn: false,
        }
    }

    fn draw(&mut self, job: &Value) {
        let p = job["progress"].as_f64().unwrap_or(0.0).clamp(0.0, 1.0);
        let line = job["line"].as_u64().unwrap_or(0);
        let total = job["total_lines"].as_u64().unwrap_or(0);
        let planned = job["planned_time_s"].as_f64().unwrap_or(0.0);
        let elapsed = job["elapsed_s"].as_f64().unwrap_or(0.0);
        let eta = (planned - elapsed).max(0.0);
        let text = format!(
            "{:5.1}%  line {line}/{total}  ETA {}",
            p * 100.0,
            fmt_duration(eta)
        );
        if self.tty {
            let filled = (p * 30.0).round() as usize;
            eprint!(
                "\r[{}{}] {text}   ",
                "#".repeat(filled),
                ".".repeat(30 - filled)
            );
            let _ = std::io::stderr().flush();
            self.drawn = true;
        } else {
            let decile = (p * 10.0).floor() as i64;
            if decile > self.last_decile {
                self.last_decile = decile;
                eprintln!("progress {text}");
            }
        }
    }

    fn clear(&mut self) {
        if self.tty && self.drawn {
            eprint!("\r{}\r", " ".repeat(70));
        }
    }

    fn finish(&mut self) {
        if self.tty && self.drawn {
            eprintln!();
        }
    }
}
