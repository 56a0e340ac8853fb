//! The Modbus simulator's engine: the units of a device map, their tables, named points,
//! scripted inputs and fault injection, served over TCP and RTU. `hytask modbus-sim` puts a
//! command line around it; tests and benchmarks run it in-process.
//!
//! Requests are handled by the sans-IO [`Tables::handle`]; the transport here only frames
//! them and applies the injected faults: a delay before every answer, dropping requests
//! (no answer: the client times out), an exception code for every request, and garbling
//! (bad CRC, short response, wrong unit id).

use crate::config::{IoConfig, IoKind};
use hytask_hal::modbus::server::{
    parse_rtu_request, parse_tcp_request, rtu_frame, tcp_frame, RtuRequest, Tables,
};
use hytask_hal::modbus::PointSpec;
use std::collections::BTreeMap;
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};
use tokio::io::{AsyncReadExt, AsyncWriteExt};

/// A named point of a simulated unit.
#[derive(Debug, Clone)]
pub struct SimPoint {
    /// Channel name.
    pub name: String,
    /// Unit id.
    pub unit: u8,
    /// Place.
    pub spec: PointSpec,
    /// True for the machine's outputs (coils, holding registers it writes).
    pub output: bool,
}

/// How answers are garbled.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Garble {
    /// Correct answers.
    #[default]
    None,
    /// RTU: a wrong CRC (TCP: same as `Short`).
    Crc,
    /// The answer's last byte is cut.
    Short,
    /// The answer carries another unit id.
    Unit,
    /// A well-formed read answer with one item fewer than asked for (byte count adjusted).
    Count,
    /// A well-formed answer with another function code than the request's.
    Function,
    /// A write's answer echoes another address.
    Echo,
}

/// Injected faults.
#[derive(Debug, Clone, Copy, Default)]
pub struct Faults {
    /// Delay before each answer.
    pub delay: Duration,
    /// Do not answer.
    pub drop: bool,
    /// Answer every request with this exception code.
    pub exception: Option<u8>,
    /// Garble answers.
    pub garble: Garble,
}

/// An input that follows an output (a VFD's at-speed after its run coil).
#[derive(Debug, Clone)]
struct Follow {
    input: usize,
    output: usize,
    delay: Duration,
    since: Option<Instant>,
}

/// A scripted toggle of an input.
#[derive(Debug, Clone)]
struct Toggle {
    point: usize,
    period: Duration,
    next: Instant,
}

/// The simulator's state.
#[derive(Debug)]
pub struct SimState {
    /// Tables by unit id.
    pub units: BTreeMap<u8, Tables>,
    /// Named points.
    pub points: Vec<SimPoint>,
    /// Faults in force.
    pub faults: Faults,
    /// Requests answered (for benchmarks and tests).
    pub requests: u64,
    /// When a client's write last changed each point (by index in `points`; benchmarks).
    changed: Vec<Option<Instant>>,
    follows: Vec<Follow>,
    toggles: Vec<Toggle>,
    /// Bumped by `close`: connections of an older generation are closed.
    generation: u64,
}

/// Shared simulator state.
#[derive(Debug, Clone)]
pub struct Sim(Arc<Mutex<SimState>>);

/// A user error in a command or map.
#[derive(Debug, thiserror::Error)]
pub enum SimError {
    /// No point of that name.
    #[error("no point named {0:?}")]
    NoPoint(String),
    /// A bad argument.
    #[error("{0}")]
    Usage(String),
}

