//! The Zenoh bridge (issue 15): a deployment's task interfaces on Zenoh, so that peers in
//! other processes and hosts (a vision job, a cell controller, a ROS 2 system through
//! rmw_zenoh) can watch and operate the machine without a home-made protocol.
//!
//! Time-critical loops stay local: the bridge runs on ordinary threads and meets the
//! realtime tasks only through the lock-free primitives (data-object readers, deferred event
//! subscriptions, the command queues behind the control methods). Keys are in [`keys`],
//! payloads (JSON) in [`codec`], the session settings in [`session`], the exporter in
//! [`export`] and its pool of call workers in [`calls`]; peers of other processes in
//! [`remote`] (and [`remote_host`], the `hytask peer` side), those a machine depends on
//! (`[[remote]]`) in [`watch`].
//!
//! Enabled by a `[zenoh]` table in the machine file (`config::zenoh`), local-only by default.
//!
//! # From ROS 2
//! ROS 2 over `rmw_zenoh` uses its own key layout (`<domain>/<topic>/<type>/<hash>`) and CDR
//! payloads, so ROS 2 nodes do not see these keys as topics directly. Two ways work: a
//! small adapter node that subscribes to `hytask/<machine>/**` with a Zenoh session (the
//! Python `eclipse-zenoh` package, as in `tests/zenoh/client.py`) and republishes to ROS
//! topics and services; or tools that speak plain Zenoh (`z_sub`, `z_get`, zenoh-bridge
//! plugins) next to the ROS graph, since `rmw_zenoh`'s router is an ordinary Zenoh router
//! the bridge can connect to (`[zenoh] connect = ["tcp/127.0.0.1:7447"]`).

pub mod calls;
pub mod codec;
pub mod export;
pub mod keys;
pub mod remote;
pub mod remote_host;
pub mod session;
pub mod watch;

pub use export::Bridge;

/// Why the bridge could not start.
#[derive(Debug, thiserror::Error)]
pub enum BridgeError {
    /// A `[zenoh]` setting Zenoh refused, or an exported name that does not exist.
    #[error("{key}: {message}")]
    Config {
        /// The key (`zenoh.ports`, `zenoh.zenoh_config`).
        key: String,
        /// What is wrong.
        message: String,
    },
    /// Zenoh failed (opening the session, declaring a key).
    #[error("zenoh: {0}")]
    Zenoh(String),
}
