//! The session: one thread that owns the frame pipeline, takes the pages'
//! controls between frames, and publishes each frame (its picture and what
//! every stage did) as the latest; pages read the latest when they are
//! ready, so a slow page skips frames and nothing queues.

use std::collections::VecDeque;
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::mpsc::{Receiver, RecvTimeoutError};
use std::time::{Duration, Instant};

use axum::body::Bytes;
use engine::{EngineError, Executor, FrameStats, Scene, Sequence, Stage};
use glam::{Quat, Vec3};
use raster::{Camera, ShadingModel};
use shadow::{Light, MethodConfig};
use tokio::sync::{mpsc, watch};

use crate::ViewerError;
use crate::control::{Control, EFFECTS, main_setting, with_main_setting};

/// Makes the executor of a scene's frames: cluster workers, connected for
/// each scene the page changes to. `None` in the session: this process.
pub type Connect = Box<dyn FnMut(&Scene) -> Result<Box<dyn Executor>, EngineError> + Send>;

/// What a page sent, with where to tell it what was wrong.
#[derive(Debug)]
pub(crate) enum Input {
    Control {
        control: Control,
        errors: mpsc::Sender<String>,
    },
    /// A page arrived: render if nothing was rendered for lack of one.
    Wake,
}

/// The pages watching, counted by the server.
pub(crate) type Viewers = Arc<AtomicUsize>;

/// The camera about its target, in degrees and scene units, `up` as the
/// framed camera's.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Orbit {
    target: Vec3,
    /// Rotation from +y up to the camera's up.
    frame: Quat,
    yaw_deg: f32,
    pitch_deg: f32,
    distance: f32,
}

impl Orbit {
    fn of(camera: &Camera) -> Orbit {
        let target = camera.look_at();
        let up = camera.up_hint().normalize_or(Vec3::Y);
        let frame = Quat::from_rotation_arc(Vec3::Y, up);
        let local = frame.inverse() * (camera.position - target);
        let distance = local.length().max(1e-6);
        Orbit {
            target,
            frame,
            yaw_deg: local.x.atan2(local.z).to_degrees(),
            pitch_deg: (local.y / distance).clamp(-1.0, 1.0).asin().to_degrees(),
            distance,
        }
    }

    fn camera(&self, like: &Camera) -> Result<Camera, raster::RasterError> {
        let (yaw, pitch) = (self.yaw_deg.to_radians(), self.pitch_deg.to_radians());
        let local = Vec3::new(
            pitch.cos() * yaw.sin(),
            pitch.sin(),
            pitch.cos() * yaw.cos(),
        ) * self.distance;
        Camera::new(
            self.target + self.frame * local,
            self.target,
            like.fov_deg(),
            like.width(),
            like.height(),
        )?
        .with_up(like.up_hint())
    }
}

/// Where light `l` comes from, seen from `centre`: azimuth about +y from
/// +z towards +x and elevation, degrees; and its distance (a source).
fn light_angles(l: &Light, centre: Vec3) -> (f32, f32, Option<f32>) {
    let (from, distance) = match *l {
        Light::Directional { direction } => (-direction, None),
        Light::Point { position, .. } | Light::Spot { position, .. } => {
            let d = position - centre;
            (d, Some(d.length()))
        }
    };
    let from = from.normalize_or(Vec3::Y);
    (
        from.x.atan2(from.z).to_degrees(),
        from.y.clamp(-1.0, 1.0).asin().to_degrees(),
        distance,
    )
}

/// Light `l` moved to come from azimuth `az` and elevation `el` (degrees)
/// seen from `centre`; a source at `distance` (or where it was), a spot
/// aimed at `centre`.
fn placed(l: &Light, centre: Vec3, az: f32, el: f32, distance: Option<f32>) -> Light {
    let (az, el) = (az.to_radians(), el.to_radians());
    let from = Vec3::new(el.cos() * az.sin(), el.sin(), el.cos() * az.cos());
    let at = |position: Vec3| {
        let r = distance.unwrap_or_else(|| position.distance(centre));
        centre + from * r
    };
    match *l {
        Light::Directional { .. } => Light::Directional { direction: -from },
        Light::Point {
            position,
            intensity,
        } => Light::Point {
            position: at(position),
            intensity,
        },
        Light::Spot {
            position,
            cone_deg,
            falloff_deg,
            intensity,
            ..
        } => Light::Spot {
            position: at(position),
            direction: -from,
            cone_deg,
            falloff_deg,
            intensity,
        },
    }
}

