//! The fragment rasterizer every peer method shares, and the light-view
//! pixels it fills (see the module documentation of `peers`).

use glam::Vec3;
use rayon::prelude::*;

use crate::input::{OPAQUE_DEPTH, ShadowInput};
use crate::{FillStats, LightFrame, ShadowError};

/// A map of light-view pixels and the fragments of the last build.
#[derive(Debug, Default)]
pub(super) struct Pixels {
    /// The frame of the last build.
    pub(super) frame: Option<LightFrame>,
    pub(super) frags: Fragments,
}

impl Pixels {
    /// Fits a frame of `resolution` pixels a side and rasterizes the hair
    /// and occluders into it.
    pub(super) fn build(
        &mut self,
        input: &ShadowInput,
        resolution: u32,
    ) -> Result<FillStats, ShadowError> {
        let frame = input.fit(resolution)?;
        let (frags, stats) = rasterize(&frame, input);
        self.frame = Some(frame);
        self.frags = frags;
        Ok(stats)
    }

    /// The frame of the last build. Panics before a build.
    pub(super) fn frame(&self) -> &LightFrame {
        self.frame
            .as_ref()
            .expect("the density stage runs before the transmittance stage and lookups")
    }

    /// Pixels of the map.
    pub(super) fn count(&self) -> usize {
        self.frags.start.len().saturating_sub(1)
    }
}

/// A piece of fiber seen from one light-view pixel: it adds optical depth
/// `beta` uniformly over depths `[z, z + len]` (cells along the light).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Frag {
    pub(super) z: f32,
    pub(super) len: f32,
    pub(super) beta: f32,
}

impl Frag {
    pub(super) fn mid(&self) -> f32 {
        self.z + 0.5 * self.len
    }
}

/// Every pixel's fragments, in a fixed order (strand order, then occluders).
#[derive(Debug, Default)]
pub(super) struct Fragments {
    pub(super) start: Vec<u32>,
    pub(super) frags: Vec<Frag>,
}

impl Fragments {
    pub(super) fn of(&self, pixel: usize) -> &[Frag] {
        &self.frags[self.start[pixel] as usize..self.start[pixel + 1] as usize]
    }
}

/// Strand chunks rasterized in parallel: fixed, so the fragment order does
/// not depend on the number of threads.
const CHUNKS: usize = 64;

fn rasterize(frame: &LightFrame, input: &ShadowInput) -> (Fragments, FillStats) {
    let n = frame.n_cells as usize;
    let hair = input.hair;
    let offsets = hair.offsets();
    let points = hair.points();
    // beta per cell of piece length across the light (for a fan, per
    // unit of a piece's weight, see `density::for_each_fan_piece`).
    let k_beta = input.fiber.cross_section() / frame.fan.map_or(frame.ds, |f| f.du);
    let strands = hair.strand_count();
    let per_chunk = strands.div_ceil(CHUNKS).max(1);
    let lists: Vec<(Vec<(u32, Frag)>, FillStats)> = (0..strands.div_ceil(per_chunk))
        .into_par_iter()
        .map(|c| {
            let mut out = Vec::new();
            let mut stats = FillStats::default();
            if k_beta == 0.0 {
                return (out, stats);
            }
            for s in c * per_chunk..((c + 1) * per_chunk).min(strands) {
                let pts = &points[offsets[s] as usize..offsets[s + 1] as usize];
                stats = stats + strand_fragments(frame, pts, k_beta, &mut out);
            }
            (out, stats)
        })
        .collect();
    // Occluders: one opaque fragment where each pixel's centre line enters.
    let mut opaque = Vec::new();
    for o in input.occluders {
        opaque.extend(o.entries(frame).into_iter().map(|(col, entry)| {
            (
                col,
                Frag {
                    z: entry,
                    len: 0.0,
                    beta: OPAQUE_DEPTH,
                },
            )
        }));
    }
    // Counting sort by pixel, stable: the order within a pixel is fixed.
    let mut start = vec![0u32; n * n + 1];
    let all = || {
        lists
            .iter()
            .flat_map(|(l, _)| l.iter())
            .chain(opaque.iter())
    };
    for (p, _) in all() {
        start[*p as usize + 1] += 1;
    }
    for i in 0..n * n {
        start[i + 1] += start[i];
    }
    let mut fill = start.clone();
    let mut frags = vec![
        Frag {
            z: 0.0,
            len: 0.0,
            beta: 0.0
        };
        start[n * n] as usize
    ];
    for &(p, f) in all() {
        let at = &mut fill[p as usize];
        frags[*at as usize] = f;
        *at += 1;
    }
    let stats = lists.iter().map(|(_, s)| *s).sum();
    (Fragments { start, frags }, stats)
}