impl Sim {
    /// A simulator serving the Modbus devices among `io` (sim devices are skipped), with
    /// tables of at least `size` items per unit.
    pub fn from_io(io: &[IoConfig], size: usize) -> Result<Sim, SimError> {
        let mut points = Vec::new();
        for (i, dev) in io.iter().enumerate() {
            if dev.backend == crate::config::IoBackend::Sim {
                continue;
            }
            let key = IoConfig::key(i, &dev.name);
            let unit = dev.unit_id.unwrap_or(1);
            for kind in IoKind::ALL {
                let specs = crate::config::modbus::specs(dev, kind)
                    .map_err(|(k, m)| SimError::Usage(format!("{key}.{k}: {m}")))?;
                for (name, spec) in dev.names(kind).into_iter().zip(specs) {
                    points.push(SimPoint {
                        name: name.to_string(),
                        unit,
                        spec,
                        output: matches!(kind, IoKind::DigitalOutput | IoKind::AnalogOutput),
                    });
                }
            }
        }
        let mut units: BTreeMap<u8, Tables> = BTreeMap::new();
        for p in &points {
            let need = usize::from(p.spec.address) + usize::from(p.spec.width());
            let t = units.entry(p.unit).or_insert_with(|| Tables::new(size));
            if t.holding.len() < need {
                *t = Tables::new(need.max(size));
            }
        }
        if units.is_empty() {
            return Err(SimError::Usage("the map has no Modbus device".into()));
        }
        Ok(Sim(Arc::new(Mutex::new(SimState {
            units,
            changed: vec![None; points.len()],
            points,
            faults: Faults::default(),
            requests: 0,
            follows: Vec::new(),
            toggles: Vec::new(),
            generation: 0,
        }))))
    }

    /// Locks the state (poisoning is ignored: the state stays usable).
    pub fn lock(&self) -> MutexGuard<'_, SimState> {
        self.0.lock().unwrap_or_else(|p| p.into_inner())
    }
}

impl SimState {
    fn find(&self, name: &str) -> Result<usize, SimError> {
        self.points
            .iter()
            .position(|p| p.name == name)
            .ok_or_else(|| SimError::NoPoint(name.to_string()))
    }

    /// Sets a point's raw value (digital: 0/1, the electrical level).
    pub fn set(&mut self, name: &str, value: f64) -> Result<(), SimError> {
        let i = self.find(name)?;
        self.set_index(i, value);
        Ok(())
    }

    fn set_index(&mut self, i: usize, value: f64) {
        let p = self.points[i].clone();
        let Some(t) = self.units.get_mut(&p.unit) else {
            return;
        };
        let (words, n) = p.spec.encode(value);
        if let hytask_hal::modbus::DataType::Bit(b) = p.spec.data_type {
            let cur = t.get(p.spec.table, p.spec.address).unwrap_or(0);
            t.set(p.spec.table, p.spec.address, (cur & !(1 << b)) | words[0]);
            return;
        }
        for (k, w) in words.iter().take(n).enumerate() {
            t.set(p.spec.table, p.spec.address + k as u16, *w);
        }
    }

    /// A point's raw value.
    pub fn get(&self, name: &str) -> Result<f64, SimError> {
        Ok(self.get_index(self.find(name)?))
    }

    fn get_index(&self, i: usize) -> f64 {
        let p = &self.points[i];
        let Some(t) = self.units.get(&p.unit) else {
            return 0.0;
        };
        let raw: Vec<u16> = (0..p.spec.width())
            .map(|k| t.get(p.spec.table, p.spec.address + k).unwrap_or(0))
            .collect();
        p.spec.decode(&raw)
    }

    /// When a client's write last changed the point `name` (`None`: never).
    pub fn changed_at(&self, name: &str) -> Result<Option<Instant>, SimError> {
        Ok(self.changed[self.find(name)?])
    }

    /// Every point with its value, in map order.
    pub fn values(&self) -> Vec<(String, bool, f64)> {
        (0..self.points.len())
            .map(|i| {
                (
                    self.points[i].name.clone(),
                    self.points[i].output,
                    self.get_index(i),
                )
            })
            .collect()
    }

    /// Input `input` follows output `output` after `delay` (on at once when off).
    pub fn follow(&mut self, input: &str, output: &str, delay: Duration) -> Result<(), SimError> {
        let (input, output) = (self.find(input)?, self.find(output)?);
        self.follows.retain(|f| f.input != input);
        self.follows.push(Follow {
            input,
            output,
            delay,
            since: None,
        });
        Ok(())
    }

    /// Toggles `name` every `period` (zero: stop).
    pub fn toggle(&mut self, name: &str, period: Duration) -> Result<(), SimError> {
        let point = self.find(name)?;
        self.toggles.retain(|t| t.point != point);
        if !period.is_zero() {
            self.toggles.push(Toggle {
                point,
                period,
                next: Instant::now() + period,
            });
        }
        Ok(())
    }

    /// Closes every open TCP connection.
    pub fn close_connections(&mut self) {
        self.generation += 1;
    }

