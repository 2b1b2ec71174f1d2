//! One frame: the shadow stages, Kajiya-Kay shading at every drawn vertex,
//! and the draw (head, then hair), or the compositing of hair drawn
//! elsewhere over the head.

use std::sync::Arc;

use glam::{Affine3A, Vec3};
use raster::{Camera, Canvas, DualTable, HairLayer, ShadingModel};
use strands::{Bounds, Hair};

use crate::bounce::{HairIn, HeadLight};
use crate::part::{HeadPoint, Seen, draw_head, head_lambert};
use crate::{
    DrawJob, DrawReport, Drawn, EngineError, HairPart, PendingPicture, Scene, ShadowPipeline,
};

pub use crate::part::DEFAULT_HAIR_COLOR;

/// Renders frames of one scene, keeping its buffers between frames.
///
/// [`Self::render`] runs every stage of a frame; a frame pipeline that
/// skips stages calls [`Self::shadows_mut`], [`Self::filter`],
/// [`Self::shade`] and [`Self::draw`] itself, or, for hair drawn
/// elsewhere, [`Self::draw_job`] and [`Self::compose`].
#[derive(Debug)]
pub struct Renderer {
    scene: Scene,
    shadows: ShadowPipeline,
    part: HairPart,
    /// The groups the hair is drawn in (strand boundaries; empty: one).
    groups: Vec<u32>,
    /// Kept between frames: allocating and zeroing ~50 MB per frame at
    /// 1280x720 costs more than clearing it in parallel.
    canvas: Option<Canvas>,
    /// The camera, framed on the first frame and then fixed, so that an
    /// animation does not shake.
    view: Option<View>,
    /// The fiber the head's light is scattered by, when the head lights
    /// the hair ([`crate::bounce`]).
    head_optics: Option<raster::FiberOptics>,
}

#[derive(Debug, Clone, Copy)]
struct View {
    camera: Camera,
    /// Distance that sets the depth weighting of hair fragments.
    depth_ref: f32,
}

impl Renderer {
    /// A renderer for `scene`; fails on shadow settings out of range.
    pub fn new(scene: &Scene) -> Result<Renderer, EngineError> {
        let shadows = ShadowPipeline::new(scene)?;
        let mut scene = scene.clone();
        if !scene.effects.specular {
            scene.shading.specular = 0.0;
        }
        // Multiple scattering rides on the shadow stages' transmittance.
        if let ShadingModel::Marschner { multiple, .. } = &mut scene.shading.model {
            *multiple = scene.effects.multiple_scattering && scene.effects.self_shadow;
        }
        Ok(Renderer {
            head_optics: crate::part::head_optics(&scene),
            shadows,
            scene,
            part: HairPart::default(),
            groups: Vec::new(),
            canvas: None,
            view: None,
        })
    }

    /// Draws hair in these groups from now on (strand boundaries, see
    /// [`raster::Canvas::draw_hair`]; empty: one group).
    pub fn set_groups(&mut self, groups: Vec<u32>) {
        self.groups = groups;
    }

    /// Transmittance of each light at each drawn point in the last
    /// shadowed frame: `[light][point]`.
    pub fn transmittance(&self) -> &[Vec<f32>] {
        self.part.transmittance()
    }

    /// The shaded colour of each drawn point in the last [`Self::shade`]
    /// (linear RGB).
    pub fn colors(&self) -> &[Vec3] {
        self.part.colors()
    }

    /// The camera, once framed (on the first frame drawn).
    pub fn camera(&self) -> Option<&Camera> {
        self.view.as_ref().map(|v| &v.camera)
    }

    /// The shadow stages.
    pub fn shadows(&self) -> &ShadowPipeline {
        &self.shadows
    }

    /// The shadow stages 1 and 2 ([`ShadowPipeline::density`] and
    /// [`ShadowPipeline::transmittance`]).
    pub fn shadows_mut(&mut self) -> &mut ShadowPipeline {
        &mut self.shadows
    }

    /// Moves the head (drawn, and as an occluder) to `pose`, the head
    /// motion's transform.
    pub fn set_head_pose(&mut self, pose: Affine3A) {
        self.shadows.set_head_pose(pose);
    }

