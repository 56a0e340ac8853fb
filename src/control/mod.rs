//! The control socket: JSON lines `{id, method, params}` over a Unix domain socket.
