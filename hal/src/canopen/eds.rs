//! Reading a drive's EDS file (CiA 306 electronic data sheet, INI format) for the names and
//! data types of its objects: what a tool needs to print a value typed, and what a
//! configuration needs to accept "Statusword" for 0x6041:00.
//!
//! Only the object sections are read: `[1018]` (an object), `[1018sub1]` (a sub-index of a
//! record or array), with their `ParameterName`, `ObjectType`, `DataType`, `AccessType`,
//! `PDOMapping` and `DefaultValue`. Other sections (`[FileInfo]`, `[DeviceInfo]`, the object
//! lists) are skipped. A plain variable is reachable as sub-index 0.

use std::collections::BTreeMap;

/// A CiA 301 basic data type (the `DataType` of an EDS entry).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DataType {
    /// BOOLEAN (0x0001).
    Boolean,
    /// INTEGER8/16/32/64 (0x0002, 0x0003, 0x0004, 0x0015): size in bytes.
    Integer(usize),
    /// UNSIGNED8/16/32/64 (0x0005, 0x0006, 0x0007, 0x001B): size in bytes.
    Unsigned(usize),
    /// REAL32 (0x0008).
    Real32,
    /// REAL64 (0x0011).
    Real64,
    /// VISIBLE_STRING (0x0009).
    VisibleString,
    /// OCTET_STRING (0x000A).
    OctetString,
    /// DOMAIN (0x000F).
    Domain,
    /// Any other code (kept, printed as hex).
    Other(u16),
}

impl DataType {
    /// The type of a CiA 301 data type code.
    pub fn from_code(code: u16) -> DataType {
        match code {
            0x0001 => DataType::Boolean,
            0x0002 => DataType::Integer(1),
            0x0003 => DataType::Integer(2),
            0x0004 => DataType::Integer(4),
            0x0015 => DataType::Integer(8),
            0x0005 => DataType::Unsigned(1),
            0x0006 => DataType::Unsigned(2),
            0x0007 => DataType::Unsigned(4),
            0x001B => DataType::Unsigned(8),
            0x0008 => DataType::Real32,
            0x0011 => DataType::Real64,
            0x0009 => DataType::VisibleString,
            0x000A => DataType::OctetString,
            0x000F => DataType::Domain,
            c => DataType::Other(c),
        }
    }

    /// The size in bytes of a fixed-size type (`None` for strings and domains).
    pub fn size(self) -> Option<usize> {
        match self {
            DataType::Boolean => Some(1),
            DataType::Integer(n) | DataType::Unsigned(n) => Some(n),
            DataType::Real32 => Some(4),
            DataType::Real64 => Some(8),
            _ => None,
        }
    }

    /// `data` (little-endian, as an SDO upload gives it) as text of this type: numbers in
    /// decimal, strings as text, anything else as hex bytes. A fixed-size type whose data
    /// has another length is an error naming both lengths.
    pub fn format(self, data: &[u8]) -> Result<String, String> {
        if let Some(n) = self.size() {
            if data.len() != n {
                return Err(format!(
                    "{self:?} has {n} byte(s), the value has {}",
                    data.len()
                ));
            }
        }
        let mut b = [0u8; 8];
        b[..data.len().min(8)].copy_from_slice(&data[..data.len().min(8)]);
        let u = u64::from_le_bytes(b);
        Ok(match self {
            DataType::Boolean => (data[0] != 0).to_string(),
            DataType::Unsigned(_) => u.to_string(),
            DataType::Integer(n) => {
                let shift = 64 - 8 * n as u32;
                (((u << shift) as i64) >> shift).to_string()
            }
            DataType::Real32 => f32::from_le_bytes([b[0], b[1], b[2], b[3]]).to_string(),
            DataType::Real64 => f64::from_le_bytes(b).to_string(),
            DataType::VisibleString => String::from_utf8_lossy(data).into_owned(),
            DataType::OctetString | DataType::Domain | DataType::Other(_) => data
                .iter()
                .map(|b| format!("{b:02x}"))
                .collect::<Vec<_>>()
                .join(" "),
        })
    }
}

