//! The peer methods: shadow maps over light-view pixels.
//!
//! All four rasterize the hair the same way the density map fills it (so
//! that they estimate the same quantity): each segment is cut into pieces no
//! longer than a pixel along any axis, and each piece becomes a fragment of
//! optical depth
//!
//! ```text
//! beta = alpha * w * |piece x L| / ds^2
//! ```
//!
//! (its projected area times its opacity, over the pixel's area), spread
//! over the four nearest pixels with bilinear weights. The fragment keeps
//! the depth span `[z, z + len]` (in cells along the light) the piece covers.
//! What each method keeps of a pixel's fragments differs:
//!
//! - opacity shadow maps: accumulated opacity at uniform slice planes;
//! - deep opacity maps: accumulated opacity at layers that start at the
//!   pixel's first fragment;
//! - density clustering: a histogram bin per k-means cluster of depths;
//! - deep shadow maps: the whole visibility function, compressed.
//!
//! Lookups blend the four pixels around a point with bilinear weights
//! (non-negative: a blend of non-increasing functions never increases), or
//! take the nearest pixel with filtering off.

use glam::Vec3;
use rayon::prelude::*;

use crate::method::{Beyond, MethodConfig, OPAQUE_DEPTH, OpacityMode, ShadowInput, ShadowMethod};
use crate::{FillStats, LightFrame, ShadowError};

/// A piece of fiber seen from one light-view pixel: it adds optical depth
/// `beta` uniformly over depths `[z, z + len]` (cells along the light).
#[derive(Debug, Clone, Copy, PartialEq)]
struct Frag {
    z: f32,
    len: f32,
    beta: f32,
}

impl Frag {
    fn mid(&self) -> f32 {
        self.z + 0.5 * self.len
    }
}

/// Every pixel's fragments, in a fixed order (strand order, then occluders).
#[derive(Debug, Default)]
struct Fragments {
    start: Vec<u32>,
    frags: Vec<Frag>,
}

