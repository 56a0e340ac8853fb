//! Event emit with one immediate and one deferred handler (the deferred queue drained each
//! iteration, as the owning task would at its safe point). 64-byte payload.
#![allow(missing_docs)] // criterion_group! generates undocumented items

use criterion::{black_box, criterion_group, criterion_main, Criterion};
use hytask::rt::event::Event;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

#[derive(Clone, Copy, Default)]
struct Payload([u64; 8]);

fn emit(c: &mut Criterion) {
    let mut g = c.benchmark_group("event");
    let ev = Event::<Payload>::new("bench.ev");
    let sum = Arc::new(AtomicU64::new(0));
    let s2 = sum.clone();
    ev.subscribe_immediate(move |p: &Payload| {
        s2.fetch_add(p.0[0], Ordering::Relaxed);
    });
    let mut rx = ev.subscribe(64);
    let mut src = ev.source().unwrap_or_else(|e| panic!("{e}"));
    let p = Payload([1; 8]);
    g.bench_function("emit_1_immediate_1_deferred_and_handle", |b| {
        b.iter(|| {
            src.emit(black_box(p));
            black_box(rx.pop());
        })
    });
    g.finish();
}

criterion_group!(benches, emit);
criterion_main!(benches);
