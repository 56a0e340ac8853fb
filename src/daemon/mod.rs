//! Daemon life: systemd notification and watchdog, signals, and the testable
//! [`run`]`(machine, listener, shutdown)` shared by `hytask serve` and the embedded daemon
//! of `hytask run`.
//!
//! Shutdown order matters on a machine: on SIGTERM/SIGINT (or the shutdown future) the
//! control socket stops accepting, systemd is told `STOPPING=1`, every axis comes to a
//! controlled stop and the drives are disabled, and only then does the process exit 0.

pub mod notify;

use crate::control::listen::{self, Listener};
use crate::control::server::{self, ServerOptions};
use crate::machine::api::MachineApi;
use notify::Notifier;
use std::future::Future;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

/// What the daemon needs of a deployed machine beyond the operator API.
pub trait Deployed: MachineApi {
    /// Machine name from the config.
    fn name(&self) -> String;
    /// Whether the realtime threads run with SCHED_FIFO and locked memory.
    fn realtime(&self) -> bool;
    /// Cycles the servo thread has completed; the watchdog checks that it advances.
    fn servo_cycles(&self) -> u64;
    /// Controlled stop of all axes, drives disabled, realtime threads stopped.
    fn shutdown(&self) -> anyhow::Result<()>;
}

/// After the machine has stopped, how long the daemon waits for requests still running on
/// the blocking pool (a `job.load` reading a slow file, say) before it exits anyway.
pub const SHUTDOWN_GRACE: Duration = Duration::from_secs(2);

/// Serves the control socket for `machine` until `shutdown` completes or SIGTERM/SIGINT
/// arrives, then stops the machine under control. Notifies systemd and feeds its watchdog
/// when started by it. The claim on the socket path is held until the machine has stopped,
/// so that a successor cannot start while this daemon still drives the machine.
pub fn run(
    machine: Arc<dyn Deployed>,
    listener: Listener,
    shutdown: impl Future<Output = ()> + Send + 'static,
) -> anyhow::Result<()> {
    run_with(machine, listener, ServerOptions::default(), shutdown)
}

/// [`run`] with the server options of `[control]` ([`ServerOptions::from_config`]).
pub fn run_with(
    machine: Arc<dyn Deployed>,
    listener: Listener,
    options: ServerOptions,
    shutdown: impl Future<Output = ()> + Send + 'static,
) -> anyhow::Result<()> {
    serve_until(machine, listener, options, shutdown, true)
}

/// [`run_with`]; `watch_sigint` false leaves Ctrl-C to the embedding command (`hytask run`
/// holds the job on the first press and aborts on the second, then stops this daemon).
fn serve_until(
    machine: Arc<dyn Deployed>,
    listener: Listener,
    options: ServerOptions,
    shutdown: impl Future<Output = ()> + Send + 'static,
    watch_sigint: bool,
) -> anyhow::Result<()> {
    let (listener, claim) = listener.into_parts();
    let notifier = Notifier::from_env();
    let stop_watchdog = Arc::new(AtomicBool::new(false));
    let watchdog = Notifier::watchdog_interval().map(|interval| {
        let machine = machine.clone();
        let stop = stop_watchdog.clone();
        std::thread::Builder::new()
            .name("watchdog".into())
            .spawn(move || feed_watchdog(&*machine, interval, &stop))
    });
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .thread_name("control")
        .enable_all()
        .build()?;
    let api: Arc<dyn MachineApi> = machine.clone();
    let (name, realtime) = (machine.name(), machine.realtime());
    rt.block_on(async move {
        let listener = tokio::net::UnixListener::from_std(listener)?;
        let _ = notifier.notify(&format!(
            "READY=1\nSTATUS=machine '{name}' running{}",
            if realtime { "" } else { " (not realtime)" }
        ));
        tracing::info!("machine '{name}' ready");
        server::serve_with(listener, api, options, async move {
            let mut term =
                match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
                    Ok(s) => s,
                    Err(e) => {
                        tracing::error!("cannot watch SIGTERM: {e}");
                        shutdown.await;
                        return;
                    }
                };
            tokio::select! {
                _ = shutdown => tracing::info!("shutdown requested"),
                _ = term.recv() => tracing::info!("SIGTERM: stopping the machine"),
                _ = async {
                    if !watch_sigint || tokio::signal::ctrl_c().await.is_err() {
                        std::future::pending::<()>().await
                    }
                } => tracing::info!("SIGINT: stopping the machine"),
            }
        })
        .await;
        let _ = notifier.notify("STOPPING=1");
        anyhow::Ok(())
    })?;
    let result = machine.shutdown();
    // A request blocked in a read must not keep the process alive once the axes stopped.
    rt.shutdown_timeout(SHUTDOWN_GRACE);
    stop_watchdog.store(true, Ordering::Release);
    if let Some(Ok(w)) = watchdog {
        let _ = w.join();
    }
    drop(claim);
    result
}