/// The session's state, owned by its thread.
pub(crate) struct Session {
    seq: Sequence,
    /// The scene of the last frame that rendered (what a failed change
    /// goes back to).
    good: Scene,
    connect: Option<Connect>,
    workers: usize,
    playing: bool,
    steps: u32,
    /// A control changed something the current frame shows.
    dirty: bool,
    /// The camera the first frame framed, and the orbit now.
    framed: Option<(Camera, Orbit)>,
    orbit: Option<Orbit>,
    /// The hair's centre when first framed: lights turn about it.
    centre: Vec3,
    error: Option<String>,
    /// When the last second's frames were published (while playing).
    recent: VecDeque<Instant>,
    last_stats: Option<FrameStats>,
    last_picture: Option<Bytes>,
    published: u64,
}

impl std::fmt::Debug for Session {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Session")
            .field("playing", &self.playing)
            .field("workers", &self.workers)
            .finish_non_exhaustive()
    }
}

impl Session {
    /// A session of `scene`, through the executor `connect` makes (cluster
    /// workers; `workers` of them) or in this process.
    pub(crate) fn new(
        scene: &Scene,
        mut connect: Option<Connect>,
        workers: usize,
    ) -> Result<Session, ViewerError> {
        let mut seq = Sequence::new(scene)?;
        if let Some(c) = &mut connect {
            seq.set_executor(c(scene)?)?;
        }
        Ok(Session {
            seq,
            good: scene.clone(),
            connect,
            workers,
            playing: true,
            steps: 0,
            dirty: true,
            framed: None,
            orbit: None,
            centre: Vec3::ZERO,
            error: None,
            recent: VecDeque::new(),
            last_stats: None,
            last_picture: None,
            published: 0,
        })
    }

    /// Renders and publishes frames until every sender of `inputs` is
    /// gone: while playing at most the scene's frame rate, paused only
    /// what a control asks for, and nothing while no page watches.
    pub(crate) fn run(
        mut self,
        inputs: Receiver<Input>,
        frames: watch::Sender<Option<Bytes>>,
        viewers: Viewers,
    ) {
        let period = Duration::from_secs_f32(1.0 / self.seq.scene().animation.fps.max(1e-3));
        let mut due = Instant::now();
        loop {
            let watched = viewers.load(Ordering::Relaxed) > 0;
            let work = watched && (self.playing || self.steps > 0 || self.dirty);
            // Wait for the next frame's time, or for input when there is
            // nothing to render.
            let first = if work {
                let wait = due.saturating_duration_since(Instant::now());
                if self.playing && !self.dirty && wait > Duration::ZERO {
                    match inputs.recv_timeout(wait) {
                        Ok(i) => Some(i),
                        Err(RecvTimeoutError::Timeout) => None,
                        Err(RecvTimeoutError::Disconnected) => return,
                    }
                } else {
                    None
                }
            } else {
                match inputs.recv() {
                    Ok(i) => Some(i),
                    Err(_) => return,
                }
            };
            let playing = self.playing;
            for input in first.into_iter().chain(inputs.try_iter()) {
                if let Input::Control { control, errors } = input
                    && let Err(e) = self.apply(control)
                {
                    let _ = errors.try_send(e.to_string());
                }
            }
            // Paused: every page learns it at once, with the frame it
            // stopped on.
            if playing
                && !self.playing
                && !self.dirty
                && self.steps == 0
                && let Some(msg) = self.message()
            {
                frames.send_replace(Some(msg));
            }
            let watched = viewers.load(Ordering::Relaxed) > 0;
            if !watched || !(self.playing || self.steps > 0 || self.dirty) {
                continue;
            }
            if self.playing && !self.dirty && Instant::now() < due {
                continue;
            }
            due = Instant::now() + period;
            self.frame();
            if let Some(msg) = self.message() {
                frames.send_replace(Some(msg));
            }
        }
    }