    /// Frames the camera on hair with `bounds` (and the head), unless it
    /// is already framed: the view is fixed from the first frame on.
    pub fn frame_on(&mut self, bounds: Bounds) -> Result<(), EngineError> {
        if self.view.is_none() {
            self.view = Some(self.framing(bounds)?);
        }
        Ok(())
    }

    /// [`Self::frame_on`] hair with `bounds` (and the head) as each of
    /// `moves` carries them (transforms from the frame drawn first; the
    /// identity among them): the view holds all of them. `points` are
    /// points of the hair (a sample of them will do) that the moves carry:
    /// moving them, rather than the corners of `bounds`, keeps the view
    /// as tight as the hair's own sweep (a box turned by 40 degrees grows
    /// by half; the hair inside it much less).
    pub fn frame_on_motion(
        &mut self,
        bounds: Bounds,
        points: &[Vec3],
        moves: &[Affine3A],
    ) -> Result<(), EngineError> {
        if self.view.is_some() {
            return Ok(());
        }
        let head = self.shadows.head().map(|h| h.bounds());
        let all = head.map_or(bounds, |h| bounds.union(h));
        if all.is_empty() {
            self.view = Some(self.framing_of(bounds, all, None)?);
            return Ok(());
        }
        let corners = |b: Bounds| -> Vec<Vec3> {
            (0..8)
                .map(|c| {
                    let pick =
                        |bit: usize, lo: f32, hi: f32| if c >> bit & 1 == 0 { lo } else { hi };
                    Vec3::new(
                        pick(0, b.min.x, b.max.x),
                        pick(1, b.min.y, b.max.y),
                        pick(2, b.min.z, b.max.z),
                    )
                })
                .collect()
        };
        let mut kept = if points.is_empty() {
            corners(bounds)
        } else {
            points.to_vec()
        };
        kept.extend(
            head.filter(|h| !h.is_empty())
                .map(corners)
                .into_iter()
                .flatten(),
        );
        // Every kept point as each move carries it.
        let carried = |visit: &mut dyn FnMut(Vec3)| {
            kept.iter().for_each(|&p| visit(p));
            for m in moves {
                kept.iter().for_each(|&p| visit(m.transform_point3(p)));
            }
        };
        let mut moved = all;
        carried(&mut |p| moved = moved.union(Bounds { min: p, max: p }));
        self.view = Some(self.framing_of(bounds, moved, Some(&carried))?);
        Ok(())
    }

    /// The fixed view, framed on `hair` the first time.
    fn view(&mut self, hair: &Hair) -> Result<View, EngineError> {
        self.frame_on(hair.bounds())?;
        Ok(self.view.expect("framed above"))
    }

    /// The camera of the scene, framing hair with `hair_bounds` (and the
    /// head) where the scene leaves position or target open: from the front
    /// (+z), slightly above (or from three quarters, see
    /// [`crate::view_direction`]), far enough that the whole hair fits the
    /// vertical field of view.
    fn framing(&self, hair_bounds: Bounds) -> Result<View, EngineError> {
        let mut b = hair_bounds;
        if let Some(h) = self.shadows.head() {
            b = b.union(h.bounds());
        }
        self.framing_of(hair_bounds, b, None)
    }

