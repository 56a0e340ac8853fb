//! Buffer ports through the deployment: declared with `Configure::buffer_out` /
//! `Configure::buffer_in`, checked by the topology check (no producer, two consumers,
//! conflicting declarations, type mismatch are errors; no consumer is a warning), listed in the
//! task interface, and carrying items between tasks on the stepped runtime.
#![allow(clippy::unwrap_used)]

use hytask::rt::deploy::{TopologyErrorKind, TopologyErrors};
use hytask::rt::interface::{PortDirection, PortKind};
use hytask::rt::prelude::*;
use std::sync::{Arc, Mutex};

const MS: u64 = 1_000_000;

fn sched(priority: i32, period_ns: u64) -> Schedule {
    Schedule {
        priority,
        period_ns,
        cpu: None,
    }
}

/// Pushes `per_cycle` numbered items per cycle (`tag << 32 | n`) into buffer `name`.
struct Producer {
    name: &'static str,
    capacity: usize,
    policy: FullPolicy,
    per_cycle: u64,
    tag: u64,
    next: u64,
    out: Option<BufferWriter<u64>>,
}

impl Producer {
    fn new(name: &'static str, capacity: usize, policy: FullPolicy) -> Self {
        Self {
            name,
            capacity,
            policy,
            per_cycle: 1,
            tag: 0,
            next: 0,
            out: None,
        }
    }
}

impl Task for Producer {
    type Command = NoCommands;
    fn configure(&mut self, ctx: &mut Configure<'_>) -> Result<(), TaskError> {
        self.out = Some(ctx.buffer_out(self.name, self.capacity, self.policy));
        Ok(())
    }
    fn update(&mut self, _: &StepContext) -> Result<(), TaskError> {
        if let Some(out) = &self.out {
            for _ in 0..self.per_cycle {
                out.push(self.tag << 32 | self.next);
                self.next += 1;
            }
        }
        Ok(())
    }
}

/// What a consumer received: per cycle that got anything, (cycle, items).
type Received = Arc<Mutex<Vec<(u64, Vec<u64>)>>>;

/// Drains buffer `name` every cycle.
struct Consumer {
    name: &'static str,
    got: Received,
    input: Option<BufferReader<u64>>,
}

impl Consumer {
    fn new(name: &'static str) -> (Self, Received) {
        let got = Received::default();
        (
            Self {
                name,
                got: got.clone(),
                input: None,
            },
            got,
        )
    }
}

impl Task for Consumer {
    type Command = NoCommands;
    fn configure(&mut self, ctx: &mut Configure<'_>) -> Result<(), TaskError> {
        self.input = Some(ctx.buffer_in(self.name));
        Ok(())
    }
    fn update(&mut self, ctx: &StepContext) -> Result<(), TaskError> {
        if let Some(input) = &mut self.input {
            let mut batch = Vec::new();
            input.drain(|x| batch.push(x));
            if !batch.is_empty() {
                self.got.lock().unwrap().push((ctx.cycle, batch));
            }
        }
        Ok(())
    }
}

#[test]
fn producer_feeds_a_slower_consumer_through_a_declared_buffer() {
    let mut app = Deployment::new();
    // The consumer is added (so configured) first: the buffer is created by its input port and
    // sized by the producer's declaration later in the same `configure`.
    let (consumer, got) = Consumer::new("samples");
    app.add_periodic("logger", consumer, sched(50, 4 * MS))
        .unwrap();
    app.add_periodic(
        "sampler",
        Producer::new("samples", 8, FullPolicy::DropNewest),
        sched(60, MS),
    )
    .unwrap();
    let report = app.configure().unwrap();
    assert!(report.warnings.is_empty(), "{report:?}");
    let mut rt = app.start_stepped(SimClock::new(0)).unwrap();
    rt.run_cycles(16);
    let got = got.lock().unwrap().clone();
    // The producer runs at 0..=15 ms; the consumer at 0, 4, 8 and 12 ms, after the producer
    // when both are due (higher priority first): one item, then four per consumer cycle.
    assert_eq!(
        got,
        [
            (0, vec![0]),
            (1, vec![1, 2, 3, 4]),
            (2, vec![5, 6, 7, 8]),
            (3, vec![9, 10, 11, 12]),
        ]
    );
    let deployment = rt.stop();
    let consumer = deployment.tasks()[0].interface();
    assert_eq!(consumer.ports.len(), 1);
    assert_eq!(consumer.ports[0].object, "samples");
    assert_eq!(consumer.ports[0].direction, PortDirection::Input);
    let producer = deployment.tasks()[1].interface();
    assert_eq!(producer.ports[0].direction, PortDirection::Output);
    assert_eq!(producer.ports[0].type_name, "u64");
    assert_eq!(
        (consumer.ports[0].kind, producer.ports[0].kind),
        (PortKind::Buffer, PortKind::Buffer)
    );
}

#[test]
fn several_producers_one_consumer_and_the_declared_policy_applies() {
    let mut app = Deployment::new();
    for (name, tag) in [("a", 1), ("b", 2)] {
        let mut p = Producer::new("merged", 4, FullPolicy::DropOldest);
        p.tag = tag;
        p.per_cycle = 3;
        app.add_periodic(name, p, sched(60, MS)).unwrap();
    }
    let (consumer, got) = Consumer::new("merged");
    app.add_periodic("sink", consumer, sched(60, MS)).unwrap();
    app.configure().unwrap();
    let mut rt = app.start_stepped(SimClock::new(0)).unwrap();
    rt.run_cycles(2);
    // Per cycle a pushes 3, b pushes 3 into 4 slots, dropping the oldest: the consumer (last
    // on the thread) gets the newest four, b's three after a's last.
    let got = got.lock().unwrap().clone();
    let a = |n| 1u64 << 32 | n;
    let b = |n| 2u64 << 32 | n;
    assert_eq!(
        got,
        [
            (0, vec![a(2), b(0), b(1), b(2)]),
            (1, vec![a(5), b(3), b(4), b(5)])
        ]
    );
}

