//! Tasks on real threads and the topology check: topology errors listed and refused,
//! type mismatch and priority inversion, the interface as data, periodic threads with and
//! without SCHED_FIFO, CPU affinity, clean-up and restart of a deployment.
#![allow(clippy::unwrap_used)]

mod rt_support;

use hytask::rt::deploy::{TopologyErrorKind, TopologyErrors};
use hytask::rt::prelude::*;
use rt_support::*;
use std::sync::{Arc, Mutex};
/// Wires ports/peers as told, to provoke topology errors.
struct Wiring {
    inputs: &'static [&'static str],
    outputs: &'static [&'static str],
    peer_ops: &'static [(&'static str, &'static str)],
    subs: &'static [&'static str],
    readers: Vec<DataReader<f64>>,
    writers: Vec<DataWriter<f64>>,
}

impl Wiring {
    fn new(
        inputs: &'static [&'static str],
        outputs: &'static [&'static str],
        peer_ops: &'static [(&'static str, &'static str)],
        subs: &'static [&'static str],
    ) -> Self {
        Self {
            inputs,
            outputs,
            peer_ops,
            subs,
            readers: vec![],
            writers: vec![],
        }
    }
}

impl Task for Wiring {
    type Command = Op;
    fn configure(&mut self, ctx: &mut Configure<'_>) -> Result<(), TaskError> {
        for i in self.inputs {
            self.readers.push(ctx.input(i));
        }
        for o in self.outputs {
            self.writers.push(ctx.output(o));
        }
        for (p, op) in self.peer_ops {
            ctx.require_operation(p, op);
        }
        for s in self.subs {
            let _ = ctx.subscribe::<u64>(s, 4);
        }
        Ok(())
    }
    fn update(&mut self, _: &StepContext) -> Result<(), TaskError> {
        Ok(())
    }
}

#[test]
fn topology_check_lists_every_error_and_refuses_to_start() {
    let mut app = Deployment::new();
    app.add_periodic(
        "a",
        Wiring::new(&["nobody.writes"], &["shared.out"], &[("b", "wait")], &[]),
        sched(50, MS),
    )
    .unwrap();
    app.add_periodic(
        "b",
        Wiring::new(
            &[],
            &["shared.out"],
            &[("ghost", "x"), ("a", "fly")],
            &["a.nothing"],
        ),
        sched(50, MS),
    )
    .unwrap();
    let err = app.configure().unwrap_err();
    let DeployError::Topology(TopologyErrors(errors)) = &err else {
        panic!("{err}");
    };
    let summary: Vec<(String, String, bool)> = errors
        .iter()
        .map(|e| (e.task.clone(), e.port.clone(), true))
        .collect();
    let has = |task: &str, port: &str, k: fn(&TopologyErrorKind) -> bool| {
        errors
            .iter()
            .any(|e| e.task == task && e.port == port && k(&e.kind))
    };
    assert!(
        has("a", "nobody.writes", |k| *k
            == TopologyErrorKind::InputWithoutWriter),
        "{summary:?}"
    );
    assert!(has(
        "b",
        "shared.out",
        |k| matches!(k, TopologyErrorKind::MultipleWriters(w) if w == &["a", "b"])
    ));
    assert!(has("b", "ghost", |k| *k == TopologyErrorKind::UnknownTask));
    assert!(has("b", "a.fly", |k| *k == TopologyErrorKind::UnknownOperation));
    assert!(has("b", "a.nothing", |k| *k
        == TopologyErrorKind::EventWithoutEmitter));
    assert_eq!(errors.len(), 5, "{err}");
    let text = err.to_string();
    assert!(
        text.contains("task 'a' input 'nobody.writes': connected to no writer"),
        "{text}"
    );
    assert!(matches!(
        app.start_stepped(SimClock::new(0)),
        Err(DeployError::NotConfigured)
    ));
}