    /// [`Self::framing`] of everything within `b` (the hair with
    /// `hair_bounds`, the head, wherever they go). With `points` (a
    /// visitor of the points inside `b` to keep in view), the camera is
    /// as near as keeps each of them inside the picture with a margin of
    /// 5 % of its half-height: a point `q` from the target, with the view
    /// direction `d` (from the target to the camera), up `u`, right `r`
    /// and the half field of view `tan_v` (vertical) and `tan_h`
    /// (horizontal), is in the picture from distance
    ///
    /// ```text
    /// dist >= max(|q.u| / tan_v, |q.r| / tan_h) + q.d
    /// ```
    ///
    /// Without, the camera stands where the box's largest side fills the
    /// vertical field of view from its near face.
    fn framing_of(
        &self,
        hair_bounds: Bounds,
        b: Bounds,
        points: Option<&VisitPoints<'_>>,
    ) -> Result<View, EngineError> {
        let s = &self.scene;
        let (center, size) = if b.is_empty() {
            (Vec3::ZERO, 1.0)
        } else {
            (b.center(), b.size().max_element().max(1e-3))
        };
        let look_at = s.camera.look_at.unwrap_or(center);
        let tan_v = (0.5 * s.camera.fov_deg.to_radians()).tan();
        let position = s.camera.position.unwrap_or_else(|| {
            let d = crate::view_direction(hair_bounds, s.camera.view);
            let dist = match points {
                Some(visit) => {
                    let tan_h = tan_v * s.render.width as f32 / s.render.height as f32;
                    let up = s.camera.up.unwrap_or(Vec3::Y);
                    let r = (-d).cross(up).try_normalize().unwrap_or(Vec3::X);
                    let u = r.cross(-d);
                    const MARGIN: f32 = 1.05;
                    let mut dist = 1e-3f32;
                    visit(&mut |p| {
                        let q = p - look_at;
                        let side = (q.dot(u).abs() / tan_v).max(q.dot(r).abs() / tan_h);
                        dist = dist.max(MARGIN * side + q.dot(d));
                    });
                    dist
                }
                None => 0.5 * size / tan_v + 0.5 * size,
            };
            look_at + d * dist
        });
        let mut camera = Camera::new(
            position,
            look_at,
            s.camera.fov_deg,
            s.render.width,
            s.render.height,
        )?;
        if let Some(up) = s.camera.up {
            camera = camera.with_up(up)?;
        }
        let depth_ref = position.distance(s.camera.look_at.unwrap_or(hair_bounds.center()));
        Ok(View {
            camera,
            depth_ref: if depth_ref.is_finite() {
                depth_ref.max(1e-3)
            } else {
                1.0
            },
        })
    }

    /// Shadow stage 3: the transmittance of every light at every drawn
    /// point, kept for [`Self::shade`].
    pub fn filter(&mut self, hair: &Hair) {
        self.shadows
            .set_eye(self.view.as_ref().map(|v| v.camera.position));
        let shadows = &self.shadows;
        self.part
            .filter(hair, shadows.light_count(), |l, pts, out| {
                shadows.filter_light(l, pts, out)
            });
        if let Some(head) = self.head_light(true) {
            self.part.filter_head(hair, head);
        }
    }

    /// The fiber that scatters light on to the head, when the head lights
    /// the hair (with `shadows`).
    fn forward_table(&mut self, shadows: bool) -> Option<Arc<DualTable>> {
        let optics = self.head_optics.filter(|_| shadows)?;
        Some(self.part.dual_table(&optics))
    }

    /// The head's light on the hair this frame, when the head lights the
    /// hair (after the shadow stages); not `lit`, its map alone
    /// ([`crate::part::head_map`]).
    fn head_light(&mut self, lit: bool) -> Option<HeadLight> {
        let forward = self.forward_table(true)?;
        let head = self.shadows.head()?;
        if self.shadows.light_count() == 0 {
            return None;
        }
        let (pipeline, lights) = (&self.shadows, self.lights());
        let head_shadow = self.scene.effects.head_shadow;
        let lookup = |pts: &[Vec3], out: &mut [f32]| pipeline.filter_light(0, pts, out);
        let hair = match pipeline.swept(0) {
            Some((map, trilinear)) => HairIn::Swept(map, trilinear),
            None => HairIn::Lookup(&lookup),
        };
        if !lit {
            return Some(crate::part::head_map(
                head,
                &lights,
                pipeline.frame(0),
                hair,
            ));
        }
        Some(crate::part::head_light(
            head,
            &self.scene.shading,
            &lights,
            &forward,
            pipeline.frame(0),
            |l, x, n| {
                if head_shadow {
                    pipeline.transmittance_off_surface(l, x, n)
                } else {
                    1.0
                }
            },
            hair,
        ))
    }

