//! Ctrl-C for the commands that drive motion (`run`, and `home`/`mdi`/`jog` while they
//! wait): SIGINT is counted instead of killing the process, so the command can stop the
//! machine under control (feed hold, then abort) and report, rather than vanish with the
//! axes still moving on the daemon. The command's loops look at the count between events.

use anyhow::Context;
use std::sync::atomic::{AtomicU32, Ordering};

/// SIGINTs received since [`Interrupts::install`].
static PRESSES: AtomicU32 = AtomicU32::new(0);

extern "C" fn on_sigint(_: libc::c_int) {
    PRESSES.fetch_add(1, Ordering::AcqRel);
}

/// Counts Ctrl-C presses; [`take`](Interrupts::take) returns those not yet handled.
pub struct Interrupts {
    handled: u32,
}

impl Interrupts {
    /// Installs the counting SIGINT handler. Without SA_RESTART a blocked socket read
    /// returns early (the client retries it), so a press is noticed within one read timeout.
    pub fn install() -> anyhow::Result<Interrupts> {
        use nix::sys::signal::{sigaction, SaFlags, SigAction, SigHandler, SigSet, Signal};
        let act = SigAction::new(
            SigHandler::Handler(on_sigint),
            SaFlags::empty(),
            SigSet::empty(),
        );
        // SAFETY: the handler only adds to an atomic, which is async-signal-safe.
        unsafe { sigaction(Signal::SIGINT, &act) }.context("installing the Ctrl-C handler")?;
        Ok(Interrupts {
            handled: PRESSES.load(Ordering::Acquire),
        })
    }

    /// Presses since the last call.
    pub fn take(&mut self) -> u32 {
        let now = PRESSES.load(Ordering::Acquire);
        let new = now.wrapping_sub(self.handled);
        self.handled = now;
        new
    }

    /// From now on Ctrl-C kills the process again: the way out when the controlled stop
    /// itself hangs (a daemon that no longer answers).
    pub fn restore_default(&self) {
        use nix::sys::signal::{signal, SigHandler, Signal};
        // SAFETY: restoring the default disposition installs no handler code.
        let _ = unsafe { signal(Signal::SIGINT, SigHandler::SigDfl) };
    }
}

/// Exit code of a command stopped by Ctrl-C (128 + SIGINT, as shells report it).
pub const EXIT_INTERRUPTED: u8 = 130;
