//! The machine state machine: which requests each mode accepts, and why the others are
//! refused.
//!
//! It is a plain value owned by the machine task on the servo thread, so every transition
//! happens at one point in the cycle, in order with motion and safety. Requests come in
//! as [`Request`]s (from commands) and facts as [`Fact`]s (from the monitor and the
//! interpolator); a refused request returns a reason an operator can act on. Safety facts
//! (e-stop, fault) are never refused.

use super::api::Mode;

/// What an operator asks for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Request {
    /// Trip the e-stop (never refused).
    Estop,
    /// Release the e-stop.
    EstopReset,
    /// Enable drives.
    On,
    /// Disable drives.
    Off,
    /// Start homing.
    Home,
    /// Start a jog.
    Jog,
    /// Start a job or an MDI line (needs every axis homed).
    Run,
    /// Feed hold.
    Pause,
    /// Leave feed hold.
    Resume,
    /// Stop what is running under control.
    Abort,
}

/// What the machine reports about itself.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Fact {
    /// The e-stop input is active (or the e-stop chain opened).
    EstopInput,
    /// A fault stopped the machine (following error, drive fault, soft limit, overrun storm,
    /// communication loss).
    Faulted,
    /// Homing finished on all requested axes.
    HomingDone,
    /// The jog, job or MDI line finished or came to rest after an abort.
    MotionDone,
    /// The job reached a program stop (M0, M60, or M1 with optional stop on): it holds,
    /// and `Resume` goes on with the next line (LinuxCNC's pause and cycle start).
    ProgramStop,
}

/// The state machine. `estop_input` mirrors the e-stop input so a reset can be refused
/// while it is still pressed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ModeMachine {
    mode: Mode,
    estop_input: bool,
}

impl Default for ModeMachine {
    fn default() -> Self {
        Self::new()
    }
}

impl ModeMachine {
    /// A machine starts in e-stop: power-up must never move anything.
    pub fn new() -> Self {
        ModeMachine {
            mode: Mode::Estop,
            estop_input: false,
        }
    }

    /// The current mode.
    pub fn mode(&self) -> Mode {
        self.mode
    }

    /// Tracks the e-stop input; an active input forces `Estop`.
    pub fn set_estop_input(&mut self, active: bool) {
        self.estop_input = active;
        if active {
            self.mode = Mode::Estop;
        }
    }

    /// Applies a fact. Facts are never refused; they may be irrelevant in a mode.
    pub fn fact(&mut self, fact: Fact) {
        self.mode = match (fact, self.mode) {
            (Fact::EstopInput, _) => Mode::Estop,
            (Fact::Faulted, Mode::Estop | Mode::Off) => self.mode,
            (Fact::Faulted, _) => Mode::Fault,
            (Fact::HomingDone, Mode::Homing) => Mode::Idle,
            (Fact::MotionDone, Mode::Manual | Mode::Running | Mode::Holding) => Mode::Idle,
            (Fact::ProgramStop, Mode::Running) => Mode::Holding,
            (_, m) => m,
        };
    }

