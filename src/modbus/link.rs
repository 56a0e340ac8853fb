//! The poller of one link: a non-realtime task that owns the connection (TCP or RTU),
//! polls each device (unit) on it at the device's rate with the merged reads of its map,
//! writes outputs when they change and refreshes them periodically, publishes everything
//! into the devices' [`Image`]s, and reconnects with backoff when the link fails.
//!
//! Fault policy: an exception answer marks the points of that request bad and keeps the
//! connection (the device is there); a timeout, a transport error or a malformed answer
//! marks every point of the link bad and reconnects (a late or garbled answer would
//! otherwise desynchronise the stream). Every change of health is reported once, as a
//! [`LinkEvent`].

use super::event::LinkEvent;
pub use super::stats::TxStats;
use hytask_hal::modbus::{
    plan_reads, Backoff, DataType, FaultKind, Image, InputCell, OutputCell, PointSpec, ReadBlock,
    Table,
};
use std::sync::mpsc::Sender;
use std::sync::Arc;
use std::time::{Duration, Instant};
use tokio::time::timeout as within;
use tokio_modbus::client::{Client, Context};
use tokio_modbus::slave::{Slave, SlaveContext};
use tokio_modbus::{Request, Response};

/// Where a link goes.
#[derive(Debug, Clone, PartialEq)]
pub enum Endpoint {
    /// Modbus TCP to `host:port`.
    Tcp(String),
    /// Modbus RTU on a serial device.
    Rtu {
        /// Device path.
        path: String,
        /// Baud rate.
        baud: u32,
        /// Parity.
        parity: tokio_serial::Parity,
        /// Stop bits.
        stop_bits: tokio_serial::StopBits,
    },
}

/// A named input point of a device.
#[derive(Debug, Clone)]
pub struct InputPoint {
    /// Channel name.
    pub name: String,
    /// Digital (true) or analog.
    pub digital: bool,
    /// Index in the image's digital or analog inputs.
    pub index: usize,
    /// Place on the device.
    pub spec: PointSpec,
    /// Whether its loss stops the machine.
    pub critical: bool,
}

/// A named output point of a device.
#[derive(Debug, Clone)]
pub struct OutputPoint {
    /// Channel name.
    pub name: String,
    /// Digital (true) or analog.
    pub digital: bool,
    /// Index in the image's digital or analog outputs.
    pub index: usize,
    /// Place on the device.
    pub spec: PointSpec,
}

/// One device (unit) on a link.
#[derive(Debug, Clone)]
pub struct UnitConfig {
    /// `[[io]]` name.
    pub device: String,
    /// Unit id.
    pub unit: u8,
    /// Shared with the machine's [`hytask_hal::modbus::ModbusIo`].
    pub image: Arc<Image>,
    /// Inputs to read.
    pub inputs: Vec<InputPoint>,
    /// Outputs to write.
    pub outputs: Vec<OutputPoint>,
    /// Poll period.
    pub poll: Duration,
    /// Output refresh period (`None`: only on change).
    pub refresh: Option<Duration>,
    /// Unused items a read may span.
    pub max_gap: u16,
}

/// A link and its devices.
#[derive(Debug, Clone)]
pub struct LinkConfig {
    /// Name used in events (`tcp:host:port`, `rtu:/dev/...`).
    pub name: String,
    /// Where.
    pub endpoint: Endpoint,
    /// Answer timeout per transaction (also the connect timeout).
    pub timeout: Duration,
    /// Longest reconnect wait.
    pub max_backoff: Duration,
    /// Devices.
    pub units: Vec<UnitConfig>,
}

/// Why a transaction failed, and whether the connection survives it.
struct TxError {
    fault: FaultKind,
    reconnect: bool,
}

fn tx<T>(r: Result<tokio_modbus::Result<T>, tokio::time::error::Elapsed>) -> Result<T, TxError> {
    match r {
        Err(_) => Err(TxError {
            fault: FaultKind::Timeout,
            reconnect: true,
        }),
        Ok(Err(tokio_modbus::Error::Transport(e))) => Err(TxError {
            fault: if e.kind() == std::io::ErrorKind::TimedOut {
                FaultKind::Timeout
            } else {
                FaultKind::Disconnected(e.to_string())
            },
            reconnect: true,
        }),
        Ok(Err(tokio_modbus::Error::Protocol(e))) => Err(TxError {
            fault: FaultKind::Protocol(e.to_string()),
            reconnect: true,
        }),
        Ok(Ok(Err(code))) => Err(TxError {
            fault: FaultKind::Exception(u8::from(code)),
            reconnect: false,
        }),
        Ok(Ok(Ok(v))) => Ok(v),
    }
}

