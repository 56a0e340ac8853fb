//! Helpers shared by the Zenoh tests.
#![allow(clippy::unwrap_used, dead_code)]

/// A TCP port that was free a moment ago, for a Zenoh endpoint given in a config file.
/// The port is released before the daemon binds it, so another process could take it in
/// between; the window is short and ports come from the kernel's ephemeral range.
pub fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}