/// Access of an entry (`AccessType`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Access {
    /// `ro`.
    ReadOnly,
    /// `wo`.
    WriteOnly,
    /// `rw`, `rwr`, `rww`.
    ReadWrite,
    /// `const`.
    Const,
}

/// One object or sub-index of an EDS.
#[derive(Debug, Clone, PartialEq)]
pub struct EdsEntry {
    /// Index.
    pub index: u16,
    /// Sub-index (0 for a plain variable).
    pub sub: u8,
    /// `ParameterName`; for a sub-index, prefixed by its object's name and a dot when the
    /// object is a record or array ("Identity object.Vendor-ID").
    pub name: String,
    /// `DataType`.
    pub data_type: DataType,
    /// `AccessType`.
    pub access: Access,
    /// `PDOMapping = 1`.
    pub pdo_mappable: bool,
    /// `DefaultValue`, as written.
    pub default: Option<String>,
}

/// An EDS file's objects.
#[derive(Debug, Clone, Default)]
pub struct Eds {
    entries: BTreeMap<(u16, u8), EdsEntry>,
}

/// Why an EDS file cannot be read: file, line and what is wrong there.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{origin}:{line}: {message}")]
pub struct EdsError {
    /// The file (or whatever the text came from).
    pub origin: String,
    /// 1-based line.
    pub line: usize,
    /// What is wrong.
    pub message: String,
}

/// A section name: `Some((index, None))` for `[6041]`, `Some((index, Some(sub)))` for
/// `[1018sub1]`, `None` for the other sections.
fn object_section(name: &str) -> Option<(u16, Option<u8>)> {
    let lower = name.to_ascii_lowercase();
    let (idx, sub) = match lower.split_once("sub") {
        Some((i, s)) => (i, Some(s)),
        None => (lower.as_str(), None),
    };
    if idx.len() != 4 {
        return None;
    }
    let index = u16::from_str_radix(idx, 16).ok()?;
    match sub {
        None => Some((index, None)),
        Some(s) => Some((index, Some(u8::from_str_radix(s, 16).ok()?))),
    }
}

/// A number as EDS files write them: `0x` hex, or decimal.
fn number(v: &str) -> Option<u32> {
    let v = v.trim();
    match v.strip_prefix("0x").or_else(|| v.strip_prefix("0X")) {
        Some(h) => u32::from_str_radix(h, 16).ok(),
        None => v.parse().ok(),
    }
}

#[derive(Default)]
struct Section {
    at: usize,
    keys: BTreeMap<String, String>,
}

