//! The camera detection task: non-periodic, on a thread of lower priority than the servo
//! thread (the paper's Fig. 9: detection is slow and must not disturb position control).
//!
//! `start_detection` grabs a frame of what the camera sees (the `hw` task's scene), renders
//! it into a preallocated greyscale image (seeded sensor noise plus a blob whose brightness
//! depends on the object's kind), and then processes it a band of rows per step (3×3 box
//! filter, then counting pixels per brightness band) so one step's work stays bounded. The
//! result is emitted as `object_a_detected`, `object_b_detected` or `no_object_detected`
//! (an unknown object or an empty view: nothing to sort into A or B) when the image is
//! processed *and* the simulated processing time has passed: tens of milliseconds, drawn from
//! the seed, so runs on simulated time are reproducible and runs on real threads show what a
//! slow vision task does to the servo thread (nothing, when the priorities are right).

use super::names;
use super::rng::SplitMix64;
use super::types::{CameraScene, ObjectKind};
use crate::rt::prelude::*;

/// Parameters of the simulated camera.
#[derive(Debug, Clone, Copy, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields)]
pub struct CameraConfig {
    /// Seed of the noise and of the processing times.
    #[serde(default = "default_seed")]
    pub seed: u64,
    /// Shortest processing time, ms.
    #[serde(default = "default_min_ms")]
    pub processing_min_ms: u64,
    /// Longest processing time, ms.
    #[serde(default = "default_max_ms")]
    pub processing_max_ms: u64,
    /// Image width, pixels.
    #[serde(default = "default_width")]
    pub width: usize,
    /// Image height, pixels.
    #[serde(default = "default_height")]
    pub height: usize,
    /// Rows filtered per step of the task (bounds one step's work).
    #[serde(default = "default_rows")]
    pub rows_per_step: usize,
}

fn default_seed() -> u64 {
    1
}
fn default_min_ms() -> u64 {
    20
}
fn default_max_ms() -> u64 {
    40
}
fn default_width() -> usize {
    320
}
fn default_height() -> usize {
    240
}
fn default_rows() -> usize {
    40
}

impl Default for CameraConfig {
    fn default() -> Self {
        Self {
            seed: default_seed(),
            processing_min_ms: default_min_ms(),
            processing_max_ms: default_max_ms(),
            width: default_width(),
            height: default_height(),
            rows_per_step: default_rows(),
        }
    }
}

/// The camera's operation.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CameraCmd {
    /// Grab a frame and classify the object in view.
    StartDetection,
}

const OPS: &[OperationDescriptor] = &[OperationDescriptor::new(
    "start_detection",
    "Grab a frame and classify the object in view; done when the result event is emitted.",
    &[],
    NextCommand::AfterCompletion,
)];

impl Commands for CameraCmd {
    fn operations() -> &'static [OperationDescriptor] {
        OPS
    }
    fn operation_index(&self) -> usize {
        0
    }
    fn from_args(operation: &str, args: &[ArgValue]) -> Result<Self, ArgError> {
        Args::new(OPS, operation, args)?;
        Ok(Self::StartDetection)
    }
}

/// Brightness of the blob per kind, and the background level.
const BACKGROUND: u8 = 20;
const fn blob_level(kind: ObjectKind) -> u8 {
    match kind {
        ObjectKind::A => 220,
        ObjectKind::B => 140,
        ObjectKind::Unknown => 70,
    }
}

/// Pixels of a band needed to call it a blob.
const MIN_BLOB_PIXELS: u32 = 200;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Phase {
    Idle,
    /// Filtering row `next_row`; result due at `due_ns`.
    Processing {
        next_row: usize,
        due_ns: u64,
    },
    /// Result emitted; the command completes.
    Done,
}

/// The camera task.
pub struct Camera {
    cfg: CameraConfig,
    rng: SplitMix64,
    image: Vec<u8>,
    scene_in: Option<DataReader<CameraScene>>,
    a_detected: Option<EventSource<u32>>,
    b_detected: Option<EventSource<u32>>,
    none_detected: Option<EventSource<u32>>,
    phase: Phase,
    /// Pixels per band: bright (A), medium (B), dim (unknown).
    bands: [u32; 3],
    detections: u32,
}

