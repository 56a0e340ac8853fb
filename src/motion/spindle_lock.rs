//! Position-locked spindle synchronisation (G33, G76 passes, G33.1 rigid tapping), as
//! LinuxCNC's motion does it: the move waits for the spindle's index pulse, then its
//! progress along the path follows the *measured* spindle position,
//! `s = pitch × (revs − revs_at_index)`, not the commanded speed. Because every pass of a
//! thread starts on the index, every pass cuts the same groove, whatever the spindle's
//! actual speed (its ramp, its load ripple) does meanwhile.
//!
//! [`SpindleLock`] is the per-cycle follower of one synchronised move: no allocation, no
//! lock, constant work per [`step`](SpindleLock::step), so it can run in the servo cycle.
//! The axis starts from rest when the index comes, so it lags the spindle while it
//! accelerates; it then catches up (faster than the sync speed, within the axis limits)
//! until the lag is gone, as LinuxCNC's position sync does. Near the end of a G33 move it
//! stops within the acceleration limit (the thread's run-out).
//!
//! Limits: the follower never exceeds the velocity and acceleration it is given. When the
//! spindle turns so fast that the sync speed (pitch × rev/s) is above the velocity limit the
//! axis could never keep up; LinuxCNC then silently cuts a wrong thread (its motion only
//! warns). hytask stops the move with [`LockError::SpindleTooFast`], naming both speeds:
//! a scrapped thread is worse than a stopped job.
//!
//! Rigid tapping ([`LockMode::RigidTap`]): the follower asks for the spindle to reverse
//! when the tap reaches the depth, keeps following through the spindle's deceleration (the
//! tap overruns the depth by what the spindle turns while it stops, as in LinuxCNC) and
//! follows it back out, so the tap leaves in the thread it cut; once the spindle position
//! is back at the start, the axis stops at the start point.

use super::interpolator::discrete_brake_speed;

/// One servo cycle's reading of the spindle encoder.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SpindleSample {
    /// Position in revolutions since start-up (signed: M4 counts down).
    pub revs: f64,
    /// Speed in revolutions per second (signed).
    pub rps: f64,
    /// The index pulse came during this cycle, at revolution [`index_at`](Self::index_at).
    pub index: bool,
    /// Revolution count at the index pulse (an integer), valid when `index`.
    pub index_at: f64,
}

/// What kind of synchronised move.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LockMode {
    /// G33 / a G76 pass: follow the spindle to the end of the move, then stop.
    Thread,
    /// G33.1: follow in to the depth, reverse the spindle, follow out to the start.
    RigidTap,
}

/// Why a synchronised move stopped.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum LockError {
    /// The spindle turns too fast for the axis to follow at the programmed pitch.
    #[error(
        "spindle-synchronised move: the spindle at {rpm:.0} rpm needs {needed:.2} mm/s along \
         the move (pitch {pitch} mm/rev), the axes allow {max:.2} mm/s; lower S or the pitch"
    )]
    SpindleTooFast {
        /// Measured spindle speed.
        rpm: f64,
        /// Sync speed along the path.
        needed: f64,
        /// Velocity limit along the path.
        max: f64,
        /// Pitch along the path, mm per revolution.
        pitch: f64,
    },
    /// Rigid tapping with a stopped spindle (it would wait for an index forever).
    #[error("rigid tapping / threading needs the spindle turning (M3/M4 with S > 0)")]
    SpindleStopped,
    /// Rigid tapping on a machine without a spindle position (encoder): it cannot reverse
    /// with the spindle.
    #[error(
        "rigid tapping (G33.1) needs a spindle position (encoder with index); this machine \
         has none"
    )]
    NoSpindlePosition,
}

/// Where the follower is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LockPhase {
    /// At rest at the start, waiting for the index pulse.
    WaitIndex,
    /// Following the spindle in (toward the end of the move).
    In,
    /// Rigid tap: spindle reversal requested, following it through the stop and back out.
    Out,
    /// Rigid tap: back at the start of the thread; stopping at the start point.
    Park,
    /// The move is over (at rest).
    Done,
}

/// The result of one cycle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LockStep {
    /// Distance along the move from its start, mm.
    pub s: f64,
    /// Velocity along the move, mm/s.
    pub v: f64,
    /// Rigid tap: the spindle must reverse now (set once, in the cycle the depth is reached).
    pub reverse_spindle: bool,
    /// The move is finished.
    pub done: bool,
}

