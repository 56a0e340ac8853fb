//! DataObject get/set against triple_buffer (the single-reader target), arc-swap, and a plain
//! seqlock (reference line only: it is not wait-free for readers). 64-byte payload.
//! Uncontended and with another thread hammering the other side; `set` with 1, 3 and 8
//! registered readers; `get` with and without new data.
#![allow(missing_docs)] // criterion_group! generates undocumented items

use arc_swap::ArcSwap;
use criterion::{black_box, criterion_group, criterion_main, Criterion};
use hytask::rt::data_object::DataObject;
use std::cell::UnsafeCell;
use std::sync::atomic::{fence, AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

#[derive(Clone, Copy, Default)]
struct Payload(#[allow(dead_code)] [u64; 8]);

/// Textbook seqlock, reference only.
struct SeqLock {
    seq: AtomicU64,
    data: UnsafeCell<Payload>,
}
// SAFETY: benchmark reference; torn reads are detected by the sequence check.
unsafe impl Sync for SeqLock {}
impl SeqLock {
    fn write(&self, v: Payload) {
        let s = self.seq.load(Ordering::Relaxed);
        self.seq.store(s + 1, Ordering::Relaxed);
        fence(Ordering::Release);
        // SAFETY: single writer.
        unsafe { std::ptr::write_volatile(self.data.get(), v) };
        self.seq.store(s + 2, Ordering::Release);
    }
    fn read(&self) -> Payload {
        loop {
            let s1 = self.seq.load(Ordering::Acquire);
            // SAFETY: value discarded if a write overlapped.
            let v = unsafe { std::ptr::read_volatile(self.data.get()) };
            fence(Ordering::Acquire);
            if s1 & 1 == 0 && self.seq.load(Ordering::Relaxed) == s1 {
                return v;
            }
        }
    }
}

fn uncontended(c: &mut Criterion) {
    let mut g = c.benchmark_group("data_object_uncontended");
    let p = Payload([7; 8]);

    let obj = DataObject::<Payload>::new("p", 4);
    let mut w = obj.writer().unwrap_or_else(|e| panic!("{e}"));
    let mut r = obj.reader().unwrap_or_else(|e| panic!("{e}"));
    g.bench_function("hytask_set_1reader", |b| b.iter(|| w.set(black_box(p))));
    let mut out = Payload::default();
    g.bench_function("hytask_get", |b| b.iter(|| black_box(r.get(&mut out))));
    g.bench_function("hytask_set_get", |b| {
        b.iter(|| {
            w.set(black_box(p));
            black_box(r.get(&mut out));
        })
    });
    let fixed = DataObject::<Payload>::with_fixed_readers("f", 4);
    let mut fr = fixed.reader().unwrap_or_else(|e| panic!("{e}"));
    let mut fw = fixed.writer().unwrap_or_else(|e| panic!("{e}"));
    g.bench_function("hytask_fixed_set_1reader", |b| {
        b.iter(|| fw.set(black_box(p)))
    });
    g.bench_function("hytask_fixed_set_get", |b| {
        b.iter(|| {
            fw.set(black_box(p));
            black_box(fr.get(&mut out));
        })
    });
    let mut r2 = obj.reader().unwrap_or_else(|e| panic!("{e}"));
    let mut r3 = obj.reader().unwrap_or_else(|e| panic!("{e}"));
    g.bench_function("hytask_set_3readers", |b| b.iter(|| w.set(black_box(p))));
    black_box((r2.read().0, r3.read().0));
    let eight = DataObject::<Payload>::new("e", 8);
    let mut ew = eight.writer().unwrap_or_else(|e| panic!("{e}"));
    let mut er: Vec<_> = (0..8)
        .map(|_| eight.reader().unwrap_or_else(|e| panic!("{e}")))
        .collect();
    // Every reader pins a slot, so the writer has to pick around all eight.
    ew.set(p);
    for r in &mut er {
        black_box(r.read().0);
    }
    g.bench_function("hytask_set_8readers", |b| b.iter(|| ew.set(black_box(p))));

    // `get` that finds new data: GETS_PER_ROUND objects (one reader each) are written outside
    // the timed region, then each is read once, timed. Same for triple_buffer.
    let mut objects: Vec<_> = (0..GETS_PER_ROUND)
        .map(|_| {
            let o = DataObject::<Payload>::new("n", 4);
            let r = o.reader().unwrap_or_else(|e| panic!("{e}"));
            let w = o.writer().unwrap_or_else(|e| panic!("{e}"));
            (w, r)
        })
        .collect();
    g.bench_function("hytask_get_new_data", |b| {
        b.iter_custom(|iters| {
            timed_rounds(iters, |n| {
                for (w, _) in &mut objects[..n] {
                    w.set(black_box(p));
                }
                let start = Instant::now();
                for (_, r) in &mut objects[..n] {
                    black_box(r.get(&mut out));
                }
                start.elapsed()
            })
        })
    });
    let mut triples: Vec<_> = (0..GETS_PER_ROUND)
        .map(|_| triple_buffer::triple_buffer(&Payload::default()))
        .collect();
    g.bench_function("triple_buffer_get_new_data", |b| {
        b.iter_custom(|iters| {
            timed_rounds(iters, |n| {
                for (i, _) in &mut triples[..n] {
                    i.write(black_box(p));
                }
                let start = Instant::now();
                for (_, o) in &mut triples[..n] {
                    black_box(*o.read());
                }
                start.elapsed()
            })
        })
    });

    let (mut ti, mut to) = triple_buffer::triple_buffer(&Payload::default());
    g.bench_function("triple_buffer_set", |b| b.iter(|| ti.write(black_box(p))));
    g.bench_function("triple_buffer_get", |b| b.iter(|| black_box(*to.read())));
    g.bench_function("triple_buffer_set_get", |b| {
        b.iter(|| {
            ti.write(black_box(p));
            black_box(*to.read());
        })
    });

    let a = ArcSwap::from_pointee(Payload::default());
    g.bench_function("arc_swap_set", |b| {
        b.iter(|| a.store(Arc::new(black_box(p))))
    });
    g.bench_function("arc_swap_get", |b| b.iter(|| black_box(**a.load())));

    let s = SeqLock {
        seq: AtomicU64::new(0),
        data: UnsafeCell::new(Payload::default()),
    };
    g.bench_function("seqlock_set_ref", |b| b.iter(|| s.write(black_box(p))));
    g.bench_function("seqlock_get_ref", |b| b.iter(|| black_box(s.read())));
    g.finish();
}

/// Objects written per timed round of the get-with-new-data rows: enough that the clock
/// reads (~20-30 ns) are spread over many gets.
const GETS_PER_ROUND: usize = 64;

/// Runs `iters` timed operations in rounds of up to [`GETS_PER_ROUND`]; `round(n)` prepares
/// and times `n` of them.
fn timed_rounds(iters: u64, mut round: impl FnMut(usize) -> Duration) -> Duration {
    let mut left = iters;
    let mut total = Duration::ZERO;
    while left > 0 {
        let n = left.min(GETS_PER_ROUND as u64);
        total += round(n as usize);
        left -= n;
    }
    total
}

/// Runs `hammer` on another thread while `measure` is benchmarked.
fn with_hammer<H: FnMut() + Send + 'static, R>(mut hammer: H, f: impl FnOnce() -> R) {
    let stop = Arc::new(AtomicBool::new(false));
    let s2 = stop.clone();
    let t = std::thread::spawn(move || {
        while !s2.load(Ordering::Relaxed) {
            hammer();
        }
    });
    let _ = f();
    stop.store(true, Ordering::Relaxed);
    let _ = t.join();
}

fn contended(c: &mut Criterion) {
    let mut g = c.benchmark_group("data_object_contended");
    let p = Payload([7; 8]);

    let obj = DataObject::<Payload>::new("p", 4);
    let mut w = obj.writer().unwrap_or_else(|e| panic!("{e}"));
    let mut r = obj.reader().unwrap_or_else(|e| panic!("{e}"));
    with_hammer(
        move || {
            let mut o = Payload::default();
            black_box(r.get(&mut o));
        },
        || {
            g.bench_function("hytask_set_while_reading", |b| {
                b.iter(|| w.set(black_box(p)))
            })
        },
    );
    let mut r = obj.reader().unwrap_or_else(|e| panic!("{e}"));
    drop(w);
    let mut w = obj.writer().unwrap_or_else(|e| panic!("{e}"));
    let mut out = Payload::default();
    with_hammer(
        move || w.set(black_box(p)),
        || {
            g.bench_function("hytask_get_while_writing", |b| {
                b.iter(|| black_box(r.get(&mut out)))
            })
        },
    );

    let (mut ti, mut to) = triple_buffer::triple_buffer(&Payload::default());
    let (mut ti2, mut to2) = triple_buffer::triple_buffer(&Payload::default());
    with_hammer(
        move || {
            black_box(*to.read());
        },
        || {
            g.bench_function("triple_buffer_set_while_reading", |b| {
                b.iter(|| ti.write(black_box(p)))
            })
        },
    );
    with_hammer(
        move || ti2.write(black_box(p)),
        || {
            g.bench_function("triple_buffer_get_while_writing", |b| {
                b.iter(|| black_box(*to2.read()))
            })
        },
    );

    let a = Arc::new(ArcSwap::from_pointee(Payload::default()));
    let a2 = a.clone();
    with_hammer(
        move || {
            black_box(**a2.load());
        },
        || {
            g.bench_function("arc_swap_set_while_reading", |b| {
                b.iter(|| a.store(Arc::new(black_box(p))))
            })
        },
    );

    let s = Arc::new(SeqLock {
        seq: AtomicU64::new(0),
        data: UnsafeCell::new(Payload::default()),
    });
    let s2 = s.clone();
    with_hammer(
        move || s2.write(black_box(p)),
        || {
            g.bench_function("seqlock_get_while_writing_ref", |b| {
                b.iter(|| black_box(s.read()))
            })
        },
    );
    g.finish();
}

criterion_group!(benches, uncontended, contended);
criterion_main!(benches);
