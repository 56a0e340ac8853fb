//! The control socket server: accepts Unix-socket connections and serves JSON-line requests
//! (see [`super::protocol`]) against a [`MachineApi`].
//!
//! Robustness rules, each with a test in `tests/control_socket.rs`:
//! - A request line is bounded ([`MAX_REQUEST_BYTES`]); an oversized or malformed line gets
//!   an error reply and the connection stays usable.
//! - Every client has a bounded output queue. Replies wait for space (the client only slows
//!   itself); events are dropped for a client that does not read, and it is told how many
//!   with a `lagged` event. A write that stalls past [`WRITE_TIMEOUT`] closes that client.
//!   Nothing a client does can block the daemon or another client.
//! - Machine calls run on tokio's blocking pool, never on the reactor threads.
//! - A client disconnecting mid-job does not stop the job: connections own no machine state.
//! - The peer's credentials (SO_PEERCRED) are logged per connection.

use super::methods;
use super::protocol::{
    event_line, parse_request, reply_line, ControlError, ErrorCode, MAX_REQUEST_BYTES,
};
use crate::machine::api::MachineApi;
use serde_json::{json, Value};
use std::collections::HashSet;
use std::future::Future;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Arc;
use std::time::Duration;
use tokio::io::{AsyncBufReadExt, AsyncWriteExt, BufReader};
use tokio::net::unix::OwnedReadHalf;
use tokio::net::{UnixListener, UnixStream};
use tokio::sync::{broadcast, mpsc};

/// Lines queued for one client before events are dropped for it.
pub const CLIENT_QUEUE: usize = 256;
/// A client whose socket accepts nothing for this long is disconnected.
pub const WRITE_TIMEOUT: Duration = Duration::from_secs(5);
/// Connections served at once; more are answered with an error and closed.
pub const MAX_CLIENTS: usize = 512;

/// Where and how to create the socket.
#[derive(Debug, Clone)]
pub struct SocketOptions {
    /// Socket path (default `/run/hytask/control.sock`).
    pub path: PathBuf,
    /// File mode, e.g. 0o660.
    pub mode: u32,
    /// Group that owns the socket, if any.
    pub group: Option<String>,
}

/// Why the socket could not be created.
#[derive(Debug, thiserror::Error)]
pub enum BindError {
    /// Another daemon answers on the path.
    #[error("{0}: another daemon is already listening there")]
    InUse(PathBuf),
    /// A filesystem or socket error.
    #[error("{path}: {source}")]
    Io {
        /// Path involved.
        path: PathBuf,
        /// Cause.
        source: std::io::Error,
    },
    /// The configured group does not exist.
    #[error("control.group: no group named '{0}'")]
    NoSuchGroup(String),
}

/// Creates the listening socket: makes the parent directory, replaces a stale socket file
/// (one nobody answers on), applies mode and group.
pub fn bind(opts: &SocketOptions) -> Result<std::os::unix::net::UnixListener, BindError> {
    use std::os::unix::fs::PermissionsExt;
    let io = |source| BindError::Io {
        path: opts.path.clone(),
        source,
    };
    if let Some(parent) = opts.path.parent() {
        if !parent.as_os_str().is_empty() {
            std::fs::create_dir_all(parent).map_err(io)?;
        }
    }
    if opts.path.exists() {
        if std::os::unix::net::UnixStream::connect(&opts.path).is_ok() {
            return Err(BindError::InUse(opts.path.clone()));
        }
        std::fs::remove_file(&opts.path).map_err(io)?;
    }
    let listener = std::os::unix::net::UnixListener::bind(&opts.path).map_err(io)?;
    std::fs::set_permissions(&opts.path, std::fs::Permissions::from_mode(opts.mode)).map_err(io)?;
    if let Some(group) = &opts.group {
        let gid = nix::unistd::Group::from_name(group)
            .ok()
            .flatten()
            .ok_or_else(|| BindError::NoSuchGroup(group.clone()))?
            .gid;
        nix::unistd::chown(&opts.path, None, Some(gid))
            .map_err(|e| io(std::io::Error::from_raw_os_error(e as i32)))?;
    }
    listener.set_nonblocking(true).map_err(io)?;
    Ok(listener)
}

