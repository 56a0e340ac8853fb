//! `hytask peer --config FILE`: a process hosting tasks without a machine, exported over
//! Zenoh for remote peers (`bridge::remote`), until SIGTERM/SIGINT.
//!
//! It runs its own rt deployment (one thread, `[peer] period_us` / `priority`), serves it
//! with the ordinary exporter (`hytask/<name>/...`: task list, operations, ports, events)
//! and declares its liveliness token (`hytask/<name>/alive`), which users of the peer watch
//! to notice its loss. The tasks it can host are named by table; today the pick-and-place
//! cell's camera (`[camera]`, config/vision-peer.toml):
//!
//! ```toml
//! [peer]
//! name = "vision"            # key on Zenoh: hytask/vision/...
//! period_us = 10000
//! priority = 60
//! [zenoh]                    # as for a machine; local-only by default
//! listen = ["tcp/127.0.0.1:17461"]
//! connect = ["tcp/127.0.0.1:17460"]
//! [[remote]]                 # the cell, which feeds the camera's scene
//! name = "cell"
//! machine = "pick-and-place"
//! check = false              # the cell exports no task list; it only publishes the scene
//! [camera]
//! scene_from = "cell/camera" # <remote>/<its proxy task> publishing cell.scene
//! [camera.settings]          # as [cell.camera] (same seed: same results as a local camera)
//! seed = 1
//! ```

use crate::bridge::remote::RemoteLink;
use crate::bridge::remote_host::PeerHost;
use crate::cell::camera::CameraConfig;
use crate::config::remote::RemoteConfig;
use crate::config::ZenohConfig;
use crate::rt::prelude::*;
use anyhow::{bail, Context};
use serde::Deserialize;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

/// Arguments of `hytask peer`.
#[derive(Debug, clap::Args)]
pub struct PeerArgs {
    /// The peer's file (e.g. config/vision-peer.toml).
    #[arg(long)]
    pub config: PathBuf,
}

/// `[peer]`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct PeerSection {
    name: String,
    #[serde(default = "default_period_us")]
    period_us: u64,
    #[serde(default = "default_priority")]
    priority: i32,
}

fn default_period_us() -> u64 {
    10_000
}
fn default_priority() -> i32 {
    60
}

/// `[camera]`: host the cell's camera task.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct CameraSection {
    /// `<remote>/<task>` publishing `cell.scene`.
    scene_from: String,
    #[serde(default)]
    settings: CameraConfig,
}

/// A peer file.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct PeerFile {
    peer: PeerSection,
    #[serde(default)]
    zenoh: Option<ZenohConfig>,
    #[serde(default)]
    remote: Vec<RemoteConfig>,
    #[serde(default)]
    camera: Option<CameraSection>,
}

fn load(path: &Path) -> anyhow::Result<PeerFile> {
    let text = crate::config::read(path)?;
    let file: PeerFile = crate::config::deserialize(&text, &path.display().to_string())?;
    let problems = RemoteConfig::problems(&file.remote);
    if !problems.is_empty() {
        bail!("{}: {}", path.display(), problems.join("; "));
    }
    if file.camera.is_none() {
        bail!("{}: no task to host (add a [camera] table)", path.display());
    }
    Ok(file)
}

/// Runs the subcommand.
pub fn run(args: PeerArgs) -> anyhow::Result<ExitCode> {
    super::serve::init_logging();
    let file = load(&args.config).with_context(|| format!("loading {}", args.config.display()))?;
    // `[zenoh]` absent: its defaults (loopback listener, local-only).
    let zenoh: ZenohConfig = match file.zenoh.clone() {
        Some(z) => z,
        None => toml::from_str("")?,
    };
    let session = crate::bridge::session::open(&zenoh)?;
    let name = zenoh.key.clone().unwrap_or_else(|| file.peer.name.clone());
    let schedule = Schedule {
        priority: file.peer.priority,
        period_ns: file.peer.period_us * 1000,
        cpu: None,
    };
    let mut app = Deployment::new();
    let mut links = Vec::new();
    if let Some(cam) = &file.camera {
        let (remote, task) = RemoteConfig::split_peer(&cam.scene_from).with_context(|| {
            format!(
                "camera.scene_from: '{}' is not '<remote>/<task>'",
                cam.scene_from
            )
        })?;
        let cfg = RemoteConfig::find(&file.remote, remote)
            .map_err(|e| anyhow::anyhow!("camera.scene_from: {e}"))?;
        let link = RemoteLink::connect(&session, cfg)?;
        crate::cell::remote::host_camera(&mut app, &link, task, &name, cam.settings, schedule)?;
        links.push(link);
    }
    app.configure()?;
    let runtime = app.start()?;
    let peer = PeerHost::serve(session, runtime, &file.peer.name, &zenoh)?;
    tracing::info!("peer '{name}': serving hytask/{name}/ until SIGTERM/SIGINT");
    wait_for_signal()?;
    peer.stop();
    drop(links);
    tracing::info!("peer '{name}' stopped");
    Ok(ExitCode::SUCCESS)
}

fn wait_for_signal() -> anyhow::Result<()> {
    use tokio::signal::unix::{signal, SignalKind};
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()?;
    rt.block_on(async {
        let mut term = signal(SignalKind::terminate())?;
        let mut int = signal(SignalKind::interrupt())?;
        tokio::select! {
            _ = term.recv() => {}
            _ = int.recv() => {}
        }
        Ok::<(), std::io::Error>(())
    })?;
    Ok(())
}