    /// Renders the next frame (or, paused, the current one again with
    /// what changed) and keeps its picture and record.
    fn frame(&mut self) {
        if self.playing || self.steps > 0 {
            self.steps = self.steps.saturating_sub(1);
        } else {
            self.seq.hold();
        }
        self.dirty = false;
        match self.seq.next_frame() {
            Ok((img, stats)) => {
                let mut jpeg = Vec::with_capacity(img.as_raw().len() / 8);
                let enc = image::codecs::jpeg::JpegEncoder::new_with_quality(&mut jpeg, 88);
                if let Err(e) = img.write_with_encoder(enc) {
                    self.error = Some(format!("cannot encode the frame: {e}"));
                    return;
                }
                self.last_picture = Some(Bytes::from(jpeg));
                self.last_stats = Some(stats);
                self.good = self.seq.scene().clone();
                self.error = None;
                if self.framed.is_none()
                    && let Some(c) = self.seq.renderer().camera()
                {
                    let o = Orbit::of(c);
                    self.framed = Some((*c, o));
                    self.orbit = Some(o);
                    self.centre = o.target;
                }
                let now = Instant::now();
                self.recent.push_back(now);
                while self
                    .recent
                    .front()
                    .is_some_and(|t| now - *t > Duration::from_secs(1))
                {
                    self.recent.pop_front();
                }
            }
            Err(e) => {
                tracing::warn!(error = %e, "a frame failed");
                self.error = Some(e.to_string());
                self.playing = false;
                self.steps = 0;
                // Back to the settings of the last frame that rendered.
                if self.seq.scene() != &self.good {
                    let good = self.good.clone();
                    if self.change(good, true).is_ok() {
                        self.dirty = true;
                    }
                }
            }
        }
    }

    /// Applies one control; an error names what cannot be done and
    /// changes nothing.
    fn apply(&mut self, control: Control) -> Result<(), ViewerError> {
        match control {
            Control::Play {} => self.playing = true,
            Control::Pause {} => self.playing = false,
            Control::Step {} => {
                self.playing = false;
                self.steps = (self.steps + 1).min(1000);
            }
            Control::Orbit { yaw_deg, pitch_deg } => {
                let o = self.orbit.as_mut().ok_or(ViewerError::NotYet)?;
                o.yaw_deg = (o.yaw_deg + yaw_deg).rem_euclid(360.0);
                o.pitch_deg = (o.pitch_deg + pitch_deg).clamp(-89.0, 89.0);
                self.look()?;
            }
            Control::Zoom { factor } => {
                let framed = self.framed.as_ref().ok_or(ViewerError::NotYet)?.1.distance;
                let o = self.orbit.as_mut().ok_or(ViewerError::NotYet)?;
                o.distance = (o.distance * factor).clamp(0.05 * framed, 20.0 * framed);
                self.look()?;
            }
            Control::ResetCamera {} => {
                let (_, o) = self.framed.ok_or(ViewerError::NotYet)?;
                self.orbit = Some(o);
                self.look()?;
            }
            Control::Light {
                index,
                azimuth_deg,
                elevation_deg,
                distance,
            } => {
                let mut scene = self.seq.scene().clone();
                let n = scene.lights.len();
                let l = scene.lights.get_mut(index).ok_or_else(|| {
                    ViewerError::BadMessage(format!(
                        "light {index}: the scene has {n} light(s), 0 to {}",
                        n.saturating_sub(1)
                    ))
                })?;
                if distance.is_some() && matches!(l, Light::Directional { .. }) {
                    return Err(ViewerError::BadMessage(format!(
                        "light {index} is directional: it has no distance"
                    )));
                }
                *l = placed(l, self.centre, azimuth_deg, elevation_deg, distance);
                self.change(scene, false)?;
            }
            Control::Effect { name, on } => {
                let mut scene = self.seq.scene().clone();
                let fx = &mut scene.effects;
                let switch = match name.as_str() {
                    "dynamics" => &mut fx.dynamics,
                    "self_collision" => &mut fx.self_collision,
                    "body_collision" => &mut fx.body_collision,
                    "self_shadow" => &mut fx.self_shadow,
                    "specular" => &mut fx.specular,
                    "head_shadow" => &mut fx.head_shadow,
                    "multiple_scattering" => &mut fx.multiple_scattering,
                    "head_bounce" => &mut fx.head_bounce,
                    _ => unreachable!("checked against EFFECTS: {EFFECTS:?}"),
                };
                if *switch == on {
                    return Ok(());
                }
                *switch = on;
                if name == "multiple_scattering"
                    && on
                    && !matches!(scene.shading.model, ShadingModel::Marschner { .. })
                {
                    return Err(ViewerError::BadMessage(
                        "multiple_scattering needs the scene's [shading] model = \"marschner\""
                            .into(),
                    ));
                }
                if name == "dynamics" {
                    self.restart(scene)?;
                } else {
                    self.change(scene, true)?;
                }
            }
            Control::Shadow {
                method,
                setting,
                cells,
            } => {
                let mut scene = self.seq.scene().clone();
                let now = scene.shadow.method;
                let mut m = if now.name() == method {
                    now
                } else {
                    scene
                        .shadow
                        .switch_to(&method)
                        .expect("checked against the method names")
                        .method
                };
                if let Some(c) = cells {
                    m.set_resolution(c);
                }
                if let Some(v) = setting {
                    m = with_main_setting(m, v)?;
                }
                m.validate()
                    .map_err(|e| ViewerError::BadMessage(e.to_string()))?;
                if m == now {
                    return Ok(());
                }
                scene.shadow.method = m;
                self.change(scene, true)?;
            }
        }
        Ok(())
    }

