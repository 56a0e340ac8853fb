//! `hytask sim-drive --nodes 1,2,3` on a real vcan0, seen through our own SDO client, NMT
//! codec and heartbeat consumer on a `SocketCanBus`: one process serves three nodes (boot-up,
//! heartbeat, SDO, NMT for each), prints its ready line, and exits 0 on SIGTERM. (The
//! interoperability checks against python-canopen are in tests/vcan/py/.) Runs under
//! `tests/vcan/run`, which sets `HYTASK_VCAN`; elsewhere it says why and returns.
#![allow(clippy::unwrap_used)]

mod vcan;

const NAME: &str = "vcan_sim_drive";

use hytask_hal::canopen::heartbeat::HeartbeatConsumer;
use hytask_hal::canopen::nmt::{NmtCommand, NmtState};
use hytask_hal::canopen::sdo::{SdoClient, SdoStep};
use hytask_hal::canopen::NodeId;
use hytask_hal::socketcan::SocketCanBus;
use hytask_hal::CanBus;
use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

const GUARD: Duration = Duration::from_secs(120);

/// The sim-drive process; killed if the test panics before stopping it.
struct Drive(Child);

impl Drop for Drive {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn nodes() -> [NodeId; 3] {
    [1, 2, 3].map(|n| NodeId::new(n).unwrap())
}

#[test]
fn one_process_serves_three_nodes_and_stops_on_sigterm() {
    let Some(iface) = vcan::iface(NAME) else {
        return;
    };
    let mut bus = SocketCanBus::open(&iface).unwrap();
    let mut drive = Drive(
        Command::new(env!("CARGO_BIN_EXE_hytask"))
            .args(["sim-drive", "--iface", &iface, "--nodes", "1,2,3"])
            .args(["--heartbeat-ms", "50"])
            .stdout(Stdio::piped())
            .spawn()
            .unwrap(),
    );
    let mut out = BufReader::new(drive.0.stdout.take().unwrap());
    let mut line = String::new();
    out.read_line(&mut line).unwrap();
    assert!(line.starts_with("ready: sim-drive on"), "{line:?}");
    assert!(line.contains("nodes 1,2,3"), "{line:?}");

    let t0 = Instant::now();
    let now = || t0.elapsed();
    let mut hb = HeartbeatConsumer::default();
    for n in nodes() {
        hb.watch(n, GUARD, now());
    }
    let mut clients: Vec<(SdoClient, Option<Vec<u8>>)> = nodes()
        .iter()
        .map(|&n| {
            let mut c = SdoClient::with_timeout(n, Duration::from_secs(30));
            bus.try_send(&c.upload(0x1018, 4, now()).unwrap()).unwrap();
            (c, None)
        })
        .collect();
    let mut started = false;
    loop {
        assert!(
            t0.elapsed() < GUARD,
            "hang guard: {:?}",
            nodes().map(|n| hb.state(n))
        );
        while let Some(f) = bus.try_recv().unwrap() {
            hb.on_frame(&f, now());
            for (c, v) in clients.iter_mut() {
                match c.on_frame(&f, now()) {
                    SdoStep::Send(r) => bus.try_send(&r).unwrap(),
                    SdoStep::Uploaded(d) => *v = Some(d),
                    SdoStep::Ignored => {}
                    other => panic!("node {}: {other:?}", c.node()),
                }
            }
        }
        for (c, _) in clients.iter_mut() {
            if let Some(step) = c.poll(now()) {
                panic!("node {}: {step:?}", c.node());
            }
        }
        assert_eq!(hb.check(now()), None);
        let answered = clients.iter().all(|(_, v)| v.is_some());
        if answered && !started {
            // Every node answered SDO in pre-operational; start them all with one command.
            assert!(nodes()
                .iter()
                .all(|&n| hb.state(n) == Some(NmtState::PreOperational)));
            bus.try_send(&NmtCommand::Start.frame(None)).unwrap();
            started = true;
        }
        if started
            && nodes()
                .iter()
                .all(|&n| hb.state(n) == Some(NmtState::Operational))
        {
            break;
        }
        std::thread::sleep(Duration::from_millis(1));
    }
    for (c, v) in &clients {
        // 0x1018:4 (serial number) of the loopback drive is its node id.
        assert_eq!(
            v.as_deref(),
            Some(&u32::from(c.node().get()).to_le_bytes()[..])
        );
    }

    nix::sys::signal::kill(
        nix::unistd::Pid::from_raw(drive.0.id() as i32),
        nix::sys::signal::Signal::SIGTERM,
    )
    .unwrap();
    let t1 = Instant::now();
    loop {
        if let Some(st) = drive.0.try_wait().unwrap() {
            assert!(st.success(), "sim-drive exit {st:?} on SIGTERM");
            break;
        }
        assert!(t1.elapsed() < GUARD, "sim-drive did not exit on SIGTERM");
        std::thread::sleep(Duration::from_millis(10));
    }
}
