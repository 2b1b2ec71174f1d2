//! One frame: the shadow stages, Kajiya-Kay shading at every drawn vertex,
//! and the draw (head, then hair).

use std::time::Instant;

use glam::Vec3;
use raster::{Camera, Canvas, Sphere, kajiya_kay};
use rayon::prelude::*;
use strands::{Bounds, Hair};

use crate::{EngineError, Scene, ShadowPipeline};

/// Hair colour when neither the style nor the file gives one (linear RGB).
pub const DEFAULT_HAIR_COLOR: Vec3 = Vec3::new(0.30, 0.17, 0.08);

/// Milliseconds of each stage of one frame; stages that did not run are 0.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct FrameTimes {
    pub density_ms: f64,
    pub transmittance_ms: f64,
    pub filter_ms: f64,
    pub shade_ms: f64,
    pub draw_ms: f64,
}

impl FrameTimes {
    pub fn total_ms(&self) -> f64 {
        self.density_ms + self.transmittance_ms + self.filter_ms + self.shade_ms + self.draw_ms
    }
}

/// Renders frames of one scene, keeping its buffers between frames.
///
/// [`Self::render`] runs every stage of a frame; a frame pipeline that
/// skips stages calls [`Self::shadows_mut`], [`Self::filter`],
/// [`Self::shade`] and [`Self::draw`] itself.
#[derive(Debug)]
pub struct Renderer {
    scene: Scene,
    shadows: ShadowPipeline,
    trans: Vec<Vec<f32>>,
    colors: Vec<Vec3>,
    /// Kept between frames: allocating and zeroing ~50 MB per frame at
    /// 1280x720 costs more than clearing it in parallel.
    canvas: Option<Canvas>,
    /// The camera, framed on the first frame and then fixed, so that an
    /// animation does not shake.
    view: Option<View>,
}

#[derive(Debug, Clone, Copy)]
struct View {
    camera: Camera,
    /// Distance that sets the depth weighting of hair fragments.
    depth_ref: f32,
}

fn ms(since: Instant) -> f64 {
    since.elapsed().as_secs_f64() * 1e3
}

impl Renderer {
    /// A renderer for `scene`; fails on shadow settings out of range.
    pub fn new(scene: &Scene) -> Result<Renderer, EngineError> {
        let shadows = ShadowPipeline::new(scene)?;
        let mut scene = scene.clone();
        if !scene.effects.specular {
            scene.shading.specular = 0.0;
        }
        Ok(Renderer {
            trans: vec![Vec::new(); shadows.light_count()],
            shadows,
            scene,
            colors: Vec::new(),
            canvas: None,
            view: None,
        })
    }

    /// Transmittance of each light at each drawn point in the last
    /// shadowed frame: `[light][point]`.
    pub fn transmittance(&self) -> &[Vec<f32>] {
        &self.trans
    }

    /// The shaded colour of each drawn point in the last [`Self::shade`]
    /// (linear RGB).
    pub fn colors(&self) -> &[Vec3] {
        &self.colors
    }

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
    pub fn set_head_pose(&mut self, pose: glam::Affine3A) {
        self.shadows.set_head_pose(pose);
    }

    /// The fixed view, framed on `hair` the first time.
    fn view(&mut self, hair: &Hair) -> Result<View, EngineError> {
        match self.view {
            Some(v) => Ok(v),
            None => {
                let v = self.framing(hair.bounds())?;
                Ok(*self.view.insert(v))
            }
        }
    }

    /// The camera of the scene, framing hair with `hair_bounds` (and the
    /// head) where the scene leaves position or target open: from the front
    /// (+z), slightly above, far enough that the whole hair fits the
    /// vertical field of view.
    fn framing(&self, hair_bounds: Bounds) -> Result<View, EngineError> {
        let s = &self.scene;
        let mut b = hair_bounds;
        if let Some(h) = self.shadows.head() {
            b = b.union(h.bounds());
        }
        let (center, size) = if b.is_empty() {
            (Vec3::ZERO, 1.0)
        } else {
            (b.center(), b.size().max_element().max(1e-3))
        };
        let look_at = s.camera.look_at.unwrap_or(center);
        let position = s.camera.position.unwrap_or_else(|| {
            let dist = 0.5 * size / (0.5 * s.camera.fov_deg.to_radians()).tan() + 0.5 * size;
            look_at + Vec3::new(0.0, 0.15, 1.0).normalize() * dist
        });
        let camera = Camera::new(
            position,
            look_at,
            s.camera.fov_deg,
            s.render.width,
            s.render.height,
        )?;
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
        self.shadows.filter(hair.points(), &mut self.trans);
    }

    /// Renders `hair` with self-shadowing (`shadows`) or without (every
    /// transmittance 1, no head shadow): all the stages, the picture and
    /// their times.
    pub fn render(
        &mut self,
        hair: &Hair,
        shadows: bool,
    ) -> Result<(image::RgbImage, FrameTimes), EngineError> {
        let mut times = FrameTimes::default();
        if shadows {
            let t = Instant::now();
            self.shadows.density(hair)?;
            times.density_ms = ms(t);
            let t = Instant::now();
            self.shadows.transmittance()?;
            times.transmittance_ms = ms(t);
            let t = Instant::now();
            self.filter(hair);
            times.filter_ms = ms(t);
        }
        let t = Instant::now();
        self.shade(hair, shadows)?;
        times.shade_ms = ms(t);
        let t = Instant::now();
        let img = self.draw(hair, shadows)?;
        times.draw_ms = ms(t);
        Ok((img, times))
    }