/// Per-unit poll state.
struct UnitState {
    cfg: UnitConfig,
    reads: Vec<ReadBlock>,
    next_poll: Instant,
    next_refresh: Option<Instant>,
    /// The fault the unit is in (reported once), `None` when healthy.
    fault: Option<FaultKind>,
    /// Points currently bad (by input index in `cfg.inputs`).
    bad: Vec<bool>,
    /// The device refused an output write (reported once; retried at the poll rate, not
    /// as soon as possible, until a write succeeds).
    out_fault: Option<FaultKind>,
}

impl UnitState {
    fn new(cfg: UnitConfig) -> UnitState {
        let specs: Vec<Option<PointSpec>> = cfg.inputs.iter().map(|p| Some(p.spec)).collect();
        let reads = plan_reads(&specs, cfg.max_gap);
        let now = Instant::now();
        UnitState {
            bad: vec![false; cfg.inputs.len()],
            next_refresh: cfg.refresh.map(|r| now + r),
            reads,
            next_poll: now,
            fault: None,
            out_fault: None,
            cfg,
        }
    }

    fn input_cell(&self, p: &InputPoint) -> &InputCell {
        let img = &self.cfg.image;
        if p.digital {
            &img.di[p.index]
        } else {
            &img.ai[p.index]
        }
    }

    fn output_cell(&self, p: &OutputPoint) -> &OutputCell {
        let img = &self.cfg.image;
        if p.digital {
            &img.dout[p.index]
        } else {
            &img.ao[p.index]
        }
    }
}

/// The link's state machine around a connection.
pub struct Link {
    name: String,
    endpoint: Endpoint,
    timeout: Duration,
    backoff: Backoff,
    units: Vec<UnitState>,
    events: Sender<LinkEvent>,
    stats: Arc<TxStats>,
}

impl Link {
    /// A link ready to run.
    pub fn new(cfg: LinkConfig, events: Sender<LinkEvent>) -> Link {
        let min = cfg
            .units
            .iter()
            .map(|u| u.poll)
            .min()
            .unwrap_or(Duration::from_millis(10))
            .max(Duration::from_millis(10));
        Link {
            name: cfg.name,
            endpoint: cfg.endpoint,
            timeout: cfg.timeout,
            backoff: Backoff::new(min, cfg.max_backoff),
            units: cfg.units.into_iter().map(UnitState::new).collect(),
            events,
            stats: Arc::default(),
        }
    }

    /// The link's transaction statistics.
    pub fn stats(&self) -> Arc<TxStats> {
        self.stats.clone()
    }

    fn closed(&self) -> bool {
        self.units.iter().all(|u| u.cfg.image.is_closed())
    }

    async fn connect(&self) -> Result<Context, FaultKind> {
        let first = self.units.first().map_or(1, |u| u.cfg.unit);
        let fut = async {
            match &self.endpoint {
                Endpoint::Tcp(addr) => {
                    let sa = tokio::net::lookup_host(addr.as_str())
                        .await?
                        .next()
                        .ok_or_else(|| {
                            std::io::Error::new(
                                std::io::ErrorKind::NotFound,
                                format!("{addr} resolves to no address"),
                            )
                        })?;
                    let stream = tokio::net::TcpStream::connect(sa).await?;
                    stream.set_nodelay(true)?;
                    Ok::<_, std::io::Error>(tokio_modbus::client::tcp::attach_slave(
                        stream,
                        Slave(first),
                    ))
                }
                Endpoint::Rtu {
                    path,
                    baud,
                    parity,
                    stop_bits,
                } => {
                    use tokio_serial::SerialPortBuilderExt;
                    let port = tokio_serial::new(path, *baud)
                        .parity(*parity)
                        .stop_bits(*stop_bits)
                        .open_native_async()
                        .map_err(std::io::Error::from)?;
                    Ok(tokio_modbus::client::rtu::attach_slave(port, Slave(first)))
                }
            }
        };
        match tokio::time::timeout(self.timeout.max(Duration::from_millis(500)), fut).await {
            Err(_) => Err(FaultKind::Timeout),
            Ok(Err(e)) => Err(FaultKind::Disconnected(e.to_string())),
            Ok(Ok(ctx)) => Ok(ctx),
        }
    }

