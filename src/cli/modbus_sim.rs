//! `hytask modbus-sim`: a Modbus TCP/RTU server simulating the devices of a map, for tests,
//! demos and commissioning without hardware.
//!
//! The map is a machine configuration (its Modbus `[[io]]` devices) or a file holding only
//! `[[io]]` tables in the same format: the simulator then has exactly the points the machine
//! expects, by name. Commands on standard input (one per line) change it at runtime:
//!
//! ```text
//! set NAME VALUE          set a point's raw value (digital: 0/1 electrical level)
//! get NAME                print a point's value
//! dump                    print every point
//! toggle NAME MS          toggle a point every MS milliseconds (0 stops)
//! follow INPUT OUTPUT MS  INPUT follows OUTPUT's level after MS ms (a VFD's at-speed)
//! delay MS                answer every request after MS ms
//! drop on|off             stop/resume answering (clients time out)
//! exception CODE          answer every request with exception CODE (0: off)
//! garble none|crc|short|unit|count|function|echo
//!                         corrupt answers (RTU CRC, cut frame, wrong unit id, one item
//!                         fewer than asked for, another function code, a write's
//!                         answer echoing another address)
//! close                   close every TCP connection now
//! quit                    exit
//! ```
//!
//! It prints `listening tcp ADDR` / `listening rtu DEVICE` once serving, and
//! `out NAME VALUE` whenever the client changes an output: tests read those lines.

use crate::modbus::sim::{serve_rtu, serve_tcp, watch, Garble, Sim};
use anyhow::{bail, Context};
use std::io::{BufRead, Write};
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

/// Arguments of `hytask modbus-sim`.
#[derive(Debug, clap::Args)]
pub struct ModbusSimArgs {
    /// Machine configuration whose Modbus `[[io]]` devices are simulated.
    #[arg(long, conflicts_with = "map")]
    pub config: Option<PathBuf>,
    /// A file of `[[io]]` tables only (same format as in a machine configuration).
    #[arg(long)]
    pub map: Option<PathBuf>,
    /// Serve Modbus TCP on ADDR:PORT (port 0: any free port, printed).
    #[arg(long)]
    pub listen: Option<String>,
    /// Serve Modbus RTU on a serial device or pty.
    #[arg(long)]
    pub rtu: Option<PathBuf>,
    /// RTU baud rate.
    #[arg(long, default_value_t = 19200)]
    pub baud: u32,
    /// Items per table of each unit (at least what the map uses).
    #[arg(long, default_value_t = 256)]
    pub size: usize,
    /// Commands to run at start, as on standard input (repeatable), e.g. `--exec "set estop 1"`.
    #[arg(long = "exec")]
    pub exec: Vec<String>,
}

#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct MapFile {
    io: Vec<crate::config::IoConfig>,
}

fn load(args: &ModbusSimArgs) -> anyhow::Result<Sim> {
    let io = match (&args.config, &args.map) {
        (Some(p), _) => crate::config::load(p)?.io,
        (None, Some(p)) => {
            let text = std::fs::read_to_string(p).with_context(|| p.display().to_string())?;
            let m: MapFile = toml::from_str(&text).with_context(|| p.display().to_string())?;
            m.io
        }
        (None, None) => bail!("give a device map: --config MACHINE.toml or --map MAP.toml"),
    };
    Ok(Sim::from_io(&io, args.size)?)
}