/// Pings systemd only while the servo thread makes progress: a hung servo loop stops the
/// pings and systemd restarts the daemon.
fn feed_watchdog(machine: &dyn Deployed, interval: Duration, stop: &AtomicBool) {
    let notifier = Notifier::from_env();
    let mut last = machine.servo_cycles();
    while !stop.load(Ordering::Acquire) {
        std::thread::sleep(interval);
        let now = machine.servo_cycles();
        if now != last {
            let _ = notifier.notify("WATCHDOG=1");
        } else {
            tracing::error!(
                "servo thread made no progress for {interval:?}; not feeding the watchdog"
            );
        }
        last = now;
    }
}

/// An in-process daemon on a private socket: what `hytask run` starts when no daemon is
/// reachable, and what tests use. It does not react to SIGINT: Ctrl-C belongs to the command
/// in front (a daemon thread shutting the socket on Ctrl-C made `hytask run` fail with
/// "Broken pipe" while it was still following the job); the command calls
/// [`shutdown`](Embedded::shutdown) when it is done.
pub struct Embedded {
    machine: Arc<dyn Deployed>,
    socket: PathBuf,
    _dir: tempdir::Dir,
    stop: Option<tokio::sync::oneshot::Sender<()>>,
    thread: Option<std::thread::JoinHandle<anyhow::Result<()>>>,
}

impl Embedded {
    /// Starts the machine described by `config` (default: the built-in sim mill).
    pub fn start(config: Option<&Path>) -> anyhow::Result<Embedded> {
        let cfg = crate::machine::load_config(config)?;
        Self::start_with(&cfg.control, || Ok(crate::machine::deploy_from(config)?))
    }

    /// Starts what `deploy` deploys (a machine, a cell), served with the options of
    /// `control` on a private socket.
    pub fn start_with(
        control: &crate::config::ControlConfig,
        deploy: impl FnOnce() -> anyhow::Result<Arc<dyn Deployed>>,
    ) -> anyhow::Result<Embedded> {
        let options = ServerOptions::from_config(control)?;
        let dir = tempdir::Dir::new()?;
        let socket = dir.path().join("control.sock");
        // The path is claimed before the machine is deployed, as `hytask serve` does.
        let claim = listen::claim(&listen::SocketOptions {
            path: socket.clone(),
            mode: 0o600,
            group: None,
        })?;
        let machine = deploy()?;
        let listener = claim.bind()?;
        let (tx, rx) = tokio::sync::oneshot::channel::<()>();
        let m = machine.clone();
        let thread = std::thread::Builder::new()
            .name("embedded-daemon".into())
            .spawn(move || {
                serve_until(
                    m,
                    listener,
                    options,
                    async move {
                        let _ = rx.await;
                    },
                    false,
                )
            })?;
        Ok(Embedded {
            machine,
            socket,
            _dir: dir,
            stop: Some(tx),
            thread: Some(thread),
        })
    }

    /// The socket to connect to.
    pub fn socket(&self) -> &Path {
        &self.socket
    }

    /// Machine name.
    pub fn machine_name(&self) -> String {
        self.machine.name()
    }

    /// Whether it runs with realtime scheduling.
    pub fn realtime(&self) -> bool {
        self.machine.realtime()
    }

    /// Controlled stop, then exit.
    pub fn shutdown(mut self) -> anyhow::Result<()> {
        self.stop_and_join()
    }

    fn stop_and_join(&mut self) -> anyhow::Result<()> {
        if let Some(s) = self.stop.take() {
            let _ = s.send(());
        }
        match self.thread.take() {
            Some(t) => t
                .join()
                .map_err(|_| anyhow::anyhow!("embedded daemon thread panicked"))?,
            None => Ok(()),
        }
    }
}

impl Drop for Embedded {
    fn drop(&mut self) {
        let _ = self.stop_and_join();
    }
}

/// A private temporary directory for the embedded daemon's socket, removed on drop.
mod tempdir {
    use std::path::{Path, PathBuf};

    pub struct Dir(PathBuf);

    impl Dir {
        pub fn new() -> std::io::Result<Dir> {
            use std::os::unix::fs::DirBuilderExt;
            let base = std::env::temp_dir();
            for n in 0..1000u32 {
                let p = base.join(format!("hytask-{}-{n}", std::process::id()));
                match std::fs::DirBuilder::new().mode(0o700).create(&p) {
                    Ok(()) => return Ok(Dir(p)),
                    Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => continue,
                    Err(e) => return Err(e),
                }
            }
            Err(std::io::Error::other("no free temporary directory name"))
        }

        pub fn path(&self) -> &Path {
            &self.0
        }
    }

    impl Drop for Dir {
        fn drop(&mut self) {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }
}
