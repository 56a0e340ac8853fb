//! The control socket server: accepts Unix-socket connections and serves JSON-line requests
//! (see [`super::protocol`]) against a [`MachineApi`].
//!
//! Robustness rules, each with a test in `tests/control_socket.rs`:
//! - A request line is bounded ([`MAX_REQUEST_BYTES`]); an oversized or malformed line gets
//!   an error reply and the connection stays usable. A final request without a newline is
//!   answered at end of input (`printf '{"method":"estop"}' | socat - UNIX-CONNECT:…`).
//! - Unfinished lines are bounded in total, across clients ([`ServerOptions::max_buffered_bytes`]):
//!   a client may buffer [`FREE_LINE_BYTES`] on its own, more only from a shared budget, and
//!   is disconnected with an error reply when the budget is spent.
//! - Every client has a bounded output queue. Replies wait for space (the client only slows
//!   itself); events are dropped for a client that does not read, and it is told how many
//!   with a `lagged` event. A write that stalls past the write timeout closes that client
//!   and frees its slot.
//! - An e-stop always gets through: beyond [`ServerOptions::max_clients`] a connection is
//!   still accepted, answers only `estop`, and is closed. Those over-limit connections are
//!   bounded too (as many again); when they are all held, the oldest one still waiting for
//!   its request is closed to make room, so a flood of silent connections cannot shut the
//!   e-stop out ([`Overflow`]). Idle connections (no request, no event for
//!   [`ServerOptions::idle_timeout`]) are closed.
//!   Nothing a client does can block the daemon or another client.
//! - Machine calls run on tokio's blocking pool, never on the reactor threads.
//! - A client disconnecting mid-job does not stop the job: connections own no machine state.
//!   A client that hangs up while its `job.load` is being prepared cancels that preparation
//!   ([`until_hangup`]): the preparations run one at a time, and nobody waits for the answer.
//! - The peer's credentials (SO_PEERCRED) decide its role ([`super::access`]).

use super::access::{permits, AccessPolicy, Role};
pub use super::listen::{bind, default_socket_path, BindError, Listener, SocketOptions};
use super::methods;
use super::protocol::{
    event_line, parse_request, reply_line, ControlError, ErrorCode, MAX_REQUEST_BYTES,
};
use crate::machine::api::MachineApi;
use crate::machine::job_cancel::{self, Cancel, Why};
use crate::machine::job_file::JobFilePolicy;
use serde_json::{json, Value};
use std::collections::HashSet;
use std::future::Future;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};
use tokio::io::{AsyncBufReadExt, AsyncReadExt, AsyncWriteExt, BufReader};
use tokio::net::unix::OwnedReadHalf;
use tokio::net::{UnixListener, UnixStream};
use tokio::sync::{broadcast, mpsc};

/// Lines queued for one client before events are dropped for it.
pub const CLIENT_QUEUE: usize = 256;
/// A client whose socket accepts nothing for this long is disconnected (default).
pub const WRITE_TIMEOUT: Duration = Duration::from_secs(5);
/// Connections served at once by default (`[control] max_clients`).
pub const MAX_CLIENTS: usize = 512;
/// Bytes of an unfinished line a client may buffer without drawing on the shared budget:
/// every ordinary request, `estop` included, fits.
pub const FREE_LINE_BYTES: usize = 64 * 1024;
/// Largest request read on an over-limit (e-stop only) connection.
const OVERFLOW_REQUEST_BYTES: u64 = 4096;
/// How long an over-limit connection may take to send its request.
const OVERFLOW_READ_TIMEOUT: Duration = Duration::from_secs(10);

