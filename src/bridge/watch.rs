//! `[[remote]]` of a machine: peers in other processes it depends on, watched on the
//! bridge's session. Each is reached at start (its task list within `timeout_s`, unless
//! `check = false`: a missing peer refuses the start, naming it), then its liveliness token
//! is watched: when Zenoh withdraws it (the process died, the link broke) the machine hears
//! of it at once through [`MachineApi::remote_lost`], which reports it and, for a
//! `critical` peer, stops the machine under control.

use super::remote::{RemoteError, RemoteLink};
use crate::config::remote::RemoteConfig;
use crate::machine::api::MachineApi;
use std::sync::Arc;

/// Connects every remote of `remotes` on `session` and hands each loss to `machine`; the
/// links live as long as the returned list.
pub fn watch(
    session: &zenoh::Session,
    machine: &Arc<dyn MachineApi>,
    remotes: &[RemoteConfig],
) -> Result<Vec<RemoteLink>, RemoteError> {
    remotes
        .iter()
        .map(|cfg| {
            let link = RemoteLink::connect(session, cfg)?;
            let m = Arc::downgrade(machine);
            link.on_lost(move |msg, critical| {
                if let Some(m) = m.upgrade() {
                    m.remote_lost(msg, critical);
                }
            });
            tracing::info!(
                "watching remote peer '{}' (hytask/{}){}",
                cfg.name,
                cfg.machine(),
                if cfg.critical { ", critical" } else { "" }
            );
            Ok(link)
        })
        .collect()
}