    /// Looks through the orbit's camera from the next frame on.
    fn look(&mut self) -> Result<(), ViewerError> {
        let (like, _) = self.framed.as_ref().ok_or(ViewerError::NotYet)?;
        let o = self.orbit.as_ref().ok_or(ViewerError::NotYet)?;
        let camera = o.camera(like)?;
        self.seq.set_camera(camera);
        self.dirty = true;
        Ok(())
    }

    /// Renders from the next frame on with `scene`'s settings; with
    /// workers, connected anew for them unless only the lights moved
    /// (`executor_too` false), which the workers learn with each frame.
    fn change(&mut self, scene: Scene, executor_too: bool) -> Result<(), ViewerError> {
        let before = self.seq.scene().clone();
        self.seq.set_scene(&scene)?;
        if executor_too && let Some(c) = &mut self.connect {
            let connected = c(&scene).and_then(|ex| self.seq.set_executor(ex));
            if let Err(e) = connected {
                // The settings go back with the executor they had.
                let _ = self.seq.set_scene(&before);
                return Err(e.into());
            }
        }
        self.dirty = true;
        Ok(())
    }

    /// A new sequence of `scene` from its first frame, the camera kept
    /// (the dynamics switched: the hair's state is made anew).
    fn restart(&mut self, scene: Scene) -> Result<(), ViewerError> {
        let mut seq = Sequence::new(&scene)?;
        if let Some(c) = &mut self.connect {
            seq.set_executor(c(&scene)?)?;
        }
        if let (Some((like, _)), Some(o)) = (&self.framed, &self.orbit) {
            seq.set_camera(o.camera(like)?);
        }
        self.seq = seq;
        self.dirty = true;
        Ok(())
    }

    /// The frame message: a little-endian u32 length, the header (JSON),
    /// then the picture (JPEG).
    fn message(&mut self) -> Option<Bytes> {
        let picture = self.last_picture.clone()?;
        self.published += 1;
        let header = serde_json::to_vec(&self.header()).expect("JSON of plain values");
        let mut msg = Vec::with_capacity(4 + header.len() + picture.len());
        msg.extend_from_slice(&(header.len() as u32).to_le_bytes());
        msg.extend_from_slice(&header);
        msg.extend_from_slice(&picture);
        Some(Bytes::from(msg))
    }