    /// Runs the scripts (follows, toggles) up to `now`.
    pub fn tick(&mut self, now: Instant) {
        for k in 0..self.follows.len() {
            let f = self.follows[k].clone();
            let on = self.get_index(f.output) != 0.0;
            let since = if on { f.since.or(Some(now)) } else { None };
            self.follows[k].since = since;
            let level = since.is_some_and(|s| now.duration_since(s) >= f.delay);
            self.set_index(f.input, f64::from(u8::from(level)));
        }
        for k in 0..self.toggles.len() {
            if self.toggles[k].next <= now {
                let p = self.toggles[k].point;
                self.toggles[k].next = now + self.toggles[k].period;
                let v = self.get_index(p);
                self.set_index(p, f64::from(u8::from(v == 0.0)));
            }
        }
    }

    /// Handles one request PDU for `unit`: `None` when the simulator stays silent (no such
    /// unit on RTU, dropping).
    fn answer(&mut self, unit: u8, pdu: &[u8], rtu: bool) -> Option<Vec<u8>> {
        if self.faults.drop {
            return None;
        }
        let fc = pdu.first().copied().unwrap_or(0);
        if let Some(code) = self.faults.exception {
            return Some(vec![fc | 0x80, code]);
        }
        let Some(t) = self.units.get_mut(&unit) else {
            // A gateway's "target device failed to respond"; a serial unit stays silent.
            return (!rtu).then(|| vec![fc | 0x80, 11]);
        };
        self.requests += 1;
        if !matches!(fc, 5 | 6 | 15 | 16 | 22 | 23) {
            return Some(t.handle(pdu));
        }
        let of_unit: Vec<usize> = (0..self.points.len())
            .filter(|&i| self.points[i].unit == unit)
            .collect();
        let before: Vec<f64> = of_unit.iter().map(|&i| self.get_index(i)).collect();
        let answer = self.units.get_mut(&unit).map(|t| t.handle(pdu));
        let now = Instant::now();
        for (&i, v) in of_unit.iter().zip(before) {
            if self.get_index(i) != v {
                self.changed[i] = Some(now);
            }
        }
        answer
    }
}

/// Garbles of the PDU, before framing: the frame stays well formed.
fn garble_pdu(mut pdu: Vec<u8>, g: Garble) -> Vec<u8> {
    let fc = pdu.first().copied().unwrap_or(0);
    match g {
        Garble::Count if matches!(fc, 1..=4) && pdu.len() >= 2 => {
            // Bits come 8 to a byte, registers 2 bytes each.
            let cut = if fc <= 2 { 1 } else { 2 };
            if pdu[1] >= cut {
                pdu[1] -= cut;
                pdu.truncate(pdu.len() - usize::from(cut));
            }
        }
        Garble::Echo if matches!(fc, 5 | 6 | 15 | 16 | 22) && pdu.len() >= 3 => pdu[2] ^= 1,
        Garble::Function => {
            pdu[0] = match fc {
                1 => 2,
                2 => 1,
                3 => 4,
                4 => 3,
                f => f.wrapping_add(0x10),
            };
        }
        _ => {}
    }
    pdu
}

fn garble(mut frame: Vec<u8>, g: Garble, rtu: bool, unit_at: usize) -> Vec<u8> {
    match g {
        Garble::None | Garble::Count | Garble::Function | Garble::Echo => {}
        Garble::Crc if rtu => {
            if let Some(b) = frame.last_mut() {
                *b ^= 0x5A;
            }
        }
        Garble::Crc | Garble::Short => {
            frame.pop();
        }
        Garble::Unit => {
            if let Some(u) = frame.get_mut(unit_at) {
                *u = u.wrapping_add(1);
            }
            if rtu {
                let n = frame.len() - 2;
                let crc = hytask_hal::modbus::server::crc16(&frame[..n]);
                frame.truncate(n);
                frame.extend_from_slice(&crc.to_le_bytes());
            }
        }
    }
    frame
}

/// Serves Modbus TCP on `listener` until the process ends.
pub async fn serve_tcp(sim: Sim, listener: tokio::net::TcpListener) -> std::io::Result<()> {
    loop {
        let (stream, _) = listener.accept().await?;
        let _ = stream.set_nodelay(true);
        let sim = sim.clone();
        tokio::spawn(async move {
            if let Err(e) = tcp_connection(sim, stream).await {
                tracing::debug!("modbus-sim: connection ended: {e}");
            }
        });
    }
}

