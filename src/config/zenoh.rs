//! `[zenoh]`: export the machine's task interfaces over Zenoh (issue 15; `src/bridge/`).
//!
//! Local-only by default: the bridge listens on loopback, connects nowhere and does not scout
//! by multicast, so nothing leaves the host unless the file says so. An endpoint off the
//! host must use TLS (`tls/...` with `[zenoh.tls]`), or the file must opt in to plain TCP
//! explicitly (`allow_plain_network = true`, for a closed machine network); remote callers
//! then default to the observer role. Zenoh's own access control (and any other Zenoh
//! setting) comes from an optional Zenoh JSON5 file (`zenoh_config`), on top of which
//! these keys apply.
//!
//! ```toml
//! [zenoh]
//! listen = ["tcp/127.0.0.1:7447"]      # default
//! role = "operator"                    # default when every endpoint is local
//! port_rate_hz = 50.0                  # data-object ports published at most this often
//! status_rate_hz = 10.0
//! ```

use super::error::Issues;
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// What remote callers may do (the control socket's roles).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum ZenohRole {
    /// Read ports, status and events; call only the observer methods (e-stop, status).
    Observer,
    /// Everything the control socket's operator may do.
    Operator,
}

/// TLS files (Zenoh's `transport/link/tls` settings).
#[derive(Debug, Clone, PartialEq, Eq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct ZenohTls {
    /// CA certificate that signs the peers' certificates (PEM).
    pub root_ca_certificate: PathBuf,
    /// This host's certificate (PEM), for listening.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub listen_certificate: Option<PathBuf>,
    /// This host's private key (PEM), for listening.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub listen_private_key: Option<PathBuf>,
    /// Require and check client certificates (mutual TLS); when connecting, present
    /// `connect_certificate`.
    #[serde(default)]
    pub enable_mtls: bool,
    /// This host's certificate (PEM) when it connects to a peer requiring mutual TLS.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub connect_certificate: Option<PathBuf>,
    /// Its private key (PEM).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub connect_private_key: Option<PathBuf>,
}

/// `[zenoh]`.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct ZenohConfig {
    /// First key segment after `hytask/`: default the machine's name.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub key: Option<String>,
    /// Zenoh endpoints to listen on (`tcp/127.0.0.1:7447`, `unixsock-stream//run/x.sock`,
    /// `tls/host:7447`).
    #[serde(default = "default_listen")]
    pub listen: Vec<String>,
    /// Zenoh endpoints to connect to (routers or peers).
    #[serde(default)]
    pub connect: Vec<String>,
    /// Multicast scouting (discovering peers on the LAN). Off: peers are configured.
    #[serde(default)]
    pub multicast_scouting: bool,
    /// Plain TCP to endpoints off this host (otherwise refused: use `tls/`).
    #[serde(default)]
    pub allow_plain_network: bool,
    /// TLS files, required by `tls/` endpoints.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tls: Option<ZenohTls>,
    /// A Zenoh JSON5 configuration (access control, timeouts...) the keys above override.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub zenoh_config: Option<PathBuf>,
    /// Role of remote callers; default operator when every endpoint is local, observer
    /// otherwise.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub role: Option<ZenohRole>,
    /// Data-object ports are published when they changed, at most this often.
    #[serde(default = "default_port_rate")]
    pub port_rate_hz: f64,
    /// The machine status is published this often.
    #[serde(default = "default_status_rate")]
    pub status_rate_hz: f64,
    /// Ports to publish (data-object names); absent: every port whose type is exportable.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ports: Option<Vec<String>>,
    /// Longest a remote operation call may take before it is answered with a timeout, s.
    #[serde(default = "default_call_timeout")]
    pub call_timeout_s: f64,
}

fn default_listen() -> Vec<String> {
    vec!["tcp/127.0.0.1:7447".into()]
}
fn default_port_rate() -> f64 {
    50.0
}
fn default_status_rate() -> f64 {
    10.0
}
fn default_call_timeout() -> f64 {
    30.0
}

/// Whether a Zenoh endpoint stays on this host (loopback address or Unix socket).
pub fn endpoint_is_local(endpoint: &str) -> bool {
    let Some((proto, addr)) = endpoint.split_once('/') else {
        return false;
    };
    if proto.starts_with("unixsock") {
        return true;
    }
    // `host:port`, possibly `[v6]:port`, possibly followed by `#config` or `?metadata`.
    let addr = addr.split(['#', '?']).next().unwrap_or_default();
    let host = match addr.rsplit_once(':') {
        Some((h, _)) => h.trim_start_matches('[').trim_end_matches(']'),
        None => addr,
    };
    host == "localhost"
        || host
            .parse::<std::net::IpAddr>()
            .map(|ip| ip.is_loopback())
            .unwrap_or(false)
}

const PROTOCOLS: [&str; 3] = ["tcp", "tls", "unixsock-stream"];

impl ZenohConfig {
    /// True when every endpoint stays on this host.
    pub fn local_only(&self) -> bool {
        self.listen
            .iter()
            .chain(&self.connect)
            .all(|e| endpoint_is_local(e))
            && !self.multicast_scouting
    }

    /// The role remote callers get.
    pub fn effective_role(&self) -> ZenohRole {
        self.role.unwrap_or(if self.local_only() {
            ZenohRole::Operator
        } else {
            ZenohRole::Observer
        })
    }

