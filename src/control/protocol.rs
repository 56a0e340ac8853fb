//! Wire format of the control socket: one JSON object per line, UTF-8, `\n`-terminated.
//!
//! ```text
//! request:  {"id": 7, "method": "status", "params": {}}
//! reply:    {"id": 7, "result": {...}}
//! error:    {"id": 7, "error": {"code": -32601, "message": "unknown method 'sttaus'"}}
//! event:    {"event": "mode", "data": {"mode": "idle"}}        (after "subscribe")
//! ```
//! `id` is any JSON value and is echoed back; it may be omitted (then replies carry
//! `"id": null`). `params` may be omitted when a method takes none. Error codes follow
//! JSON-RPC 2.0 for protocol errors and use small positive numbers for machine answers,
//! so a script can tell "you asked wrong" from "the machine said no".

use serde::Serialize;
use serde_json::{json, Value};

/// Largest request line accepted, bytes. Inline G-code jobs are the large requests; bigger
/// jobs are sent by path.
pub const MAX_REQUEST_BYTES: usize = 4 * 1024 * 1024;

/// Error codes on the wire.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum ErrorCode {
    /// -32700: the line is not valid JSON.
    ParseError,
    /// -32600: valid JSON but not a request object, or too large.
    InvalidRequest,
    /// -32601: no such method.
    MethodNotFound,
    /// -32602: parameters missing, of the wrong type or out of range.
    InvalidParams,
    /// 1: the machine refused in its current state.
    Rejected,
    /// 2: accepted but failed while running.
    Failed,
    /// 3: G-code error (message names file:line:col).
    Gcode,
    /// 4: the realtime side did not answer in time.
    Timeout,
    /// 5: not supported by this machine (e.g. sim inputs on real hardware).
    NotSupported,
    /// 6: this client's role may not call the method (see `control::access`).
    Forbidden,
}

impl ErrorCode {
    /// The number sent on the wire.
    pub fn as_i64(self) -> i64 {
        match self {
            ErrorCode::ParseError => -32700,
            ErrorCode::InvalidRequest => -32600,
            ErrorCode::MethodNotFound => -32601,
            ErrorCode::InvalidParams => -32602,
            ErrorCode::Rejected => 1,
            ErrorCode::Failed => 2,
            ErrorCode::Gcode => 3,
            ErrorCode::Timeout => 4,
            ErrorCode::NotSupported => 5,
            ErrorCode::Forbidden => 6,
        }
    }
}

/// An error reply before serialisation.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{message}")]
pub struct ControlError {
    /// Code.
    pub code: ErrorCode,
    /// Human-readable message.
    pub message: String,
}

impl ControlError {
    /// Builds an error.
    pub fn new(code: ErrorCode, message: impl Into<String>) -> Self {
        ControlError {
            code,
            message: message.into(),
        }
    }

    /// Invalid parameters.
    pub fn params(message: impl Into<String>) -> Self {
        Self::new(ErrorCode::InvalidParams, message)
    }
}

impl From<crate::machine::api::ApiError> for ControlError {
    fn from(e: crate::machine::api::ApiError) -> Self {
        use crate::machine::api::ApiError as E;
        let code = match &e {
            E::Rejected(_) => ErrorCode::Rejected,
            E::InvalidParams(_) => ErrorCode::InvalidParams,
            E::Gcode(_) => ErrorCode::Gcode,
            E::Failed(_) => ErrorCode::Failed,
            E::Timeout(_) => ErrorCode::Timeout,
            E::NotSupported(_) => ErrorCode::NotSupported,
        };
        ControlError::new(code, e.to_string())
    }
}

/// A parsed request.
#[derive(Debug, Clone, PartialEq)]
pub struct Request {
    /// Echoed id.
    pub id: Value,
    /// Method name.
    pub method: String,
    /// Parameters (`null` when absent).
    pub params: Value,
}

/// Parses one request line. On error returns the id (if one could be read) and the error.
pub fn parse_request(line: &[u8]) -> Result<Request, (Value, ControlError)> {
    let value: Value = serde_json::from_slice(line).map_err(|e| {
        (
            Value::Null,
            ControlError::new(ErrorCode::ParseError, format!("malformed JSON: {e}")),
        )
    })?;
    // serde_json keeps the last of duplicate keys: `{"method":"status","method":"job.run"}`
    // would run what a filter or a log reading the first key did not see.
    if let Err(e) = serde_json::from_slice::<NoDuplicateKeys>(line) {
        let id = match &value {
            Value::Object(o) => o.get("id").cloned().unwrap_or(Value::Null),
            _ => Value::Null,
        };
        return Err((
            id,
            ControlError::new(ErrorCode::InvalidRequest, format!("ambiguous request: {e}")),
        ));
    }
    let Value::Object(mut obj) = value else {
        return Err((
            Value::Null,
            ControlError::new(
                ErrorCode::InvalidRequest,
                "a request must be a JSON object {id, method, params}",
            ),
        ));
    };
    let id = obj.remove("id").unwrap_or(Value::Null);
    let method = match obj.remove("method") {
        Some(Value::String(m)) => m,
        Some(_) => {
            return Err((
                id,
                ControlError::new(ErrorCode::InvalidRequest, "'method' must be a string"),
            ))
        }
        None => {
            return Err((
                id,
                ControlError::new(ErrorCode::InvalidRequest, "missing 'method'"),
            ))
        }
    };
    let params = obj.remove("params").unwrap_or(Value::Null);
    if let Some(k) = obj.keys().next() {
        return Err((
            id,
            ControlError::new(ErrorCode::InvalidRequest, format!("unknown field '{k}'")),
        ));
    }
    Ok(Request { id, method, params })
}

