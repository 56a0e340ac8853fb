//! The simulated world of the cell: three gantry axes (mass, viscous friction, brakes when the
//! amplifiers are off), a pneumatic gripper with end switches and an "object present" sensor,
//! objects of a seeded sequence of kinds appearing at the pick position, carried when
//! grabbed and landing in whatever container lies below when released, and the faults a test
//! injects (the gripper loses the object while moving, the e-stop button).
//!
//! Pure state and arithmetic, no realtime handles: [`World::step`] is called by the `hw` task
//! ([`super::hw`]) at the end of every servo cycle, and tests can drive it alone.

use super::rng::SplitMix64;
use super::types::{
    distance, CameraScene, Container, DriveOutput, Feedback, ObjectKind, Vec3, WorldTally, AXES,
};

/// Where things are in the cell, mm (Z up; the table at Z = 0).
#[derive(Debug, Clone, Copy, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields)]
pub struct Layout {
    /// Home and start position of the gripper.
    pub home_mm: Vec3,
    /// Where the gripper closes on an arriving object.
    pub pick_mm: Vec3,
    /// Where the camera looks at the held object.
    pub camera_mm: Vec3,
    /// Release positions above containers A, B and reject.
    pub containers_mm: [Vec3; 3],
    /// Height of travel moves.
    pub travel_z_mm: f64,
}

impl Default for Layout {
    fn default() -> Self {
        Self {
            home_mm: [0.0, 0.0, 100.0],
            pick_mm: [50.0, 50.0, 10.0],
            camera_mm: [200.0, 50.0, 80.0],
            containers_mm: [
                [100.0, 250.0, 60.0],
                [200.0, 250.0, 60.0],
                [300.0, 250.0, 60.0],
            ],
            travel_z_mm: 100.0,
        }
    }
}

impl Layout {
    /// Release position above `c`.
    pub fn container(&self, c: Container) -> Vec3 {
        self.containers_mm[c.index()]
    }
}

/// Faults a test or an operator injects into the world.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields)]
pub struct Faults {
    /// The gripper loses the `n`-th grabbed object (from 1) once it has carried it
    /// [`World::DROP_DISTANCE_MM`] away from the pick position.
    #[serde(default)]
    pub drop_on_grab: Option<u32>,
}

/// Physical parameters of the simulation.
#[derive(Debug, Clone, Copy, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields)]
pub struct WorldConfig {
    /// Seed of the object sequence.
    pub seed: u64,
    /// Moving mass per axis, kg.
    #[serde(default = "default_mass")]
    pub mass_kg: f64,
    /// Viscous friction per axis, N·s/m.
    #[serde(default = "default_friction")]
    pub friction_n_s_m: f64,
    /// Time the gripper takes to open or close, ms.
    #[serde(default = "default_gripper_ms")]
    pub gripper_ms: f64,
    /// How close the fingers must be to an object to grab it, mm.
    #[serde(default = "default_grab_radius")]
    pub grab_radius_mm: f64,
    /// How close to a release position an object must fall to land in that container, mm.
    #[serde(default = "default_container_radius")]
    pub container_radius_mm: f64,
    /// How close to the camera position a held object is in view, mm.
    #[serde(default = "default_camera_radius")]
    pub camera_radius_mm: f64,
    /// Faults to inject.
    #[serde(default)]
    pub faults: Faults,
}

fn default_mass() -> f64 {
    2.0
}
fn default_friction() -> f64 {
    20.0
}
fn default_gripper_ms() -> f64 {
    80.0
}
fn default_grab_radius() -> f64 {
    2.0
}
fn default_container_radius() -> f64 {
    40.0
}
fn default_camera_radius() -> f64 {
    5.0
}

