//! Daemon life: systemd notification and watchdog, signals, and the testable
//! `run(config, listener, shutdown)` that the `serve` subcommand and the embedded daemon of
//! `hytask run` share.

pub mod notify;

/// An in-process daemon on a private socket: what `hytask run` starts when no daemon is
/// reachable, and what tests use. (Built with the machine deployment.)
pub struct Embedded {
    _private: (),
}

impl Embedded {
    /// Starts the machine described by `config` (default: the built-in sim mill).
    pub fn start(_config: Option<&std::path::Path>) -> anyhow::Result<Embedded> {
        anyhow::bail!("the embedded machine is not built yet")
    }
    /// The socket to connect to.
    pub fn socket(&self) -> &std::path::Path {
        std::path::Path::new("")
    }
    /// Machine name.
    pub fn machine_name(&self) -> &str {
        ""
    }
    /// Whether it runs with realtime scheduling.
    pub fn realtime(&self) -> bool {
        false
    }
    /// Controlled stop, then exit.
    pub fn shutdown(self) -> anyhow::Result<()> {
        Ok(())
    }
}
