//! Builds the cell's deployment from its configuration: the servo chain in data-flow order
//! on one thread, the selection on a slower one, the camera as a non-periodic task after it.

use super::camera::{Camera, CameraCmd};
use super::config::CellConfig;
use super::hw::{Hardware, HwCmd};
use super::names;
use super::pid::{Effector, Pid};
use super::robot::{Robot, RobotCmd};
use super::selection::{Selection, SelectionCmd};
use super::sensor::Sensor;
use super::world::World;
use crate::rt::prelude::*;

/// A configured (not started) cell and its typed command senders.
pub struct Cell {
    /// The deployment, configured and checked.
    pub deployment: Deployment,
    /// The selection task.
    pub selection: TaskHandle<SelectionCmd>,
    /// The robot task.
    pub robot: TaskHandle<RobotCmd>,
    /// The camera task.
    pub camera: TaskHandle<CameraCmd>,
    /// The simulated hardware (fault injection).
    pub hw: TaskHandle<HwCmd>,
}

/// Margin of the sensor's valid range beyond the workspace, mm: a setpoint inside the
/// workspace may overshoot a little; a reading beyond this is a fault.
pub const RANGE_MARGIN_MM: f64 = 5.0;

/// Adds the cell's tasks to a new deployment and configures it.
pub fn deploy(cfg: &CellConfig) -> Result<Cell, DeployError> {
    let mut app = Deployment::new();
    let servo = cfg.threads.servo.schedule();
    let (lo, hi) = (cfg.robot.min_mm, cfg.robot.max_mm);
    let sensor = Sensor::new(
        lo.map(|v| v - RANGE_MARGIN_MM),
        hi.map(|v| v + RANGE_MARGIN_MM),
    );
    app.add_periodic(names::SENSOR, sensor, servo)?;
    let robot = app.add_periodic(names::ROBOT, Robot::new(cfg.robot), servo)?;
    app.add_periodic(names::PID, Pid::new(cfg.pid), servo)?;
    app.add_periodic(names::EFFECTOR, Effector::new(cfg.pid.max_force_n), servo)?;
    let world = World::new(cfg.world, cfg.layout);
    let hw = app.add_periodic(names::HW, Hardware::new(world), servo)?;
    let selection = app.add_periodic(
        names::SELECTION,
        Selection::new(cfg.selection, cfg.layout),
        cfg.threads.selection.schedule(),
    )?;
    let camera = app.add_non_periodic(
        names::CAMERA,
        Camera::new(cfg.camera),
        cfg.threads.selection.priority,
    )?;
    app.configure()?;
    Ok(Cell {
        deployment: app,
        selection,
        robot,
        camera,
        hw,
    })
}
