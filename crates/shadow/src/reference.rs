//! The exact reference: the light a fiber receives, from the rays that
//! leave it for the light, each tested against the other fibers.
//!
//! Definition. Every drawn segment is a capsule of radius `w / 2` (the
//! fiber's width `w`) and opacity `alpha`. A drawn point `p` on a fiber
//! with unit tangent `t` sends `K` rays to the light from
//!
//! ```text
//! o_k = p + w ((k + 1/2) / K - 1/2) b,    b = unit(l x t),  k = 0..K
//! ```
//!
//! evenly across the fiber's width as the light sees it (`l` the unit
//! direction to the light at `p`). With the camera's eye `e` known
//! ([`crate::ShadowMethod::set_eye`]), the rays start instead where the
//! camera's rays meet the fiber's surface, at even steps of the offset
//! across the fiber as the camera sees it:
//!
//! ```text
//! o_k = p + (w / 2) (sqrt(1 - h_k^2) e' + h_k u),   h_k = 2 (k + 1/2) / K - 1,
//! e' = unit(v - (v . t) t),  v = e - p,  u = unit(t x e')
//! ```
//!
//! the points a path tracer shades and starts its shadow rays from
//! (against Blender Cycles: the mean shadow ratio of the pictures from 3
//! to 6 % below Cycles' to within 3.1 %, and the block error 0.039 to
//! 0.051 on the project's grooms, from 0.046 to 0.062 from the axis).
//! Each ray
//! counts `n_k`, the fibers it crosses on its way: one strand's
//! consecutive capsules that the ray passes through without leaving them
//! are one crossing; its own fiber where the ray starts inside it or
//! meets it within two widths of its start (a ray from the fiber's
//! surface may pass through the fiber) is the fiber itself, not a shadow.
//! Nor is another fiber the ray starts inside: where fibers run through
//! one another, the point a camera sees lies outside both, so the light
//! it gets has not crossed the other (counted, it left the reference's
//! pictures darker than Cycles' on grooms whose fibers overlap). An
//! opaque body (the head) stops the ray or not. Then
//!
//! ```text
//! T(p) = (1 / K) sum_k (1 - alpha)^{n_k} [o_k not behind a body]
//! ```
//!
//! With the camera known and the fiber's light across its width given
//! ([`crate::ShadowMethod::set_across`], [`AcrossFiber`]: the physically
//! based fiber's), the rays are weighed by it instead of evenly:
//!
//! ```text
//! T(p) = sum_k W_k T_k / sum_k W_k,   W_k = int over h in ray k's part f(w_o, w_i; h) dh
//! ```
//!
//! `T_k` the ray's term above. A picture shows a fiber's `T` where the
//! fiber is bright, and its lobes are narrow across it: rendered in
//! Blender Cycles at 8x8 the pixels, 90 % of one fiber's light came from
//! `h` between 0.25 and 0.75, where a neighbour's shadow fell; Cycles
//! showed T = 0.51 there, the even mean of the rays 0.74, and the rays
//! weighed by the model's profile about 0.50. Against Cycles on the
//! project's grooms, block error 0.037 to 0.050 (evenly: 0.039 to 0.051;
//! the smooth style 0.041, from 0.045).
//!
//! No footprint wider than the fiber, no grid of values, no interpolation:
//! what a path tracer's shadow rays from the fiber's surface see. A point
//! that is not a drawn point (a probe) is a point: one ray, from it.
//!
//! Acceleration: segments are binned by the light-view columns of a
//! [`GRID`]^2 map fitted to the hair ([`crate::bins`]); a ray towards the
//! light stays in the column of its origin (for a point or spot light, a
//! column is a bundle of rays from the source), so it tests only that
//! column's segments.

use std::sync::Arc;

use std::collections::HashMap;

use glam::{DVec3, Vec3};

use crate::bins::SegmentBins;
use crate::input::ShadowInput;
use crate::occluder::OccluderView;
use crate::{FillStats, Light, LightFrame, ShadowError};

/// Columns of the grid per side: finer than the footprint reference's, as
/// a ray is as thin as a line.
pub(crate) const GRID: u32 = 512;

/// The per-fiber reference (see the module documentation).
#[derive(Debug)]
pub struct Reference {
    rays: u32,
    /// The camera's eye: drawn points' rays start where its rays meet
    /// their fiber's surface.
    eye: Option<Vec3>,
    across: Option<Arc<dyn AcrossFiber>>,
    built: Option<Built>,
}

