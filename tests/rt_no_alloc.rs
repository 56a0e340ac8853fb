//! Proves that steady-state realtime operations allocate nothing: a counting global allocator
//! wraps the system one, and each scenario asserts zero allocations (and frees) across many
//! iterations after a warm-up.
#![allow(clippy::unwrap_used)]

use hytask::rt::prelude::*;
use hytask::rt::stats::TimingStats;

mod counting_alloc;

use counting_alloc::during as allocations;

#[derive(Clone, Copy, Default)]
struct Payload([u64; 8]);

#[test]
fn counting_allocator_counts() {
    assert!(allocations(|| drop(std::hint::black_box(vec![1u8; 10]))) >= 2);
}

#[test]
fn data_object_set_get_do_not_allocate() {
    let obj = DataObject::<Payload>::new("p", 4);
    let mut w = obj.writer().unwrap();
    let mut r1 = obj.reader().unwrap();
    let mut r2 = obj.reader().unwrap();
    let mut out = Payload::default();
    let n = allocations(|| {
        for i in 0..10_000u64 {
            w.set(Payload([i; 8]));
            r1.get(&mut out);
            std::hint::black_box(r2.read());
        }
    });
    assert_eq!(n, 0);
}

#[test]
fn buffers_push_pop_overflow_do_not_allocate() {
    let (w, mut r) = buffer::<Payload>(16, FullPolicy::DropOldest);
    let (w2, mut r2) = buffer::<Payload>(16, FullPolicy::DropNewest);
    let n = allocations(|| {
        for i in 0..10_000u64 {
            w.push(Payload([i; 8]));
            w2.push(Payload([i; 8]));
            let _ = w2.try_push(Payload([i; 8]));
            if i % 3 == 0 {
                r.pop();
                r2.pop();
            }
        }
    });
    assert_eq!(n, 0);
    assert!(r.overflows() > 0 && r2.overflows() > 0);
}

#[test]
fn events_emit_and_drain_do_not_allocate() {
    let ev = Event::<Payload>::new("e");
    let mut sum = 0u64;
    let counter = std::sync::Arc::new(std::sync::atomic::AtomicU64::new(0));
    let c2 = counter.clone();
    ev.subscribe_immediate(move |p: &Payload| {
        c2.fetch_add(p.0[0], std::sync::atomic::Ordering::Relaxed);
    });
    let mut rx = ev.subscribe(8);
    let mut src = ev.source().unwrap();
    src.emit(Payload::default()); // picks up the subscribers (configuration)
    let n = allocations(|| {
        for i in 0..10_000u64 {
            src.emit(Payload([i; 8]));
            if i % 16 == 0 {
                rx.drain(|p| sum += p.0[0]);
            }
        }
    });
    assert_eq!(n, 0);
    assert!(rx.lost() > 0, "overflow path exercised");
}

#[test]
fn statistics_recording_does_not_allocate() {
    let s = TimingStats::for_task();
    let n = allocations(|| {
        for i in 0..10_000u64 {
            s.wakeup.record(i * 10);
            s.exec.record(i);
            s.record_overrun(i % 7 == 0);
        }
    });
    assert_eq!(n, 0);
}

enum Cmd {
    Go(u64),
}

impl Commands for Cmd {
    fn operations() -> &'static [OperationDescriptor] {
        &[OperationDescriptor {
            name: "go",
            doc: "Completes after one evaluation.",
            params: &[ParamDescriptor {
                name: "n",
                ty: ArgType::Int,
            }],
            next: NextCommand::AfterCompletion,
        }]
    }
    fn operation_index(&self) -> usize {
        0
    }
    fn from_args(op: &str, args: &[ArgValue]) -> Result<Self, ArgError> {
        let a = Args::new(Self::operations(), op, args)?;
        Ok(Cmd::Go(a.int(0)? as u64))
    }
}

/// Reads an input, writes an output, serves commands, emits and handles events.
#[derive(Default)]
struct Full {
    input: Option<DataReader<Payload>>,
    output: Option<DataWriter<Payload>>,
    ev: Option<EventSource<Payload>>,
    rx: Option<EventReceiver<Payload>>,
    x: Payload,
}