/// How the server treats its clients; [`ServerOptions::from_config`] reads `[control]`.
#[derive(Debug, Clone)]
pub struct ServerOptions {
    /// Connections served at once; more answer only `estop`.
    pub max_clients: usize,
    /// Close a connection with no request and no event for this long (`None`: never).
    pub idle_timeout: Option<Duration>,
    /// Close a client whose socket accepts nothing for this long.
    pub write_timeout: Duration,
    /// Bytes of unfinished request lines across all clients beyond [`FREE_LINE_BYTES`] each.
    pub max_buffered_bytes: usize,
    /// Roles.
    pub access: AccessPolicy,
    /// What `job.load` may read.
    pub jobs: JobFilePolicy,
}

impl Default for ServerOptions {
    fn default() -> Self {
        ServerOptions {
            max_clients: MAX_CLIENTS,
            idle_timeout: Some(Duration::from_secs(300)),
            write_timeout: WRITE_TIMEOUT,
            max_buffered_bytes: 64 * 1024 * 1024,
            access: AccessPolicy::default(),
            jobs: JobFilePolicy::default(),
        }
    }
}

impl ServerOptions {
    /// Options from `[control]`; fails on a user or group name unknown on this host.
    pub fn from_config(
        c: &crate::config::ControlConfig,
    ) -> Result<Self, super::access::UnknownName> {
        Ok(ServerOptions {
            max_clients: c.max_clients as usize,
            idle_timeout: (c.idle_timeout_s > 0).then(|| Duration::from_secs(c.idle_timeout_s)),
            write_timeout: WRITE_TIMEOUT,
            max_buffered_bytes: usize::try_from(c.max_buffered_bytes).unwrap_or(usize::MAX),
            access: AccessPolicy::from_config(c)?,
            jobs: JobFilePolicy {
                jobs_dir: c.jobs_dir.clone(),
                max_bytes: c.max_job_bytes,
            },
        })
    }
}

/// State shared by all connections.
struct Shared {
    opts: ServerOptions,
    machine: Arc<dyn MachineApi>,
    clients: AtomicUsize,
    overflow: Overflow,
    buffered: AtomicUsize,
}

/// The over-limit (e-stop only) connections still waiting for their request, oldest first.
/// Why: dropping a connection when they are all held (as before) let anyone who holds
/// 2 × `max_clients` silent connections shut every e-stop out; evicting the oldest instead
/// means a flood must open `max_clients` more connections between a client's connect and its
/// request (microseconds for `hytask estop`) to keep it out.
#[derive(Default)]
struct Overflow {
    waiting: std::sync::Mutex<std::collections::VecDeque<(u64, Arc<tokio::sync::Notify>)>>,
    next: AtomicU64,
}

impl Overflow {
    /// Registers a new over-limit connection, evicting the oldest waiting one beyond `max`.
    fn enter(&self, max: usize) -> OverflowEntry<'_> {
        let id = self.next.fetch_add(1, Ordering::Relaxed);
        let evict = Arc::new(tokio::sync::Notify::new());
        let mut waiting = self
            .waiting
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        while waiting.len() >= max.max(1) {
            if let Some((_, oldest)) = waiting.pop_front() {
                oldest.notify_one();
            }
        }
        waiting.push_back((id, evict.clone()));
        OverflowEntry {
            overflow: self,
            id,
            evict,
        }
    }
}

/// One over-limit connection's place in [`Overflow`]; leaves it when dropped.
struct OverflowEntry<'a> {
    overflow: &'a Overflow,
    id: u64,
    evict: Arc<tokio::sync::Notify>,
}

impl Drop for OverflowEntry<'_> {
    fn drop(&mut self) {
        let mut waiting = self
            .overflow
            .waiting
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        waiting.retain(|(id, _)| *id != self.id);
    }
}

/// Decrements a counter when dropped, so that an aborted connection task frees its slot.
struct Slot<'a>(&'a AtomicUsize);

impl Drop for Slot<'_> {
    fn drop(&mut self) {
        self.0.fetch_sub(1, Ordering::AcqRel);
    }
}

/// Serves connections with default [`ServerOptions`] until `shutdown` completes.
pub async fn serve(
    listener: UnixListener,
    machine: Arc<dyn MachineApi>,
    shutdown: impl Future<Output = ()>,
) {
    serve_with(listener, machine, ServerOptions::default(), shutdown).await
}