    /// Runs until every device on the link is dropped by the machine.
    pub async fn run(mut self) {
        while !self.closed() {
            let mut ctx = match self.connect().await {
                Ok(c) => c,
                Err(f) => {
                    self.all_bad(&f);
                    self.wait_backoff().await;
                    continue;
                }
            };
            self.backoff.reset();
            for u in &self.units {
                // Whatever the device had before, it gets the commanded outputs again.
                for o in &u.cfg.outputs {
                    u.output_cell(o).invalidate();
                }
            }
            if let Err(f) = self.connected(&mut ctx).await {
                self.all_bad(&f);
                let _ = ctx.disconnect().await;
                self.wait_backoff().await;
            }
        }
    }

    async fn wait_backoff(&mut self) {
        let until = Instant::now() + self.backoff.next_delay();
        while Instant::now() < until && !self.closed() {
            let left = until.saturating_duration_since(Instant::now());
            tokio::time::sleep(left.min(Duration::from_millis(50))).await;
        }
    }

    /// Polls while the connection holds; returns the fault that broke it.
    async fn connected(&mut self, ctx: &mut Context) -> Result<(), FaultKind> {
        loop {
            if self.closed() {
                return Ok(());
            }
            let mut next = Instant::now() + Duration::from_millis(50);
            for k in 0..self.units.len() {
                let now = Instant::now();
                let due = self.units[k].next_poll <= now;
                let pending = self.units[k]
                    .cfg
                    .outputs
                    .iter()
                    .any(|o| self.units[k].output_cell(o).pending().is_some());
                let retry_later = self.units[k].out_fault.is_some();
                if due || (pending && !retry_later) {
                    self.poll_unit(k, ctx, due).await?;
                }
                next = next.min(self.units[k].next_poll);
            }
            // Outputs changed by the machine are picked up within a millisecond.
            let wait = next.saturating_duration_since(Instant::now());
            // Work due now: go on (every transaction awaits the network, which yields).
            if !wait.is_zero() {
                tokio::time::sleep(wait.min(Duration::from_millis(1))).await;
            }
        }
    }

    async fn poll_unit(
        &mut self,
        k: usize,
        ctx: &mut Context,
        read: bool,
    ) -> Result<(), FaultKind> {
        let timeout = self.timeout;
        let u = &mut self.units[k];
        ctx.set_slave(Slave(u.cfg.unit));
        let now = Instant::now();
        let refresh = u.next_refresh.is_some_and(|t| t <= now);
        if refresh {
            u.next_refresh = u.cfg.refresh.map(|r| now + r);
        }
        let mut exception: Option<(FaultKind, Vec<String>)> = None;
        let mut wrote = false;
        for o in 0..u.cfg.outputs.len() {
            let p = &u.cfg.outputs[o];
            let cell = u.output_cell(p);
            let Some((seq, value)) = cell.pending().or(refresh.then(|| cell.current())) else {
                continue;
            };
            let t0 = Instant::now();
            let r = write(ctx, &p.spec, value, timeout).await;
            self.stats.record(t0.elapsed());
            match r {
                Ok(()) => {
                    cell.confirm(seq);
                    wrote = true;
                }
                Err(e) if e.reconnect => return Err(e.fault),
                Err(e) => {
                    cell.invalidate();
                    match &mut exception {
                        Some((_, names)) => names.push(p.name.clone()),
                        None => exception = Some((e.fault, vec![p.name.clone()])),
                    }
                }
            }
        }
        // An output refusal is reported when it starts or changes; retried at the poll rate.
        match exception {
            Some((f, points)) if u.out_fault.as_ref() != Some(&f) => {
                u.out_fault = Some(f.clone());
                self.report_outputs(k, f, points);
            }
            Some(_) => {}
            None if wrote => u.out_fault = None,
            None => {}
        }
        if !read {
            return Ok(());
        }
        let u = &mut self.units[k];
        u.next_poll += u.cfg.poll;
        if u.next_poll < now {
            u.next_poll = now + u.cfg.poll;
        }
        let mut failed: Vec<(FaultKind, Vec<usize>)> = Vec::new();
        for b in 0..u.reads.len() {
            let block = &u.reads[b];
            let t0 = Instant::now();
            let r = read_block(ctx, block, timeout).await;
            self.stats.record(t0.elapsed());
            let stamp = u.cfg.image.now_ns();
            match r {
                Ok(data) => {
                    for &(i, off) in &block.points {
                        let p = &u.cfg.inputs[i];
                        let v = data.decode(block, &p.spec, off);
                        Image::publish(u.input_cell(p), v, stamp);
                    }
                }
                Err(e) if e.reconnect => return Err(e.fault),
                Err(e) => {
                    let pts: Vec<usize> = block.points.iter().map(|&(i, _)| i).collect();
                    for &i in &pts {
                        Image::mark_bad(u.input_cell(&u.cfg.inputs[i]));
                    }
                    failed.push((e.fault, pts));
                }
            }
        }
        self.update_health(k, failed);
        Ok(())
    }