async fn tcp_connection(sim: Sim, mut stream: tokio::net::TcpStream) -> std::io::Result<()> {
    let generation = sim.lock().generation;
    let mut buf = Vec::with_capacity(512);
    let mut chunk = [0u8; 512];
    loop {
        let n = tokio::select! {
            r = stream.read(&mut chunk) => r?,
            () = tokio::time::sleep(Duration::from_millis(20)) => {
                if sim.lock().generation != generation {
                    return Ok(());
                }
                continue;
            }
        };
        if n == 0 || sim.lock().generation != generation {
            return Ok(());
        }
        buf.extend_from_slice(&chunk[..n]);
        loop {
            let (req, used) = match parse_tcp_request(&buf) {
                Ok(Some(r)) => r,
                Ok(None) => break,
                Err(e) => {
                    return Err(std::io::Error::new(std::io::ErrorKind::InvalidData, e));
                }
            };
            buf.drain(..used);
            let (answer, faults) = {
                let mut s = sim.lock();
                (s.answer(req.unit, &req.pdu, false), s.faults)
            };
            if !faults.delay.is_zero() {
                tokio::time::sleep(faults.delay).await;
            }
            if let Some(pdu) = answer {
                let pdu = garble_pdu(pdu, faults.garble);
                let frame = tcp_frame(req.transaction, req.unit, &pdu);
                stream
                    .write_all(&garble(frame, faults.garble, false, 6))
                    .await?;
            }
        }
    }
}

/// Serves Modbus RTU on an open serial stream (or pty) until it fails.
pub async fn serve_rtu<S>(sim: Sim, mut port: S) -> std::io::Result<()>
where
    S: tokio::io::AsyncRead + tokio::io::AsyncWrite + Unpin,
{
    let mut buf: Vec<u8> = Vec::with_capacity(512);
    let mut chunk = [0u8; 512];
    loop {
        // A silence of 20 ms ends a frame we cannot size (unknown function, garbage).
        let read = tokio::time::timeout(Duration::from_millis(20), port.read(&mut chunk)).await;
        match read {
            Err(_) => {
                // Whatever is left after a silence (an unknown function, a cut frame) is
                // noise: a real server resynchronises the same way.
                buf.clear();
                continue;
            }
            Ok(r) => {
                let n = r?;
                if n == 0 {
                    return Ok(());
                }
                buf.extend_from_slice(&chunk[..n]);
            }
        }
        loop {
            match parse_rtu_request(&buf) {
                RtuRequest::Incomplete | RtuRequest::Unknown => break,
                RtuRequest::BadCrc { len } => {
                    tracing::debug!("modbus-sim: RTU frame with a bad CRC dropped");
                    buf.drain(..len);
                }
                RtuRequest::Frame { len, unit, pdu } => {
                    buf.drain(..len);
                    let (answer, faults) = {
                        let mut s = sim.lock();
                        (s.answer(unit, &pdu, true), s.faults)
                    };
                    if !faults.delay.is_zero() {
                        tokio::time::sleep(faults.delay).await;
                    }
                    if let Some(pdu) = answer {
                        let pdu = garble_pdu(pdu, faults.garble);
                        let frame = rtu_frame(unit, &pdu);
                        port.write_all(&garble(frame, faults.garble, true, 0))
                            .await?;
                        port.flush().await?;
                    }
                }
            }
        }
    }
}

/// Runs the scripts every millisecond and calls `changed` with every output whose value
/// changed (and every point once at start).
pub async fn watch(sim: Sim, mut changed: impl FnMut(&str, f64)) {
    let mut last: Vec<Option<f64>> = Vec::new();
    loop {
        let values = {
            let mut s = sim.lock();
            s.tick(Instant::now());
            s.values()
        };
        last.resize(values.len(), None);
        for (k, (name, output, v)) in values.into_iter().enumerate() {
            if output && last[k] != Some(v) {
                changed(&name, v);
            }
            last[k] = Some(v);
        }
        tokio::time::sleep(Duration::from_millis(1)).await;
    }
}
