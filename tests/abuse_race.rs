//! Session 10's races from outside: several clients firing job.load / job.run / job.abort /
//! estop / estop.reset / machine.on / machine.off / home / mdi at the real daemon (simulated
//! mill, simulated clock) in a seeded random order; a client flooding requests without
//! reading a reply; an events subscriber that never reads. Expected whatever the
//! interleaving: every request answered (an error is an answer), nothing panics, an e-stop
//! still stops everything and the machine then runs a job to its end. Waits are hang guards.
#![allow(clippy::unwrap_used)]

mod support;

use hytask::control::client::{Client, ClientError};
use serde_json::{json, Value};
use std::io::Write;
use std::os::unix::net::UnixStream;
use std::time::Duration;
use support::*;

const GUARD: Duration = Duration::from_secs(120);
/// Clients racing, requests each.
const RACERS: u64 = 6;
const ROUNDS: usize = 150;
const JOB: &str = "G21 G90\nG0 X20 Y20 Z-5\nG1 X40 F3000\nG1 Y40\nM2\n";

/// A small seeded generator (xorshift64*): the same seed gives the same request order.
struct Rng(u64);

impl Rng {
    fn below(&mut self, n: usize) -> usize {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        (self.0.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 33) as usize % n
    }
}

/// One racing client: `rounds` requests drawn from the operator's commands. Panics if a
/// request is not answered (the client's 30 s read timeout) or the answer is malformed.
fn racer(socket: std::path::PathBuf, seed: u64, rounds: usize) {
    let mut c = Client::connect(&socket).unwrap();
    let mut rng = Rng(seed);
    for _ in 0..rounds {
        // Weighted so that jobs do run: e-stop and power off are rare.
        let (method, params) = match rng.below(20) {
            0 => ("estop", Value::Null),
            1 => ("machine.off", Value::Null),
            2 => ("estop.reset", Value::Null),
            3 | 4 => ("machine.on", Value::Null),
            5 | 6 => ("home", Value::Null),
            7..=9 => ("job.load", json!({"text": JOB, "name": "race.ngc"})),
            10..=13 => ("job.run", Value::Null),
            14 | 15 => ("job.abort", Value::Null),
            16 => ("job.pause", Value::Null),
            17 => ("job.resume", Value::Null),
            _ => ("mdi", json!({"line": "G91 G0 X-1"})),
        };
        match c.call(method, params) {
            Ok(_) | Err(ClientError::Remote { .. }) => {}
            Err(e) => panic!("seed {seed}: {method} not answered: {e}"),
        }
    }
}

/// After any race: an e-stop stops everything, then the machine is made ready and runs a
/// job to its end; the daemon never panicked.
fn still_sound(d: &Daemon, c: &mut Client) {
    ok(c, "estop", Value::Null);
    wait_status(c, "at rest in e-stop", GUARD, |s| {
        s["mode"] == json!("estop") && at_rest(s, 1e-9)
    });
    ready(c);
    run_text(c, JOB, "after.ngc");
    let s = wait_job_end(c, "the job after the race", GUARD);
    assert_eq!(s["job"]["state"], json!("done"), "{s}");
    assert!(!d.log().contains("panicked"), "{}", d.log());
}

#[test]
fn seeded_racing_clients_get_every_answer_and_leave_a_sound_machine() {
    let d = Daemon::start_sim();
    let mut c = d.client();
    ready(&mut c);
    let racers: Vec<_> = (1..=RACERS)
        .map(|seed| {
            let socket = d.socket.clone();
            std::thread::spawn(move || {
                racer(socket, seed.wrapping_mul(0x9e37_79b9_7f4a_7c15), ROUNDS)
            })
        })
        .collect();
    for r in racers {
        r.join().unwrap();
    }
    still_sound(&d, &mut c);
}

#[test]
fn a_flood_without_reading_and_a_subscriber_that_never_reads_do_not_stop_others() {
    let d = Daemon::start_sim();
    let mut c = d.client();
    ready(&mut c);
    // Subscribed to every topic, never reads.
    let mut deaf = UnixStream::connect(&d.socket).unwrap();
    deaf.write_all(b"{\"id\":1,\"method\":\"subscribe\"}\n")
        .unwrap();
    // Twenty thousand requests written, no reply read (on a thread: the write may block
    // once the daemon stops reading this connection).
    let flood = {
        let socket = d.socket.clone();
        std::thread::spawn(move || {
            let mut s = UnixStream::connect(&socket).unwrap();
            s.set_write_timeout(Some(GUARD)).unwrap();
            let line = b"{\"id\":1,\"method\":\"status\"}\n".repeat(20_000);
            // Closed by the daemon or written: both are fine.
            let _ = s.write_all(&line);
            s
        })
    };
    // Meanwhile jobs run and make events (progress, job, mode) for the deaf subscriber.
    for i in 0..3 {
        run_text(&mut c, JOB, &format!("busy{i}.ngc"));
        let s = wait_job_end(&mut c, "a job beside the flood", GUARD);
        assert_eq!(s["job"]["state"], json!("done"), "{s}");
    }
    let _flooder = flood.join().unwrap();
    still_sound(&d, &mut c);
    drop(deaf);
}