impl Fragments {
    fn of(&self, pixel: usize) -> &[Frag] {
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
fn sample(
    frame: &LightFrame,
    p: Vec3,
    filter: bool,
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
    if filter {
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
fn ceil_index(u: f32) -> usize {
    let whole = u as usize;
    whole + usize::from((whole as f32) < u)
}

/// Turns per-slice (or per-layer) values into running sums, front to back.
fn accumulate(o: &mut [f32]) {
    let mut acc = 0.0;
    for v in o.iter_mut() {
        acc += *v;
        *v = acc;
    }
}

/// `a + t (b - a)` for `t` in [0, 1]: between `a` and `b` whatever the rounding.
#[inline]
fn lerp(a: f32, b: f32, t: f32) -> f32 {
    (a + t * (b - a)).clamp(a.min(b), a.max(b))
}

/// One row of pixels' compressed visibility: vertex counts, then vertices.
type RowVertices = (Vec<u32>, Vec<(f32, f32)>);

/// What a method keeps of each pixel's fragments after `prepare`.
#[derive(Debug)]
enum Prepared {
    None,
    /// Accumulated optical depth at `slices` planes `d0 + s delta`.
    Slices {
        d0: f32,
        delta: f32,
        slices: usize,
        omega: Vec<f32>,
    },
    /// Per pixel: first hair `z0`, layer thickness, `layers` accumulated
    /// optical depths at `z0 + (l + 1) delta`.
    Layers {
        z0: Vec<f32>,
        delta: Vec<f32>,
        layers: usize,
        omega: Vec<f32>,
    },
    /// Per pixel `k` bins `[lo, hi]` each adding optical depth `b`.
    Bins {
        k: usize,
        bins: Vec<Bin>,
    },
    /// Per pixel a compressed visibility function: vertices `(z, V)`.
    Visibility {
        start: Vec<u32>,
        verts: Vec<(f32, f32)>,
    },
}

#[derive(Debug, Clone, Copy, PartialEq)]
struct Bin {
    lo: f32,
    hi: f32,
    b: f32,
}

impl Bin {
    const EMPTY: Bin = Bin {
        lo: f32::INFINITY,
        hi: f32::INFINITY,
        b: 0.0,
    };

    /// The bin's optical depth in front of depth `x`: uniform inside it; a
    /// bin of zero width is a step (all of it lies in front of `x > lo`).
    #[inline]
    fn depth(&self, x: f32) -> f32 {
        if x <= self.lo {
            0.0
        } else if x >= self.hi {
            self.b
        } else {
            self.b * ((x - self.lo) / (self.hi - self.lo)).clamp(0.0, 1.0)
        }
    }
}

/// One of the four peer methods.
#[derive(Debug)]
pub(crate) struct PixelMethod {
    config: MethodConfig,
    frame: Option<LightFrame>,
    frags: Fragments,
    prepared: Prepared,
}

impl PixelMethod {
    pub(crate) fn new(config: MethodConfig) -> PixelMethod {
        PixelMethod {
            config,
            frame: None,
            frags: Fragments::default(),
            prepared: Prepared::None,
        }
    }

    fn pixels(&self) -> usize {
        self.frags.start.len().saturating_sub(1)
    }
}

/// Shortest depth span (cells) of a fragment in a visibility function: an
/// opaque body's entry becomes a steep ramp, not a vertical step.
const MIN_SPAN: f32 = 1e-3;

impl ShadowMethod for PixelMethod {
    fn build(&mut self, input: &ShadowInput) -> Result<FillStats, ShadowError> {
        let frame = input.fit(self.config.resolution())?;
        let (frags, stats) = rasterize(&frame, input);
        self.frame = Some(frame);
        self.frags = frags;
        self.prepared = Prepared::None;
        Ok(stats)
    }

    fn prepare(&mut self) {
        assert!(self.frame.is_some(), "build runs before prepare");
        let pixels = self.pixels();
        let frags = &self.frags;
        self.prepared = match self.config {
            MethodConfig::OpacityShadowMap { slices, .. } => {
                let slices = slices as usize;
                // The hair's depth range (Koster et al.: the bounding box).
                let (lo, hi) = frags
                    .frags
                    .iter()
                    .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), f| {
                        (lo.min(f.z), hi.max(f.z + f.len))
                    });
                let (d0, delta) = if lo.is_finite() {
                    (lo, ((hi - lo) / (slices - 1) as f32).max(1e-6))
                } else {
                    (0.0, 1.0)
                };
                let mut omega = vec![0.0f32; pixels * slices];
                omega
                    .par_chunks_mut(slices)
                    .enumerate()
                    .for_each(|(pix, o)| {
                        // A fragment between planes s - 1 and s counts from plane s on.
                        for f in frags.of(pix) {
                            let u = ((f.mid() - d0) / delta).max(0.0);
                            let s = ceil_index(u).min(slices - 1);
                            o[s] += f.beta;
                        }
                        accumulate(o);
                    });
                Prepared::Slices {
                    d0,
                    delta,
                    slices,
                    omega,
                }
            }
            MethodConfig::DeepOpacityMap {
                layers,
                layer_cells,
                beyond,
                ..
            } => {
                let layers = layers as usize;
                let mut z0 = vec![f32::INFINITY; pixels];
                let mut delta = vec![layer_cells; pixels];
                let mut omega = vec![0.0f32; pixels * layers];
                omega
                    .par_chunks_mut(layers)
                    .zip(z0.par_iter_mut().zip(delta.par_iter_mut()))
                    .enumerate()
                    .for_each(|(pix, (o, (z0, delta)))| {
                        let fs = frags.of(pix);
                        // The depth map: where the pixel's hair begins.
                        *z0 = fs.iter().map(|f| f.z).fold(f32::INFINITY, f32::min);
                        if beyond == Beyond::Cover {
                            let far = fs.iter().map(Frag::mid).fold(*z0, f32::max);
                            *delta = (far - *z0) / layers as f32;
                        }
                        for f in fs {
                            let u = (f.mid() - *z0) / *delta;
                            // Layer l (0-based) spans (z0 + l delta, z0 + (l + 1) delta].
                            let l = if u.is_finite() {
                                ceil_index(u).max(1) - 1
                            } else if f.mid() <= *z0 {
                                0
                            } else {
                                usize::MAX
                            };
                            let l = if l < layers {
                                l
                            } else if beyond == Beyond::Ignore {
                                continue;
                            } else {
                                layers - 1
                            };
                            o[l] += f.beta;
                        }
                        accumulate(o);
                    });
                Prepared::Layers {
                    z0,
                    delta,
                    layers,
                    omega,
                }
            }
            MethodConfig::DensityClustering { clusters, .. } => {
                let k = clusters as usize;
                let mut bins = vec![Bin::EMPTY; pixels * k];
                bins.par_chunks_mut(k)
                    .enumerate()
                    .for_each(|(pix, out)| cluster_bins(frags.of(pix), out));
                Prepared::Bins { k, bins }
            }
            MethodConfig::DeepShadowMap { tolerance, .. } => {
                let n = self.frame.map_or(0, |f| f.n_cells as usize);
                let rows: Vec<RowVertices> = (0..n)
                    .into_par_iter()
                    .map(|row| {
                        let mut lens = Vec::with_capacity(n);
                        let mut verts = Vec::new();
                        let mut exact = Vec::new();
                        for pix in row * n..(row + 1) * n {
                            let before = verts.len();
                            visibility(frags.of(pix), &mut exact);
                            compress(&exact, tolerance, &mut verts);
                            lens.push((verts.len() - before) as u32);
                        }
                        (lens, verts)
                    })
                    .collect();
                let mut start = Vec::with_capacity(pixels + 1);
                start.push(0u32);
                let mut verts = Vec::new();
                for (lens, v) in rows {
                    for l in lens {
                        start.push(start.last().copied().unwrap_or(0) + l);
                    }
                    verts.extend(v);
                }
                Prepared::Visibility { start, verts }
            }
            MethodConfig::DensityMap { .. } | MethodConfig::Reference { .. } => Prepared::None,
        };
    }

    fn transmittance(&self, p: Vec3) -> f32 {
        let frame = self.frame.as_ref().expect("build runs before lookups");
        let filter = self.config.filter();
        match &self.prepared {
            Prepared::None => panic!("prepare runs before lookups"),
            Prepared::Slices {
                d0,
                delta,
                slices,
                omega,
            } => {
                let offset = match self.config {
                    MethodConfig::OpacityShadowMap { offset, .. } => offset,
                    _ => 0.0,
                };
                let om = sample(frame, p, filter, 0.0, |pix, x| {
                    let o = &omega[pix * slices..(pix + 1) * slices];
                    let u = (x - offset * delta - d0) / delta;
                    if u <= 0.0 {
                        // At or in front of the first plane: no hair lies
                        // between the point and the light (plane 0 holds
                        // hair at exactly `d0`, as in a sheet across it).
                        return 0.0;
                    }
                    if u >= (slices - 1) as f32 {
                        return o[slices - 1];
                    }
                    let s = u as usize;
                    lerp(o[s], o[s + 1], u - s as f32)
                });
                match self.config {
                    MethodConfig::OpacityShadowMap {
                        mode: OpacityMode::Linear,
                        ..
                    } => (1.0 - om).clamp(0.0, 1.0),
                    MethodConfig::OpacityShadowMap {
                        mode: OpacityMode::Exponential { kappa },
                        ..
                    } => (-kappa * om).exp(),
                    _ => (-om).exp(),
                }
            }
            Prepared::Layers {
                z0,
                delta,
                layers,
                omega,
            } => {
                let d = sample(frame, p, filter, 0.0, |pix, x| {
                    let z = z0[pix];
                    if x <= z {
                        return 0.0;
                    }
                    let o = &omega[pix * layers..(pix + 1) * layers];
                    let u = (x - z) / delta[pix];
                    if u.is_nan() || u >= *layers as f32 {
                        return o[layers - 1];
                    }
                    let l = u as usize;
                    let before = if l == 0 { 0.0 } else { o[l - 1] };
                    lerp(before, o[l], u - l as f32)
                });
                (-d).exp()
            }
            Prepared::Bins { k, bins } => {
                let d = sample(frame, p, filter, 0.0, |pix, x| {
                    bins[pix * k..(pix + 1) * k]
                        .iter()
                        .map(|b| b.depth(x))
                        .sum()
                });
                (-d).exp()
            }
            Prepared::Visibility { start, verts } => sample(frame, p, filter, 1.0, |pix, x| {
                let v = &verts[start[pix] as usize..start[pix + 1] as usize];
                visibility_at(v, x)
            })
            .clamp(0.0, 1.0),
        }
    }

    fn frame(&self) -> Option<&LightFrame> {
        self.frame.as_ref()
    }
}

/// Density clustering of one pixel (Mertens et al. 2004, section 3):
/// `out.len()` initial centres spread uniformly from the nearest to the
/// farthest fragment, one k-means iteration with `beta`-weighted means,
/// `beta`-weighted standard deviations about the means, bins
/// `mu +- sqrt(3) sigma` (a uniform density of width `W` has
/// `sigma^2 = W^2 / 12`), overlaps cut at their midpoint, and every
/// fragment's `beta` in the bin that holds its depth or else in the nearest
/// cluster's.
fn cluster_bins(fs: &[Frag], out: &mut [Bin]) {
    const GAMMA: f32 = 1.732_050_8; // sqrt(3)
    out.fill(Bin::EMPTY);
    if fs.is_empty() {
        return;
    }
    let k = out.len();
    // The nearest and farthest fragment centres, and where the pixel's
    // hair begins and ends.
    let (near, far, first, last) = fs.iter().fold(
        (
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::INFINITY,
            f32::NEG_INFINITY,
        ),
        |(a, b, c, d), f| {
            (
                a.min(f.mid()),
                b.max(f.mid()),
                c.min(f.z),
                d.max(f.z + f.len),
            )
        },
    );
    let nearest = |centres: &[f32], m: f32| {
        let mut best = 0;
        for (i, &c) in centres.iter().enumerate() {
            if (m - c).abs() < (m - centres[best]).abs() {
                best = i;
            }
        }
        best
    };
    let init: Vec<f32> = (0..k)
        .map(|i| {
            if k == 1 {
                0.5 * (near + far)
            } else {
                near + (far - near) * i as f32 / (k - 1) as f32
            }
        })
        .collect();
    // One iteration: weighted means of the fragments nearest each centre.
    let mut w = vec![0.0f64; k];
    let mut wm = vec![0.0f64; k];
    for f in fs {
        let c = nearest(&init, f.mid());
        w[c] += f64::from(f.beta);
        wm[c] += f64::from(f.beta) * f64::from(f.mid());
    }
    let mut mu: Vec<f32> = (0..k)
        .filter(|&c| w[c] > 0.0)
        .map(|c| ((wm[c] / w[c]) as f32).clamp(near, far))
        .collect();
    mu.sort_by(f32::total_cmp);
    // Weighted spread about each mean.
    let m = mu.len();
    let mut w = vec![0.0f64; m];
    let mut wv = vec![0.0f64; m];
    for f in fs {
        let c = nearest(&mu, f.mid());
        let d = f64::from(f.mid() - mu[c]);
        w[c] += f64::from(f.beta);
        wv[c] += f64::from(f.beta) * d * d;
    }
    // A bin never reaches past the pixel's hair (`first..last`): a cluster
    // with a wide spread would otherwise start in front of the nearest
    // fragment and shadow points that have no hair between them and the
    // light.
    let mut bins: Vec<Bin> = (0..m)
        .map(|c| {
            let sigma = if w[c] > 0.0 {
                (wv[c] / w[c]).sqrt() as f32
            } else {
                0.0
            };
            let lo = (mu[c] - GAMMA * sigma).max(first);
            Bin {
                lo,
                hi: (mu[c] + GAMMA * sigma).min(last).max(lo),
                b: 0.0,
            }
        })
        .collect();
    // Overlapping neighbours meet at the midpoint of the overlap.
    for c in 1..m {
        let (l, r) = bins.split_at_mut(c);
        let (a, b) = (&mut l[c - 1], &mut r[0]);
        if a.hi > b.lo {
            let mid = (0.5 * (a.hi + b.lo)).clamp(a.lo, b.hi.max(a.lo));
            a.hi = mid;
            b.lo = mid;
            b.hi = b.hi.max(mid);
        }
    }
    for f in fs {
        let x = f.mid();
        let c = bins
            .iter()
            .position(|b| b.lo <= x && x <= b.hi)
            .unwrap_or_else(|| nearest(&mu, x));
        bins[c].b += f.beta;
    }
    out[..m].copy_from_slice(&bins);
}

/// The exact visibility function `V(z) = exp(-D(z))` of one pixel's
/// fragments, each adding its `beta` uniformly over its depth span: the
/// vertices `(z, V)` where the slope of `D` changes.
fn visibility(fs: &[Frag], out: &mut Vec<(f32, f32)>) {
    out.clear();
    if fs.is_empty() {
        return;
    }
    let mut events: Vec<(f32, f64)> = Vec::with_capacity(2 * fs.len());
    for f in fs {
        let len = f.len.max(MIN_SPAN);
        let slope = f64::from(f.beta) / f64::from(len);
        events.push((f.z, slope));
        events.push((f.z + len, -slope));
    }
    // Stable sort: equal depths keep their (fixed) order.
    events.sort_by(|a, b| a.0.total_cmp(&b.0));
    let (mut z, mut d, mut slope) = (events[0].0, 0.0f64, 0.0f64);
    out.push((z, 1.0));
    for (x, ds) in events {
        if x > z {
            d += (slope * f64::from(x - z)).max(0.0);
            z = x;
            out.push((z, (-d).exp() as f32));
        }
        slope += ds;
    }
}

/// Lokovic and Veach's compression: from each output vertex, the longest
/// segment that stays within `tol` of every original vertex it spans, with
/// the middle of the feasible slopes. Slopes are kept <= 0, so the result
/// never rises.
fn compress(v: &[(f32, f32)], tol: f32, out: &mut Vec<(f32, f32)>) {
    let Some(&first) = v.first() else {
        return;
    };
    let mut o = first;
    out.push(o);
    let (mut lo, mut hi) = (f32::NEG_INFINITY, 0.0f32);
    let mut last = o;
    let mut i = 1;
    while i < v.len() {
        let p = v[i];
        let dz = p.0 - o.0;
        if dz <= 0.0 {
            i += 1;
            continue;
        }
        let nlo = lo.max((p.1 - tol - o.1) / dz);
        let nhi = hi.min((p.1 + tol - o.1) / dz);
        if nlo <= nhi {
            (lo, hi, last) = (nlo, nhi, p);
            i += 1;
        } else if last == o {
            // Nothing fits yet (rounding): take the vertex as it is.
            o = (p.0, p.1.min(o.1));
            out.push(o);
            (lo, hi, last) = (f32::NEG_INFINITY, 0.0, o);
            i += 1;
        } else {
            let s = 0.5 * (lo + hi);
            o = (last.0, (o.1 + s * (last.0 - o.0)).clamp(0.0, o.1));
            out.push(o);
            (lo, hi, last) = (f32::NEG_INFINITY, 0.0, o);
        }
    }
    if last != o {
        let s = if lo.is_finite() { 0.5 * (lo + hi) } else { hi };
        out.push((last.0, (o.1 + s * (last.0 - o.0)).clamp(0.0, o.1)));
    }
}

/// A compressed visibility function at depth `x`: 1 before its first
/// vertex, its last value after the last, linear in between.
fn visibility_at(v: &[(f32, f32)], x: f32) -> f32 {
    match v {
        [] => 1.0,
        [first, ..] if x <= first.0 => 1.0,
        [.., last] if x >= last.0 => last.1,
        _ => {
            let i = v.partition_point(|&(z, _)| z <= x);
            let (a, b) = (v[i - 1], v[i]);
            lerp(a.1, b.1, (x - a.0) / (b.0 - a.0))
        }
    }
}

#[cfg(test)]
mod tests;
