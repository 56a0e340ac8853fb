//! `[[remote]]`: peers in other processes or hosts, reached over Zenoh (`bridge::remote`).
//!
//! A remote is named once, then tasks refer to its tasks as `"<remote>/<task>"`:
//!
//! ```toml
//! [[remote]]
//! name = "vision"       # how this file refers to it ("vision/camera")
//! machine = "vision"    # its key on Zenoh: hytask/vision/... (default: name)
//! timeout_s = 5.0       # topology check and every remote call give up after this
//! critical = false      # true: losing it stops this machine safely
//! check = true          # false: it exports no task list (a caller only feeding ports here)
//! ```
//!
//! Losing a remote is seen through its liveliness token (`hytask/<machine>/alive`), which
//! every exporter declares (`hytask peer`, and `hytask serve` with `[zenoh]`); Zenoh
//! withdraws it when the process dies or its link breaks. A machine file may list
//! `[[remote]]` tables too: the daemon watches them (`bridge::watch`).

use serde::{Deserialize, Serialize};

/// One `[[remote]]` table.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct RemoteConfig {
    /// Name used in `peer = "<name>/<task>"` references.
    pub name: String,
    /// Its Zenoh key (`hytask/<machine>/...`); default: `name`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub machine: Option<String>,
    /// Longest wait for its task list at configure time and for each remote call, s.
    #[serde(default = "default_timeout_s")]
    pub timeout_s: f64,
    /// Losing it (liveliness token withdrawn) stops this machine safely.
    #[serde(default)]
    pub critical: bool,
    /// Query its task list at configure time and refuse to start on a missing name.
    #[serde(default = "yes")]
    pub check: bool,
}

fn default_timeout_s() -> f64 {
    5.0
}
fn yes() -> bool {
    true
}

impl RemoteConfig {
    /// The remote's Zenoh key segment.
    pub fn machine(&self) -> &str {
        self.machine.as_deref().unwrap_or(&self.name)
    }

    /// Problems, each naming its key (`remote[i].timeout_s`).
    pub fn problems(list: &[RemoteConfig]) -> Vec<String> {
        let mut out = Vec::new();
        for (i, r) in list.iter().enumerate() {
            if r.name.is_empty() || r.name.contains('/') {
                out.push(format!(
                    "remote[{i}].name: '{}' must be non-empty and without '/'",
                    r.name
                ));
            }
            if !(r.timeout_s.is_finite() && r.timeout_s > 0.0) {
                out.push(format!(
                    "remote[{i}].timeout_s: {} must be a positive number of seconds",
                    r.timeout_s
                ));
            }
            if list[..i].iter().any(|o| o.name == r.name) {
                out.push(format!("remote[{i}].name: '{}' is declared twice", r.name));
            }
        }
        out
    }

    /// Splits a peer reference `"<remote>/<task>"`; `None` for a local peer name.
    pub fn split_peer(reference: &str) -> Option<(&str, &str)> {
        reference.split_once('/')
    }

    /// The remote named `name` in `list`, or an error naming the reference and the known names.
    pub fn find<'a>(list: &'a [RemoteConfig], name: &str) -> Result<&'a RemoteConfig, String> {
        list.iter().find(|r| r.name == name).ok_or_else(|| {
            let known: Vec<&str> = list.iter().map(|r| r.name.as_str()).collect();
            format!("no [[remote]] named '{name}' (declared: {known:?})")
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_and_problems_name_their_keys() {
        #[derive(Deserialize)]
        struct F {
            remote: Vec<RemoteConfig>,
        }
        let f: F = toml::from_str(
            "[[remote]]\nname = \"vision\"\n[[remote]]\nname = \"vision\"\ntimeout_s = 0\n",
        )
        .unwrap();
        assert_eq!(f.remote[0].machine(), "vision");
        assert_eq!(f.remote[0].timeout_s, 5.0);
        assert!(f.remote[0].check && !f.remote[0].critical);
        let p = RemoteConfig::problems(&f.remote);
        assert!(
            p.iter().any(|m| m.starts_with("remote[1].timeout_s")),
            "{p:?}"
        );
        assert!(p.iter().any(|m| m.contains("declared twice")), "{p:?}");
        assert_eq!(
            RemoteConfig::split_peer("vision/camera"),
            Some(("vision", "camera"))
        );
        assert!(RemoteConfig::find(&f.remote, "nope")
            .unwrap_err()
            .contains("'nope'"));
    }
}
