//! Opening the Zenoh session from `[zenoh]`: local-only unless the file says otherwise (see
//! `config::zenoh`), with TLS files and an optional Zenoh JSON5 file for access control.

use super::BridgeError;
use crate::config::ZenohConfig;

/// The Zenoh configuration for `cfg`: its `zenoh_config` file (or Zenoh's defaults), then
/// peer mode, the endpoints, multicast scouting and TLS from `cfg`.
pub fn zenoh_config(cfg: &ZenohConfig) -> Result<zenoh::Config, BridgeError> {
    let mut c = match &cfg.zenoh_config {
        Some(path) => zenoh::Config::from_file(path).map_err(|e| BridgeError::Config {
            key: "zenoh.zenoh_config".into(),
            message: format!("{}: {e}", path.display()),
        })?,
        None => zenoh::Config::default(),
    };
    let mut set = |key: &str, value: String| {
        c.insert_json5(key, &value)
            .map_err(|e| BridgeError::Config {
                key: format!("zenoh ({key})"),
                message: e.to_string(),
            })
    };
    set("mode", "\"peer\"".into())?;
    set("listen/endpoints", json_list(&cfg.listen))?;
    set("connect/endpoints", json_list(&cfg.connect))?;
    set(
        "scouting/multicast/enabled",
        cfg.multicast_scouting.to_string(),
    )?;
    if let Some(tls) = &cfg.tls {
        let path =
            |p: &std::path::Path| serde_json::Value::from(p.display().to_string()).to_string();
        set(
            "transport/link/tls/root_ca_certificate",
            path(&tls.root_ca_certificate),
        )?;
        if let Some(p) = &tls.listen_certificate {
            set("transport/link/tls/listen_certificate", path(p))?;
        }
        if let Some(p) = &tls.listen_private_key {
            set("transport/link/tls/listen_private_key", path(p))?;
        }
        if let Some(p) = &tls.connect_certificate {
            set("transport/link/tls/connect_certificate", path(p))?;
        }
        if let Some(p) = &tls.connect_private_key {
            set("transport/link/tls/connect_private_key", path(p))?;
        }
        set(
            "transport/link/tls/enable_mtls",
            tls.enable_mtls.to_string(),
        )?;
    }
    Ok(c)
}

fn json_list(items: &[String]) -> String {
    serde_json::Value::from(items.to_vec()).to_string()
}

/// Opens a session for `cfg`.
pub fn open(cfg: &ZenohConfig) -> Result<zenoh::Session, BridgeError> {
    use zenoh::Wait;
    zenoh::open(zenoh_config(cfg)?)
        .wait()
        .map_err(|e| BridgeError::Zenoh(format!("cannot open the session: {e}")))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_session_config_carries_endpoints_and_no_multicast() {
        let cfg: ZenohConfig = toml::from_str("listen = [\"tcp/127.0.0.1:17447\"]").unwrap();
        let c = zenoh_config(&cfg).unwrap();
        let listen = c.get_json("listen/endpoints").unwrap();
        assert!(listen.contains("tcp/127.0.0.1:17447"), "{listen}");
        assert_eq!(c.get_json("scouting/multicast/enabled").unwrap(), "false");
    }

    #[test]
    fn a_missing_zenoh_file_names_the_key() {
        let cfg: ZenohConfig = toml::from_str("zenoh_config = \"/nonexistent/z.json5\"").unwrap();
        let e = zenoh_config(&cfg).unwrap_err().to_string();
        assert!(e.contains("zenoh.zenoh_config"), "{e}");
    }
}
