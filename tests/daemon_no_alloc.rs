//! Proves that the daemon's realtime path allocates nothing over the whole life of a machine
//! and its jobs, on the real thread: the machine is deployed as `hytask serve` deploys it
//! (`Machine::deploy` with the simulated mill, its periodic servo thread on the real-time
//! loop, `SCHED_FIFO` when permitted), the daemon's control socket served in-process with an
//! event subscriber attached, and a counting global allocator counts every allocation made
//! inside a servo cycle on any thread (the activities mark the thread while a cycle runs).
//!
//! One window per operation or trip; each must show zero allocations inside realtime steps.
//! The soft-limit trip cannot be reached through the daemon (the planner refuses such jobs);
//! it is proven on the stepped runtime in `tests/machine_no_alloc.rs`, as probing is.
//!
//! One test function on purpose: the count is process-wide, so nothing else may run beside it.
#![allow(clippy::unwrap_used)]

mod counting_alloc;
mod support;

use hytask::control::client::Client;
use serde_json::{json, Value};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};
use support::*;

/// Hang guard of every wait: a loaded host may run the machine slower than real time.
const GUARD: Duration = Duration::from_secs(120);

/// The daemon of `hytask serve`, in this process: machine deployed, socket served on its own
/// thread, stopped (machine shut down under control) when dropped.
struct InProcess {
    socket: std::path::PathBuf,
    stop: Option<tokio::sync::oneshot::Sender<()>>,
    thread: Option<std::thread::JoinHandle<()>>,
    _dir: tempfile::TempDir,
}

impl InProcess {
    fn start(config: &std::path::Path) -> InProcess {
        let dir = tempfile::tempdir().unwrap();
        let socket = dir.path().join("control.sock");
        let cfg = hytask::machine::load_config(Some(config)).unwrap();
        let opts =
            hytask::control::server::SocketOptions::from_config(&cfg.control, Some(socket.clone()));
        let machine = hytask::machine::deploy_from(Some(config)).unwrap();
        let listener = hytask::control::server::bind(&opts).unwrap();
        let (tx, rx) = tokio::sync::oneshot::channel::<()>();
        let thread = std::thread::spawn(move || {
            hytask::daemon::run(machine, listener, async {
                let _ = rx.await;
            })
            .unwrap();
        });
        InProcess {
            socket,
            stop: Some(tx),
            thread: Some(thread),
            _dir: dir,
        }
    }

    fn client(&self) -> Client {
        Client::connect(&self.socket).unwrap()
    }

    /// A subscriber to every topic, drained on its own thread as a monitoring client would.
    fn subscriber(&self) -> Subscriber {
        let mut c = self.client();
        ok(&mut c, "subscribe", Value::Null);
        let stop = Arc::new(AtomicBool::new(false));
        let s = stop.clone();
        let thread = std::thread::spawn(move || {
            let mut topics = std::collections::BTreeSet::new();
            // Once told to stop, it still reads what is queued (until 50 ms pass without an
            // event, hang guard 60 s): a starved thread must not miss the backlog.
            let mut stopped: Option<Instant> = None;
            loop {
                match c.next_event(Duration::from_millis(50)) {
                    Ok(Some(e)) => {
                        topics.insert(e.topic);
                    }
                    Ok(None) if stopped.is_some() => break,
                    Ok(None) => {}
                    // The connection is gone: nothing more to read.
                    Err(_) => break,
                }
                if stopped.is_none() && s.load(Ordering::Acquire) {
                    stopped = Some(Instant::now());
                }
                if stopped.is_some_and(|t| t.elapsed() > GUARD) {
                    break;
                }
            }
            topics
        });
        Subscriber {
            stop,
            thread: Some(thread),
        }
    }
}

