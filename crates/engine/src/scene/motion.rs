//! The animated part of a scene: `[effects]`, `[animation]`, `[dynamics]`,
//! `[collision]` and `[[body]]`.

use glam::Vec3;
use serde::Deserialize;
use sim::{Keyframe, Motion, SimParams};

use super::{SceneError, Validator};

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawEffects {
    dynamics: Option<bool>,
    self_collision: Option<bool>,
    body_collision: Option<bool>,
    self_shadow: Option<bool>,
    specular: Option<bool>,
    head_shadow: Option<bool>,
    multiple_scattering: Option<bool>,
    head_bounce: Option<bool>,
}

/// The most frames a shot may declare (`animation.frames`), as many as
/// one run renders.
const MAX_FRAMES: i64 = 1_000_000;

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawAnimation {
    motion: Option<String>,
    amplitude: Option<f32>,
    fps: Option<f32>,
    frames: Option<i64>,
    key: Option<Vec<RawKey>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawKey {
    time: f32,
    translate: Option<[f32; 3]>,
    rotate_deg: Option<[f32; 3]>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawDynamics {
    time_step: Option<f32>,
    gravity: Option<[f32; 3]>,
    damping: Option<f32>,
    stiffness: Option<f32>,
    iterations: Option<i64>,
    settle: Option<f32>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawCollision {
    density: Option<f32>,
    repulsion: Option<f32>,
    max_acceleration: Option<f32>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawBody {
    center: [f32; 3],
    radius: f32,
    follows_head: Option<bool>,
}

/// Which effects the scene calls for. The frame pipeline runs a stage only
/// when an effect needs it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Effects {
    /// Simulate the wisps (procedural styles). Off, or for hair from
    /// files, the hair moves rigidly with the head.
    pub dynamics: bool,
    /// Hair is pushed out of cells denser than `collision.density`
    /// (with dynamics).
    pub self_collision: bool,
    /// Hair is kept out of the head and the `[[body]]` spheres (with
    /// dynamics).
    pub body_collision: bool,
    /// The shadow stages; off, every transmittance is 1.
    pub self_shadow: bool,
    /// The Kajiya-Kay highlight.
    pub specular: bool,
    /// The head casts shadow on the hair and receives the hair's (with
    /// self-shadowing).
    pub head_shadow: bool,
    /// Light scattered between fibers (dual scattering from the
    /// self-shadowing's transmittance; with the fiber shading model and
    /// self-shadowing).
    pub multiple_scattering: bool,
    /// With multiple scattering, the head lights the hair around it with
    /// the light it reflects (a diffuse surface of its colour).
    pub head_bounce: bool,
}

/// How the scene moves in time.
#[derive(Debug, Clone, PartialEq)]
pub struct Animation {
    /// How the head moves.
    pub motion: Motion,
    /// Frames per second of a rendered sequence.
    pub fps: f32,
    /// The shot's frames, `0..frames`, when the scene says
    /// (`animation.frames`): the camera is framed on the head's motion
    /// over them. Otherwise over the motion's whole span
    /// ([`Motion::span`]). Never the frames a run renders, so that frame
    /// `k` is the same picture whatever range is rendered.
    pub frames: Option<u64>,
}

impl Animation {
    /// The frames the camera is framed over: `0..=last`.
    pub fn framing_last_frame(&self) -> u64 {
        match self.frames {
            Some(n) => n.saturating_sub(1),
            None => (f64::from(self.motion.span()) * f64::from(self.fps)).ceil() as u64,
        }
    }
}

/// The wisp simulation's settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Dynamics {
    /// Step, gravity, damping and stiffness.
    pub params: SimParams,
    /// Seconds simulated at the first pose before frame 0, so that the
    /// first frame shows hair at rest under gravity rather than falling.
    pub settle_s: f32,
}

impl Dynamics {
    /// Simulation steps per frame at `fps`: the time step rounded so that a
    /// frame holds a whole number of steps, at least one.
    pub fn steps_per_frame(&self, fps: f32) -> u32 {
        (1.0 / (f64::from(fps) * f64::from(self.params.dt)))
            .round()
            .clamp(1.0, f64::from(u32::MAX)) as u32
    }
}

/// Self-collisions through the density map (see the engine's `collide` module).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Collision {
    /// `rho_max`: hair density (length per volume, 1/scene unit^2) above
    /// which a cell pushes hair out.
    pub density: f32,
    /// `k`: acceleration (scene units/s^2) per unit of relative excess
    /// density `rho / rho_max - 1`.
    pub repulsion: f32,
    /// `a_max`: the bound on the repulsion, scene units/s^2.
    pub max_acceleration: f32,
}

/// A sphere hair collides with (neck, shoulders); the head is one too.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BodySettings {
    /// Centre, scene units.
    pub center: Vec3,
    /// Radius, scene units.
    pub radius: f32,
    /// Moves with the head's motion (else stays put in the world).
    pub follows_head: bool,
}