/// Applies one command line; returns the text to print, or `None` for `quit`.
pub fn command(sim: &Sim, line: &str) -> anyhow::Result<Option<String>> {
    let w: Vec<&str> = line.split_whitespace().collect();
    let ms = |s: &str| -> anyhow::Result<Duration> {
        Ok(Duration::from_millis(
            s.parse()
                .with_context(|| format!("{s:?} is not milliseconds"))?,
        ))
    };
    let mut s = sim.lock();
    let out = match w.as_slice() {
        [] => String::new(),
        ["quit"] | ["exit"] => return Ok(None),
        ["set", name, v] => {
            let v: f64 = v.parse().with_context(|| format!("{v:?} is not a number"))?;
            s.set(name, v)?;
            format!("ok {name} {v}")
        }
        ["get", name] => format!("{name} {}", s.get(name)?),
        ["dump"] => s
            .values()
            .iter()
            .map(|(n, o, v)| format!("{} {n} {v}", if *o { "out" } else { "in" }))
            .collect::<Vec<_>>()
            .join("\n"),
        ["toggle", name, t] => {
            s.toggle(name, ms(t)?)?;
            format!("ok toggle {name}")
        }
        ["follow", input, output, t] => {
            s.follow(input, output, ms(t)?)?;
            format!("ok follow {input} {output}")
        }
        ["delay", t] => {
            s.faults.delay = ms(t)?;
            "ok delay".into()
        }
        ["drop", on] => {
            s.faults.drop = match *on {
                "on" => true,
                "off" => false,
                _ => bail!("drop on|off"),
            };
            format!("ok drop {on}")
        }
        ["exception", code] => {
            let c: u8 = code.parse().with_context(|| format!("{code:?} is not 0..=255"))?;
            s.faults.exception = (c != 0).then_some(c);
            format!("ok exception {c}")
        }
        ["garble", g] => {
            s.faults.garble = match *g {
                "none" => Garble::None,
                "crc" => Garble::Crc,
                "short" => Garble::Short,
                "unit" => Garble::Unit,
                "count" => Garble::Count,
                "function" => Garble::Function,
                "echo" => Garble::Echo,
                _ => bail!("garble none|crc|short|unit|count|function|echo"),
            };
            format!("ok garble {g}")
        }
        ["close"] => {
            s.close_connections();
            "ok close".into()
        }
        _ => bail!("unknown command {line:?} (set, get, dump, toggle, follow, delay, drop, exception, garble, close, quit)"),
    };
    Ok(Some(out))
}

fn say(text: &str) {
    let mut o = std::io::stdout().lock();
    let _ = writeln!(o, "{text}");
    let _ = o.flush();
}

/// Runs the simulator until `quit`, or until killed: at the end of standard input it keeps
/// serving (so it can run with `< /dev/null` as a background service).
pub fn run(args: ModbusSimArgs) -> anyhow::Result<ExitCode> {
    let sim = load(&args)?;
    if args.listen.is_none() && args.rtu.is_none() {
        bail!("nothing to serve: give --listen ADDR:PORT and/or --rtu DEVICE");
    }
    for c in &args.exec {
        command(&sim, c)?;
    }
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()?;
    rt.block_on(async {
        if let Some(addr) = &args.listen {
            let l = tokio::net::TcpListener::bind(addr)
                .await
                .with_context(|| format!("--listen {addr}"))?;
            say(&format!("listening tcp {}", l.local_addr()?));
            tokio::spawn(serve_tcp(sim.clone(), l));
        }
        if let Some(dev) = &args.rtu {
            let path = dev.display().to_string();
            let port = tokio_serial::SerialStream::open(&tokio_serial::new(&path, args.baud))
                .with_context(|| format!("--rtu {path}"))?;
            say(&format!("listening rtu {path}"));
            let s = sim.clone();
            tokio::spawn(async move {
                if let Err(e) = serve_rtu(s, port).await {
                    eprintln!("hytask modbus-sim: rtu {path}: {e}");
                }
            });
        }
        tokio::spawn(watch(sim.clone(), |name, v| {
            say(&format!("out {name} {v}"))
        }));
        anyhow::Ok(())
    })?;
    let stdin = std::io::stdin();
    for line in stdin.lock().lines() {
        match command(&sim, &line?) {
            Ok(None) => return Ok(ExitCode::SUCCESS),
            Ok(Some(t)) if t.is_empty() => {}
            Ok(Some(t)) => say(&t),
            Err(e) => say(&format!("error: {e:#}")),
        }
    }
    loop {
        std::thread::park();
    }
}
