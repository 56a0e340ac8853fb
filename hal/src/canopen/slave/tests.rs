use super::*;
use crate::canopen::cia402::{Command, State402};
use crate::canopen::sdo::{SdoAbortCode, SdoClient, SdoStep};
use crate::canopen::{COB_EMCY, COB_RPDO1, COB_TPDO1};

const MS: Duration = Duration::from_millis(1);

fn n1() -> NodeId {
    NodeId::new(1).unwrap()
}

/// A booted drive and an SDO client to it, talking through direct calls.
struct T {
    s: DriveSlave,
    c: SdoClient,
    now: Duration,
}

impl T {
    fn new(cfg: SlaveConfig) -> T {
        let mut s = DriveSlave::new(n1(), cfg);
        let mut out = Outbox::default();
        s.tick(Duration::ZERO, &mut out);
        assert_eq!(
            out.iter().next().map(|f| (f.id().raw(), f.data()[0])),
            Some((0x701, 0))
        );
        T {
            s,
            c: SdoClient::new(n1()),
            now: Duration::ZERO,
        }
    }

    fn feed(&mut self, f: &CanFrame) -> Vec<CanFrame> {
        let mut out = Outbox::default();
        self.s.on_frame(f, self.now, &mut out);
        out.iter().copied().collect()
    }

    fn sdo(&mut self, mut f: CanFrame) -> SdoStep {
        loop {
            let replies = self.feed(&f);
            let Some(reply) = replies.iter().find(|r| r.id().raw() == 0x581) else {
                panic!("no SDO reply to {f:?}")
            };
            match self.c.on_frame(reply, self.now) {
                SdoStep::Send(next) => f = next,
                done => return done,
            }
        }
    }

    fn write(&mut self, index: u16, sub: u8, d: &[u8]) -> Result<(), SdoAbortCode> {
        let f = self.c.download(index, sub, d, self.now).unwrap();
        match self.sdo(f) {
            SdoStep::Downloaded => Ok(()),
            SdoStep::Failed {
                error: crate::canopen::CanOpenError::SdoAbort { abort, .. },
                ..
            } => Err(abort),
            other => panic!("{other:?}"),
        }
    }

    fn read(&mut self, index: u16, sub: u8) -> Result<Vec<u8>, SdoAbortCode> {
        let f = self.c.upload(index, sub, self.now).unwrap();
        match self.sdo(f) {
            SdoStep::Uploaded(v) => Ok(v),
            SdoStep::Failed {
                error: crate::canopen::CanOpenError::SdoAbort { abort, .. },
                ..
            } => Err(abort),
            other => panic!("{other:?}"),
        }
    }

    fn cw(&mut self, cmd: Command) {
        self.write(0x6040, 0, &cmd.controlword().to_le_bytes())
            .unwrap();
    }

    fn state(&self) -> State402 {
        State402::from_statusword(self.s.statusword())
    }

    fn enable(&mut self, mode: i8) {
        self.write(0x6060, 0, &[mode as u8]).unwrap();
        for c in [
            Command::Shutdown,
            Command::SwitchOn,
            Command::EnableOperation,
        ] {
            self.cw(c);
        }
        assert_eq!(self.state(), State402::OperationEnabled);
    }

    fn start(&mut self) {
        self.feed(&NmtCommand::Start.frame(Some(n1())));
    }

    fn sync(&mut self) -> Vec<CanFrame> {
        self.now += MS;
        self.feed(&crate::canopen::sync::SyncProducer::new().next_frame())
    }
}

