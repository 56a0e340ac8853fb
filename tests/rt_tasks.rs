//! Semantics of tasks on the stepped activity: step order within a thread, deferred handlers
//! in the owner's thread, command accept/reject/completion, serial commands, lifecycle
//! refusals, non-periodic after periodic, overrun storms. (Real threads and the topology
//! check: `rt_threads.rs`.)
#![allow(clippy::unwrap_used)]

mod rt_support;

use hytask::rt::activity::OverrunPolicy;
use hytask::rt::prelude::*;
use rt_support::*;
use std::sync::{Arc, Mutex};
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
