//! The PDO layout of a CANopen drive: the default CSP layout, or RPDO1 / TPDO1 mapped by
//! the object names of the drive's EDS file (`[drive.canopen] eds`, `rpdo`, `tpdo`).
//!
//! Resolved on the non-realtime path at deployment. Errors name the key (`…rpdo[1]`) and
//! the name that did not resolve, or the object the master needs and the mapping lacks.

use crate::config::CanopenDriveConfig;
use hytask_hal::canopen::eds::Eds;
use hytask_hal::canopen::pdo::{
    CspLayout, MappedObject, PdoMapping, CONTROLWORD, MODES_DISPLAY, MODES_OF_OPERATION,
    POSITION_ACTUAL, STATUSWORD, TARGET_POSITION,
};
use hytask_hal::canopen::NodeId;

/// Why a layout cannot be made: the key and what is wrong.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LayoutError {
    /// The key under `[drive.canopen]` (`eds`, `rpdo[1]`, `tpdo`, `velocity_pdo`).
    pub key: String,
    /// What is wrong.
    pub message: String,
}

fn error(key: impl Into<String>, message: impl Into<String>) -> LayoutError {
    LayoutError {
        key: key.into(),
        message: message.into(),
    }
}

/// The layout of drive `co` at `node`; `with_mode` maps 0x6060 / 0x6061 (drive-side homing).
pub fn layout(
    co: &CanopenDriveConfig,
    node: NodeId,
    with_mode: bool,
) -> Result<CspLayout, LayoutError> {
    if co.rpdo.is_none() && co.tpdo.is_none() {
        let l = if with_mode {
            CspLayout::with_mode(node, co.velocity_pdo)
        } else {
            CspLayout::new(node, co.velocity_pdo)
        };
        return l.map_err(|e| error("velocity_pdo", e.to_string()));
    }
    let eds = load(co)?;
    let (rpdo_default, tpdo_default): (&[MappedObject], &[MappedObject]) = if with_mode {
        (
            &[CONTROLWORD, TARGET_POSITION, MODES_OF_OPERATION],
            &[STATUSWORD, POSITION_ACTUAL, MODES_DISPLAY],
        )
    } else {
        (
            &[CONTROLWORD, TARGET_POSITION],
            &[STATUSWORD, POSITION_ACTUAL],
        )
    };
    let mut needs_r = vec![
        (CONTROLWORD, "Controlword"),
        (TARGET_POSITION, "Target position"),
    ];
    let mut needs_t = vec![
        (STATUSWORD, "Statusword"),
        (POSITION_ACTUAL, "Position actual value"),
    ];
    if with_mode {
        needs_r.push((
            MODES_OF_OPERATION,
            "Modes of operation (homing = \"drive\")",
        ));
        needs_t.push((
            MODES_DISPLAY,
            "Modes of operation display (homing = \"drive\")",
        ));
    }
    let rpdo = mapping(&eds, "rpdo", co.rpdo.as_deref(), rpdo_default, &needs_r)?;
    let tpdo = mapping(&eds, "tpdo", co.tpdo.as_deref(), tpdo_default, &needs_t)?;
    CspLayout::mapped(node, &rpdo, &tpdo, co.velocity_pdo)
        .map_err(|e| error("velocity_pdo", e.to_string()))
}

fn load(co: &CanopenDriveConfig) -> Result<Eds, LayoutError> {
    let Some(path) = &co.eds else {
        return Err(error("eds", "object names need the drive's EDS file"));
    };
    let text = std::fs::read_to_string(path)
        .map_err(|e| error("eds", format!("cannot read {}: {e}", path.display())))?;
    Eds::parse(&text, &path.display().to_string()).map_err(|e| error("eds", e.to_string()))
}

/// The objects `names` map (or the default), checked to contain every object of `needs`.
fn mapping(
    eds: &Eds,
    key: &str,
    names: Option<&[String]>,
    default: &[MappedObject],
    needs: &[(MappedObject, &str)],
) -> Result<Vec<MappedObject>, LayoutError> {
    let Some(names) = names else {
        return Ok(default.to_vec());
    };
    let objects = names
        .iter()
        .enumerate()
        .map(|(i, n)| {
            eds.mapped_object(n)
                .map_err(|e| error(format!("{key}[{i}]"), e))
        })
        .collect::<Result<Vec<_>, _>>()?;
    for (need, what) in needs {
        if !objects
            .iter()
            .any(|o| o.index == need.index && o.sub == need.sub)
        {
            return Err(error(
                key,
                format!(
                    "must map {what} ({:04X}:{:02X}), which the master reads or writes every cycle",
                    need.index, need.sub
                ),
            ));
        }
    }
    PdoMapping::new(&objects).map_err(|e| {
        let bytes: usize = objects.iter().map(|o| usize::from(o.bits / 8)).sum();
        error(key, format!("{e}: {names:?} take {bytes} bytes"))
    })?;
    Ok(objects)
}
