//! Found by an abuse test: a 60-byte `job.load` (`o1 repeat [99999999] … o1 endrepeat`)
//! occupied job preparation for minutes, and every other `job.load` waited behind it on the
//! one-at-a-time lock. Now `job.abort`, an e-stop, the requesting client hanging up, or the
//! budget `[job] prepare_timeout_s` cancels a preparation in progress. Also here: `script.load`
//! with an unknown field answers invalid params (-32602) like every other method.
//!
//! The real daemon (simulated mill on a simulated clock). Every wait is a hang guard (60 s and
//! more); each test accepts every order in which the daemon may see the requests.
#![allow(clippy::unwrap_used)]

mod support;

use serde_json::{json, Value};
use std::io::{BufRead, BufReader, Write};
use std::os::unix::net::UnixStream;
use std::path::Path;
use std::sync::mpsc;
use std::time::{Duration, Instant};
use support::*;

const GUARD: Duration = Duration::from_secs(120);

/// Ten million iterations of a block that adds 200 terms: far longer than [`GUARD`] to the
/// loop limit, so a load that is not cancelled fails the test (the budget is set out of
/// the way, [`daemon`]).
fn runaway() -> String {
    format!(
        "o1 repeat [99999999]\n#1=[#1{}]\no1 endrepeat\nM2\n",
        "+1".repeat(200)
    )
}

/// The simulated mill with `[job] prepare_timeout_s` = `budget_s` (and the directory of its
/// configuration, kept while it runs). Its `[gcode] subroutine_path` holds `spin.ngc`, a
/// subroutine running the loop of [`runaway`]: `o<spin> call` is a one-line runaway MDI.
fn daemon(budget_s: f64) -> (Daemon, tempfile::TempDir) {
    let dir = tempfile::tempdir().unwrap();
    let config = sim_clock_config(dir.path(), SIM_SPEED, None);
    let subs = dir.path().join("subs");
    std::fs::create_dir(&subs).unwrap();
    let body = runaway().replace("M2\n", "");
    std::fs::write(
        subs.join("spin.ngc"),
        format!("o<spin> sub\n{body}o<spin> endsub\n"),
    )
    .unwrap();
    let mut text = std::fs::read_to_string(&config).unwrap();
    text.push_str(&format!(
        "\n[job]\nprepare_timeout_s = {budget_s:?}\n\n[gcode]\nsubroutine_path = [\"subs\"]\n"
    ));
    std::fs::write(&config, text).unwrap();
    (Daemon::start(&config), dir)
}
const SPIN: &str = "o<spin> call";
const SHORT: &str = "G21 G90\nG0 X20\nM2\n";

fn request_line(method: &str, params: Value) -> Vec<u8> {
    let mut line = json!({"id": 1, "method": method, "params": params}).to_string();
    line.push('\n');
    line.into_bytes()
}

fn load_line(text: &str) -> Vec<u8> {
    request_line("job.load", json!({ "text": text }))
}

fn mdi_line(line: &str) -> Vec<u8> {
    request_line("mdi", json!({ "line": line }))
}

/// Sends `job.load` of `text` on a connection of its own and waits (at most [`GUARD`]) for
/// the reply, on a thread; the reply arrives on the returned channel.
fn load_in_background(socket: &Path, text: &str) -> mpsc::Receiver<Value> {
    in_background(socket, load_line(text))
}

/// Sends the request `line` on a connection of its own; the reply arrives on the returned
/// channel (waited for at most [`GUARD`], on a thread).
fn in_background(socket: &Path, line: Vec<u8>) -> mpsc::Receiver<Value> {
    let mut s = UnixStream::connect(socket).unwrap();
    s.set_read_timeout(Some(GUARD)).unwrap();
    s.write_all(&line).unwrap();
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        let mut line = String::new();
        if BufReader::new(s).read_line(&mut line).is_ok() && !line.is_empty() {
            let _ = tx.send(serde_json::from_str::<Value>(&line).unwrap());
        }
    });
    rx
}

/// Calls `method` (its reply, error or not, is not the point) until `reply` has an answer.
fn repeat_until_answered(
    c: &mut hytask::control::client::Client,
    method: &str,
    reply: &mpsc::Receiver<Value>,
) -> Value {
    repeat_until_answered_with(c, method, reply, |_| ())
}

/// [`repeat_until_answered`], calling `between` before each call.
fn repeat_until_answered_with(
    c: &mut hytask::control::client::Client,
    method: &str,
    reply: &mpsc::Receiver<Value>,
    mut between: impl FnMut(&mut hytask::control::client::Client),
) -> Value {
    let t0 = Instant::now();
    loop {
        between(c);
        let _ = c.call(method, Value::Null);
        if let Ok(v) = reply.recv_timeout(Duration::from_millis(100)) {
            return v;
        }
        assert!(
            t0.elapsed() < GUARD,
            "the runaway preparation was not cancelled by {method}"
        );
    }
}

fn error_message(v: &Value) -> &str {
    v["error"]["message"]
        .as_str()
        .unwrap_or_else(|| panic!("not an error: {v}"))
}

#[test]
fn a_runaway_job_load_is_cancelled_by_job_abort_and_by_estop_and_the_next_load_succeeds() {
    let (d, _dir) = daemon(3600.0);
    let mut c = d.client();
    let reply = load_in_background(&d.socket, &runaway());
    let v = repeat_until_answered(&mut c, "job.abort", &reply);
    assert_eq!(v["error"]["code"], json!(2), "{v}");
    assert_eq!(
        error_message(&v),
        "failed: job preparation cancelled by job.abort"
    );
    let info = ok(
        &mut c,
        "job.load",
        json!({"text": SHORT, "name": "short.ngc"}),
    );
    assert_eq!(info["name"], json!("short.ngc"), "{info}");

    let reply = load_in_background(&d.socket, &runaway());
    let v = repeat_until_answered(&mut c, "estop", &reply);
    assert_eq!(
        error_message(&v),
        "failed: job preparation cancelled by an e-stop"
    );
    ok(&mut c, "job.load", json!({"text": SHORT}));
}

