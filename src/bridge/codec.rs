//! Payloads: JSON, as on the control socket, so a remote caller needs no schema beyond what
//! `hytask tasks` prints.
//!
//! - Queries carry the parameters (`control/<method>`: the method's params; `op/<name>`:
//!   the operation's arguments, an object by parameter name as for the `call` method). An
//!   empty payload is `null` (no parameters).
//! - Replies: `{"status":"done","result":...}` on success; an error reply
//!   `{"status":"rejected"|"failed"|"timeout"|"invalid"|"forbidden","error":"..."}`.

use crate::control::protocol::{ControlError, ErrorCode};
use serde_json::{json, Value};

/// A request payload as JSON; `None`/empty is `null`.
pub fn decode(bytes: Option<&[u8]>) -> Result<Value, String> {
    match bytes {
        None => Ok(Value::Null),
        Some(b) if b.iter().all(u8::is_ascii_whitespace) => Ok(Value::Null),
        Some(b) => serde_json::from_slice(b).map_err(|e| format!("payload is not JSON: {e}")),
    }
}

/// A JSON value as payload bytes.
pub fn encode(v: &Value) -> Vec<u8> {
    serde_json::to_vec(v).unwrap_or_else(|_| b"null".to_vec())
}

/// The reply of a successful call.
pub fn done(result: Value) -> Value {
    json!({"status": "done", "result": result})
}

/// The error reply for `status` with message `error`.
pub fn failure(status: &str, error: impl std::fmt::Display) -> Value {
    json!({"status": status, "error": error.to_string()})
}

/// The error reply for a control-layer error, with the status word its code means.
pub fn control_failure(e: &ControlError) -> Value {
    let status = match e.code {
        ErrorCode::Rejected | ErrorCode::NotSupported => "rejected",
        ErrorCode::Timeout => "timeout",
        ErrorCode::Forbidden => "forbidden",
        ErrorCode::InvalidParams
        | ErrorCode::MethodNotFound
        | ErrorCode::ParseError
        | ErrorCode::InvalidRequest
        | ErrorCode::Gcode => "invalid",
        ErrorCode::Failed => "failed",
    };
    failure(status, &e.message)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn empty_payloads_are_null_and_bad_json_is_named() {
        assert_eq!(decode(None), Ok(Value::Null));
        assert_eq!(decode(Some(b"  ")), Ok(Value::Null));
        assert_eq!(decode(Some(b"{\"rpm\":100}")), Ok(json!({"rpm": 100})));
        assert!(decode(Some(b"{rpm"))
            .unwrap_err()
            .starts_with("payload is not JSON"));
    }
}