impl WorldConfig {
    /// Defaults with `seed`.
    pub fn with_seed(seed: u64) -> Self {
        Self {
            seed,
            mass_kg: default_mass(),
            friction_n_s_m: default_friction(),
            gripper_ms: default_gripper_ms(),
            grab_radius_mm: default_grab_radius(),
            container_radius_mm: default_container_radius(),
            camera_radius_mm: default_camera_radius(),
            faults: Faults::default(),
        }
    }
}

/// The kinds of the first `n` objects a world seeded with `seed` brings: what a correct
/// selection must sort (tests check the counts against it).
pub fn object_sequence(seed: u64, n: usize) -> Vec<ObjectKind> {
    let mut rng = SplitMix64::new(seed);
    (0..n).map(|_| next_kind(&mut rng)).collect()
}

fn next_kind(rng: &mut SplitMix64) -> ObjectKind {
    match rng.below(3) {
        0 => ObjectKind::A,
        1 => ObjectKind::B,
        _ => ObjectKind::Unknown,
    }
}

/// The simulated cell.
#[derive(Debug, Clone)]
pub struct World {
    cfg: WorldConfig,
    layout: Layout,
    rng: SplitMix64,
    position_mm: Vec3,
    velocity_mm_s: Vec3,
    /// 0 = open, 1 = closed.
    closure: f64,
    at_pick: Option<ObjectKind>,
    held: Option<ObjectKind>,
    grabs: u32,
    estop_pressed: bool,
    tally: WorldTally,
}

impl World {
    /// How far from the pick position a fault-injected object slips out, mm.
    pub const DROP_DISTANCE_MM: f64 = 30.0;

    /// A world with the gripper open at the home position and the first object at the pick
    /// position.
    pub fn new(cfg: WorldConfig, layout: Layout) -> Self {
        let mut w = Self {
            cfg,
            layout,
            rng: SplitMix64::new(cfg.seed),
            position_mm: layout.home_mm,
            velocity_mm_s: [0.0; AXES],
            closure: 0.0,
            at_pick: None,
            held: None,
            grabs: 0,
            estop_pressed: false,
            tally: WorldTally::default(),
        };
        w.spawn();
        w
    }

    fn spawn(&mut self) {
        self.at_pick = Some(next_kind(&mut self.rng));
        self.tally.spawned += 1;
    }

    /// Presses (true) or releases the e-stop button.
    pub fn set_estop(&mut self, pressed: bool) {
        self.estop_pressed = pressed;
    }

    /// The gripper loses the object it holds, now (fault injection). True if it held one.
    pub fn drop_object(&mut self) -> bool {
        if self.held.take().is_some() {
            self.tally.on_floor += 1;
            true
        } else {
            false
        }
    }

    /// One cycle of `dt_s`: applies the drive outputs and returns what the sensors read.
    pub fn step(&mut self, dt_s: f64, out: &DriveOutput) -> Feedback {
        self.move_axes(dt_s, out);
        self.move_gripper(dt_s, out.gripper_close);
        let from_pick = distance(&self.position_mm, &self.layout.pick_mm);
        if self.held.is_some()
            && self.cfg.faults.drop_on_grab == Some(self.grabs)
            && from_pick > Self::DROP_DISTANCE_MM
        {
            self.drop_object();
        }
        if self.at_pick.is_none() && from_pick > Self::DROP_DISTANCE_MM {
            self.spawn();
        }
        self.feedback()
    }

    fn move_axes(&mut self, dt_s: f64, out: &DriveOutput) {
        for i in 0..AXES {
            if !out.enabled {
                // Brakes: a disabled axis stands still.
                self.velocity_mm_s[i] = 0.0;
                continue;
            }
            let friction_n = self.cfg.friction_n_s_m * self.velocity_mm_s[i] * 1e-3;
            let accel_mm_s2 = (out.force_n[i] - friction_n) / self.cfg.mass_kg * 1e3;
            self.velocity_mm_s[i] += accel_mm_s2 * dt_s;
            self.position_mm[i] += self.velocity_mm_s[i] * dt_s;
        }
    }

