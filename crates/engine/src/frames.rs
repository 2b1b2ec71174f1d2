//! The frame pipeline of an animation: each frame runs only the stages the
//! scene's effects call for, and only when their inputs changed.
//!
//! | stage | runs when |
//! |---|---|
//! | `self_collide` | dynamics and self-collision: the previous frame's density map pushes hair out of dense cells |
//! | `simulate` | dynamics, for procedural hair on a moving head (the first frame also settles the hair) |
//! | `body_collide` | dynamics and body collision |
//! | `pose` | the hair moved: drawn strands from the guides, or the rest hair under the head |
//! | `density` | self-shadowing (or a self-collision still lacking a map) and the hair moved since the last fill |
//! | `transmittance` | self-shadowing and the density was just filled |
//! | `filter` | self-shadowing and the hair moved |
//! | `shade` | the hair moved |
//! | `draw` | the hair moved; otherwise the last picture is the frame |
//!
//! The light never moves, so "the hair moved" is the whole test of whether
//! a shadow result can be reused.

use std::time::Instant;

use glam::Affine3A;
use shadow::{MethodConfig, ShadowInput, ShadowMethod};
use sim::Body;

use crate::animate::Animator;
use crate::collide::DensityRepulsion;
use crate::{EngineError, Renderer, Scene, StepPlan};

/// A stage of a frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Stage {
    Simulate,
    SelfCollide,
    BodyCollide,
    Pose,
    Density,
    Transmittance,
    Filter,
    Shade,
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
    pub ran: bool,
    pub ms: f64,
}

/// What one frame did.
#[derive(Debug, Clone, PartialEq)]
pub struct FrameStats {
    pub index: u64,
    /// Scene time of the frame, seconds.
    pub time_s: f32,
    stages: [StageRecord; 9],
    /// Simulation steps taken (the first frame's include the settling).
    pub steps: u32,
}

impl FrameStats {
    pub fn new(index: u64, time_s: f32) -> FrameStats {
        FrameStats {
            index,
            time_s,
            stages: [StageRecord::default(); 9],
            steps: 0,
        }
    }

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

    /// Runs `f` as stage `s`, adding its time.
    pub fn time<T>(&mut self, s: Stage, f: impl FnOnce() -> T) -> T {
        let t = Instant::now();
        let out = f();
        let r = &mut self.stages[s.index()];
        r.ran = true;
        r.ms += t.elapsed().as_secs_f64() * 1e3;
        out
    }
}

/// Which hair a map or result was computed from: the pose counter.
type Version = u64;

/// The frames of one scene, rendered in order.
#[derive(Debug)]
pub struct Sequence {
    scene: Scene,
    anim: Animator,
    renderer: Renderer,
    /// Self-collisions' own density map, when the shadows do not fill one
    /// (self-shadowing off, or another shadow method).
    collision_map: Option<Box<dyn ShadowMethod>>,
    /// Counts poses of the drawn hair.
    version: Version,
    /// The hair the self-collision map holds.
    collision_at: Option<Version>,
    /// The hair the shadow result (and the filtered transmittance) holds.
    shadow_at: Option<Version>,
    shaded_at: Option<Version>,
    picture: Option<(Version, image::RgbImage)>,
    next: u64,
}

impl Sequence {
    pub fn new(scene: &Scene) -> Result<Sequence, EngineError> {
        let anim = Animator::new(scene)?;
        let renderer = Renderer::new(scene)?;
        let shares_map = scene.effects.self_shadow
            && matches!(scene.shadow.method, MethodConfig::DensityMap { .. });
        let collides = anim.simulates() && scene.effects.self_collision;
        let collision_map = if collides && !shares_map {
            Some(
                MethodConfig::DensityMap {
                    cells: scene.shadow.cells().max(1),
                    filter: false,
                }
                .create()?,
            )
        } else {
            None
        };
        Ok(Sequence {
            scene: scene.clone(),
            anim,
            renderer,
            collision_map,
            version: 0,
            collision_at: None,
            shadow_at: None,
            shaded_at: None,
            picture: None,
            next: 0,
        })
    }

    /// Runs the density map's fill and sweep through `executor` (cluster
    /// workers) from the next frame on. The pictures are the same bytes.
    pub fn set_executor(&mut self, executor: Box<dyn crate::Executor>) {
        self.renderer.shadows_mut().set_executor(executor);
    }

    /// The drawn hair of the last frame.
    pub fn hair(&self) -> &strands::Hair {
        self.anim.hair()
    }

    pub fn animator(&self) -> &Animator {
        &self.anim
    }

    /// The renderer, with the last frame's transmittance and colours.
    pub fn renderer(&self) -> &Renderer {
        &self.renderer
    }

