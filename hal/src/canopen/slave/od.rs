//! The loopback drive's object dictionary: values as little-endian bytes for the SDO
//! server, PDO parameters with the CiA 301 rules (mapping only while the PDO is disabled and
//! its count is 0, mappable objects only, at most 8 bytes), and the fault-injection objects.

use super::super::emcy::Emergency;
use super::super::pdo::{MappedObject, COB_INVALID};
use super::super::sdo::{ObjectAccess, SdoAbortCode};
use super::super::{NodeId, Outbox};
use super::drive::{Drive, MODE_CSP, MODE_HM, MODE_PP};
use super::SlaveConfig;

/// Fault injection (manufacturer area): sub 1 = write an error code to raise a drive fault
/// with it; sub 2 = write 1 to stop the heartbeat, 0 to resume; sub 3 = write an error code
/// to send an EMCY without a fault.
pub const INJECT: u16 = 0x2000;
/// A read/write domain (manufacturer area) for block transfers: any length up to
/// [`DOMAIN_MAX`]; initially [`domain_default`].
pub const DOMAIN: u16 = 0x2001;
/// The longest value [`DOMAIN`] stores.
pub const DOMAIN_MAX: usize = 4096;

/// The initial content of [`DOMAIN`]: 1000 bytes, `i * 7 + 3` (mod 256), so a reader can
/// check every byte without knowing more.
pub fn domain_default() -> Vec<u8> {
    // Cannot truncate: the value is taken mod 256 on purpose.
    (0..1000usize).map(|i| (i * 7 + 3) as u8).collect()
}

/// The simulated switches, motor counts (i32): sub 1 = home switch (active at and above it
/// for homing methods 19/20, at and below for 21/22), sub 2 = negative limit switch
/// (method 17), sub 3 = positive limit switch (method 18).
pub const SWITCHES: u16 = 0x2002;

/// Device name (0x1008), long enough to need a segmented upload.
pub const DEVICE_NAME: &str = "hytask loopback CiA 402 drive";
/// Device type 0x1000: CiA 402 profile, servo drive.
pub const DEVICE_TYPE: u32 = 0x0002_0192;
/// Vendor id in 0x1018:1 (none assigned: a test device).
pub const VENDOR_ID: u32 = 0;
/// Product code in 0x1018:2 ("HYT1").
pub const PRODUCT_CODE: u32 = 0x4859_5431;

/// Communication + mapping parameters of one PDO.
#[derive(Debug, Clone, Copy)]
pub(crate) struct PdoParams {
    pub(crate) cob: u32,
    pub(crate) transmission: u8,
    pub(crate) inhibit: u16,
    pub(crate) event_timer: u16,
    pub(crate) count: u8,
    pub(crate) map: [u32; 8],
}

impl PdoParams {
    fn new(cob: u32, transmission: u8, first: Option<MappedObject>) -> PdoParams {
        let mut map = [0; 8];
        if let Some(m) = first {
            map[0] = m.raw();
        }
        PdoParams {
            cob,
            transmission,
            inhibit: 0,
            event_timer: 0,
            count: u8::from(first.is_some()),
            map,
        }
    }

    pub(crate) fn valid(&self) -> bool {
        self.cob & COB_INVALID == 0
    }

    pub(crate) fn entries(&self) -> impl Iterator<Item = MappedObject> + '_ {
        self.map[..usize::from(self.count.min(8))]
            .iter()
            .map(|&r| MappedObject::from_raw(r))
    }

    pub(crate) fn data_len(&self) -> usize {
        self.entries().map(|e| usize::from(e.bits / 8)).sum()
    }
}

/// Bits of a mappable object in direction `rx` (RPDO), `None` when it cannot be mapped.
fn mappable_bits(index: u16, sub: u8, rx: bool) -> Option<u8> {
    if sub != 0 {
        return None;
    }
    match (index, rx) {
        (0x6040, true) | (0x6041, false) | (0x603F, false) => Some(16),
        (0x607A | 0x60FF, true) | (0x6064 | 0x606C, false) => Some(32),
        (0x6060, true) | (0x6061, false) => Some(8),
        _ => None,
    }
}