impl Camera {
    /// A camera with `cfg` (the image is allocated here, never in a step).
    pub fn new(cfg: CameraConfig) -> Self {
        let cfg = CameraConfig {
            width: cfg.width.max(8),
            height: cfg.height.max(8),
            rows_per_step: cfg.rows_per_step.max(1),
            ..cfg
        };
        Self {
            cfg,
            rng: SplitMix64::new(cfg.seed),
            image: vec![0; cfg.width * cfg.height],
            scene_in: None,
            a_detected: None,
            b_detected: None,
            none_detected: None,
            phase: Phase::Idle,
            bands: [0; 3],
            detections: 0,
        }
    }

    /// Renders the frame: noise everywhere, a square blob in the middle if an object is seen.
    fn grab(&mut self, scene: CameraScene) {
        let (w, h) = (self.cfg.width, self.cfg.height);
        let blob = scene.object.map(blob_level);
        for y in 0..h {
            for x in 0..w {
                let noise = (self.rng.next_u64() & 0x0F) as u8;
                let in_blob = (w / 3..2 * w / 3).contains(&x) && (h / 3..2 * h / 3).contains(&y);
                let level = match blob {
                    Some(l) if in_blob => l,
                    _ => BACKGROUND,
                };
                self.image[y * w + x] = level.saturating_add(noise);
            }
        }
        self.bands = [0; 3];
    }

    /// Filters one band of rows (3×3 box filter) and counts the pixels per brightness band.
    fn process_rows(&mut self, from: usize, to: usize) {
        let w = self.cfg.width;
        for y in from.max(1)..to.min(self.cfg.height - 1) {
            for x in 1..w - 1 {
                let mut sum = 0u32;
                for dy in 0..3 {
                    let row = (y + dy - 1) * w;
                    for dx in 0..3 {
                        sum += u32::from(self.image[row + x + dx - 1]);
                    }
                }
                let v = sum / 9;
                let band = match v {
                    190.. => Some(0),
                    110..190 => Some(1),
                    50..110 => Some(2),
                    _ => None,
                };
                if let Some(b) = band {
                    self.bands[b] += 1;
                }
            }
        }
    }

    fn emit_result(&mut self) {
        self.detections += 1;
        let n = self.detections;
        let [a, b, _] = self.bands;
        let ev = if a >= MIN_BLOB_PIXELS {
            &mut self.a_detected
        } else if b >= MIN_BLOB_PIXELS {
            &mut self.b_detected
        } else {
            &mut self.none_detected
        };
        if let Some(e) = ev {
            e.emit(n);
        }
    }
}

impl Task for Camera {
    type Command = CameraCmd;
    fn configure(&mut self, ctx: &mut Configure<'_>) -> Result<(), TaskError> {
        self.scene_in = Some(ctx.input(names::SCENE));
        self.a_detected = Some(ctx.event("object_a_detected"));
        self.b_detected = Some(ctx.event("object_b_detected"));
        self.none_detected = Some(ctx.event("no_object_detected"));
        Ok(())
    }
    fn update(&mut self, ctx: &StepContext) -> Result<(), TaskError> {
        if let Phase::Processing { next_row, due_ns } = self.phase {
            let h = self.cfg.height;
            if next_row < h {
                let to = (next_row + self.cfg.rows_per_step).min(h);
                self.process_rows(next_row, to);
                self.phase = Phase::Processing {
                    next_row: to,
                    due_ns,
                };
            } else if ctx.now_ns >= due_ns {
                self.emit_result();
                self.phase = Phase::Done;
            }
        }
        Ok(())
    }
    fn accept(&mut self, _: &CameraCmd, ctx: &StepContext) -> Result<(), RejectReason> {
        let mut scene = CameraScene::default();
        if let Some(r) = &mut self.scene_in {
            r.get(&mut scene);
        }
        self.grab(scene);
        let span = self
            .cfg
            .processing_max_ms
            .saturating_sub(self.cfg.processing_min_ms);
        let ms = self.cfg.processing_min_ms + self.rng.below(span + 1);
        self.phase = Phase::Processing {
            next_row: 0,
            due_ns: ctx.now_ns + ms * 1_000_000,
        };
        Ok(())
    }
    fn progress(&mut self, _: &CameraCmd, _: &StepContext) -> Progress {
        if self.phase == Phase::Done {
            self.phase = Phase::Idle;
            Progress::Done
        } else {
            Progress::Running
        }
    }
    fn has_work(&self) -> bool {
        self.phase != Phase::Idle
    }
}