/// Serves connections until `shutdown` completes. Open connections are dropped then.
pub async fn serve(
    listener: UnixListener,
    machine: Arc<dyn MachineApi>,
    shutdown: impl Future<Output = ()>,
) {
    let clients = Arc::new(AtomicUsize::new(0));
    tokio::pin!(shutdown);
    let mut tasks = tokio::task::JoinSet::new();
    loop {
        tokio::select! {
            _ = &mut shutdown => break,
            accepted = listener.accept() => match accepted {
                Ok((stream, _)) => {
                    let machine = machine.clone();
                    let clients = clients.clone();
                    tasks.spawn(async move {
                        if clients.fetch_add(1, Ordering::AcqRel) >= MAX_CLIENTS {
                            reject_busy(stream).await;
                        } else {
                            serve_client(stream, machine).await;
                        }
                        clients.fetch_sub(1, Ordering::AcqRel);
                    });
                }
                Err(e) => {
                    tracing::warn!("control socket accept failed: {e}");
                    tokio::time::sleep(Duration::from_millis(50)).await;
                }
            },
            Some(_) = tasks.join_next(), if !tasks.is_empty() => {}
        }
    }
    tasks.shutdown().await;
}

async fn reject_busy(mut stream: UnixStream) {
    let line = reply_line(
        &Value::Null,
        Err(ControlError::new(
            ErrorCode::Failed,
            format!("too many clients (limit {MAX_CLIENTS})"),
        )),
    );
    let _ = tokio::time::timeout(WRITE_TIMEOUT, stream.write_all(line.as_bytes())).await;
}

/// One connection: a reader loop that handles requests in order and a writer task that
/// owns the socket's write half.
async fn serve_client(stream: UnixStream, machine: Arc<dyn MachineApi>) {
    match stream.peer_cred() {
        Ok(c) => tracing::info!(
            uid = c.uid(),
            gid = c.gid(),
            pid = c.pid(),
            "control client connected"
        ),
        Err(e) => tracing::info!("control client connected (no peer credentials: {e})"),
    }
    let (read_half, mut write_half) = stream.into_split();
    let (out_tx, mut out_rx) = mpsc::channel::<String>(CLIENT_QUEUE);
    let writer = tokio::spawn(async move {
        while let Some(line) = out_rx.recv().await {
            match tokio::time::timeout(WRITE_TIMEOUT, write_half.write_all(line.as_bytes())).await {
                Ok(Ok(())) => {}
                Ok(Err(_)) => break,
                Err(_) => {
                    tracing::warn!("control client stalled for {WRITE_TIMEOUT:?}; disconnecting");
                    break;
                }
            }
        }
    });
    let mut events: Option<tokio::task::JoinHandle<()>> = None;
    read_requests(read_half, &machine, &out_tx, &mut events).await;
    if let Some(e) = events {
        e.abort();
    }
    drop(out_tx);
    let _ = writer.await;
    tracing::info!("control client disconnected");
}

/// Reads bounded lines and answers each. Returns on EOF, read error or writer gone.
async fn read_requests(
    read_half: OwnedReadHalf,
    machine: &Arc<dyn MachineApi>,
    out: &mpsc::Sender<String>,
    events: &mut Option<tokio::task::JoinHandle<()>>,
) {
    let mut reader = BufReader::with_capacity(64 * 1024, read_half);
    let mut line: Vec<u8> = Vec::new();
    let mut oversized = false;
    loop {
        let (consumed, complete) = {
            let buf = match reader.fill_buf().await {
                Ok([]) => return,
                Ok(b) => b,
                Err(_) => return,
            };
            match buf.iter().position(|&b| b == b'\n') {
                Some(i) => {
                    if !oversized {
                        line.extend_from_slice(&buf[..i]);
                    }
                    (i + 1, true)
                }
                None => {
                    if !oversized {
                        line.extend_from_slice(buf);
                    }
                    (buf.len(), false)
                }
            }
        };
        reader.consume(consumed);
        if line.len() > MAX_REQUEST_BYTES {
            oversized = true;
            line = Vec::new();
        }
        if !complete {
            continue;
        }
        let reply = if oversized {
            oversized = false;
            Some(reply_line(
                &Value::Null,
                Err(ControlError::new(
                    ErrorCode::InvalidRequest,
                    format!("request larger than {MAX_REQUEST_BYTES} bytes"),
                )),
            ))
        } else if line.iter().all(u8::is_ascii_whitespace) {
            None
        } else {
            Some(handle_line(&line, machine, out, events).await)
        };
        line.clear();
        if let Some(reply) = reply {
            if out.send(reply).await.is_err() {
                return;
            }
        }
    }
}

