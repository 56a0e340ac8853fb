//! Who may do what on the control socket, by the peer's credentials (SO_PEERCRED).
//!
//! Two roles: an **observer** may watch (`status`, `subscribe`, `unsubscribe`, `tasks`,
//! `plc.vars`, `plc.get`) and trip the e-stop (stopping is never refused to anyone who can
//! reach the socket, as the red button on the machine is not); an **operator** may do
//! everything. Roles apply when
//! `[control] operators` or `observers` is configured; then root and the daemon's own user
//! are always operators, the lists decide for everyone else, and `[control] unlisted`
//! decides for a user in neither list (observer by default, or refused). Without either
//! list everyone who can open the socket is an operator: its mode and group are the
//! access control, as before roles existed.

use crate::config::{ControlConfig, UnlistedRole};
use std::collections::HashSet;

/// A client's role.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Role {
    /// May watch and e-stop.
    Observer,
    /// May do everything.
    Operator,
}

impl Role {
    /// Name used in messages.
    pub fn as_str(self) -> &'static str {
        match self {
            Role::Observer => "observer",
            Role::Operator => "operator",
        }
    }
}

/// Methods an observer may call.
pub const OBSERVER_METHODS: &[&str] = &[
    "status",
    "subscribe",
    "unsubscribe",
    "tasks",
    "estop",
    "plc.vars",
    "plc.get",
];

/// Whether `role` may call `method`.
pub fn permits(role: Role, method: &str) -> bool {
    role == Role::Operator || OBSERVER_METHODS.contains(&method)
}

/// A set of users and groups, resolved to ids.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Ids {
    /// User ids.
    pub uids: HashSet<u32>,
    /// Group ids.
    pub gids: HashSet<u32>,
}

/// The resolved role rules.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct AccessPolicy {
    /// Roles apply (a list is configured); otherwise everyone is an operator.
    pub enabled: bool,
    /// Operators.
    pub operators: Ids,
    /// Observers.
    pub observers: Ids,
    /// Role of a user in neither list; `None` refuses the connection.
    pub unlisted: Option<Role>,
    /// The daemon's own uid (always an operator).
    pub daemon_uid: u32,
}

impl Default for AccessPolicy {
    /// No roles: everyone who can connect is an operator.
    fn default() -> Self {
        AccessPolicy {
            enabled: false,
            operators: Ids::default(),
            observers: Ids::default(),
            unlisted: Some(Role::Observer),
            daemon_uid: nix::unistd::geteuid().as_raw(),
        }
    }
}

/// A user or group name in the config that does not exist on this host.
#[derive(Debug, thiserror::Error)]
#[error("control.{list}.{kind}: no {} named '{name}' on this host", &kind[..kind.len() - 1])]
pub struct UnknownName {
    /// `operators` or `observers`.
    pub list: &'static str,
    /// `users` or `groups`.
    pub kind: &'static str,
    /// The name.
    pub name: String,
}

impl AccessPolicy {
    /// Resolves the names of `[control]` to ids; an unknown name is an error (a typo must
    /// not silently demote or promote anyone).
    pub fn from_config(c: &ControlConfig) -> Result<AccessPolicy, UnknownName> {
        let resolve = |list: &'static str, p: &Option<crate::config::Principals>| {
            let mut ids = Ids::default();
            let Some(p) = p else { return Ok(ids) };
            for name in &p.users {
                let u = nix::unistd::User::from_name(name).ok().flatten();
                let u = u.ok_or_else(|| UnknownName {
                    list,
                    kind: "users",
                    name: name.clone(),
                })?;
                ids.uids.insert(u.uid.as_raw());
            }
            for name in &p.groups {
                let g = nix::unistd::Group::from_name(name).ok().flatten();
                let g = g.ok_or_else(|| UnknownName {
                    list,
                    kind: "groups",
                    name: name.clone(),
                })?;
                ids.gids.insert(g.gid.as_raw());
            }
            Ok(ids)
        };
        Ok(AccessPolicy {
            enabled: c.operators.is_some() || c.observers.is_some(),
            operators: resolve("operators", &c.operators)?,
            observers: resolve("observers", &c.observers)?,
            unlisted: match c.unlisted {
                UnlistedRole::Observer => Some(Role::Observer),
                UnlistedRole::None => None,
            },
            daemon_uid: nix::unistd::geteuid().as_raw(),
        })
    }

    /// The role of a peer with user `uid`, primary group `gid` and supplementary `groups`
    /// (`None` = refused). A peer without credentials is treated as an unlisted user.
    pub fn role(&self, peer: Option<(u32, u32)>, groups: &[u32]) -> Option<Role> {
        if !self.enabled {
            return Some(Role::Operator);
        }
        let Some((uid, gid)) = peer else {
            return self.unlisted;
        };
        if uid == 0 || uid == self.daemon_uid {
            return Some(Role::Operator);
        }
        let member = |ids: &Ids| {
            ids.uids.contains(&uid)
                || ids.gids.contains(&gid)
                || groups.iter().any(|g| ids.gids.contains(g))
        };
        if member(&self.operators) {
            Some(Role::Operator)
        } else if member(&self.observers) {
            Some(Role::Observer)
        } else {
            self.unlisted
        }
    }

    /// The role of a connected peer; looks up its supplementary groups (a blocking NSS
    /// lookup: call it off the reactor).
    pub fn role_of_peer(&self, peer: Option<(u32, u32)>) -> Option<Role> {
        if !self.enabled {
            return Some(Role::Operator);
        }
        let groups = peer.map(|(uid, gid)| supplementary_groups(uid, gid));
        self.role(peer, groups.as_deref().unwrap_or(&[]))
    }
}

