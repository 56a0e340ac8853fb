//! The command queue's lock-free MPSC ring (exposed as a `DropNewest` buffer, the same ring
//! and single-consumer pop the command queue uses) against crossbeam's `ArrayQueue` (MPMC,
//! the target) and `rtrb` (SPSC, reference). 64-byte payload; push+pop on one thread, and one
//! consumer with two producer threads. Also the full command path (send, processor takes,
//! accepts and completes it, handle released) through a stepped task.
#![allow(missing_docs)] // criterion_group! generates undocumented items

use criterion::{black_box, criterion_group, criterion_main, Criterion};
use crossbeam_queue::ArrayQueue;
use hytask::rt::prelude::*;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

#[derive(Clone, Copy, Default)]
struct Payload(#[allow(dead_code)] [u64; 8]);

fn push_pop(c: &mut Criterion) {
    let mut g = c.benchmark_group("queue_push_pop");
    let p = Payload([3; 8]);
    let (w, mut r) = buffer::<Payload>(64, FullPolicy::DropNewest);
    g.bench_function("hytask_mpsc", |b| {
        b.iter(|| {
            let _ = w.try_push(black_box(p));
            black_box(r.pop());
        })
    });
    let q = ArrayQueue::<Payload>::new(64);
    g.bench_function("crossbeam_array_queue", |b| {
        b.iter(|| {
            let _ = q.push(black_box(p));
            black_box(q.pop());
        })
    });
    let (mut tx, mut rx) = rtrb::RingBuffer::<Payload>::new(64);
    g.bench_function("rtrb_spsc_ref", |b| {
        b.iter(|| {
            let _ = tx.push(black_box(p));
            black_box(rx.pop().ok());
        })
    });
    g.finish();
}

/// Two producer threads keep pushing; the benchmark measures the consumer's pop of one item
/// (spinning until one is there), i.e. throughput per item at one consumer.
fn contended(c: &mut Criterion) {
    let mut g = c.benchmark_group("queue_two_producers_one_consumer");
    let p = Payload([3; 8]);

    let (w, mut r) = buffer::<Payload>(1024, FullPolicy::DropNewest);
    let stop = Arc::new(AtomicBool::new(false));
    let producers: Vec<_> = (0..2)
        .map(|_| {
            let w = w.clone();
            let stop = stop.clone();
            std::thread::spawn(move || {
                while !stop.load(Ordering::Relaxed) {
                    let _ = w.try_push(p);
                }
            })
        })
        .collect();
    g.bench_function("hytask_mpsc_pop", |b| {
        b.iter(|| loop {
            if let Some(v) = r.pop() {
                break black_box(v);
            }
        })
    });
    stop.store(true, Ordering::Relaxed);
    for t in producers {
        let _ = t.join();
    }

    let q = Arc::new(ArrayQueue::<Payload>::new(1024));
    let stop = Arc::new(AtomicBool::new(false));
    let producers: Vec<_> = (0..2)
        .map(|_| {
            let q = q.clone();
            let stop = stop.clone();
            std::thread::spawn(move || {
                while !stop.load(Ordering::Relaxed) {
                    let _ = q.push(p);
                }
            })
        })
        .collect();
    g.bench_function("crossbeam_array_queue_pop", |b| {
        b.iter(|| loop {
            if let Some(v) = q.pop() {
                break black_box(v);
            }
        })
    });
    stop.store(true, Ordering::Relaxed);
    for t in producers {
        let _ = t.join();
    }
    g.finish();
}

enum Cmd {
    Go,
}

impl Commands for Cmd {
    fn operations() -> &'static [OperationDescriptor] {
        &[OperationDescriptor {
            name: "go",
            doc: "Completes at once.",
            params: &[],
            next: NextCommand::AfterAcceptance,
        }]
    }
    fn operation_index(&self) -> usize {
        0
    }
    fn from_args(op: &str, args: &[ArgValue]) -> Result<Self, ArgError> {
        Args::new(Self::operations(), op, args).map(|_| Cmd::Go)
    }
}

struct Idle;

impl Task for Idle {
    type Command = Cmd;
    fn update(&mut self, _: &StepContext) -> Result<(), TaskError> {
        Ok(())
    }
}

fn command_round_trip(c: &mut Criterion) {
    let mut g = c.benchmark_group("command_round_trip");
    let mut app = Deployment::new();
    let s = Schedule {
        priority: 50,
        period_ns: 1_000_000,
        cpu: None,
    };
    let h = app
        .add_periodic("idle", Idle, s)
        .unwrap_or_else(|e| panic!("{e}"));
    app.configure().unwrap_or_else(|e| panic!("{e}"));
    let mut rt = app
        .start_stepped(SimClock::new(0))
        .unwrap_or_else(|e| panic!("{e}"));
    g.bench_function("send_accept_done_2_cycles", |b| {
        b.iter(|| {
            let c = h.send(Cmd::Go).unwrap_or_else(|e| panic!("{e}"));
            rt.run_cycles(2);
            black_box(c.status())
        })
    });
    g.bench_function("empty_cycle_ref", |b| b.iter(|| rt.run_cycles(1)));
    g.finish();
}

criterion_group!(benches, push_pop, contended, command_round_trip);
criterion_main!(benches);