async fn handle_line(
    line: &[u8],
    machine: &Arc<dyn MachineApi>,
    out: &mpsc::Sender<String>,
    events: &mut Option<tokio::task::JoinHandle<()>>,
) -> String {
    let req = match parse_request(line) {
        Ok(r) => r,
        Err((id, e)) => return reply_line(&id, Err(e)),
    };
    let result = match req.method.as_str() {
        "subscribe" => subscribe(machine, req.params, out, events),
        "unsubscribe" => {
            if let Some(e) = events.take() {
                e.abort();
            }
            Ok(json!({"ok": true}))
        }
        _ => {
            let machine = machine.clone();
            let method = req.method.clone();
            tokio::task::spawn_blocking(move || methods::dispatch(&*machine, &method, req.params))
                .await
                .unwrap_or_else(|e| {
                    Err(ControlError::new(
                        ErrorCode::Failed,
                        format!("internal error: {e}"),
                    ))
                })
        }
    };
    reply_line(&req.id, result)
}

/// Topics a client may subscribe to.
pub const TOPICS: &[&str] = &["mode", "fault", "progress", "job", "message", "task"];

fn subscribe(
    machine: &Arc<dyn MachineApi>,
    params: Value,
    out: &mpsc::Sender<String>,
    events: &mut Option<tokio::task::JoinHandle<()>>,
) -> Result<Value, ControlError> {
    let topics: HashSet<String> = match params.get("topics") {
        None | Some(Value::Null) => TOPICS.iter().map(|s| s.to_string()).collect(),
        Some(Value::Array(a)) => {
            let mut set = HashSet::new();
            for t in a {
                let t = t
                    .as_str()
                    .ok_or_else(|| ControlError::params("topics must be strings"))?;
                if !TOPICS.contains(&t) {
                    return Err(ControlError::params(format!(
                        "unknown topic '{t}' (topics: {})",
                        TOPICS.join(", ")
                    )));
                }
                set.insert(t.to_string());
            }
            set
        }
        Some(_) => return Err(ControlError::params("topics must be an array")),
    };
    if let Some(e) = events.take() {
        e.abort();
    }
    let mut rx = machine.subscribe();
    let out = out.clone();
    let mut list: Vec<String> = topics.iter().cloned().collect();
    list.sort();
    *events = Some(tokio::spawn(async move {
        let mut dropped: u64 = 0;
        loop {
            let ev = match rx.recv().await {
                Ok(ev) => ev,
                Err(broadcast::error::RecvError::Lagged(n)) => {
                    dropped += n;
                    continue;
                }
                Err(broadcast::error::RecvError::Closed) => return,
            };
            if !topics.contains(&ev.topic) {
                continue;
            }
            if dropped > 0 {
                let lag = event_line("lagged", &json!({"dropped": dropped}));
                if out.try_send(lag).is_ok() {
                    dropped = 0;
                } else {
                    dropped += 1;
                    continue;
                }
            }
            match out.try_send(event_line(&ev.topic, &ev.data)) {
                Ok(()) => {}
                Err(mpsc::error::TrySendError::Full(_)) => dropped += 1,
                Err(mpsc::error::TrySendError::Closed(_)) => return,
            }
        }
    }));
    Ok(json!({"topics": list}))
}

/// Default socket path.
pub fn default_socket_path() -> &'static Path {
    Path::new("/run/hytask/control.sock")
}