#[test]
fn od_refuses_with_the_right_abort_codes() {
    let mut t = T::new(SlaveConfig::default());
    assert_eq!(t.write(0x1000, 0, &[0; 4]), Err(SdoAbortCode::ReadOnly));
    assert_eq!(t.read(0x1234, 0), Err(SdoAbortCode::ObjectDoesNotExist));
    assert_eq!(t.read(0x1018, 9), Err(SdoAbortCode::SubIndexDoesNotExist));
    assert_eq!(
        t.write(0x6040, 0, &[1, 2, 3]),
        Err(SdoAbortCode::LengthTooHigh)
    );
    assert_eq!(t.write(0x6040, 0, &[1]), Err(SdoAbortCode::LengthTooLow));
    assert_eq!(
        t.write(0x6060, 0, &[3]),
        Err(SdoAbortCode::InvalidValue),
        "PV unsupported"
    );
    assert_eq!(t.read(0x6502, 0).unwrap(), 0xA1u32.to_le_bytes());
}

#[test]
fn pdo_mapping_follows_the_cia301_rules() {
    let mut t = T::new(SlaveConfig::default());
    // RPDO1 is valid by default: its mapping is locked.
    assert_eq!(
        t.write(0x1600, 0, &[0]),
        Err(SdoAbortCode::CannotStoreDeviceState)
    );
    assert_eq!(
        t.write(0x1400, 1, &0x181u32.to_le_bytes()),
        Err(SdoAbortCode::InvalidValue)
    );
    t.write(0x1400, 1, &(0x201u32 | 0x8000_0000).to_le_bytes())
        .unwrap();
    // Entries only while the count is 0.
    assert_eq!(
        t.write(0x1600, 1, &0x607A_0020u32.to_le_bytes()),
        Err(SdoAbortCode::CannotStoreDeviceState)
    );
    t.write(0x1600, 0, &[0]).unwrap();
    assert_eq!(
        t.write(0x1600, 1, &0x6041_0010u32.to_le_bytes()),
        Err(SdoAbortCode::NotMappable),
        "statusword is not an RPDO object"
    );
    assert_eq!(
        t.write(0x1600, 1, &0x607A_0010u32.to_le_bytes()),
        Err(SdoAbortCode::NotMappable),
        "wrong length"
    );
    for (i, e) in [0x607A_0020u32, 0x60FF_0020, 0x6040_0010]
        .iter()
        .enumerate()
    {
        t.write(0x1600, i as u8 + 1, &e.to_le_bytes()).unwrap();
    }
    assert_eq!(
        t.write(0x1600, 0, &[3]),
        Err(SdoAbortCode::PdoLengthExceeded)
    );
    t.write(0x1600, 0, &[2]).unwrap();
    t.write(0x1400, 1, &0x201u32.to_le_bytes()).unwrap();
    assert_eq!(t.read(0x1600, 0).unwrap(), [2]);
}

#[test]
fn nmt_gates_pdos_and_resets_reboot() {
    let mut t = T::new(SlaveConfig::default());
    assert!(t.sync().is_empty(), "no TPDO in pre-operational");
    t.start();
    let out = t.sync();
    assert_eq!(out.len(), 1);
    assert_eq!(out[0].id().raw(), u32::from(COB_TPDO1) + 1);
    assert_eq!(out[0].data(), &t.s.statusword().to_le_bytes());
    t.feed(&NmtCommand::Stop.frame(None));
    assert!(t.sync().is_empty());
    assert_eq!(t.s.nmt_state(), Some(NmtState::Stopped));
    t.feed(&NmtCommand::EnterPreOperational.frame(None));
    t.write(0x1017, 0, &50u16.to_le_bytes()).unwrap();
    let out = t.feed(&NmtCommand::ResetCommunication.frame(Some(n1())));
    assert_eq!(out[0].data(), &[0], "boot-up");
    assert_eq!(
        t.read(0x1017, 0).unwrap(),
        [0, 0],
        "communication parameters reset"
    );
    t.write(0x6060, 0, &[8]).unwrap();
    t.feed(&NmtCommand::ResetNode.frame(None));
    assert_eq!(t.read(0x6061, 0).unwrap(), [0], "application reset");
}