#[test]
fn type_mismatch_and_priority_inversion_are_reported() {
    struct U32Out(Option<DataWriter<u32>>);
    impl Task for U32Out {
        type Command = NoCommands;
        fn configure(&mut self, ctx: &mut Configure<'_>) -> Result<(), TaskError> {
            self.0 = Some(ctx.output("x"));
            Ok(())
        }
        fn update(&mut self, _: &StepContext) -> Result<(), TaskError> {
            Ok(())
        }
    }
    let mut app = Deployment::new();
    app.add_periodic("w", U32Out(None), sched(50, MS)).unwrap();
    app.add_periodic("r", Wiring::new(&["x"], &[], &[], &[]), sched(50, MS))
        .unwrap();
    let err = app.configure().unwrap_err().to_string();
    assert!(err.contains("task 'r' port 'x': type f64"), "{err}");

    let mut app = Deployment::new();
    app.add_periodic("fast", Worker::default(), sched(40, MS))
        .unwrap();
    app.add_periodic("slow", Worker::default(), sched(60, 10 * MS))
        .unwrap();
    let report = app.configure().unwrap();
    assert_eq!(report.warnings.len(), 1, "{report:?}");
    assert!(report.warnings[0].contains("'rt-p60-10000us'"));
}

#[test]
fn interface_is_data_and_status_reports_realtime_flag() {
    let mut app = Deployment::new();
    app.add_periodic("emitter", Emitter::default(), sched(50, MS))
        .unwrap();
    app.add_periodic(
        "w",
        Wiring::new(&[], &["w.out"], &[("emitter", "x")], &[]),
        sched(50, MS),
    )
    .unwrap();
    let err = app.configure().unwrap_err().to_string();
    assert!(err.contains("operation 'emitter.x' not found"), "{err}");

    let mut app = Deployment::new();
    app.add_periodic("emitter", Emitter::default(), sched(50, MS))
        .unwrap();
    app.add_periodic(
        "w",
        Wiring::new(&[], &["w.out"], &[], &["emitter.tick"]),
        sched(50, MS),
    )
    .unwrap();
    app.configure().unwrap();
    let iface = app.tasks()[1].interface();
    let json = serde_json::to_value(&iface).unwrap();
    assert_eq!(json["operations"][0]["name"], "wait");
    assert_eq!(json["operations"][0]["params"][0]["ty"], "int");
    assert_eq!(json["ports"][0]["object"], "w.out");
    assert_eq!(json["ports"][0]["direction"], "Output");
    assert_eq!(json["ports"][0]["kind"], "Data");
    assert_eq!(json["subscribes"][0]["name"], "emitter.tick");
    assert_eq!(app.tasks()[0].interface().emits[0].name, "emitter.tick");
    let rt = app.start_stepped(SimClock::new(0)).unwrap();
    let status = serde_json::to_value(rt.status()).unwrap();
    assert_eq!(status["realtime"], false);
    assert_eq!(status["tasks"][1]["state"], "Running");
}

#[test]
fn periodic_thread_runs_and_reports_timing() {
    let mut app = Deployment::new();
    let w = app
        .add_periodic("worker", Worker::default(), sched(50, MS))
        .unwrap();
    app.configure().unwrap();
    let rt = app.start().unwrap();
    let c = w.send(Op::Wait(5)).unwrap();
    assert_eq!(c.wait(GUARD), CommandStatus::Done);
    let t = &rt.threads()[0];
    // Ten cycles of the thread and of the task (its run and its start latency) recorded.
    wait_for("10 cycles recorded", || {
        let task = w.info().timing();
        t.stats.summary().wakeup.count >= 10 && task.exec.count >= 10 && task.wakeup.count >= 10
    });
    let s = t.stats.summary();
    assert!(s.wakeup.count >= 10, "{s:?}");
    assert!(s.exec.max_ns >= s.exec.min_ns);
    assert!(w.info().timing().exec.count >= 10);
    assert!(
        w.info().timing().wakeup.count >= 10,
        "task start latency recorded"
    );
    let status = rt.status();
    assert_eq!(status.realtime, t.realtime());
    let _ = rt.stop();
    assert_eq!(w.info().state(), TaskState::Stopped);
}