/// Where across its width a fiber sends the light it scatters towards
/// the eye: what the exact reference weighs its rays by when the camera
/// is known ([`crate::ShadowMethod::set_across`]). A fiber's lobes are
/// narrow across it (a glint over a quarter of the width is common), and
/// a picture shows `T` where the fiber is bright, not `T` averaged
/// evenly across it.
pub trait AcrossFiber: Send + Sync + std::fmt::Debug {
    /// The light the fiber scatters from unit direction `wi` (towards the
    /// light) into unit direction `wo` (towards the eye) over the offsets
    /// `h0..h1` across it (within -1 to 1), any measure that is not
    /// negative (luminance, say). Both directions are in the fiber's
    /// frame: `x` along it, `z` across it towards the eye, `y = z x x`;
    /// the offset `h` is along `y` (Chiang et al.'s and pbrt's `h`).
    fn weight(&self, wo: Vec3, wi: Vec3, h0: f32, h1: f32) -> f32;
}

#[derive(Debug)]
struct Built {
    bins: SegmentBins,
    light: Light,
    drawn: DrawnPoints,
    /// Fiber radius, scene units.
    radius: f32,
    transmit: f32,
    occluders: Option<OccluderView>,
}

/// Where a ray meets a capsule: the interval `[s0, s1]` of the ray
/// `o + s d` (`d` unit) within distance `r` of segment `a e`, if any.
/// The capsule is convex, so the ray meets it in one interval: the hull
/// of the intervals of its pieces (the two end spheres and the cylinder
/// between them). In double precision: the differences of points far from
/// the origin are exact there, and a ray nearly along the capsule's axis
/// keeps its digits.
fn ray_capsule(o: Vec3, d: Vec3, a: Vec3, e: Vec3, r: f32) -> Option<(f64, f64)> {
    let (o, d, a, e, r) = (
        o.as_dvec3(),
        d.as_dvec3(),
        a.as_dvec3(),
        e.as_dvec3(),
        f64::from(r),
    );
    let r2 = r * r;
    let mut lo = f64::INFINITY;
    let mut hi = f64::NEG_INFINITY;
    let mut take = |iv: Option<(f64, f64)>| {
        if let Some((s0, s1)) = iv {
            lo = lo.min(s0);
            hi = hi.max(s1);
        }
    };
    // |m + s d|^2 = r^2 with |d| = 1.
    let sphere = |c: DVec3| {
        let m = o - c;
        let b = m.dot(d);
        let disc = b * b - (m.length_squared() - r2);
        (disc >= 0.0).then(|| {
            let q = disc.sqrt();
            (-b - q, -b + q)
        })
    };
    take(sphere(a));
    take(sphere(e));
    let ab = e - a;
    let len = ab.length();
    if len > 1e-9 * r {
        let u = ab / len;
        let m = o - a;
        let (mu, du) = (m.dot(u), d.dot(u));
        let mp = m - mu * u;
        let dp = d - du * u;
        // The infinite cylinder: A s^2 + 2 B s + C <= 0.
        let (qa, qb, qc) = (dp.length_squared(), mp.dot(dp), mp.length_squared() - r2);
        let cyl = if qa < 1e-18 {
            (qc <= 0.0).then_some((f64::NEG_INFINITY, f64::INFINITY))
        } else {
            let disc = qb * qb - qa * qc;
            (disc >= 0.0).then(|| {
                let q = disc.sqrt();
                ((-qb - q) / qa, (-qb + q) / qa)
            })
        };
        // Between the end caps' planes: 0 <= mu + s du <= len.
        let slab = if du.abs() < 1e-18 {
            (0.0..=len)
                .contains(&mu)
                .then_some((f64::NEG_INFINITY, f64::INFINITY))
        } else {
            let (s0, s1) = (-mu / du, (len - mu) / du);
            Some((s0.min(s1), s0.max(s1)))
        };
        if let (Some(c), Some(s)) = (cyl, slab) {
            let (s0, s1) = (c.0.max(s.0), c.1.min(s.1));
            if s0 <= s1 {
                take(Some((s0, s1)));
            }
        }
    }
    (lo <= hi).then_some((lo, hi))
}

