//! `hytask sim-drive`: loopback CiA 402 drives on a SocketCAN interface.
//!
//! Runs one [`DriveSlave`] per node id on one [`SocketCanBus`] (a vcan0 for tests, or a real
//! bus to try a master against): NMT, SDO server, PDOs, heartbeat, EMCY, the 402 state
//! machine with the simulated axis's motor model and fault injection at 0x2000. Time
//! advances in 1 ms steps on `CLOCK_MONOTONIC` with absolute sleeps, so the drives' clock
//! does not drift with the loop's own run time. One socket serves every node: each received
//! frame goes to every drive (the kernel does not loop a socket's own frames back, and
//! drives never need each other's frames).
//!
//! It prints one `ready` line on stdout once the boot-up messages are sent (the heartbeat
//! runs from then on), so a test can wait for it instead of sleeping, and exits 0 on
//! SIGINT/SIGTERM.

use crate::rt::activity::sleep_until_ns;
use crate::rt::clock::monotonic_ns;
use anyhow::{bail, Context};
use hytask_hal::canopen::slave::{DriveSlave, SlaveConfig, OUTBOX};
use hytask_hal::canopen::{NodeId, Outbox};
use hytask_hal::socketcan::{SocketCanBus, SocketCanError};
use hytask_hal::{CanBus, Error as _, ErrorKind};
use std::io::Write as _;
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

/// Arguments of `hytask sim-drive`.
#[derive(Debug, clap::Args)]
pub struct SimDriveArgs {
    /// The SocketCAN interface (e.g. vcan0).
    #[arg(long)]
    pub iface: String,
    /// One node id (1..=127).
    #[arg(long, conflicts_with = "nodes", required_unless_present = "nodes")]
    pub node: Option<u8>,
    /// Several node ids, comma separated (e.g. 1,2,3).
    #[arg(long, value_delimiter = ',')]
    pub nodes: Vec<u8>,
    /// Heartbeat producer time after boot (0x1017), ms; 0 = none until a master sets it.
    #[arg(long, default_value_t = 100)]
    pub heartbeat_ms: u16,
    /// Step of the drives' clock (and nominal SYNC period), µs.
    #[arg(long, default_value_t = 1000)]
    pub cycle_us: u64,
}

/// Set by SIGINT/SIGTERM; the loop checks it every step.
static STOP: AtomicBool = AtomicBool::new(false);

extern "C" fn on_signal(_: libc::c_int) {
    STOP.store(true, Ordering::Release);
}

fn install_signal_handlers() -> anyhow::Result<()> {
    use nix::sys::signal::{sigaction, SaFlags, SigAction, SigHandler, SigSet, Signal};
    let act = SigAction::new(
        SigHandler::Handler(on_signal),
        SaFlags::empty(),
        SigSet::empty(),
    );
    for sig in [Signal::SIGINT, Signal::SIGTERM] {
        // SAFETY: the handler only stores to an atomic, which is async-signal-safe.
        unsafe { sigaction(sig, &act) }.with_context(|| format!("installing a {sig} handler"))?;
    }
    Ok(())
}

/// The node ids of the arguments, checked and without duplicates.
fn node_ids(a: &SimDriveArgs) -> anyhow::Result<Vec<NodeId>> {
    let raw: Vec<u8> = a.node.into_iter().chain(a.nodes.iter().copied()).collect();
    if raw.is_empty() {
        bail!("give --node N or --nodes 1,2,3");
    }
    let mut ids = Vec::with_capacity(raw.len());
    for r in raw {
        let id = NodeId::new(r).with_context(|| format!("--node(s): {r}"))?;
        if ids.contains(&id) {
            bail!("--nodes: node {r} is given twice");
        }
        ids.push(id);
    }
    Ok(ids)
}

/// Sends what the drives produced. A full transmit queue drops the frame (counted; a real
/// drive would lose it the same way); any other error ends the run.
fn send_all(
    bus: &mut SocketCanBus,
    out: &mut Outbox<OUTBOX>,
    dropped: &mut u64,
) -> Result<(), SocketCanError> {
    for f in out.iter() {
        match bus.try_send(f) {
            Ok(()) => {}
            Err(e) if e.kind() == ErrorKind::WouldBlock => *dropped += 1,
            Err(e) => return Err(e),
        }
    }
    out.clear();
    Ok(())
}

/// Runs `hytask sim-drive`.
pub fn run(a: SimDriveArgs) -> anyhow::Result<ExitCode> {
    let ids = node_ids(&a)?;
    if a.cycle_us == 0 {
        bail!("--cycle-us must be at least 1");
    }
    let cfg = SlaveConfig {
        cycle: Duration::from_micros(a.cycle_us),
        heartbeat_ms: a.heartbeat_ms,
        ..SlaveConfig::default()
    };
    let mut drives: Vec<DriveSlave> = ids.iter().map(|&n| DriveSlave::new(n, cfg)).collect();
    let mut bus = SocketCanBus::open(&a.iface)?;
    install_signal_handlers()?;

    let period = a.cycle_us * 1000;
    let start = monotonic_ns();
    let mut deadline = start;
    let mut out = Outbox::<OUTBOX>::default();
    let mut dropped = 0u64;
    let mut ready = false;
    while !STOP.load(Ordering::Acquire) {
        let now = Duration::from_nanos(monotonic_ns().saturating_sub(start));
        loop {
            let f = match bus.try_recv() {
                Ok(Some(f)) => f,
                Ok(None) => break,
                // Bus trouble that is not fatal for a simulated drive (error-passive, a
                // protocol error frame): report and carry on, as a drive would.
                Err(e) if !e.kind().is_link_failure() => {
                    eprintln!("sim-drive: {e}");
                    continue;
                }
                Err(e) => return Err(e.into()),
            };
            for d in drives.iter_mut() {
                d.on_frame(&f, now, &mut out);
                send_all(&mut bus, &mut out, &mut dropped)?;
            }
        }
        for d in drives.iter_mut() {
            d.tick(now, &mut out);
            send_all(&mut bus, &mut out, &mut dropped)?;
        }
        if !ready {
            ready = true;
            let list: Vec<String> = ids.iter().map(|n| n.to_string()).collect();
            println!(
                "ready: sim-drive on {} nodes {} heartbeat {} ms",
                bus.iface(),
                list.join(","),
                a.heartbeat_ms
            );
            std::io::stdout()
                .flush()
                .context("writing the ready line")?;
        }
        deadline += period;
        let late = monotonic_ns();
        if late > deadline + 100 * period {
            // Far behind (a stopped process, a loaded emulator): skip ahead instead of
            // running a burst of catch-up steps.
            deadline = late;
        }
        sleep_until_ns(deadline);
    }
    if dropped > 0 {
        eprintln!("sim-drive: {dropped} frame(s) dropped on a full transmit queue");
    }
    Ok(ExitCode::SUCCESS)
}