impl Task for Full {
    type Command = Cmd;
    fn configure(&mut self, ctx: &mut Configure<'_>) -> Result<(), TaskError> {
        let me = ctx.task_name().to_owned();
        let other = if me == "a" { "b" } else { "a" };
        self.input = Some(ctx.input(&format!("{other}.out")));
        self.output = Some(ctx.output(&format!("{me}.out")));
        self.ev = Some(ctx.event("ev"));
        self.rx = Some(ctx.subscribe(&format!("{other}.ev"), 8));
        Ok(())
    }
    fn read_inputs(&mut self, _: &StepContext) {
        if let Some(i) = &mut self.input {
            i.get(&mut self.x);
        }
    }
    fn update(&mut self, ctx: &StepContext) -> Result<(), TaskError> {
        self.x.0[0] += 1;
        if let Some(o) = &mut self.output {
            o.set(self.x);
        }
        if ctx.cycle.is_multiple_of(2) {
            if let Some(e) = &mut self.ev {
                e.emit(self.x);
            }
        }
        Ok(())
    }
    fn accept(&mut self, _: &Cmd, _: &StepContext) -> Result<(), RejectReason> {
        Ok(())
    }
    fn progress(&mut self, c: &Cmd, _: &StepContext) -> Progress {
        let Cmd::Go(n) = c;
        if *n > 0 {
            Progress::Done
        } else {
            Progress::Failed("n must be positive")
        }
    }
    fn process_events(&mut self, _: &StepContext) {
        let x = &mut self.x;
        if let Some(rx) = &mut self.rx {
            rx.drain(|p| x.0[1] = p.0[0]);
        }
    }
}

#[test]
fn full_periodic_step_of_a_task_group_does_not_allocate() {
    let mut app = Deployment::new();
    let sched = Schedule {
        priority: 50,
        period_ns: 1_000_000,
        cpu: None,
    };
    let a = app.add_periodic("a", Full::default(), sched).unwrap();
    app.add_periodic("b", Full::default(), sched).unwrap();
    app.configure().unwrap();
    let mut rt = app.start_stepped(SimClock::new(0)).unwrap();
    // Warm-up: subscribers picked up, first command slot used.
    let h = a.send(Cmd::Go(1)).unwrap();
    rt.run_cycles(4);
    assert_eq!(h.status(), CommandStatus::Done);
    drop(h);
    let n = allocations(|| {
        for _ in 0..1_000 {
            // A command sent and completed per cycle, from the same thread (as an RT sender).
            let h = a.send(Cmd::Go(1)).unwrap();
            rt.run_cycles(1);
            std::hint::black_box(h.status());
            drop(h);
            rt.run_cycles(1);
        }
    });
    assert_eq!(n, 0);
    assert!(a.info().timing().exec.count > 2_000);
}

/// Allocates in its step while `on` is set.
struct AllocatesWhenTold {
    on: std::sync::Arc<std::sync::atomic::AtomicBool>,
}

impl Task for AllocatesWhenTold {
    type Command = NoCommands;
    fn update(&mut self, _: &StepContext) -> Result<(), TaskError> {
        if self.on.load(std::sync::atomic::Ordering::Acquire) {
            drop(std::hint::black_box(vec![1u8; 16]));
        }
        Ok(())
    }
}

/// The realtime-step count covers the real periodic thread (not only the test's own thread)
/// and only what runs inside its cycles: it stays at zero while the test thread allocates
/// freely, and sees an allocation made in a step on the periodic thread.
#[test]
fn allocations_inside_steps_are_counted_on_the_periodic_thread_and_only_there() {
    use std::sync::atomic::{AtomicBool, Ordering};
    let on = std::sync::Arc::new(AtomicBool::new(false));
    let mut app = Deployment::new();
    let sched = Schedule {
        priority: 10,
        period_ns: 1_000_000,
        cpu: None,
    };
    app.add_periodic("alloc", AllocatesWhenTold { on: on.clone() }, sched)
        .unwrap();
    app.configure().unwrap();
    let rt = app.start().unwrap();
    let thread = rt.threads()[0].clone();
    let cycles = || thread.stats.summary().wakeup.count;
    let wait_cycles = |n: u64| {
        let until = cycles() + n;
        let t0 = std::time::Instant::now();
        while cycles() < until {
            // Allocating here, outside any step, must not count.
            drop(std::hint::black_box(vec![0u8; 64]));
            std::thread::sleep(std::time::Duration::from_millis(1));
            assert!(t0.elapsed().as_secs() < 60, "the periodic thread stalled");
        }
    };
    wait_cycles(5);
    let before = counting_alloc::in_rt_steps();
    wait_cycles(100);
    let quiet = counting_alloc::in_rt_steps() - before;
    on.store(true, Ordering::Release);
    let before = counting_alloc::in_rt_steps();
    wait_cycles(20);
    let loud = counting_alloc::in_rt_steps() - before;
    on.store(false, Ordering::Release);
    drop(rt.stop());
    assert_eq!(quiet, 0, "counted allocations made outside steps");
    assert!(
        loud >= 20,
        "missed allocations in steps on the periodic thread: {loud}"
    );
    assert!(counting_alloc::first_rt_backtrace()
        .unwrap()
        .contains("AllocatesWhenTold"));
}