impl Drop for InProcess {
    fn drop(&mut self) {
        if let Some(s) = self.stop.take() {
            let _ = s.send(());
        }
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

struct Subscriber {
    stop: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<std::collections::BTreeSet<String>>>,
}

impl Subscriber {
    /// Topics seen.
    fn finish(mut self) -> std::collections::BTreeSet<String> {
        self.stop.store(true, Ordering::Release);
        self.thread.take().unwrap().join().unwrap()
    }
}

/// Allocations inside realtime steps per window, in order.
#[derive(Default)]
struct Windows(Vec<(&'static str, u64)>);

impl Windows {
    fn measure(&mut self, name: &'static str, f: impl FnOnce()) {
        let before = counting_alloc::in_rt_steps();
        f();
        self.0.push((name, counting_alloc::in_rt_steps() - before));
    }

    fn assert_none(&mut self) {
        let windows: u64 = self.0.iter().map(|(_, n)| n).sum();
        self.0.push((
            "between the windows (switching back on, start-up, shutdown)",
            counting_alloc::in_rt_steps() - windows,
        ));
        let bad: Vec<_> = self.0.iter().filter(|(_, n)| *n > 0).collect();
        assert!(
            bad.is_empty(),
            "allocations inside realtime steps, per window: {:?}\nfirst one at:\n{}",
            self.0,
            counting_alloc::first_rt_backtrace().unwrap_or_default()
        );
    }
}

fn status(c: &mut Client) -> Value {
    ok(c, "status", Value::Null)
}

fn mode_is(c: &mut Client, what: &'static str) -> Value {
    wait_status(c, what, GUARD, |s| s["mode"] == json!(what))
}

fn job_line_at_least(c: &mut Client, line: u64) {
    wait_status(c, "job moving", GUARD, |s| {
        s["mode"] == json!("running") && s["job"]["line"].as_u64().unwrap() >= line
    });
}

fn job_ends(c: &mut Client, state: &'static str) -> Value {
    wait_status(c, state, GUARD, |s| {
        s["job"]["state"] == json!(state) && s["mode"] != json!("running")
    })
}

fn back_on(c: &mut Client) {
    ok(c, "machine.on", Value::Null);
    mode_is(c, "idle");
}

/// The long job, running and moving (line 6: a 200 mm feed move).
fn long_job_moving(c: &mut Client) {
    run_job(c, "jobs/long.ngc");
    job_line_at_least(c, 6);
}

#[test]
fn the_daemon_servo_thread_allocates_nothing_in_any_window() {
    let mut w = Windows::default();
    assert_eq!(counting_alloc::in_rt_steps(), 0);
    // The fast mill, with a storm threshold no loaded host reaches by itself (400 overruns in
    // a row: 0.4 s without the CPU), so only the injected storm trips the machine.
    let dir = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(fast_sim()).unwrap();
    assert!(
        text.contains("overrun_storm_count = 50\n"),
        "sim-fast.toml changed"
    );
    let config = dir.path().join("sim-fast-storm-400.toml");
    std::fs::write(
        &config,
        text.replace("overrun_storm_count = 50\n", "overrun_storm_count = 400\n"),
    )
    .unwrap();
    {
        let d = InProcess::start(&config);
        let events = d.subscriber();
        let mut c = d.client();
        // Counted from the machine's first cycle: start-up is realtime too.
        w.measure("e-stop reset, machine on, homing", || ready(&mut c));
        w.measure("job start: acceptance and first cycles", || {
            run_job(&mut c, "jobs/long.ngc");
            job_line_at_least(&mut c, 5);
        });
        w.measure("overrides", || {
            ok(&mut c, "override", json!({"feed": 1.5}));
            ok(
                &mut c,
                "call",
                json!({"task": "machine", "operation": "set_overrides",
                       "args": {"feed": 0.5, "rapid": 0.25, "spindle": 0.8}}),
            );
            ok(
                &mut c,
                "override",
                json!({"feed": 1.0, "rapid": 1.0, "spindle": 1.0}),
            );
            job_line_at_least(&mut c, 6);
        });
        w.measure("feed hold and resume", || {
            ok(&mut c, "job.pause", Value::Null);
            wait_status(&mut c, "held", GUARD, |s| {
                s["mode"] == json!("holding") && at_rest(s, 1e-6)
            });
            ok(&mut c, "job.resume", Value::Null);
            mode_is(&mut c, "running");
        });
        w.measure("single step", || {
            ok(&mut c, "job.step", Value::Null);
            wait_status(&mut c, "held after a step", GUARD, |s| {
                s["mode"] == json!("holding") && at_rest(s, 1e-6)
            });
        });
        w.measure("abort", || {
            ok(&mut c, "job.abort", Value::Null);
            job_ends(&mut c, "aborted");
            mode_is(&mut c, "idle");
        });
        w.measure("MSG and M0", || {
            let text = "G21 G90\n(MSG, a message)\nG0 X120 Y120 Z-5\nM0\nG1 X130 F3000\nM2\n";
            ok(&mut c, "job.load", json!({"text": text, "name": "m0.ngc"}));
            ok(&mut c, "job.run", Value::Null);
            // At an M0 the job holds (mode and job "holding") until `job.resume`.
            wait_status(&mut c, "paused at M0", GUARD, |s| {
                s["mode"] == json!("holding")
                    && s["job"]["state"] == json!("holding")
                    && at_rest(s, 1e-6)
            });
            ok(&mut c, "job.resume", Value::Null);
            job_ends(&mut c, "done");
        });
        w.measure("MDI", || {
            ok(&mut c, "mdi", json!({"line": "G0 X100 Y120 Z-30"}));
            wait_status(&mut c, "mdi done", GUARD, |s| {
                s["mode"] == json!("idle")
                    && (axis(s, "Y")["actual"].as_f64().unwrap() - 120.0).abs() < 0.002
            });
        });
        w.measure("jog", || {
            ok(
                &mut c,
                "jog",
                json!({"axis": "X", "velocity": 20.0, "distance": 5.0}),
            );
            wait_status(&mut c, "jog done", GUARD, |s| {
                s["mode"] == json!("idle")
                    && (axis(s, "X")["actual"].as_f64().unwrap() - 105.0).abs() < 0.002
            });
            ok(&mut c, "jog", json!({"axis": "Y", "velocity": -30.0}));
            wait_status(&mut c, "jogging", GUARD, |s| {
                axis(s, "Y")["actual"].as_f64().unwrap() < 118.0
            });
            ok(&mut c, "jog.stop", Value::Null);
            mode_is(&mut c, "idle");
        });
        w.measure("machine off during a job", || {
            long_job_moving(&mut c);
            ok(&mut c, "machine.off", Value::Null);
            mode_is(&mut c, "off");
        });
        back_on(&mut c);
        w.measure("e-stop input during a job", || {
            long_job_moving(&mut c);
            ok(&mut c, "sim.input", json!({"name": "estop", "value": 1}));
            wait_status(&mut c, "stopped in e-stop", GUARD, |s| {
                s["mode"] == json!("estop") && at_rest(s, 1e-3)
            });
            ok(&mut c, "sim.input", json!({"name": "estop", "value": 0}));
            ok(&mut c, "estop.reset", Value::Null);
        });
        back_on(&mut c);
        for (name, kind, axis_name, window) in [
            ("following error", "stall", "X", "trip: following error"),
            ("drive fault", "drive_fault", "Y", "trip: drive fault"),
            (
                "communication loss",
                "disconnect",
                "Z",
                "trip: communication loss",
            ),
        ] {
            w.measure(window, || {
                long_job_moving(&mut c);
                ok(
                    &mut c,
                    "sim.fault",
                    json!({"kind": kind, "axis": axis_name, "code": 0x7500}),
                );
                wait_status(&mut c, name, GUARD, |s| {
                    s["mode"] == json!("fault") && at_rest(s, 1e-3)
                });
                job_ends(&mut c, "failed");
            });
            if kind != "drive_fault" {
                ok(
                    &mut c,
                    "sim.fault",
                    json!({"kind": kind, "axis": axis_name, "on": false}),
                );
            }
            back_on(&mut c);
        }
        w.measure("trip: overrun storm", || {
            long_job_moving(&mut c);
            ok(
                &mut c,
                "sim.fault",
                json!({"kind": "overrun", "cycles": 450}),
            );
            let s = wait_status(&mut c, "overrun storm", GUARD, |s| {
                s["mode"] == json!("fault") && at_rest(s, 1e-3)
            });
            assert!(
                s["faults"].to_string().contains("overran"),
                "{}",
                s["faults"]
            );
        });
        back_on(&mut c);
        assert!(
            status(&mut c)["threads"][0]["cycles"].as_u64().unwrap() > 1000,
            "the servo thread ran"
        );
        let topics = events.finish();
        for t in ["mode", "job", "fault", "progress", "message"] {
            assert!(
                topics.contains(t),
                "the subscriber saw no '{t}' event: {topics:?}"
            );
        }
    }
    // The limit switches sit beyond the soft limits, which even a jog respects: a second
    // machine whose X switch is moved inside them (at 10 mm) is jogged onto it.
    let text = std::fs::read_to_string(&config).unwrap();
    assert!(
        text.contains("negative_limit = -3.0"),
        "sim-fast.toml changed"
    );
    let switch_inside = dir.path().join("switch-inside.toml");
    std::fs::write(
        &switch_inside,
        text.replacen("negative_limit = -3.0", "negative_limit = 10.0", 1),
    )
    .unwrap();
    let d = InProcess::start(&switch_inside);
    let _events = d.subscriber();
    let mut c = d.client();
    ready(&mut c);
    w.measure("trip: limit switch", || {
        ok(
            &mut c,
            "jog",
            json!({"axis": "X", "velocity": -100.0, "distance": 295.0}),
        );
        let s = wait_status(&mut c, "limit switch", GUARD, |s| {
            s["mode"] == json!("fault") && at_rest(s, 1e-3)
        });
        assert!(
            s["faults"].to_string().contains("limit switch"),
            "{}",
            s["faults"]
        );
    });
    back_on(&mut c);
    w.measure("machine off", || {
        ok(&mut c, "machine.off", Value::Null);
        mode_is(&mut c, "off");
    });
    drop(d);
    eprintln!("allocations inside servo cycles per window: {:?}", w.0);
    w.assert_none();
}
