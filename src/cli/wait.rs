//! Waiting for a motion the operator started (`home`, `mdi`, `jog --distance`, and the
//! homing of `hytask run`) until the machine is idle again, with progress on a terminal, the
//! outcome as a result (the error names why the motion ended early), and Ctrl-C stopping the
//! motion under control.
//!
//! The wait follows the control socket's events (`mode`, `fault`, `job`): the caller
//! subscribes ([`subscribe`]) *before* it starts the motion, so no event is missed. Status is
//! read when an event arrives and otherwise every [`poll_interval`]: 200 ms on a terminal
//! (the per-axis homing line moves), 1 s otherwise (only a lost event's fallback).

use super::interrupt::Interrupts;
use crate::control::client::Client;
use serde_json::{json, Value};
use std::io::{IsTerminal, Write};
use std::time::Duration;

/// What is being waited for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Motion {
    /// Homing of these axes (letters); all axes when empty.
    Home,
    /// One MDI line.
    Mdi,
    /// An incremental jog.
    Jog,
}

impl Motion {
    fn noun(self) -> &'static str {
        match self {
            Motion::Home => "homing",
            Motion::Mdi => "MDI line",
            Motion::Jog => "jog",
        }
    }
}

/// How a wait ended.
#[derive(Debug, thiserror::Error)]
pub enum WaitError {
    /// The motion ended without doing all of its work (fault, e-stop, abort).
    #[error("{0}")]
    Failed(String),
    /// The operator pressed Ctrl-C and the motion was stopped under control.
    #[error("{0} stopped by Ctrl-C")]
    Interrupted(&'static str),
    /// Talking to the daemon failed.
    #[error(transparent)]
    Client(#[from] crate::control::client::ClientError),
}

/// Subscribes `c` to the events a wait follows. Call before starting the motion.
pub fn subscribe(c: &mut Client) -> Result<(), WaitError> {
    c.call("subscribe", json!({"topics": ["mode", "fault", "job"]}))?;
    Ok(())
}

/// Status reads between events: frequent enough to move a terminal's progress line, rare
/// otherwise.
pub fn poll_interval(tty: bool) -> Duration {
    Duration::from_millis(if tty { 200 } else { 1000 })
}

/// Waits until `motion`, just started on `c`, has ended. `axes` are the axes homing is
/// expected to home (ignored for other motions).
pub fn until_idle(
    c: &mut Client,
    motion: Motion,
    axes: &[String],
    intr: &mut Interrupts,
) -> Result<(), WaitError> {
    let tty = std::io::stderr().is_terminal();
    let mut line = StatusLine::new(tty);
    let mut stopping = false;
    let mut faults: Vec<String> = Vec::new();
    loop {
        if intr.take() > 0 && !stopping {
            stopping = true;
            line.clear();
            eprintln!(
                "hytask: Ctrl-C: stopping the {} under control (Ctrl-C again leaves at once)",
                motion.noun()
            );
            // A second press kills the client; the machine is already stopping.
            intr.restore_default();
            c.call("job.abort", Value::Null)?;
        }
        let s = c.call("status", Value::Null)?;
        match s["mode"].as_str().unwrap_or("") {
            "idle" => {
                line.clear();
                if stopping {
                    return Err(WaitError::Interrupted(motion.noun()));
                }
                return outcome(motion, axes, &s);
            }
            "fault" | "estop" => {
                line.clear();
                let mut why: Vec<String> = faults;
                if why.is_empty() {
                    why = s["faults"]
                        .as_array()
                        .into_iter()
                        .flatten()
                        .filter_map(Value::as_str)
                        .map(str::to_string)
                        .collect();
                }
                return Err(WaitError::Failed(format!(
                    "{} stopped: machine in {} ({})",
                    motion.noun(),
                    s["mode"].as_str().unwrap_or(""),
                    if why.is_empty() {
                        "no fault recorded".to_string()
                    } else {
                        why.join("; ")
                    }
                )));
            }
            _ => line.draw(motion, axes, &s),
        }
        // Sleep until an event (any topic may mean the end) or the poll interval.
        if let Some(ev) = c.next_event(poll_interval(tty))? {
            if ev.topic == "fault" {
                if let Some(m) = ev.data["message"].as_str() {
                    faults.push(m.to_string());
                }
            }
        }
    }
}

/// Whether a motion that ended with the machine idle did its work.
fn outcome(motion: Motion, axes: &[String], s: &Value) -> Result<(), WaitError> {
    match motion {
        Motion::Home => {
            let unhomed: Vec<&str> = axis_list(s)
                .filter(|a| a["homed"] != json!(true))
                .filter_map(|a| a["name"].as_str())
                .filter(|n| axes.is_empty() || axes.iter().any(|x| x.eq_ignore_ascii_case(n)))
                .collect();
            if unhomed.is_empty() {
                Ok(())
            } else {
                Err(WaitError::Failed(format!(
                    "homing ended with {} not homed",
                    unhomed.join(" ")
                )))
            }
        }
        Motion::Mdi => {
            let job = &s["job"];
            match job["state"].as_str().unwrap_or("") {
                "aborted" | "failed" => Err(WaitError::Failed(format!(
                    "MDI line {}: {}",
                    job["state"].as_str().unwrap_or(""),
                    job["reason"].as_str().unwrap_or("no reason given")
                ))),
                _ => Ok(()),
            }
        }
        Motion::Jog => Ok(()),
    }
}

fn axis_list(s: &Value) -> impl Iterator<Item = &Value> {
    s["axes"].as_array().into_iter().flatten()
}

/// One line of progress redrawn in place on a terminal; on a pipe, a line per axis homed.
struct StatusLine {
    tty: bool,
    drawn: bool,
    homed: Vec<String>,
}

impl StatusLine {
    fn new(tty: bool) -> Self {
        StatusLine {
            tty,
            drawn: false,
            homed: Vec::new(),
        }
    }

    fn draw(&mut self, motion: Motion, axes: &[String], s: &Value) {
        let wanted = |n: &str| axes.is_empty() || axes.iter().any(|x| x.eq_ignore_ascii_case(n));
        let mut text = String::new();
        for a in axis_list(s) {
            let name = a["name"].as_str().unwrap_or("?");
            let pos = a["actual"].as_f64().unwrap_or(f64::NAN);
            let moving = a["velocity"].as_f64().unwrap_or(0.0).abs() > 1e-6;
            let state = match motion {
                Motion::Home if !wanted(name) => continue,
                Motion::Home if a["homed"] == json!(true) => {
                    if !self.homed.iter().any(|h| h == name) {
                        self.homed.push(name.to_string());
                        if !self.tty {
                            eprintln!("hytask: {name} homed");
                        }
                    }
                    "homed"
                }
                Motion::Home if moving => "homing",
                Motion::Home => "waiting",
                _ => "",
            };
            text.push_str(&format!("  {name} {pos:9.3} {state}"));
        }
        if self.tty {
            eprint!("\r{}:{}   ", motion.noun(), text.trim_end());
            let _ = std::io::stderr().flush();
            self.drawn = true;
        }
    }

    fn clear(&mut self) {
        if self.tty && self.drawn {
            eprint!("\r{}\r", " ".repeat(78));
            let _ = std::io::stderr().flush();
            self.drawn = false;
        }
    }
}
