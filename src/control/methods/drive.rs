//! `drive.sdo_read` and `drive.sdo_write`: read or write an object of a CANopen drive by
//! SDO, on the non-realtime path (a bus of its own, one transfer per interface at a time;
//! the servo thread never waits for it).
//!
//! ```text
//! → {"id":1,"method":"drive.sdo_read","params":{"drive":"x-servo","index":"0x6064","sub":0}}
//! ← {"id":1,"result":{"data":"a0860100","value":100000}}
//! → {"id":2,"method":"drive.sdo_write","params":{"drive":"x-servo","index":"0x1017","sub":0,"value":50,"size":2}}
//! → {"id":3,"method":"drive.sdo_write","params":{"drive":"x-servo","index":24672,"sub":0,"data":"08"}}
//! ← {"id":n,"result":{"ok":true}}
//! ```
//! `index` is a number or a `"0x…"` string; `data` is hex, little-endian as on the bus;
//! `value` is an integer written in `size` bytes (1, 2 or 4; default 4). A read answers the
//! raw bytes and, up to 8 bytes, their unsigned little-endian value. An abort, a timeout or
//! an unknown drive is an error naming node and object. Operators only (a write changes the
//! drive, and some reads have side effects).

use super::{ok, parse, ControlError};
use crate::machine::api::MachineApi;
use serde::Deserialize;
use serde_json::{json, Value};

#[derive(Deserialize)]
#[serde(untagged)]
enum Index {
    Number(u16),
    Text(String),
}

impl Index {
    fn get(&self) -> Result<u16, ControlError> {
        match self {
            Index::Number(n) => Ok(*n),
            Index::Text(t) => {
                let hex = t.strip_prefix("0x").or_else(|| t.strip_prefix("0X"));
                match hex {
                    Some(h) => u16::from_str_radix(h, 16),
                    None => t.parse(),
                }
                .map_err(|_| ControlError::params(format!("index {t:?}: not a 16-bit number")))
            }
        }
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ReadParams {
    drive: String,
    index: Index,
    #[serde(default)]
    sub: u8,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct WriteParams {
    drive: String,
    index: Index,
    #[serde(default)]
    sub: u8,
    #[serde(default)]
    data: Option<String>,
    #[serde(default)]
    value: Option<i64>,
    #[serde(default)]
    size: Option<u8>,
}

fn hex(data: &[u8]) -> String {
    data.iter().map(|b| format!("{b:02x}")).collect()
}

fn unhex(s: &str) -> Result<Vec<u8>, ControlError> {
    let bad = || ControlError::params(format!("data {s:?}: not an even number of hex digits"));
    if !s.len().is_multiple_of(2) {
        return Err(bad());
    }
    (0..s.len())
        .step_by(2)
        .map(|i| s.get(i..i + 2).and_then(|b| u8::from_str_radix(b, 16).ok()))
        .collect::<Option<Vec<u8>>>()
        .ok_or_else(bad)
}

pub(super) fn handle_read(m: &dyn MachineApi, params: Value) -> Result<Value, ControlError> {
    let p: ReadParams = parse(params)?;
    let data = m.sdo_read(&p.drive, p.index.get()?, p.sub)?;
    let value = (data.len() <= 8).then(|| {
        let mut b = [0u8; 8];
        b[..data.len()].copy_from_slice(&data);
        u64::from_le_bytes(b)
    });
    Ok(json!({"data": hex(&data), "value": value}))
}

pub(super) fn handle_write(m: &dyn MachineApi, params: Value) -> Result<Value, ControlError> {
    let p: WriteParams = parse(params)?;
    let data = match (&p.data, p.value) {
        (Some(d), None) => unhex(d)?,
        (None, Some(v)) => {
            let size = usize::from(p.size.unwrap_or(4));
            if ![1, 2, 4].contains(&size) {
                return Err(ControlError::params(format!(
                    "size {size}: must be 1, 2 or 4"
                )));
            }
            let lo = -(1i64 << (8 * size - 1));
            let hi = (1i64 << (8 * size)) - 1;
            if !(lo..=hi).contains(&v) {
                return Err(ControlError::params(format!(
                    "value {v} does not fit {size} byte(s)"
                )));
            }
            v.to_le_bytes()[..size].to_vec()
        }
        _ => return Err(ControlError::params("give exactly one of data or value")),
    };
    m.sdo_write(&p.drive, p.index.get()?, p.sub, &data)?;
    Ok(ok())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hex_round_trips_and_refuses_odd_digits() {
        assert_eq!(hex(&[0xa0, 0x86, 0x01, 0x00]), "a0860100");
        assert_eq!(unhex("a0860100").unwrap(), [0xa0, 0x86, 0x01, 0x00]);
        assert!(unhex("abc").is_err());
        assert!(unhex("zz").is_err());
        assert_eq!(Index::Text("0x6064".into()).get().unwrap(), 0x6064);
        assert_eq!(Index::Text("24676".into()).get().unwrap(), 24676);
        assert!(Index::Text("0x10000".into()).get().is_err());
    }
}