    pub(super) fn validate(&self, issues: &mut Issues) {
        let lists = [("listen", &self.listen), ("connect", &self.connect)];
        for (name, list) in lists {
            for (i, e) in list.iter().enumerate() {
                let key = format!("zenoh.{name}[{i}]");
                let proto = e.split_once('/').map(|(p, _)| p);
                match proto {
                    Some(p) if PROTOCOLS.contains(&p) => {}
                    _ => {
                        issues.push(
                            key,
                            format!("'{e}': expected one of {PROTOCOLS:?} followed by '/address'"),
                        );
                        continue;
                    }
                }
                if proto == Some("tls") && self.tls.is_none() {
                    issues.push(key, format!("'{e}' is a TLS endpoint: add [zenoh.tls]"));
                } else if proto == Some("tcp") && !endpoint_is_local(e) && !self.allow_plain_network
                {
                    issues.push(
                        key,
                        format!(
                            "'{e}' leaves this host in plain TCP: use tls/ with [zenoh.tls], \
                             or set zenoh.allow_plain_network = true for a closed network"
                        ),
                    );
                }
            }
        }
        if let Some(tls) = &self.tls {
            match (&tls.connect_certificate, &tls.connect_private_key) {
                (Some(_), None) => issues.push(
                    "zenoh.tls.connect_private_key",
                    "needed with zenoh.tls.connect_certificate",
                ),
                (None, Some(_)) => issues.push(
                    "zenoh.tls.connect_certificate",
                    "needed with zenoh.tls.connect_private_key",
                ),
                _ => {}
            }
        }
        if self.listen.is_empty() && self.connect.is_empty() {
            issues.push("zenoh.listen", "no endpoint: listen or connect somewhere");
        }
        for (key, hz) in [
            ("zenoh.port_rate_hz", self.port_rate_hz),
            ("zenoh.status_rate_hz", self.status_rate_hz),
        ] {
            if !(hz > 0.0 && hz <= 10_000.0) {
                issues.push(key, format!("must be in (0, 10000] Hz, got {hz}"));
            }
        }
        if !(self.call_timeout_s > 0.0 && self.call_timeout_s <= 3600.0) {
            issues.push(
                "zenoh.call_timeout_s",
                format!("must be in (0, 3600] s, got {}", self.call_timeout_s),
            );
        }
        if let Some(k) = &self.key {
            if !crate::config::zenoh::key_segment_ok(k) {
                issues.push(
                    "zenoh.key",
                    format!("'{k}': one key segment, without '/', '*', '$', '#', '?' or spaces"),
                );
            }
        }
    }
}

/// Whether `s` can be one segment of a Zenoh key expression.
pub fn key_segment_ok(s: &str) -> bool {
    !s.is_empty() && !s.contains(['/', '*', '$', '#', '?', ' '])
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cfg(toml_text: &str) -> ZenohConfig {
        toml::from_str(toml_text).unwrap()
    }

    fn issues(c: &ZenohConfig) -> Vec<String> {
        let mut i = Issues::default();
        c.validate(&mut i);
        i.into_vec().into_iter().map(|i| i.to_string()).collect()
    }

    #[test]
    fn the_default_is_local_with_operator_callers() {
        let c = cfg("");
        assert_eq!(c.listen, vec!["tcp/127.0.0.1:7447"]);
        assert!(c.local_only());
        assert_eq!(c.effective_role(), ZenohRole::Operator);
        assert!(issues(&c).is_empty());
    }

    #[test]
    fn endpoints_on_loopback_or_unix_sockets_are_local() {
        for e in [
            "tcp/127.0.0.1:7447",
            "tcp/[::1]:7447",
            "tcp/localhost:1",
            "unixsock-stream//run/hytask/z.sock",
        ] {
            assert!(endpoint_is_local(e), "{e}");
        }
        for e in [
            "tcp/0.0.0.0:7447",
            "tcp/192.168.1.5:7447",
            "tls/cell.local:7447",
        ] {
            assert!(!endpoint_is_local(e), "{e}");
        }
    }

    #[test]
    fn plain_tcp_off_the_host_is_refused_naming_the_key() {
        let c = cfg("listen = [\"tcp/127.0.0.1:7447\", \"tcp/0.0.0.0:7447\"]");
        let i = issues(&c);
        assert_eq!(i.len(), 1, "{i:?}");
        assert!(i[0].starts_with("zenoh.listen[1]: 'tcp/0.0.0.0:7447' leaves this host"));
        let c = cfg("listen = [\"tcp/0.0.0.0:7447\"]\nallow_plain_network = true");
        assert!(issues(&c).is_empty());
        assert_eq!(c.effective_role(), ZenohRole::Observer);
    }

    #[test]
    fn tls_endpoints_need_tls_files_and_unknown_protocols_are_named() {
        let c = cfg("connect = [\"tls/router:7447\", \"quic/x:1\"]");
        let i = issues(&c);
        assert!(i
            .iter()
            .any(|m| m.starts_with("zenoh.connect[0]: 'tls/router:7447' is a TLS")));
        assert!(i
            .iter()
            .any(|m| m.starts_with("zenoh.connect[1]: 'quic/x:1': expected")));
    }

    #[test]
    fn a_connect_certificate_needs_its_key() {
        let c = cfg("[tls]\nroot_ca_certificate = \"ca.pem\"\nconnect_certificate = \"c.pem\"");
        let i = issues(&c);
        assert!(
            i.iter()
                .any(|m| m.starts_with("zenoh.tls.connect_private_key")),
            "{i:?}"
        );
    }

    #[test]
    fn rates_and_key_are_checked() {
        let c = cfg("port_rate_hz = 0.0\nkey = \"a/b\"");
        let i = issues(&c);
        assert!(i.iter().any(|m| m.starts_with("zenoh.port_rate_hz")));
        assert!(i.iter().any(|m| m.starts_with("zenoh.key")));
    }
}
