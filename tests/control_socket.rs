//! Control socket robustness, against a machine double: malformed and oversized requests,
//! unknown methods, event push and lag, slow and vanished clients, many concurrent clients.
//! The real daemon is exercised end to end in `tests/daemon_e2e.rs`.
#![allow(clippy::unwrap_used)]

use hytask::control::access::{AccessPolicy, Ids};
use hytask::control::client::{Client, ClientError};
use hytask::control::server::{bind, serve_with, ServerOptions, SocketOptions};
use hytask::machine::api::*;
use serde_json::{json, Value};
use std::io::{BufRead, BufReader, Read, Write};
use std::os::unix::net::UnixStream;
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};
use tokio::sync::broadcast;

/// Hang guard of every wait on the server's threads.
const GUARD: Duration = Duration::from_secs(60);

struct Double {
    events: broadcast::Sender<MachineEvent>,
    estops: AtomicU32,
    /// `job.load` of a job named "block" waits here until the sender is dropped.
    gate: std::sync::Mutex<Option<std::sync::mpsc::Receiver<()>>>,
    entered: std::sync::atomic::AtomicBool,
}

impl Double {
    fn new() -> Double {
        Double {
            events: broadcast::channel(64).0,
            estops: AtomicU32::new(0),
            gate: std::sync::Mutex::new(None),
            entered: std::sync::atomic::AtomicBool::new(false),
        }
    }
}

impl hytask::daemon::Deployed for Double {
    fn name(&self) -> String {
        "double".into()
    }
    fn realtime(&self) -> bool {
        false
    }
    fn servo_cycles(&self) -> u64 {
        0
    }
    fn shutdown(&self) -> anyhow::Result<()> {
        Ok(())
    }
}

impl MachineApi for Double {
    fn status(&self) -> Status {
        Status {
            machine: "double".into(),
            mode: Mode::Idle,
            realtime: false,
            servo_cycle: 0,
            axes: vec![],
            job: JobStatus::default(),
            overrides: Overrides::default(),
            spindle_rpm: 0.0,
            faults: vec![],
            threads: vec![],
            inputs: Default::default(),
            outputs: Default::default(),
            probe: Default::default(),
            optional_stop: false,
            plc: None,
        }
    }
    fn estop(&self) -> Result<(), ApiError> {
        self.estops.fetch_add(1, Ordering::SeqCst);
        Ok(())
    }
    fn estop_reset(&self) -> Result<(), ApiError> {
        Err(ApiError::Rejected("e-stop input still active".into()))
    }
    fn machine_on(&self) -> Result<(), ApiError> {
        Ok(())
    }
    fn machine_off(&self) -> Result<(), ApiError> {
        Ok(())
    }
    fn home(&self, axis: Option<&str>) -> Result<(), ApiError> {
        match axis {
            Some("Q") => Err(ApiError::InvalidParams("no axis Q".into())),
            _ => Ok(()),
        }
    }
    fn jog(&self, _: &JogRequest) -> Result<(), ApiError> {
        Ok(())
    }
    fn jog_stop(&self) -> Result<(), ApiError> {
        Ok(())
    }
    fn mdi(&self, _: &str) -> Result<(), ApiError> {
        Ok(())
    }
    fn job_load(&self, src: &JobSource) -> Result<JobInfo, ApiError> {
        if src.name.as_deref() == Some("block") {
            let gate = self.gate.lock().unwrap().take();
            self.entered.store(true, Ordering::SeqCst);
            if let Some(rx) = gate {
                let _ = rx.recv();
            }
        }
        Ok(JobInfo {
            name: src.name.clone().unwrap_or_default(),
            lines: 1,
            commands: 1,
            planned_time_s: 0.0,
            distance_mm: 0.0,
        })
    }
    fn job_run(&self) -> Result<(), ApiError> {
        Ok(())
    }
    fn job_pause(&self) -> Result<(), ApiError> {
        Ok(())
    }
    fn job_resume(&self) -> Result<(), ApiError> {
        Ok(())
    }
    fn job_abort(&self) -> Result<(), ApiError> {
        Ok(())
    }
    fn job_step(&self) -> Result<(), ApiError> {
        Ok(())
    }
    fn set_overrides(&self, r: &OverrideRequest) -> Result<Overrides, ApiError> {
        Ok(Overrides {
            feed: r.feed.unwrap_or(1.0),
            ..Overrides::default()
        })
    }
    fn tasks(&self) -> Vec<TaskInfo> {
        vec![]
    }
    fn call(&self, task: &str, op: &str, _: &Value) -> Result<Value, ApiError> {
        Err(ApiError::InvalidParams(format!("no operation {task}.{op}")))
    }
    fn set_sim_input(&self, _: &str, _: f64) -> Result<(), ApiError> {
        Ok(())
    }
    fn sim_fault(&self, _: &SimFault) -> Result<(), ApiError> {
        Err(ApiError::NotSupported("no simulation here".into()))
    }
    fn subscribe(&self) -> broadcast::Receiver<MachineEvent> {
        self.events.subscribe()
    }
}