/// Serves connections until `shutdown` completes. Open connections are dropped then.
pub async fn serve_with(
    listener: UnixListener,
    machine: Arc<dyn MachineApi>,
    opts: ServerOptions,
    shutdown: impl Future<Output = ()>,
) {
    let shared = Arc::new(Shared {
        opts,
        machine,
        clients: AtomicUsize::new(0),
        overflow: Overflow::default(),
        buffered: AtomicUsize::new(0),
    });
    tokio::pin!(shutdown);
    let mut tasks = tokio::task::JoinSet::new();
    loop {
        tokio::select! {
            _ = &mut shutdown => break,
            accepted = listener.accept() => match accepted {
                Ok((stream, _)) => {
                    let shared = shared.clone();
                    tasks.spawn(async move {
                        let max = shared.opts.max_clients;
                        if shared.clients.fetch_add(1, Ordering::AcqRel) < max {
                            let _slot = Slot(&shared.clients);
                            serve_client(stream, &shared).await;
                        } else {
                            shared.clients.fetch_sub(1, Ordering::AcqRel);
                            // Over-limit connections are bounded too (the oldest waiting
                            // one makes room); each lives at most OVERFLOW_READ_TIMEOUT.
                            serve_estop_only(stream, &shared).await;
                        }
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

fn peer(stream: &UnixStream) -> Option<(u32, u32)> {
    match stream.peer_cred() {
        Ok(c) => Some((c.uid(), c.gid())),
        Err(e) => {
            tracing::info!("control client without peer credentials: {e}");
            None
        }
    }
}

async fn role_of(shared: &Arc<Shared>, peer: Option<(u32, u32)>) -> Option<Role> {
    let s = shared.clone();
    tokio::task::spawn_blocking(move || s.opts.access.role_of_peer(peer))
        .await
        .unwrap_or(None)
}

fn refused_line(peer: Option<(u32, u32)>) -> String {
    let who = match peer {
        Some((uid, _)) => format!("uid {uid}"),
        None => "a client without credentials".into(),
    };
    reply_line(
        &Value::Null,
        Err(ControlError::new(
            ErrorCode::Forbidden,
            format!("{who} may not use this socket (control.operators, control.observers, control.unlisted)"),
        )),
    )
}

/// An over-limit connection: reads one request; `estop` is served, anything else gets
/// "too many clients"; then the connection is closed.
async fn serve_estop_only(mut stream: UnixStream, shared: &Arc<Shared>) {
    let peer = peer(&stream);
    let max = shared.opts.max_clients;
    let entry = shared.overflow.enter(max);
    let mut buf = Vec::new();
    let read = async {
        let mut limited = (&mut stream).take(OVERFLOW_REQUEST_BYTES);
        let mut byte = [0u8; 1];
        // Byte by byte up to the first newline: this path serves one short request.
        while limited.read(&mut byte).await.ok()? == 1 {
            if byte[0] == b'\n' {
                break;
            }
            buf.push(byte[0]);
        }
        Some(())
    };
    let evicted = tokio::select! {
        _ = tokio::time::timeout(OVERFLOW_READ_TIMEOUT, read) => false,
        _ = entry.evict.notified() => true,
    };
    // Read or not, this connection no longer waits: it cannot be evicted any more.
    drop(entry);
    let busy = || {
        ControlError::new(
            ErrorCode::Failed,
            format!("too many clients (limit {max}, control.max_clients); this connection serves only 'estop'"),
        )
    };
    if evicted {
        // No wait for a client that sent nothing in time: what the socket takes now, then
        // the connection is closed.
        let why = ControlError::new(
            ErrorCode::Failed,
            format!("too many clients (limit {max}, control.max_clients); closed to make room for a newer connection"),
        );
        let _ = stream.try_write(reply_line(&Value::Null, Err(why)).as_bytes());
        return;
    }
    let line = match parse_request(&buf) {
        Ok(req) if req.method == "estop" => {
            if role_of(shared, peer).await.is_none() {
                refused_line(peer)
            } else {
                tracing::warn!("e-stop over an over-limit control connection");
                let token = Cancel::new();
                let result = dispatch(shared, Role::Observer, req.method, req.params, &token).await;
                reply_line(&req.id, result)
            }
        }
        Ok(req) => reply_line(&req.id, Err(busy())),
        Err(_) => reply_line(&Value::Null, Err(busy())),
    };
    let _ =
        tokio::time::timeout(shared.opts.write_timeout, stream.write_all(line.as_bytes())).await;
}

/// Runs one method on the blocking pool, under the job-file policy; `token` cancels a job
/// preparation the method starts.
async fn dispatch(
    shared: &Arc<Shared>,
    role: Role,
    method: String,
    params: Value,
    token: &Cancel,
) -> Result<Value, ControlError> {
    if !permits(role, &method) {
        return Err(ControlError::new(
            ErrorCode::Forbidden,
            format!(
                "'{method}' needs the operator role; this client is an {} (control.operators)",
                role.as_str()
            ),
        ));
    }
    let s = shared.clone();
    let token = token.clone();
    tokio::task::spawn_blocking(move || {
        job_cancel::with_request_token(&token, || {
            crate::machine::job_file::with_policy(&s.opts.jobs, || {
                methods::dispatch(&*s.machine, &method, params)
            })
        })
    })
    .await
    .unwrap_or_else(|e| {
        Err(ControlError::new(
            ErrorCode::Failed,
            format!("internal error: {e}"),
        ))
    })
}

/// Milliseconds since the connection began, when it last sent or received something.
struct Activity {
    start: Instant,
    last_ms: AtomicU64,
}

impl Activity {
    fn touch(&self) {
        self.last_ms
            .store(self.start.elapsed().as_millis() as u64, Ordering::Relaxed);
    }
    fn last(&self) -> Instant {
        self.start + Duration::from_millis(self.last_ms.load(Ordering::Relaxed))
    }
}

/// Per-connection context.
struct Conn<'a> {
    shared: &'a Arc<Shared>,
    role: Role,
    out: mpsc::Sender<String>,
    activity: Arc<Activity>,
    events: Option<tokio::task::JoinHandle<()>>,
}

/// One connection: a reader loop that handles requests in order and a writer task that
/// owns the socket's write half.
async fn serve_client(stream: UnixStream, shared: &Arc<Shared>) {
    let peer = peer(&stream);
    let Some(role) = role_of(shared, peer).await else {
        tracing::warn!(?peer, "control client refused: no role");
        let (_, mut w) = stream.into_split();
        let _ = tokio::time::timeout(
            shared.opts.write_timeout,
            w.write_all(refused_line(peer).as_bytes()),
        )
        .await;
        return;
    };
    if let Some((uid, gid)) = peer {
        tracing::info!(uid, gid, role = role.as_str(), "control client connected");
    }
    let (read_half, mut write_half) = stream.into_split();
    let (out_tx, mut out_rx) = mpsc::channel::<String>(CLIENT_QUEUE);
    let activity = Arc::new(Activity {
        start: Instant::now(),
        last_ms: AtomicU64::new(0),
    });
    let write_timeout = shared.opts.write_timeout;
    let writer_activity = activity.clone();
    let writer = tokio::spawn(async move {
        while let Some(line) = out_rx.recv().await {
            match tokio::time::timeout(write_timeout, write_half.write_all(line.as_bytes())).await {
                Ok(Ok(())) => writer_activity.touch(),
                Ok(Err(_)) => break,
                Err(_) => {
                    tracing::warn!("control client stalled for {write_timeout:?}; disconnecting");
                    break;
                }
            }
        }
    });
    let mut conn = Conn {
        shared,
        role,
        out: out_tx,
        activity,
        events: None,
    };
    read_requests(read_half, &mut conn).await;
    if let Some(e) = conn.events.take() {
        e.abort();
    }
    drop(conn);
    let _ = writer.await;
    tracing::info!("control client disconnected");
}

/// An unfinished request line, with what it holds of the shared budget.
struct LineBuf<'a> {
    line: Vec<u8>,
    oversized: bool,
    reserved: usize,
    budget: &'a AtomicUsize,
    max: usize,
}

impl LineBuf<'_> {
    /// Appends `bytes`; false when the shared budget cannot cover it.
    fn extend(&mut self, bytes: &[u8]) -> bool {
        if self.oversized {
            return true;
        }
        if self.line.len() + bytes.len() > MAX_REQUEST_BYTES {
            self.oversized = true;
            self.reset();
            return true;
        }
        let need = (self.line.len() + bytes.len()).saturating_sub(FREE_LINE_BYTES);
        if need > self.reserved {
            let more = need - self.reserved;
            let got = self
                .budget
                .fetch_update(Ordering::AcqRel, Ordering::Acquire, |used| {
                    (used + more <= self.max).then_some(used + more)
                });
            if got.is_err() {
                return false;
            }
            self.reserved = need;
        }
        self.line.extend_from_slice(bytes);
        true
    }

    /// Empties the line and returns its memory and its budget.
    fn reset(&mut self) {
        if self.line.capacity() > FREE_LINE_BYTES {
            self.line = Vec::new();
        } else {
            self.line.clear();
        }
        self.budget.fetch_sub(self.reserved, Ordering::AcqRel);
        self.reserved = 0;
    }
}

impl Drop for LineBuf<'_> {
    fn drop(&mut self) {
        self.budget.fetch_sub(self.reserved, Ordering::AcqRel);
    }
}

fn error_line(code: ErrorCode, message: String) -> String {
    reply_line(&Value::Null, Err(ControlError::new(code, message)))
}

/// Reads bounded lines and answers each. Returns on EOF (after answering a final request
/// without newline), read error, idle timeout, budget exhausted, or writer gone.
async fn read_requests(read_half: OwnedReadHalf, conn: &mut Conn<'_>) {
    let shared = conn.shared;
    let mut reader = BufReader::with_capacity(FREE_LINE_BYTES, read_half);
    let mut line = LineBuf {
        line: Vec::new(),
        oversized: false,
        reserved: 0,
        budget: &shared.buffered,
        max: shared.opts.max_buffered_bytes,
    };
    let idle = shared.opts.idle_timeout;
    loop {
        let idle_at = idle.map(|d| conn.activity.last() + d);
        let (consumed, complete, eof) = {
            let buf = tokio::select! {
                r = reader.fill_buf() => match r {
                    Ok(b) => b,
                    Err(_) => return,
                },
                _ = conn.out.closed() => return,
                _ = sleep_until(idle_at) => {
                    if idle.is_some_and(|d| conn.activity.last().elapsed() >= d) {
                        let d = idle.unwrap_or_default();
                        let _ = conn.out.send(error_line(ErrorCode::Failed, format!(
                            "idle for {} s (control.idle_timeout_s); closing", d.as_secs()
                        ))).await;
                        return;
                    }
                    continue;
                }
            };
            conn.activity.touch();
            if buf.is_empty() {
                (0, !line.line.is_empty() || line.oversized, true)
            } else {
                let (take, complete) = match buf.iter().position(|&b| b == b'\n') {
                    Some(i) => (i, true),
                    None => (buf.len(), false),
                };
                if !line.extend(&buf[..take]) {
                    let _ = conn
                        .out
                        .send(error_line(
                            ErrorCode::InvalidRequest,
                            format!(
                                "too much unfinished request data buffered across clients (limit {} bytes, control.max_buffered_bytes); closing",
                                shared.opts.max_buffered_bytes
                            ),
                        ))
                        .await;
                    return;
                }
                (take + usize::from(complete), complete, false)
            }
        };
        reader.consume(consumed);
        if complete {
            let reply = if line.oversized {
                line.oversized = false;
                Some(error_line(
                    ErrorCode::InvalidRequest,
                    format!("request larger than {MAX_REQUEST_BYTES} bytes"),
                ))
            } else if line.line.iter().all(u8::is_ascii_whitespace) {
                None
            } else {
                Some(handle_line(&line.line, conn, reader.get_ref()).await)
            };
            line.reset();
            if let Some(reply) = reply {
                if conn.out.send(reply).await.is_err() {
                    return;
                }
            }
        }
        if eof {
            return;
        }
    }
}

async fn sleep_until(at: Option<Instant>) {
    match at {
        Some(at) => tokio::time::sleep_until(at.into()).await,
        None => std::future::pending().await,
    }
}

async fn handle_line(line: &[u8], conn: &mut Conn<'_>, socket: &OwnedReadHalf) -> String {
    let req = match parse_request(line) {
        Ok(r) => r,
        Err((id, e)) => return reply_line(&id, Err(e)),
    };
    let result = match req.method.as_str() {
        "subscribe" => subscribe(
            &conn.shared.machine,
            req.params,
            &conn.out,
            &conn.activity,
            &mut conn.events,
        ),
        "unsubscribe" => {
            if let Some(e) = conn.events.take() {
                e.abort();
            }
            Ok(json!({"ok": true}))
        }
        _ => {
            let token = Cancel::new();
            let call = dispatch(conn.shared, conn.role, req.method, req.params, &token);
            until_hangup(call, socket, &token).await
        }
    };
    reply_line(&req.id, result)
}

/// How often a running request checks whether its client hung up.
const HANGUP_POLL: Duration = Duration::from_millis(100);

/// Awaits `call`; if the client hangs up meanwhile (closes its socket: it can no longer read
/// the answer), cancels `token`, so that a `job.load` it asked for stops instead of holding
/// the one-at-a-time preparation lock, and then still awaits `call`, which ends soon. A
/// client that only shuts down its sending side (`printf … | socat`) still waits for its
/// answer and is not a hang-up.
async fn until_hangup<T>(
    call: impl Future<Output = T>,
    socket: &OwnedReadHalf,
    token: &Cancel,
) -> T {
    tokio::pin!(call);
    loop {
        tokio::select! {
            out = &mut call => return out,
            _ = tokio::time::sleep(HANGUP_POLL) => {
                if hung_up(socket) {
                    token.cancel(Why::Disconnected);
                    return call.await;
                }
            }
        }
    }
}

/// Whether the peer has closed the connection both ways (POLLHUP; a half-close sets only
/// POLLRDHUP).
fn hung_up(socket: &OwnedReadHalf) -> bool {
    use nix::poll::{poll, PollFd, PollFlags, PollTimeout};
    use std::os::fd::AsFd;
    let stream: &UnixStream = socket.as_ref();
    let mut fds = [PollFd::new(stream.as_fd(), PollFlags::empty())];
    matches!(poll(&mut fds, PollTimeout::ZERO), Ok(n) if n > 0)
        && fds[0]
            .revents()
            .is_some_and(|r| r.contains(PollFlags::POLLHUP))
}

/// Topics a client may subscribe to (`io`: health changes of Modbus links, naming link, unit
/// and points).
pub const TOPICS: &[&str] = &["mode", "fault", "progress", "job", "message", "task", "io"];

fn subscribe(
    machine: &Arc<dyn MachineApi>,
    params: Value,
    out: &mpsc::Sender<String>,
    activity: &Arc<Activity>,
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
    let activity = activity.clone();
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
                Ok(()) => activity.touch(),
                Err(mpsc::error::TrySendError::Full(_)) => dropped += 1,
                Err(mpsc::error::TrySendError::Closed(_)) => return,
            }
        }
    }));
    Ok(json!({"topics": list}))
}
