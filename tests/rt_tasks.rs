//! Semantics of tasks on the stepped activity: step order within a thread, deferred handlers
//! in the owner's thread, command accept/reject/completion, serial commands, lifecycle
//! refusals, non-periodic after periodic, overrun storms, topology errors.
#![allow(clippy::unwrap_used)]

use hytask::rt::activity::OverrunPolicy;
use hytask::rt::deploy::{TopologyErrorKind, TopologyErrors};
use hytask::rt::prelude::*;
use std::sync::{Arc, Mutex};
use std::time::Duration;

type Log = Arc<Mutex<Vec<String>>>;

fn log(l: &Log, s: impl Into<String>) {
    l.lock().unwrap().push(s.into());
}

const MS: u64 = 1_000_000;

/// Hang guard of the waits on real threads: a loaded 2-CPU host may starve them for seconds.
const GUARD: Duration = Duration::from_secs(60);

/// Polls until `done` holds: the tests act on what the threads did, never after a sleep.
fn wait_for(what: &str, done: impl Fn() -> bool) {
    let t0 = std::time::Instant::now();
    while !done() {
        assert!(t0.elapsed() < GUARD, "timed out waiting for {what}");
        std::thread::sleep(Duration::from_millis(1));
    }
}

fn sched(priority: i32, period_ns: u64) -> Schedule {
    Schedule {
        priority,
        period_ns,
        cpu: None,
    }
}

/// Logs every hook, to check the order of a step and of tasks.
struct Probe {
    name: &'static str,
    log: Log,
}

impl Task for Probe {
    type Command = Op;
    fn read_inputs(&mut self, _: &StepContext) {
        log(&self.log, format!("{}:read", self.name));
    }
    fn update(&mut self, _: &StepContext) -> Result<(), TaskError> {
        log(&self.log, format!("{}:update", self.name));
        Ok(())
    }
    fn state_machines(&mut self, _: &StepContext) {
        log(&self.log, format!("{}:sm", self.name));
    }
    fn programs(&mut self, _: &StepContext) {
        log(&self.log, format!("{}:prog", self.name));
    }
    fn accept(&mut self, _: &Op, _: &StepContext) -> Result<(), RejectReason> {
        log(&self.log, format!("{}:accept", self.name));
        Ok(())
    }
    fn process_events(&mut self, _: &StepContext) {
        log(&self.log, format!("{}:events", self.name));
    }
}

/// Commands used by the tests.
#[derive(Debug)]
enum Op {
    /// Completes after `cycles` evaluations; rejected if negative.
    Wait(i64),
    /// Completes at once; the next command may start right after acceptance.
    Quick,
    /// Fails on first evaluation.
    Doomed,
}

impl Commands for Op {
    fn operations() -> &'static [OperationDescriptor] {
        &[
            OperationDescriptor {
                name: "wait",
                doc: "Completes after n cycles.",
                params: &[ParamDescriptor {
                    name: "cycles",
                    ty: ArgType::Int,
                }],
                next: NextCommand::AfterCompletion,
            },
            OperationDescriptor {
                name: "quick",
                doc: "Completes at once.",
                params: &[],
                next: NextCommand::AfterAcceptance,
            },
            OperationDescriptor {
                name: "doomed",
                doc: "Always fails.",
                params: &[],
                next: NextCommand::AfterCompletion,
            },
        ]
    }
    fn operation_index(&self) -> usize {
        match self {
            Op::Wait(_) => 0,
            Op::Quick => 1,
            Op::Doomed => 2,
        }
    }
    fn from_args(op: &str, args: &[ArgValue]) -> Result<Self, ArgError> {
        let a = Args::new(Self::operations(), op, args)?;
        Ok(match a.operation() {
            "wait" => Op::Wait(a.int(0)?),
            "quick" => Op::Quick,
            _ => Op::Doomed,
        })
    }
}

/// Serves `Op`: counts completion evaluations; `busy` makes it reject.
#[derive(Default)]
struct Worker {
    busy: bool,
    evaluations: i64,
    log: Option<Log>,
}

