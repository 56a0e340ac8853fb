//! PDOs: communication (0x1400/0x1800 + n) and mapping (0x1600/0x1A00 + n) parameters, the
//! configuration sequence as SDO writes, and encode/decode of a mapped PDO.
//!
//! Mapping entries are `index << 16 | sub << 8 | bit length`; only whole bytes are
//! supported (every CiA 402 object a servo loop maps is 8, 16 or 32 bits). The
//! per-cycle [`PdoMapping::encode`] / [`PdoMapping::decode`] work on fixed arrays and never
//! allocate.

use super::{frame, CanOpenError, NodeId, COB_RPDO1, COB_TPDO1};
use crate::can::CanFrame;

/// Most entries a mapping can hold (CiA 301 allows 64; 8 bytes give at most 8 whole-byte
/// entries).
pub const MAX_ENTRIES: usize = 8;

/// Bit 31 of a PDO COB-ID: the PDO does not exist / is disabled.
pub const COB_INVALID: u32 = 0x8000_0000;

/// Transmission type: acyclic synchronous (CiA 301 0).
pub const TRANSMISSION_SYNC_ACYCLIC: u8 = 0;
/// Transmission type: on every SYNC (1; n = 2..240 is every n-th SYNC).
pub const TRANSMISSION_SYNC_EVERY: u8 = 1;
/// Transmission type: event-driven, manufacturer-specific (254).
pub const TRANSMISSION_EVENT_MANUFACTURER: u8 = 254;
/// Transmission type: event-driven, device-profile-specific (255).
pub const TRANSMISSION_EVENT_PROFILE: u8 = 255;

/// One mapped object.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MappedObject {
    /// Object index.
    pub index: u16,
    /// Sub-index.
    pub sub: u8,
    /// Length in bits (8, 16, 24, 32, …, 64).
    pub bits: u8,
}

impl MappedObject {
    /// An entry of `bits` bits.
    pub const fn new(index: u16, sub: u8, bits: u8) -> MappedObject {
        MappedObject { index, sub, bits }
    }

    /// The 32-bit mapping entry.
    pub fn raw(self) -> u32 {
        (u32::from(self.index) << 16) | (u32::from(self.sub) << 8) | u32::from(self.bits)
    }

    /// The entry of a 32-bit mapping value.
    pub fn from_raw(raw: u32) -> MappedObject {
        MappedObject {
            // Cannot truncate: shifted and masked fields.
            index: (raw >> 16) as u16,
            sub: ((raw >> 8) & 0xFF) as u8,
            bits: (raw & 0xFF) as u8,
        }
    }

    fn bytes(self) -> usize {
        usize::from(self.bits / 8)
    }
}

/// The objects one PDO carries, in order. Fixed size (`Copy`), at most 64 bits.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PdoMapping {
    entries: [MappedObject; MAX_ENTRIES],
    len: usize,
}

impl PdoMapping {
    /// A mapping of `objects`, refused when an entry is not whole bytes or the total
    /// exceeds 8 bytes.
    pub fn new(objects: &[MappedObject]) -> Result<PdoMapping, CanOpenError> {
        if objects.len() > MAX_ENTRIES {
            return Err(CanOpenError::Mapping("more than 8 objects"));
        }
        let mut bits = 0u32;
        for o in objects {
            if o.bits == 0 || o.bits % 8 != 0 {
                return Err(CanOpenError::Mapping(
                    "only whole-byte objects can be mapped",
                ));
            }
            bits += u32::from(o.bits);
        }
        if bits > 64 {
            return Err(CanOpenError::Mapping(
                "the mapped objects exceed the 8 bytes of a classic CAN frame",
            ));
        }
        let mut entries = [MappedObject::new(0, 0, 0); MAX_ENTRIES];
        entries[..objects.len()].copy_from_slice(objects);
        Ok(PdoMapping {
            entries,
            len: objects.len(),
        })
    }

    /// The mapped objects.
    pub fn entries(&self) -> &[MappedObject] {
        &self.entries[..self.len]
    }

    /// The data length of the PDO in bytes.
    pub fn data_len(&self) -> usize {
        self.entries().iter().map(|e| e.bytes()).sum()
    }

    /// Encodes `values` (one per entry, in order, truncated to each entry's width,
    /// little-endian) into a frame on `cob`. Never allocates.
    pub fn encode(&self, cob: crate::can::CanId, values: &[i64]) -> Result<CanFrame, CanOpenError> {
        if values.len() != self.len {
            return Err(CanOpenError::Mapping(
                "one value per mapped object is needed",
            ));
        }
        let mut buf = [0u8; 8];
        let mut pos = 0;
        for (e, v) in self.entries().iter().zip(values) {
            let n = e.bytes();
            buf[pos..pos + n].copy_from_slice(&v.to_le_bytes()[..n]);
            pos += n;
        }
        Ok(frame(cob, &buf[..pos]))
    }