    /// What the page shows beside the picture: the frame's record and the
    /// session's settings, so that every page's controls agree.
    fn header(&self) -> serde_json::Value {
        let scene = self.seq.scene();
        let fx = scene.effects;
        let effects: serde_json::Map<String, serde_json::Value> = EFFECTS
            .iter()
            .zip([
                fx.dynamics,
                fx.self_collision,
                fx.body_collision,
                fx.self_shadow,
                fx.specular,
                fx.head_shadow,
                fx.multiple_scattering,
                fx.head_bounce,
            ])
            .map(|(n, on)| (n.to_string(), on.into()))
            .collect();
        let lights: Vec<serde_json::Value> = scene
            .lights
            .iter()
            .map(|l| {
                let (az, el, distance) = light_angles(l, self.centre);
                let kind = match l {
                    Light::Directional { .. } => "directional",
                    Light::Point { .. } => "point",
                    Light::Spot { .. } => "spot",
                };
                serde_json::json!({
                    "kind": kind, "azimuth_deg": az, "elevation_deg": el, "distance": distance,
                })
            })
            .collect();
        let method = scene.shadow.method;
        let fps = if self.playing && self.recent.len() > 1 {
            let span = *self.recent.back().expect("two") - *self.recent.front().expect("two");
            (self.recent.len() - 1) as f64 / span.as_secs_f64().max(1e-6)
        } else {
            0.0
        };
        serde_json::json!({
            "seq": self.published,
            "stats": self.last_stats,
            // The stages in the order a frame runs them (the record's
            // object has no order).
            "stage_names": Stage::ALL.map(Stage::name),
            "total_ms": self.last_stats.as_ref().map(FrameStats::total_ms),
            "playing": self.playing,
            "fps": fps,
            "workers": self.workers,
            "effects": effects,
            "effect_names": EFFECTS,
            "marschner": matches!(scene.shading.model, ShadingModel::Marschner { .. }),
            "shadow": {
                "method": method.name(),
                "setting": main_setting(&method).map(|(n, v)| serde_json::json!({"name": n, "value": v})),
                "cells": method.resolution(),
                "methods": MethodConfig::NAMES,
            },
            "lights": lights,
            "camera": self.orbit.map(|o| serde_json::json!({
                "yaw_deg": o.yaw_deg, "pitch_deg": o.pitch_deg, "distance": o.distance,
            })),
            "error": self.error,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_orbit_gives_back_the_camera_it_was_read_from() {
        let c = Camera::new(
            Vec3::new(3.0, 2.0, 5.0),
            Vec3::new(0.0, 1.0, 0.0),
            30.0,
            64,
            48,
        )
        .unwrap();
        let o = Orbit::of(&c);
        let back = o.camera(&c).unwrap();
        assert!(back.position.distance(c.position) < 1e-4, "{back:?}");
        // A quarter turn of yaw keeps the height and the distance.
        let mut turned = o;
        turned.yaw_deg += 90.0;
        let t = turned.camera(&c).unwrap();
        assert!((t.position.y - c.position.y).abs() < 1e-4);
        assert!((t.position.distance(c.look_at()) - o.distance).abs() < 1e-4);
        assert!(t.position.distance(c.position) > 1.0);
    }

    #[test]
    fn a_light_placed_at_its_own_angles_stays_where_it_is() {
        let centre = Vec3::new(0.0, 1.0, 0.0);
        for l in [
            Light::directional(Vec3::new(0.9, -0.35, -0.25)).unwrap(),
            Light::point(Vec3::new(4.0, 3.0, 2.0), 50.0).unwrap(),
            Light::spot(
                Vec3::new(-4.0, 3.0, 2.0),
                Vec3::new(1.0, -0.5, -0.5),
                30.0,
                5.0,
                50.0,
            )
            .unwrap(),
        ] {
            let (az, el, _) = light_angles(&l, centre);
            let again = placed(&l, centre, az, el, None);
            match (l, again) {
                (Light::Directional { direction: a }, Light::Directional { direction: b }) => {
                    assert!(a.distance(b) < 1e-5)
                }
                (Light::Point { position: a, .. }, Light::Point { position: b, .. }) => {
                    assert!(a.distance(b) < 1e-4)
                }
                (
                    Light::Spot { position: a, .. },
                    Light::Spot {
                        position: b,
                        direction,
                        ..
                    },
                ) => {
                    assert!(a.distance(b) < 1e-4);
                    // Aimed at the centre.
                    assert!(direction.dot((centre - b).normalize()) > 0.9999);
                }
                _ => panic!("the kind changed"),
            }
        }
        // Straight overhead, a directional light shines down.
        let l = placed(
            &Light::directional(Vec3::X).unwrap(),
            centre,
            0.0,
            90.0,
            None,
        );
        let Light::Directional { direction } = l else {
            panic!()
        };
        assert!(direction.distance(-Vec3::Y) < 1e-5);
    }
}