/// The fibers the ray `o + s d` (`d` unit), `0 < s < reach`, crosses among
/// the segments `segs` of `bins`: one strand's consecutive capsules that
/// the ray passes through without leaving them are one crossing; a fiber
/// the ray starts inside, and its own fiber (strand `own`, when the ray
/// leaves a drawn point) where it meets it within two widths of its
/// start, are not counted (see the module documentation).
pub(crate) fn crossings(
    bins: &SegmentBins,
    segs: impl IntoIterator<Item = u32>,
    o: Vec3,
    d: Vec3,
    reach: f64,
    own: Option<u32>,
    radius: f32,
) -> u32 {
    thread_local! {
        static HITS: std::cell::RefCell<Vec<(u32, f64, f64)>> = const {
            std::cell::RefCell::new(Vec::new())
        };
    }
    HITS.with_borrow_mut(|hits| {
        hits.clear();
        for s in segs {
            let (a, e) = (bins.world[s as usize], bins.world[s as usize + 1]);
            if let Some((s0, s1)) = ray_capsule(o, d, a, e, radius)
                && s1 > 0.0
                && s0 < reach
            {
                hits.push((bins.strand[s as usize], s0, s1));
            }
        }
        hits.sort_unstable_by(|x, y| x.0.cmp(&y.0).then(x.1.total_cmp(&y.1)));
        // Crossings: each strand's intervals merged where they touch.
        let slack = 1e-4 * f64::from(radius);
        let near_own = 4.0 * f64::from(radius);
        let mut crossings = 0u32;
        let mut i = 0;
        while i < hits.len() {
            let strand = hits[i].0;
            let (mut start, mut end) = (hits[i].1, hits[i].2);
            i += 1;
            loop {
                while i < hits.len() && hits[i].0 == strand && hits[i].1 <= end + slack {
                    end = end.max(hits[i].2);
                    i += 1;
                }
                // A fiber the drawn point's ray starts inside; and
                // its own fiber near where it starts (a ray from the
                // fiber's surface may pass through the fiber itself).
                let itself =
                    own.is_some() && (start <= 0.0 || (own == Some(strand) && start <= near_own));
                if !itself {
                    crossings += 1;
                }
                if i < hits.len() && hits[i].0 == strand {
                    (start, end) = (hits[i].1, hits[i].2);
                    i += 1;
                } else {
                    break;
                }
            }
        }
        crossings
    })
}

/// The drawn points of a frame's hair by strand: a drawn point's fiber
/// from its index.
#[derive(Debug)]
pub(crate) struct StrandPoints {
    /// The strand offsets (the first point of each strand and the end),
    /// to find a point's neighbours.
    offsets: Vec<u32>,
    points: Vec<Vec3>,
}

impl StrandPoints {
    pub(crate) fn new(hair: &strands::Hair) -> StrandPoints {
        StrandPoints {
            offsets: hair.offsets().to_vec(),
            points: hair.points().to_vec(),
        }
    }

    /// The strand of the `i`-th drawn point and its tangent (not
    /// normalized; zero where the strand has one point), when `p` is
    /// exactly that point.
    pub(crate) fn fiber_at(&self, i: usize, p: Vec3) -> Option<(u32, Vec3)> {
        (bits(*self.points.get(i)?) == bits(p)).then(|| self.fiber_of(i))
    }

    fn fiber_of(&self, i: usize) -> (u32, Vec3) {
        let s = self.offsets.partition_point(|&o| o as usize <= i) - 1;
        let (first, last) = (self.offsets[s] as usize, self.offsets[s + 1] as usize - 1);
        let t = self.points[(i + 1).min(last)] - self.points[i.saturating_sub(1).max(first)];
        (s as u32, t)
    }
}

/// [`StrandPoints`] with an index by coordinates, to find the fiber of
/// any point.
#[derive(Debug)]
struct DrawnPoints {
    strands: StrandPoints,
    /// A drawn point's index by its coordinates' bits.
    index: HashMap<[u32; 3], u32>,
}

impl DrawnPoints {
    fn new(hair: &strands::Hair) -> DrawnPoints {
        let strands = StrandPoints::new(hair);
        let mut index = HashMap::with_capacity(strands.points.len());
        for (i, p) in strands.points.iter().enumerate() {
            index.entry(bits(*p)).or_insert(i as u32);
        }
        DrawnPoints { strands, index }
    }