/// Declares buffer ports as told.
struct Ports {
    outs: &'static [(&'static str, usize, FullPolicy)],
    ins: &'static [&'static str],
    u32_in: Option<&'static str>,
    writers: Vec<BufferWriter<u64>>,
    readers: Vec<BufferReader<u64>>,
    u32_reader: Option<BufferReader<u32>>,
}

impl Ports {
    fn new(
        outs: &'static [(&'static str, usize, FullPolicy)],
        ins: &'static [&'static str],
    ) -> Self {
        Self {
            outs,
            ins,
            u32_in: None,
            writers: vec![],
            readers: vec![],
            u32_reader: None,
        }
    }
}

impl Task for Ports {
    type Command = NoCommands;
    fn configure(&mut self, ctx: &mut Configure<'_>) -> Result<(), TaskError> {
        for (name, cap, policy) in self.outs {
            self.writers.push(ctx.buffer_out(name, *cap, *policy));
        }
        for name in self.ins {
            self.readers.push(ctx.buffer_in(name));
        }
        if let Some(name) = self.u32_in {
            self.u32_reader = Some(ctx.buffer_in(name));
        }
        Ok(())
    }
    fn update(&mut self, _: &StepContext) -> Result<(), TaskError> {
        Ok(())
    }
}

#[test]
fn buffer_topology_errors_name_task_and_port_and_refuse_to_start() {
    use FullPolicy::{DropNewest, DropOldest};
    let mut app = Deployment::new();
    app.add_periodic(
        "p1",
        Ports::new(&[("q", 16, DropNewest)], &[]),
        sched(50, MS),
    )
    .unwrap();
    app.add_periodic(
        "p2",
        Ports::new(&[("q", 32, DropNewest), ("r", 4, DropOldest)], &[]),
        sched(50, MS),
    )
    .unwrap();
    app.add_periodic("c1", Ports::new(&[], &["q", "nobody.feeds"]), sched(50, MS))
        .unwrap();
    let mut c2 = Ports::new(&[], &["q"]);
    c2.u32_in = Some("r");
    app.add_periodic("c2", c2, sched(50, MS)).unwrap();
    let err = app.configure().unwrap_err();
    let DeployError::Topology(TopologyErrors(errors)) = &err else {
        panic!("{err}");
    };
    let has = |task: &str, port: &str, k: &dyn Fn(&TopologyErrorKind) -> bool| {
        errors
            .iter()
            .any(|e| e.task == task && e.port == port && k(&e.kind))
    };
    assert!(
        has("p2", "q", &|k| *k
            == TopologyErrorKind::BufferConflict {
                existing: (16, DropNewest),
                declared_by: "p1".into(),
                requested: (32, DropNewest),
            }),
        "{err}"
    );
    assert!(has("c2", "q", &|k| matches!(
        k,
        TopologyErrorKind::MultipleConsumers(c) if c == &["c1", "c2"]
    )));
    assert!(has("c1", "nobody.feeds", &|k| *k
        == TopologyErrorKind::BufferWithoutProducer));
    assert!(has("c2", "r", &|k| matches!(
        k,
        TopologyErrorKind::TypeMismatch {
            existing: "u64",
            requested: "u32"
        }
    )));
    assert_eq!(errors.len(), 4, "{err}");
    let text = err.to_string();
    for line in [
        "task 'p2' buffer output 'q': capacity 32 DropNewest but task 'p1' declared capacity 16 \
         DropNewest",
        "task 'c2' buffer input 'q': buffer has several consumers: c1, c2",
        "task 'c1' buffer input 'nobody.feeds': no task produces into it",
        "task 'c2' port 'r': type u32 but the object has type u64",
    ] {
        assert!(text.contains(line), "{line}\n{text}");
    }
    assert!(matches!(
        app.start_stepped(SimClock::new(0)),
        Err(DeployError::NotConfigured)
    ));
}

#[test]
fn a_buffer_without_consumer_is_a_warning_naming_its_producers() {
    let mut app = Deployment::new();
    app.add_periodic(
        "tracer",
        Producer::new("trace", 64, FullPolicy::DropOldest),
        sched(50, MS),
    )
    .unwrap();
    app.add_periodic(
        "other",
        Producer::new("trace", 64, FullPolicy::DropOldest),
        sched(50, MS),
    )
    .unwrap();
    let report = app.configure().unwrap();
    assert_eq!(report.warnings.len(), 1, "{report:?}");
    let w = &report.warnings[0];
    assert!(
        w.contains("buffer 'trace'")
            && w.contains("'tracer', 'other'")
            && w.contains("no consumer"),
        "{w}"
    );
    // It still runs: pushes into the unconsumed buffer drop without blocking anything.
    let mut rt = app.start_stepped(SimClock::new(0)).unwrap();
    rt.run_cycles(200);
    assert_eq!(rt.task("tracer").unwrap().state(), TaskState::Running);
}
