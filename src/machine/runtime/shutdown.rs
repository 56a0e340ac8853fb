//! A machine as a daemon deployment ([`crate::daemon::Deployed`]): its name, realtime flag,
//! cycle count and orderly shutdown (stop jobs and the bridge, then the realtime runtime). Why
//! apart: the daemon sees only this.

use super::{lock, Machine};
use crate::machine::api::*;
use crate::machine::servo::machine_task::MachineCmd;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

impl crate::daemon::Deployed for Machine {
    fn name(&self) -> String {
        self.name.clone()
    }

    fn realtime(&self) -> bool {
        // The servo thread sets its flag when it starts: wait for that, briefly.
        let t0 = Instant::now();
        while !self.servo.running() && t0.elapsed() < Duration::from_secs(1) {
            std::thread::sleep(Duration::from_millis(1));
        }
        self.servo.realtime()
    }

    fn servo_cycles(&self) -> u64 {
        self.servo.stats.summary().wakeup.count
    }

    fn shutdown(&self) -> anyhow::Result<()> {
        // No script command is carried out once the machine goes down.
        self.scripts.stop();
        // A controlled stop of whatever moves, then drives off, then threads down.
        let snap = self.snapshot().machine;
        if snap.mode == Mode::Fault {
            // A fault has already stopped the axes under control and disabled the drives; the
            // machine does not take `Off` in that mode, so waiting for it would outlast
            // systemd's stop timeout. The e-stop puts the outputs in their safe state at once.
            let _ = self.command(MachineCmd::Estop);
            std::thread::sleep(Duration::from_millis(200));
        } else if !matches!(snap.mode, Mode::Estop | Mode::Off) {
            if let Err(e) = self.command_done(MachineCmd::Off, Duration::from_secs(30)) {
                tracing::warn!("controlled stop at shutdown: {e}; tripping the e-stop");
                let _ = self.command(MachineCmd::Estop);
                std::thread::sleep(Duration::from_millis(200));
            }
        }
        self.bridge_stop.store(true, Ordering::Release);
        if let Some(b) = lock(&self.bridge).take() {
            let _ = b.join();
        }
        if let Some(rt) = lock(&self.runtime).take() {
            let _ = rt.stop();
        }
        if let Some(p) = &self.params {
            if let Err(e) = p.save() {
                tracing::warn!("saving {}: {e}", p.path().display());
            }
        }
        Ok(())
    }
}
