//! Builds the cell's deployment from its configuration: the servo chain in data-flow order
//! on one thread, the selection on a slower one, the camera as a non-periodic task after it.

use super::camera::{Camera, CameraCmd};
use super::config::CellConfig;
use super::hw::{Hardware, HwCmd};
use super::names;
use super::pid::{Effector, Pid};
use super::robot::{Robot, RobotCmd};
use super::scripted::{self, ScriptLoadError, ScriptedSelection};
use super::selection::{Selection, SelectionCmd, SelectionKind};
use super::sensor::Sensor;
use super::world::World;
use crate::bridge::remote::RemoteProxy;
use crate::rt::prelude::*;
use crate::script::ScriptHosts;
use std::sync::Arc;

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
    /// The script hosts: the selection task when it runs the script (the default).
    pub scripts: ScriptHosts,
}

/// Errors deploying the cell.
#[derive(Debug, thiserror::Error)]
pub enum CellDeployError {
    /// The deployment refused.
    #[error(transparent)]
    Deploy(#[from] DeployError),
    /// The selection script failed to load (`file:line:col: ...`).
    #[error(transparent)]
    Script(#[from] ScriptLoadError),
}

/// Margin of the sensor's valid range beyond the workspace, mm: a setpoint inside the
/// workspace may overshoot a little; a reading beyond this is a fault.
pub const RANGE_MARGIN_MM: f64 = 5.0;

/// Adds the cell's tasks to a new deployment and configures it.
pub fn deploy(cfg: &CellConfig) -> Result<Cell, CellDeployError> {
    deploy_with(cfg, None)
}

/// As [`deploy`], with the camera task replaced by `remote_camera` (a proxy of a camera in
/// another process, [`super::remote`]) when given.
pub fn deploy_with(
    cfg: &CellConfig,
    remote_camera: Option<RemoteProxy<CameraCmd>>,
) -> Result<Cell, CellDeployError> {
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
    let sel_sched = cfg.threads.selection.schedule();
    let (selection, script) = match cfg.selection.kind {
        SelectionKind::Rust => {
            let task = Selection::new(cfg.selection.clone(), cfg.layout);
            (app.add_periodic(names::SELECTION, task, sel_sched)?, None)
        }
        SelectionKind::Script => {
            let mut source = scripted::read(cfg.selection.script.as_deref())?;
            let (task, control) = ScriptedSelection::new(&mut source);
            let handle = app.add_periodic(names::SELECTION, task, sel_sched)?;
            (handle, Some((source, control)))
        }
    };
    let prio = cfg.threads.selection.priority;
    let camera = match remote_camera {
        Some(proxy) => app.add_non_periodic(names::CAMERA, proxy, prio)?,
        None => app.add_non_periodic(names::CAMERA, Camera::new(cfg.camera), prio)?,
    };
    app.configure()?;
    let mut scripts = ScriptHosts::default();
    if let Some((source, control)) = script {
        // Bound after configure: the bindings name the deployed peers and events.
        let (done, error) = source.flags();
        let b = scripted::bindings(&app, robot.info(), camera.info(), done, error)?;
        scripted::bind(
            &source.file,
            &source.src,
            &control,
            &b,
            &cfg.layout,
            &cfg.selection,
        )?;
        control.attach(selection.info().clone());
        let b = scripted::bindings(&app, robot.info(), camera.info(), done, error)?;
        scripts.add(Arc::new(control), b);
    }
    Ok(Cell {
        deployment: app,
        selection,
        robot,
        camera,
        hw,
        scripts,
    })
}