    /// Renders the next frame: its picture and what each stage did.
    pub fn next_frame(&mut self) -> Result<(&image::RgbImage, FrameStats), EngineError> {
        let index = self.next;
        // Every log line of the frame (here and in an executor) names it,
        // warnings included.
        let _span = tracing::warn_span!("frame", index).entered();
        let t = index as f32 * self.anim.frame_dt();
        let mut stats = FrameStats::new(index, t);
        let fx = self.scene.effects;

        // Motion: simulated steps, or a rigid move of the head.
        let head = self.anim.head_at(t);
        if self.anim.simulates() {
            let n = self.anim.substeps() as usize;
            let drawn = if fx.body_collision {
                self.bodies(&head)
            } else {
                Vec::new()
            };
            if index == 0 {
                // Settle at the first pose: frames' worth of steps, the
                // collision map refreshed once per such frame.
                let settle = self.anim.settle_frames();
                for f in 0..settle {
                    let last = f + 1 == settle;
                    let d = if last { drawn.clone() } else { Vec::new() };
                    self.advance(&mut stats, vec![head; n], head, d)?;
                }
                if settle == 0 && !drawn.is_empty() {
                    stats.time(Stage::BodyCollide, || self.anim.collide_drawn(&drawn));
                }
            } else {
                let (t0, dt) = (t - self.anim.frame_dt(), self.anim.frame_dt());
                let anim = &self.anim;
                let heads: Vec<Affine3A> = (1..=n)
                    .map(|s| anim.head_at(t0 + dt * s as f32 / n as f32))
                    .collect();
                self.advance(&mut stats, heads, head, drawn)?;
            }
        } else if head != self.anim.head() {
            self.pose(&mut stats, head);
        }
        self.renderer.set_head_pose(head);

        // Shadows, only when the hair moved since the last result.
        let hair = self.anim.hair();
        let version = Some(self.version);
        if fx.self_shadow && self.shadow_at != Some(self.version) {
            let r = &mut self.renderer;
            stats.time(Stage::Density, || r.shadows_mut().density_of(hair, version))?;
            stats.time(Stage::Transmittance, || r.shadows_mut().transmittance())?;
            stats.time(Stage::Filter, || r.filter(hair));
            self.shadow_at = Some(self.version);
            if self.collision_map.is_none() {
                self.collision_at = Some(self.version);
            }
        }
        if self.shaded_at != Some(self.version) {
            let r = &mut self.renderer;
            stats.time(Stage::Shade, || r.shade(hair, fx.self_shadow))?;
            self.shaded_at = Some(self.version);
        }
        if self.picture.as_ref().is_none_or(|p| p.0 != self.version) {
            let r = &mut self.renderer;
            let img = stats.time(Stage::Draw, || r.draw(hair, fx.self_shadow))?;
            self.picture = Some((self.version, img));
        }
        self.next += 1;
        let (_, img) = self.picture.as_ref().expect("drawn above");
        Ok((img, stats))
    }

    /// Poses the drawn hair under `head`: a new version of the hair.
    fn pose(&mut self, stats: &mut FrameStats, head: Affine3A) {
        stats.time(Stage::Pose, || self.anim.set_head(head));
        self.version += 1;
    }

    /// One frame's worth of simulation steps through the executor, under
    /// the head transforms `heads`, then the pose of the drawn hair under
    /// `head`, pushed out of `drawn_bodies`.
    fn advance(
        &mut self,
        stats: &mut FrameStats,
        heads: Vec<Affine3A>,
        head: Affine3A,
        drawn_bodies: Vec<Body>,
    ) -> Result<(), EngineError> {
        let fx = self.scene.effects;
        let c = self.scene.collision;
        if fx.self_collision && self.collision_at != Some(self.version) {
            // The density map of the hair as it is now (the previous frame's).
            let hair = self.anim.hair();
            let version = Some(self.version);
            let shadows = self.renderer.shadows_mut();
            match self
                .collision_map
                .as_mut()
                .and_then(|m| m.as_density_map_method())
            {
                Some(m) => {
                    let input = ShadowInput {
                        light: &self.scene.lights[0],
                        hair,
                        fiber: &self.scene.fiber,
                        occluders: &[],
                    };
                    let ex = shadows.executor_mut();
                    stats.time(Stage::Density, || {
                        m.build_with(&input, |map| ex.fill(0, map, hair, input.fiber, version))
                    })?;
                }
                None => {
                    stats.time(Stage::Density, || shadows.density_of(hair, version))?;
                    // The shadow result now lags the map: recompute it.
                    self.shadow_at = None;
                }
            }
            self.collision_at = Some(self.version);
        }
        let map = match &self.collision_map {
            Some(m) => m.density_map(),
            None => self.renderer.shadows().density_map(),
        };
        let field = map.filter(|_| fx.self_collision).and_then(|m| {
            DensityRepulsion::new(
                m,
                &self.scene.fiber,
                c.density,
                c.repulsion,
                c.max_acceleration,
            )
        });
        let accel = field.map(|f| stats.time(Stage::SelfCollide, || self.anim.sample_field(&f)));
        let bodies = heads
            .iter()
            .map(|h| {
                if fx.body_collision {
                    self.bodies(h)
                } else {
                    Vec::new()
                }
            })
            .collect();
        let plan = StepPlan {
            heads,
            bodies,
            accel,
            drawn_bodies,
            version: self.version + 1,
        };
        let ex = self.renderer.shadows_mut().executor_mut();
        ex.simulate(&mut self.anim, &plan, stats)?;
        self.pose(stats, head);
        if !plan.drawn_bodies.is_empty() {
            let b = &plan.drawn_bodies;
            stats.time(Stage::BodyCollide, || self.anim.collide_drawn(b));
        }
        Ok(())
    }

    /// The head and the scene's bodies under head transform `head`.
    fn bodies(&self, head: &Affine3A) -> Vec<Body> {
        let s = &self.scene;
        s.head
            .as_ref()
            .map(|h| Body {
                center: head.transform_point3(h.center),
                radius: h.radius,
            })
            .into_iter()
            .chain(s.bodies.iter().map(|b| Body {
                center: if b.follows_head {
                    head.transform_point3(b.center)
                } else {
                    b.center
                },
                radius: b.radius,
            }))
            .collect()
    }
}