    fn move_gripper(&mut self, dt_s: f64, close: bool) {
        let rate = dt_s * 1e3 / self.cfg.gripper_ms.max(1e-3);
        let was_closed = self.closure >= 1.0;
        self.closure = if close {
            (self.closure + rate).min(1.0)
        } else {
            (self.closure - rate).max(0.0)
        };
        if self.closure >= 1.0 && !was_closed && self.held.is_none() {
            let near = distance(&self.position_mm, &self.layout.pick_mm) <= self.cfg.grab_radius_mm;
            if near {
                if let Some(kind) = self.at_pick.take() {
                    self.held = Some(kind);
                    self.grabs += 1;
                }
            }
        }
        if self.closure < 0.5 {
            if let Some(kind) = self.held.take() {
                self.release(kind);
            }
        }
    }

    fn release(&mut self, kind: ObjectKind) {
        let xy = |p: &Vec3| [p[0], p[1], 0.0];
        let here = xy(&self.position_mm);
        let target = Container::ALL.into_iter().find(|c| {
            distance(&here, &xy(&self.layout.container(*c))) <= self.cfg.container_radius_mm
        });
        match target {
            Some(c) => {
                self.tally.in_container[c.index()] += 1;
                if kind.container() != c {
                    self.tally.missorted += 1;
                }
            }
            None => self.tally.on_floor += 1,
        }
    }

    /// What the sensors read now.
    pub fn feedback(&self) -> Feedback {
        Feedback {
            position_mm: self.position_mm,
            gripper_open: self.closure <= 0.0,
            gripper_closed: self.closure >= 1.0,
            object_present: self.held.is_some(),
            estop_pressed: self.estop_pressed,
        }
    }

    /// What the camera sees.
    pub fn scene(&self) -> CameraScene {
        let in_view =
            distance(&self.position_mm, &self.layout.camera_mm) <= self.cfg.camera_radius_mm;
        CameraScene {
            object: if in_view { self.held } else { None },
        }
    }

    /// Objects counted so far.
    pub fn tally(&self) -> WorldTally {
        self.tally
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn hold(w: &mut World, at: Vec3, close: bool, cycles: usize) {
        // Teleport for the test: the axes are exercised through the servo tasks elsewhere.
        w.position_mm = at;
        let out = DriveOutput {
            gripper_close: close,
            ..DriveOutput::default()
        };
        for _ in 0..cycles {
            w.step(1e-3, &out);
        }
    }

    #[test]
    fn grab_at_pick_release_over_container_counts_it() {
        let layout = Layout::default();
        let mut w = World::new(WorldConfig::with_seed(3), layout);
        let first = object_sequence(3, 1)[0];
        hold(&mut w, layout.pick_mm, true, 100);
        assert!(w.feedback().object_present);
        hold(&mut w, layout.camera_mm, true, 1);
        assert_eq!(w.scene().object, Some(first));
        let c = first.container();
        hold(&mut w, layout.container(c), false, 100);
        let t = w.tally();
        assert_eq!(t.in_container[c.index()], 1);
        assert_eq!((t.missorted, t.on_floor, t.spawned), (0, 0, 2));
    }

    #[test]
    fn closing_away_from_the_object_grabs_nothing_and_faults_drop() {
        let layout = Layout::default();
        let mut cfg = WorldConfig::with_seed(1);
        cfg.faults.drop_on_grab = Some(1);
        let mut w = World::new(cfg, layout);
        hold(&mut w, layout.home_mm, true, 100);
        assert!(!w.feedback().object_present);
        hold(&mut w, layout.pick_mm, false, 100);
        hold(&mut w, layout.pick_mm, true, 100);
        assert!(w.feedback().object_present);
        hold(&mut w, layout.camera_mm, true, 1);
        assert!(!w.feedback().object_present, "lost on the way");
        assert_eq!(w.tally().on_floor, 1);
    }
}
