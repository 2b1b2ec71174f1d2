//! The canvas: an opaque layer (the head, depth-tested) under a
//! semi-transparent hair layer, resolved once per pixel.
//!
//! Hair is drawn as anti-aliased line strips. Its fragments are blended in
//! an order-independent way (weighted blended transparency, McGuire and
//! Bavoil 2013): each pixel sums colour times alpha times a depth weight,
//! alpha times the weight, and `-ln(1 - alpha)`, all in fixed-point
//! integers. Integer sums do not depend on the order of the fragments, so
//! the picture is the same bytes whatever the draw order or thread count.

use glam::Vec3;
use rayon::prelude::*;

use crate::{Camera, RasterError};

/// The largest image side, in pixels.
pub const MAX_SIDE: u32 = 16_384;
/// The most pixels an image may have (about 200 MB of accumulators).
pub const MAX_PIXELS: u64 = 40_000_000;

/// Fixed-point scale of the colour and weight sums.
const SCALE: f32 = (1u32 << 20) as f32;
/// Fixed-point scale of the optical depth sum `-ln(1 - alpha)`.
const DEPTH_SCALE: f32 = (1u32 << 24) as f32;
/// Fragment alpha never reaches 1, so `-ln(1 - alpha)` stays finite.
const MAX_ALPHA: f32 = 0.995;
/// Image rows per band: bands are drawn in parallel, each by one thread.
const BAND: usize = 16;

/// An opaque sphere: the default head.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sphere {
    pub center: Vec3,
    pub radius: f32,
}

impl Sphere {
    /// Distance along the unit ray `o + t d` to the nearest hit in front.
    pub fn hit(&self, o: Vec3, d: Vec3) -> Option<f32> {
        let oc = o - self.center;
        let b = oc.dot(d);
        let c = oc.length_squared() - self.radius * self.radius;
        let disc = b * b - c;
        if disc < 0.0 {
            return None;
        }
        let s = disc.sqrt();
        [-b - s, -b + s].into_iter().find(|&t| t > 0.0)
    }
}

/// How drawn strands look.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HairLook {
    /// Strand width, scene units (projected to pixels by the camera).
    pub fiber_width: f32,
    /// Opacity where a strand covers a whole pixel.
    pub opacity: f32,
    /// Distance from the camera (scene units) that sets the depth
    /// weighting: fragments nearer count more, farther less.
    pub depth_ref: f32,
}

/// Per-pixel hair sums, in fixed point.
#[derive(Debug, Clone, Copy, Default)]
struct Acc {
    rgb: [u64; 3],
    weight: u64,
    depth: u64,
}

/// A picture being drawn.
#[derive(Debug)]
pub struct Canvas {
    width: usize,
    height: usize,
    /// Opaque layer: view depth (infinite where nothing) and linear colour.
    depth: Vec<f32>,
    opaque: Vec<Vec3>,
    hair: Vec<Acc>,
}

/// One vertex of a line strip, in screen space: pixel position and view
/// depth, and its shaded linear colour.
#[derive(Debug, Clone, Copy)]
struct ScreenVertex {
    p: Vec3,
    color: Vec3,
    /// Line width in pixels at this vertex.
    width: f32,
}

impl Canvas {
    pub fn new(width: u32, height: u32) -> Result<Canvas, RasterError> {
        if !(1..=MAX_SIDE).contains(&width)
            || !(1..=MAX_SIDE).contains(&height)
            || u64::from(width) * u64::from(height) > MAX_PIXELS
        {
            return Err(RasterError::Size { width, height });
        }
        let n = width as usize * height as usize;
        Ok(Canvas {
            width: width as usize,
            height: height as usize,
            depth: vec![f32::INFINITY; n],
            opaque: vec![Vec3::ZERO; n],
            hair: vec![Acc::default(); n],
        })
    }

    /// Empties the canvas for the next frame, keeping its memory.
    pub fn clear(&mut self) {
        self.depth
            .par_iter_mut()
            .with_min_len(4096)
            .for_each(|d| *d = f32::INFINITY);
        self.opaque
            .par_iter_mut()
            .with_min_len(4096)
            .for_each(|c| *c = Vec3::ZERO);
        self.hair
            .par_iter_mut()
            .with_min_len(4096)
            .for_each(|a| *a = Acc::default());
    }

    pub fn width(&self) -> u32 {
        self.width as u32
    }

    pub fn height(&self) -> u32 {
        self.height as u32
    }