#[test]
fn without_fifo_the_thread_still_runs_and_reports_not_realtime() {
    // Priority 0 is refused for SCHED_FIFO even as root: the same path as a missing privilege.
    let mut app = Deployment::new();
    let w = app
        .add_periodic("worker", Worker::default(), sched(0, MS))
        .unwrap();
    app.configure().unwrap();
    let rt = app.start().unwrap();
    let c = w.send(Op::Wait(3)).unwrap();
    assert_eq!(c.wait(GUARD), CommandStatus::Done);
    assert!(!rt.realtime());
    assert!(!rt.status().realtime);
    assert!(!rt.threads()[0].realtime());
    let _ = rt.stop();
}

/// Records the CPU it runs on.
struct WhereAmI(Arc<Mutex<Vec<i32>>>);

impl Task for WhereAmI {
    type Command = NoCommands;
    fn update(&mut self, _: &StepContext) -> Result<(), TaskError> {
        // SAFETY: plain libc call without arguments.
        let cpu = unsafe { libc::sched_getcpu() };
        self.0.lock().unwrap().push(cpu);
        Ok(())
    }
}

#[test]
fn cpu_affinity_pins_the_thread() {
    let cpus = Arc::new(Mutex::new(Vec::new()));
    let mut app = Deployment::new();
    app.add_periodic(
        "where",
        WhereAmI(cpus.clone()),
        Schedule {
            priority: 50,
            period_ns: MS,
            cpu: Some(1),
        },
    )
    .unwrap();
    app.configure().unwrap();
    let rt = app.start().unwrap();
    wait_for("6 cycles", || cpus.lock().unwrap().len() > 5);
    let _ = rt.stop();
    let cpus = cpus.lock().unwrap();
    assert!(cpus.len() > 5);
    assert!(cpus.iter().all(|&c| c == 1), "{cpus:?}");
}

/// Writes a counter to data object `x`.
struct Counter {
    out: Option<DataWriter<u64>>,
    n: u64,
}

impl Task for Counter {
    type Command = NoCommands;
    fn configure(&mut self, ctx: &mut Configure<'_>) -> Result<(), TaskError> {
        self.out = Some(ctx.output("x"));
        Ok(())
    }
    fn update(&mut self, _: &StepContext) -> Result<(), TaskError> {
        self.n += 1;
        if let Some(w) = &mut self.out {
            w.set(self.n);
        }
        Ok(())
    }
    fn cleanup(&mut self) {
        self.out = None;
    }
}

/// Copies data object `x` into a shared cell.
struct Sink {
    input: Option<DataReader<u64>>,
    seen: Arc<Mutex<u64>>,
}

impl Task for Sink {
    type Command = NoCommands;
    fn configure(&mut self, ctx: &mut Configure<'_>) -> Result<(), TaskError> {
        self.input = Some(ctx.input("x"));
        Ok(())
    }
    fn update(&mut self, _: &StepContext) -> Result<(), TaskError> {
        if let Some(v) = self.input.as_mut().and_then(DataReader::latest) {
            *self.seen.lock().unwrap() = v;
        }
        Ok(())
    }
    fn cleanup(&mut self) {
        self.input = None;
    }
}

#[test]
fn a_deployment_can_be_cleaned_up_configured_again_and_restarted() {
    let seen = Arc::new(Mutex::new(0));
    let mut app = Deployment::new();
    app.add_periodic("counter", Counter { out: None, n: 0 }, sched(50, MS))
        .unwrap();
    app.add_periodic(
        "sink",
        Sink {
            input: None,
            seen: seen.clone(),
        },
        sched(50, MS),
    )
    .unwrap();
    for round in 0..3 {
        app.configure()
            .unwrap_or_else(|e| panic!("configure, round {round}: {e}"));
        assert_eq!(app.tasks()[0].interface().ports.len(), 1, "declared once");
        let mut rt = app.start_stepped(SimClock::new(0)).unwrap();
        rt.run_cycles(5);
        app = rt.stop();
        app.cleanup();
        let v = *seen.lock().unwrap();
        assert_eq!(
            v,
            5 * (round + 1),
            "round {round}: data flows after reconfiguring"
        );
        let ports = app.tasks()[0].interface().ports.len();
        assert_eq!(ports, 0, "cleanup forgets the declared ports");
    }
}
