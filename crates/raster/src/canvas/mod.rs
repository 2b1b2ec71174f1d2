//! The canvas: an opaque layer (the head, depth-tested) under a
//! semi-transparent hair layer, resolved once per pixel.
//!
//! Hair is drawn as anti-aliased line strips. Its fragments are blended in
//! an order-independent way (weighted blended transparency, McGuire and
//! Bavoil 2013): each pixel sums colour times alpha times a depth weight
//! and alpha times the weight, and multiplies `1 - alpha`. The picture is
//! cut into bands of rows; one thread rasterizes a band into sums that stay
//! in cache, and composites it.
//!
//! Strands come in groups (say, a cluster worker's share is a set of whole
//! groups). Inside a group, fragments are summed in floating point in
//! strand order; each group's sums are then rounded once into exact
//! integers ([`Sums`]) and added. So the picture is the same bytes whatever
//! the thread count, and whether the groups are drawn on one canvas or on
//! several whose [`HairLayer`]s are composited together; drawing the
//! strands of a group in another order changes only rounding.

mod front;
mod layer;
mod line;
mod look;
mod opaque;
mod resolve;
mod scratch;
mod segments;
mod srgb;
mod sums;

pub use front::{Fragment, MAX_NEAREST};
pub use layer::HairLayer;
pub use look::HairLook;
pub use opaque::Sphere;
pub use segments::BandSegments;
pub use srgb::to_srgb8;
pub use sums::Sums;

use glam::{Vec3, Vec4};
use rayon::prelude::*;

use crate::{Camera, RasterError};
use line::{ScreenVertex, Steps, is_steep, line_steps};
use look::{Look, Projected};
use scratch::{NO_SLOT, Scratch};

/// The largest image side, in pixels.
pub(crate) const MAX_SIDE: u32 = 16_384;
/// The most pixels an image may have (about 200 MB of accumulators).
pub const MAX_PIXELS: u64 = 40_000_000;

/// Fragment alpha never reaches 1: one fragment never hides all behind it.
const MAX_ALPHA: f32 = 0.995;
/// A band's rows are a multiple of this, and are this many unless the
/// hair is dense ([`Canvas::band_rows_for`]).
const BAND_STEP: usize = 16;
/// Pixels of a band at most (but for the narrowest bands): 64 rows of a
/// 1280-pixel picture. A thread drawing a band holds about `36 + 48 k`
/// bytes a band pixel (its cells, and the group's and the exact nearest
/// fragments, `k` of each): 19 MB at the default `k = 4`, 66 MB at the
/// most, 16.
const BAND_PIXELS: usize = 64 * 1280;
/// Rows of the tallest band.
const MAX_BAND: usize = 64;
/// Bands a picture has at least (but for the shortest pictures): the
/// threads that can draw it at once.
const MIN_BANDS: usize = 8;
/// Segments a pixel from which bands grow taller.
const DENSE: f64 = 1.0;

/// `rows` rounded down to a multiple of [`BAND_STEP`], within
/// `BAND_STEP..=MAX_BAND`.
fn whole_band(rows: usize) -> usize {
    (rows / BAND_STEP * BAND_STEP).clamp(BAND_STEP, MAX_BAND)
}

/// One band pixel while a group is rasterized: the group's hair sums
/// (colour times alpha times depth weight, alpha times depth weight, and
/// the product of `1 - alpha`, the fraction of the background the hair
/// reveals), and what every fragment there is tested against: the opaque
/// layer's depth, and the length and farthest depth of the group's list
/// of nearest fragments.
///
/// Colour and weight sit in one vector (`xyz` and `w`), so that a fragment
/// adds both in one operation. All of it fits the 32 bytes the vector's
/// alignment gives: a fragment touches one cache line, not one per array.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Acc {
    rgbw: Vec4,
    reveal: f32,
    /// View depth of the opaque layer (infinite where nothing).
    depth: f32,
    /// The depth of the farthest of a full list (infinite until full).
    far: f32,
    /// Fragments in the list.
    len: u8,
}