    /// Draws an opaque sphere, one ray per pixel centre; `shade(point,
    /// normal)` gives the linear colour of a visible surface point.
    pub fn draw_sphere(
        &mut self,
        camera: &Camera,
        sphere: &Sphere,
        shade: impl Fn(Vec3, Vec3) -> Vec3 + Sync,
    ) {
        let w = self.width;
        self.depth
            .par_chunks_mut(w)
            .zip(self.opaque.par_chunks_mut(w))
            .enumerate()
            .for_each(|(y, (depth, color))| {
                for x in 0..w {
                    let d = camera.ray(x as f32 + 0.5, y as f32 + 0.5);
                    if let Some(t) = sphere.hit(camera.position, d) {
                        let p = camera.position + t * d;
                        // View depth, comparable with the camera's projection.
                        let z = camera.project(p).map_or(f32::INFINITY, |s| s.z);
                        if z < depth[x] {
                            depth[x] = z;
                            color[x] = shade(p, (p - sphere.center) / sphere.radius);
                        }
                    }
                }
            });
    }

    /// Draws hair: line strips through `points` (strand `s` is
    /// `offsets[s]..offsets[s + 1]`) with per-vertex linear `colors`, looking
    /// as `look` says.
    pub fn draw_hair(
        &mut self,
        camera: &Camera,
        points: &[Vec3],
        offsets: &[u32],
        colors: &[Vec3],
        look: &HairLook,
    ) {
        assert_eq!(points.len(), colors.len());
        let HairLook {
            fiber_width,
            opacity,
            depth_ref,
        } = *look;
        let focal = camera.focal();
        // Project every vertex once.
        let verts: Vec<Option<ScreenVertex>> = points
            .par_iter()
            .zip(colors)
            .map(|(&p, &color)| {
                let s = camera.project(p)?;
                // Projected width: w * focal / z pixels, at least a hair's
                // breadth so that distant hair still covers something.
                let width = (fiber_width * focal / s.z).clamp(0.05, 8.0);
                Some(ScreenVertex { p: s, color, width })
            })
            .collect();
        // Bin segments to bands of rows, in strand order.
        let bands = self.height.div_ceil(BAND);
        let mut bins: Vec<Vec<(u32, u32)>> = vec![Vec::new(); bands];
        for s in 0..offsets.len().saturating_sub(1) {
            for i in offsets[s] as usize..(offsets[s + 1] as usize).saturating_sub(1) {
                let (Some(a), Some(b)) = (verts[i], verts[i + 1]) else {
                    continue;
                };
                let pad = a.width.max(b.width) + 2.0;
                let lo = (a.p.y.min(b.p.y) - pad).max(0.0);
                let hi = (a.p.y.max(b.p.y) + pad).min(self.height as f32);
                if lo >= hi || a.p.x.max(b.p.x) < -pad || a.p.x.min(b.p.x) > self.width as f32 + pad
                {
                    continue;
                }
                let (first, last) = (
                    lo as usize / BAND,
                    (hi as usize).min(self.height - 1) / BAND,
                );
                for bin in &mut bins[first..=last] {
                    bin.push((i as u32, i as u32 + 1));
                }
            }
        }
        let (w, h) = (self.width, self.height);
        let weight = |z: f32| (depth_ref / z).powi(6).clamp(1e-3, 1e3);
        let opacity = opacity.clamp(0.0, 1.0);
        self.hair
            .par_chunks_mut(w * BAND)
            .zip(self.depth.par_chunks(w * BAND))
            .zip(bins)
            .enumerate()
            .for_each(|(band, ((acc, depth), segs))| {
                let y0 = band * BAND;
                let rows = acc.len() / w;
                for (ia, ib) in segs {
                    let (a, b) = (
                        verts[ia as usize].expect("binned"),
                        verts[ib as usize].expect("binned"),
                    );
                    line_fragments(a, b, |x, y, t, coverage| {
                        if x < 0
                            || x >= w as i32
                            || y < y0 as i32
                            || y >= (y0 + rows) as i32
                            || y >= h as i32
                        {
                            return;
                        }
                        let px = (y as usize - y0) * w + x as usize;
                        let z = a.p.z + t * (b.p.z - a.p.z);
                        if z >= depth[px] {
                            return;
                        }
                        let alpha = (opacity * coverage).min(MAX_ALPHA);
                        if alpha <= 0.0 {
                            return;
                        }
                        let c = a.color + t * (b.color - a.color);
                        let aw = alpha * weight(z);
                        let cell = &mut acc[px];
                        for k in 0..3 {
                            cell.rgb[k] += (c[k].max(0.0) * aw * SCALE) as u64;
                        }
                        cell.weight += (aw * SCALE) as u64;
                        cell.depth += (-(1.0 - alpha).ln() * DEPTH_SCALE) as u64;
                    });
                }
            });
    }