#[test]
fn heartbeat_follows_0x1017_and_can_be_stopped() {
    let mut t = T::new(SlaveConfig {
        heartbeat_ms: 10,
        ..SlaveConfig::default()
    });
    let count = |t: &mut T, ms: u64| {
        let mut n = 0;
        for _ in 0..ms {
            t.now += MS;
            let mut out = Outbox::default();
            t.s.tick(t.now, &mut out);
            n += out.iter().filter(|f| f.id().raw() == 0x701).count();
        }
        n
    };
    assert_eq!(count(&mut t, 100), 10);
    t.write(od::INJECT, 2, &[1]).unwrap();
    assert_eq!(count(&mut t, 100), 0);
    t.write(od::INJECT, 2, &[0]).unwrap();
    assert_eq!(count(&mut t, 100), 10);
}

#[test]
fn quick_stop_brakes_then_disable_voltage_leaves() {
    let mut t = T::new(SlaveConfig::default());
    t.start();
    t.enable(8);
    for k in 1..=50 {
        t.write(0x607A, 0, &(k * 100i32).to_le_bytes()).unwrap();
        t.sync();
    }
    t.cw(Command::QuickStop);
    assert_eq!(t.state(), State402::QuickStopActive);
    for _ in 0..100 {
        t.sync();
    }
    let p = t.s.position();
    t.sync();
    assert_eq!(t.s.position(), p, "stopped");
    t.cw(Command::EnableOperation);
    assert_eq!(
        t.state(),
        State402::QuickStopActive,
        "stays until disable voltage"
    );
    t.cw(Command::DisableVoltage);
    assert_eq!(t.state(), State402::SwitchOnDisabled);
}

#[test]
fn following_error_faults_with_emcy_and_fault_reset_clears_it() {
    let mut t = T::new(SlaveConfig::default());
    t.start();
    t.write(0x6065, 0, &100u32.to_le_bytes()).unwrap();
    t.enable(8);
    // A 10 000 count step: the loop cannot follow, the window is 100.
    t.write(0x607A, 0, &10_000i32.to_le_bytes()).unwrap();
    let out = t.sync();
    let emcy = out
        .iter()
        .find(|f| f.id().raw() == u32::from(COB_EMCY) + 1)
        .expect("EMCY");
    assert_eq!(&emcy.data()[..3], &[0x11, 0x86, 0x21]);
    assert!(t.s.statusword() & crate::canopen::cia402::SW_OP_MODE_13 != 0);
    for _ in 0..200 {
        t.sync();
    }
    assert_eq!(t.state(), State402::Fault);
    t.cw(Command::DisableVoltage);
    let f =
        t.c.download(0x6040, 0, &0x80u16.to_le_bytes(), t.now)
            .unwrap();
    let replies = t.feed(&f);
    assert!(
        replies
            .iter()
            .any(|r| r.id().raw() == 0x81 && r.data()[..3] == [0, 0, 0]),
        "EMCY error reset"
    );
    assert_eq!(t.state(), State402::SwitchOnDisabled);
}

#[test]
fn rpdo_applies_at_sync_and_short_rpdo_is_reported() {
    let mut t = T::new(SlaveConfig::default());
    t.start();
    let cob = crate::canopen::cob_id(COB_RPDO1 + 1);
    t.feed(&crate::canopen::frame(
        cob,
        &Command::Shutdown.controlword().to_le_bytes(),
    ));
    assert_eq!(
        t.state(),
        State402::SwitchOnDisabled,
        "synchronous RPDO waits for SYNC"
    );
    t.sync();
    assert_eq!(t.state(), State402::ReadyToSwitchOn);
    let out = t.feed(&crate::canopen::frame(cob, &[6]));
    assert_eq!(out[0].id().raw(), 0x81);
    assert_eq!(
        &out[0].data()[..2],
        &[0x10, 0x82],
        "EMCY 0x8210 PDO length error"
    );
}

