//! The `hytask` command line. One file per subcommand; each owns its argument struct and a
//! `run` function returning `anyhow::Result<ExitCode>` (errors are reported here, once).

use clap::{Parser, Subcommand};
use std::process::ExitCode;

mod canopen_tool;
mod check;
mod client;
mod gcode;
mod interrupt;
mod latency;
mod modbus_sim;
mod peer;
mod plan;
mod plc;
mod plot;
mod run;
mod run_cell;
mod script;
mod serve;
mod sim_drive;
mod wait;

/// hytask: realtime hybrid task-based controller for machine tools and robots.
#[derive(Debug, Parser)]
#[command(name = "hytask", version, about)]
pub struct Cli {
    /// What to do.
    #[command(subcommand)]
    pub command: Command,
}

/// The subcommands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Run the daemon: load a machine, start its realtime tasks, serve the control socket.
    Serve(serve::ServeArgs),
    /// Run a G-code job (on the daemon, or on an embedded simulated machine if none runs).
    Run(run::RunArgs),
    /// Run the pick-and-place cell (on an embedded daemon, or `--socket`) and report.
    RunCell(run_cell::RunCellArgs),
    /// Host tasks without a machine, exported over Zenoh for remote peers (e.g. the cell's
    /// camera: config/vision-peer.toml).
    Peer(peer::PeerArgs),
    /// Talk to a running daemon: status, estop, home, jog, mdi, ...
    #[command(flatten)]
    Client(client::ClientCommand),
    /// Validate a machine configuration file and print the resolved machine.
    Check(check::CheckArgs),
    /// Measure hytask's periodic-thread wake-up latency, cyclictest-style.
    Latency(latency::LatencyArgs),
    /// G-code tools (canonical trace, ...).
    Gcode(gcode::GcodeArgs),
    /// Plan a G-code file: cycle-time estimate and peak velocity/acceleration/jerk per axis.
    Plan(plan::PlanArgs),
    /// Plot the planned toolpath of a G-code file to SVG.
    Plot(plot::PlotArgs),
    /// Loopback CiA 402 drives (CANopen slaves) on a SocketCAN interface, for tests.
    SimDrive(sim_drive::SimDriveArgs),
    /// CANopen master tool on a SocketCAN interface: sdo-read, sdo-write, nmt, scan, heartbeat.
    Canopen(canopen_tool::CanopenArgs),
    /// Simulate Modbus devices (TCP and RTU) from a device map, with fault injection.
    ModbusSim(modbus_sim::ModbusSimArgs),
    /// PLC tools: compile-check or run a Structured Text program offline.
    Plc(plc::PlcArgs),
    /// Scripts (programs and state machines): check offline; load, start, pause, step,
    /// stop, unload and list on a running daemon.
    Script(script::ScriptArgs),
}

/// Entry point of the binary.
pub fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Serve(a) => serve::run(a),
        Command::Run(a) => run::run(a),
        Command::RunCell(a) => run_cell::run(a),
        Command::Peer(a) => peer::run(a),
        Command::Client(a) => client::run(a),
        Command::Check(a) => check::run(a),
        Command::Latency(a) => latency::run(a),
        Command::Gcode(a) => gcode::run(a),
        Command::Plan(a) => plan::run(a),
        Command::Plot(a) => plot::run(a),
        Command::SimDrive(a) => sim_drive::run(a),
        Command::Canopen(a) => canopen_tool::run(a),
        Command::ModbusSim(a) => modbus_sim::run(a),
        Command::Plc(a) => plc::run(a),
        Command::Script(a) => script::run(a),
    };
    match result {
        Ok(code) => code,
        Err(e) => {
            eprintln!("hytask: {e:#}");
            ExitCode::FAILURE
        }
    }
}