impl Acc {
    const EMPTY: Acc = Acc {
        rgbw: Vec4::ZERO,
        reveal: 1.0,
        depth: f32::INFINITY,
        far: f32::INFINITY,
        len: 0,
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
    /// Projected hair vertices.
    verts: Vec<Projected>,
    /// Per chunk of strands (binned in parallel) and band of rows, every
    /// segment that touches the band, as its first vertex's index and its
    /// look's index. A band reads the chunks in order: strand order.
    bins: Vec<Vec<Vec<Segment>>>,
    /// Per chunk and band, the pixel columns `[x0, x1)` its segments can
    /// reach there (`x0 >= x1`: none).
    reach: Vec<Vec<[u32; 2]>>,
    /// The group of each chunk in use; a chunk holds strands of one group,
    /// and a group's chunks follow each other.
    chunk_group: Vec<u32>,
    /// Groups drawn since the last clear.
    groups: u32,
    /// The look of each call to [`Canvas::draw_hair`] since the last clear,
    /// with the camera's focal length then.
    looks: Vec<Look>,
    /// Fragments of a pixel composited front to back (the rest blended).
    nearest: usize,
    /// Image rows per band: bands are drawn in parallel, each by one
    /// thread ([`Canvas::band_rows_for`]).
    band: usize,
    /// The rows the opaque layer is drawn in (`None`: all).
    opaque_only: Option<Vec<std::ops::Range<u32>>>,
}

/// A segment binned for drawing: the index in `verts` of its first end
/// (the second follows it) and the index of its look. Eight bytes, where
/// the ends themselves would be sixty: a band reads its segments' ends from
/// the shared vertices, in strand order.
type Segment = (u32, u32);

/// Strands per binning task.
const STRANDS_PER_CHUNK: usize = 256;

/// Segments whose ends a band fetches at once before rasterizing them.
const GATHER: usize = 64;

/// No pixel columns.
const NO_REACH: [u32; 2] = [u32::MAX, 0];

impl Canvas {
    /// An empty canvas of `width x height` pixels (each side in 1..=`MAX_SIDE`).
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
            reach: Vec::new(),
            chunk_group: Vec::new(),
            groups: 0,
            looks: Vec::new(),
            nearest: 0,
            band: BAND_STEP,
            opaque_only: None,
        })
    }

    /// Composites the `k` nearest fragments of each pixel front to back
    /// (at most [`MAX_NEAREST`]), blending only those behind them; 0 (the
    /// default) blends every fragment order-independently.
    pub fn set_nearest(&mut self, k: usize) {
        self.nearest = k.min(MAX_NEAREST);
    }

    /// The fragments of a pixel composited front to back.
    pub fn nearest(&self) -> usize {
        self.nearest
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
        self.clear_hair();
    }

    /// Empties the canvas of hair, keeping its opaque layer (see
    /// [`Self::draw_segments`]).
    pub fn clear_hair(&mut self) {
        self.verts.clear();
        let used = self.chunk_group.len();
        for (chunk, reach) in self.bins[..used].iter_mut().zip(&mut self.reach) {
            chunk.iter_mut().for_each(Vec::clear);
            reach.fill(NO_REACH);
        }
        self.chunk_group.clear();
        self.groups = 0;
        self.looks.clear();
    }

    /// Canvas width, pixels.
    pub fn width(&self) -> u32 {
        self.width as u32
    }

    /// Canvas height, pixels.
    pub fn height(&self) -> u32 {
        self.height as u32
    }

    /// Draws hair: line strips through `points` (strand `s` is
    /// `offsets[s]..offsets[s + 1]`) with per-vertex linear `colors`, looking
    /// as `look` says, in groups of strands: group `g` is strands
    /// `groups[g]..groups[g + 1]` (`groups` ascending from 0 to the strand
    /// count; empty for one group of all). `first_strand` is the index of
    /// the first of these strands in the whole hair, which decides the
    /// strands a [simplified](HairLook::simplify) look draws whatever
    /// share of the hair a canvas draws. The strips are projected and
    /// binned here, and rasterized by [`Self::resolve`] or [`Self::layer`].
    #[allow(clippy::too_many_arguments)]
    pub fn draw_hair(
        &mut self,
        camera: &Camera,
        points: &[Vec3],
        offsets: &[u32],
        colors: &[Vec3],
        look: &HairLook,
        groups: &[u32],
        first_strand: u32,
    ) {
        assert_eq!(points.len(), colors.len());
        let strands = offsets.len().saturating_sub(1);
        let all = [0, strands as u32];
        let groups = if groups.is_empty() { &all[..] } else { groups };
        assert!(
            groups[0] == 0
                && groups[groups.len() - 1] as usize == strands
                && groups.windows(2).all(|g| g[0] <= g[1]),
            "groups cover the strands in order"
        );
        let base = self.verts.len();
        // Project every vertex once.
        self.verts
            .par_extend(points.par_iter().zip(colors).map(|(&p, &color)| {
                let p = camera.project(p).unwrap_or(Vec3::NAN);
                Projected { p, color }
            }));
        let look = Look::new(look, camera);
        self.looks.push(look);
        let look_index = (self.looks.len() - 1) as u32;
        // Chunks of strands, none across a group's end.
        let first_chunk = self.chunk_group.len();
        let mut chunks = Vec::new();
        for g in groups.windows(2) {
            for s in (g[0]..g[1]).step_by(STRANDS_PER_CHUNK) {
                chunks.push(s as usize..(s as usize + STRANDS_PER_CHUNK).min(g[1] as usize));
                self.chunk_group.push(self.groups);
            }
            self.groups += 1;
        }
        // Bin segments to bands of rows: chunks of strands in parallel, each
        // in strand order.
        let band_rows = self.band;
        let bands = self.height.div_ceil(band_rows);
        let end_chunk = self.chunk_group.len();
        if self.bins.len() < end_chunk {
            self.bins.resize_with(end_chunk, || vec![Vec::new(); bands]);
            self.reach.resize_with(end_chunk, || vec![NO_REACH; bands]);
        }
        let verts = &self.verts;
        let (w, h) = (self.width, self.height);
        self.bins[first_chunk..end_chunk]
            .par_iter_mut()
            .zip(&mut self.reach[first_chunk..end_chunk])
            .zip(chunks)
            .for_each(|((bins, reach), strands)| {
                for s in strands {
                    // Segment `i` joins vertices `i` and `i + 1`: each
                    // vertex made a screen vertex once.
                    let mut prev = None;
                    for j in offsets[s] as usize..offsets[s + 1] as usize {
                        let end = look.vertex(verts[base + j]);
                        let (Some(a), Some(b)) = (std::mem::replace(&mut prev, end), end) else {
                            continue;
                        };
                        let i = j - 1;
                        if !look.draws_segment(a.p.z, b.p.z, first_strand + s as u32) {
                            continue;
                        }
                        let Some((bands, cols)) = footprint(a, b, w, h, band_rows) else {
                            continue;
                        };
                        for (bin, r) in bins[bands.clone()].iter_mut().zip(&mut reach[bands]) {
                            bin.push(((base + i) as u32, look_index));
                            *r = [r[0].min(cols[0]), r[1].max(cols[1])];
                        }
                    }
                }
            });
    }

    /// This canvas's hair alone, as exact sums at the pixels it touched
    /// (hidden behind the opaque layer where that is in front), for
    /// [`Self::resolve_layers`] elsewhere.
    pub fn layer(&self) -> HairLayer {
        self.layer_rows(0..self.height as u32)
    }

    /// Band rows are always a multiple of this: rows cut on multiples of
    /// it can be drawn by a canvas whose bands divide the cuts
    /// ([`Self::set_band_rows`]).
    pub const BAND_ROWS: u32 = BAND_STEP as u32;

    /// Rows are rasterized in bands of this many (16 unless
    /// [`Self::set_band_rows`] said otherwise): [`Self::layer_rows`]
    /// takes whole bands.
    pub fn band_rows(&self) -> u32 {
        self.band as u32
    }

    /// Bands of `rows` rows (rounded down to a multiple of 16, from 16 to
    /// 64) for the hair drawn next: call it on a canvas with no hair
    /// drawn since [`Self::clear`]. The bytes drawn do not depend on it;
    /// the time does.
    pub fn set_band_rows(&mut self, rows: u32) {
        assert!(
            self.chunk_group.is_empty(),
            "band rows are set before hair is drawn"
        );
        let rows = whole_band(rows as usize);
        if rows != self.band {
            self.band = rows;
            self.bins.clear();
            self.reach.clear();
        }
    }

    /// The band rows that draw `segments` segments on a `width x height`
    /// canvas fastest, as measured: 16 for hair of under one segment a
    /// pixel, whose lists of nearest fragments then stay in a core's
    /// cache; for denser hair, taller bands, which cut fewer segments in
    /// two (each piece costs its line's set-up and a fetch of its ends),
    /// up to 64 rows and about 64 x 1280 pixels, the picture kept in at
    /// least 8 bands.
    pub fn band_rows_for(width: u32, height: u32, segments: usize) -> u32 {
        let pixels = f64::from(width) * f64::from(height);
        if (segments as f64) < DENSE * pixels {
            return BAND_STEP as u32;
        }
        let rows = (BAND_PIXELS / width.max(1) as usize).min(height as usize / MIN_BANDS);
        whole_band(rows) as u32
    }

    /// [`Self::layer`] of rows `rows` alone: the bands that hold them
    /// (`rows` should start and end on a multiple of [`Self::band_rows`],
    /// or at the last row). A picture's layers of consecutive row ranges,
    /// appended, are its [`Self::layer`], so a layer can be sent a few
    /// bands at a time, each as soon as it is rasterized.
    pub fn layer_rows(&self, rows: std::ops::Range<u32>) -> HairLayer {
        let (w, h, band_rows) = (self.width, self.height, self.band);
        let first = rows.start as usize / band_rows;
        let end = (rows.end as usize).min(h).div_ceil(band_rows).max(first);
        let parts: Vec<HairLayer> = (first..end)
            .into_par_iter()
            .map_init(Scratch::default, |scratch, band| {
                let y0 = band * band_rows;
                let rows = band_rows.min(h - y0);
                self.band_sums(band, rows, scratch, true);
                let mut part = HairLayer::new(w as u32, h as u32);
                for r in 0..rows {
                    let words = &mut scratch.marked[r * scratch.words..(r + 1) * scratch.words];
                    for (k, bits) in words.iter_mut().enumerate() {
                        while *bits != 0 {
                            let x = k * 64 + bits.trailing_zeros() as usize;
                            *bits &= *bits - 1;
                            let s = std::mem::replace(&mut scratch.slot[r * w + x], NO_SLOT);
                            let s = s as usize;
                            let k = scratch.k;
                            let front =
                                &scratch.fronts[s * k..s * k + scratch.front_len[s] as usize];
                            part.push(((y0 + r) * w + x) as u32, scratch.sums[s], front);
                        }
                    }
                }
                part
            })
            .collect();
        let mut layer = HairLayer::new(w as u32, h as u32);
        for p in parts {
            layer.append(p);
        }
        layer
    }

    /// Rasterizes band `band` (its first `rows` rows) of every group into
    /// `scratch`, group by group, each group's float sums folded into the
    /// exact ones when it is done; the last group's too when `fold_last`.
    /// Returns the columns `[x0, x1)` where float sums are left.
    fn band_sums(
        &self,
        band: usize,
        rows: usize,
        scratch: &mut Scratch,
        fold_last: bool,
    ) -> [u32; 2] {
        let (w, y0) = (self.width, band * self.band);
        scratch.ready(rows, w, self.nearest);
        for (cell, &d) in scratch
            .acc
            .iter_mut()
            .zip(&self.depth[y0 * w..(y0 + rows) * w])
        {
            cell.depth = d;
        }
        let mut group = None;
        let mut reach = NO_REACH;
        let mut batch = Vec::with_capacity(GATHER);
        for ((chunk, r), &g) in self.bins.iter().zip(&self.reach).zip(&self.chunk_group) {
            if group != Some(g) {
                scratch.fold(rows, w, reach);
                reach = NO_REACH;
                group = Some(g);
            }
            reach = [reach[0].min(r[band][0]), reach[1].max(r[band][1])];
            // A band's segments are scattered over the projected vertices
            // (hundreds of MB for a full groom): their ends are fetched a
            // batch at a time, in a loop of loads alone, so that the
            // fetches overlap one another instead of each stalling the
            // rasterizing between them.
            for segments in chunk[band].chunks(GATHER) {
                batch.clear();
                batch.extend(segments.iter().filter_map(|&(i, look)| {
                    let i = i as usize;
                    // Binned segments have both ends on screen.
                    let at = &self.looks[look as usize];
                    Some((
                        at.vertex(self.verts[i])?,
                        at.vertex(self.verts[i + 1])?,
                        look,
                    ))
                }));
                for &(a, b, look) in &batch {
                    self.rasterize(a, b, &self.looks[look as usize].look, y0, rows, scratch);
                }
            }
        }
        if fold_last {
            scratch.fold(rows, w, reach);
            return NO_REACH;
        }
        reach
    }

    /// Adds the fragments of the segment from `a` to `b` that fall in rows
    /// `y0..y0 + rows` to that band's float sums, or its nearest fragments.
    fn rasterize(
        &self,
        a: ScreenVertex,
        b: ScreenVertex,
        look: &HairLook,
        y0: usize,
        rows: usize,
        scratch: &mut Scratch,
    ) {
        let w = self.width;
        let opacity = look.opacity.clamp(0.0, 1.0);
        let (wa, wb) = (a.weight, b.weight);
        let clip = [0, w as i32, y0 as i32, (y0 + rows) as i32];
        let band = Band {
            w,
            y0,
            opacity,
            wa,
            wb,
        };
        // One copy of the loop per major axis, with no per-fragment test of
        // which axis is which.
        let k = scratch.k;
        if k == 0 {
            let acc = &mut scratch.acc;
            if is_steep(a, b) {
                line_steps::<true>(a, b, clip, |s| band.add::<true, false>(a, b, s, acc, None));
            } else {
                line_steps::<false>(a, b, clip, |s| band.add::<false, false>(a, b, s, acc, None));
            }
        } else {
            let (acc, near) = (&mut scratch.acc, (&mut scratch.near[..], k));
            let mut near = Some(near);
            if is_steep(a, b) {
                line_steps::<true>(a, b, clip, |s| {
                    band.add::<true, true>(a, b, s, acc, near.as_mut())
                });
            } else {
                line_steps::<false>(a, b, clip, |s| {
                    band.add::<false, true>(a, b, s, acc, near.as_mut())
                });
            }
        }
    }
}