impl Eds {
    /// Parses the text of an EDS file; `origin` names it in errors.
    pub fn parse(text: &str, origin: &str) -> Result<Eds, EdsError> {
        let err = |line: usize, message: String| EdsError {
            origin: origin.to_string(),
            line,
            message,
        };
        let mut sections: Vec<((u16, Option<u8>), Section)> = Vec::new();
        let mut current: Option<usize> = None;
        for (n, raw) in text.lines().enumerate() {
            let line = raw.trim();
            if line.is_empty() || line.starts_with(';') || line.starts_with('#') {
                continue;
            }
            if let Some(name) = line.strip_prefix('[') {
                let name = name
                    .strip_suffix(']')
                    .ok_or_else(|| err(n + 1, format!("section header without ']': {line}")))?;
                current = object_section(name).map(|key| {
                    sections.push((
                        key,
                        Section {
                            at: n + 1,
                            keys: BTreeMap::new(),
                        },
                    ));
                    sections.len() - 1
                });
                continue;
            }
            let Some((k, v)) = line.split_once('=') else {
                return Err(err(n + 1, format!("expected key=value, got {line:?}")));
            };
            if let Some(i) = current {
                sections[i]
                    .1
                    .keys
                    .insert(k.trim().to_ascii_lowercase(), v.trim().to_string());
            }
        }
        let names: BTreeMap<u16, (String, u32)> = sections
            .iter()
            .filter(|((_, sub), _)| sub.is_none())
            .map(|((index, _), s)| {
                let name = s.keys.get("parametername").cloned().unwrap_or_default();
                let ty = s
                    .keys
                    .get("objecttype")
                    .and_then(|v| number(v))
                    .unwrap_or(7);
                (*index, (name, ty))
            })
            .collect();
        let mut eds = Eds::default();
        for ((index, sub), s) in &sections {
            let (parent, object_type) = names.get(index).cloned().unwrap_or_default();
            // Records and arrays (0x8, 0x9) only describe their subs.
            if sub.is_none() && matches!(object_type, 8 | 9) {
                continue;
            }
            let get = |k: &str| {
                s.keys
                    .get(k)
                    .ok_or_else(|| err(s.at, format!("[{index:04X}] has no {k}")))
            };
            let name = get("parametername")?.clone();
            let code = number(get("datatype")?)
                .ok_or_else(|| err(s.at, format!("[{index:04X}] DataType is not a number")))?;
            let access = match get("accesstype")?.to_ascii_lowercase().as_str() {
                "ro" => Access::ReadOnly,
                "wo" => Access::WriteOnly,
                "rw" | "rwr" | "rww" => Access::ReadWrite,
                "const" => Access::Const,
                other => {
                    return Err(err(
                        s.at,
                        format!(
                        "[{index:04X}] AccessType {other:?} is not ro, wo, rw, rwr, rww or const"
                    ),
                    ))
                }
            };
            let entry = EdsEntry {
                index: *index,
                sub: sub.unwrap_or(0),
                name: match sub {
                    Some(_) if !parent.is_empty() => format!("{parent}.{name}"),
                    _ => name,
                },
                data_type: DataType::from_code(u16::try_from(code).unwrap_or(u16::MAX)),
                access,
                pdo_mappable: s.keys.get("pdomapping").and_then(|v| number(v)) == Some(1),
                default: s.keys.get("defaultvalue").cloned(),
            };
            eds.entries.insert((entry.index, entry.sub), entry);
        }
        Ok(eds)
    }

    /// The entry of `index:sub`.
    pub fn get(&self, index: u16, sub: u8) -> Option<&EdsEntry> {
        self.entries.get(&(index, sub))
    }

    /// The entry named `name` (case-insensitive; a sub-index by "Object.Sub" or by its
    /// own name when that is unique).
    pub fn find(&self, name: &str) -> Option<&EdsEntry> {
        let exact = self
            .entries
            .values()
            .find(|e| e.name.eq_ignore_ascii_case(name));
        exact.or_else(|| {
            let mut by_sub = self.entries.values().filter(|e| {
                e.name
                    .rsplit_once('.')
                    .is_some_and(|(_, s)| s.eq_ignore_ascii_case(name))
            });
            match (by_sub.next(), by_sub.next()) {
                (Some(e), None) => Some(e),
                _ => None,
            }
        })
    }

    /// Every entry, by index and sub-index.
    pub fn entries(&self) -> impl Iterator<Item = &EdsEntry> {
        self.entries.values()
    }