    /// The strand of the drawn point at exactly `p` and its tangent, as
    /// [`StrandPoints::fiber_at`], or `None` for a point that is not
    /// drawn (a probe).
    fn fiber(&self, p: Vec3) -> Option<(u32, Vec3)> {
        let &i = self.index.get(&bits(p))?;
        Some(self.strands.fiber_of(i as usize))
    }
}

fn bits(p: Vec3) -> [u32; 3] {
    p.to_array().map(f32::to_bits)
}

impl Reference {
    pub(crate) fn new(rays: u32) -> Reference {
        Reference {
            rays: rays.max(1),
            eye: None,
            across: None,
            built: None,
        }
    }

    /// The camera's eye (see the module documentation); `None`: rays
    /// start on the fiber's axis, across it as the light sees it.
    pub(crate) fn set_eye(&mut self, eye: Option<Vec3>) {
        self.eye = eye.filter(|e| e.is_finite());
    }

    /// How the fiber's light is spread across its width (see
    /// [`AcrossFiber`]); `None`: evenly.
    pub(crate) fn set_across(&mut self, across: Option<Arc<dyn AcrossFiber>>) {
        self.across = across;
    }

    pub(crate) fn density(&mut self, input: &ShadowInput) -> Result<FillStats, ShadowError> {
        let bins = SegmentBins::new(input, GRID)?;
        let stats = bins.stats;
        let occluders =
            (!input.occluders.is_empty()).then(|| OccluderView::new(bins.frame, input.occluders));
        self.built = Some(Built {
            bins,
            light: *input.light,
            drawn: DrawnPoints::new(input.hair),
            radius: 0.5 * input.fiber.width(),
            transmit: 1.0 - input.fiber.opacity(),
            occluders,
        });
        Ok(stats)
    }

    pub(crate) fn transmittance(&mut self) {
        assert!(
            self.built.is_some(),
            "the density stage runs before the transmittance stage"
        );
    }

    pub(crate) fn transmittance_at(&self, p: Vec3) -> f32 {
        let b = self
            .built
            .as_ref()
            .expect("the density stage runs before lookups");
        let to_light = -b.light.direction_at(p);
        // A probe is a point: one ray from it.
        let Some((strand, t)) = b.drawn.fiber(p) else {
            return self.ray(b, p, None) as f32;
        };
        // With the eye known: from the surface the camera sees, at even
        // steps of the offset `h` across the fiber as the camera sees it
        // (where a camera ray meets a round fiber of radius r at offset
        // h r, it meets its surface at `p + r (sqrt(1 - h^2) e + h u)`,
        // `e` towards the eye across the fiber and `u` across it both). A
        // fiber seen end-on, or with no direction, is sampled as without
        // a camera: from its axis, across it as the light sees it (a
        // fiber along the light is round to it: across any axis).
        let tn = t.normalize_or_zero();
        let seen = self.eye.and_then(|e| {
            let v = e - p;
            let e = (v - v.dot(tn) * tn).try_normalize()?;
            Some((e, tn.cross(e).try_normalize()?))
        });
        let across = to_light
            .cross(t)
            .try_normalize()
            .unwrap_or(b.bins.frame.axes[1]);
        let k = self.rays;
        // Each ray's weight: the light its part of the width sends to the
        // eye. In the fiber's frame (x = t, z = e', y = z x x = -u) the
        // ray at offset h along u covers -h -/+ 1/K along y.
        let frame = match (seen, &self.across, self.eye) {
            (Some((e, _)), Some(w), Some(eye)) => {
                let y = e.cross(tn);
                let local = |v: Vec3| Vec3::new(v.dot(tn), v.dot(y), v.dot(e));
                Some((w, local((eye - p).normalize_or_zero()), local(to_light)))
            }
            _ => None,
        };
        let half = 1.0 / k as f32;
        let (mut sum, mut weights, mut even) = (0.0f64, 0.0f64, 0.0f64);
        for r in 0..k {
            // The offset across the fiber, -1 to 1.
            let h = 2.0 * ((r as f32 + 0.5) / k as f32 - 0.5);
            let o = match seen {
                Some((e, u)) => p + (e * (1.0 - h * h).sqrt() + u * h) * b.radius,
                None => p + across * (h * b.radius),
            };
            let w = frame.map_or(1.0, |(w, wo, wi)| {
                f64::from(w.weight(wo, wi, (-h - half).max(-1.0), (-h + half).min(1.0)))
            });
            let w = if w.is_finite() { w.max(0.0) } else { 0.0 };
            let t_ray = self.ray(b, o, Some(strand));
            sum += w * t_ray;
            weights += w;
            even += t_ray;
        }
        // A fiber that sends the eye no light at all: evenly.
        let t = if weights > 0.0 {
            sum / weights
        } else {
            even / f64::from(k)
        };
        t.clamp(0.0, 1.0) as f32
    }

