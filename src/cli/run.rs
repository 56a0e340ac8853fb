//! `hytask run JOB.ngc`: submit a G-code job and follow it to the end.
//!
//! With a daemon reachable on the socket, the job runs there. Without one, an embedded
//! daemon is started on the built-in simulated machine (or `--config`), on a private socket,
//! and the very same client flow drives it: this is the README's main command. The flow:
//! subscribe to events, bring the machine to idle (reset e-stop, switch on, home), load the
//! job (interpreted and planned in full: errors name file:line:col and nothing moves), run
//! it, draw progress (line, percent, ETA), stream faults and messages, print a summary
//! (time, distance, max following error per axis). Exits non-zero unless the job completes.

use super::interrupt::{Interrupts, EXIT_INTERRUPTED};
use super::wait::{self, WaitError};
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
    let mut intr = Interrupts::install()?;
    match Client::connect(&args.socket) {
        Ok(client) => {
            eprintln!("hytask: using the daemon at {}", args.socket.display());
            let end = follow_job(client, &job, args.feed_override, &args.socket, &mut intr)?;
            Ok(end.exit_code())
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
            let socket = daemon.socket().to_path_buf();
            let end = follow_job(client, &job, args.feed_override, &socket, &mut intr);
            // Whatever happened to the client, the axes stop under control before exit.
            let stopped = daemon.shutdown();
            let end = end?;
            if end == End::Interrupted {
                match &stopped {
                    Ok(()) => eprintln!(
                        "hytask: job aborted by Ctrl-C; axes stopped, drives off, embedded machine shut down"
                    ),
                    Err(e) => eprintln!("hytask: job aborted by Ctrl-C; stopping the machine failed: {e:#}"),
                }
            }
            stopped?;
            Ok(end.exit_code())
        }
        Err(e) => {
            Err(e).with_context(|| format!("cannot reach the daemon at {}", args.socket.display()))
        }
    }
}

/// How a followed job ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum End {
    /// Ran to its end.
    Done,
    /// Refused, failed or aborted by someone else.
    Failed,
    /// Aborted by the operator's second Ctrl-C.
    Interrupted,
}

impl End {
    fn exit_code(self) -> ExitCode {
        match self {
            End::Done => ExitCode::SUCCESS,
            End::Failed => ExitCode::FAILURE,
            End::Interrupted => ExitCode::from(EXIT_INTERRUPTED),
        }
    }
}

/// Brings the machine to idle and homed, runs the job, reports. Shared by both paths.
/// `socket` is where the operator can reach the same daemon (for `hytask resume`).
fn follow_job(
    mut c: Client,
    job: &std::path::Path,
    feed: Option<f64>,
    socket: &std::path::Path,
    intr: &mut Interrupts,
) -> anyhow::Result<End> {
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
    let unhomed: Vec<String> = status["axes"]
        .as_array()
        .into_iter()
        .flatten()
        .filter(|a| a["homed"] != json!(true))
        .filter_map(|a| a["name"].as_str().map(str::to_string))
        .collect();
    if !unhomed.is_empty() {
        eprintln!("hytask: homing {}", unhomed.join(" "));
        c.call("home", Value::Null)?;
        match wait::until_idle(&mut c, wait::Motion::Home, &unhomed, intr) {
            Ok(()) => eprintln!("hytask: homed {}", unhomed.join(" ")),
            Err(WaitError::Interrupted(what)) => {
                eprintln!("hytask: {what} stopped by Ctrl-C; the job did not start");
                return Ok(End::Interrupted);
            }
            Err(e) => return Err(e).context("homing before the job"),
        }
    }
    if let Some(f) = feed {
        c.call("override", json!({ "feed": f }))?;
    }
    let info = match c.call("job.load", json!({"path": job.display().to_string()})) {
        Ok(info) => info,
        Err(ClientError::Remote { message, .. }) => {
            eprintln!("hytask: job refused, nothing moved: {message}");
            return Ok(End::Failed);
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
    let mut ctrl_c = CtrlC::new(socket);
    let outcome = loop {
        ctrl_c.check(&mut c, intr, &mut bar)?;
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
    if ctrl_c.aborted && state == "aborted" {
        println!(
            "job {} aborted by Ctrl-C at line {}/{} ({:.1} %, {:.1} of {:.1} mm); machine at {}",
            job_status["name"].as_str().unwrap_or(""),
            job_status["line"],
            job_status["total_lines"],
            job_status["progress"].as_f64().unwrap_or(0.0) * 100.0,
            job_status["distance_mm"].as_f64().unwrap_or(0.0)
                - job_status["distance_to_go_mm"].as_f64().unwrap_or(0.0),
            job_status["distance_mm"].as_f64().unwrap_or(0.0),
            per_axis(&status, "actual")
        );
        return Ok(End::Interrupted);
    }
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
        End::Done
    } else {
        End::Failed
    })
}

/// Ctrl-C while a job runs: the first press holds it (feed hold: the axes decelerate on
/// the path and the job can go on), the second aborts it under control. While held, Enter
/// on the terminal resumes.
struct CtrlC {
    held: bool,
    aborted: bool,
    resume_hint: String,
    stdin_tty: bool,
}

impl CtrlC {
    fn new(socket: &std::path::Path) -> Self {
        CtrlC {
            held: false,
            aborted: false,
            resume_hint: format!("`hytask resume --socket {}`", socket.display()),
            stdin_tty: std::io::stdin().is_terminal(),
        }
    }

    fn check(
        &mut self,
        c: &mut Client,
        intr: &mut Interrupts,
        bar: &mut ProgressBar,
    ) -> anyhow::Result<()> {
        let presses = intr.take();
        if presses > 0 && !self.held {
            self.held = true;
            c.call("job.pause", Value::Null)?;
            bar.clear();
            eprintln!(
                "\nhytask: Ctrl-C: feed hold, the job stops on its path. {}{}; Ctrl-C again aborts the job.",
                if self.stdin_tty { "Enter resumes, or " } else { "Resume with " },
                self.resume_hint
            );
            if presses == 1 {
                return Ok(());
            }
        }
        if presses > 0 && self.held && !self.aborted {
            self.aborted = true;
            // A third press kills the client; the abort is already on its way.
            intr.restore_default();
            bar.clear();
            eprintln!("hytask: Ctrl-C: aborting the job under control");
            c.call("job.abort", Value::Null)?;
            return Ok(());
        }
        if self.held && !self.aborted && self.stdin_tty && enter_pressed() {
            self.held = false;
            eprintln!("hytask: resuming");
            c.call("job.resume", Value::Null)?;
        }
        Ok(())
    }
}

/// Whether a line is waiting on stdin (Enter pressed); consumes it.
fn enter_pressed() -> bool {
    use nix::poll::{poll, PollFd, PollFlags, PollTimeout};
    use std::os::fd::AsFd;
    let stdin = std::io::stdin();
    let mut fds = [PollFd::new(stdin.as_fd(), PollFlags::POLLIN)];
    if !matches!(poll(&mut fds, PollTimeout::ZERO), Ok(n) if n > 0) {
        return false;
    }
    let mut line = String::new();
    matches!(stdin.read_line(&mut line), Ok(n) if n > 0)
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
