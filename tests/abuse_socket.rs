//! The real daemon (simulated mill on a simulated clock) attacked from its control socket as
//! an abuse tool would: ambiguous and malformed requests, numbers out of every range, silent
//! connection floods, racing clients. Expected each time: an error reply naming what is wrong,
//! the daemon still serving others, and the e-stop always getting through. Waits are hang
//! guards (60 s and more), never timings.
#![allow(clippy::unwrap_used)]

mod support;

use hytask::control::client::Client;
use serde_json::{json, Value};
use std::io::{BufRead, BufReader, Read, Write};
use std::os::unix::net::UnixStream;
use std::path::Path;
use std::time::{Duration, Instant};
use support::*;

const GUARD: Duration = Duration::from_secs(60);

/// Sends raw bytes on a fresh connection and reads one reply line (None: closed unanswered).
fn raw(socket: &Path, bytes: &[u8]) -> Option<Value> {
    let mut s = UnixStream::connect(socket).unwrap();
    s.set_read_timeout(Some(GUARD)).unwrap();
    s.write_all(bytes).unwrap();
    let mut line = String::new();
    match BufReader::new(s).read_line(&mut line) {
        Ok(n) if n > 0 => Some(serde_json::from_str(&line).unwrap()),
        _ => None,
    }
}

fn mode(c: &mut Client) -> String {
    ok(c, "status", Value::Null)["mode"]
        .as_str()
        .unwrap()
        .to_string()
}

/// Found: `{"method":"status","method":"estop"}` ran `estop` (serde_json keeps the last
/// duplicate), so a filter or a log that reads the first key saw another request than the one
/// run. A duplicate key, at any depth, is now an invalid request naming the key.
#[test]
fn duplicate_keys_are_refused_by_name_and_nothing_runs() {
    let d = Daemon::start_sim();
    let mut c = d.client();
    ok(&mut c, "estop.reset", Value::Null);
    assert_ne!(mode(&mut c), "estop");
    let r = raw(
        &d.socket,
        b"{\"id\":5,\"method\":\"status\",\"method\":\"estop\"}\n",
    )
    .unwrap();
    assert_eq!(r["id"], json!(5), "{r}");
    assert_eq!(r["error"]["code"], json!(-32600), "{r}");
    let msg = r["error"]["message"].as_str().unwrap();
    assert!(msg.contains("duplicate key 'method'"), "{msg}");
    let r = raw(
        &d.socket,
        b"{\"id\":6,\"method\":\"override\",\"params\":{\"feed\":0.5,\"feed\":2.0}}\n",
    )
    .unwrap();
    assert!(
        r["error"]["message"]
            .as_str()
            .unwrap()
            .contains("duplicate key 'feed'"),
        "{r}"
    );
    assert_ne!(mode(&mut c), "estop", "the hidden estop ran");
    assert_eq!(ok(&mut c, "override", json!({}))["feed"], json!(1.0));
}

/// Seeded battery of malformed, binary, nested, huge-number and wrong-typed requests: every
/// one gets an error reply (the daemon never closes on it), and the daemon keeps serving.
#[test]
fn malformed_requests_get_error_replies_and_the_daemon_keeps_serving() {
    let d = Daemon::start_sim();
    let nested = format!("{}1{}", "[".repeat(5000), "]".repeat(5000));
    let fixed: Vec<Vec<u8>> = vec![
        b"{\"id\":1,\"method\":\"status\"".to_vec(),
        vec![0, 0xff, 0xfe, b'{'],
        nested.clone().into_bytes(),
        format!("{{\"id\":{nested},\"method\":\"status\"}}").into_bytes(),
        b"{\"id\":1,\"method\":\"override\",\"params\":{\"feed\":1e400}}".to_vec(),
        b"{\"id\":1,\"method\":\"override\",\"params\":{\"feed\":NaN}}".to_vec(),
        b"{\"id\":1,\"method\":\"override\",\"params\":{\"feed\":-1}}".to_vec(),
        b"{\"id\":1,\"method\":\"override\",\"params\":{\"rapid\":1e308}}".to_vec(),
        b"{\"id\":1,\"method\":\"jog\",\"params\":{\"axis\":\"X\",\"velocity\":1e999}}".to_vec(),
        b"{\"id\":1,\"method\":\"jog\",\"params\":{\"axis\":\"X\",\"velocity\":0}}".to_vec(),
        b"{\"id\":1,\"method\":\"jog\",\"params\":{\"axis\":\"X\",\"velocity\":1,\"distance\":-5}}"
            .to_vec(),
        b"{\"id\":1,\"method\":\"call\",\"params\":{\"task\":\"machine\",\"operation\":\"set_overrides\",\"args\":[1e308,-1,5]}}".to_vec(),
        b"{\"id\":1,\"method\":\"call\",\"params\":{\"task\":\"machine\",\"operation\":\"run\",\"args\":[1,99999999999,false]}}".to_vec(),
        b"{\"id\":1,\"method\":\"sim.fault\",\"params\":{\"kind\":\"overrun\",\"cycles\":-5}}".to_vec(),
        b"{\"id\":1,\"method\":\"drive.sdo_read\",\"params\":{\"drive\":\"x\",\"index\":99999999,\"sub\":-1}}".to_vec(),
        b"{\"id\":1,\"method\":\"job.load\",\"params\":{\"path\":\"/dev/zero\"}}".to_vec(),
        b"{\"id\":1,\"method\":\"job.load\",\"params\":{\"path\":\"/\"}}".to_vec(),
        b"{\"id\":1,\"method\":\"job.load\",\"params\":{\"path\":\"a\\u0000b\"}}".to_vec(),
        b"{\"id\":1,\"method\":\"mdi\",\"params\":{\"line\":\"G0 X1\\nM2\"}}".to_vec(),
        b"{\"id\":1,\"method\":\"no.such.method\"}".to_vec(),
        b"{\"id\":1,\"method\":\"status\",\"params\":[1,2,3]}".to_vec(),
        b"{\"id\":1e400,\"method\":\"status\"}".to_vec(),
        b"[]".to_vec(),
        b"\"estop\"".to_vec(),
    ];
    // Seeded mutations of a valid request: bytes flipped, cut, duplicated (xorshift, fixed
    // seed, so every run sends the same requests).
    let base = br#"{"id":7,"method":"override","params":{"feed":0.5,"rapid":0.5}}"#;
    let mut seed: u64 = 0x5eed_ab05e;
    let mut next = move || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        seed
    };
    let mut requests = fixed;
    for _ in 0..200 {
        let mut m = base.to_vec();
        for _ in 0..1 + next() % 3 {
            let i = (next() as usize) % m.len();
            match next() % 3 {
                0 => m[i] = (next() % 256) as u8,
                1 => m.truncate(i.max(1)),
                _ => m.insert(i, m[i]),
            }
        }
        m.retain(|&b| b != b'\n');
        requests.push(m);
    }
    for req in &requests {
        let mut line = req.clone();
        line.push(b'\n');
        if req.iter().all(u8::is_ascii_whitespace) {
            continue;
        }
        let r = raw(&d.socket, &line)
            .unwrap_or_else(|| panic!("no reply to {:?}", String::from_utf8_lossy(req)));
        if r.get("error").is_some() {
            let m = r["error"]["message"].as_str().unwrap();
            assert!(!m.is_empty(), "{r}");
        }
    }
    let mut c = d.client();
    assert!(ok(&mut c, "status", Value::Null)["axes"].is_array());
}