#[test]
fn profile_position_and_homing_on_current_position() {
    let mut t = T::new(SlaveConfig::default());
    t.start();
    t.enable(1);
    t.write(0x607A, 0, &3000i32.to_le_bytes()).unwrap();
    t.write(0x6040, 0, &0x1Fu16.to_le_bytes()).unwrap();
    for _ in 0..20 {
        t.now += Duration::from_millis(10);
        let mut out = Outbox::default();
        t.s.tick(t.now, &mut out);
    }
    assert_eq!(t.s.position(), 3000, "PP move free-runs without SYNC");
    assert!(t.s.statusword() & crate::canopen::cia402::SW_TARGET_REACHED != 0);
    t.write(0x6060, 0, &[6]).unwrap();
    t.write(0x6098, 0, &[37]).unwrap();
    t.write(0x6040, 0, &0x0Fu16.to_le_bytes()).unwrap();
    t.write(0x6040, 0, &0x1Fu16.to_le_bytes()).unwrap();
    assert_eq!(t.s.position(), 0);
    assert!(
        t.s.statusword() & crate::canopen::cia402::SW_OP_MODE_12 != 0,
        "homing attained"
    );
    t.write(0x6098, 0, &[1]).unwrap();
    t.write(0x6040, 0, &0x0Fu16.to_le_bytes()).unwrap();
    t.write(0x6040, 0, &0x1Fu16.to_le_bytes()).unwrap();
    assert!(
        t.s.statusword() & crate::canopen::cia402::SW_OP_MODE_13 != 0,
        "method 1 (index pulse) is not modelled: homing error"
    );
}

impl T {
    /// Homing mode, method `method` with home offset `offset`, started by a rising bit 4;
    /// free-runs (no SYNC) until homing attained or error. Returns the statusword.
    fn home(&mut self, method: i8, offset: i32) -> u16 {
        use crate::canopen::cia402::{SW_OP_MODE_12, SW_OP_MODE_13, SW_TARGET_REACHED};
        self.write(0x6060, 0, &[6]).unwrap();
        assert_eq!(self.read(0x6061, 0).unwrap(), vec![6], "mode confirmed");
        self.write(0x6098, 0, &[method as u8]).unwrap();
        self.write(0x607C, 0, &offset.to_le_bytes()).unwrap();
        self.write(0x6040, 0, &0x0Fu16.to_le_bytes()).unwrap();
        self.write(0x6040, 0, &0x1Fu16.to_le_bytes()).unwrap();
        for _ in 0..20_000 {
            let sw = self.s.statusword();
            let done = sw & SW_OP_MODE_12 != 0 && sw & SW_TARGET_REACHED != 0;
            if done || sw & SW_OP_MODE_13 != 0 {
                return sw;
            }
            self.now += MS;
            let mut out = Outbox::default();
            self.s.tick(self.now, &mut out);
        }
        panic!("homing method {method} did not end")
    }
}