    /// Whether `req` would be accepted in `mode`, changing nothing: the non-realtime side
    /// asks first so that the operator hears about the machine (e-stop, off, not homed)
    /// before anything about a job. The machine task's own `request` stays the authority.
    pub fn check(mode: Mode, req: Request, all_homed: bool) -> Result<(), &'static str> {
        let mut m = ModeMachine {
            mode,
            estop_input: false,
        };
        m.request(req, all_homed).map(|_| ())
    }

    /// Applies a request: `Ok(new mode)` or `Err(reason)`. `all_homed` matters for `Run`.
    pub fn request(&mut self, req: Request, all_homed: bool) -> Result<Mode, &'static str> {
        use Mode as M;
        use Request as R;
        let next = match (req, self.mode) {
            (R::Estop, _) => M::Estop,
            (R::EstopReset, M::Estop) if self.estop_input => {
                return Err("the e-stop input is still active")
            }
            (R::EstopReset, M::Estop) => M::Off,
            (R::EstopReset, _) => return Err("not in e-stop"),
            (_, M::Estop) => return Err("machine is in e-stop: reset it first"),
            (R::On, M::Off | M::Fault) => M::Idle,
            (R::On, _) => return Err("machine is already on"),
            (R::Off, _) => M::Off,
            (_, M::Off) => return Err("machine is off: switch it on first"),
            (_, M::Fault) => return Err("machine is in fault: switch it on again to clear"),
            (R::Home, M::Idle) => M::Homing,
            (R::Jog, M::Idle | M::Manual) => M::Manual,
            (R::Run, M::Idle) if !all_homed => return Err("axes are not homed"),
            (R::Run, M::Idle) => M::Running,
            (R::Pause, M::Running) => M::Holding,
            (R::Pause, M::Holding) => M::Holding,
            (R::Resume, M::Holding) => M::Running,
            (R::Abort, M::Running | M::Holding | M::Manual | M::Homing) => self.mode,
            (R::Abort, M::Idle) => return Err("nothing to abort"),
            (R::Pause | R::Resume, _) => return Err("no job is running"),
            (R::Home | R::Jog | R::Run, _) => return Err("machine is busy"),
        };
        self.mode = next;
        Ok(next)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use Mode as M;
    use Request as R;

    fn on_and_idle() -> ModeMachine {
        let mut m = ModeMachine::new();
        m.request(R::EstopReset, false).unwrap();
        m.request(R::On, false).unwrap();
        m
    }

    #[test]
    fn powers_up_in_estop_and_needs_reset_then_on() {
        let mut m = ModeMachine::new();
        assert_eq!(m.mode(), M::Estop);
        assert_eq!(
            m.request(R::On, true),
            Err("machine is in e-stop: reset it first")
        );
        assert_eq!(m.request(R::EstopReset, true), Ok(M::Off));
        assert!(m.request(R::Run, true).unwrap_err().contains("off"));
        assert_eq!(m.request(R::On, true), Ok(M::Idle));
    }

    #[test]
    fn reset_is_refused_while_the_input_is_pressed() {
        let mut m = on_and_idle();
        m.set_estop_input(true);
        assert_eq!(m.mode(), M::Estop);
        assert_eq!(
            m.request(R::EstopReset, true),
            Err("the e-stop input is still active")
        );
        m.set_estop_input(false);
        assert_eq!(m.request(R::EstopReset, true), Ok(M::Off));
    }

    #[test]
    fn run_needs_homed_axes_and_hold_resume_work() {
        let mut m = on_and_idle();
        assert_eq!(m.request(R::Run, false), Err("axes are not homed"));
        assert_eq!(m.request(R::Home, false), Ok(M::Homing));
        assert_eq!(m.request(R::Run, true), Err("machine is busy"));
        m.fact(Fact::HomingDone);
        assert_eq!(m.request(R::Run, true), Ok(M::Running));
        assert_eq!(m.request(R::Pause, true), Ok(M::Holding));
        assert_eq!(m.request(R::Resume, true), Ok(M::Running));
        m.fact(Fact::MotionDone);
        assert_eq!(m.mode(), M::Idle);
        assert_eq!(m.request(R::Pause, true), Err("no job is running"));
    }

    #[test]
    fn estop_and_faults_are_never_refused() {
        for setup in [R::Home, R::Jog, R::Run] {
            let mut m = on_and_idle();
            m.request(setup, true).unwrap();
            let mut f = m;
            f.fact(Fact::Faulted);
            assert_eq!(f.mode(), M::Fault);
            assert!(f.request(R::Run, true).unwrap_err().contains("fault"));
            assert_eq!(f.request(R::On, true), Ok(M::Idle));
            assert_eq!(m.request(R::Estop, true), Ok(M::Estop));
        }
        let mut m = on_and_idle();
        m.fact(Fact::EstopInput);
        assert_eq!(m.mode(), M::Estop);
    }

    #[test]
    fn check_answers_like_request_and_changes_nothing() {
        for (mode, homed, expected) in [
            (
                Mode::Estop,
                true,
                Err("machine is in e-stop: reset it first"),
            ),
            (Mode::Off, true, Err("machine is off: switch it on first")),
            (Mode::Idle, false, Err("axes are not homed")),
            (Mode::Running, true, Err("machine is busy")),
            (Mode::Idle, true, Ok(())),
        ] {
            assert_eq!(
                ModeMachine::check(mode, Request::Run, homed),
                expected,
                "{mode:?}"
            );
        }
    }

    #[test]
    fn a_program_stop_holds_a_running_job_until_resume() {
        let mut m = on_and_idle();
        m.fact(Fact::ProgramStop);
        assert_eq!(m.mode(), M::Idle, "no job, no stop");
        m.request(R::Run, true).unwrap();
        m.fact(Fact::ProgramStop);
        assert_eq!(m.mode(), M::Holding);
        assert_eq!(m.request(R::Pause, true), Ok(M::Holding));
        assert_eq!(m.request(R::Resume, true), Ok(M::Running));
        m.fact(Fact::ProgramStop);
        assert_eq!(m.request(R::Abort, true), Ok(M::Holding));
        m.fact(Fact::MotionDone);
        assert_eq!(m.mode(), M::Idle);
    }

    #[test]
    fn abort_keeps_the_mode_until_motion_is_done() {
        let mut m = on_and_idle();
        m.request(R::Run, true).unwrap();
        assert_eq!(m.request(R::Abort, true), Ok(M::Running));
        m.fact(Fact::MotionDone);
        assert_eq!(m.mode(), M::Idle);
        assert_eq!(m.request(R::Abort, true), Err("nothing to abort"));
    }
}