    /// The PDO mapping entry of the object named `name` (as [`Eds::find`]), its width from
    /// the EDS data type. Refused, saying why, when the name is unknown, the object is not
    /// PDO-mappable or its type has no fixed size.
    pub fn mapped_object(&self, name: &str) -> Result<super::pdo::MappedObject, String> {
        let e = self
            .find(name)
            .ok_or_else(|| format!("no object named {name:?} in the EDS"))?;
        let at = format!("{name:?} ({:04X}:{:02X})", e.index, e.sub);
        if !e.pdo_mappable {
            return Err(format!(
                "{at} is not PDO-mappable (PDOMapping=0 in the EDS)"
            ));
        }
        let bits = e
            .data_type
            .size()
            .and_then(|n| u8::try_from(n * 8).ok())
            .ok_or_else(|| format!("{at} has no fixed size ({:?}) to map", e.data_type))?;
        Ok(super::pdo::MappedObject::new(e.index, e.sub, bits))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A small EDS as a drive vendor writes it (CiA 306), for the loopback drive.
    const EDS: &str = "\
[FileInfo]
FileName=hytask-loopback.eds
; a comment
[DeviceInfo]
VendorName=hytask

[MandatoryObjects]
SupportedObjects=2
1=0x1000
2=0x1018

[1000]
ParameterName=Device type
ObjectType=0x7
DataType=0x0007
AccessType=ro
DefaultValue=0x00020192
PDOMapping=0

[1018]
ParameterName=Identity object
ObjectType=0x9
SubNumber=2

[1018sub0]
ParameterName=Highest sub-index supported
ObjectType=0x7
DataType=0x0005
AccessType=const
DefaultValue=4

[1018sub1]
ParameterName=Vendor-ID
ObjectType=0x7
DataType=0x0007
AccessType=ro

[6041]
ParameterName=Statusword
ObjectType=0x7
DataType=0x0006
AccessType=ro
PDOMapping=1

[6064]
ParameterName=Position actual value
ObjectType=0x7
DataType=0x0004
AccessType=ro
PDOMapping=1

[1008]
ParameterName=Manufacturer device name
ObjectType=0x7
DataType=0x0009
AccessType=const
";

    #[test]
    fn objects_names_types_and_access_are_read() {
        let eds = Eds::parse(EDS, "drive.eds").unwrap();
        assert_eq!(eds.entries().count(), 6, "records describe only their subs");
        let sw = eds.find("statusword").unwrap();
        assert_eq!((sw.index, sw.sub), (0x6041, 0));
        assert_eq!(sw.data_type, DataType::Unsigned(2));
        assert!(sw.pdo_mappable);
        assert_eq!(sw.access, Access::ReadOnly);
        let v = eds.get(0x1018, 1).unwrap();
        assert_eq!(v.name, "Identity object.Vendor-ID");
        assert_eq!(eds.find("Vendor-ID"), Some(v));
        assert_eq!(eds.get(0x1018, 0).unwrap().access, Access::Const);
        assert_eq!(
            eds.get(0x1000, 0).unwrap().default.as_deref(),
            Some("0x00020192")
        );
        assert_eq!(eds.find("no such object"), None);
    }

    #[test]
    fn values_print_by_their_type() {
        let eds = Eds::parse(EDS, "drive.eds").unwrap();
        let ty = |name: &str| eds.find(name).unwrap().data_type;
        assert_eq!(
            ty("Position actual value")
                .format(&(-1234i32).to_le_bytes())
                .unwrap(),
            "-1234"
        );
        assert_eq!(ty("Statusword").format(&[0x37, 0x02]).unwrap(), "567");
        assert_eq!(
            ty("Manufacturer device name").format(b"hytask").unwrap(),
            "hytask"
        );
        let e = ty("Statusword").format(&[1, 2, 3]).unwrap_err();
        assert!(e.contains("2 byte(s)") && e.contains('3'), "{e}");
        assert_eq!(DataType::Domain.format(&[1, 0xab]).unwrap(), "01 ab");
    }

    #[test]
    fn errors_name_file_and_line() {
        let e = Eds::parse(
            "[6041]\nParameterName=Statusword\nDataType=0x0006\n",
            "x.eds",
        )
        .unwrap_err();
        assert_eq!(e.to_string(), "x.eds:1: [6041] has no accesstype");
        let e = Eds::parse("[1000]\nthis is not a key\n", "y.eds").unwrap_err();
        assert_eq!(e.line, 2);
        assert!(
            e.to_string().starts_with("y.eds:2: expected key=value"),
            "{e}"
        );
        let e = Eds::parse("[6041\n", "z.eds").unwrap_err();
        assert_eq!((e.line, e.origin.as_str()), (1, "z.eds"));
    }
}