/// Walks a JSON document and fails on an object with the same key twice, at any depth.
struct NoDuplicateKeys;

impl<'de> serde::Deserialize<'de> for NoDuplicateKeys {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        d.deserialize_any(NoDuplicateKeys)
    }
}

impl<'de> serde::de::Visitor<'de> for NoDuplicateKeys {
    type Value = NoDuplicateKeys;

    fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        f.write_str("any JSON value")
    }
    fn visit_bool<E>(self, _: bool) -> Result<Self, E> {
        Ok(self)
    }
    fn visit_i64<E>(self, _: i64) -> Result<Self, E> {
        Ok(self)
    }
    fn visit_u64<E>(self, _: u64) -> Result<Self, E> {
        Ok(self)
    }
    fn visit_f64<E>(self, _: f64) -> Result<Self, E> {
        Ok(self)
    }
    fn visit_str<E>(self, _: &str) -> Result<Self, E> {
        Ok(self)
    }
    fn visit_unit<E>(self) -> Result<Self, E> {
        Ok(self)
    }
    fn visit_seq<A: serde::de::SeqAccess<'de>>(self, mut seq: A) -> Result<Self, A::Error> {
        while seq.next_element::<NoDuplicateKeys>()?.is_some() {}
        Ok(self)
    }
    fn visit_map<A: serde::de::MapAccess<'de>>(self, mut map: A) -> Result<Self, A::Error> {
        let mut seen = std::collections::HashSet::new();
        while let Some(key) = map.next_key::<String>()? {
            if !seen.insert(key.clone()) {
                return Err(serde::de::Error::custom(format!("duplicate key '{key}'")));
            }
            map.next_value::<NoDuplicateKeys>()?;
        }
        Ok(self)
    }
}

/// Serialises a reply line (with trailing newline).
pub fn reply_line(id: &Value, result: Result<Value, ControlError>) -> String {
    let v = match result {
        Ok(r) => json!({"id": id, "result": r}),
        Err(e) => json!({"id": id, "error": {"code": e.code.as_i64(), "message": e.message}}),
    };
    let mut s = v.to_string();
    s.push('\n');
    s
}

/// Serialises an event line (with trailing newline).
pub fn event_line(topic: &str, data: &Value) -> String {
    let mut s = json!({"event": topic, "data": data}).to_string();
    s.push('\n');
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_full_and_minimal_requests() {
        let r = parse_request(br#"{"id": 3, "method": "status", "params": {"a": 1}}"#).unwrap();
        assert_eq!(r.id, json!(3));
        assert_eq!(r.method, "status");
        assert_eq!(r.params, json!({"a": 1}));
        let r = parse_request(br#"{"method":"estop"}"#).unwrap();
        assert_eq!(r.id, Value::Null);
        assert_eq!(r.params, Value::Null);
    }

    #[test]
    fn malformed_requests_get_specific_codes() {
        let (_, e) = parse_request(b"{not json").unwrap_err();
        assert_eq!(e.code, ErrorCode::ParseError);
        let (_, e) = parse_request(b"[1,2]").unwrap_err();
        assert_eq!(e.code, ErrorCode::InvalidRequest);
        let (id, e) = parse_request(br#"{"id":"x","method":5}"#).unwrap_err();
        assert_eq!((id, e.code), (json!("x"), ErrorCode::InvalidRequest));
        let (_, e) = parse_request(br#"{"id":1,"method":"status","extra":1}"#).unwrap_err();
        assert!(e.message.contains("extra"));
        let (id, e) = parse_request(br#"{"id":4,"method":"status","method":"estop"}"#).unwrap_err();
        assert_eq!((id, e.code), (json!(4), ErrorCode::InvalidRequest));
        assert!(
            e.message.contains("duplicate key 'method'"),
            "{}",
            e.message
        );
        let (_, e) =
            parse_request(br#"{"method":"override","params":{"feed":0.5,"feed":2}}"#).unwrap_err();
        assert!(e.message.contains("duplicate key 'feed'"), "{}", e.message);
        assert!(parse_request(br#"{"method":"x","params":[{"a":1},{"a":2}]}"#).is_ok());
    }

    #[test]
    fn reply_lines_are_single_json_lines() {
        let ok = reply_line(&json!(1), Ok(json!({"x": 1})));
        assert_eq!(ok, "{\"id\":1,\"result\":{\"x\":1}}\n");
        let err = reply_line(&json!(2), Err(ControlError::params("bad")));
        let v: Value = serde_json::from_str(err.trim_end()).unwrap();
        assert_eq!(v["error"]["code"], json!(-32602));
        assert_eq!(event_line("mode", &json!("idle")).matches('\n').count(), 1);
    }
}
