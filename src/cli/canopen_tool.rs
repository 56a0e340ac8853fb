//! `hytask canopen`: a small CANopen master tool on a SocketCAN interface, for machine
//! builders commissioning drives (and for the vcan interoperability tests): SDO read and
//! write (expedited and segmented), NMT commands, a scan of the nodes on the bus, and a
//! heartbeat watch. It uses the same sans-IO SDO client, NMT codec and heartbeat consumer as
//! the daemon's master, on a [`SocketCanBus`] filtered to the COB-IDs it needs. Not
//! realtime: it waits on the bus with short sleeps.

use anyhow::{bail, Context};
use hytask_hal::canopen::eds::{DataType, Eds};
use hytask_hal::canopen::heartbeat::{HeartbeatConsumer, HeartbeatEvent};
use hytask_hal::canopen::nmt::{NmtCommand, NmtState};
use hytask_hal::canopen::sdo::{SdoClient, SdoStep};
use hytask_hal::canopen::{CanOpenError, NodeId, COB_NMT};
use hytask_hal::socketcan::{IdFilter, SocketCanBus};
use hytask_hal::{CanBus, CanId};
use std::process::ExitCode;
use std::time::{Duration, Instant};

/// Arguments of `hytask canopen`.
#[derive(Debug, clap::Args)]
pub struct CanopenArgs {
    /// The SocketCAN interface (e.g. can0, vcan0).
    #[arg(long, global = true, default_value = "can0")]
    pub iface: String,
    /// How long to wait for an answer, ms (raise it on slow or emulated hosts).
    #[arg(long, global = true, default_value_t = 1000)]
    pub timeout_ms: u64,
    /// What to do.
    #[command(subcommand)]
    pub action: Action,
}

/// The `hytask canopen` actions.
#[derive(Debug, clap::Subcommand)]
pub enum Action {
    /// Read an object over SDO and print it.
    SdoRead {
        /// The server node (1..=127).
        #[arg(long)]
        node: u8,
        /// Object index, e.g. 0x1018; with --eds also an object name ("Statusword",
        /// "Identity object.Vendor-ID"), whose sub-index the EDS gives.
        object: String,
        /// Sub-index, e.g. 1 or 0x01.
        #[arg(value_parser = parse_u8, default_value = "0")]
        sub: u8,
        /// How to print the value (default: the EDS's data type, else hex).
        #[arg(long = "type", value_enum)]
        ty: Option<ValueType>,
        /// The node's EDS file (CiA 306): object names and data types.
        #[arg(long)]
        eds: Option<std::path::PathBuf>,
    },
    /// Write an object over SDO.
    SdoWrite {
        /// The server node (1..=127).
        #[arg(long)]
        node: u8,
        /// Object index, e.g. 0x6060.
        #[arg(value_parser = parse_u16)]
        index: u16,
        /// Sub-index.
        #[arg(value_parser = parse_u8)]
        sub: u8,
        /// The value (a number for integer types, text for `str`, bytes like `01 02` or
        /// `0102` for `hex`).
        value: String,
        /// The object's type.
        #[arg(long = "type", value_enum)]
        ty: ValueType,
    },
    /// Send an NMT command to one node or to all.
    Nmt {
        /// The command.
        #[arg(value_enum)]
        command: NmtArg,
        /// The node (all nodes when omitted).
        #[arg(long)]
        node: Option<u8>,
    },
    /// List the nodes that answer an SDO read of their device type (0x1000).
    Scan,
    /// Watch the heartbeats of nodes for a while; fails naming the node whose heartbeat
    /// stops (consumer time = --timeout-ms).
    Heartbeat {
        /// The nodes to watch, comma separated.
        #[arg(long, value_delimiter = ',', required = true)]
        nodes: Vec<u8>,
        /// How long to watch, ms.
        #[arg(long, default_value_t = 3000)]
        for_ms: u64,
    },
}