/// The follower of one synchronised move of `length` mm at `pitch` mm per revolution along
/// the path. See the module documentation.
#[derive(Debug, Clone)]
pub struct SpindleLock {
    mode: LockMode,
    pitch: f64,
    length: f64,
    vmax: f64,
    amax: f64,
    phase: LockPhase,
    /// Revolution at the index that started the move, and the spindle direction then.
    rev0: f64,
    dir: f64,
    s: f64,
    v: f64,
}

impl SpindleLock {
    /// A move of `length` mm (> 0) at `pitch` mm/rev (> 0), with velocity and acceleration
    /// limits along the path (`vmax`, `amax` > 0).
    pub fn new(mode: LockMode, pitch: f64, length: f64, vmax: f64, amax: f64) -> SpindleLock {
        SpindleLock {
            mode,
            pitch,
            length,
            vmax,
            amax,
            phase: LockPhase::WaitIndex,
            rev0: 0.0,
            dir: 1.0,
            s: 0.0,
            v: 0.0,
        }
    }

    /// A thread move that continues the synchronisation of the one that just ended at this
    /// point, without waiting for the index (G76's exit taper after its thread, consecutive
    /// G33 lines), as LinuxCNC's motion keeps one synchronisation across consecutive
    /// synchronised moves: `rev0` is the revolution at which the previous move's target
    /// reached its end, `dir` its spindle direction. The axis starts from rest, lags the
    /// spindle and catches up as after an index, so the groove goes on in phase instead of
    /// the tool dwelling in the cut for up to a revolution.
    pub fn continuing(
        pitch: f64,
        length: f64,
        vmax: f64,
        amax: f64,
        rev0: f64,
        dir: f64,
    ) -> SpindleLock {
        SpindleLock {
            phase: LockPhase::In,
            rev0,
            dir,
            ..SpindleLock::new(LockMode::Thread, pitch, length, vmax, amax)
        }
    }

    /// The revolution at which a thread move's target reaches its end, and the spindle
    /// direction: where a [`continuing`](Self::continuing) move takes over.
    pub fn end_revolution(&self) -> (f64, f64) {
        (self.rev0 + self.dir * self.length / self.pitch, self.dir)
    }

    /// Thread or rigid tap.
    pub fn mode(&self) -> LockMode {
        self.mode
    }

    /// The current phase.
    pub fn phase(&self) -> LockPhase {
        self.phase
    }

    /// Where the spindle position says the tool should be (mm along the move), once locked.
    pub fn target(&self, sp: &SpindleSample) -> f64 {
        self.pitch * self.dir * (sp.revs - self.rev0)
    }

    /// Advances one servo period `dt` with this cycle's spindle reading.
    pub fn step(&mut self, dt: f64, sp: &SpindleSample) -> Result<LockStep, LockError> {
        let mut reverse_spindle = false;
        match self.phase {
            LockPhase::WaitIndex => {
                if sp.rps == 0.0 && !sp.index {
                    return Err(LockError::SpindleStopped);
                }
                if sp.index {
                    self.rev0 = sp.index_at;
                    self.dir = if sp.rps < 0.0 { -1.0 } else { 1.0 };
                    self.phase = LockPhase::In;
                    self.follow(dt, sp, self.end(), None)?;
                }
            }
            LockPhase::In => {
                self.follow(dt, sp, self.end(), None)?;
                match self.mode {
                    LockMode::Thread if self.s >= self.length - 1e-9 && self.v <= 1e-9 => {
                        self.s = self.length;
                        self.v = 0.0;
                        self.phase = LockPhase::Done;
                    }
                    LockMode::RigidTap if self.target(sp) >= self.length => {
                        reverse_spindle = true;
                        self.phase = LockPhase::Out;
                    }
                    _ => {}
                }
            }
            LockPhase::Out => {
                // Braking into the start point, not past it (the start may be at a limit).
                self.follow(dt, sp, None, Some(0.0))?;
                if self.target(sp) <= 0.0 && self.s <= 1e-6 {
                    self.phase = LockPhase::Park;
                }
            }
            LockPhase::Park => {
                // Back to the start point (a few µm at most) and to rest.
                let v_des = -self.s.signum() * (2.0 * self.amax * self.s.abs()).sqrt();
                let inside = self.s >= 0.0;
                self.slew(dt, v_des);
                if inside {
                    // Never past the start point (it may be at a soft limit).
                    self.s = self.s.max(0.0);
                }
                if self.s.abs() <= self.amax * dt * dt && self.v.abs() <= self.amax * dt {
                    self.s = 0.0;
                    self.v = 0.0;
                    self.phase = LockPhase::Done;
                }
            }
            LockPhase::Done => {}
        }
        Ok(LockStep {
            s: self.s,
            v: self.v,
            reverse_spindle,
            done: self.phase == LockPhase::Done,
        })
    }