struct Server {
    _dir: tempfile::TempDir,
    path: std::path::PathBuf,
    machine: Arc<Double>,
    stop: Option<tokio::sync::oneshot::Sender<()>>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Server {
    fn start() -> Server {
        Self::start_with(ServerOptions::default())
    }

    fn start_with(opts: ServerOptions) -> Server {
        Self::start_in(tempfile::tempdir().unwrap(), 0o660, opts)
    }

    fn start_in(dir: tempfile::TempDir, mode: u32, opts: ServerOptions) -> Server {
        let path = dir.path().join("control.sock");
        let machine = Arc::new(Double::new());
        let listener = bind(&SocketOptions {
            path: path.clone(),
            mode,
            group: None,
        })
        .unwrap();
        let (tx, rx) = tokio::sync::oneshot::channel::<()>();
        let m: Arc<dyn MachineApi> = machine.clone();
        let thread = std::thread::spawn(move || {
            let (listener, claim) = listener.into_parts();
            let rt = tokio::runtime::Builder::new_multi_thread()
                .worker_threads(2)
                .enable_all()
                .build()
                .unwrap();
            rt.block_on(async move {
                let l = tokio::net::UnixListener::from_std(listener).unwrap();
                serve_with(l, m, opts, async {
                    let _ = rx.await;
                })
                .await;
            });
            drop(claim);
        });
        Server {
            _dir: dir,
            path,
            machine,
            stop: Some(tx),
            thread: Some(thread),
        }
    }
}

impl Drop for Server {
    fn drop(&mut self) {
        if let Some(s) = self.stop.take() {
            let _ = s.send(());
        }
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

fn raw(path: &std::path::Path) -> (BufReader<UnixStream>, UnixStream) {
    let s = UnixStream::connect(path).unwrap();
    s.set_read_timeout(Some(GUARD)).unwrap();
    (BufReader::new(s.try_clone().unwrap()), s)
}

fn read_json(r: &mut BufReader<UnixStream>) -> Value {
    let mut line = String::new();
    r.read_line(&mut line).unwrap();
    serde_json::from_str(&line).unwrap()
}

#[test]
fn socket_has_configured_mode_and_refuses_a_second_daemon() {
    use std::os::unix::fs::PermissionsExt;
    let srv = Server::start();
    let mode = std::fs::metadata(&srv.path).unwrap().permissions().mode() & 0o777;
    assert_eq!(mode, 0o660);
    let err = bind(&SocketOptions {
        path: srv.path.clone(),
        mode: 0o660,
        group: None,
    })
    .unwrap_err();
    assert!(err.to_string().contains("already listening"), "{err}");
}

#[test]
fn malformed_and_unknown_requests_get_errors_and_the_connection_survives() {
    let srv = Server::start();
    let (mut r, mut w) = raw(&srv.path);
    w.write_all(b"{this is not json\n").unwrap();
    assert_eq!(read_json(&mut r)["error"]["code"], json!(-32700));
    w.write_all(b"[1,2,3]\n").unwrap();
    assert_eq!(read_json(&mut r)["error"]["code"], json!(-32600));
    w.write_all(b"{\"id\":9,\"method\":\"sttaus\"}\n").unwrap();
    let v = read_json(&mut r);
    assert_eq!(v["id"], json!(9));
    assert_eq!(v["error"]["code"], json!(-32601));
    assert!(v["error"]["message"].as_str().unwrap().contains("status"));
    w.write_all(b"{\"id\":10,\"method\":\"status\",\"params\":{\"x\":1}}\n")
        .unwrap();
    assert_eq!(read_json(&mut r)["error"]["code"], json!(-32602));
    w.write_all(b"{\"id\":11,\"method\":\"override\",\"params\":{\"feed\":7}}\n")
        .unwrap();
    let v = read_json(&mut r);
    assert!(v["error"]["message"].as_str().unwrap().contains("feed"));
    // An absurd value is quoted short, not as 309 digits.
    w.write_all(b"{\"id\":13,\"method\":\"override\",\"params\":{\"rapid\":1e308}}\n")
        .unwrap();
    let v = read_json(&mut r);
    assert_eq!(
        v["error"]["message"],
        json!("rapid must be within 0..=1, got 1e308")
    );
    // Blank lines are ignored; the next request still works.
    w.write_all(b"\n\n{\"id\":12,\"method\":\"status\"}\n")
        .unwrap();
    let v = read_json(&mut r);
    assert_eq!(v["id"], json!(12));
    assert_eq!(v["result"]["machine"], json!("double"));
}

#[test]
fn machine_refusals_map_to_their_codes() {
    let srv = Server::start();
    let mut c = Client::connect(&srv.path).unwrap();
    match c.call("estop.reset", Value::Null) {
        Err(ClientError::Remote { code: 1, message }) => assert!(message.contains("e-stop")),
        other => panic!("{other:?}"),
    }
    match c.call("home", json!({"axis": "Q"})) {
        Err(ClientError::Remote { code: -32602, .. }) => {}
        other => panic!("{other:?}"),
    }
    match c.call("job.load", json!({"path": "a", "text": "b"})) {
        Err(ClientError::Remote {
            code: -32602,
            message,
        }) => assert!(message.contains("exactly one")),
        other => panic!("{other:?}"),
    }
    c.call("estop", Value::Null).unwrap();
    assert_eq!(srv.machine.estops.load(Ordering::SeqCst), 1);
}

#[test]
fn oversized_request_is_refused_and_the_connection_stays_usable() {
    let srv = Server::start();
    let (mut r, mut w) = raw(&srv.path);
    let writer = std::thread::spawn(move || {
        let big = vec![b'x'; hytask::control::protocol::MAX_REQUEST_BYTES + 10];
        w.write_all(&big).unwrap();
        w.write_all(b"\n{\"id\":2,\"method\":\"status\"}\n")
            .unwrap();
        w
    });
    let v = read_json(&mut r);
    assert_eq!(v["error"]["code"], json!(-32600));
    assert!(v["error"]["message"].as_str().unwrap().contains("larger"));
    let v = read_json(&mut r);
    assert_eq!(v["id"], json!(2));
    drop(writer.join().unwrap());
}

#[test]
fn subscribed_clients_receive_events_and_slow_ones_are_told_they_lagged() {
    // A write timeout past the hang guard: the slow client's stalled writes must outlast a
    // loaded host's pause between the flood and the drain (the default 5 s would disconnect
    // it; that is a_stalled_subscriber_is_disconnected_and_frees_its_slot's business).
    let srv = Server::start_with(ServerOptions {
        write_timeout: GUARD,
        ..ServerOptions::default()
    });
    let mut fast = Client::connect(&srv.path).unwrap();
    let topics = fast.call("subscribe", json!({"topics": ["mode"]})).unwrap();
    assert_eq!(topics["topics"], json!(["mode"]));
    match fast.call("subscribe", json!({"topics": ["nope"]})) {
        Err(ClientError::Remote { code: -32602, .. }) => {}
        other => panic!("{other:?}"),
    }
    // The failed subscribe left the old subscription in place.
    let ev = |topic: &str, n: u64| MachineEvent {
        topic: topic.into(),
        data: json!({"n": n}),
    };
    srv.machine.events.send(ev("fault", 0)).unwrap();
    srv.machine.events.send(ev("mode", 1)).unwrap();
    let e = fast.next_event(GUARD).unwrap().unwrap();
    assert_eq!((e.topic.as_str(), &e.data), ("mode", &json!({"n": 1})));

    // A client that subscribes and never reads: flood it; the daemon and the other
    // client stay responsive, and the slow one is told how much it missed.
    let (mut slow_r, mut slow_w) = raw(&srv.path);
    slow_w
        .write_all(b"{\"id\":1,\"method\":\"subscribe\"}\n")
        .unwrap();
    let _ = read_json(&mut slow_r);
    for n in 0..5000 {
        let _ = srv.machine.events.send(ev("progress", n));
        if n % 500 == 0 {
            std::thread::sleep(Duration::from_millis(2));
        }
    }
    // Answered at all: a server blocked on the slow client would never answer, and the
    // client's own read timeout turns that into an error (a hang guard, not a timing).
    fast.call("status", Value::Null).unwrap();
    let mut lagged = false;
    let mut buf = String::new();
    // Drain what was queued; then one more event must produce a `lagged` notice.
    let mut drained = 0;
    let mut all = Vec::new();
    let mut chunk = [0u8; 65536];
    slow_r
        .get_ref()
        .set_read_timeout(Some(Duration::from_millis(500)))
        .unwrap();
    while let Ok(n) = slow_r.read(&mut chunk) {
        if n == 0 {
            break;
        }
        all.extend_from_slice(&chunk[..n]);
        drained += n;
    }
    assert!(drained > 0);
    // Delivery resumes after the lag: later events arrive.
    for n in 0..10 {
        srv.machine
            .events
            .send(ev("progress", 100_000 + n))
            .unwrap();
        std::thread::sleep(Duration::from_millis(10));
    }
    // The drain above may stop early on a loaded host (the server's writer not scheduled for
    // 500 ms): read on, through whatever of the backlog is left, until an event sent after
    // the lag (n = 100000 and up; the flood's n are below 5000) arrives (hang guard 60 s).
    slow_r.get_ref().set_read_timeout(Some(GUARD)).unwrap();
    let mut resumed = false;
    loop {
        buf.clear();
        let n = slow_r
            .read_line(&mut buf)
            .map_err(|e| format!("{e}; drained {} bytes", all.len()))
            .unwrap();
        if n == 0 {
            break;
        }
        lagged |= buf.contains("\"lagged\"");
        if buf.contains("\"n\":10000") {
            resumed = true;
            break;
        }
    }
    assert!(resumed, "events stopped after the lag");
    let text = String::from_utf8_lossy(&all);
    assert!(lagged || text.contains("\"lagged\""), "no lagged notice");
}

#[test]
fn vanished_clients_do_not_disturb_others_and_fifty_clients_are_served() {
    let srv = Server::start();
    for _ in 0..20 {
        let mut s = UnixStream::connect(&srv.path).unwrap();
        s.write_all(b"{\"id\":1,\"method\":\"status\"}").unwrap();
        drop(s); // vanish mid-request
    }
    let path = srv.path.clone();
    let handles: Vec<_> = (0..50)
        .map(|_| {
            let path = path.clone();
            std::thread::spawn(move || {
                let mut c = Client::connect(&path).unwrap();
                for _ in 0..20 {
                    let s = c.call("status", Value::Null).unwrap();
                    assert_eq!(s["mode"], json!("idle"));
                }
            })
        })
        .collect();
    for h in handles {
        h.join().unwrap();
    }
}

/// Reads until the daemon closes the connection (hang guard 60 s); returns what it sent.
fn read_to_close(s: &mut UnixStream) -> String {
    s.set_read_timeout(Some(Duration::from_secs(60))).unwrap();
    let mut all = Vec::new();
    let mut chunk = [0u8; 4096];
    loop {
        match s.read(&mut chunk) {
            Ok(0) => break,
            Ok(n) => all.extend_from_slice(&chunk[..n]),
            Err(e) if e.kind() == std::io::ErrorKind::ConnectionReset => break,
            Err(e) => panic!(
                "connection not closed: {e}; got {:?}",
                String::from_utf8_lossy(&all)
            ),
        }
    }
    String::from_utf8_lossy(&all).into_owned()
}

#[test]
fn a_final_request_without_newline_is_answered_at_end_of_input() {
    let srv = Server::start();
    let mut s = UnixStream::connect(&srv.path).unwrap();
    s.write_all(br#"{"id":1,"method":"estop"}"#).unwrap();
    s.shutdown(std::net::Shutdown::Write).unwrap();
    let reply = read_to_close(&mut s);
    let v: Value = serde_json::from_str(reply.trim()).unwrap();
    assert_eq!(v, json!({"id": 1, "result": {"ok": true}}));
    assert_eq!(srv.machine.estops.load(Ordering::SeqCst), 1);
}

#[test]
fn estop_gets_through_while_every_client_slot_is_held_by_idle_connections() {
    let srv = Server::start_with(ServerOptions {
        max_clients: 8,
        ..ServerOptions::default()
    });
    // Fill every slot, and make sure each is being served (not just queued in the backlog).
    let mut held: Vec<Client> = (0..8)
        .map(|_| Client::connect(&srv.path).unwrap())
        .collect();
    for c in &mut held {
        c.call("status", Value::Null).unwrap();
    }
    let mut s = UnixStream::connect(&srv.path).unwrap();
    s.write_all(b"{\"id\":7,\"method\":\"estop\"}\n").unwrap();
    let v: Value = serde_json::from_str(read_to_close(&mut s).trim()).unwrap();
    assert_eq!(v, json!({"id": 7, "result": {"ok": true}}));
    assert_eq!(srv.machine.estops.load(Ordering::SeqCst), 1);
    // Anything else on an over-limit connection is refused, and says why.
    let mut s = UnixStream::connect(&srv.path).unwrap();
    s.write_all(b"{\"id\":8,\"method\":\"status\"}\n").unwrap();
    let v: Value = serde_json::from_str(read_to_close(&mut s).trim()).unwrap();
    let m = v["error"]["message"].as_str().unwrap();
    assert!(m.contains("too many clients") && m.contains("estop"), "{m}");
    // The held connections still work.
    held[0].call("status", Value::Null).unwrap();
}

#[test]
fn idle_connections_are_closed_and_free_their_slot() {
    let srv = Server::start_with(ServerOptions {
        max_clients: 1,
        idle_timeout: Some(Duration::from_millis(500)),
        ..ServerOptions::default()
    });
    let mut idle = UnixStream::connect(&srv.path).unwrap();
    let said = read_to_close(&mut idle);
    assert!(said.contains("control.idle_timeout_s"), "{said}");
    // The slot is free again: a normal client is served.
    let t0 = Instant::now();
    loop {
        let mut c = Client::connect(&srv.path).unwrap();
        match c.call("status", Value::Null) {
            Ok(s) => {
                assert_eq!(s["machine"], json!("double"));
                break;
            }
            Err(e) => assert!(t0.elapsed() < Duration::from_secs(60), "{e}"),
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}

#[test]
fn a_subscriber_receiving_events_is_not_idle() {
    let srv = Server::start_with(ServerOptions {
        idle_timeout: Some(Duration::from_secs(3)),
        ..ServerOptions::default()
    });
    let mut c = Client::connect(&srv.path).unwrap();
    c.call("subscribe", json!({"topics": ["progress"]}))
        .unwrap();
    // Events for twice the idle timeout, without a request.
    for n in 0..120 {
        let _ = srv.machine.events.send(MachineEvent {
            topic: "progress".into(),
            data: json!({"n": n}),
        });
        std::thread::sleep(Duration::from_millis(50));
    }
    // Every event arrives, up to the last (hang guard: the server may lag on a loaded host).
    let mut last = None;
    while last != Some(json!(119)) {
        let e = c.next_event(GUARD).unwrap();
        last = Some(e.expect("events stopped before n = 119").data["n"].clone());
    }
    c.call("status", Value::Null).unwrap();
}

#[test]
fn a_stalled_subscriber_is_disconnected_and_frees_its_slot() {
    let srv = Server::start_with(ServerOptions {
        max_clients: 1,
        write_timeout: Duration::from_millis(200),
        ..ServerOptions::default()
    });
    let (mut r, mut w) = raw(&srv.path);
    w.write_all(b"{\"id\":1,\"method\":\"subscribe\"}\n")
        .unwrap();
    assert_eq!(read_json(&mut r)["id"], json!(1));
    // Never read again; flood it until its socket buffer fills and the write stalls.
    let big = "x".repeat(16 * 1024);
    let t0 = Instant::now();
    loop {
        for _ in 0..50 {
            let _ = srv.machine.events.send(MachineEvent {
                topic: "progress".into(),
                data: json!({"pad": big}),
            });
        }
        std::thread::sleep(Duration::from_millis(20));
        let mut c = Client::connect(&srv.path).unwrap();
        if c.call("status", Value::Null).is_ok() {
            break; // served: the stalled client's slot was freed
        }
        assert!(
            t0.elapsed() < Duration::from_secs(60),
            "the stalled subscriber still holds the only slot"
        );
    }
    drop((r, w));
}

#[test]
fn unfinished_lines_are_capped_in_total_across_clients() {
    let srv = Server::start_with(ServerOptions {
        max_buffered_bytes: 2 * 1024 * 1024,
        ..ServerOptions::default()
    });
    // Eight clients each send 1 MiB without a newline: 8 MiB against a 2 MiB budget.
    let (tx, rx) = std::sync::mpsc::channel::<String>();
    let streams: Vec<UnixStream> = (0..8)
        .map(|_| {
            let s = UnixStream::connect(&srv.path).unwrap();
            let mut w = s.try_clone().unwrap();
            std::thread::spawn(move || {
                let _ = w.write_all(&vec![b' '; 1024 * 1024]);
            });
            let r = s.try_clone().unwrap();
            let tx = tx.clone();
            std::thread::spawn(move || {
                let mut line = String::new();
                if BufReader::new(r).read_line(&mut line).is_ok() && !line.is_empty() {
                    let _ = tx.send(line);
                }
            });
            s
        })
        .collect();
    // Clients over the budget are told and closed; those within it wait for the rest of
    // their line (they get no answer).
    let mut refused = 0;
    while refused < 5 {
        let line = rx
            .recv_timeout(Duration::from_secs(60))
            .unwrap_or_else(|_| panic!("only {refused} of 8 clients were refused"));
        let v: Value = serde_json::from_str(line.trim()).unwrap();
        let m = v["error"]["message"].as_str().unwrap();
        assert!(m.contains("control.max_buffered_bytes"), "{m}");
        refused += 1;
    }
    // Others are still served, small requests within their free allowance.
    let mut c = Client::connect(&srv.path).unwrap();
    c.call("status", Value::Null).unwrap();
    for s in streams {
        let _ = s.shutdown(std::net::Shutdown::Both);
    }
}

#[test]
fn observers_may_watch_and_estop_but_not_move_operators_may() {
    // A client process running as `nobody` against roles that list only uid 65534's
    // group as observers; root (this test) is always an operator.
    use std::os::unix::fs::PermissionsExt;
    let dir = tempfile::tempdir().unwrap();
    std::fs::set_permissions(dir.path(), std::fs::Permissions::from_mode(0o755)).unwrap();
    let mut access = AccessPolicy {
        enabled: true,
        operators: Ids::default(),
        observers: Ids::default(),
        unlisted: Some(hytask::control::access::Role::Observer),
        daemon_uid: 0,
    };
    access.operators.uids.insert(4242);
    let srv = Server::start_in(
        dir,
        0o666,
        ServerOptions {
            access,
            ..ServerOptions::default()
        },
    );
    let as_nobody = |args: &[&str]| {
        use std::os::unix::process::CommandExt;
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_hytask"))
            .args(args)
            .arg("--socket")
            .arg(&srv.path)
            .uid(65534)
            .gid(65534)
            .output()
            .unwrap();
        (
            out.status.success(),
            String::from_utf8_lossy(&out.stdout).into_owned()
                + &String::from_utf8_lossy(&out.stderr),
        )
    };
    let (ok, out) = as_nobody(&["status", "--json"]);
    assert!(ok && out.contains("double"), "{out}");
    let (ok, out) = as_nobody(&["on"]);
    assert!(!ok && out.contains("operator role"), "{out}");
    let (ok, out) = as_nobody(&["home"]);
    assert!(!ok && out.contains("operator role"), "{out}");
    let (ok, out) = as_nobody(&["estop"]);
    assert!(ok, "{out}");
    assert_eq!(srv.machine.estops.load(Ordering::SeqCst), 1);
    // root is an operator.
    let mut c = Client::connect(&srv.path).unwrap();
    c.call("machine.on", Value::Null).unwrap();
}

#[test]
fn bind_never_removes_a_file_that_is_not_a_socket() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("precious");
    std::fs::write(&path, "data").unwrap();
    let err = bind(&SocketOptions {
        path: path.clone(),
        mode: 0o660,
        group: None,
    })
    .unwrap_err();
    assert!(err.to_string().contains("not a socket"), "{err}");
    assert_eq!(std::fs::read_to_string(&path).unwrap(), "data");
}

#[test]
fn bind_replaces_a_stale_socket() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("control.sock");
    drop(std::os::unix::net::UnixListener::bind(&path).unwrap());
    assert!(path.exists());
    let l = bind(&SocketOptions {
        path: path.clone(),
        mode: 0o660,
        group: None,
    })
    .unwrap();
    UnixStream::connect(&path).unwrap();
    drop(l);
    assert!(
        !path.exists(),
        "the daemon's own socket is removed when it stops"
    );
}

#[test]
fn bind_refuses_a_directory_other_users_can_write() {
    use std::os::unix::fs::PermissionsExt;
    let dir = tempfile::tempdir().unwrap();
    for mode in [0o777, 0o1777, 0o775] {
        std::fs::set_permissions(dir.path(), std::fs::Permissions::from_mode(mode)).unwrap();
        let err = bind(&SocketOptions {
            path: dir.path().join("control.sock"),
            mode: 0o660,
            group: None,
        })
        .unwrap_err()
        .to_string();
        assert!(err.contains("writable by"), "{mode:o}: {err}");
    }
}

#[test]
fn the_path_is_claimed_before_anything_is_bound() {
    let dir = tempfile::tempdir().unwrap();
    let opts = SocketOptions {
        path: dir.path().join("control.sock"),
        mode: 0o660,
        group: None,
    };
    let first = hytask::control::listen::claim(&opts).unwrap();
    // No socket exists yet, but the path is taken.
    let err = hytask::control::listen::claim(&opts).unwrap_err();
    assert!(err.to_string().contains("already listening"), "{err}");
    drop(first);
    hytask::control::listen::claim(&opts).unwrap();
}

#[test]
fn daemon_shutdown_does_not_wait_for_a_blocked_request() {
    let machine = Arc::new(Double::new());
    let (gate_tx, gate_rx) = std::sync::mpsc::channel::<()>();
    *machine.gate.lock().unwrap() = Some(gate_rx);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("control.sock");
    let listener = bind(&SocketOptions {
        path: path.clone(),
        mode: 0o600,
        group: None,
    })
    .unwrap();
    let (stop_tx, stop_rx) = tokio::sync::oneshot::channel::<()>();
    let (done_tx, done_rx) = std::sync::mpsc::channel();
    let m: Arc<dyn hytask::daemon::Deployed> = machine.clone();
    std::thread::spawn(move || {
        let r = hytask::daemon::run(m, listener, async move {
            let _ = stop_rx.await;
        });
        let _ = done_tx.send(r.is_ok());
    });
    let mut s = UnixStream::connect(&path).unwrap();
    s.write_all(
        b"{\"id\":1,\"method\":\"job.load\",\"params\":{\"text\":\"M2\",\"name\":\"block\"}}\n",
    )
    .unwrap();
    let t0 = Instant::now();
    while !machine.entered.load(Ordering::SeqCst) {
        assert!(
            t0.elapsed() < Duration::from_secs(60),
            "job.load never arrived"
        );
        std::thread::sleep(Duration::from_millis(5));
    }
    stop_tx.send(()).unwrap();
    // The request is still blocked (gate_tx alive), yet the daemon returns.
    let ok = done_rx
        .recv_timeout(Duration::from_secs(60))
        .expect("daemon::run waited for the blocked request");
    assert!(ok);
    drop(gate_tx);
}