    /// Renders `hair` with self-shadowing (`shadows`) or without (every
    /// transmittance 1, no head shadow): all the stages of a still, untimed.
    /// Frames that are timed, or skip what did not change, go through
    /// [`crate::Sequence`].
    pub fn render(&mut self, hair: &Hair, shadows: bool) -> Result<image::RgbImage, EngineError> {
        if shadows {
            self.shadows.density(hair)?;
            self.shadows.transmittance()?;
            self.filter(hair);
        }
        self.shade(hair, shadows)?;
        self.draw(hair, shadows)
    }

    /// The lights, in order.
    fn lights(&self) -> Vec<shadow::Light> {
        self.shadows.lights().copied().collect()
    }

    /// Kajiya-Kay shading at every drawn vertex with the strand's colour,
    /// lit by the transmittance of the last [`Self::filter`] (`shadows`) or
    /// by full light.
    pub fn shade(&mut self, hair: &Hair, shadows: bool) -> Result<(), EngineError> {
        let view = self.view(hair)?;
        let (lights, look) = (self.lights(), self.look(&view));
        let seen = Seen {
            camera: &view.camera,
            look: &look,
            first_strand: 0,
        };
        self.part
            .shade(hair, seen, &self.scene.shading, &lights, shadows);
        Ok(())
    }

    /// The inputs for filtering, shading and drawing hair of version
    /// `version` elsewhere, on the view framed by [`Self::frame_on`].
    pub fn draw_job(&self, version: u64, shadows: bool) -> Result<DrawJob, EngineError> {
        let view = self
            .view
            .ok_or_else(|| EngineError::executor("the camera is framed before drawing"))?;
        let s = &self.scene;
        Ok(DrawJob {
            version,
            camera: view.camera,
            look: self.look(&view),
            shading: s.shading,
            lights: self.lights(),
            shadows,
            trilinear: s.shadow.method.trilinear(),
            head: self.shadows.head_pose(),
            nearest: s.render.nearest,
        })
    }

    fn look(&self, view: &View) -> raster::HairLook {
        raster::HairLook {
            fiber_width: self.scene.fiber.width(),
            opacity: self.scene.render.hair_alpha,
            depth_ref: view.depth_ref,
            simplify: self.scene.render.simplify,
        }
    }

    /// The canvas, cleared, with the head drawn and shaded: Lambert under
    /// the hair's shadow when `shadows` and the scene's head shadow are on;
    /// its bands sized for `segments` segments of hair to be drawn on it.
    fn canvas_with_head(
        &mut self,
        shadows: bool,
        segments: usize,
    ) -> Result<(View, &mut Canvas), EngineError> {
        let view = self
            .view
            .ok_or_else(|| EngineError::executor("the camera is framed before drawing"))?;
        let lights = self.lights();
        let s = &self.scene;
        if self.canvas.is_none() {
            self.canvas = Some(Canvas::new(s.render.width, s.render.height)?);
        }
        let forward = self.forward_table(shadows);
        // The sky over the head from the head's map: this frame's filter
        // made it, or (the hair filtered elsewhere) it is made here.
        let made = (shadows && !self.part.has_head_light() && self.scene.shading.ambient > 0.0)
            .then(|| self.head_light(false))
            .flatten();
        let s = &self.scene;
        let canvas = self.canvas.as_mut().expect("made above");
        canvas.clear();
        canvas.set_nearest(s.render.nearest as usize);
        canvas.set_band_rows(Canvas::band_rows_for(
            s.render.width,
            s.render.height,
            segments,
        ));
        if let Some(head) = self.shadows.head() {
            let head_shadow = shadows && s.effects.head_shadow;
            let pipeline = &self.shadows;
            let shading = &s.shading;
            let color = head.settings().color;
            let part = &self.part;
            let shade = |p: Vec3, n: Vec3| {
                let sky = made
                    .as_ref()
                    .map_or_else(|| part.sky_over_head(p), |h| h.sky_over(p));
                let at = HeadPoint {
                    p,
                    n,
                    sky: sky.filter(|_| shadows),
                };
                head_lambert(color, shading, &lights, at, forward.as_deref(), |l| {
                    // Off the surface: past the head's own deposit.
                    if head_shadow {
                        pipeline.transmittance_off_surface(l, p, n)
                    } else {
                        1.0
                    }
                })
            };
            draw_head(canvas, &view.camera, head, shade);
        }
        Ok((view, canvas))
    }