    /// Decodes `data` into `out` (one value per entry; signed entries are sign-extended
    /// when `signed` says so for that position, others zero-extended). Never allocates.
    pub fn decode(
        &self,
        data: &[u8],
        signed: &[bool],
        out: &mut [i64],
    ) -> Result<(), CanOpenError> {
        if data.len() != self.data_len() {
            return Err(CanOpenError::Mapping(
                "PDO length does not match its mapping",
            ));
        }
        if out.len() < self.len {
            return Err(CanOpenError::Mapping(
                "output has fewer slots than mapped objects",
            ));
        }
        let mut pos = 0;
        for (i, e) in self.entries().iter().enumerate() {
            let n = e.bytes();
            let mut b = [0u8; 8];
            b[..n].copy_from_slice(&data[pos..pos + n]);
            let raw = u64::from_le_bytes(b);
            let shift = 64 - 8 * n as u32;
            out[i] = if signed.get(i).copied().unwrap_or(false) && n < 8 {
                ((raw << shift) as i64) >> shift
            } else {
                raw as i64
            };
            pos += n;
        }
        Ok(())
    }
}

/// Receive (master → drive) or transmit (drive → master), seen from the drive.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PdoDirection {
    /// RPDO: the drive receives (controlword, targets).
    Rpdo,
    /// TPDO: the drive transmits (statusword, actual values).
    Tpdo,
}

/// One SDO write of a configuration sequence.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SdoWrite {
    /// Object index.
    pub index: u16,
    /// Sub-index.
    pub sub: u8,
    /// Little-endian value.
    pub data: Vec<u8>,
}

impl SdoWrite {
    fn u32(index: u16, sub: u8, v: u32) -> SdoWrite {
        SdoWrite {
            index,
            sub,
            data: v.to_le_bytes().to_vec(),
        }
    }
    fn u16(index: u16, sub: u8, v: u16) -> SdoWrite {
        SdoWrite {
            index,
            sub,
            data: v.to_le_bytes().to_vec(),
        }
    }
    fn u8(index: u16, sub: u8, v: u8) -> SdoWrite {
        SdoWrite {
            index,
            sub,
            data: vec![v],
        }
    }
}

/// The configuration of one PDO of one drive.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PdoConfig {
    /// RPDO or TPDO.
    pub direction: PdoDirection,
    /// PDO number 1..=512 (1..=4 have predefined COB-IDs).
    pub number: u16,
    /// The COB-ID (without the invalid bit).
    pub cob_id: u16,
    /// Transmission type (see the `TRANSMISSION_*` constants).
    pub transmission: u8,
    /// TPDO event timer in ms (0 = off); ignored for RPDOs.
    pub event_timer_ms: u16,
    /// The mapped objects.
    pub mapping: PdoMapping,
}

impl PdoConfig {
    /// PDO `number` (1..=4) of `node` on its predefined COB-ID.
    pub fn predefined(
        direction: PdoDirection,
        number: u16,
        node: NodeId,
        transmission: u8,
        mapping: PdoMapping,
    ) -> Result<PdoConfig, CanOpenError> {
        if !(1..=4).contains(&number) {
            return Err(CanOpenError::Mapping(
                "only PDOs 1..=4 have predefined COB-IDs",
            ));
        }
        let base = match direction {
            PdoDirection::Rpdo => COB_RPDO1,
            PdoDirection::Tpdo => COB_TPDO1,
        };
        Ok(PdoConfig {
            direction,
            number,
            cob_id: base + 0x100 * (number - 1) + u16::from(node.get()),
            transmission,
            event_timer_ms: 0,
            mapping,
        })
    }

    /// The communication parameter object (0x1400 / 0x1800 + number − 1).
    pub fn comm_index(&self) -> u16 {
        match self.direction {
            PdoDirection::Rpdo => 0x1400 + self.number - 1,
            PdoDirection::Tpdo => 0x1800 + self.number - 1,
        }
    }

    /// The mapping parameter object (0x1600 / 0x1A00 + number − 1).
    pub fn mapping_index(&self) -> u16 {
        self.comm_index() + 0x200
    }

    /// The CAN id.
    pub fn can_id(&self) -> crate::can::CanId {
        super::cob_id(self.cob_id)
    }

