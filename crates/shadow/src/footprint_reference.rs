//! The footprint reference: transmittance from the fiber geometry itself,
//! averaged over a square footprint across the light (a volume estimate
//! without a grid; the exact, per-fiber reference is [`crate::Reference`]).
//!
//! Definition. Every drawn segment is a fiber of width `w` and opacity
//! `alpha`. Light reaching `p` crosses a square footprint of side `a`
//! centred on `p` across the light. A fiber that passes through the
//! footprint more than one fiber width in front of `p` along the light (so
//! that a point on a fiber is not shadowed by that fiber itself) covers the
//! fraction `c_i = w * l_i / a^2` of it, `l_i` the length of its shadow
//! inside the square, and lets through `1 - alpha c_i` of the light. An
//! occluder lets through the fraction `1 - c_o` of the footprint it does not
//! cover (sampled by `R` stratified rays):
//!
//! ```text
//! T(p) = prod_i (1 - alpha min(c_i, 1)) * prod_o (1 - c_o)
//! ```
//!
//! The segments of one strand inside the footprint are one fiber (so a
//! strand's zero-length segments and repeated points change nothing). No density, no grid of values, no interpolation: for fibers much
//! thinner than the footprint, `-ln T` is `alpha` times the number of
//! fibers a ray crosses, and a slab of parallel fibers gives Beer-Lambert,
//! `exp(-n w alpha sin(theta) x)`.
//!
//! Acceleration: segments are binned by the light-view columns of a 128^3
//! map fitted to the hair that their capsule's shadow overlaps
//! ([`crate::bins`]); each lookup tests the segments of the columns its
//! footprint overlaps.

use glam::Vec3;

use crate::bins::{GRID, SegmentBins};
use crate::input::ShadowInput;
use crate::occluder::OccluderView;
use crate::{FillStats, LightFrame, ShadowError};

/// The reference method (see the module documentation).
#[derive(Debug)]
pub struct FootprintReference {
    footprint: Option<f32>,
    rays: u32,
    built: Option<Built>,
}

#[derive(Debug)]
struct Built {
    bins: SegmentBins,
    /// Fiber width, scene units.
    width: f32,
    transmit: f32,
    /// Footprint side, in cells.
    side: f32,
    /// Sample offsets across the light for occluders, in cells.
    offsets: Vec<(f32, f32)>,
    /// The opaque bodies, if any, prepared for queries along the light.
    occluders: Option<OccluderView>,
}

impl FootprintReference {
    pub(crate) fn new(footprint: Option<f32>, rays: u32) -> FootprintReference {
        FootprintReference {
            footprint,
            rays: rays.max(1),
            built: None,
        }
    }

    pub(crate) fn density(&mut self, input: &ShadowInput) -> Result<FillStats, ShadowError> {
        let bins = SegmentBins::new(input, GRID)?;
        let frame = bins.frame;
        let stats = bins.stats;
        let a = self.footprint.map_or(1.0, |f| f / frame.ds);
        let g = (self.rays as f32).sqrt().ceil() as u32;
        let offsets = (0..self.rays)
            .map(|r| {
                let (u, v) = (r % g, r / g);
                (
                    a * ((u as f32 + 0.5) / g as f32 - 0.5),
                    a * ((v as f32 + 0.5) / g as f32 - 0.5),
                )
            })
            .collect();
        self.built = Some(Built {
            bins,
            width: input.fiber.width(),
            side: a,
            transmit: 1.0 - input.fiber.opacity(),
            offsets,
            occluders: (!input.occluders.is_empty())
                .then(|| OccluderView::new(frame, input.occluders)),
        });
        Ok(stats)
    }

    pub(crate) fn transmittance(&mut self) {
        assert!(self.built.is_some(), "build runs before prepare");
    }