    /// Where the axis must stop while following in: the end of a thread; none for a tap
    /// (it overruns the depth while the spindle stops).
    fn end(&self) -> Option<f64> {
        match self.mode {
            LockMode::Thread => Some(self.length),
            LockMode::RigidTap => None,
        }
    }

    /// One cycle of following the spindle position: feed-forward of the spindle speed plus a
    /// correction of the lag (fastest approach that can still stop at half the acceleration,
    /// linear near zero), limited in velocity, in acceleration, and (with `end`, going in;
    /// with `start`, coming out) so that the axis can stop there.
    fn follow(
        &mut self,
        dt: f64,
        sp: &SpindleSample,
        end: Option<f64>,
        start: Option<f64>,
    ) -> Result<(), LockError> {
        let v_sync = self.pitch * self.dir * sp.rps;
        if v_sync.abs() > self.vmax {
            return Err(LockError::SpindleTooFast {
                rpm: sp.rps.abs() * 60.0,
                needed: v_sync.abs(),
                max: self.vmax,
                pitch: self.pitch,
            });
        }
        let err = self.target(sp) - self.s;
        let a_c = 0.5 * self.amax;
        let corr = err.signum() * (2.0 * a_c * err.abs()).sqrt().min(err.abs() / (4.0 * dt));
        let mut v_des = (v_sync + corr).clamp(-self.vmax, self.vmax);
        // Braking toward the end (going in) or the start (coming out) in whole servo periods
        // at 80 % of the acceleration, counting this period's trapezoid: the slew can always
        // follow it, so the axis stops on the point without being clamped onto it (a clamp
        // is a velocity step: the exit taper of a G76 thread braked at 1.9× the limit).
        let a_brake = 0.8 * self.amax;
        if let Some(end) = end {
            let room = end - self.s - self.v.max(0.0) * dt / 2.0;
            v_des = v_des.min(discrete_brake_speed(room, a_brake, dt));
        }
        if let Some(start) = start {
            let room = self.s - start - (-self.v).max(0.0) * dt / 2.0;
            v_des = v_des.max(-discrete_brake_speed(room, a_brake, dt));
        }
        self.slew(dt, v_des);
        if let Some(end) = end {
            if self.s > end {
                self.s = end;
            }
        }
        if let Some(start) = start {
            self.s = self.s.max(start);
        }
        Ok(())
    }

    /// Moves the velocity toward `v_des` within the acceleration limit and integrates.
    fn slew(&mut self, dt: f64, v_des: f64) {
        let dv = (v_des - self.v).clamp(-self.amax * dt, self.amax * dt);
        let v0 = self.v;
        self.v += dv;
        self.s += 0.5 * (v0 + self.v) * dt;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn turning(revs: f64, rps: f64) -> SpindleSample {
        SpindleSample {
            revs,
            rps,
            index: false,
            index_at: 0.0,
        }
    }

    #[test]
    fn waits_at_rest_for_the_index() {
        let mut l = SpindleLock::new(LockMode::Thread, 1.0, 10.0, 50.0, 500.0);
        let st = l.step(0.001, &turning(0.3, 10.0)).unwrap();
        assert_eq!((st.s, st.v, l.phase()), (0.0, 0.0, LockPhase::WaitIndex));
        assert_eq!(
            l.step(0.001, &turning(0.3, 0.0)),
            Err(LockError::SpindleStopped)
        );
    }

    #[test]
    fn a_spindle_too_fast_for_the_axis_is_an_error_naming_both_speeds() {
        let mut l = SpindleLock::new(LockMode::Thread, 2.0, 10.0, 50.0, 500.0);
        let sp = SpindleSample {
            revs: 1.0,
            rps: 30.0,
            index: true,
            index_at: 1.0,
        };
        let e = l.step(0.001, &sp).unwrap_err();
        let text = e.to_string();
        assert!(
            text.contains("1800 rpm") && text.contains("60.00 mm/s"),
            "{text}"
        );
        assert!(text.contains("50.00 mm/s"), "{text}");
    }
}
