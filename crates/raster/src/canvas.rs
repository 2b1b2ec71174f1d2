//! The canvas: an opaque layer (the head, depth-tested) under a
//! semi-transparent hair layer, resolved once per pixel.
//!
//! Hair is drawn as anti-aliased line strips. Its fragments are blended in
//! an order-independent way (weighted blended transparency, McGuire and
//! Bavoil 2013): each pixel sums colour times alpha times a depth weight
//! and alpha times the weight, and multiplies `1 - alpha`. The picture is cut into
//! bands of rows; one thread rasterizes a band, always in the order the
//! strands were given, into sums that stay in cache, and composites it. The
//! sums are the same floating-point operations in the same order whatever
//! the thread count, so the picture is the same bytes; drawing the strands
//! in another order changes only rounding.

use glam::{Vec3, Vec4};
use rayon::prelude::*;

use crate::{Camera, RasterError};

/// The largest image side, in pixels.
pub const MAX_SIDE: u32 = 16_384;
/// The most pixels an image may have (about 200 MB of accumulators).
pub const MAX_PIXELS: u64 = 40_000_000;

/// Fragment alpha never reaches 1: one fragment never hides all behind it.
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

/// Per-pixel hair sums: colour times alpha times depth weight, alpha
/// times depth weight, and the product of `1 - alpha`, the fraction of the
/// background the hair reveals.
///
/// Colour and weight sit in one vector (`xyz` and `w`), so that a fragment
/// adds both in one operation.
#[derive(Debug, Clone, Copy)]
struct Acc {
    rgbw: Vec4,
    reveal: f32,
}

impl Acc {
    const EMPTY: Acc = Acc {
        rgbw: Vec4::ZERO,
        reveal: 1.0,
    };
}

/// A picture being drawn.
///
/// The opaque layer is kept for the whole image, and cleared only where the
/// last frame drew. Hair is not accumulated over the whole image: its
/// segments are projected and binned to bands of rows, and [`Self::resolve`]
/// rasterizes each band into a small buffer that stays in cache and
/// composites it at once.
#[derive(Debug)]
pub struct Canvas {
    width: usize,
    height: usize,
    /// Opaque layer: view depth (infinite where nothing) and linear colour.
    depth: Vec<f32>,
    opaque: Vec<Vec3>,
    /// Rows `y0..y1`, columns `x0..x1` of the opaque layer drawn since the
    /// last clear.
    dirty: Option<[usize; 4]>,
    /// Projected hair vertices (`None`: behind the camera).
    verts: Vec<Option<ScreenVertex>>,
    /// Per chunk of strands (binned in parallel) and band of rows, every
    /// segment that touches the band, as its first vertex's index and its
    /// look's index. A band reads the chunks in order: strand order.
    bins: Vec<Vec<Vec<Segment>>>,
    /// Chunks of `bins` in use since the last clear.
    chunks: usize,
    /// The look of each call to [`Canvas::draw_hair`] since the last clear.
    looks: Vec<HairLook>,
}

/// The smallest pixel rectangle `[x0, x1, y0, y1]` holding `a` (if any) and `b`.
fn union(a: Option<[usize; 4]>, b: [usize; 4]) -> [usize; 4] {
    match a {
        Some([a0, a1, b0, b1]) => [a0.min(b[0]), a1.max(b[1]), b0.min(b[2]), b1.max(b[3])],
        None => b,
    }
}

/// A triangle's corners on screen, if all three are in front of the camera.
#[inline]
fn screen_corners(tri: [u32; 3], screen: &[Option<Vec3>]) -> Option<[Vec3; 3]> {
    Some([
        screen[tri[0] as usize]?,
        screen[tri[1] as usize]?,
        screen[tri[2] as usize]?,
    ])
}

/// A segment binned for drawing: the index in `verts` of its first end
/// (the second follows it) and the index of its look. Eight bytes, where
/// the ends themselves would be sixty: a band reads its segments' ends from
/// the shared vertices, in strand order.
type Segment = (u32, u32);