/// Value types of `sdo-read` / `sdo-write`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum ValueType {
    /// Raw bytes in hex.
    Hex,
    /// Text (VISIBLE_STRING).
    Str,
    /// UNSIGNED8..64, INTEGER8..64 (little-endian).
    U8,
    /// UNSIGNED16.
    U16,
    /// UNSIGNED32.
    U32,
    /// UNSIGNED64.
    U64,
    /// INTEGER8.
    I8,
    /// INTEGER16.
    I16,
    /// INTEGER32.
    I32,
    /// INTEGER64.
    I64,
}

/// NMT commands by name.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum NmtArg {
    /// Start (operational).
    Start,
    /// Stop.
    Stop,
    /// Enter pre-operational.
    Preop,
    /// Reset node.
    ResetNode,
    /// Reset communication.
    ResetComm,
}

fn parse_u32(s: &str) -> Result<u32, String> {
    let r = match s.strip_prefix("0x").or_else(|| s.strip_prefix("0X")) {
        Some(h) => u32::from_str_radix(h, 16),
        None => s.parse(),
    };
    r.map_err(|e| format!("{s:?}: {e}"))
}

fn parse_u16(s: &str) -> Result<u16, String> {
    u16::try_from(parse_u32(s)?).map_err(|_| format!("{s:?} does not fit 16 bits"))
}

fn parse_u8(s: &str) -> Result<u8, String> {
    u8::try_from(parse_u32(s)?).map_err(|_| format!("{s:?} does not fit 8 bits"))
}

/// The bytes of `value` as an object of type `ty`.
fn encode(value: &str, ty: ValueType) -> anyhow::Result<Vec<u8>> {
    let int = |bits: u32, signed: bool| -> anyhow::Result<Vec<u8>> {
        let v: i128 = match value.strip_prefix("0x") {
            Some(h) => i128::from_str_radix(h, 16)?,
            None => value.parse()?,
        };
        let (lo, hi) = if signed {
            (-(1i128 << (bits - 1)), (1i128 << (bits - 1)) - 1)
        } else {
            (0, (1i128 << bits) - 1)
        };
        if v < lo || v > hi {
            bail!("{value} is outside {lo}..={hi}");
        }
        Ok(v.to_le_bytes()[..(bits / 8) as usize].to_vec())
    };
    Ok(match ty {
        ValueType::Str => value.as_bytes().to_vec(),
        ValueType::Hex => {
            let h: String = value.chars().filter(|c| !c.is_whitespace()).collect();
            if !h.len().is_multiple_of(2) {
                bail!("{value:?}: an odd number of hex digits");
            }
            (0..h.len())
                .step_by(2)
                .map(|i| u8::from_str_radix(&h[i..i + 2], 16))
                .collect::<Result<_, _>>()
                .with_context(|| format!("{value:?} is not hex bytes"))?
        }
        ValueType::U8 => int(8, false)?,
        ValueType::U16 => int(16, false)?,
        ValueType::U32 => int(32, false)?,
        ValueType::U64 => int(64, false)?,
        ValueType::I8 => int(8, true)?,
        ValueType::I16 => int(16, true)?,
        ValueType::I32 => int(32, true)?,
        ValueType::I64 => int(64, true)?,
    })
}

/// `data` printed as type `ty`.
fn decode(data: &[u8], ty: ValueType) -> anyhow::Result<String> {
    let fixed = |n: usize| -> anyhow::Result<[u8; 8]> {
        if data.len() != n {
            bail!("the object has {} bytes, {ty:?} has {n}", data.len());
        }
        let mut b = [0u8; 8];
        b[..n].copy_from_slice(data);
        Ok(b)
    };
    let sext = |b: [u8; 8], n: usize| -> i64 {
        let shift = 64 - 8 * n as u32;
        (i64::from_le_bytes(b) << shift) >> shift
    };
    Ok(match ty {
        ValueType::Hex => data
            .iter()
            .map(|b| format!("{b:02x}"))
            .collect::<Vec<_>>()
            .join(" "),
        ValueType::Str => String::from_utf8_lossy(data).into_owned(),
        ValueType::U8 => u64::from_le_bytes(fixed(1)?).to_string(),
        ValueType::U16 => u64::from_le_bytes(fixed(2)?).to_string(),
        ValueType::U32 => u64::from_le_bytes(fixed(4)?).to_string(),
        ValueType::U64 => u64::from_le_bytes(fixed(8)?).to_string(),
        ValueType::I8 => sext(fixed(1)?, 1).to_string(),
        ValueType::I16 => sext(fixed(2)?, 2).to_string(),
        ValueType::I32 => sext(fixed(4)?, 4).to_string(),
        ValueType::I64 => sext(fixed(8)?, 8).to_string(),
    })
}

