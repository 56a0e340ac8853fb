//! Concurrency stress: one writer and several readers hammer a data object; every value is a
//! 64-byte block whose words must all be equal, so a torn read is detected. Also buffers and
//! command queues under several producers.
#![allow(clippy::unwrap_used)]

use hytask::rt::prelude::*;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

#[derive(Clone, Copy, Default, PartialEq, Debug)]
struct Block([u64; 8]);

#[test]
fn one_writer_many_readers_never_torn_never_backwards() {
    let obj = DataObject::<Block>::new("block", 8);
    let mut w = obj.writer().unwrap();
    let stop = Arc::new(AtomicBool::new(false));
    // Readers that have done enough (1000 reads, 10 new values) to make the run meaningful:
    // the writer goes on until all have, however the loaded host schedules them.
    let enough = Arc::new(AtomicUsize::new(0));
    let readers: Vec<_> = (0..3)
        .map(|_| {
            let mut r = obj.reader().unwrap();
            let (stop, enough) = (stop.clone(), enough.clone());
            std::thread::spawn(move || {
                let (mut last, mut reads, mut new) = (0u64, 0u64, 0u64);
                let mut counted = false;
                while !stop.load(Ordering::Relaxed) {
                    if !counted && reads > 1000 && new > 10 {
                        counted = true;
                        enough.fetch_add(1, Ordering::Relaxed);
                    }
                    let (st, v) = r.read();
                    reads += 1;
                    let first = v.0[0];
                    assert!(v.0.iter().all(|&x| x == first), "torn read: {v:?}");
                    match st {
                        FlowStatus::NoData => assert_eq!(first, 0),
                        FlowStatus::NewData => {
                            assert!(first > last, "new data must be newer");
                            new += 1;
                            last = first;
                        }
                        FlowStatus::OldData => assert_eq!(first, last),
                    }
                }
                (reads, new)
            })
        })
        .collect();
    let start = Instant::now();
    let mut i = 0u64;
    // At least 400 ms of writing, and on until every reader did enough (hang guard 60 s).
    while start.elapsed() < Duration::from_millis(400)
        || i <= 10_000
        || enough.load(Ordering::Relaxed) < 3
    {
        assert!(
            start.elapsed() < Duration::from_secs(60),
            "readers starved: {} of 3 did 1000 reads",
            enough.load(Ordering::Relaxed)
        );
        i += 1;
        w.set(Block([i; 8]));
        // A late reader registering mid-stream sees a recent, whole value.
        if i.is_multiple_of(50_000) {
            let mut r = obj.reader().unwrap();
            let (st, v) = r.read();
            assert_eq!(st, FlowStatus::NewData);
            assert!(v.0.iter().all(|&x| x == v.0[0]) && v.0[0] <= i && v.0[0] > 0);
        }
    }
    stop.store(true, Ordering::Relaxed);
    for r in readers {
        let (reads, new) = r.join().unwrap();
        assert!(reads > 1000 && new > 10, "reads {reads} new {new}");
    }
    assert!(i > 10_000);
}

#[test]
fn buffer_with_three_producers_loses_nothing_with_try_push() {
    let (w, mut r) = buffer::<u64>(64, FullPolicy::DropNewest);
    let producers: Vec<_> = (0..3u64)
        .map(|p| {
            let w = w.clone();
            std::thread::spawn(move || {
                for i in 0..20_000u64 {
                    let mut v = p << 32 | i;
                    while let Err(back) = w.try_push(v) {
                        v = back;
                        std::thread::yield_now();
                    }
                }
            })
        })
        .collect();
    let mut next = [0u64; 3];
    let mut n = 0;
    while n < 60_000 {
        match r.pop() {
            Some(v) => {
                let (p, i) = ((v >> 32) as usize, v & 0xffff_ffff);
                assert_eq!(i, next[p]);
                next[p] += 1;
                n += 1;
            }
            None => std::thread::yield_now(),
        }
    }
    for p in producers {
        p.join().unwrap();
    }
    assert_eq!(r.overflows(), 0);
}
