//! The control socket: JSON lines `{id, method, params}` over a Unix domain socket, with
//! pushed events after `subscribe`. Scriptable with `socat`:
//!
//! ```text
//! echo '{"id":1,"method":"status"}' | socat - UNIX-CONNECT:/run/hytask/control.sock
//! ```
//! [`protocol`] holds the wire format, [`methods`] one file per method with its wire format,
//! [`server`] the connection handling and its robustness rules, [`listen`] taking the socket
//! path, [`access`] roles by peer credentials, [`client`] a blocking client.
//! The socket reaches the machine only through [`crate::machine::api::MachineApi`].

pub mod access;
pub mod client;
pub mod listen;
pub mod methods;
pub mod protocol;
pub mod server;
