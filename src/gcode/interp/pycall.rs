//! The interpreter's side of embedded Python (see [`crate::gcode::python`]): Python O-word
//! procedures, `;py,` and `(py,…)` comments, and the answers to what Python asks while it
//! runs (parameters, canonical calls, its printed output).
//!
//! As in rs274: a Python procedure of the `oword` module is called before an `.ngc`
//! subroutine of the same name is looked for; it gets `self` and the call's arguments (as
//! floats, only as many as were given) and runs at the next call level, with its own local
//! named parameters but the caller's `#1`–`#30`; a float it returns sets `#<_value>` and
//! `#<_value_returned>` = 1, `None` clears both, a string is an error with that text, and any
//! other type (an int too) is an error. Its canonical calls are emitted as it makes them, in
//! its own numbers (no offsets, units or interpreter position are applied or updated, as in
//! rs274), and its printed lines appear in the trace where it prints them.

use super::Interp;
use crate::gcode::canon::CanonCmd;
use crate::gcode::expr::ParamSource;
use crate::gcode::params::Params;
use crate::gcode::python::{Bridge, Event, Key, PyError};
use crate::gcode::GcodeError;
use serde_json::{json, Value};
use std::collections::HashMap;

/// How a request ended.
struct Done {
    kind: String,
    value: Option<Value>,
}