    /// Draws the head, then `hair` over it with the colours of the last
    /// [`Self::shade`]; the head receives the hair's shadow when `shadows`
    /// and the scene's head shadow are on.
    pub fn draw(&mut self, hair: &Hair, shadows: bool) -> Result<image::RgbImage, EngineError> {
        let background = self.scene.render.background;
        let canvas = self.bin(hair, shadows)?;
        Ok(canvas.resolve(background))
    }

    /// [`Self::draw`] up to the rasterization, which the returned
    /// [`Composite`] does wherever it is sent (while this renderer runs the
    /// next frame's stages, say): `hair`'s strands are projected and binned
    /// with the colours of the last [`Self::shade`], so that neither the
    /// hair nor this renderer is read again. Hand its canvas back with
    /// [`Self::restore_canvas`] before the next draw, or a new one is made.
    pub fn draw_later(&mut self, hair: &Hair, shadows: bool) -> Result<Composite, EngineError> {
        let background = self.scene.render.background;
        self.bin(hair, shadows)?;
        let canvas = self.canvas.take().expect("made by bin");
        Ok(Composite {
            background,
            state: Composing::Layers {
                canvas,
                layers: Vec::new(),
            },
        })
    }

    /// The canvas with the head drawn and `hair` projected and binned.
    fn bin(&mut self, hair: &Hair, shadows: bool) -> Result<&Canvas, EngineError> {
        self.view(hair)?;
        let (view, _) = self.canvas_with_head(shadows, hair.segment_count())?;
        let look = self.look(&view);
        let canvas = self.canvas.as_mut().expect("made above");
        let seen = Seen {
            camera: &view.camera,
            look: &look,
            first_strand: 0,
        };
        self.part.draw(hair, seen, &self.groups, canvas);
        Ok(canvas)
    }

    /// The head drawn here while `hair` draws the hair elsewhere (see
    /// [`Self::draw_job`]), then the partial pictures it returns over the
    /// head: the same bytes as [`Self::draw`] of all that hair. The two run
    /// at once, so the head costs the frame nothing while remote workers
    /// draw.
    pub fn compose(
        &mut self,
        shadows: bool,
        hair: impl FnOnce() -> Result<DrawReport, EngineError> + Send,
    ) -> Result<(image::RgbImage, DrawReport), EngineError> {
        let (mut composite, drawn) = self.compose_later(shadows, false, hair)?;
        composite.wait()?;
        let (canvas, img) = composite.resolve().map_err(|(_, e)| e)?;
        self.restore_canvas(canvas);
        Ok((img, drawn))
    }

    /// [`Self::compose`] up to the compositing, which the returned
    /// [`Composite`] does wherever it is sent (while this renderer runs the
    /// next frame's shadows, say); hand its canvas back with
    /// [`Self::restore_canvas`] before the next draw, or a new one is made.
    /// The report's layers are in the composite. With `head_elsewhere`
    /// (the executor [composites](crate::Drawing::composites)) the head is
    /// drawn here only when the hair's call returns layers rather than the
    /// finished picture.
    pub fn compose_later(
        &mut self,
        shadows: bool,
        head_elsewhere: bool,
        hair: impl FnOnce() -> Result<DrawReport, EngineError> + Send,
    ) -> Result<(Composite, DrawReport), EngineError> {
        let background = self.scene.render.background;
        let drawn = if head_elsewhere {
            let drawn = hair()?;
            if !matches!(drawn.drawn, Drawn::Layers(_)) {
                let (state, report) = Composing::of(None, drawn);
                return Ok((Composite { background, state }, report));
            }
            self.canvas_with_head(shadows, 0)?;
            drawn
        } else {
            // The hair's call waits on the network in a thread of its own
            // (not one of rayon's, which the head and any in-process
            // drawing need).
            let (drawn, head) = std::thread::scope(|s| {
                let drawn = s.spawn(hair);
                let head = self.canvas_with_head(shadows, 0).map(|_| ());
                let drawn = drawn
                    .join()
                    .unwrap_or_else(|p| std::panic::resume_unwind(p));
                (drawn, head)
            });
            let (drawn, ()) = (drawn?, head?);
            drawn
        };
        let canvas = self.canvas.take().expect("drawn above");
        if let Drawn::Layers(layers) = &drawn.drawn
            && let Some(l) = layers
                .iter()
                .find(|l| l.width() != canvas.width() || l.height() != canvas.height())
        {
            let msg = format!(
                "a partial picture of {}x{} for a {}x{} frame",
                l.width(),
                l.height(),
                canvas.width(),
                canvas.height()
            );
            self.canvas = Some(canvas);
            return Err(EngineError::executor(msg));
        }
        let (state, drawn) = Composing::of(Some(canvas), drawn);
        let composite = Composite { background, state };
        Ok((composite, drawn))
    }