    /// The light one ray from `o` to the light lets through, its own fiber
    /// (strand `own`) not counted.
    fn ray(&self, b: &Built, o: Vec3, own: Option<u32>) -> f64 {
        if let Some(view) = &b.occluders
            && view.blocks(o)
        {
            return 0.0;
        }
        let (j, k) = b.bins.column_of(o);
        let (d, reach) = match b.light.source() {
            None => (-b.light.direction(), f64::INFINITY),
            Some(src) => {
                let v = src - o;
                (v.normalize_or_zero(), f64::from(v.length()))
            }
        };
        let n = crossings(
            &b.bins,
            b.bins.column(j, k).iter().copied(),
            o,
            d,
            reach,
            own,
            b.radius,
        );
        f64::from(b.transmit).powi(n as i32)
    }

    pub(crate) fn frame(&self) -> Option<&LightFrame> {
        self.built.as_ref().map(|b| &b.bins.frame)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_ray_through_a_capsule_across_it() {
        // Along x through a capsule along z of radius 0.5 at x = 3.
        let iv = ray_capsule(
            Vec3::ZERO,
            Vec3::X,
            Vec3::new(3.0, 0.0, -1.0),
            Vec3::new(3.0, 0.0, 1.0),
            0.5,
        )
        .unwrap();
        assert!(
            (iv.0 - 2.5).abs() < 1e-5 && (iv.1 - 3.5).abs() < 1e-5,
            "{iv:?}"
        );
        // Off by 0.3 in y: the chord of a circle of radius 0.5.
        let iv = ray_capsule(
            Vec3::new(0.0, 0.3, 0.0),
            Vec3::X,
            Vec3::new(3.0, 0.0, -1.0),
            Vec3::new(3.0, 0.0, 1.0),
            0.5,
        )
        .unwrap();
        assert!((iv.1 - iv.0 - 0.8).abs() < 1e-5, "{iv:?}");
        // Missed: past the end cap, and beside it.
        assert!(
            ray_capsule(
                Vec3::new(0.0, 0.0, 1.6),
                Vec3::X,
                Vec3::new(3.0, 0.0, -1.0),
                Vec3::new(3.0, 0.0, 1.0),
                0.5
            )
            .is_none()
        );
        assert!(
            ray_capsule(
                Vec3::new(0.0, 0.6, 0.0),
                Vec3::X,
                Vec3::new(3.0, 0.0, -1.0),
                Vec3::new(3.0, 0.0, 1.0),
                0.5
            )
            .is_none()
        );
    }

    #[test]
    fn a_ray_along_a_capsule_and_into_its_cap() {
        // Along the axis: from one cap's far side to the other's.
        let iv = ray_capsule(
            Vec3::ZERO,
            Vec3::X,
            Vec3::new(2.0, 0.0, 0.0),
            Vec3::new(4.0, 0.0, 0.0),
            0.5,
        )
        .unwrap();
        assert!(
            (iv.0 - 1.5).abs() < 1e-5 && (iv.1 - 4.5).abs() < 1e-5,
            "{iv:?}"
        );
        // Starting inside: the interval holds 0.
        let iv = ray_capsule(
            Vec3::new(3.0, 0.2, 0.0),
            Vec3::Y,
            Vec3::new(2.0, 0.0, 0.0),
            Vec3::new(4.0, 0.0, 0.0),
            0.5,
        )
        .unwrap();
        assert!(iv.0 < 0.0 && (iv.1 - 0.3).abs() < 1e-5, "{iv:?}");
        // A degenerate segment is a sphere.
        let iv = ray_capsule(
            Vec3::ZERO,
            Vec3::X,
            Vec3::new(2.0, 0.0, 0.0),
            Vec3::new(2.0, 0.0, 0.0),
            0.5,
        )
        .unwrap();
        assert!(
            (iv.0 - 1.5).abs() < 1e-5 && (iv.1 - 2.5).abs() < 1e-5,
            "{iv:?}"
        );
    }
}