/// Everything the SDO server and the PDOs read and write.
#[derive(Debug, Clone)]
pub(crate) struct Core {
    pub(crate) node: NodeId,
    pub(crate) cfg: SlaveConfig,
    pub(crate) drive: Drive,
    pub(crate) heartbeat_ms: u16,
    pub(crate) heartbeat_changed: bool,
    pub(crate) heartbeat_stopped: bool,
    pub(crate) rpdo: [PdoParams; 4],
    pub(crate) tpdo: [PdoParams; 4],
    /// Frames produced by object writes (EMCY), sent by the slave after the write.
    pub(crate) pending: Outbox<8>,
    /// The value of [`DOMAIN`] (capacity [`DOMAIN_MAX`], reserved once).
    pub(crate) domain: Vec<u8>,
    /// Where a refused write reads the object to tell read-only from missing (capacity
    /// reserved once; the values that land there are at most 8 bytes).
    scratch: Vec<u8>,
}

impl Core {
    pub(crate) fn new(node: NodeId, cfg: SlaveConfig) -> Core {
        let mut c = Core {
            node,
            cfg,
            drive: Drive::new(),
            heartbeat_ms: cfg.heartbeat_ms,
            heartbeat_changed: true,
            heartbeat_stopped: false,
            rpdo: [PdoParams::new(0, 0, None); 4],
            tpdo: [PdoParams::new(0, 0, None); 4],
            pending: Outbox::default(),
            domain: {
                let mut d = Vec::with_capacity(DOMAIN_MAX);
                d.extend(domain_default());
                d
            },
            scratch: Vec::with_capacity(64),
        };
        c.reset_communication();
        c
    }

    /// Communication parameters to their defaults: RPDO1 = controlword, TPDO1 =
    /// statusword (both on every SYNC), the other PDOs disabled, heartbeat from the config.
    pub(crate) fn reset_communication(&mut self) {
        let n = u32::from(self.node.get());
        for k in 0..4u32 {
            self.rpdo[k as usize] = PdoParams::new((0x200 + 0x100 * k + n) | COB_INVALID, 1, None);
            self.tpdo[k as usize] = PdoParams::new((0x180 + 0x100 * k + n) | COB_INVALID, 1, None);
        }
        self.rpdo[0] = PdoParams::new(0x200 + n, 1, Some(MappedObject::new(0x6040, 0, 16)));
        self.tpdo[0] = PdoParams::new(0x180 + n, 1, Some(MappedObject::new(0x6041, 0, 16)));
        self.heartbeat_ms = self.cfg.heartbeat_ms;
        self.heartbeat_changed = true;
    }

    /// The value of a mapped TPDO object. Never allocates.
    pub(crate) fn mapped_value(&self, index: u16) -> i64 {
        match index {
            0x6041 => i64::from(self.drive.statusword()),
            0x6064 => i64::from(self.drive.position_actual()),
            0x606C => i64::from(self.drive.velocity_actual()),
            0x6061 => i64::from(self.drive.mode),
            0x603F => i64::from(self.drive.error_code),
            _ => 0,
        }
    }

    /// Stores a mapped RPDO object. Never allocates.
    pub(crate) fn set_mapped(&mut self, index: u16, raw: u64) {
        // Truncations are the PDO's wire widths.
        match index {
            0x6040 => self.controlword(raw as u16),
            0x607A => self.drive.target_position = raw as u32 as i32,
            0x60FF => self.drive.target_velocity = raw as u32 as i32,
            0x6060 => {
                if matches!(raw as u8 as i8, MODE_PP | MODE_HM | MODE_CSP) {
                    self.drive.mode = raw as u8 as i8;
                }
            }
            _ => {}
        }
    }

    fn controlword(&mut self, cw: u16) {
        if self.drive.write_controlword(cw) {
            self.emcy(Emergency::new(0, 0));
        }
    }

    fn emcy(&mut self, e: Emergency) {
        self.pending.push(e.frame(self.node));
    }

