//! Heartbeats (COB-ID 0x700 + node): a consumer that watches each node against its consumer
//! time and reports a lost node by name, detects boot-ups and tracks NMT states; and a
//! producer. Fixed arrays indexed by node id: the per-cycle check never allocates.

use super::nmt::NmtState;
use super::{CanOpenError, NodeId};
use crate::can::CanFrame;
use std::time::Duration;

#[derive(Debug, Clone, Copy)]
struct Watch {
    timeout: Duration,
    last: Duration,
    lost: bool,
}

/// What a received heartbeat changed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum HeartbeatEvent {
    /// The node sent its boot-up message (first start, or it reset and lost its
    /// configuration).
    BootUp(NodeId),
    /// The node's NMT state changed.
    StateChanged {
        /// The node.
        node: NodeId,
        /// Previous state (`None` if never seen).
        from: Option<NmtState>,
        /// New state.
        to: NmtState,
    },
    /// A node that was reported lost is heard again.
    Recovered(NodeId),
}

/// The heartbeat consumer and NMT state tracker of the master.
#[derive(Debug, Clone)]
pub struct HeartbeatConsumer {
    watch: [Option<Watch>; 128],
    /// The watched node ids, so the per-cycle check visits only them.
    watched: [u8; 128],
    n_watched: usize,
    state: [Option<NmtState>; 128],
}

impl Default for HeartbeatConsumer {
    fn default() -> Self {
        HeartbeatConsumer {
            watch: [None; 128],
            watched: [0; 128],
            n_watched: 0,
            state: [None; 128],
        }
    }
}

impl HeartbeatConsumer {
    /// Starts watching `node`: from `now` on it must send a heartbeat at least every
    /// `timeout` (the consumer time, 0x1016; typically 1.5–3 × its producer time).
    pub fn watch(&mut self, node: NodeId, timeout: Duration, now: Duration) {
        if self.watch[usize::from(node.get())].is_none() {
            self.watched[self.n_watched] = node.get();
            self.n_watched += 1;
        }
        self.watch[usize::from(node.get())] = Some(Watch {
            timeout,
            last: now,
            lost: false,
        });
    }

    /// Stops watching `node` (its state is still tracked).
    pub fn unwatch(&mut self, node: NodeId) {
        if self.watch[usize::from(node.get())].take().is_some() {
            if let Some(i) = self.watched[..self.n_watched]
                .iter()
                .position(|&n| n == node.get())
            {
                self.watched.copy_within(i + 1..self.n_watched, i);
                self.n_watched -= 1;
            }
        }
    }

    /// The last NMT state `node` reported (boot-up reads as pre-operational: a node enters
    /// it right after the boot-up message).
    pub fn state(&self, node: NodeId) -> Option<NmtState> {
        self.state[usize::from(node.get())]
    }

    /// Handles a frame; `None` if it is not a heartbeat or changes nothing.
    pub fn on_frame(&mut self, f: &CanFrame, now: Duration) -> Option<HeartbeatEvent> {
        let (node, st) = NmtState::decode_heartbeat(f)?;
        let i = usize::from(node.get());
        let mut recovered = false;
        if let Some(w) = &mut self.watch[i] {
            w.last = now;
            recovered = core::mem::replace(&mut w.lost, false);
        }
        let prev = self.state[i];
        if st == NmtState::BootUp {
            self.state[i] = Some(NmtState::PreOperational);
            return Some(HeartbeatEvent::BootUp(node));
        }
        self.state[i] = Some(st);
        if recovered {
            Some(HeartbeatEvent::Recovered(node))
        } else if prev != Some(st) {
            Some(HeartbeatEvent::StateChanged {
                node,
                from: prev,
                to: st,
            })
        } else {
            None
        }
    }

    /// Returns the next node whose heartbeat is overdue at `now`, once per loss (call until
    /// `None`). Never allocates.
    pub fn check(&mut self, now: Duration) -> Option<CanOpenError> {
        for &id in &self.watched[..self.n_watched] {
            let i = usize::from(id);
            let Some(w) = &mut self.watch[i] else {
                continue;
            };
            let silent = now.saturating_sub(w.last);
            if !w.lost && silent > w.timeout {
                w.lost = true;
                let node = NodeId::new(id).ok()?;
                return Some(CanOpenError::HeartbeatLost {
                    node,
                    silent_ms: u64::try_from(silent.as_millis()).unwrap_or(u64::MAX),
                    timeout_ms: u64::try_from(w.timeout.as_millis()).unwrap_or(u64::MAX),
                });
            }
        }
        None
    }
}

/// Sends the heartbeat of one node every `period` (0x1017; zero disables).
#[derive(Debug, Clone)]
pub struct HeartbeatProducer {
    node: NodeId,
    period: Duration,
    next: Option<Duration>,
}