    pub(crate) fn transmittance_at(&self, p: Vec3) -> f32 {
        let built = self.built.as_ref().expect("build runs before lookups");
        let b = &built.bins;
        let n = GRID as i32;
        let c = b.frame.to_cells(p);
        // More than one fiber width in front of p.
        let before = c.x - 2.0 * b.radius;
        let h = 0.5 * built.side;
        let (y0, y1, z0, z1) = (c.y - h, c.y + h, c.z - h, c.z + h);
        let mut t = 1.0f64;
        if y1 >= 0.0 && z1 >= 0.0 && y0 < n as f32 && z0 < n as f32 {
            let cols = |lo: f32, hi: f32| (lo.max(0.0) as i32)..=(hi.max(0.0) as i32).min(n - 1);
            // One candidate buffer per thread, not one allocation per lookup.
            thread_local! {
                static CANDIDATES: std::cell::RefCell<Vec<u32>> = const {
                    std::cell::RefCell::new(Vec::new())
                };
            }
            CANDIDATES.with_borrow_mut(|cand| {
                cand.clear();
                for k in cols(z0, z1) {
                    for j in cols(y0, y1) {
                        cand.extend_from_slice(b.column(j, k));
                    }
                }
                cand.sort_unstable();
                cand.dedup();
                // Coverage of the footprint by one fiber: its shadow strip, w
                // wide, over the length of its projection inside the square.
                let side = built.side;
                let per_length = 2.0 * b.radius / (side * side);
                let alpha = f64::from(1.0 - built.transmit);
                let (mut cover, mut last) = (0.0f64, u32::MAX);
                for &s in cand.iter() {
                    let (a, e) = (b.cells[s as usize], b.cells[s as usize + 1]);
                    let Some((t0, t1)) = clip(a, e, [y0, y1, z0, z1], before) else {
                        continue;
                    };
                    // The area of the fiber's shadow inside the square, in
                    // cells: its width times its length across the rays
                    // (for a fan, w sqrt(Q) / (x du), see the density map).
                    let d = e - a;
                    let area = match &b.frame.fan {
                        None => per_length * ((t1 - t0) * (d.y * d.y + d.z * d.z).sqrt()),
                        Some(f) => {
                            let mid = a + d * (0.5 * (t0 + t1));
                            let x = f.start.x + mid.x * b.frame.ds;
                            let (u, v) = (f.start.y + mid.y * f.du, f.start.z + mid.z * f.du);
                            let q = 1.0 + u * u + v * v;
                            let cross = u * d.y + v * d.z;
                            let across = (q * (d.y * d.y + d.z * d.z) - cross * cross).max(0.0);
                            built.width * across.sqrt() * (t1 - t0)
                                / (x.max(1e-30) * f.du * side * side)
                        }
                    };
                    if area.is_nan() || area <= 0.0 {
                        continue;
                    }
                    // The segments of one strand are one fiber (candidates
                    // are in ascending order, so a strand's come together).
                    let strand = b.strand[s as usize];
                    if strand != last && cover > 0.0 {
                        t *= 1.0 - alpha * cover.min(1.0);
                        cover = 0.0;
                    }
                    cover += f64::from(area);
                    last = strand;
                }
                t *= 1.0 - alpha * cover.min(1.0);
            });
        }
        if let Some(view) = &built.occluders {
            let blocked = built
                .offsets
                .iter()
                .filter(|&&(oy, oz)| {
                    let q = b.frame.to_world(Vec3::new(c.x, c.y + oy, c.z + oz));
                    view.blocks(q)
                })
                .count();
            t *= 1.0 - blocked as f64 / built.offsets.len() as f64;
        }
        t.clamp(0.0, 1.0) as f32
    }

    pub(crate) fn frame(&self) -> Option<&LightFrame> {
        self.built.as_ref().map(|b| &b.bins.frame)
    }
}

/// The part `t0..t1` of segment `a e` (`a + t (e - a)`) inside the square
/// `y0..y1 x z0..z1` and in front of depth `before` (Liang-Barsky
/// clipping), if any.
fn clip(a: Vec3, e: Vec3, [y0, y1, z0, z1]: [f32; 4], before: f32) -> Option<(f32, f32)> {
    let d = e - a;
    let (mut t0, mut t1) = (0.0f32, 1.0f32);
    for (p, q) in [
        (-d.y, a.y - y0),
        (d.y, y1 - a.y),
        (-d.z, a.z - z0),
        (d.z, z1 - a.z),
        (d.x, before - a.x),
    ] {
        if p == 0.0 {
            if q < 0.0 {
                return None;
            }
        } else {
            let r = q / p;
            if p < 0.0 {
                t0 = t0.max(r);
            } else {
                t1 = t1.min(r);
            }
        }
    }
    (t1 > t0).then_some((t0, t1))
}