    fn pdo_read(
        p: &PdoParams,
        comm: bool,
        tx: bool,
        sub: u8,
        out: &mut Vec<u8>,
    ) -> Result<(), SdoAbortCode> {
        use SdoAbortCode::SubIndexDoesNotExist as Nx;
        if comm {
            match sub {
                0 => out.push(if tx { 5 } else { 2 }),
                1 => out.extend_from_slice(&p.cob.to_le_bytes()),
                2 => out.push(p.transmission),
                3 if tx => out.extend_from_slice(&p.inhibit.to_le_bytes()),
                5 if tx => out.extend_from_slice(&p.event_timer.to_le_bytes()),
                _ => return Err(Nx),
            }
        } else {
            match sub {
                0 => out.push(p.count),
                1..=8 => out.extend_from_slice(&p.map[usize::from(sub - 1)].to_le_bytes()),
                _ => return Err(Nx),
            }
        }
        Ok(())
    }

    fn pdo_write(
        p: &mut PdoParams,
        comm: bool,
        rx: bool,
        sub: u8,
        d: &[u8],
    ) -> Result<(), SdoAbortCode> {
        use SdoAbortCode as A;
        if comm {
            match sub {
                1 => {
                    let v = u32_of(d)?;
                    // CiA 301: a valid PDO's COB-ID cannot change; disable it first.
                    if p.valid() && v & COB_INVALID == 0 && v != p.cob {
                        return Err(A::InvalidValue);
                    }
                    if v & 0x1FFF_F800 != 0 && v & COB_INVALID == 0 {
                        return Err(A::InvalidValue);
                    }
                    if v & COB_INVALID == 0 && p.data_len() > 8 {
                        return Err(A::PdoLengthExceeded);
                    }
                    p.cob = v;
                }
                2 => {
                    let t = u8_of(d)?;
                    if !(t <= 240 || t >= 254) {
                        return Err(A::InvalidValue);
                    }
                    p.transmission = t;
                }
                3 if !rx => p.inhibit = u16_of(d)?,
                5 if !rx => p.event_timer = u16_of(d)?,
                0 => return Err(A::ReadOnly),
                _ => return Err(A::SubIndexDoesNotExist),
            }
            return Ok(());
        }
        if p.valid() {
            return Err(A::CannotStoreDeviceState);
        }
        match sub {
            0 => {
                let n = u8_of(d)?;
                if n > 8 {
                    return Err(A::ValueTooHigh);
                }
                let mut bits = 0u32;
                for &raw in &p.map[..usize::from(n)] {
                    let e = MappedObject::from_raw(raw);
                    match mappable_bits(e.index, e.sub, rx) {
                        Some(b) if b == e.bits => bits += u32::from(b),
                        _ => return Err(A::NotMappable),
                    }
                }
                if bits > 64 {
                    return Err(A::PdoLengthExceeded);
                }
                p.count = n;
            }
            1..=8 => {
                if p.count != 0 {
                    return Err(A::CannotStoreDeviceState);
                }
                let raw = u32_of(d)?;
                let e = MappedObject::from_raw(raw);
                if mappable_bits(e.index, e.sub, rx) != Some(e.bits) {
                    return Err(A::NotMappable);
                }
                p.map[usize::from(sub - 1)] = raw;
            }
            _ => return Err(A::SubIndexDoesNotExist),
        }
        Ok(())
    }
}

fn exact<const N: usize>(d: &[u8]) -> Result<[u8; N], SdoAbortCode> {
    if d.len() > N {
        return Err(SdoAbortCode::LengthTooHigh);
    }
    d.try_into().map_err(|_| SdoAbortCode::LengthTooLow)
}
fn u8_of(d: &[u8]) -> Result<u8, SdoAbortCode> {
    Ok(exact::<1>(d)?[0])
}
fn u16_of(d: &[u8]) -> Result<u16, SdoAbortCode> {
    Ok(u16::from_le_bytes(exact(d)?))
}
fn u32_of(d: &[u8]) -> Result<u32, SdoAbortCode> {
    Ok(u32::from_le_bytes(exact(d)?))
}