/// The bands of `band_rows` rows (as indices `first..last + 1`) and the
/// pixel columns `[x0, x1)` of a `w x h` picture that the fragments of the
/// segment from `a` to `b` can reach (its ends' box, padded by its width
/// and two pixels), or `None` when they reach no pixel.
#[inline]
fn footprint(
    a: ScreenVertex,
    b: ScreenVertex,
    w: usize,
    h: usize,
    band_rows: usize,
) -> Option<(std::ops::Range<usize>, [u32; 2])> {
    let (wf, hf) = (w as f32, h as f32);
    let pad = a.width.max(b.width) + 2.0;
    let lo = (a.p.y.min(b.p.y) - pad).max(0.0);
    let hi = (a.p.y.max(b.p.y) + pad).min(hf);
    let (left, right) = (a.p.x.min(b.p.x) - pad, a.p.x.max(b.p.x) + pad);
    if lo >= hi || right < 0.0 || left > wf {
        return None;
    }
    // Columns the segment's fragments can fall in.
    let cols = [left.max(0.0) as u32, (right.min(wf) as u32 + 1)];
    let (first, last) = (
        lo as usize / band_rows,
        (hi as usize).min(h - 1) / band_rows,
    );
    Some((first..last + 1, cols))
}

/// A band's nearest fragments while a group is rasterized: the lists (`k`
/// places a pixel; their lengths and farthest depths are in [`Acc`]), and
/// `k`.
type Near<'a> = (&'a mut [Fragment], usize);

