//! The cell's camera in another process (`hytask peer --config config/vision-peer.toml`),
//! reached over Zenoh as a remote peer (`bridge::remote`).
//!
//! In the cell file (config/pickplace-remote.toml):
//! ```toml
//! [peers]
//! camera = "vision/camera"   # the cell's `camera` task is task `camera` of remote `vision`
//! [[remote]]
//! name = "vision"
//! timeout_s = 10.0
//! critical = false           # true: losing it e-stops the robot
//! [zenoh]
//! listen = ["tcp/127.0.0.1:17460"]
//! connect = ["tcp/127.0.0.1:17461"]
//! ```
//! The cell then deploys a proxy named `camera` instead of the camera task: the selection
//! sends it `start_detection` as before; the proxy publishes the scene (`cell.scene`)
//! then calls the remote operation, and re-emits the remote's detection events locally. The
//! peer imports the scene from the cell (`[[remote]] name = "cell" check = false`) and runs
//! the ordinary [`Camera`](super::camera::Camera) task on it, with the same seed, so both
//! variants sort the same objects the same way.
//!
//! Losing the peer: its pending `start_detection` fails at once, and the selection reports
//! "no detection result" (error detected; `selection.stop` recovers once the peer is back);
//! the loss is also pushed on the control socket's `fault` topic with the peer's name. A
//! critical peer also e-stops the robot.

use super::camera::{Camera, CameraCmd, CameraConfig};
use super::names;
use super::types::CameraScene;
use crate::bridge::remote::{RemoteCommand, RemoteError, RemoteLink, RemoteProxy};
use crate::config::remote::RemoteConfig;
use crate::rt::prelude::*;
use serde_json::Value;

impl RemoteCommand for CameraCmd {
    fn remote_args(&self) -> Value {
        Value::Null
    }
}

/// The detection events the camera emits (short names).
pub const DETECTION_EVENTS: [&str; 3] = [
    "object_a_detected",
    "object_b_detected",
    "no_object_detected",
];

/// The proxy standing for the remote camera `task` on `link`, in cell `local` (its key).
pub fn camera_proxy(
    link: &RemoteLink,
    task: &str,
    local: &str,
) -> Result<RemoteProxy<CameraCmd>, RemoteError> {
    let mut p = RemoteProxy::<CameraCmd>::new(link, task, local)?;
    for e in DETECTION_EVENTS {
        p = p.event::<u32>(e)?;
    }
    Ok(p.forward::<CameraScene>(names::SCENE))
}

/// Adds the peer side to `app`: a proxy named `scene` feeding `cell.scene` from the cell's
/// camera proxy (`<remote>/<task>` of `scene_from`), and the camera task itself.
pub fn host_camera(
    app: &mut Deployment,
    link: &RemoteLink,
    scene_task: &str,
    local: &str,
    camera: CameraConfig,
    schedule: Schedule,
) -> Result<TaskHandle<CameraCmd>, PeerCameraError> {
    // The scene arrives before the call that needs it (one link keeps the order); the
    // feeding proxy runs on the camera's thread before it, every cycle.
    let scene = RemoteProxy::<ScenePort>::new(link, scene_task, local)?
        .port::<CameraScene>(names::SCENE)?;
    app.add_periodic("scene", scene, schedule)?;
    Ok(app.add_non_periodic(names::CAMERA, Camera::new(camera), schedule.priority)?)
}

/// Errors hosting the camera in a peer.
#[derive(Debug, thiserror::Error)]
pub enum PeerCameraError {
    /// The remote cell.
    #[error(transparent)]
    Remote(#[from] RemoteError),
    /// The deployment refused.
    #[error(transparent)]
    Deploy(#[from] DeployError),
}

/// The command set of a proxy that only imports a port (no operations).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ScenePort {}

impl Commands for ScenePort {
    fn operations() -> &'static [OperationDescriptor] {
        &[]
    }
    fn operation_index(&self) -> usize {
        match *self {}
    }
    fn from_args(operation: &str, _: &[ArgValue]) -> Result<Self, ArgError> {
        Err(ArgError::UnknownOperation(operation.to_owned()))
    }
}

impl RemoteCommand for ScenePort {
    fn remote_args(&self) -> Value {
        match *self {}
    }
}

/// The cell's remote camera, if its file has `[peers] camera = "<remote>/<task>"`: the
/// session and link, kept as long as the cell runs.
pub struct RemoteCamera {
    /// The link to the peer.
    pub link: RemoteLink,
    /// The remote task.
    pub task: String,
    /// This cell's key on Zenoh.
    pub local: String,
    _session: zenoh::Session,
}

impl RemoteCamera {
    /// Connects to the peer named by `reference` (`"<remote>/<task>"`) among `remotes`, on a
    /// session opened from `zenoh` (required), as cell `local`.
    pub fn connect(
        reference: &str,
        remotes: &[RemoteConfig],
        zenoh: Option<&crate::config::ZenohConfig>,
        local: &str,
    ) -> anyhow::Result<Self> {
        let (remote, task) = RemoteConfig::split_peer(reference).ok_or_else(|| {
            anyhow::anyhow!("peers.camera: '{reference}' is not '<remote>/<task>'")
        })?;
        let cfg = RemoteConfig::find(remotes, remote)
            .map_err(|e| anyhow::anyhow!("peers.camera: {e}"))?;
        let z = zenoh
            .ok_or_else(|| anyhow::anyhow!("peers.camera: a remote peer needs a [zenoh] table"))?;
        let session = crate::bridge::session::open(z)?;
        let link = RemoteLink::connect(&session, cfg)?;
        Ok(Self {
            link,
            task: task.to_owned(),
            local: z.key.clone().unwrap_or_else(|| local.to_owned()),
            _session: session,
        })
    }

    /// Reports a loss of the peer on the control socket's `fault` topic, and e-stops the
    /// robot if the peer is critical.
    pub fn watch(
        &self,
        events: tokio::sync::broadcast::Sender<crate::machine::api::MachineEvent>,
        robot: CommandSender<super::robot::RobotCmd>,
    ) {
        self.link.on_lost(move |msg, critical| {
            let _ = events.send(crate::machine::api::MachineEvent {
                topic: "fault".into(),
                data: serde_json::json!({ "message": msg, "critical": critical }),
            });
            if critical {
                tracing::error!("{msg}: critical peer, emergency stop");
                let _ = robot.send(super::robot::RobotCmd::EmergencyStop);
            }
        });
    }

    /// The proxy to deploy as the cell's camera.
    pub fn proxy(&self) -> Result<RemoteProxy<CameraCmd>, RemoteError> {
        camera_proxy(&self.link, &self.task, &self.local)
    }
}