/// Found: with `max_clients` normal and as many over-limit connections held open silently, a
/// further connection was closed unanswered, so `hytask estop` could not get through (the
/// README promises it always does). Now the oldest silent over-limit connection makes room.
#[test]
fn an_estop_gets_through_a_flood_of_silent_connections() {
    let dir = tempfile::tempdir().unwrap();
    let config = sim_clock_config(dir.path(), SIM_SPEED, None);
    let text = std::fs::read_to_string(&config).unwrap();
    let text = text.replacen("[control]\n", "[control]\nmax_clients = 4\n", 1);
    std::fs::write(&config, text).unwrap();
    let d = Daemon::start(&config);
    {
        let mut c = d.client();
        ok(&mut c, "estop.reset", Value::Null);
    }
    // 4 normal + 4 over-limit slots, and 40 more: hold them all, sending nothing.
    let flood: Vec<UnixStream> = (0..48)
        .map(|_| UnixStream::connect(&d.socket).unwrap())
        .collect();
    // Wait until the daemon has dealt with all of them: every connection beyond the 8 it can
    // hold is closed (with or without a reply line), before or after the fix alike.
    let t0 = Instant::now();
    loop {
        let closed = flood
            .iter()
            .filter(|s| {
                s.set_nonblocking(true).unwrap();
                let mut buf = [0u8; 512];
                let mut s = *s;
                loop {
                    match s.read(&mut buf) {
                        Ok(0) => return true,
                        Ok(_) => continue,
                        Err(_) => return false,
                    }
                }
            })
            .count();
        if closed >= flood.len() - 8 {
            break;
        }
        assert!(t0.elapsed() < GUARD, "only {closed} of the flood closed");
        std::thread::sleep(Duration::from_millis(20));
    }
    let r = raw(&d.socket, b"{\"id\":1,\"method\":\"estop\"}\n")
        .expect("the e-stop connection was closed unanswered");
    assert_eq!(r["result"], json!({"ok": true}), "{r}");
    drop(flood);
    // The daemon frees the flood's slots when it notices the hang-ups: until then a new
    // connection is one more over the limit and serves only `estop`. Retry until a full one.
    let t0 = Instant::now();
    let status = loop {
        if let Ok(mut c) = Client::connect(&d.socket) {
            match c.call("status", Value::Null) {
                Ok(s) => break s,
                Err(e) => assert!(e.to_string().contains("too many clients"), "{e}"),
            }
        }
        assert!(
            t0.elapsed() < GUARD,
            "no full connection after the flood hung up"
        );
        std::thread::sleep(Duration::from_millis(20));
    };
    assert_eq!(status["mode"], json!("estop"));
}

/// Two clients race start, abort, e-stop and reset for many rounds: whatever the
/// interleaving, every request is answered, and after the last e-stop the machine is in
/// e-stop with nothing moving.
#[test]
fn racing_clients_never_beat_the_estop() {
    let d = Daemon::start_sim();
    let mut c = d.client();
    ready(&mut c);
    let socket = d.socket.clone();
    let racer = std::thread::spawn(move || {
        let mut c = Client::connect(&socket).unwrap();
        for _ in 0..30 {
            let _ = c.call("estop", Value::Null);
            let _ = c.call("estop.reset", Value::Null);
            let _ = c.call("machine.on", Value::Null);
            let _ = c.call("job.abort", Value::Null);
        }
    });
    for i in 0..30 {
        let _ = c.call(
            "mdi",
            json!({"line": format!("G91 G1 X-{} F3000", 1 + i % 3)}),
        );
        let _ = c.call("job.run", Value::Null);
        let _ = c.call("jog", json!({"axis": "Y", "velocity": -20.0}));
    }
    racer.join().unwrap();
    ok(&mut c, "estop", Value::Null);
    let s = wait_status(&mut c, "at rest in e-stop", GUARD, |s| {
        s["mode"] == "estop" && at_rest(s, 1e-9)
    });
    assert_eq!(s["mode"], json!("estop"));
}
