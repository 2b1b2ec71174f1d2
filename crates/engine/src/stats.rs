//! What each stage of a frame did: whether it ran and how long it took.

use std::sync::atomic::{AtomicU8, Ordering};
use std::time::Instant;

/// The stage this process runs now ([`Stage::ALL`]'s index; past its end:
/// none), for a progress display.
static RUNNING: AtomicU8 = AtomicU8::new(u8::MAX);

/// The stage a [`FrameStats::time`] of this process runs now, if any: what
/// a progress display names while a long frame renders.
pub fn running_stage() -> Option<Stage> {
    Stage::ALL
        .get(RUNNING.load(Ordering::Relaxed) as usize)
        .copied()
}

/// A stage of a frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Stage {
    /// The wisps' simulation.
    Simulate,
    /// Sampling the self-collision field from the density map.
    SelfCollide,
    /// Collisions with the body spheres.
    BodyCollide,
    /// Drawn strands from the guides, or the rest hair moved.
    Pose,
    /// Filling the density map (or any method's build).
    Density,
    /// Sweeping it (or any method's prepare).
    Transmittance,
    /// Transmittance at every drawn vertex.
    Filter,
    /// Shading every vertex.
    Shade,
    /// Drawing the picture.
    Draw,
}

impl Stage {
    /// Every stage, in the order a frame runs them (self-collision forces
    /// are sampled before each simulation step).
    pub const ALL: [Stage; 9] = [
        Stage::SelfCollide,
        Stage::Simulate,
        Stage::BodyCollide,
        Stage::Pose,
        Stage::Density,
        Stage::Transmittance,
        Stage::Filter,
        Stage::Shade,
        Stage::Draw,
    ];

    /// The stage's name in `--stats` files.
    pub fn name(self) -> &'static str {
        match self {
            Stage::Simulate => "simulate",
            Stage::SelfCollide => "self_collide",
            Stage::BodyCollide => "body_collide",
            Stage::Pose => "pose",
            Stage::Density => "density",
            Stage::Transmittance => "transmittance",
            Stage::Filter => "filter",
            Stage::Shade => "shade",
            Stage::Draw => "draw",
        }
    }

    fn index(self) -> usize {
        Stage::ALL
            .iter()
            .position(|&s| s == self)
            .expect("every stage is listed")
    }
}

/// Whether a stage ran in a frame and its wall-clock milliseconds (summed
/// over the simulation steps of the frame).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct StageRecord {
    /// Whether the stage ran.
    pub ran: bool,
    /// Its milliseconds.
    pub ms: f64,
}

/// What one frame did.
#[derive(Debug, Clone, PartialEq)]
pub struct FrameStats {
    /// The frame's number, from 0.
    pub index: u64,
    /// Scene time of the frame, seconds.
    pub time_s: f32,
    stages: [StageRecord; 9],
    /// Simulation steps taken (the first frame's include the settling).
    pub steps: u32,
    /// Density samples the frame's shadow fill deposited, over all lights
    /// (0 when the shadows were reused).
    pub samples: u64,
}

impl FrameStats {
    /// Frame `index` at `time_s`, no stage run yet.
    pub fn new(index: u64, time_s: f32) -> FrameStats {
        FrameStats {
            index,
            time_s,
            stages: [StageRecord::default(); 9],
            steps: 0,
            samples: 0,
        }
    }

    /// What stage `s` did.
    pub fn stage(&self, s: Stage) -> StageRecord {
        self.stages[s.index()]
    }

    /// Every stage with its record, in [`Stage::ALL`] order.
    pub fn stages(&self) -> impl Iterator<Item = (Stage, StageRecord)> + '_ {
        Stage::ALL.iter().map(|&s| (s, self.stage(s)))
    }

    /// Milliseconds of all stages.
    pub fn total_ms(&self) -> f64 {
        self.stages.iter().map(|r| r.ms).sum()
    }

    /// Marks stage `s` as run, adding `ms` milliseconds measured elsewhere.
    pub fn record(&mut self, s: Stage, ms: f64) {
        let r = &mut self.stages[s.index()];
        r.ran = true;
        r.ms += ms.max(0.0);
    }

    /// Runs `f` as stage `s`, adding its time.
    pub fn time<T>(&mut self, s: Stage, f: impl FnOnce() -> T) -> T {
        let t = Instant::now();
        let before = RUNNING.swap(s.index() as u8, Ordering::Relaxed);
        let out = f();
        RUNNING.store(before, Ordering::Relaxed);
        let r = &mut self.stages[s.index()];
        r.ran = true;
        r.ms += t.elapsed().as_secs_f64() * 1e3;
        out
    }
}

/// The record `--stats` files and the viewer's overlay show:
/// `{"index", "time_s", "steps", "stages": {name: {"ran", "ms"}}}`, the
/// stages in [`Stage::ALL`] order.
impl serde::Serialize for FrameStats {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        use serde::ser::{SerializeMap, SerializeStruct};

        struct Stages<'a>(&'a FrameStats);
        struct Record(StageRecord);
        impl serde::Serialize for Record {
            fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
                let mut r = s.serialize_struct("StageRecord", 2)?;
                r.serialize_field("ran", &self.0.ran)?;
                r.serialize_field("ms", &self.0.ms)?;
                r.end()
            }
        }
        impl serde::Serialize for Stages<'_> {
            fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
                let mut m = s.serialize_map(Some(Stage::ALL.len()))?;
                for (stage, r) in self.0.stages() {
                    m.serialize_entry(stage.name(), &Record(r))?;
                }
                m.end()
            }
        }
        let mut f = s.serialize_struct("FrameStats", 4)?;
        f.serialize_field("index", &self.index)?;
        f.serialize_field("time_s", &self.time_s)?;
        f.serialize_field("steps", &self.steps)?;
        f.serialize_field("stages", &Stages(self))?;
        f.end()
    }
}

/// Milliseconds of the stages of one [`crate::Share::draw`].
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct DrawTimes {
    /// The filter stage, ms.
    pub filter_ms: f64,
    /// Shading, ms.
    pub shade_ms: f64,
    /// Rasterization, ms.
    pub raster_ms: f64,
    /// Compositing on the workers: waiting for the others' stripes of
    /// this share's band, then resolving it.
    pub wait_ms: f64,
    /// Resolving the band, ms.
    pub composite_ms: f64,
}

pub(crate) fn ms(since: Instant) -> f64 {
    since.elapsed().as_secs_f64() * 1e3
}