impl Interp<'_> {
    /// An error about Python at the current line; the child is ended (its conversation is
    /// in an unknown state, and the run stops anyway).
    fn py_fail(&mut self, message: String) -> GcodeError {
        self.py = None;
        self.err(self.loc.col, message)
    }

    fn py_io(&mut self, what: &str, e: PyError) -> GcodeError {
        self.py_fail(format!("{what}: {e}"))
    }

    /// Starts the child (with the ini's `[PYTHON]` configuration, if any) and runs its
    /// start-up, once.
    fn py_start(&mut self) -> Result<(), GcodeError> {
        if self.py.is_some() {
            return Ok(());
        }
        let bridge =
            Bridge::spawn(self.opts.python.as_ref()).map_err(|e| self.err(1, e.to_string()))?;
        self.py = Some(bridge);
        let what = match self.opts.python.as_ref().and_then(|c| c.toplevel.as_ref()) {
            Some(t) => format!("Python start-up (TOPLEVEL {})", t.display()),
            None => "Python start-up".to_string(),
        };
        let done = self.py_run(&what)?;
        if done.kind != "ready" {
            return Err(self.py_fail(format!("{what}: no ready message")));
        }
        Ok(())
    }

    /// Sends `req` and serves the child's events until it is done.
    fn py_request(&mut self, req: &Value, what: &str) -> Result<Done, GcodeError> {
        self.py_start()?;
        let r = match self.py.as_mut() {
            Some(b) => b.send(req),
            None => return Err(self.py_fail(format!("{what}: Python is not running"))),
        };
        r.map_err(|e| self.py_io(what, e))?;
        self.py_run(what)
    }

    fn py_reply(&mut self, what: &str, v: &Value) -> Result<(), GcodeError> {
        let r = match self.py.as_mut() {
            Some(b) => b.send(v),
            None => return Err(self.py_fail(format!("{what}: Python is not running"))),
        };
        r.map_err(|e| self.py_io(what, e))
    }

    fn py_run(&mut self, what: &str) -> Result<Done, GcodeError> {
        // An error of the interpreter's own while Python runs (a limit on canonical calls):
        // Python is stopped with it, and it is the one reported.
        let mut stopped: Option<GcodeError> = None;
        loop {
            let cancel = self.opts.cancel.clone();
            let ev = match self.py.as_mut() {
                Some(b) => b.recv(cancel.as_deref()),
                None => return Err(self.py_fail(format!("{what}: Python is not running"))),
            };
            let ev = ev.map_err(|e| self.py_io(what, e))?;
            match ev {
                Event::Ready => {
                    return Ok(Done {
                        kind: "ready".into(),
                        value: None,
                    })
                }
                Event::Print { text } => self.py_print(&text)?,
                Event::Get { key } => {
                    let r = match self.py_get(&key) {
                        Ok(v) => json!({ "value": v }),
                        Err((kind, m)) => json!({ "error": m, "kind": kind }),
                    };
                    self.py_reply(what, &r)?;
                }
                Event::Set { key, value } => {
                    let r = match self.py_set(&key, value) {
                        Ok(()) => json!({ "ok": true }),
                        Err((kind, m)) => json!({ "error": m, "kind": kind }),
                    };
                    self.py_reply(what, &r)?;
                }
                Event::Level => {
                    let level = self.frames.len() + usize::from(self.py_in_call);
                    self.py_reply(what, &json!({ "value": level }))?;
                }
                Event::Canon { name, args, text } => {
                    let r = match self.py_canon(&name, &args, text) {
                        Ok(Ok(())) => json!({ "ok": true }),
                        Ok(Err(m)) => json!({ "error": m }),
                        Err(e) => {
                            let m = e.message.clone();
                            stopped = Some(e);
                            json!({ "error": m, "kind": "stop" })
                        }
                    };
                    self.py_reply(what, &r)?;
                }
                Event::Done { kind, value } => {
                    self.py_flush_print()?;
                    if let Some(e) = stopped {
                        self.py = None;
                        return Err(e);
                    }
                    return Ok(Done { kind, value });
                }
                Event::Error { msg, at } => {
                    self.py_flush_print()?;
                    if let Some(e) = stopped {
                        self.py = None;
                        return Err(e);
                    }
                    // where in the user's Python (not for a one-line `;py,` statement)
                    let at = if at.is_empty() || at.starts_with("<string>:") {
                        String::new()
                    } else {
                        format!(" (at {at})")
                    };
                    return Err(self.err(self.loc.col, format!("{what}: {msg}{at}")));
                }
            }
        }
    }

    /// Python's printed text: each whole line is a bare trace line, as rs274 prints it.
    fn py_print(&mut self, text: &str) -> Result<(), GcodeError> {
        self.py_out.push_str(text);
        while let Some(i) = self.py_out.find('\n') {
            let line: String = self.py_out.drain(..=i).collect();
            self.emit(CanonCmd::Print(line[..i].to_string()))?;
        }
        Ok(())
    }

    /// A last line without its newline, at the end of a request.
    fn py_flush_print(&mut self) -> Result<(), GcodeError> {
        if self.py_out.is_empty() {
            return Ok(());
        }
        let line = std::mem::take(&mut self.py_out);
        self.emit(CanonCmd::Print(line))
    }

    /// `self.params[key]`: (error kind, message) when there is no such parameter.
    fn py_get(&self, key: &Key) -> Result<f64, (&'static str, String)> {
        match key {
            Key::Num(n) => ParamSource::numbered(self, *n).map_err(|m| ("value", m)),
            Key::Name(s) => {
                let name = param_name(s);
                ParamSource::named(self, &name)
                    .ok_or_else(|| ("key", format!("unknown parameter name: {s}")))
            }
        }
    }

    /// `self.params[key] = value`, with the checks of an assignment in the program.
    fn py_set(&mut self, key: &Key, value: f64) -> Result<(), (&'static str, String)> {
        match key {
            Key::Num(n) => {
                let i = Params::index(*n).map_err(|m| ("value", m))?;
                if i == 0 {
                    return Err(("value", "Parameter #0 is read-only".into()));
                }
                self.p.numbered[i] = value;
            }
            Key::Name(s) => {
                let name = param_name(s);
                let ini = !self.opts.ini.is_empty() && self.opts.ini.lookup(&name).is_some();
                if ini || self.predefined(&name).is_some() {
                    return Err((
                        "value",
                        format!("can't assign value to parameter: {s} (read-only)"),
                    ));
                }
                self.p.set_named(&name, value);
            }
        }
        Ok(())
    }

    /// An `emccanon` call: `Err` for an error of the interpreter (it stops the run),
    /// `Ok(Err)` for one Python sees as an exception.
    fn py_canon(
        &mut self,
        name: &str,
        args: &[f64],
        text: Option<String>,
    ) -> Result<Result<(), String>, GcodeError> {
        let n = |k: usize| -> Result<(), String> {
            if args.len() == k {
                Ok(())
            } else {
                Err(format!(
                    "emccanon.{name}: {} arguments, expected {k}",
                    args.len()
                ))
            }
        };
        let cmd = match name {
            "STRAIGHT_FEED" | "STRAIGHT_TRAVERSE" => {
                if let Err(m) = n(crate::gcode::NUM_AXES) {
                    return Ok(Err(m));
                }
                let mut p = [0.0; crate::gcode::NUM_AXES];
                p.copy_from_slice(args);
                if name == "STRAIGHT_FEED" {
                    CanonCmd::StraightFeed(p)
                } else {
                    CanonCmd::StraightTraverse(p)
                }
            }
            "MESSAGE" => CanonCmd::Message(text.unwrap_or_default()),
            "COMMENT" => CanonCmd::Comment(text.unwrap_or_default()),
            "SET_FEED_RATE" | "DWELL" => {
                if let Err(m) = n(1) {
                    return Ok(Err(m));
                }
                if name == "DWELL" {
                    CanonCmd::Dwell(args[0])
                } else {
                    CanonCmd::SetFeedRate(args[0])
                }
            }
            "MIST_ON" => CanonCmd::MistOn,
            "MIST_OFF" => CanonCmd::MistOff,
            "FLOOD_ON" => CanonCmd::FloodOn,
            "FLOOD_OFF" => CanonCmd::FloodOff,
            _ => return Ok(Err(format!("emccanon.{name} is not supported by hytask"))),
        };
        self.emit(cmd).map(Ok)
    }

    /// A `;py,` or `(py,…)` comment: `code` runs in the Python module context (TOPLEVEL's
    /// namespace, where `interpreter.this` is `self`). Only where the options enable Python
    /// ([`crate::gcode::InterpOptions::python`]): a program alone must not run code on the
    /// host (a job sent to the daemon would run it as the daemon's user), so without that
    /// it is an ordinary comment.
    pub(super) fn py_exec(&mut self, code: &str) -> Result<(), GcodeError> {
        if self.opts.python.is_none() {
            return Ok(());
        }
        let what = format!("Python statement '{code}'");
        self.py_request(&json!({ "op": "exec", "code": code }), &what)?;
        Ok(())
    }

    /// Calls the Python O-word procedure `label` if the ini's `[PYTHON]` TOPLEVEL defines
    /// one (`oword.label`); false when it does not (or there is no `[PYTHON]` section).
    pub(super) fn py_oword(&mut self, label: &str, args: &[f64]) -> Result<bool, GcodeError> {
        if self.opts.python.is_none() {
            return Ok(false);
        }
        let what = format!("Python O-word procedure o<{label}>");
        let has = self.py_request(&json!({ "op": "has", "name": label }), &what)?;
        if has.value != Some(Value::Bool(true)) {
            return Ok(false);
        }
        self.p.locals.push(HashMap::new());
        self.py_in_call = true;
        let r = self.py_request(&json!({ "op": "call", "name": label, "args": args }), &what);
        self.py_in_call = false;
        self.p.locals.pop();
        let done = r?;
        match (done.kind.as_str(), done.value) {
            ("none", _) => {
                self.s.value = 0.0;
                self.s.value_returned = 0.0;
            }
            ("float", Some(v)) => {
                self.s.value = v.as_f64().unwrap_or(f64::NAN);
                self.s.value_returned = 1.0;
            }
            ("str", Some(Value::String(s))) => {
                return Err(self.err(self.loc.col, format!("o<{label}>: {s}")));
            }
            (kind, v) => {
                let v = v.map(|v| v.as_str().map_or(v.to_string(), str::to_string));
                return Err(self.err(
                    self.loc.col,
                    format!(
                        "{what} returned {kind} {}: expected a float or None (rs274 refuses any other type, an int too)",
                        v.unwrap_or_default()
                    ),
                ));
            }
        }
        Ok(true)
    }
}

/// A named parameter as the interpreter stores it: lower case, without spaces.
fn param_name(s: &str) -> String {
    s.chars()
        .filter(|c| !c.is_whitespace())
        .map(|c| c.to_ascii_lowercase())
        .collect()
}