impl ObjectAccess for Core {
    fn read(&mut self, index: u16, sub: u8, out: &mut Vec<u8>) -> Result<(), SdoAbortCode> {
        use SdoAbortCode::{ObjectDoesNotExist as NoObj, SubIndexDoesNotExist as NoSub};
        let d = &self.drive;
        match (index, sub) {
            (0x1000, 0) => out.extend_from_slice(&DEVICE_TYPE.to_le_bytes()),
            (0x1001, 0) => out.push(d.error_register),
            (0x1008, 0) => out.extend_from_slice(DEVICE_NAME.as_bytes()),
            (0x1017, 0) => out.extend_from_slice(&self.heartbeat_ms.to_le_bytes()),
            (0x1018, 0) => out.push(4),
            (0x1018, 1) => out.extend_from_slice(&VENDOR_ID.to_le_bytes()),
            (0x1018, 2) => out.extend_from_slice(&PRODUCT_CODE.to_le_bytes()),
            (0x1018, 3) => out.extend_from_slice(&1u32.to_le_bytes()),
            (0x1018, 4) => out.extend_from_slice(&u32::from(self.node.get()).to_le_bytes()),
            (0x1400..=0x1403, _) => Self::pdo_read(
                &self.rpdo[usize::from(index - 0x1400)],
                true,
                false,
                sub,
                out,
            )?,
            (0x1600..=0x1603, _) => Self::pdo_read(
                &self.rpdo[usize::from(index - 0x1600)],
                false,
                false,
                sub,
                out,
            )?,
            (0x1800..=0x1803, _) => Self::pdo_read(
                &self.tpdo[usize::from(index - 0x1800)],
                true,
                true,
                sub,
                out,
            )?,
            (0x1A00..=0x1A03, _) => Self::pdo_read(
                &self.tpdo[usize::from(index - 0x1A00)],
                false,
                true,
                sub,
                out,
            )?,
            (DOMAIN, 0) => out.extend_from_slice(&self.domain),
            (INJECT, 0) => out.push(3),
            (INJECT, 1) => out.extend_from_slice(&d.error_code.to_le_bytes()),
            (INJECT, 2) => out.push(u8::from(self.heartbeat_stopped)),
            (INJECT, 3) => out.extend_from_slice(&0u16.to_le_bytes()),
            (0x603F, 0) => out.extend_from_slice(&d.error_code.to_le_bytes()),
            (0x6040, 0) => out.extend_from_slice(&d.controlword.to_le_bytes()),
            (0x6041, 0) => out.extend_from_slice(&d.statusword().to_le_bytes()),
            (0x6060, 0) => out.extend_from_slice(&d.mode.to_le_bytes()),
            (0x6061, 0) => out.extend_from_slice(&d.mode.to_le_bytes()),
            (0x6064, 0) => out.extend_from_slice(&d.position_actual().to_le_bytes()),
            (0x6065, 0) => out.extend_from_slice(&d.following_window.to_le_bytes()),
            (0x606C, 0) => out.extend_from_slice(&d.velocity_actual().to_le_bytes()),
            (0x607A, 0) => out.extend_from_slice(&d.target_position.to_le_bytes()),
            (0x6098, 0) => out.extend_from_slice(&d.homing_method.to_le_bytes()),
            (0x607C, 0) => out.extend_from_slice(&d.home_offset.to_le_bytes()),
            (0x6099, 0) | (SWITCHES, 0) => out.push(if index == SWITCHES { 3 } else { 2 }),
            (0x6099, s @ 1..=2) => {
                out.extend_from_slice(&d.homing_speeds[usize::from(s - 1)].to_le_bytes())
            }
            (0x609A, 0) => out.extend_from_slice(&d.homing_acceleration.to_le_bytes()),
            (SWITCHES, 1) => out.extend_from_slice(&d.switches.home.to_le_bytes()),
            (SWITCHES, 2) => out.extend_from_slice(&d.switches.negative_limit.to_le_bytes()),
            (SWITCHES, 3) => out.extend_from_slice(&d.switches.positive_limit.to_le_bytes()),
            (0x60FF, 0) => out.extend_from_slice(&d.target_velocity.to_le_bytes()),
            // Supported drive modes: PP (bit 0), HM (bit 5), CSP (bit 7).
            (0x6502, 0) => out.extend_from_slice(&0x0000_00A1u32.to_le_bytes()),
            (
                0x1000
                | 0x1001
                | 0x1008
                | 0x1017
                | 0x1018
                | INJECT
                | DOMAIN
                | SWITCHES
                | 0x603F..=0x6502,
                _,
            ) if self.exists(index) => return Err(NoSub),
            _ => return Err(NoObj),
        }
        Ok(())
    }