fn supplementary_groups(uid: u32, gid: u32) -> Vec<u32> {
    let Ok(Some(user)) = nix::unistd::User::from_uid(nix::unistd::Uid::from_raw(uid)) else {
        return Vec::new();
    };
    let Ok(name) = std::ffi::CString::new(user.name) else {
        return Vec::new();
    };
    nix::unistd::getgrouplist(&name, nix::unistd::Gid::from_raw(gid))
        .map(|g| g.into_iter().map(|g| g.as_raw()).collect())
        .unwrap_or_default()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn policy() -> AccessPolicy {
        AccessPolicy {
            enabled: true,
            operators: Ids {
                uids: [1000].into(),
                gids: [50].into(),
            },
            observers: Ids {
                uids: [2000].into(),
                gids: HashSet::new(),
            },
            unlisted: Some(Role::Observer),
            daemon_uid: 990,
        }
    }

    #[test]
    fn root_the_daemon_and_listed_operators_are_operators() {
        let p = policy();
        assert_eq!(p.role(Some((0, 0)), &[]), Some(Role::Operator));
        assert_eq!(p.role(Some((990, 990)), &[]), Some(Role::Operator));
        assert_eq!(p.role(Some((1000, 1000)), &[]), Some(Role::Operator));
        assert_eq!(p.role(Some((1234, 50)), &[]), Some(Role::Operator));
        assert_eq!(p.role(Some((1234, 1234)), &[7, 50]), Some(Role::Operator));
    }

    #[test]
    fn observers_and_unlisted_users_watch_or_are_refused() {
        let mut p = policy();
        assert_eq!(p.role(Some((2000, 2000)), &[]), Some(Role::Observer));
        assert_eq!(p.role(Some((3000, 3000)), &[]), Some(Role::Observer));
        assert_eq!(p.role(None, &[]), Some(Role::Observer));
        p.unlisted = None;
        assert_eq!(p.role(Some((3000, 3000)), &[]), None);
        assert_eq!(p.role(Some((2000, 2000)), &[]), Some(Role::Observer));
    }

    #[test]
    fn without_lists_everyone_is_an_operator() {
        let p = AccessPolicy::default();
        assert_eq!(p.role(Some((3000, 3000)), &[]), Some(Role::Operator));
    }

    #[test]
    fn observers_may_watch_and_stop_but_not_move() {
        for m in ["status", "subscribe", "unsubscribe", "tasks", "estop"] {
            assert!(permits(Role::Observer, m), "{m}");
        }
        for m in [
            "machine.on",
            "home",
            "jog",
            "mdi",
            "job.load",
            "job.run",
            "estop.reset",
            "override",
            "call",
            "sim.input",
        ] {
            assert!(!permits(Role::Observer, m), "{m}");
            assert!(permits(Role::Operator, m), "{m}");
        }
    }

    #[test]
    fn unknown_names_in_the_config_are_errors_naming_the_key() {
        let c = ControlConfig {
            operators: Some(crate::config::Principals {
                users: vec!["no-such-user-hytask".into()],
                groups: vec![],
            }),
            ..ControlConfig::default()
        };
        let e = AccessPolicy::from_config(&c).unwrap_err().to_string();
        assert!(e.contains("control.operators.users") && e.contains("no-such-user-hytask"));
    }
}
