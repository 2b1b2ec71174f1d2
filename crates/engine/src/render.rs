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
#[derive(Debug)]
pub struct Renderer {
    scene: Scene,
    shadows: ShadowPipeline,
    trans: Vec<Vec<f32>>,
    colors: Vec<Vec3>,
    /// Kept between frames: allocating and zeroing ~50 MB per frame at
    /// 1280x720 costs more than clearing it in parallel.
    canvas: Option<Canvas>,
}

fn ms(since: Instant) -> f64 {
    since.elapsed().as_secs_f64() * 1e3
}

impl Renderer {
    /// A renderer for `scene`; fails on shadow settings out of range.
    pub fn new(scene: &Scene) -> Result<Renderer, EngineError> {
        let shadows = ShadowPipeline::new(scene)?;
        Ok(Renderer {
            trans: vec![Vec::new(); shadows.light_count()],
            shadows,
            scene: scene.clone(),
            colors: Vec::new(),
            canvas: None,
        })
    }

    /// Transmittance of each light at each drawn point in the last
    /// shadowed frame: `[light][point]`.
    pub fn transmittance(&self) -> &[Vec<f32>] {
        &self.trans
    }

    /// The camera of the scene, framing `hair` (and the head) where the
    /// scene leaves position or target open: from the front (+z), slightly
    /// above, far enough that the whole hair fits the vertical field of view.
    pub fn camera(&self, hair: &Hair) -> Result<Camera, EngineError> {
        self.framing(hair.bounds())
    }

    /// [`Self::camera`] from the hair's bounds.
    fn framing(&self, hair_bounds: Bounds) -> Result<Camera, EngineError> {
        let s = &self.scene;
        let mut b = hair_bounds;
        if let Some(h) = &s.head {
            b.include(h.center - Vec3::splat(h.radius));
            b.include(h.center + Vec3::splat(h.radius));
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
        Ok(Camera::new(
            position,
            look_at,
            s.camera.fov_deg,
            s.render.width,
            s.render.height,
        )?)
    }

    /// Renders `hair` with self-shadowing (`shadows`) or without (every
    /// transmittance 1, no head shadow): the picture and its stage times.
    pub fn render(
        &mut self,
        hair: &Hair,
        shadows: bool,
    ) -> Result<(image::RgbImage, FrameTimes), EngineError> {
        let mut times = FrameTimes::default();
        // One pass over the points serves the framing and the depth weighting.
        let hair_bounds = hair.bounds();
        let camera = self.framing(hair_bounds)?;
        let points = hair.points();

        // Shadow stages.
        if shadows {
            let t = Instant::now();
            self.shadows.density(hair)?;
            times.density_ms = ms(t);
            let t = Instant::now();
            self.shadows.transmittance();
            times.transmittance_ms = ms(t);
            let t = Instant::now();
            self.shadows.filter(points, &mut self.trans);
            times.filter_ms = ms(t);
        }

        // Shading: Kajiya-Kay at every vertex, with the strand's colour.
        let t = Instant::now();
        let s = &self.scene;
        let to_lights: Vec<Vec3> = self.shadows.lights().map(|l| -l.direction()).collect();
        self.colors.resize(points.len(), Vec3::ZERO);
        let offsets = hair.offsets();
        let strand_colors = hair.colors();
        let trans = &self.trans;
        let eye = camera.position;
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
        times.shade_ms = ms(t);

        // Draw: the head, then the hair over it.
        let t = Instant::now();
        let canvas = match &mut self.canvas {
            Some(c) => {
                c.clear();
                c
            }
            None => self
                .canvas
                .insert(Canvas::new(s.render.width, s.render.height)?),
        };
        if let Some(h) = &s.head {
            let head_shadow = shadows && h.shadow;
            let pipeline = &self.shadows;
            let ambient = s.shading.ambient;
            canvas.draw_sphere(
                &camera,
                &Sphere {
                    center: h.center,
                    radius: h.radius,
                },
                |p, n| {
                    let mut c = ambient * h.color;
                    for (l, &to_light) in to_lights.iter().enumerate() {
                        let lambert = n.dot(to_light).max(0.0);
                        if lambert > 0.0 {
                            // 1.5 cells towards the light: past the head's own deposit.
                            let tr = if head_shadow {
                                pipeline.transmittance_at(l, p, 1.5)
                            } else {
                                1.0
                            };
                            c += tr * lambert * (1.0 - ambient) * h.color;
                        }
                    }
                    c
                },
            );
        }
        let depth_ref = camera
            .position
            .distance(s.camera.look_at.unwrap_or_else(|| hair_bounds.center()));
        let look = raster::HairLook {
            fiber_width: s.fiber.width(),
            opacity: s.render.hair_alpha,
            depth_ref: depth_ref.max(1e-3),
        };
        canvas.draw_hair(&camera, points, offsets, &self.colors, &look);
        let img = canvas.resolve(s.render.background);
        times.draw_ms = ms(t);
        Ok((img, times))
    }
}