impl HeartbeatProducer {
    /// A producer for `node`.
    pub fn new(node: NodeId, period: Duration) -> HeartbeatProducer {
        HeartbeatProducer {
            node,
            period,
            next: None,
        }
    }

    /// Changes the period (a write of 0x1017); the next heartbeat goes out one new period
    /// after `now`.
    pub fn set_period(&mut self, period: Duration, now: Duration) {
        self.period = period;
        self.next = Some(now + period);
    }

    /// The configured period.
    pub fn period(&self) -> Duration {
        self.period
    }

    /// The heartbeat due at `now` in NMT state `state`, if any.
    pub fn poll(&mut self, now: Duration, state: NmtState) -> Option<CanFrame> {
        if self.period.is_zero() {
            return None;
        }
        let due = *self.next.get_or_insert(now);
        if now < due {
            return None;
        }
        // Next slot after now on the period grid, so a late poll does not send a burst.
        let mut next = due + self.period;
        if next <= now {
            next = now + self.period;
        }
        self.next = Some(next);
        Some(state.heartbeat_frame(self.node))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::error::{Error, ErrorKind};

    fn n(id: u8) -> NodeId {
        NodeId::new(id).unwrap()
    }
    fn ms(m: u64) -> Duration {
        Duration::from_millis(m)
    }

    #[test]
    fn a_silent_node_is_reported_once_by_name() {
        let mut c = HeartbeatConsumer::default();
        c.watch(n(3), ms(30), ms(0));
        c.watch(n(4), ms(30), ms(0));
        let hb3 = NmtState::Operational.heartbeat_frame(n(3));
        let hb4 = NmtState::Operational.heartbeat_frame(n(4));
        for t in (10..=100).step_by(10) {
            c.on_frame(&hb4, ms(t));
            if t <= 20 {
                c.on_frame(&hb3, ms(t));
            }
            let lost = c.check(ms(t));
            if t == 60 {
                let e = lost.expect("node 3 lost at 60 ms");
                assert_eq!(e.kind(), ErrorKind::Timeout);
                assert!(e.to_string().starts_with("node 3: heartbeat lost"), "{e}");
            } else {
                assert_eq!(lost, None, "t={t}");
            }
        }
        assert_eq!(
            c.on_frame(&hb3, ms(110)),
            Some(HeartbeatEvent::Recovered(n(3)))
        );
    }

    #[test]
    fn a_node_that_never_speaks_is_lost_too() {
        let mut c = HeartbeatConsumer::default();
        c.watch(n(9), ms(50), ms(1000));
        assert_eq!(c.check(ms(1050)), None);
        assert!(matches!(
            c.check(ms(1051)),
            Some(CanOpenError::HeartbeatLost { node, .. }) if node == n(9)
        ));
    }

    #[test]
    fn unwatched_nodes_are_not_reported() {
        let mut c = HeartbeatConsumer::default();
        c.watch(n(1), ms(10), ms(0));
        c.watch(n(2), ms(10), ms(0));
        c.watch(n(3), ms(10), ms(0));
        c.unwatch(n(2));
        c.watch(n(1), ms(10), ms(0));
        let mut lost = Vec::new();
        while let Some(CanOpenError::HeartbeatLost { node, .. }) = c.check(ms(11)) {
            lost.push(node.get());
        }
        assert_eq!(lost, [1, 3]);
    }

    #[test]
    fn boot_up_and_state_changes_are_tracked() {
        let mut c = HeartbeatConsumer::default();
        assert_eq!(
            c.on_frame(&NmtState::BootUp.heartbeat_frame(n(1)), ms(0)),
            Some(HeartbeatEvent::BootUp(n(1)))
        );
        assert_eq!(c.state(n(1)), Some(NmtState::PreOperational));
        assert_eq!(
            c.on_frame(&NmtState::PreOperational.heartbeat_frame(n(1)), ms(1)),
            None
        );
        assert_eq!(
            c.on_frame(&NmtState::Operational.heartbeat_frame(n(1)), ms(2)),
            Some(HeartbeatEvent::StateChanged {
                node: n(1),
                from: Some(NmtState::PreOperational),
                to: NmtState::Operational
            })
        );
    }

    #[test]
    fn producer_sends_on_its_period_without_bursts() {
        let mut p = HeartbeatProducer::new(n(2), ms(100));
        let st = NmtState::Operational;
        assert!(p.poll(ms(0), st).is_some());
        assert!(p.poll(ms(50), st).is_none());
        assert_eq!(p.poll(ms(100), st).map(|f| f.data()[0]), Some(0x05));
        assert!(p.poll(ms(450), st).is_some());
        assert!(p.poll(ms(451), st).is_none(), "late poll does not burst");
        p.set_period(Duration::ZERO, ms(500));
        assert!(p.poll(ms(10_000), st).is_none());
    }
}