    /// The CiA 301 configuration sequence as SDO writes, in order: disable the PDO (COB-ID
    /// bit 31), set the transmission type (and event timer), clear the mapping (sub 0 = 0),
    /// write each entry, set the entry count, enable the PDO.
    pub fn sdo_writes(&self) -> Vec<SdoWrite> {
        let comm = self.comm_index();
        let map = self.mapping_index();
        let cob = u32::from(self.cob_id);
        let mut w = vec![
            SdoWrite::u32(comm, 1, cob | COB_INVALID),
            SdoWrite::u8(comm, 2, self.transmission),
        ];
        if self.direction == PdoDirection::Tpdo {
            w.push(SdoWrite::u16(comm, 5, self.event_timer_ms));
        }
        w.push(SdoWrite::u8(map, 0, 0));
        for (i, e) in self.mapping.entries().iter().enumerate() {
            // Cannot truncate: at most 8 entries.
            w.push(SdoWrite::u32(map, i as u8 + 1, e.raw()));
        }
        // Cannot truncate: at most 8 entries.
        w.push(SdoWrite::u8(map, 0, self.mapping.entries().len() as u8));
        w.push(SdoWrite::u32(comm, 1, cob));
        w
    }
}

/// Controlword.
pub const CONTROLWORD: MappedObject = MappedObject::new(0x6040, 0, 16);
/// Statusword.
pub const STATUSWORD: MappedObject = MappedObject::new(0x6041, 0, 16);
/// Modes of operation.
pub const MODES_OF_OPERATION: MappedObject = MappedObject::new(0x6060, 0, 8);
/// Modes of operation display.
pub const MODES_DISPLAY: MappedObject = MappedObject::new(0x6061, 0, 8);
/// Position actual value.
pub const POSITION_ACTUAL: MappedObject = MappedObject::new(0x6064, 0, 32);
/// Velocity actual value.
pub const VELOCITY_ACTUAL: MappedObject = MappedObject::new(0x606C, 0, 32);
/// Target position.
pub const TARGET_POSITION: MappedObject = MappedObject::new(0x607A, 0, 32);

/// The default CSP process data of one drive, all synchronous (transmission type 1):
///
/// * RPDO1: controlword 0x6040 + target position 0x607A (6 bytes);
/// * TPDO1: statusword 0x6041 + position actual 0x6064 (6 bytes);
/// * TPDO2 (optional): velocity actual 0x606C + modes display 0x6061 (5 bytes). Velocity
///   does not fit TPDO1 (2 + 4 + 4 = 10 bytes > 8), so it costs a frame per cycle of its
///   own; leave it out where the bus-load budget is tight.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CspLayout {
    /// Controlword + target position.
    pub rpdo1: PdoConfig,
    /// Statusword + position actual.
    pub tpdo1: PdoConfig,
    /// Velocity actual + modes display, if wanted.
    pub tpdo2: Option<PdoConfig>,
}

impl CspLayout {
    /// The layout for `node`, with or without the velocity TPDO.
    pub fn new(node: NodeId, with_velocity: bool) -> Result<CspLayout, CanOpenError> {
        CspLayout::mapped(
            node,
            &[CONTROLWORD, TARGET_POSITION],
            &[STATUSWORD, POSITION_ACTUAL],
            with_velocity,
        )
    }

    /// The layout of a drive that homes itself (CiA 402 homing mode, commanded by the
    /// master): RPDO1 also carries modes of operation 0x6060 and TPDO1 modes display
    /// 0x6061 (7 bytes each, still one frame). The mode switch CSP → homing → CSP then
    /// travels with the SYNC-timed process data, and its confirmation arrives in the same
    /// TPDO as the statusword and position it applies to: no SDO on the servo thread.
    pub fn with_mode(node: NodeId, with_velocity: bool) -> Result<CspLayout, CanOpenError> {
        CspLayout::mapped(
            node,
            &[CONTROLWORD, TARGET_POSITION, MODES_OF_OPERATION],
            &[STATUSWORD, POSITION_ACTUAL, MODES_DISPLAY],
            with_velocity,
        )
    }

    /// A layout with the given RPDO1 and TPDO1 mappings (checked to fit 8 bytes), and the
    /// default TPDO2 if wanted.
    pub fn mapped(
        node: NodeId,
        rpdo1: &[MappedObject],
        tpdo1: &[MappedObject],
        with_velocity: bool,
    ) -> Result<CspLayout, CanOpenError> {
        use PdoDirection::{Rpdo, Tpdo};
        let rpdo1 = PdoConfig::predefined(
            Rpdo,
            1,
            node,
            TRANSMISSION_SYNC_EVERY,
            PdoMapping::new(rpdo1)?,
        )?;
        let tpdo1 = PdoConfig::predefined(
            Tpdo,
            1,
            node,
            TRANSMISSION_SYNC_EVERY,
            PdoMapping::new(tpdo1)?,
        )?;
        let tpdo2 = if with_velocity {
            Some(PdoConfig::predefined(
                Tpdo,
                2,
                node,
                TRANSMISSION_SYNC_EVERY,
                PdoMapping::new(&[VELOCITY_ACTUAL, MODES_DISPLAY])?,
            )?)
        } else {
            None
        };
        Ok(CspLayout {
            rpdo1,
            tpdo1,
            tpdo2,
        })
    }

