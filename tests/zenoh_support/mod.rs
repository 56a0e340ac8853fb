//! Helpers shared by the Zenoh tests and benches (the benches include this file with
//! `#[path]`): loopback endpoints, the bridge's `[zenoh]` table, a client session, queries
//! that wait for their route, and waits with a hang guard (never a timing).
#![allow(clippy::unwrap_used, dead_code)]

use hytask::config::ZenohConfig;
use hytask::machine::api::MachineApi;
use serde_json::{json, Value};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};
use zenoh::Wait;

/// A TCP port that was free a moment ago, for a Zenoh endpoint given in a config file.
///
/// The port is released before the session binds it, so it must not come from the
/// kernel's ephemeral range (`ip_local_port_range`, 32768-60999 by default): every outgoing
/// connection of a parallel test draws its source port from that range and could take it
/// in between (stop 25's CI lost a test to exactly that). Ports are handed out from
/// 20000-32767 instead, starting at an offset drawn from the process id so that two test
/// binaries running at once rarely probe the same ones, and each is probed with a bind.
pub fn free_port() -> u16 {
    use std::sync::atomic::{AtomicU32, Ordering};
    const FIRST: u32 = 20000;
    const COUNT: u32 = 32768 - FIRST;
    static NEXT: AtomicU32 = AtomicU32::new(u32::MAX);
    let _ = NEXT.compare_exchange(
        u32::MAX,
        std::process::id().wrapping_mul(7919) % COUNT,
        Ordering::Relaxed,
        Ordering::Relaxed,
    );
    for _ in 0..COUNT {
        let port = (FIRST + NEXT.fetch_add(1, Ordering::Relaxed) % COUNT) as u16;
        if std::net::TcpListener::bind(("127.0.0.1", port)).is_ok() {
            return port;
        }
    }
    panic!("no free TCP port in {FIRST}..32768 on loopback");
}

/// A `[zenoh]` table exporting as `key` on a fresh loopback endpoint, with the TOML lines
/// `extra` added (rates, role...); and that endpoint.
pub fn bridge_config(key: &str, extra: &str) -> (ZenohConfig, String) {
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let cfg = toml::from_str(&format!(
        "key = \"{key}\"\nlisten = [\"{endpoint}\"]\n{extra}\n"
    ))
    .unwrap();
    (cfg, endpoint)
}

/// The configuration of a client session connected to `endpoint` only (no multicast
/// scouting), for tests that add to it (TLS).
pub fn client_config(endpoint: &str) -> zenoh::Config {
    let mut c = zenoh::Config::default();
    c.insert_json5("mode", "\"client\"").unwrap();
    c.insert_json5("connect/endpoints", &json!([endpoint]).to_string())
        .unwrap();
    c.insert_json5("scouting/multicast/enabled", "false")
        .unwrap();
    c
}

/// A client session connected to `endpoint` only (no multicast scouting).
pub fn client(endpoint: &str) -> zenoh::Session {
    zenoh::open(client_config(endpoint)).wait().unwrap()
}

/// A peer session (as `hytask serve` and `hytask peer` open) connecting to `endpoint`:
/// unlike a client it opens before `endpoint` listens, and it sees a liveliness token
/// withdrawn when the process holding it dies.
pub fn peer_session(endpoint: &str) -> zenoh::Session {
    let (mut cfg, _) = bridge_config("test-peer", "");
    cfg.connect = vec![endpoint.to_owned()];
    hytask::bridge::session::open(&cfg).unwrap()
}

/// A JSON payload.
pub fn decode(b: &zenoh::bytes::ZBytes) -> Value {
    serde_json::from_slice(&b.to_bytes()).unwrap()
}

/// The first reply to a query on `key` with `payload`: Ok(result JSON) or Err(error JSON).
/// Asks again while nobody answers (the route is still being learnt), up to `guard`.
pub fn query(
    s: &zenoh::Session,
    key: &str,
    payload: Option<&Value>,
    guard: Duration,
) -> Result<Value, Value> {
    let t0 = Instant::now();
    loop {
        let mut q = s.get(key).timeout(guard);
        if let Some(p) = payload {
            q = q.payload(p.to_string());
        }
        if let Ok(reply) = q.wait().unwrap().recv() {
            return match reply.result() {
                Ok(sample) => Ok(decode(sample.payload())),
                Err(e) => Err(decode(e.payload())),
            };
        }
        assert!(t0.elapsed() < guard, "no reply on {key} within {guard:?}");
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// Waits until a liveliness token on `key` answers, up to `guard`.
pub fn wait_token(s: &zenoh::Session, key: &str, guard: Duration) {
    wait_for(&format!("a liveliness token on {key}"), guard, || {
        let replies = s.liveliness().get(key).timeout(guard).wait().unwrap();
        replies.recv().is_ok()
    });
}

/// Waits until `f` holds, polling; panics naming `what` after `guard` (a hang guard).
pub fn wait_for(what: &str, guard: Duration, mut f: impl FnMut() -> bool) {
    let t0 = Instant::now();
    while !f() {
        assert!(t0.elapsed() < guard, "waited {guard:?} for {what}");
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Waits until `machine`'s status (as JSON) satisfies `f`, up to `guard`.
pub fn wait_status(
    what: &str,
    machine: &dyn MachineApi,
    guard: Duration,
    f: impl Fn(&Value) -> bool,
) {
    let mut last = Value::Null;
    let t0 = Instant::now();
    loop {
        last = serde_json::to_value(machine.status()).unwrap_or(last);
        if f(&last) {
            return;
        }
        assert!(t0.elapsed() < guard, "waited {guard:?} for {what}: {last}");
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// The built-in simulated mill out of e-stop and switched on.
pub fn switch_on(machine: &dyn MachineApi) {
    machine.estop_reset().unwrap();
    machine.machine_on().unwrap();
}

/// A `hytask` process (`peer --config`, `serve ... --config`) with its stderr in a file;
/// killed when dropped.
pub struct Proc {
    /// The process.
    pub child: Child,
    log: PathBuf,
}

impl Proc {
    /// Runs `hytask <args> <config>`, logging at info level into `log`.
    pub fn spawn(args: &[&str], config: &Path, log: PathBuf) -> Proc {
        let child = Command::new(env!("CARGO_BIN_EXE_hytask"))
            .args(args)
            .arg(config)
            .env("RUST_LOG", "info")
            .stdout(Stdio::null())
            .stderr(std::fs::File::create(&log).unwrap())
            .spawn()
            .unwrap();
        Proc { child, log }
    }

    /// Its stderr so far.
    pub fn log(&self) -> String {
        std::fs::read_to_string(&self.log).unwrap_or_default()
    }
}

impl Drop for Proc {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// config/vision-peer.toml (the cell's camera as a `hytask peer`), listening on
/// `listen` and connecting to `connect` instead of the shipped ports; written into `dir`.
pub fn vision_peer_config(dir: &Path, listen: u16, connect: u16) -> PathBuf {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let text = std::fs::read_to_string(root.join("config/vision-peer.toml")).unwrap();
    for port in ["17461", "17460"] {
        assert!(
            text.contains(port),
            "config/vision-peer.toml changed: no {port}"
        );
    }
    let text = text
        .replace("17461", &listen.to_string())
        .replace("17460", &connect.to_string());
    let path = dir.join("vision-peer.toml");
    std::fs::write(&path, text).unwrap();
    path
}