fn node(n: u8) -> anyhow::Result<NodeId> {
    NodeId::new(n).with_context(|| format!("--node {n}"))
}

fn sid(raw: u16) -> CanId {
    // All ids built here are CANopen predefined ids (below 0x800).
    CanId::standard(raw & 0x7FF).unwrap_or_else(|_| unreachable!())
}

/// Time since the tool started, the sans-IO layer's `now`.
struct Clock(Instant);

impl Clock {
    fn now(&self) -> Duration {
        self.0.elapsed()
    }
}

/// Runs SDO transfers started with `first` on each client to completion, concurrently.
/// Returns each client's result (value for an upload, empty for a download).
fn run_sdo(
    bus: &mut SocketCanBus,
    clock: &Clock,
    clients: &mut [(SdoClient, Option<anyhow::Result<Vec<u8>>>)],
) -> anyhow::Result<()> {
    while clients.iter().any(|(_, r)| r.is_none()) {
        let now = clock.now();
        let mut got_frame = false;
        while let Some(f) = bus.try_recv()? {
            got_frame = true;
            for (c, r) in clients.iter_mut().filter(|(_, r)| r.is_none()) {
                let step = c.on_frame(&f, now);
                settle(bus, step, r)?;
            }
        }
        for (c, r) in clients.iter_mut().filter(|(_, r)| r.is_none()) {
            if let Some(step) = c.poll(now) {
                settle(bus, step, r)?;
            }
        }
        if !got_frame {
            std::thread::sleep(Duration::from_millis(1));
        }
    }
    Ok(())
}

fn settle(
    bus: &mut SocketCanBus,
    step: SdoStep,
    result: &mut Option<anyhow::Result<Vec<u8>>>,
) -> anyhow::Result<()> {
    match step {
        SdoStep::Ignored => {}
        SdoStep::Send(f) => bus.try_send(&f)?,
        SdoStep::SendBlock(frames) => {
            for f in &frames {
                bus.try_send(f)?;
            }
        }
        SdoStep::Downloaded => *result = Some(Ok(Vec::new())),
        SdoStep::Uploaded(v) => *result = Some(Ok(v)),
        SdoStep::BlockUploaded { value, confirm } => {
            bus.try_send(&confirm)?;
            *result = Some(Ok(value));
        }
        SdoStep::Failed { error, abort } => {
            if let Some(a) = abort {
                bus.try_send(&a)?;
            }
            *result = Some(Err(error.into()));
        }
    }
    Ok(())
}

/// One SDO transfer with `node`: an upload, or a download of `write`.
fn sdo(
    a: &CanopenArgs,
    n: NodeId,
    index: u16,
    sub: u8,
    write: Option<&[u8]>,
) -> anyhow::Result<Vec<u8>> {
    let mut bus = SocketCanBus::open(&a.iface)?;
    bus.set_filters(&[IdFilter::exact(n.cob(0x580))])?;
    let clock = Clock(Instant::now());
    let mut c = SdoClient::with_timeout(n, Duration::from_millis(a.timeout_ms));
    let first = match write {
        Some(d) => c.download(index, sub, d, clock.now())?,
        // Block upload where the node offers it (a long value goes in one sub-block);
        // the client falls back to segmented when the node refuses.
        None => c.upload_block(index, sub, clock.now())?,
    };
    bus.try_send(&first)?;
    let mut clients = [(c, None)];
    run_sdo(&mut bus, &clock, &mut clients)?;
    let [(_, r)] = clients;
    r.unwrap_or_else(|| unreachable!("run_sdo returns when every transfer settled"))
}