    /// Looks through `camera` from now on. Fragments keep their depth
    /// weighting relative to the distance to the camera's target, so an
    /// orbit at the framed distance weights them as the framed view did
    /// (unframed, the weighting is set by that distance).
    pub fn set_camera(&mut self, camera: Camera) {
        let dist = camera.position.distance(camera.look_at());
        let depth_ref = match &self.view {
            Some(v) => {
                let ratio = dist / v.camera.position.distance(v.camera.look_at());
                if ratio.is_finite() && ratio > 0.0 {
                    v.depth_ref * ratio
                } else {
                    v.depth_ref
                }
            }
            None if dist.is_finite() => dist,
            None => 1.0,
        };
        self.view = Some(View {
            camera,
            depth_ref: depth_ref.max(1e-3),
        });
    }

    /// A renderer of `scene` (the same hair, other lights, effects,
    /// shading or shadow settings) that keeps this one's camera, groups,
    /// canvas and head pose.
    pub fn remade(&mut self, scene: &Scene) -> Result<Renderer, EngineError> {
        let mut r = Renderer::new(scene)?;
        r.view = self.view;
        r.groups = self.groups.clone();
        r.canvas = self.canvas.take();
        r.set_head_pose(self.shadows.head_pose());
        Ok(r)
    }

    /// Gives back the canvas a [`Composite`] resolved on, to be reused.
    pub fn restore_canvas(&mut self, canvas: Option<Canvas>) {
        if canvas.is_some() {
            self.canvas = canvas;
        }
    }

    /// The last picture drawn in this process, before it was encoded:
    /// linear RGB, not clamped, and alpha, the coverage of the head and
    /// the hair; row after row ([`Canvas::resolve_linear`]). `None` before
    /// any draw. Of a picture whose hair was drawn elsewhere (by cluster
    /// workers) it holds the head alone.
    pub fn linear_picture(&self) -> Option<Vec<glam::Vec4>> {
        self.linear_picture_over(self.scene.render.background)
    }

    /// [`Self::linear_picture`] over `background` instead of the scene's
    /// (black leaves it out: the colours are then premultiplied by alpha).
    pub fn linear_picture_over(&self, background: glam::Vec3) -> Option<Vec<glam::Vec4>> {
        let canvas = self.canvas.as_ref()?;
        Some(canvas.resolve_linear(background))
    }

    /// [`Self::linear_picture_over`], and the view depth of the nearest
    /// surface at each pixel ([`Canvas::resolve_linear_and_depth`]).
    pub fn linear_picture_and_depth(
        &self,
        background: glam::Vec3,
    ) -> Option<(Vec<glam::Vec4>, Vec<f32>)> {
        Some(self.canvas.as_ref()?.resolve_linear_and_depth(background))
    }
}

/// Calls its argument with every point of a set (the points a camera
/// keeps in view).
type VisitPoints<'a> = dyn Fn(&mut dyn FnMut(Vec3)) + 'a;

/// A frame's head and the partial pictures of its hair, not yet
/// composited (or its finished picture, or the promise of it): see
/// [`Renderer::compose_later`].
#[derive(Debug)]
pub struct Composite {
    background: Vec3,
    state: Composing,
}