    /// Kajiya-Kay shading at every drawn vertex with the strand's colour,
    /// lit by the transmittance of the last [`Self::filter`] (`shadows`) or
    /// by full light.
    pub fn shade(&mut self, hair: &Hair, shadows: bool) -> Result<(), EngineError> {
        let eye = self.view(hair)?.camera.position;
        let points = hair.points();
        let s = &self.scene;
        let to_lights: Vec<Vec3> = self.shadows.lights().map(|l| -l.direction()).collect();
        if shadows {
            assert!(
                self.trans.iter().all(|t| t.len() == points.len()),
                "filter runs before shading with shadows"
            );
        }
        self.colors.resize(points.len(), Vec3::ZERO);
        let offsets = hair.offsets();
        let strand_colors = hair.colors();
        let trans = &self.trans;
        // Strands in parallel; each writes its own vertices.
        let mut chunks: Vec<&mut [Vec3]> = Vec::with_capacity(hair.strand_count());
        let mut rest: &mut [Vec3] = &mut self.colors;
        for w in offsets.windows(2) {
            let (a, b) = rest.split_at_mut((w[1] - w[0]) as usize);
            chunks.push(a);
            rest = b;
        }
        chunks
            .into_par_iter()
            .enumerate()
            .with_min_len(64)
            .for_each(|(si, out)| {
                let base = offsets[si] as usize;
                let pts = &points[base..base + out.len()];
                let color = strand_colors.map_or(DEFAULT_HAIR_COLOR, |c| c[si]);
                for (v, o) in out.iter_mut().enumerate() {
                    // Tangent by central differences (one-sided at the ends).
                    let (a, b) = (pts[v.saturating_sub(1)], pts[(v + 1).min(pts.len() - 1)]);
                    let tangent = (b - a).normalize_or(Vec3::Y);
                    let to_eye = (eye - pts[v]).normalize_or(Vec3::Z);
                    let mut c = Vec3::ZERO;
                    for (l, &to_light) in to_lights.iter().enumerate() {
                        let tr = if shadows { trans[l][base + v] } else { 1.0 };
                        let sh = if l == 0 {
                            s.shading
                        } else {
                            raster::Shading {
                                ambient: 0.0,
                                ..s.shading
                            }
                        };
                        c += kajiya_kay(&sh, color, tangent, to_light, to_eye, tr);
                    }
                    *o = c;
                }
            });
        Ok(())
    }

    /// Draws the head, then `hair` over it with the colours of the last
    /// [`Self::shade`]; the head receives the hair's shadow when `shadows`
    /// and the scene's head shadow are on.
    pub fn draw(&mut self, hair: &Hair, shadows: bool) -> Result<image::RgbImage, EngineError> {
        let view = self.view(hair)?;
        let camera = view.camera;
        let s = &self.scene;
        assert_eq!(
            self.colors.len(),
            hair.point_count(),
            "shade runs before draw"
        );
        let to_lights: Vec<Vec3> = self.shadows.lights().map(|l| -l.direction()).collect();
        let canvas = match &mut self.canvas {
            Some(c) => {
                c.clear();
                c
            }
            None => self
                .canvas
                .insert(Canvas::new(s.render.width, s.render.height)?),
        };
        if let Some(head) = self.shadows.head() {
            let head_shadow = shadows && s.effects.head_shadow;
            let pipeline = &self.shadows;
            let ambient = s.shading.ambient;
            let color = head.settings().color;
            // Lambert under the hair's shadow: Phi = k_a C + T (1 - k_a) C max(n.l, 0).
            let shade = |p: Vec3, n: Vec3| {
                let mut c = ambient * color;
                for (l, &to_light) in to_lights.iter().enumerate() {
                    let lambert = n.dot(to_light).max(0.0);
                    if lambert > 0.0 {
                        // 1.5 cells towards the light: past the head's own deposit.
                        let tr = if head_shadow {
                            pipeline.transmittance_at(l, p, 1.5)
                        } else {
                            1.0
                        };
                        c += tr * lambert * (1.0 - ambient) * color;
                    }
                }
                c
            };
            match head.mesh() {
                Some(m) => {
                    canvas.draw_mesh(&camera, m.positions(), m.normals(), m.triangles(), shade)
                }
                None => canvas.draw_sphere(
                    &camera,
                    &Sphere {
                        center: head.center(),
                        radius: head.settings().radius,
                    },
                    shade,
                ),
            }
        }
        let look = raster::HairLook {
            fiber_width: s.fiber.width(),
            opacity: s.render.hair_alpha,
            depth_ref: view.depth_ref,
        };
        canvas.draw_hair(
            &camera,
            hair.points(),
            hair.offsets(),
            &self.colors,
            &look,
            &[],
        );
        Ok(canvas.resolve(s.render.background))
    }
}