fn scan(a: &CanopenArgs) -> anyhow::Result<ExitCode> {
    let mut bus = SocketCanBus::open(&a.iface)?;
    bus.set_filters(&[IdFilter::masked(sid(0x580), 0x780)])?;
    let clock = Clock(Instant::now());
    let mut clients = Vec::with_capacity(127);
    for id in 1..=127u8 {
        let n = node(id)?;
        let mut c = SdoClient::with_timeout(n, Duration::from_millis(a.timeout_ms));
        bus.try_send(&c.upload(0x1000, 0, clock.now())?)?;
        clients.push((c, None));
    }
    run_sdo(&mut bus, &clock, &mut clients)?;
    let mut found = 0;
    for (c, r) in &clients {
        match r {
            Some(Ok(v)) => {
                found += 1;
                println!(
                    "node {}: device type {}",
                    c.node(),
                    decode(v, ValueType::Hex)?
                );
            }
            // A node that answers with an abort exists too.
            Some(Err(e))
                if !matches!(
                    e.downcast_ref::<CanOpenError>(),
                    Some(CanOpenError::SdoTimeout { .. })
                ) =>
            {
                found += 1;
                println!("node {}: {e}", c.node());
            }
            _ => {}
        }
    }
    println!("{found} node(s) on {}", a.iface);
    Ok(ExitCode::SUCCESS)
}

fn heartbeat(a: &CanopenArgs, nodes: &[u8], for_ms: u64) -> anyhow::Result<ExitCode> {
    let mut bus = SocketCanBus::open(&a.iface)?;
    bus.set_filters(&[IdFilter::masked(sid(0x700), 0x780)])?;
    let clock = Clock(Instant::now());
    let mut hb = HeartbeatConsumer::default();
    for &n in nodes {
        hb.watch(node(n)?, Duration::from_millis(a.timeout_ms), clock.now());
    }
    let end = Duration::from_millis(for_ms);
    while clock.now() < end {
        while let Some(f) = bus.try_recv()? {
            match hb.on_frame(&f, clock.now()) {
                Some(HeartbeatEvent::StateChanged { node, to, .. }) => {
                    println!("node {node}: {to}");
                }
                Some(HeartbeatEvent::BootUp(node)) => println!("node {node}: boot-up"),
                Some(HeartbeatEvent::Recovered(node)) => println!("node {node}: heard again"),
                None => {}
            }
        }
        if let Some(e) = hb.check(clock.now()) {
            bail!(e);
        }
        std::thread::sleep(Duration::from_millis(2));
    }
    for &n in nodes {
        let s = hb.state(node(n)?);
        println!(
            "node {n}: alive, {}",
            s.map_or("state unknown".to_string(), |s: NmtState| s.to_string())
        );
    }
    Ok(ExitCode::SUCCESS)
}

fn load_eds(path: &std::path::Path) -> anyhow::Result<Eds> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("reading the EDS file {}", path.display()))?;
    Ok(Eds::parse(&text, &path.display().to_string())?)
}

/// The object `object` names (an index, or with an EDS a name) and its EDS data type.
fn resolve(
    object: &str,
    sub: u8,
    eds: Option<&Eds>,
) -> anyhow::Result<(u16, u8, Option<DataType>)> {
    if let Ok(index) = parse_u16(object) {
        return Ok((
            index,
            sub,
            eds.and_then(|e| e.get(index, sub)).map(|e| e.data_type),
        ));
    }
    let Some(eds) = eds else {
        bail!("{object:?} is not an object index (an object name needs --eds)");
    };
    match eds.find(object) {
        Some(e) => Ok((e.index, e.sub, Some(e.data_type))),
        None => bail!("no object named {object:?} in the EDS file"),
    }
}