/// Where a [`Composite`] stands. The head drawn here (`canvas`) is kept
/// with a picture finished elsewhere, when it was drawn, for the frame
/// drawn again should that picture fail.
#[derive(Debug)]
enum Composing {
    /// Partial pictures to composite on the head drawn here.
    Layers {
        canvas: Canvas,
        layers: Vec<HairLayer>,
    },
    /// The picture, finished elsewhere.
    Finished {
        picture: image::RgbImage,
        canvas: Option<Canvas>,
    },
    /// The picture, still on its way.
    Pending {
        pending: PendingPicture,
        canvas: Option<Canvas>,
    },
    /// Its picture failed, and no head was drawn here to draw the frame
    /// again on.
    Failed,
}

impl Composing {
    /// What `report` drew, on the head in `canvas` (if drawn here); the
    /// report's times.
    fn of(canvas: Option<Canvas>, mut report: DrawReport) -> (Composing, DrawReport) {
        let state = match (std::mem::take(&mut report.drawn), canvas) {
            (Drawn::Layers(layers), Some(canvas)) => Composing::Layers { canvas, layers },
            (Drawn::Layers(_), None) => Composing::Failed,
            (Drawn::Picture(picture), canvas) => Composing::Finished { picture, canvas },
            (Drawn::Pending(pending), canvas) => Composing::Pending { pending, canvas },
        };
        (state, report)
    }
}

impl Composite {
    /// Waits for the picture finished elsewhere, if one is on its way: its
    /// error when it fails (the composite then holds the head drawn here,
    /// when it was, for [`Self::add_layers`] of the frame drawn again).
    pub fn wait(&mut self) -> Result<(), EngineError> {
        match std::mem::replace(&mut self.state, Composing::Failed) {
            Composing::Pending { pending, canvas } => match pending.wait() {
                Ok(picture) => {
                    self.state = Composing::Finished { picture, canvas };
                    Ok(())
                }
                Err(e) => {
                    if let Some(canvas) = canvas {
                        self.state = Composing::Layers {
                            canvas,
                            layers: Vec::new(),
                        };
                    }
                    Err(e)
                }
            },
            other => {
                self.state = other;
                Ok(())
            }
        }
    }

    /// Whether the head was drawn here, to composite partial pictures on.
    pub fn has_head(&self) -> bool {
        match &self.state {
            Composing::Layers { .. } => true,
            Composing::Finished { canvas, .. } | Composing::Pending { canvas, .. } => {
                canvas.is_some()
            }
            Composing::Failed => false,
        }
    }

    /// Adds partial pictures to composite (a frame drawn again), in place
    /// of a finished picture; false (and nothing changes) when a layer is
    /// not of this picture's size or no head was drawn here.
    pub fn add_layers(&mut self, more: Vec<HairLayer>) -> bool {
        let fits = |c: &Canvas| {
            more.iter()
                .all(|l| l.width() == c.width() && l.height() == c.height())
        };
        match std::mem::replace(&mut self.state, Composing::Failed) {
            Composing::Layers { canvas, mut layers } if fits(&canvas) => {
                layers.extend(more);
                self.state = Composing::Layers { canvas, layers };
                true
            }
            Composing::Finished {
                canvas: Some(canvas),
                ..
            } if fits(&canvas) => {
                self.state = Composing::Layers {
                    canvas,
                    layers: more,
                };
                true
            }
            other => {
                self.state = other;
                false
            }
        }
    }

    /// The finished picture, and the canvas for the renderer to reuse
    /// (after [`Self::wait`]); when there is none to give, the error and
    /// the composite back.
    #[allow(clippy::result_large_err)]
    pub fn resolve(self) -> Result<(Option<Canvas>, image::RgbImage), (Composite, EngineError)> {
        let background = self.background;
        match self.state {
            Composing::Finished { picture, canvas } => Ok((canvas, picture)),
            Composing::Layers { canvas, layers } => {
                let img = canvas.resolve_layers(background, &layers);
                Ok((Some(canvas), img))
            }
            state @ Composing::Pending { .. } => Err((
                Composite { background, state },
                EngineError::executor("a picture on its way was resolved before it came"),
            )),
            Composing::Failed => Err((
                Composite {
                    background,
                    state: Composing::Failed,
                },
                EngineError::executor(
                    "the picture finished elsewhere failed, and no head was drawn here to draw it again on",
                ),
            )),
        }
    }
}