/// What every step of one segment in one band shares.
struct Band {
    w: usize,
    y0: usize,
    opacity: f32,
    /// Depth weights at the segment's ends.
    wa: f32,
    wb: f32,
}

impl Band {
    /// Adds the fragments of four steps to `acc`, step by step and in each
    /// step the nearer row first; `STEEP`: y is the major axis. What a
    /// step's two pixels share (depth, colour, weight, alpha) is computed
    /// for the four steps at once, each lane as one step would compute it.
    /// `NEAR`: each fragment goes to the pixel's nearest ones in `near`
    /// (list, lengths, `k`), and what they leave out to `acc`.
    #[inline(always)]
    fn add<const STEEP: bool, const NEAR: bool>(
        &self,
        a: ScreenVertex,
        b: ScreenVertex,
        s: &Steps,
        acc: &mut [Acc],
        mut near: Option<&mut Near<'_>>,
    ) {
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
                let cell = &mut acc[px];
                if z[l] >= cell.depth {
                    continue;
                }
                if NEAR && let Some((list, k)) = near.as_deref_mut() {
                    let k = *k;
                    // Behind a full list's farthest: blended at once, the
                    // list untouched (most fragments of a deep pixel).
                    if z[l] > cell.far {
                        let aw = alpha * wt[l];
                        cell.rgbw += c * aw;
                        cell.reveal *= 1.0 - alpha;
                        continue;
                    }
                    let f = Fragment {
                        z: z[l],
                        color: c.truncate(),
                        alpha,
                        weight: wt[l],
                    };
                    let mine = &mut list[px * k..(px + 1) * k];
                    if let Some(out) = front::insert(mine, &mut cell.len, k, f) {
                        let (rgbw, reveal) = out.blended();
                        cell.rgbw += rgbw;
                        cell.reveal *= reveal;
                    }
                    if cell.len as usize == k {
                        cell.far = mine[k - 1].z;
                    }
                    continue;
                }
                let aw = alpha * wt[l];
                cell.rgbw += c * aw;
                cell.reveal *= 1.0 - alpha;
            }
        }
    }
}

#[cfg(test)]
mod tests;