/// Runs `hytask canopen`.
pub fn run(a: CanopenArgs) -> anyhow::Result<ExitCode> {
    match &a.action {
        Action::SdoRead {
            node: n,
            object,
            sub,
            ty,
            eds,
        } => {
            let eds = eds.as_deref().map(load_eds).transpose()?;
            let (index, sub, eds_type) = resolve(object, *sub, eds.as_ref())?;
            let v = sdo(&a, node(*n)?, index, sub, None)?;
            match (ty, eds_type) {
                (Some(t), _) => println!("{}", decode(&v, *t)?),
                (None, Some(t)) => println!(
                    "{}",
                    t.format(&v)
                        .map_err(|e| anyhow::anyhow!("{index:04X}:{sub:02X}: {e}"))?
                ),
                (None, None) => println!("{}", decode(&v, ValueType::Hex)?),
            }
        }
        Action::SdoWrite {
            node: n,
            index,
            sub,
            value,
            ty,
        } => {
            let data = encode(value, *ty)?;
            sdo(&a, node(*n)?, *index, *sub, Some(&data))?;
        }
        Action::Nmt { command, node: n } => {
            let cmd = match command {
                NmtArg::Start => NmtCommand::Start,
                NmtArg::Stop => NmtCommand::Stop,
                NmtArg::Preop => NmtCommand::EnterPreOperational,
                NmtArg::ResetNode => NmtCommand::ResetNode,
                NmtArg::ResetComm => NmtCommand::ResetCommunication,
            };
            let target = n.map(node).transpose()?;
            let mut bus = SocketCanBus::open(&a.iface)?;
            bus.set_filters(&[IdFilter::exact(sid(COB_NMT))])?;
            bus.try_send(&cmd.frame(target))?;
        }
        Action::Scan => return scan(&a),
        Action::Heartbeat { nodes, for_ms } => return heartbeat(&a, nodes, *for_ms),
    }
    Ok(ExitCode::SUCCESS)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn objects_resolve_by_index_or_by_eds_name_with_their_type() {
        let eds = Eds::parse(
            "[6041]\nParameterName=Statusword\nDataType=0x0006\nAccessType=ro\n\
             [1018]\nParameterName=Identity object\nObjectType=0x9\n\
             [1018sub1]\nParameterName=Vendor-ID\nDataType=0x0007\nAccessType=ro\n",
            "drive.eds",
        )
        .unwrap();
        let (i, s, t) = resolve("Statusword", 0, Some(&eds)).unwrap();
        assert_eq!((i, s, t), (0x6041, 0, Some(DataType::Unsigned(2))));
        assert_eq!(t.unwrap().format(&[0x37, 0x02]).unwrap(), "567");
        let (i, s, _) = resolve("identity object.vendor-id", 0, Some(&eds)).unwrap();
        assert_eq!((i, s), (0x1018, 1));
        assert_eq!(
            resolve("0x1018", 1, Some(&eds)).unwrap().2,
            Some(DataType::Unsigned(4))
        );
        assert_eq!(resolve("0x2000", 1, None).unwrap(), (0x2000, 1, None));
        let e = resolve("Statusword", 0, None).unwrap_err().to_string();
        assert!(e.contains("needs --eds"), "{e}");
        let e = resolve("Controlword", 0, Some(&eds))
            .unwrap_err()
            .to_string();
        assert!(e.contains("no object named \"Controlword\""), "{e}");
    }

    #[test]
    fn values_encode_and_decode_by_type() {
        assert_eq!(encode("0x1234", ValueType::U16).unwrap(), vec![0x34, 0x12]);
        assert_eq!(
            encode("-2", ValueType::I32).unwrap(),
            vec![0xFE, 0xFF, 0xFF, 0xFF]
        );
        assert_eq!(encode("01 0a", ValueType::Hex).unwrap(), vec![1, 10]);
        assert_eq!(encode("abc", ValueType::Str).unwrap(), b"abc".to_vec());
        assert!(encode("256", ValueType::U8).is_err());
        assert!(encode("-129", ValueType::I8).is_err());
        assert_eq!(
            decode(&[0xFE, 0xFF, 0xFF, 0xFF], ValueType::I32).unwrap(),
            "-2"
        );
        assert_eq!(
            decode(&[0x92, 0x01, 0x02, 0], ValueType::U32).unwrap(),
            "131474"
        );
        assert_eq!(decode(&[1, 0xab], ValueType::Hex).unwrap(), "01 ab");
        assert!(decode(&[1, 2], ValueType::U32).is_err());
    }

    #[test]
    fn indexes_parse_hex_and_decimal() {
        assert_eq!(parse_u16("0x1018"), Ok(0x1018));
        assert_eq!(parse_u8("3"), Ok(3));
        assert!(parse_u8("0x100").is_err());
    }
}