    /// The finished picture: hair over the opaque layer over `background`
    /// (linear colours), encoded as 8-bit sRGB.
    pub fn resolve(&self, background: Vec3) -> image::RgbImage {
        let mut img = image::RgbImage::new(self.width as u32, self.height as u32);
        let lut = srgb_table();
        let buf: &mut [u8] = &mut img;
        buf.par_chunks_mut(3)
            .enumerate()
            .with_min_len(4096)
            .for_each(|(i, px)| {
                let base = if self.depth[i].is_finite() {
                    self.opaque[i]
                } else {
                    background
                };
                let a = self.hair[i];
                let c = if a.weight > 0 {
                    let hair = Vec3::new(a.rgb[0] as f32, a.rgb[1] as f32, a.rgb[2] as f32)
                        / a.weight as f32;
                    let reveal = (-(a.depth as f32) / DEPTH_SCALE).exp();
                    hair * (1.0 - reveal) + base * reveal
                } else {
                    base
                };
                px.copy_from_slice(&encode(lut, c));
            });
        img
    }
}

/// Steps of the linear-to-sRGB table: fine enough that every 8-bit output
/// is reached exactly as the formula would round it, within one level.
const SRGB_STEPS: usize = 8192;

/// Linear to 8-bit sRGB at `SRGB_STEPS + 1` evenly spaced linear values
/// (`powf` per channel and pixel cost more than the rest of the resolve).
fn srgb_table() -> &'static [u8] {
    static TABLE: std::sync::OnceLock<Vec<u8>> = std::sync::OnceLock::new();
    TABLE.get_or_init(|| {
        (0..=SRGB_STEPS)
            .map(|i| srgb8(i as f32 / SRGB_STEPS as f32))
            .collect()
    })
}

/// A linear colour as the 8-bit sRGB pixel [`Canvas::resolve`] writes for it.
pub fn to_srgb8(c: Vec3) -> [u8; 3] {
    encode(srgb_table(), c)
}

#[inline]
fn encode(lut: &[u8], c: Vec3) -> [u8; 3] {
    let mut px = [0u8; 3];
    for (k, p) in px.iter_mut().enumerate() {
        // The table has SRGB_STEPS + 1 entries over [0, 1].
        let v = if c[k].is_finite() {
            c[k].clamp(0.0, 1.0)
        } else {
            0.0
        };
        *p = lut[(v * SRGB_STEPS as f32 + 0.5) as usize];
    }
    px
}

/// Linear [0, 1] to 8-bit sRGB.
fn srgb8(v: f32) -> u8 {
    let v = if v.is_finite() {
        v.clamp(0.0, 1.0)
    } else {
        0.0
    };
    let s = if v <= 0.003_130_8 {
        12.92 * v
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    };
    (s * 255.0 + 0.5) as u8
}