    /// Compares the unit's bad points with the last report and reports the changes.
    fn update_health(&mut self, k: usize, failed: Vec<(FaultKind, Vec<usize>)>) {
        let u = &mut self.units[k];
        if failed.is_empty() && u.fault.is_none() && !u.bad.contains(&true) {
            return; // healthy and was healthy: the common case, nothing to compare
        }
        let mut now_bad = vec![false; u.cfg.inputs.len()];
        for (_, pts) in &failed {
            for &i in pts {
                now_bad[i] = true;
            }
        }
        let recovered: Vec<usize> = (0..now_bad.len())
            .filter(|&i| u.bad[i] && !now_bad[i])
            .collect();
        let fault = failed.first().map(|f| f.0.clone());
        let newly: Vec<usize> = (0..now_bad.len())
            .filter(|&i| now_bad[i] && (!u.bad[i] || u.fault != fault))
            .collect();
        u.bad = now_bad;
        u.fault = fault.clone();
        if !recovered.is_empty() {
            self.emit(k, &recovered, None, false);
        }
        if let (Some(f), false) = (fault, newly.is_empty()) {
            self.emit(k, &newly, Some(f), false);
        }
    }

    /// Every point of the link bad (connection lost or never made).
    fn all_bad(&mut self, f: &FaultKind) {
        for k in 0..self.units.len() {
            let u = &mut self.units[k];
            for p in &u.cfg.inputs {
                Image::mark_bad(u.input_cell(p));
            }
            for o in &u.cfg.outputs {
                u.output_cell(o).invalidate();
            }
            let same = u.fault.as_ref().map(FaultKind::as_str) == Some(f.as_str());
            if !same {
                u.bad = vec![true; u.cfg.inputs.len()];
                u.fault = Some(f.clone());
                let all: Vec<usize> = (0..u.cfg.inputs.len()).collect();
                self.emit(k, &all, Some(f.clone()), true);
            }
        }
    }

    fn report_outputs(&self, k: usize, f: FaultKind, points: Vec<String>) {
        let u = &self.units[k];
        self.send(LinkEvent {
            link: self.name.clone(),
            device: u.cfg.device.clone(),
            unit: u.cfg.unit,
            points,
            critical: Vec::new(),
            fault: Some(f),
        });
    }

    /// Reports the inputs `inputs` of unit `k` bad (`fault`) or good again; `outputs`: the
    /// whole device is unreachable, so its outputs are named too.
    fn emit(&self, k: usize, inputs: &[usize], fault: Option<FaultKind>, outputs: bool) {
        let u = &self.units[k];
        let mut points: Vec<String> = inputs
            .iter()
            .map(|&i| u.cfg.inputs[i].name.clone())
            .collect();
        if outputs {
            points.extend(u.cfg.outputs.iter().map(|o| o.name.clone()));
        }
        let critical = inputs
            .iter()
            .filter(|&&i| u.cfg.inputs[i].critical)
            .map(|&i| u.cfg.inputs[i].name.clone())
            .collect();
        self.send(LinkEvent {
            link: self.name.clone(),
            device: u.cfg.device.clone(),
            unit: u.cfg.unit,
            points,
            critical,
            fault,
        });
    }