impl Task for Worker {
    type Command = Op;
    fn update(&mut self, _: &StepContext) -> Result<(), TaskError> {
        Ok(())
    }
    fn accept(&mut self, c: &Op, ctx: &StepContext) -> Result<(), RejectReason> {
        if self.busy {
            return Err(RejectReason::Busy);
        }
        if let Op::Wait(n) = c {
            if *n < 0 {
                return Err(RejectReason::BadParameters("cycles must be >= 0"));
            }
        }
        if let Some(l) = &self.log {
            log(l, format!("accept {c:?} @{}", ctx.cycle));
        }
        self.evaluations = 0;
        Ok(())
    }
    fn progress(&mut self, c: &Op, ctx: &StepContext) -> Progress {
        if let Some(l) = &self.log {
            log(l, format!("progress {c:?} @{}", ctx.cycle));
        }
        match c {
            Op::Wait(n) => {
                self.evaluations += 1;
                if self.evaluations >= *n {
                    Progress::Done
                } else {
                    Progress::Running
                }
            }
            Op::Quick => Progress::Done,
            Op::Doomed => Progress::Failed("doomed"),
        }
    }
}

#[test]
fn step_order_and_start_order_within_a_thread() {
    let l: Log = Log::default();
    let mut app = Deployment::new();
    for name in ["first", "second", "third"] {
        app.add_periodic(
            name,
            Probe {
                name,
                log: l.clone(),
            },
            sched(50, MS),
        )
        .unwrap();
    }
    app.configure().unwrap();
    let h = app.tasks()[1].clone();
    let mut rt = app.start_stepped(SimClock::new(0)).unwrap();
    assert_eq!(
        rt.threads().len(),
        1,
        "equal (priority, period) share a thread"
    );
    let _c = h.commands().send_args("quick", &[]).unwrap();
    rt.run_cycles(1);
    let got = l.lock().unwrap().clone();
    let expect: Vec<String> = [
        "first:read",
        "first:update",
        "first:sm",
        "first:prog",
        "first:events",
        "second:read",
        "second:update",
        "second:sm",
        "second:prog",
        "second:accept",
        "second:events",
        "third:read",
        "third:update",
        "third:sm",
        "third:prog",
        "third:events",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    assert_eq!(got, expect);
}

#[test]
fn commands_accept_reject_complete_and_fail() {
    let mut app = Deployment::new();
    let w = app
        .add_periodic("worker", Worker::default(), sched(50, MS))
        .unwrap();
    app.configure().unwrap();
    let mut rt = app.start_stepped(SimClock::new(0)).unwrap();

    let bad = w.send(Op::Wait(-1)).unwrap();
    assert_eq!(bad.status(), CommandStatus::Pending);
    rt.run_cycles(1);
    assert_eq!(
        bad.status(),
        CommandStatus::Rejected(RejectReason::BadParameters("cycles must be >= 0"))
    );

    let wait = w.send(Op::Wait(3)).unwrap();
    rt.run_cycles(1);
    assert_eq!(wait.status(), CommandStatus::Accepted);
    rt.run_cycles(2);
    assert_eq!(wait.status(), CommandStatus::Accepted, "2 of 3 evaluations");
    rt.run_cycles(1);
    assert_eq!(wait.status(), CommandStatus::Done);

    let doomed = w.send(Op::Doomed).unwrap();
    rt.run_cycles(2);
    assert_eq!(doomed.status(), CommandStatus::Failed("doomed"));

    // Dynamic arguments: type and count errors are reported to the sender, not queued.
    let info = rt.task("worker").unwrap().clone();
    assert!(matches!(
        info.commands()
            .send_args("wait", &[ArgValue::Str("x".into())]),
        Err(SendError::Args(ArgError::Type { .. }))
    ));
    assert!(matches!(
        info.commands().send_args("nope", &[]),
        Err(SendError::Args(ArgError::UnknownOperation(_)))
    ));
    let ok = info
        .commands()
        .send_args("wait", &[ArgValue::Int(0)])
        .unwrap();
    rt.run_cycles(2);
    assert_eq!(ok.status(), CommandStatus::Done);
}

#[test]
fn busy_task_rejects_with_reason() {
    let mut app = Deployment::new();
    let w = app
        .add_periodic(
            "worker",
            Worker {
                busy: true,
                ..Worker::default()
            },
            sched(50, MS),
        )
        .unwrap();
    app.configure().unwrap();
    let mut rt = app.start_stepped(SimClock::new(0)).unwrap();
    let c = w.send(Op::Quick).unwrap();
    rt.run_cycles(1);
    assert_eq!(c.status(), CommandStatus::Rejected(RejectReason::Busy));
}

#[test]
fn next_command_waits_for_completion_only_when_the_operation_says_so() {
    let l: Log = Log::default();
    let mut app = Deployment::new();
    let w = app
        .add_periodic(
            "worker",
            Worker {
                log: Some(l.clone()),
                ..Worker::default()
            },
            sched(50, MS),
        )
        .unwrap();
    app.configure().unwrap();
    let mut rt = app.start_stepped(SimClock::new(0)).unwrap();
    let a = w.send(Op::Wait(2)).unwrap();
    let b = w.send(Op::Quick).unwrap();
    let c = w.send(Op::Quick).unwrap();
    rt.run_cycles(6);
    assert_eq!(
        (a.status(), b.status(), c.status()),
        (
            CommandStatus::Done,
            CommandStatus::Done,
            CommandStatus::Done
        )
    );
    let got = l.lock().unwrap().clone();
    assert_eq!(
        got,
        vec![
            "accept Wait(2) @0",
            "progress Wait(2) @1",
            "progress Wait(2) @2",
            // Wait blocks until done; Quick does not block the next one.
            "accept Quick @2",
            "progress Quick @3",
            "accept Quick @3",
            "progress Quick @4",
        ]
    );
}

#[test]
fn commands_are_rejected_unless_running_and_lifecycle_transitions() {
    let mut app = Deployment::new();
    let w = app
        .add_periodic("worker", Worker::default(), sched(50, MS))
        .unwrap();
    assert_eq!(w.info().state(), TaskState::Unconfigured);
    let c = w.send(Op::Quick).unwrap();
    assert_eq!(
        c.status(),
        CommandStatus::Rejected(RejectReason::WrongState(TaskState::Unconfigured))
    );
    app.configure().unwrap();
    assert_eq!(w.info().state(), TaskState::Stopped);
    let c = w.send(Op::Quick).unwrap();
    assert_eq!(
        c.status(),
        CommandStatus::Rejected(RejectReason::WrongState(TaskState::Stopped))
    );
    let mut rt = app.start_stepped(SimClock::new(0)).unwrap();
    assert_eq!(w.info().state(), TaskState::Running);

    // A running command fails when the task is stopped; queued ones are rejected.
    let running = w.send(Op::Wait(100)).unwrap();
    rt.run_cycles(1);
    let queued = w.send(Op::Quick).unwrap();
    w.info().request_stop();
    rt.run_cycles(1);
    assert_eq!(w.info().state(), TaskState::Stopped);
    assert_eq!(running.status(), CommandStatus::Failed("task stopped"));
    assert_eq!(
        queued.status(),
        CommandStatus::Rejected(RejectReason::WrongState(TaskState::Stopped))
    );
    w.info().request_start();
    rt.run_cycles(1);
    assert_eq!(w.info().state(), TaskState::Running);
    let mut app = rt.stop();
    assert_eq!(w.info().state(), TaskState::Stopped);
    app.cleanup();
    assert_eq!(w.info().state(), TaskState::Unconfigured);
    assert!(matches!(
        app.start_stepped(SimClock::new(0)),
        Err(DeployError::NotConfigured)
    ));
}

/// Fails in `update` when told to; counts `error` hook calls.
#[derive(Default)]
struct Fragile {
    fail: Option<TaskError>,
    errors: Arc<Mutex<u32>>,
}

impl Task for Fragile {
    type Command = Op;
    fn update(&mut self, _: &StepContext) -> Result<(), TaskError> {
        match self.fail.take() {
            Some(e) => Err(e),
            None => Ok(()),
        }
    }
    fn error(&mut self, _: &StepContext) {
        *self.errors.lock().unwrap() += 1;
    }
}

#[test]
fn exception_runs_error_hook_rejects_commands_and_recovers() {
    let errors = Arc::new(Mutex::new(0));
    let mut app = Deployment::new();
    let t = app
        .add_periodic(
            "fragile",
            Fragile {
                fail: Some(TaskError::Recoverable("sensor glitch")),
                errors: errors.clone(),
            },
            sched(50, MS),
        )
        .unwrap();
    app.configure().unwrap();
    let mut rt = app.start_stepped(SimClock::new(0)).unwrap();
    rt.run_cycles(1);
    assert_eq!(t.info().state(), TaskState::Exception);
    let c = t.send(Op::Quick).unwrap();
    assert_eq!(
        c.status(),
        CommandStatus::Rejected(RejectReason::WrongState(TaskState::Exception))
    );
    rt.run_cycles(2);
    assert_eq!(*errors.lock().unwrap(), 2, "error hook replaces update");
    t.info().request_recover();
    rt.run_cycles(1);
    assert_eq!(t.info().state(), TaskState::Running);

    let mut app = Deployment::new();
    let f = app
        .add_periodic(
            "fatal",
            Fragile {
                fail: Some(TaskError::Fatal("broken")),
                ..Fragile::default()
            },
            sched(50, MS),
        )
        .unwrap();
    app.configure().unwrap();
    let mut rt = app.start_stepped(SimClock::new(0)).unwrap();
    rt.run_cycles(1);
    f.info().request_recover();
    rt.run_cycles(1);
    assert_eq!(f.info().state(), TaskState::Fatal);
}

/// Emits its cycle number as an event every cycle.
#[derive(Default)]
struct Emitter {
    ev: Option<EventSource<u64>>,
}

impl Task for Emitter {
    type Command = NoCommands;
    fn configure(&mut self, ctx: &mut Configure<'_>) -> Result<(), TaskError> {
        self.ev = Some(ctx.event("tick"));
        Ok(())
    }
    fn update(&mut self, ctx: &StepContext) -> Result<(), TaskError> {
        if let Some(e) = &mut self.ev {
            e.emit(ctx.cycle);
        }
        Ok(())
    }
}

/// Records in which thread and step phase it handles events.
struct Listener {
    rx: Option<EventReceiver<u64>>,
    seen: Arc<Mutex<Vec<(u64, std::thread::ThreadId)>>>,
    log: Log,
}

impl Task for Listener {
    type Command = Op;
    fn configure(&mut self, ctx: &mut Configure<'_>) -> Result<(), TaskError> {
        self.rx = Some(ctx.subscribe("emitter.tick", 16));
        Ok(())
    }
    fn update(&mut self, ctx: &StepContext) -> Result<(), TaskError> {
        log(&self.log, format!("listener:update@{}", ctx.cycle));
        Ok(())
    }
    fn process_events(&mut self, _: &StepContext) {
        let seen = &self.seen;
        let l = &self.log;
        if let Some(rx) = &mut self.rx {
            rx.drain(|v| {
                seen.lock().unwrap().push((v, std::thread::current().id()));
                log(l, format!("listener:event {v}"));
            });
        }
    }
    fn has_work(&self) -> bool {
        self.rx.as_ref().is_some_and(EventReceiver::has_events)
    }
}

#[test]
fn deferred_handlers_run_in_the_owners_thread_at_its_safe_point() {
    let seen = Arc::new(Mutex::new(Vec::new()));
    let l: Log = Log::default();
    let mut app = Deployment::new();
    // The listener runs on a different (slower, lower-priority) real thread.
    app.add_periodic("emitter", Emitter::default(), sched(60, MS))
        .unwrap();
    app.add_periodic(
        "listener",
        Listener {
            rx: None,
            seen: seen.clone(),
            log: l.clone(),
        },
        sched(50, 2 * MS),
    )
    .unwrap();
    app.configure().unwrap();
    let rt = app.start().unwrap();
    wait_for("6 events delivered", || seen.lock().unwrap().len() > 5);
    let listener_thread = rt.task("listener").unwrap().thread().to_owned();
    let _app = rt.stop();
    let seen = seen.lock().unwrap().clone();
    assert!(seen.len() > 5, "events delivered: {}", seen.len());
    let tid = seen[0].1;
    assert!(seen.iter().all(|(_, t)| *t == tid), "one handler thread");
    assert_ne!(tid, std::thread::current().id());
    assert!(listener_thread.contains("p50"));
    let values: Vec<u64> = seen.iter().map(|(v, _)| *v).collect();
    assert!(
        values.windows(2).all(|w| w[1] == w[0] + 1),
        "in order, none lost"
    );
}

#[test]
fn non_periodic_task_runs_after_periodic_work_when_woken() {
    let l: Log = Log::default();
    let seen = Arc::new(Mutex::new(Vec::new()));
    let mut app = Deployment::new();
    app.add_periodic("emitter", Emitter::default(), sched(50, MS))
        .unwrap();
    // Non-periodic, added BEFORE the last periodic task: still runs after it.
    app.add_non_periodic(
        "listener",
        Listener {
            rx: None,
            seen,
            log: l.clone(),
        },
        50,
    )
    .unwrap();
    app.add_periodic(
        "late",
        Probe {
            name: "late",
            log: l.clone(),
        },
        sched(50, MS),
    )
    .unwrap();
    assert!(matches!(
        app.add_non_periodic("orphan", Worker::default(), 10),
        Err(DeployError::NoThreadForPriority { priority: 10, .. })
    ));
    app.configure().unwrap();
    let mut rt = app.start_stepped(SimClock::new(0)).unwrap();
    rt.run_cycles(1);
    let got = l.lock().unwrap().clone();
    let late_events = got.iter().position(|s| s == "late:events").unwrap();
    let listener = got.iter().position(|s| s == "listener:update@0").unwrap();
    assert!(late_events < listener, "{got:?}");
    assert!(got.contains(&"listener:event 0".to_string()));
    // Not woken (no event, no command): does not run.
    l.lock().unwrap().clear();
    let info = rt.task("listener").unwrap().clone();
    drop(rt);
    assert!(!info.is_periodic());
}

#[test]
fn non_periodic_task_is_woken_by_a_command() {
    let l: Log = Log::default();
    let mut app = Deployment::new();
    app.add_periodic(
        "p",
        Probe {
            name: "p",
            log: l.clone(),
        },
        sched(50, MS),
    )
    .unwrap();
    let np = app
        .add_non_periodic(
            "np",
            Probe {
                name: "np",
                log: l.clone(),
            },
            50,
        )
        .unwrap();
    app.configure().unwrap();
    let mut rt = app.start_stepped(SimClock::new(0)).unwrap();
    rt.run_cycles(3);
    assert!(!l.lock().unwrap().iter().any(|s| s.starts_with("np")));
    let c = np.send(Op::Quick).unwrap();
    rt.run_cycles(1);
    assert_eq!(c.status(), CommandStatus::Accepted);
    let got = l.lock().unwrap().clone();
    assert_eq!(got.last().unwrap(), "np:events");
    assert!(got.contains(&"np:accept".to_string()));
}

/// Burns simulated time to force overruns.
struct Hog {
    clock: SimClock,
    burn_ns: u64,
}

impl Task for Hog {
    type Command = NoCommands;
    fn update(&mut self, _: &StepContext) -> Result<(), TaskError> {
        self.clock.advance_ns(self.burn_ns);
        Ok(())
    }
}

#[test]
fn overrun_storm_raises_the_thread_event_once() {
    let clock = SimClock::new(0);
    let mut app = Deployment::new();
    app.set_overrun_policy(OverrunPolicy { storm_threshold: 3 });
    app.add_periodic(
        "hog",
        Hog {
            clock: clock.clone(),
            burn_ns: 2 * MS,
        },
        sched(70, MS),
    )
    .unwrap();
    app.configure().unwrap();
    let mut storms = app
        .event::<Overrun>("rt-p70-1000us.overrun")
        .unwrap()
        .subscribe(8);
    let mut rt = app.start_stepped(clock).unwrap();
    for _ in 0..5 {
        rt.run_until_ns(rt.clock().now_ns() + MS);
    }
    let t = rt.threads()[0].clone();
    assert!(t.stats.overruns() >= 3, "{}", t.stats.overruns());
    let ev = storms.pop().expect("storm event");
    assert_eq!(ev.consecutive, 3);
    assert_eq!(storms.pop(), None, "once per storm");
}

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
