//! A small blocking client for the control socket, used by the CLI and the end-to-end tests.

use serde_json::{json, Value};
use std::collections::VecDeque;
use std::io::{BufRead, BufReader, Write};
use std::os::unix::net::UnixStream;
use std::path::Path;
use std::time::Duration;

/// What can go wrong talking to the daemon.
#[derive(Debug, thiserror::Error)]
pub enum ClientError {
    /// Socket error (daemon not running, connection lost, timeout).
    #[error(transparent)]
    Io(#[from] std::io::Error),
    /// The daemon sent something that is not a valid reply.
    #[error("control socket: bad reply: {0}")]
    Protocol(String),
    /// The daemon answered with an error.
    #[error("{message} (code {code})")]
    Remote {
        /// Wire error code.
        code: i64,
        /// Message.
        message: String,
    },
}

/// A pushed event.
#[derive(Debug, Clone, PartialEq)]
pub struct Event {
    /// Topic.
    pub topic: String,
    /// Data.
    pub data: Value,
}

/// A connection to the daemon.
pub struct Client {
    reader: BufReader<UnixStream>,
    writer: UnixStream,
    next_id: u64,
    events: VecDeque<Event>,
}

impl Client {
    /// Connects to the socket at `path`.
    pub fn connect(path: &Path) -> Result<Client, ClientError> {
        let stream = UnixStream::connect(path)?;
        stream.set_read_timeout(Some(Duration::from_secs(30)))?;
        let writer = stream.try_clone()?;
        Ok(Client {
            reader: BufReader::new(stream),
            writer,
            next_id: 1,
            events: VecDeque::new(),
        })
    }

    /// Calls `method` and waits for its reply; events that arrive meanwhile are queued.
    pub fn call(&mut self, method: &str, params: Value) -> Result<Value, ClientError> {
        let id = self.next_id;
        self.next_id += 1;
        let mut line = json!({"id": id, "method": method, "params": params}).to_string();
        line.push('\n');
        self.writer.write_all(line.as_bytes())?;
        loop {
            let v = self.read_line()?;
            if v.get("event").is_some() {
                self.queue_event(v);
                continue;
            }
            if v.get("id") != Some(&json!(id)) {
                return Err(ClientError::Protocol(format!("reply for another id: {v}")));
            }
            if let Some(err) = v.get("error") {
                return Err(ClientError::Remote {
                    code: err.get("code").and_then(Value::as_i64).unwrap_or(0),
                    message: err
                        .get("message")
                        .and_then(Value::as_str)
                        .unwrap_or("")
                        .to_string(),
                });
            }
            return v
                .get("result")
                .cloned()
                .ok_or_else(|| ClientError::Protocol(format!("no result: {v}")));
        }
    }

    /// Waits up to `timeout` for the next pushed event.
    pub fn next_event(&mut self, timeout: Duration) -> Result<Option<Event>, ClientError> {
        if let Some(e) = self.events.pop_front() {
            return Ok(Some(e));
        }
        self.reader.get_ref().set_read_timeout(Some(timeout))?;
        let r = self.read_line();
        self.reader
            .get_ref()
            .set_read_timeout(Some(Duration::from_secs(30)))?;
        match r {
            Ok(v) if v.get("event").is_some() => {
                self.queue_event(v);
                Ok(self.events.pop_front())
            }
            Ok(v) => Err(ClientError::Protocol(format!("unexpected reply: {v}"))),
            Err(ClientError::Io(e))
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                ) =>
            {
                Ok(None)
            }
            Err(e) => Err(e),
        }
    }

    fn queue_event(&mut self, v: Value) {
        self.events.push_back(Event {
            topic: v["event"].as_str().unwrap_or("").to_string(),
            data: v.get("data").cloned().unwrap_or(Value::Null),
        });
    }

    fn read_line(&mut self) -> Result<Value, ClientError> {
        let mut line = String::new();
        if self.reader.read_line(&mut line)? == 0 {
            return Err(ClientError::Io(std::io::Error::new(
                std::io::ErrorKind::UnexpectedEof,
                "daemon closed the connection",
            )));
        }
        serde_json::from_str(line.trim_end()).map_err(|e| ClientError::Protocol(e.to_string()))
    }
}