#[test]
fn homing_on_the_home_switch_and_the_limit_switches_with_speeds_and_offset() {
    use crate::canopen::cia402::SW_OP_MODE_13;
    let mut t = T::new(SlaveConfig::default());
    t.start();
    t.enable(6);
    // Home switch at motor count 5000, active above; search 50000/s, back-off 1000/s.
    t.write(od::SWITCHES, 1, &5000i32.to_le_bytes()).unwrap();
    t.write(0x6099, 1, &50_000u32.to_le_bytes()).unwrap();
    t.write(0x6099, 2, &1000u32.to_le_bytes()).unwrap();
    t.write(0x609A, 0, &1_000_000u32.to_le_bytes()).unwrap();
    assert_eq!(t.read(0x6099, 0).unwrap(), vec![2]);
    let sw = t.home(19, 100);
    assert_eq!(sw & SW_OP_MODE_13, 0, "no homing error");
    // Home = the switch edge (motor 5000) is position 100 now; the drive stopped within
    // its back-off deceleration of the edge.
    let p = t.s.position();
    assert!((p - 100).abs() <= 2, "at {p}");
    // Method 21 (switch active below) homes on the same edge from the other side.
    let sw = t.home(21, -7);
    assert_eq!(sw & SW_OP_MODE_13, 0);
    assert!((t.s.position() + 7).abs() <= 2, "at {}", t.s.position());
    // Method 17: the negative limit switch at motor -20000.
    t.write(od::SWITCHES, 2, &(-20_000i32).to_le_bytes())
        .unwrap();
    let sw = t.home(17, 0);
    assert_eq!(sw & SW_OP_MODE_13, 0);
    assert!(t.s.position().abs() <= 2);
    // Method 18 with the positive limit beyond reach of a home switch search: method 20
    // (home switch) with the switch outside the limits runs into the limit: homing error.
    t.write(od::SWITCHES, 1, &300_000i32.to_le_bytes()).unwrap();
    t.write(od::SWITCHES, 3, &30_000i32.to_le_bytes()).unwrap();
    let sw = t.home(20, 0);
    assert_ne!(sw & SW_OP_MODE_13, 0, "limit switch before the home switch");
    let sw = t.home(18, 0);
    assert_eq!(sw & SW_OP_MODE_13, 0, "method 18 homes on that limit");
}

impl T {
    /// A transfer of any kind to its end: frames to the drive one per call, time passing
    /// (a tick per ms) when none is queued, so a block upload's sub-block goes out over
    /// several calls as the outbox allows. Returns the final step and the largest number
    /// of frames one call produced.
    fn transfer(&mut self, first: CanFrame) -> (SdoStep, usize) {
        let mut to_slave = std::collections::VecDeque::from([first]);
        let mut widest = 0;
        let mut done = None;
        for _ in 0..10_000 {
            let mut out = Outbox::default();
            match to_slave.pop_front() {
                Some(f) => self.s.on_frame(&f, self.now, &mut out),
                None if done.is_some() => return (done.unwrap_or(SdoStep::Ignored), widest),
                None => {
                    self.now += MS;
                    self.s.tick(self.now, &mut out);
                }
            }
            widest = widest.max(out.len());
            for r in out.iter().filter(|r| r.id().raw() == 0x581) {
                match self.c.on_frame(r, self.now) {
                    SdoStep::Ignored => {}
                    SdoStep::Send(f) => to_slave.push_back(f),
                    SdoStep::SendBlock(v) => to_slave.extend(v),
                    SdoStep::BlockUploaded { value, confirm } => {
                        to_slave.push_back(confirm);
                        done = Some(SdoStep::Uploaded(value));
                    }
                    other => done = Some(other),
                }
            }
        }
        panic!("transfer did not end")
    }
}

#[test]
fn the_domain_object_goes_by_block_transfer_both_ways() {
    let mut t = T::new(SlaveConfig::default());
    let f = t.c.upload_block(od::DOMAIN, 0, t.now).unwrap();
    let (step, widest) = t.transfer(f);
    assert_eq!(step, SdoStep::Uploaded(od::domain_default()));
    assert!(
        widest < OUTBOX,
        "the burst is paced: {widest} frames in one call"
    );
    let value: Vec<u8> = (0..2000u32).map(|i| (i % 251) as u8).collect();
    let f = t.c.download(od::DOMAIN, 0, &value, t.now).unwrap();
    assert_eq!(f.data()[0] >> 5, 6, "block download");
    assert_eq!(t.transfer(f).0, SdoStep::Downloaded);
    assert_eq!(t.read(od::DOMAIN, 0).unwrap(), value, "read back segmented");
    let f = t.c.download(od::DOMAIN, 0, &[0; 5000], t.now).unwrap();
    assert!(matches!(
        t.transfer(f).0,
        SdoStep::Failed {
            error: crate::canopen::CanOpenError::SdoAbort {
                abort: SdoAbortCode::LengthTooHigh,
                ..
            },
            ..
        }
    ));
}