pub(super) const DEFAULT_FPS: f32 = 30.0;
/// The most simulation steps one frame may take.
pub(super) const MAX_STEPS_PER_FRAME: u32 = 1000;
/// The most steps the settling before frame 0 may take.
pub(super) const MAX_SETTLE_STEPS: u32 = 100_000;
pub(super) const DEFAULT_SETTLE_S: f32 = 1.0;
pub(super) const DEFAULT_DANCE_AMPLITUDE: f32 = 1.0;
/// Twice the density around a typical strand of the smooth style (half its
/// hair lies in cells below 10 per cm^2 at 128^3 cells): only where wisps
/// crowd together does hair push.
pub(super) const DEFAULT_COLLISION_DENSITY: f32 = 20.0;
/// At twice the threshold density, about gravity.
pub(super) const DEFAULT_REPULSION: f32 = 1000.0;
/// Three times gravity: enough to part wisps, bounded so that a very dense
/// cell cannot fling hair.
pub(super) const DEFAULT_MAX_ACCELERATION: f32 = 3000.0;

impl Validator<'_> {
    pub(super) fn effects(&self, e: RawEffects, from_file: bool) -> Result<Effects, SceneError> {
        if from_file && e.dynamics == Some(true) {
            return Err(self.invalid(
                "effects.dynamics",
                true,
                "hair from a file or hair.strands has no wisps of guide strands to simulate; \
                 it moves rigidly with the head",
            ));
        }
        Ok(Effects {
            dynamics: e.dynamics.unwrap_or(!from_file),
            self_collision: e.self_collision.unwrap_or(true),
            body_collision: e.body_collision.unwrap_or(true),
            self_shadow: e.self_shadow.unwrap_or(true),
            specular: e.specular.unwrap_or(true),
            head_shadow: e.head_shadow.unwrap_or(true),
            multiple_scattering: e.multiple_scattering.unwrap_or(false),
            head_bounce: e.head_bounce.unwrap_or(true),
        })
    }

    pub(super) fn animation(&self, a: RawAnimation) -> Result<Animation, SceneError> {
        let fps = a.fps.unwrap_or(DEFAULT_FPS);
        if !(fps.is_finite() && (0.1..=1000.0).contains(&fps)) {
            return Err(self.invalid("animation.fps", fps, "must be in 0.1..=1000"));
        }
        let name = a.motion.as_deref().unwrap_or("still");
        let refuse = |field: &'static str, set: bool, owner: &str| {
            if set {
                Err(self.invalid(
                    field,
                    "(set)",
                    format!("applies to motion {owner:?} only, not {name:?}"),
                ))
            } else {
                Ok(())
            }
        };
        let motion = match name {
            "still" => {
                refuse("animation.amplitude", a.amplitude.is_some(), "dance")?;
                refuse("animation.key", a.key.is_some(), "keyframes")?;
                Motion::Still
            }
            "dance" => {
                refuse("animation.key", a.key.is_some(), "keyframes")?;
                let amplitude = a.amplitude.unwrap_or(DEFAULT_DANCE_AMPLITUDE);
                if !(amplitude.is_finite() && (0.0..=10.0).contains(&amplitude)) {
                    return Err(self.invalid(
                        "animation.amplitude",
                        amplitude,
                        "must be in 0..=10",
                    ));
                }
                Motion::Dance { amplitude }
            }
            "keyframes" => {
                refuse("animation.amplitude", a.amplitude.is_some(), "dance")?;
                let raw_keys = a.key.unwrap_or_default();
                if raw_keys.len() > super::MAX_KEYFRAMES {
                    return Err(self.invalid(
                        "animation.key",
                        format!("({} tables)", raw_keys.len()),
                        format!("at most {} keyframes", super::MAX_KEYFRAMES),
                    ));
                }
                let keys: Vec<Keyframe> = raw_keys
                    .into_iter()
                    .map(|k| Keyframe {
                        time: k.time,
                        translate: Vec3::from_array(k.translate.unwrap_or_default()),
                        rotate_deg: Vec3::from_array(k.rotate_deg.unwrap_or_default()),
                    })
                    .collect();
                let m = Motion::Keyframes(keys);
                m.validate().map_err(|e| {
                    self.invalid(
                        "animation.key",
                        "(keys)",
                        format!(
                            "{e}; give [[animation.key]] tables with time, translate, rotate_deg"
                        ),
                    )
                })?;
                m
            }
            other => {
                return Err(self.invalid(
                    "animation.motion",
                    format!("{other:?}"),
                    "expected \"still\", \"dance\" or \"keyframes\"",
                ));
            }
        };
        let frames = match a.frames {
            None => None,
            Some(n) if (1..=MAX_FRAMES).contains(&n) => Some(n as u64),
            Some(n) => {
                return Err(self.invalid(
                    "animation.frames",
                    n,
                    format!("must be in 1..={}", MAX_FRAMES),
                ));
            }
        };
        Ok(Animation {
            motion,
            fps,
            frames,
        })
    }

    pub(super) fn dynamics(&self, d: RawDynamics) -> Result<Dynamics, SceneError> {
        let def = SimParams::default();
        let gravity = d.gravity.map_or(def.gravity, Vec3::from_array);
        if !gravity.is_finite() {
            return Err(self.invalid("dynamics.gravity", gravity, "must be finite"));
        }
        let dt = d.time_step.unwrap_or(def.dt);
        if !(dt.is_finite() && dt > 0.0 && dt <= 0.1) {
            return Err(self.invalid("dynamics.time_step", dt, "must be in (0, 0.1] seconds"));
        }
        let stiffness = d.stiffness.unwrap_or(def.stiffness);
        if !(0.0..=1.0).contains(&stiffness) {
            return Err(self.invalid("dynamics.stiffness", stiffness, "must be in [0, 1]"));
        }
        let settle_s = d.settle.unwrap_or(DEFAULT_SETTLE_S);
        if !(settle_s.is_finite() && (0.0..=60.0).contains(&settle_s)) {
            return Err(self.invalid("dynamics.settle", settle_s, "must be in 0..=60 seconds"));
        }
        let params = SimParams {
            dt,
            gravity,
            damping: self.positive("dynamics.damping", d.damping, def.damping)?,
            stiffness,
            iterations: self.int("dynamics.iterations", d.iterations, def.iterations, 1..=64)?,
        };
        Ok(Dynamics { params, settle_s })
    }

    /// Refuses step counts that would run for hours: more than
    /// [`MAX_STEPS_PER_FRAME`] steps a frame, or more than
    /// [`MAX_SETTLE_STEPS`] steps of settling.
    pub(super) fn steps_in_bounds(&self, a: &Animation, d: &Dynamics) -> Result<(), SceneError> {
        let per_frame = d.steps_per_frame(a.fps);
        if per_frame > MAX_STEPS_PER_FRAME {
            return Err(self.invalid(
                "dynamics.time_step",
                d.params.dt,
                format!(
                    "{per_frame} steps a frame at {} fps; at most {MAX_STEPS_PER_FRAME}",
                    a.fps
                ),
            ));
        }
        let settle = (f64::from(d.settle_s) * f64::from(a.fps)).ceil() * f64::from(per_frame);
        if settle > f64::from(MAX_SETTLE_STEPS) {
            return Err(self.invalid(
                "dynamics.settle",
                d.settle_s,
                format!("{settle} steps of settling; at most {MAX_SETTLE_STEPS}"),
            ));
        }
        Ok(())
    }

    pub(super) fn collision(&self, c: RawCollision) -> Result<Collision, SceneError> {
        let density = self.positive("collision.density", c.density, DEFAULT_COLLISION_DENSITY)?;
        if density == 0.0 {
            return Err(self.invalid("collision.density", density, "must be > 0"));
        }
        Ok(Collision {
            density,
            repulsion: self.positive("collision.repulsion", c.repulsion, DEFAULT_REPULSION)?,
            max_acceleration: self.positive(
                "collision.max_acceleration",
                c.max_acceleration,
                DEFAULT_MAX_ACCELERATION,
            )?,
        })
    }

    pub(super) fn bodies(&self, b: Option<Vec<RawBody>>) -> Result<Vec<BodySettings>, SceneError> {
        let b = b.unwrap_or_default();
        if b.len() > super::MAX_BODIES {
            return Err(self.invalid(
                "body",
                format!("({} tables)", b.len()),
                format!("at most {} bodies", super::MAX_BODIES),
            ));
        }
        b.into_iter()
            .map(|b| {
                let center = Vec3::from_array(b.center);
                if !center.is_finite() {
                    return Err(self.invalid("body.center", center, "must be finite"));
                }
                if !(b.radius.is_finite() && b.radius > 0.0) {
                    return Err(self.invalid(
                        "body.radius",
                        b.radius,
                        "must be a finite number > 0",
                    ));
                }
                Ok(BodySettings {
                    center,
                    radius: b.radius,
                    follows_head: b.follows_head.unwrap_or(true),
                })
            })
            .collect()
    }
}
