//! The realtime side of a remote proxy (`hytask::bridge::remote::RemoteProxy`): its `accept`
//! hands the command to the proxy's worker and wakes it (`Thread::unpark`) without
//! allocating, and the worker sleeps while it has no call (parked, not polling).
//!
//! A counting global allocator counts every allocation made inside a realtime step on any
//! thread (the local proxies' and the in-process remote's tasks). One test function on
//! purpose: the count is process-wide. Every wait is a hang guard, never a timing.
#![allow(clippy::unwrap_used)]

mod counting_alloc;
#[path = "zenoh/peer_rig.rs"]
mod peer_rig;
mod zenoh_support;

use hytask::rt::prelude::*;
use peer_rig::{pair, WorkCmd};
use std::time::Duration;

const GUARD: Duration = Duration::from_secs(60);

fn run(h: &TaskHandle<WorkCmd>) {
    let s = h.send(WorkCmd::Work(0)).unwrap().wait(GUARD);
    assert_eq!(s, CommandStatus::Done);
}

/// (thread id, context switches so far) of every thread of this process whose name starts
/// with `prefix` (Linux keeps 15 bytes of a name).
fn switches(prefix: &str) -> Vec<(String, u64)> {
    let mut out = Vec::new();
    for t in std::fs::read_dir("/proc/self/task").unwrap() {
        let dir = t.unwrap().path();
        let comm = std::fs::read_to_string(dir.join("comm")).unwrap_or_default();
        if !comm.trim_end().starts_with(prefix) {
            continue;
        }
        let status = std::fs::read_to_string(dir.join("status")).unwrap_or_default();
        let n: u64 = status
            .lines()
            .filter(|l| l.contains("ctxt_switches:"))
            .filter_map(|l| l.split_whitespace().last()?.parse::<u64>().ok())
            .sum();
        out.push((dir.display().to_string(), n));
    }
    out
}

#[test]
fn a_proxy_accepts_without_allocating_and_its_idle_worker_sleeps() {
    let (peer, l) = pair("alloc-far", 60.0, false);
    // First calls: every lazily made thing (routes, subscriber queues) is made now.
    run(&l.worker);
    run(&l.other);

    let before = counting_alloc::in_rt_steps();
    for _ in 0..50 {
        run(&l.worker);
        run(&l.other);
    }
    let n = counting_alloc::in_rt_steps() - before;
    assert_eq!(
        n,
        0,
        "allocations inside realtime steps while proxies accepted calls; first one at:\n{}",
        counting_alloc::first_rt_backtrace().unwrap_or_default()
    );

    // The two proxies' workers (thread `zenoh-remote-far`), idle now. Parked, they are not
    // scheduled at all however long the window; polling every 1 ms they would switch about
    // a thousand times a second.
    let t0 = switches("zenoh-remote-fa");
    assert_eq!(t0.len(), 2, "the proxies' worker threads: {t0:?}");
    std::thread::sleep(Duration::from_secs(2));
    let t1 = switches("zenoh-remote-fa");
    for (id, a) in &t0 {
        let b = t1.iter().find(|t| t.0 == *id).map_or(*a, |t| t.1);
        assert!(
            b - a <= 20,
            "idle worker {id} was scheduled {} times in 2 s",
            b - a
        );
    }
    // Still woken by the next call.
    run(&l.worker);
    l.rt.stop();
    peer.stop();
}