/// The fragments of an anti-aliased line from `a` to `b`: for every pixel
/// column (or row, along the major axis) whose centre lies in `[a, b)`, the
/// line's coverage of that step, `width * sqrt(1 + m^2)` pixels (the area of
/// a unit step of a line of slope `m`), split between the two pixels nearest
/// the line in proportion to distance (Wu's method). `emit(x, y, t,
/// coverage)` gets the pixel, the parameter along the line and the
/// coverage. Half-open, so strips cover each joint once.
fn line_fragments(a: ScreenVertex, b: ScreenVertex, mut emit: impl FnMut(i32, i32, f32, f32)) {
    let d = b.p - a.p;
    let steep = d.y.abs() > d.x.abs();
    // Major axis u, minor axis v.
    let (ua, va, du, dv) = if steep {
        (a.p.y, a.p.x, d.y, d.x)
    } else {
        (a.p.x, a.p.y, d.x, d.y)
    };
    if du == 0.0 || !du.is_finite() || !dv.is_finite() {
        return;
    }
    let (u0, u1) = if du > 0.0 {
        (ua, ua + du)
    } else {
        (ua + du, ua)
    };
    let m = dv / du;
    let stretch = (1.0 + m * m).sqrt();
    // Pixel centres k + 0.5 in [u0, u1).
    let first = (u0 - 0.5).ceil() as i32;
    let last = (u1 - 0.5).ceil() as i32;
    for k in first..last {
        let uc = k as f32 + 0.5;
        let t = ((uc - ua) / du).clamp(0.0, 1.0);
        let v = va + t * dv;
        let width = a.width + t * (b.width - a.width);
        let cov = width * stretch;
        let vc = v - 0.5;
        // Floor by truncation (`floor` is a libm call on baseline x86-64).
        // At negative integers this picks the row below with share 0 and
        // the row itself with share 1: the same fragments.
        let r0 = if vc >= 0.0 { vc as i32 } else { vc as i32 - 1 };
        let f = vc - r0 as f32;
        for (r, share) in [(r0, 1.0 - f), (r0 + 1, f)] {
            if share > 0.0 {
                if steep {
                    emit(r, k, t, cov * share)
                } else {
                    emit(k, r, t, cov * share)
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn vertex(x: f32, y: f32, width: f32) -> ScreenVertex {
        ScreenVertex {
            p: Vec3::new(x, y, 1.0),
            color: Vec3::ONE,
            width,
        }
    }

    #[test]
    fn a_lines_coverage_adds_up_to_its_area() {
        for (a, b) in [
            ((3.2, 4.7), (40.9, 11.3)),
            ((10.0, 2.0), (12.5, 50.25)),
            ((30.0, 30.0), (5.5, 5.5)),
            ((0.5, 7.0), (20.5, 7.0)),
        ] {
            let mut sum = 0.0;
            line_fragments(
                vertex(a.0, a.1, 0.8),
                vertex(b.0, b.1, 0.8),
                |_, _, _, c| sum += c,
            );
            let len = ((b.0 - a.0).powi(2) + (b.1 - a.1).powi(2)).sqrt();
            // The half-open steps may miss or add part of one step at the ends.
            let step = 0.8
                * (1.0
                    + ((b.1 - a.1) / (b.0 - a.0))
                        .powi(2)
                        .min(((b.0 - a.0) / (b.1 - a.1)).powi(2)))
                .sqrt();
            assert!(
                (sum - 0.8 * len).abs() <= step,
                "{a:?}-{b:?}: coverage {sum}, area {}",
                0.8 * len
            );
        }
    }

    #[test]
    fn a_strip_covers_each_joint_once() {
        let pts = [
            vertex(2.0, 2.0, 1.0),
            vertex(12.0, 5.0, 1.0),
            vertex(30.0, 9.0, 1.0),
        ];
        let mut whole = 0.0;
        line_fragments(pts[0], pts[2], |_, _, _, c| whole += c);
        let mut parts = 0.0;
        line_fragments(pts[0], pts[1], |_, _, _, c| parts += c);
        line_fragments(pts[1], pts[2], |_, _, _, c| parts += c);
        assert!((whole - parts).abs() < 0.2, "{whole} vs {parts}");
    }

    #[test]
    fn zero_length_segments_draw_nothing() {
        let mut n = 0;
        line_fragments(
            vertex(3.0, 3.0, 1.0),
            vertex(3.0, 3.0, 1.0),
            |_, _, _, _| n += 1,
        );
        assert_eq!(n, 0);
    }

    #[test]
    fn refuses_absurd_sizes() {
        assert!(Canvas::new(0, 10).is_err());
        assert!(Canvas::new(100_000, 10).is_err());
        assert!(Canvas::new(16_000, 16_000).is_err());
        assert!(Canvas::new(64, 48).is_ok());
    }

    #[test]
    fn draw_order_does_not_change_a_single_byte() {
        let cam = Camera::new(Vec3::new(0.0, 0.0, 10.0), Vec3::ZERO, 40.0, 64, 48).unwrap();
        let mut pts = Vec::new();
        let mut cols = Vec::new();
        for s in 0..40 {
            let f = s as f32 * 0.1;
            pts.extend([
                Vec3::new(-2.0 + f, -1.0, f - 2.0),
                Vec3::new(2.0 - f, 1.5, 1.0 - f),
            ]);
            cols.extend([Vec3::new(f / 4.0, 0.3, 0.9 - f / 5.0); 2]);
        }
        let offsets: Vec<u32> = (0..=40).map(|s| 2 * s).collect();
        let draw = |pts: &[Vec3], cols: &[Vec3]| {
            let mut c = Canvas::new(64, 48).unwrap();
            c.draw_hair(
                &cam,
                pts,
                &offsets,
                cols,
                &HairLook {
                    fiber_width: 0.05,
                    opacity: 0.6,
                    depth_ref: 10.0,
                },
            );
            c.resolve(Vec3::splat(0.1)).into_raw()
        };
        let forward = draw(&pts, &cols);
        let rev_pts: Vec<Vec3> = pts.chunks(2).rev().flatten().copied().collect();
        let rev_cols: Vec<Vec3> = cols.chunks(2).rev().flatten().copied().collect();
        assert!(forward == draw(&rev_pts, &rev_cols));
        assert!(forward.iter().any(|&v| v > 40), "something was drawn");
    }
}