#[test]
fn a_client_hanging_up_cancels_its_job_load_and_a_waiting_load_then_runs() {
    let (d, _dir) = daemon(3600.0);
    let mut hung = UnixStream::connect(&d.socket).unwrap();
    hung.write_all(&load_line(&runaway())).unwrap();
    // Makes it likely (not required) that the runaway holds the lock before the next load.
    std::thread::sleep(Duration::from_millis(300));
    let waiting = load_in_background(&d.socket, SHORT);
    drop(hung);
    let v = waiting
        .recv_timeout(GUARD)
        .expect("the load behind a hung-up runaway was answered");
    assert_eq!(v["result"]["lines"], json!(3), "{v}");
}

#[test]
fn a_job_load_past_the_prepare_timeout_is_refused_naming_the_key() {
    let (d, _dir) = daemon(0.2);
    let v = load_in_background(&d.socket, &runaway())
        .recv_timeout(GUARD)
        .expect("answered");
    assert_eq!(v["error"]["code"], json!(4), "{v}");
    assert_eq!(
        error_message(&v),
        "timed out: job preparation took longer than 0.2 s (job.prepare_timeout_s)"
    );
}

/// Found in session 10: `mdi` had neither cancel nor budget; one line calling a runaway
/// subroutine held the preparation lock (every `job.load` behind it) to the loop limit.
#[test]
fn a_runaway_mdi_line_is_cancelled_by_job_abort_by_estop_and_by_its_client_hanging_up() {
    let (d, _dir) = daemon(3600.0);
    let mut c = d.client();
    ready(&mut c);
    let reply = in_background(&d.socket, mdi_line(SPIN));
    let v = repeat_until_answered(&mut c, "job.abort", &reply);
    assert_eq!(
        error_message(&v),
        "failed: MDI preparation cancelled by job.abort"
    );

    // The daemon may see the e-stop before the line (a loaded host delays the line's
    // thread): the line is then refused for the e-stop, and the test tries again.
    let mut cancelled = false;
    for _ in 0..20 {
        let reply = in_background(&d.socket, mdi_line(SPIN));
        let v = repeat_until_answered(&mut c, "estop", &reply);
        if error_message(&v) == "rejected: machine is in e-stop: reset it first" {
            ready(&mut c);
            continue;
        }
        assert_eq!(
            error_message(&v),
            "failed: MDI preparation cancelled by an e-stop"
        );
        cancelled = true;
        break;
    }
    assert!(cancelled, "every MDI line arrived after the e-stop");

    ready(&mut c);
    let mut hung = UnixStream::connect(&d.socket).unwrap();
    hung.write_all(&mdi_line(SPIN)).unwrap();
    // Makes it likely (not required) that the runaway holds the lock before the load.
    std::thread::sleep(Duration::from_millis(300));
    let waiting = load_in_background(&d.socket, SHORT);
    drop(hung);
    let v = waiting
        .recv_timeout(GUARD)
        .expect("the load behind a hung-up runaway MDI was answered");
    assert_eq!(v["result"]["lines"], json!(3), "{v}");
}

#[test]
fn an_mdi_line_past_the_prepare_timeout_is_refused_naming_the_key() {
    let (d, _dir) = daemon(0.2);
    let mut c = d.client();
    ready(&mut c);
    let v = in_background(&d.socket, mdi_line(SPIN))
        .recv_timeout(GUARD)
        .expect("answered");
    assert_eq!(v["error"]["code"], json!(4), "{v}");
    assert_eq!(
        error_message(&v),
        "timed out: MDI preparation took longer than 0.2 s (job.prepare_timeout_s)"
    );
    // An ordinary line still runs.
    ok(&mut c, "mdi", json!({"line": "G0 X20"}));
}

/// Found in session 10: the machine's own e-stop input (here the simulated one) stopped the
/// machine but not a preparation in progress; only the socket's `estop` did.
#[test]
fn the_estop_input_cancels_a_runaway_job_load() {
    let (d, _dir) = daemon(3600.0);
    let mut c = d.client();
    let reply = load_in_background(&d.socket, &runaway());
    // Released, reset, pressed again until the load answers: a press that lands before the
    // preparation began (or in e-stop already) cancels nothing, a later one does. A reset
    // refused because the release was not seen yet is as good.
    let input = |v: u8| json!({"name": "estop", "value": v});
    let v = repeat_until_answered_with(&mut c, "status", &reply, |c| {
        let _ = c.call("sim.input", input(0));
        let _ = c.call("estop.reset", Value::Null);
        let _ = c.call("sim.input", input(1));
    });
    assert_eq!(
        error_message(&v),
        "failed: job preparation cancelled by an e-stop"
    );
    wait_status(&mut c, "e-stop", GUARD, |s| s["mode"] == json!("estop"));
}

#[test]
fn script_load_with_an_unknown_field_is_invalid_params() {
    let d = Daemon::start_sim();
    let mut c = d.client();
    let (code, msg) = err(
        &mut c,
        "script.load",
        json!({"file": "p.st", "source": "PROGRAM p\nEND_PROGRAM\n", "sorce": 1}),
    );
    assert_eq!(code, -32602, "{msg}");
    assert!(msg.contains("unknown field `sorce`"), "{msg}");
    let (code, msg) = err(&mut c, "script.frobnicate", json!({}));
    assert_eq!(code, -32601, "{msg}");
}