    fn send(&self, e: LinkEvent) {
        if e.fault.is_some() {
            tracing::warn!("{}", e.message());
        } else {
            tracing::info!("{}", e.message());
        }
        let _ = self.events.send(e);
    }
}

/// A read's answer as `tokio-modbus` returns it: registers, or bits for coils and discrete
/// inputs (decoded point by point, not copied into registers first).
enum Answer {
    Words(Vec<u16>),
    Bits(Vec<bool>),
}

impl Answer {
    fn len(&self) -> usize {
        match self {
            Answer::Words(w) => w.len(),
            Answer::Bits(b) => b.len(),
        }
    }

    /// The value of point `spec` at `offset` in the block.
    fn decode(&self, b: &ReadBlock, spec: &PointSpec, offset: u16) -> f64 {
        match self {
            Answer::Words(w) => spec.decode(b.slice(w, offset)),
            Answer::Bits(bits) => {
                let bit = bits.get(usize::from(offset)).copied().unwrap_or(false);
                spec.decode(&[u16::from(bit)])
            }
        }
    }
}

/// One read. Through `Client::call`, not the `Reader` helpers: those `debug_assert` that the
/// answer has as many items as asked for, which is input from the device; the count is
/// checked here and a short answer is a protocol error (reconnect), never a panic.
async fn read_block(
    ctx: &mut Context,
    b: &ReadBlock,
    timeout: Duration,
) -> Result<Answer, TxError> {
    let (a, n) = (b.start, b.count);
    let request = match b.table {
        Table::Coil => Request::ReadCoils(a, n),
        Table::DiscreteInput => Request::ReadDiscreteInputs(a, n),
        Table::HoldingRegister => Request::ReadHoldingRegisters(a, n),
        Table::InputRegister => Request::ReadInputRegisters(a, n),
    };
    let protocol = |m: String| TxError {
        fault: FaultKind::Protocol(m),
        reconnect: true,
    };
    let data = match tx(within(timeout, ctx.call(request)).await)? {
        Response::ReadCoils(mut v) | Response::ReadDiscreteInputs(mut v) => {
            v.truncate(usize::from(n)); // whole bytes: up to 7 padding bits
            Answer::Bits(v)
        }
        Response::ReadHoldingRegisters(v) | Response::ReadInputRegisters(v) => Answer::Words(v),
        other => return Err(protocol(format!("unexpected answer {other:?}"))),
    };
    if data.len() != usize::from(n) {
        return Err(protocol(format!(
            "short response: {} of {n} items at {} {a}",
            data.len(),
            b.table
        )));
    }
    Ok(data)
}

/// One output write, through `Client::call` for the same reason as [`read_block`]: the
/// `Writer` helpers `debug_assert` that the device echoes the request; here a wrong echo is
/// a protocol error.
async fn write(
    ctx: &mut Context,
    spec: &PointSpec,
    value: f64,
    timeout: Duration,
) -> Result<(), TxError> {
    let (words, n) = spec.encode(value);
    let a = spec.address;
    let (request, echo) = match (spec.table, spec.data_type) {
        (Table::Coil, _) => {
            let on = value != 0.0;
            (
                Request::WriteSingleCoil(a, on),
                Response::WriteSingleCoil(a, on),
            )
        }
        (_, DataType::Bit(b)) => {
            let (and, or) = (!(1u16 << b), words[0] & (1u16 << b));
            (
                Request::MaskWriteRegister(a, and, or),
                Response::MaskWriteRegister(a, and, or),
            )
        }
        _ if n == 1 => (
            Request::WriteSingleRegister(a, words[0]),
            Response::WriteSingleRegister(a, words[0]),
        ),
        _ => (
            Request::WriteMultipleRegisters(a, std::borrow::Cow::Borrowed(&words[..n])),
            Response::WriteMultipleRegisters(a, n as u16),
        ),
    };
    let answer = tx(within(timeout, ctx.call(request)).await)?;
    if answer != echo {
        return Err(TxError {
            fault: FaultKind::Protocol(format!(
                "the answer to a write at {} {a} echoes {answer:?}",
                spec.table
            )),
            reconnect: true,
        });
    }
    Ok(())
}
