//! Deep shadow maps (Lokovic and Veach 2000): per pixel, the visibility
//! function of all fragments, compressed to a piecewise linear function
//! within a tolerance (in transmittance).

use glam::Vec3;
use rayon::prelude::*;

use super::fragments::{Frag, Pixels, lerp, sample};
use crate::input::ShadowInput;
use crate::{FillStats, LightFrame, ShadowError};

/// The deep shadow map method (see the module documentation).
#[derive(Debug)]
pub struct DeepShadowMap {
    resolution: u32,
    tolerance: f32,
    trilinear: bool,
    pixels: Pixels,
    prepared: Option<Visibility>,
}

/// Per pixel a compressed visibility function: its vertices `(z, V)` are
/// `verts[start[pixel]..start[pixel + 1]]`.
#[derive(Debug)]
struct Visibility {
    start: Vec<u32>,
    verts: Vec<(f32, f32)>,
}

/// One row of pixels' compressed visibility: vertex counts, then vertices.
type RowVertices = (Vec<u32>, Vec<(f32, f32)>);

/// Shortest depth span (cells) of a fragment in a visibility function: an
/// opaque body's entry becomes a steep ramp, not a vertical step.
const MIN_SPAN: f32 = 1e-3;

impl DeepShadowMap {
    pub(crate) fn new(resolution: u32, tolerance: f32, trilinear: bool) -> DeepShadowMap {
        DeepShadowMap {
            resolution,
            tolerance,
            trilinear,
            pixels: Pixels::default(),
            prepared: None,
        }
    }

    pub(crate) fn density(&mut self, input: &ShadowInput) -> Result<FillStats, ShadowError> {
        self.prepared = None;
        self.pixels.build(input, self.resolution)
    }

    pub(crate) fn transmittance(&mut self) {
        let n = self.pixels.frame().n_cells as usize;
        let (frags, tolerance) = (&self.pixels.frags, self.tolerance);
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
        let mut start = Vec::with_capacity(self.pixels.count() + 1);
        start.push(0u32);
        let mut verts = Vec::new();
        for (lens, v) in rows {
            for l in lens {
                start.push(start.last().copied().unwrap_or(0) + l);
            }
            verts.extend(v);
        }
        self.prepared = Some(Visibility { start, verts });
    }

    pub(crate) fn transmittance_at(&self, p: Vec3) -> f32 {
        let frame = self.pixels.frame();
        let Visibility { start, verts } = self
            .prepared
            .as_ref()
            .expect("the transmittance stage runs before lookups");
        sample(frame, p, self.trilinear, 1.0, |pix, x| {
            let v = &verts[start[pix] as usize..start[pix + 1] as usize];
            visibility_at(v, x)
        })
        .clamp(0.0, 1.0)
    }

    pub(crate) fn frame(&self) -> Option<&LightFrame> {
        self.pixels.frame.as_ref()
    }
}

/// The exact visibility function `V(z) = exp(-D(z))` of one pixel's
/// fragments, each adding its `beta` uniformly over its depth span: the
/// vertices `(z, V)` where the slope of `D` changes.
pub(super) fn visibility(fs: &[Frag], out: &mut Vec<(f32, f32)>) {
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
pub(super) fn compress(v: &[(f32, f32)], tol: f32, out: &mut Vec<(f32, f32)>) {
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
pub(super) fn visibility_at(v: &[(f32, f32)], x: f32) -> f32 {
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
