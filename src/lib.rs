//! hytask: a realtime controller daemon for machine tools and robots, built on the hybrid
//! task model of Orocos (Soetens & Bruyninckx, "Realtime Hybrid Task-Based Control for Robots
//! and Machine Tools").
//!
//! Module map (dependencies point downwards only):
//! - [`cli`]: the `hytask` command line (daemon, job client, tools).
//! - [`control`]: the control socket (JSON lines over a Unix socket).
//! - [`daemon`]: daemon life: systemd notify/watchdog, signals, the serve loop.
//! - [`machine`]: deployment of a machine from its configuration: tasks, threads, safety.
//! - [`config`]: the TOML machine description, validated with errors that name the key.
//! - [`motion`]: lookahead planner, kinematics and the realtime interpolator.
//! - [`plc`]: IEC 61131-3 Structured Text: compiler and allocation-free scan.
//! - [`script`]: programs and state machines in the PLC's Structured Text plus script
//!   statements (DO, WAIT, TRY, states and transitions), run step by step inside a task.
//! - [`cell`]: the pick-and-place cell of the seed paper on simulated hardware.
//! - [`gcode`]: RS274/NGC (LinuxCNC dialect) front end: text in, canonical commands out.
//! - [`rt`]: the reusable realtime task model: activities, data objects, buffers, events,
//!   commands, lifecycle, timing statistics. It knows nothing of machines.

// Under `--cfg loom` (model checking of rt's lock-free primitives) tokio compiles out its
// networking and signals, so the modules built on them are left out of that build.
#[cfg(not(loom))]
pub mod bridge;
#[cfg(not(loom))]
pub mod cell;
#[cfg(not(loom))]
pub mod cli;
pub mod config;
#[cfg(not(loom))]
pub mod control;
#[cfg(not(loom))]
pub mod daemon;
pub mod gcode;
#[cfg(not(loom))]
pub mod machine;
#[cfg(not(loom))]
pub mod modbus;
pub mod motion;
pub mod plc;
pub mod rt;
pub mod script;