/// Strands per binning task.
const STRANDS_PER_CHUNK: usize = 256;

/// One vertex of a line strip, in screen space: pixel position and view
/// depth, and its shaded linear colour.
#[derive(Debug, Clone, Copy)]
struct ScreenVertex {
    p: Vec3,
    color: Vec3,
    /// Line width in pixels at this vertex.
    width: f32,
    /// Depth weight of its fragments, `(depth_ref / z)^6` (see
    /// [`HairLook::depth_ref`]), clamped to [1e-3, 1e3].
    weight: f32,
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
            dirty: None,
            verts: Vec::new(),
            bins: Vec::new(),
            chunks: 0,
            looks: Vec::new(),
        })
    }

    /// Empties the canvas for the next frame, keeping its memory.
    pub fn clear(&mut self) {
        if let Some([x0, x1, y0, y1]) = self.dirty.take() {
            let w = self.width;
            self.depth[y0 * w..y1 * w]
                .par_chunks_mut(w)
                .zip(self.opaque[y0 * w..y1 * w].par_chunks_mut(w))
                .for_each(|(d, c)| {
                    d[x0..x1].fill(f32::INFINITY);
                    c[x0..x1].fill(Vec3::ZERO);
                });
        }
        self.verts.clear();
        for chunk in &mut self.bins[..self.chunks] {
            chunk.iter_mut().for_each(Vec::clear);
        }
        self.chunks = 0;
        self.looks.clear();
    }

    pub fn width(&self) -> u32 {
        self.width as u32
    }

    pub fn height(&self) -> u32 {
        self.height as u32
    }

    /// The pixel rectangle `[x0, x1, y0, y1]` that a sphere can cover: the
    /// projection of its bounding cube, or the whole image when part of
    /// the cube is behind the camera.
    fn sphere_rect(&self, camera: &Camera, sphere: &Sphere) -> [usize; 4] {
        let (w, h) = (self.width as f32, self.height as f32);
        let mut lo = Vec3::splat(f32::INFINITY);
        let mut hi = Vec3::splat(f32::NEG_INFINITY);
        for k in 0..8 {
            let corner = Vec3::new(
                if k & 1 == 0 { -1.0 } else { 1.0 },
                if k & 2 == 0 { -1.0 } else { 1.0 },
                if k & 4 == 0 { -1.0 } else { 1.0 },
            );
            match camera.project(sphere.center + sphere.radius * corner) {
                Some(s) if s.is_finite() => {
                    lo = lo.min(s);
                    hi = hi.max(s);
                }
                _ => return [0, self.width, 0, self.height],
            }
        }
        // Pixel centres x + 0.5 in [lo.x, hi.x], with a pixel to spare.
        let span = |a: f32, b: f32, max: f32| {
            let a = (a - 1.0).clamp(0.0, max) as usize;
            let b = (b + 2.0).clamp(0.0, max) as usize;
            (a, b.max(a))
        };
        let (x0, x1) = span(lo.x, hi.x, w);
        let (y0, y1) = span(lo.y, hi.y, h);
        [x0, x1, y0, y1]
    }

    /// Runs `f(y, depth, colour)` on the rows `y0..y1` of the opaque layer
    /// in parallel, and marks the rectangle `[x0, x1, y0, y1]` drawn.
    fn opaque_rows(&mut self, rect: [usize; 4], f: impl Fn(usize, &mut [f32], &mut [Vec3]) + Sync) {
        let (w, y0, y1) = (self.width, rect[2], rect[3]);
        self.dirty = Some(union(self.dirty, rect));
        self.depth[y0 * w..y1 * w]
            .par_chunks_mut(w)
            .zip(self.opaque[y0 * w..y1 * w].par_chunks_mut(w))
            .enumerate()
            .for_each(|(row, (depth, color))| f(y0 + row, depth, color));
    }

    /// Draws an opaque sphere, one ray per pixel centre; `shade(point,
    /// normal)` gives the linear colour of a visible surface point.
    pub fn draw_sphere(
        &mut self,
        camera: &Camera,
        sphere: &Sphere,
        shade: impl Fn(Vec3, Vec3) -> Vec3 + Sync,
    ) {
        let [x0, x1, y0, y1] = self.sphere_rect(camera, sphere);
        if x0 >= x1 || y0 >= y1 {
            return;
        }
        self.opaque_rows([x0, x1, y0, y1], |y, depth, color| {
            for x in x0..x1 {
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

    /// Draws an opaque triangle mesh (`positions`, unit vertex `normals`,
    /// `triangles` as index triples) with the depth test; `shade(point,
    /// normal)` gives the linear colour of a visible surface point, the
    /// normal interpolated perspective-correctly from the vertices'.
    ///
    /// Triangles are binned to bands of rows, and each row tests its
    /// band's triangles in index order at every pixel centre: edges are
    /// inclusive (no cracks between triangles) and the first triangle
    /// wins a tie, so the result does not depend on the thread count. A
    /// triangle with a corner behind the camera is not drawn. Panics when
    /// an index names no vertex.
    pub fn draw_mesh(
        &mut self,
        camera: &Camera,
        positions: &[Vec3],
        normals: &[Vec3],
        triangles: &[[u32; 3]],
        shade: impl Fn(Vec3, Vec3) -> Vec3 + Sync,
    ) {
        assert_eq!(positions.len(), normals.len());
        assert!(
            triangles
                .iter()
                .flatten()
                .all(|&i| (i as usize) < positions.len()),
            "triangle indices name vertices"
        );
        let (w, h) = (self.width, self.height);
        let screen: Vec<Option<Vec3>> = positions
            .par_iter()
            .map(|&p| camera.project(p).filter(|s| s.is_finite()))
            .collect();
        // Triangles facing either way, with their pixel rows and columns.
        let mut rect: Option<[usize; 4]> = None;
        let bands = h.div_ceil(BAND);
        let mut bins: Vec<Vec<u32>> = vec![Vec::new(); bands];
        for (t, tri) in triangles.iter().enumerate() {
            let Some([a, b, c]) = screen_corners(*tri, &screen) else {
                continue;
            };
            let lo = a.min(b).min(c);
            let hi = a.max(b).max(c);
            // Pixel centres x + 0.5 in [lo, hi].
            let first = |v: f32, max: usize| (v - 0.5).ceil().clamp(0.0, max as f32) as usize;
            let end =
                |v: f32, max: usize| ((v - 0.5).floor() + 1.0).clamp(0.0, max as f32) as usize;
            let (x0, x1, y0, y1) = (first(lo.x, w), end(hi.x, w), first(lo.y, h), end(hi.y, h));
            if x0 >= x1 || y0 >= y1 {
                continue;
            }
            rect = Some(union(rect, [x0, x1, y0, y1]));
            for bin in &mut bins[y0 / BAND..=(y1 - 1) / BAND] {
                bin.push(t as u32);
            }
        }
        let Some([x0, x1, y0, y1]) = rect else {
            return;
        };
        self.opaque_rows([x0, x1, y0, y1], |y, depth, color| {
            let py = y as f32 + 0.5;
            // Per pixel of the row: the nearest surface so far, as its
            // triangle and perspective-correct barycentric weights.
            let mut best: Vec<(f32, u32, [f32; 3])> =
                vec![(f32::INFINITY, u32::MAX, [0.0; 3]); x1 - x0];
            for &t in &bins[y / BAND] {
                let tri = triangles[t as usize];
                let Some([a, b, c]) = screen_corners(tri, &screen) else {
                    continue;
                };
                let area = (b.x - a.x) * (c.y - a.y) - (b.y - a.y) * (c.x - a.x);
                if area.abs() < 1e-12 {
                    continue;
                }
                let inv = 1.0 / area;
                // Columns where the row's centre line crosses the triangle.
                let (lo, hi) = (a.min(b).min(c), a.max(b).max(c));
                if py < lo.y || py > hi.y {
                    continue;
                }
                let xa = ((lo.x - 0.5).ceil().max(x0 as f32) as usize).max(x0);
                let xb = (((hi.x - 0.5).floor() + 1.0).clamp(0.0, x1 as f32) as usize).min(x1);
                for x in xa..xb {
                    let px = x as f32 + 0.5;
                    // Screen-space barycentric weights of the pixel centre.
                    let l1 = ((px - a.x) * (c.y - a.y) - (py - a.y) * (c.x - a.x)) * inv;
                    let l2 = ((b.x - a.x) * (py - a.y) - (b.y - a.y) * (px - a.x)) * inv;
                    let l0 = 1.0 - l1 - l2;
                    const EDGE: f32 = -1e-6;
                    if l0 < EDGE || l1 < EDGE || l2 < EDGE {
                        continue;
                    }
                    // Perspective-correct: weights over view depth.
                    let (q0, q1, q2) = (l0 / a.z, l1 / b.z, l2 / c.z);
                    let sum = q0 + q1 + q2;
                    let z = 1.0 / sum;
                    let slot = &mut best[x - x0];
                    if z < slot.0 {
                        *slot = (z, t, [q0 * z, q1 * z, q2 * z]);
                    }
                }
            }
            for (x, &(z, t, wt)) in (x0..x1).zip(&best) {
                if t != u32::MAX && z < depth[x] {
                    let [i, j, k] = triangles[t as usize].map(|v| v as usize);
                    let p = wt[0] * positions[i] + wt[1] * positions[j] + wt[2] * positions[k];
                    let n = (wt[0] * normals[i] + wt[1] * normals[j] + wt[2] * normals[k])
                        .normalize_or_zero();
                    depth[x] = z;
                    color[x] = shade(p, n);
                }
            }
        });
    }

    /// Draws hair: line strips through `points` (strand `s` is
    /// `offsets[s]..offsets[s + 1]`) with per-vertex linear `colors`, looking
    /// as `look` says. The strips are projected and binned here, and
    /// rasterized by [`Self::resolve`].
    pub fn draw_hair(
        &mut self,
        camera: &Camera,
        points: &[Vec3],
        offsets: &[u32],
        colors: &[Vec3],
        look: &HairLook,
    ) {
        assert_eq!(points.len(), colors.len());
        let base = self.verts.len();
        let fiber_width = look.fiber_width;
        let focal = camera.focal();
        let depth_ref = look.depth_ref;
        // Project every vertex once.
        self.verts
            .par_extend(points.par_iter().zip(colors).map(|(&p, &color)| {
                let s = camera.project(p)?;
                // Projected width: w * focal / z pixels, at least a hair's
                // breadth so that distant hair still covers something.
                let width = (fiber_width * focal / s.z).clamp(0.05, 8.0);
                // The depth weight at the ends, interpolated along a
                // segment (which spans a few pixels; the weight changes
                // little along it).
                let weight = (depth_ref / s.z).powi(6).clamp(1e-3, 1e3);
                Some(ScreenVertex {
                    p: s,
                    color,
                    width,
                    weight,
                })
            }));
        self.looks.push(*look);
        let look_index = (self.looks.len() - 1) as u32;
        // Bin segments to bands of rows: chunks of strands in parallel, each
        // in strand order.
        let strands = offsets.len().saturating_sub(1);
        let new_chunks = strands.div_ceil(STRANDS_PER_CHUNK);
        let bands = self.height.div_ceil(BAND);
        let (first_chunk, end_chunk) = (self.chunks, self.chunks + new_chunks);
        if self.bins.len() < end_chunk {
            self.bins.resize_with(end_chunk, || vec![Vec::new(); bands]);
        }
        self.chunks = end_chunk;
        let verts = &self.verts;
        let (w, h) = (self.width as f32, self.height);
        self.bins[first_chunk..end_chunk]
            .par_iter_mut()
            .enumerate()
            .for_each(|(c, bins)| {
                let strands = c * STRANDS_PER_CHUNK..((c + 1) * STRANDS_PER_CHUNK).min(strands);
                for s in strands {
                    for i in offsets[s] as usize..(offsets[s + 1] as usize).saturating_sub(1) {
                        let (Some(a), Some(b)) = (verts[base + i], verts[base + i + 1]) else {
                            continue;
                        };
                        let pad = a.width.max(b.width) + 2.0;
                        let lo = (a.p.y.min(b.p.y) - pad).max(0.0);
                        let hi = (a.p.y.max(b.p.y) + pad).min(h as f32);
                        if lo >= hi || a.p.x.max(b.p.x) < -pad || a.p.x.min(b.p.x) > w + pad {
                            continue;
                        }
                        let (first, last) = (lo as usize / BAND, (hi as usize).min(h - 1) / BAND);
                        for bin in &mut bins[first..=last] {
                            bin.push(((base + i) as u32, look_index));
                        }
                    }
                }
            });
    }

    /// The finished picture: hair over the opaque layer over `background`
    /// (linear colours), encoded as 8-bit sRGB. Each band of rows is
    /// rasterized into its own sums, then composited.
    pub fn resolve(&self, background: Vec3) -> image::RgbImage {
        let (w, h) = (self.width, self.height);
        let mut img = image::RgbImage::new(w as u32, h as u32);
        let lut = srgb_table();
        let bg = encode(lut, background);
        let buf: &mut [u8] = &mut img;
        let chunks = &self.bins[..self.chunks];
        buf.par_chunks_mut(w * BAND * 3).enumerate().for_each_init(
            Vec::new,
            |acc: &mut Vec<Acc>, (band, out)| {
                let y0 = band * BAND;
                let rows = out.len() / (3 * w);
                // Empty between bands: compositing empties each sum as it
                // reads it, so no separate pass clears the buffer.
                if acc.len() < rows * w {
                    acc.resize(rows * w, Acc::EMPTY);
                }
                let acc = &mut acc[..rows * w];
                for &(i, look) in chunks.iter().flat_map(|c| &c[band]) {
                    let i = i as usize;
                    // Binned segments have both ends on screen.
                    if let (Some(a), Some(b)) = (self.verts[i], self.verts[i + 1]) {
                        self.rasterize(a, b, &self.looks[look as usize], y0, rows, acc);
                    }
                }
                let depth = &self.depth[y0 * w..(y0 + rows) * w];
                let opaque = &self.opaque[y0 * w..(y0 + rows) * w];
                for (i, px) in out.chunks_exact_mut(3).enumerate() {
                    let a = std::mem::replace(&mut acc[i], Acc::EMPTY);
                    let covered = depth[i].is_finite();
                    if a.rgbw.w == 0.0 && !covered {
                        px.copy_from_slice(&bg);
                        continue;
                    }
                    let base = if covered { opaque[i] } else { background };
                    let c = if a.rgbw.w > 0.0 {
                        let hair = a.rgbw.truncate() / a.rgbw.w;
                        hair * (1.0 - a.reveal) + base * a.reveal
                    } else {
                        base
                    };
                    px.copy_from_slice(&encode(lut, c));
                }
            },
        );
        img
    }

    /// Adds the fragments of the segment from `a` to `b` that fall in rows
    /// `y0..y0 + rows` to `acc` (that band's sums).
    fn rasterize(
        &self,
        a: ScreenVertex,
        b: ScreenVertex,
        look: &HairLook,
        y0: usize,
        rows: usize,
        acc: &mut [Acc],
    ) {
        let w = self.width;
        let opacity = look.opacity.clamp(0.0, 1.0);
        let (wa, wb) = (a.weight, b.weight);
        let depth = &self.depth[y0 * w..(y0 + rows) * w];
        let clip = [0, w as i32, y0 as i32, (y0 + rows) as i32];
        let band = Band {
            w,
            y0,
            depth,
            opacity,
            wa,
            wb,
        };
        // One copy of the loop per major axis, with no per-fragment test of
        // which axis is which.
        if is_steep(a, b) {
            line_steps::<true>(a, b, clip, |s| band.add::<true>(a, b, s, acc));
        } else {
            line_steps::<false>(a, b, clip, |s| band.add::<false>(a, b, s, acc));
        }
    }
}

/// What every step of one segment in one band shares.
struct Band<'a> {
    w: usize,
    y0: usize,
    /// The band's rows of the opaque layer's depth.
    depth: &'a [f32],
    opacity: f32,
    /// Depth weights at the segment's ends.
    wa: f32,
    wb: f32,
}

impl Band<'_> {
    /// Adds the fragments of four steps to `acc`, step by step and in each
    /// step the nearer row first; `STEEP`: y is the major axis. What a
    /// step's two pixels share (depth, colour, weight, alpha) is computed
    /// for the four steps at once, each lane as one step would compute it.
    #[inline(always)]
    fn add<const STEEP: bool>(&self, a: ScreenVertex, b: ScreenVertex, s: &Steps, acc: &mut [Acc]) {
        let t = s.t;
        let z = (Vec4::splat(a.p.z) + t * (b.p.z - a.p.z)).to_array();
        // Colours with w = 1, so that colour times weight carries the
        // weight along: 1 + t (1 - 1) is exactly 1.
        let (ca, cb) = (a.color.extend(1.0), b.color.extend(1.0));
        let dc = cb - ca;
        let ts = t.to_array();
        let wt = (Vec4::splat(self.wa) + t * (self.wb - self.wa)).to_array();
        let step_alpha = self.opacity * s.cov;
        let alphas = s
            .shares
            .map(|share| (step_alpha * share).min(Vec4::splat(MAX_ALPHA)).to_array());
        for l in 0..4 {
            let major = s.major + l as i32;
            let c = (ca + ts[l] * dc).max(Vec4::ZERO);
            for (row, alpha) in alphas.iter().enumerate() {
                let alpha = alpha[l];
                if alpha <= 0.0 {
                    continue;
                }
                let minor = s.minor[l] + row as i32;
                let (x, y) = if STEEP {
                    (minor, major)
                } else {
                    (major, minor)
                };
                let px = (y as usize - self.y0) * self.w + x as usize;
                if z[l] >= self.depth[px] {
                    continue;
                }
                let aw = alpha * wt[l];
                let cell = &mut acc[px];
                cell.rgbw += c * aw;
                cell.reveal *= 1.0 - alpha;
            }
        }
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
        // v in [0, 1]: the index fits i32 (a cheaper conversion than to usize).
        *p = lut[(v * SRGB_STEPS as f32 + 0.5) as i32 as usize];
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
#[cfg(test)]
fn line_fragments(a: ScreenVertex, b: ScreenVertex, mut emit: impl FnMut(i32, i32, f32, f32)) {
    let all = [i32::MIN, i32::MAX, i32::MIN, i32::MAX];
    let steep = is_steep(a, b);
    let mut each = |s: &Steps| {
        for l in 0..4 {
            let major = s.major + l as i32;
            for (row, share) in s.shares.iter().enumerate() {
                if share[l] > 0.0 {
                    let r = s.minor[l] + row as i32;
                    let (x, y) = if steep { (r, major) } else { (major, r) };
                    emit(x, y, s.t[l], s.cov[l] * share[l]);
                }
            }
        }
    };
    if steep {
        line_steps::<true>(a, b, all, &mut each);
    } else {
        line_steps::<false>(a, b, all, &mut each);
    }
}

/// `ceil(x)` as an integer, by truncation (`ceil` is a libm call on
/// baseline x86-64); saturating far outside the `i32` range.
#[inline]
fn ceil_i32(x: f32) -> i32 {
    let c = x as i32;
    if (c as f32) < x {
        c.saturating_add(1)
    } else {
        c
    }
}

/// Four consecutive steps of a line along its major axis, lane `l` being
/// the pixel column (or row) `major + l`: the parameter `t` along the
/// line, the coverage `cov` of the step, and the two pixels across it,
/// `minor` and `minor + 1`, with their shares of the coverage (0 for a
/// pixel outside the clip, and for lanes past the line's last step).
#[derive(Debug, Clone, Copy)]
struct Steps {
    major: i32,
    t: Vec4,
    cov: Vec4,
    minor: [i32; 4],
    shares: [Vec4; 2],
}

/// Whether y is the major axis of the line from `a` to `b`.
#[inline]
fn is_steep(a: ScreenVertex, b: ScreenVertex) -> bool {
    let d = b.p - a.p;
    d.y.abs() > d.x.abs()
}

/// [`line_fragments`] restricted to the pixels `x0..x1`, `y0..y1` of
/// `clip`, four steps at a time: `emit(steps)`, along y when `STEEP`
/// (which must be [`is_steep`]), else along x. The same fragments inside
/// the clip, and no work spent outside (a segment that reaches far off
/// screen costs only its visible steps). Each lane computes what one step
/// would on its own, with the same operations in the same order, so the
/// fragments do not depend on how steps are grouped.
#[inline(always)]
fn line_steps<const STEEP: bool>(
    a: ScreenVertex,
    b: ScreenVertex,
    clip: [i32; 4],
    mut emit: impl FnMut(&Steps),
) {
    let d = b.p - a.p;
    let steep = STEEP;
    // Major axis u, minor axis v, and the clip along each.
    let (ua, va, du, dv, (u_lo, u_hi), (v_lo, v_hi)) = if steep {
        (
            a.p.y,
            a.p.x,
            d.y,
            d.x,
            (clip[2], clip[3]),
            (clip[0], clip[1]),
        )
    } else {
        (
            a.p.x,
            a.p.y,
            d.x,
            d.y,
            (clip[0], clip[1]),
            (clip[2], clip[3]),
        )
    };
    if du == 0.0 || !du.is_finite() || !dv.is_finite() {
        return;
    }
    let (u0, u1) = if du > 0.0 {
        (ua, ua + du)
    } else {
        (ua + du, ua)
    };
    let inv_du = 1.0 / du;
    if !inv_du.is_finite() {
        // Shorter than a float can invert: no pixel centre lies on it.
        return;
    }
    let m = dv * inv_du;
    let stretch = (1.0 + m * m).sqrt();
    // Pixel centres k + 0.5 in [u0, u1), within the clip.
    let mut first = ceil_i32(u0 - 0.5).max(u_lo);
    let mut last = ceil_i32(u1 - 0.5).min(u_hi);
    // Minor rows r0 = floor(v - 0.5) and r0 + 1 reach the clip only where
    // v lies in [v_lo - 0.5, v_hi + 0.5): the steps k where that holds, a
    // step wider on each side (v is clamped at the ends).
    if m != 0.0 {
        let k_at = |v: f32| ua + (v - va) / m - 0.5;
        let (ka, kb) = (k_at(v_lo as f32 - 0.5), k_at(v_hi as f32 + 0.5));
        let (lo, hi) = (ka.min(kb), ka.max(kb));
        if lo.is_finite() {
            first = first.max(ceil_i32(lo).saturating_sub(1));
        }
        if hi.is_finite() {
            last = last.min(ceil_i32(hi).saturating_add(1));
        }
    }
    let dw = b.width - a.width;
    // The clip across, and the steps' end, as floats: exact, as pixel
    // coordinates are far below 2^24.
    let (v_lo, v_hi, end) = (
        Vec4::splat(v_lo as f32),
        Vec4::splat(v_hi as f32),
        Vec4::splat(last as f32),
    );
    let mut k = first;
    while k < last {
        let ks = Vec4::splat(k as f32) + Vec4::new(0.0, 1.0, 2.0, 3.0);
        let t = ((ks + 0.5 - ua) * inv_du).clamp(Vec4::ZERO, Vec4::ONE);
        let v = Vec4::splat(va) + t * dv;
        let cov = (Vec4::splat(a.width) + t * dw) * stretch;
        let vc = v - 0.5;
        let r0 = vc.floor();
        let f = vc - r0;
        let r1 = r0 + 1.0;
        let lane = ks.cmplt(end);
        let shares = [
            Vec4::select(lane & r0.cmpge(v_lo) & r0.cmplt(v_hi), 1.0 - f, Vec4::ZERO),
            Vec4::select(lane & r1.cmpge(v_lo) & r1.cmplt(v_hi), f, Vec4::ZERO),
        ];
        if (shares[0].cmpgt(Vec4::ZERO) | shares[1].cmpgt(Vec4::ZERO)).any() {
            emit(&Steps {
                major: k,
                t,
                cov,
                minor: r0.as_ivec4().to_array(),
                shares,
            });
        }
        k = k.saturating_add(4);
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
            weight: 1.0,
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
    fn thread_count_does_not_change_a_single_byte_and_draw_order_only_rounding() {
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
        let on = |threads| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| draw(&pts, &cols))
        };
        assert!(forward == on(1) && forward == on(3), "thread counts");
        // Another order rounds differently, by at most a level.
        let rev_pts: Vec<Vec3> = pts.chunks(2).rev().flatten().copied().collect();
        let rev_cols: Vec<Vec3> = cols.chunks(2).rev().flatten().copied().collect();
        let back = draw(&rev_pts, &rev_cols);
        assert!(forward.iter().zip(&back).all(|(a, b)| a.abs_diff(*b) <= 1));
        assert!(forward.iter().any(|&v| v > 40), "something was drawn");
    }

    #[test]
    fn a_mesh_covers_its_projected_area_without_cracks_and_the_nearer_face_wins() {
        // Orthographic enough: a far camera with a narrow field of view.
        let cam = Camera::new(Vec3::new(0.0, 0.0, 400.0), Vec3::ZERO, 2.0, 96, 96).unwrap();
        let px = cam.focal() / 400.0; // pixels per unit at the plane z = 0
        // A square of side 8 px made of a fan of 4 triangles around its centre
        // (shared edges), and behind it a larger square of another colour.
        let h = 4.0 / px;
        let front = [
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(-h, -h, 0.0),
            Vec3::new(h, -h, 0.0),
            Vec3::new(h, h, 0.0),
            Vec3::new(-h, h, 0.0),
        ];
        let back = [
            Vec3::new(-3.0 * h, -3.0 * h, -1.0),
            Vec3::new(3.0 * h, -3.0 * h, -1.0),
            Vec3::new(3.0 * h, 3.0 * h, -1.0),
            Vec3::new(-3.0 * h, 3.0 * h, -1.0),
        ];
        let positions: Vec<Vec3> = back.iter().chain(&front).copied().collect();
        let normals = vec![Vec3::Z; positions.len()];
        let tris = [
            [0, 1, 2],
            [0, 2, 3],
            [4, 5, 6],
            [4, 6, 7],
            [4, 7, 8],
            [4, 8, 5],
        ];
        let draw = || {
            let mut c = Canvas::new(96, 96).unwrap();
            // Colour by depth: the front square white, the back one grey.
            c.draw_mesh(&cam, &positions, &normals, &tris, |p, n| {
                assert!((n - Vec3::Z).length() < 1e-5);
                Vec3::splat(if p.z > -0.5 { 1.0 } else { 0.2 })
            });
            c.resolve(Vec3::ZERO)
        };
        let img = draw();
        let count = |v: u8| img.pixels().filter(|p| p[0] == v).count();
        assert_eq!(count(255), 64, "an 8x8 px square, no crack and no overlap");
        assert_eq!(count(to_srgb8(Vec3::splat(0.2))[0]), 24 * 24 - 64);
        let one = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap()
            .install(draw);
        assert!(one == img, "thread counts");
    }
}
