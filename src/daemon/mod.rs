//! Daemon life: systemd notification and watchdog, signals, and the testable
//! `run(config, listener, shutdown)` that the `serve` subcommand and the embedded daemon of
//! `hytask run` share.

pub mod notify;