    /// The PDOs of this layout that travel every SYNC (for the bus-load budget).
    pub fn pdos(&self) -> impl Iterator<Item = &PdoConfig> {
        [Some(&self.rpdo1), Some(&self.tpdo1), self.tpdo2.as_ref()]
            .into_iter()
            .flatten()
    }

    /// Every SDO write that configures the layout, PDO after PDO. The unused TPDO2 is
    /// disabled so a drive default cannot add unbudgeted traffic.
    pub fn sdo_writes(&self) -> Vec<SdoWrite> {
        let mut w: Vec<SdoWrite> = self.pdos().flat_map(PdoConfig::sdo_writes).collect();
        if self.tpdo2.is_none() {
            let cob = 0x280 + u32::from(self.tpdo1.cob_id - 0x180);
            w.push(SdoWrite::u32(0x1801, 1, cob | COB_INVALID));
        }
        w
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn n(id: u8) -> NodeId {
        NodeId::new(id).unwrap()
    }

    #[test]
    fn mapping_entries_encode_as_cia301() {
        assert_eq!(TARGET_POSITION.raw(), 0x607A_0020);
        assert_eq!(MappedObject::from_raw(0x6041_0010), STATUSWORD);
    }

    #[test]
    fn mappings_over_8_bytes_or_partial_bytes_are_refused() {
        assert!(PdoMapping::new(&[STATUSWORD, POSITION_ACTUAL, VELOCITY_ACTUAL]).is_err());
        assert!(PdoMapping::new(&[MappedObject::new(0x6040, 0, 12)]).is_err());
        assert_eq!(
            PdoMapping::new(&[STATUSWORD, POSITION_ACTUAL])
                .unwrap()
                .data_len(),
            6
        );
    }

    #[test]
    fn encode_decode_round_trip_with_sign() {
        let m = PdoMapping::new(&[STATUSWORD, POSITION_ACTUAL]).unwrap();
        let f = m
            .encode(super::super::cob_id(0x181), &[0x0237, -5])
            .unwrap();
        assert_eq!(f.data(), &[0x37, 0x02, 0xFB, 0xFF, 0xFF, 0xFF]);
        let mut out = [0i64; 2];
        m.decode(f.data(), &[false, true], &mut out).unwrap();
        assert_eq!(out, [0x0237, -5]);
        m.decode(f.data(), &[false, false], &mut out).unwrap();
        assert_eq!(out[1], 0xFFFF_FFFB);
        assert!(m.decode(&f.data()[..5], &[], &mut out).is_err());
        assert!(m.encode(super::super::cob_id(0x181), &[1]).is_err());
    }

    #[test]
    fn configuration_is_disable_clear_map_enable() {
        let l = CspLayout::new(n(2), false).unwrap();
        let w = l.rpdo1.sdo_writes();
        let seq: Vec<(u16, u8, Vec<u8>)> =
            w.into_iter().map(|w| (w.index, w.sub, w.data)).collect();
        assert_eq!(
            seq,
            vec![
                (0x1400, 1, vec![0x02, 0x02, 0, 0x80]),
                (0x1400, 2, vec![1]),
                (0x1600, 0, vec![0]),
                (0x1600, 1, vec![0x10, 0, 0x40, 0x60]),
                (0x1600, 2, vec![0x20, 0, 0x7A, 0x60]),
                (0x1600, 0, vec![2]),
                (0x1400, 1, vec![0x02, 0x02, 0, 0]),
            ]
        );
        let t = l.tpdo1.sdo_writes();
        assert_eq!((t[0].index, t[2].index, t[2].sub), (0x1800, 0x1800, 5));
        assert_eq!(t.last().unwrap().data, vec![0x82, 0x01, 0, 0]);
        let all = l.sdo_writes();
        assert_eq!(all.last().unwrap().index, 0x1801, "unused TPDO2 disabled");
        assert_eq!(all.last().unwrap().data, vec![0x82, 0x02, 0, 0x80]);
    }

    #[test]
    fn csp_layout_sizes() {
        let l = CspLayout::new(n(1), true).unwrap();
        let sizes: Vec<usize> = l.pdos().map(|p| p.mapping.data_len()).collect();
        assert_eq!(sizes, [6, 6, 5]);
        assert_eq!(l.tpdo2.unwrap().cob_id, 0x281);
        assert!(PdoConfig::predefined(PdoDirection::Rpdo, 5, n(1), 1, l.rpdo1.mapping).is_err());
    }
}