    fn write(&mut self, index: u16, sub: u8, data: &[u8]) -> Result<(), SdoAbortCode> {
        use SdoAbortCode as A;
        match (index, sub) {
            (0x1017, 0) => {
                self.heartbeat_ms = u16_of(data)?;
                self.heartbeat_changed = true;
            }
            (0x1400..=0x1403, _) => Self::pdo_write(
                &mut self.rpdo[usize::from(index - 0x1400)],
                true,
                true,
                sub,
                data,
            )?,
            (0x1600..=0x1603, _) => Self::pdo_write(
                &mut self.rpdo[usize::from(index - 0x1600)],
                false,
                true,
                sub,
                data,
            )?,
            (0x1800..=0x1803, _) => Self::pdo_write(
                &mut self.tpdo[usize::from(index - 0x1800)],
                true,
                false,
                sub,
                data,
            )?,
            (0x1A00..=0x1A03, _) => Self::pdo_write(
                &mut self.tpdo[usize::from(index - 0x1A00)],
                false,
                false,
                sub,
                data,
            )?,
            (DOMAIN, 0) => {
                if data.len() > DOMAIN_MAX {
                    return Err(A::LengthTooHigh);
                }
                // Within the capacity reserved at construction: no allocation.
                self.domain.clear();
                self.domain.extend_from_slice(data);
            }
            (INJECT, 1) => {
                let code = u16_of(data)?;
                if code == 0 {
                    return Err(A::InvalidValue);
                }
                if let Some(e) = self.drive.fault(code) {
                    self.emcy(e);
                }
            }
            (INJECT, 2) => {
                self.heartbeat_stopped = match u8_of(data)? {
                    0 => false,
                    1 => true,
                    _ => return Err(A::InvalidValue),
                };
                self.heartbeat_changed = true;
            }
            (INJECT, 3) => {
                let code = u16_of(data)?;
                let mut e = Emergency::new(code, self.drive.error_register | 0x80);
                e.manufacturer = *b"INJ\0\0";
                self.emcy(e);
            }
            (0x6040, 0) => self.controlword(u16_of(data)?),
            (0x6060, 0) => {
                let m = u8_of(data)? as i8;
                if !matches!(m, MODE_PP | MODE_HM | MODE_CSP) {
                    return Err(A::InvalidValue);
                }
                self.drive.mode = m;
            }
            (0x6065, 0) => self.drive.following_window = u32_of(data)?,
            (0x607A, 0) => self.drive.target_position = u32_of(data)? as i32,
            (0x6098, 0) => self.drive.homing_method = u8_of(data)? as i8,
            (0x607C, 0) => self.drive.home_offset = u32_of(data)? as i32,
            (0x6099, s @ 1..=2) => self.drive.homing_speeds[usize::from(s - 1)] = u32_of(data)?,
            (0x609A, 0) => self.drive.homing_acceleration = u32_of(data)?,
            (SWITCHES, 1) => self.drive.switches.home = u32_of(data)? as i32,
            (SWITCHES, 2) => self.drive.switches.negative_limit = u32_of(data)? as i32,
            (SWITCHES, 3) => self.drive.switches.positive_limit = u32_of(data)? as i32,
            (0x60FF, 0) => self.drive.target_velocity = u32_of(data)? as i32,
            _ => {
                // Distinguish read-only, missing sub-index and missing object.
                // Into the scratch buffer reserved at construction: no allocation.
                let mut scratch = core::mem::take(&mut self.scratch);
                scratch.clear();
                let r = self.read(index, sub, &mut scratch);
                self.scratch = scratch;
                return Err(match r {
                    Ok(()) => A::ReadOnly,
                    Err(e) => e,
                });
            }
        }
        Ok(())
    }
}

impl Core {
    fn exists(&self, index: u16) -> bool {
        matches!(
            index,
            0x1000
                | 0x1001
                | 0x1008
                | 0x1017
                | 0x1018
                | INJECT
                | DOMAIN
                | SWITCHES
                | 0x603F
                | 0x6040
                | 0x6041
                | 0x6060
                | 0x6061
                | 0x6064
                | 0x6065
                | 0x606C
                | 0x607A
                | 0x607C
                | 0x6098
                | 0x6099
                | 0x609A
                | 0x60FF
                | 0x6502
        )
    }
}