fn strand_fragments(
    frame: &LightFrame,
    pts: &[Vec3],
    k_beta: f32,
    out: &mut Vec<(u32, Frag)>,
) -> FillStats {
    let mut stats = FillStats::default();
    let n = frame.n_cells as i32;
    let nf = n as f32;
    if frame.fan.is_some() {
        let mut behind = 0u64;
        crate::density::for_each_fan_piece(
            frame,
            pts,
            |mid, step, weight| {
                if !(mid.cmpge(Vec3::ZERO).all() && mid.cmplt(Vec3::splat(nf)).all()) {
                    stats.out_of_map += 1;
                    return;
                }
                stats.samples += 1;
                let beta = k_beta * weight;
                // As for parallel rays: a piece along its ray adds nothing.
                if beta.is_nan() || beta <= 0.0 {
                    return;
                }
                let frag = |w: f32| Frag {
                    z: mid.x - 0.5 * step.x.abs(),
                    len: step.x.abs(),
                    beta: beta * w,
                };
                splat_fragment(mid, n, frag, out);
            },
            |m| behind += u64::from(m),
        );
        stats.out_of_map += behind;
        return stats;
    }
    crate::density::for_each_segment(frame, pts, |prev, d, across, m| {
        let step = d / m as f32;
        let beta = k_beta * across / m as f32;
        if beta > 0.0 {
            for t in 0..m {
                let mid = prev + (t as f32 + 0.5) * step;
                if !(mid.cmpge(Vec3::ZERO).all() && mid.cmplt(Vec3::splat(nf)).all()) {
                    stats.out_of_map += 1;
                    continue;
                }
                stats.samples += 1;
                let frag = |w: f32| Frag {
                    z: mid.x - 0.5 * step.x.abs(),
                    len: step.x.abs(),
                    beta: beta * w,
                };
                splat_fragment(mid, n, frag, out);
            }
        }
    });
    stats
}

/// A fragment `frag(w)` into each of the four pixels around `mid` with
/// bilinear weight `w` (those in the map).
fn splat_fragment(mid: Vec3, n: i32, frag: impl Fn(f32) -> Frag, out: &mut Vec<(u32, Frag)>) {
    let (fy, fz) = (mid.y - 0.5, mid.z - 0.5);
    let (j0, k0) = ((fy + 1.0) as i32 - 1, (fz + 1.0) as i32 - 1);
    let (ty, tz) = (fy - j0 as f32, fz - k0 as f32);
    for (dj, dk, w) in [
        (0, 0, (1.0 - ty) * (1.0 - tz)),
        (1, 0, ty * (1.0 - tz)),
        (0, 1, (1.0 - ty) * tz),
        (1, 1, ty * tz),
    ] {
        let (j, k) = (j0 + dj, k0 + dk);
        if w > 0.0 && (0..n).contains(&j) && (0..n).contains(&k) {
            out.push(((k * n + j) as u32, frag(w)));
        }
    }
}

/// Blends `f(pixel, x)` over the four pixels around `p` (bilinear, between
/// pixel centres) or takes `p`'s own pixel; pixels outside the map give
/// `empty`. `x` is `p`'s depth along the light, in cells.
#[inline]
pub(super) fn sample(
    frame: &LightFrame,
    p: Vec3,
    trilinear: bool,
    empty: f32,
    f: impl Fn(usize, f32) -> f32,
) -> f32 {
    let n = frame.n_cells as i32;
    let c = frame.to_cells(p);
    let c = c.clamp(Vec3::splat(-2.0), Vec3::splat(n as f32 + 2.0)) + 2.0;
    let x = c.x - 2.0;
    let at = |j: i32, k: i32| {
        if j < 0 || k < 0 || j >= n || k >= n {
            empty
        } else {
            f((k * n + j) as usize, x)
        }
    };
    if trilinear {
        let (fy, fz) = (c.y - 0.5, c.z - 0.5);
        let (j, k) = (fy as i32, fz as i32);
        let (ty, tz) = (fy - j as f32, fz - k as f32);
        let (j, k) = (j - 2, k - 2);
        let (sy, sz) = (1.0 - ty, 1.0 - tz);
        sz * (sy * at(j, k) + ty * at(j + 1, k)) + tz * (sy * at(j, k + 1) + ty * at(j + 1, k + 1))
    } else {
        at(c.y as i32 - 2, c.z as i32 - 2)
    }
}

/// `ceil(u)` for finite `u >= 0` (negative `u` gives 0), by truncating
/// casts: `ceil` is a libm call on baseline x86-64.
#[inline]
pub(super) fn ceil_index(u: f32) -> usize {
    let whole = u as usize;
    whole + usize::from((whole as f32) < u)
}

/// Turns per-slice (or per-layer) values into running sums, front to back.
pub(super) fn accumulate(o: &mut [f32]) {
    let mut acc = 0.0;
    for v in o.iter_mut() {
        acc += *v;
        *v = acc;
    }
}

/// `a + t (b - a)` for `t` in [0, 1]: between `a` and `b` whatever the rounding.
#[inline]
pub(super) fn lerp(a: f32, b: f32, t: f32) -> f32 {
    (a + t * (b - a)).clamp(a.min(b), a.max(b))
}
