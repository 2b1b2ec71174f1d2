//! Contact shadows: the fibers just in front of a drawn point towards the
//! light, exactly; the density map beyond them.
//!
//! The map is a volume estimate: a fiber's shadow is spread over the two
//! or so cells its deposit and the trilinear lookup blur it across, so
//! the shadow of one fiber on the next (the detail a picture shows most)
//! is lost. With `contact = c` cells, a drawn point `p` sends one ray to
//! the light from where the camera sees its fiber (the middle of the
//! fiber's surface towards the eye, as the exact reference's rays start;
//! from `p` itself without a camera or for a point that is not drawn),
//! counts the fibers it crosses within the distance `a = c ds` as the
//! reference does (capsules of radius `w / 2`; its own fiber and fibers
//! it starts inside not counted; a probe counts every fiber, as the
//! reference's do), and reads the map for the rest:
//!
//! ```text
//! T(p) = (1 - alpha)^{n_a} T_map(o + a l)
//! ```
//!
//! `o` the ray's origin, `l` the unit direction to the light, `n_a` the
//! crossings with `s < a`. The map is read as any lookup reads it, half a
//! cell nearer the light than `o + a l` ([`crate::LIT_EDGE_OFFSET`]);
//! read half a cell nearer `o` or a cell nearer the light instead, the
//! smooth style (2 cells) gave 0.063 and 0.058 against 0.059: worse, or
//! the same within the noise of the measure (0.007). An
//! opaque body (the head) stops the ray exactly; it is in the map beyond
//! too.
//!
//! Against Blender Cycles (block shadow ratio error, the four grooms of
//! docs/shadows.md), 4 cells at 128^3 take the map's error from 0.058 to
//! 0.088 down to 0.045 to 0.063, at 6 to 10 times its time; at 256^3,
//! 0.037 to 0.052, the exact reference's 0.037 to 0.051 within 0.010.

use glam::Vec3;

use crate::bins::SegmentBins;
use crate::input::ShadowInput;
use crate::reference::{StrandPoints, crossings};
use crate::{Light, OccluderView, ShadowError};

/// The largest contact distance, in map cells: a bound on what a ray
/// costs (past 4 to 8 cells the pictures gain nothing measurable).
pub const MAX_CONTACT_CELLS: f32 = 16.0;

/// The fibers near each drawn point, for its contact ray.
#[derive(Debug)]
pub(crate) struct Contact {
    bins: SegmentBins,
    drawn: StrandPoints,
    light: Light,
    /// The contact distance `a`, scene units.
    reach: f32,
    /// Fiber radius, scene units.
    radius: f32,
    /// The opaque bodies, tested exactly.
    occluders: Option<OccluderView>,
    transmit: f32,
}

impl Contact {
    /// The hair of `input` prepared for contact rays of length `reach`
    /// (scene units).
    pub(crate) fn new(input: &ShadowInput, grid: u32, reach: f32) -> Result<Contact, ShadowError> {
        let mut bins = SegmentBins::new(input, grid)?;
        let radius = 0.5 * input.fiber.width();
        bins.order_by_depth(radius / bins.frame.ds);
        let occluders =
            (!input.occluders.is_empty()).then(|| OccluderView::new(bins.frame, input.occluders));
        Ok(Contact {
            occluders,
            bins,
            drawn: StrandPoints::new(input.hair),
            light: *input.light,
            reach,
            radius,
            transmit: 1.0 - input.fiber.opacity(),
        })
    }

    /// `T` at a point `p` that is not drawn (a probe, such as a point
    /// just off the head): one ray from `p`, every fiber it crosses
    /// counted (as the exact reference counts a probe's), and `map` (the
    /// map's `T` at a point) past the contact distance.
    pub(crate) fn at(&self, p: Vec3, map: impl Fn(Vec3) -> f32) -> f32 {
        let (t, beyond) = self.ray(p, None);
        t * map(beyond)
    }

    /// [`Self::at`] for the `i`-th drawn point `p` (a probe when it is not
    /// that point): one ray from the middle of the fiber's surface that
    /// `eye` sees (from `p` without an eye), its own fiber and the fibers
    /// it starts inside not counted. One ray, not the reference's four
    /// across the width: on the curly style (contact 4 cells) 2 and 4
    /// rays gave block errors against Cycles of 0.052 and 0.051 against
    /// 0.054, for 1.6 and 2.9 times the time.
    pub(crate) fn at_drawn(
        &self,
        i: usize,
        p: Vec3,
        eye: Option<Vec3>,
        map: impl Fn(Vec3) -> f32,
    ) -> f32 {
        let Some((s, t)) = self.drawn.fiber_at(i, p) else {
            return self.at(p, map);
        };
        let t = t.normalize_or_zero();
        // `p + r e'`, `e'` towards the eye at right angles to the fiber.
        let o = eye.map_or(p, |eye| {
            let v = eye - p;
            p + (v - v.dot(t) * t).normalize_or_zero() * self.radius
        });
        let (t, beyond) = self.ray(o, Some(s));
        t * map(beyond)
    }

    /// The light one ray from `o` lets through within the contact
    /// distance (its own fiber, strand `own`, not counted), and the point
    /// it reaches there.
    fn ray(&self, o: Vec3, own: Option<u32>) -> (f32, Vec3) {
        if let Some(view) = &self.occluders
            && view.blocks(o)
        {
            return (0.0, o);
        }
        let (d, reach) = match self.light.source() {
            None => (-self.light.direction(), self.reach),
            Some(src) => {
                let v = src - o;
                (v.normalize_or_zero(), self.reach.min(v.length()))
            }
        };
        if !(o.is_finite() && d != Vec3::ZERO) {
            return (1.0, o);
        }
        let end = o + d * reach;
        let (j, k) = self.bins.column_of(o);
        let (c0, c1) = (self.bins.frame.to_cells(end), self.bins.frame.to_cells(o));
        let segs = self
            .bins
            .column_between(j, k, c0.x.min(c1.x), c0.x.max(c1.x));
        // Under parallel light a ray along the map's first axis meets a
        // capsule only where the capsule's shadow across the light (a 2D
        // capsule of the same radius) holds the ray: a cheap test first.
        let cells = &self.bins.cells;
        let (at, r2) = (
            glam::Vec2::new(c1.y, c1.z),
            (self.bins.radius * 1.001 + 1e-4).powi(2),
        );
        let parallel = self.bins.frame.fan.is_none();
        let beside = |s: u32| {
            let (a, b) = (cells[s as usize], cells[s as usize + 1]);
            let (a, b) = (glam::Vec2::new(a.y, a.z), glam::Vec2::new(b.y, b.z));
            let ab = b - a;
            let t = ((at - a).dot(ab) / ab.length_squared().max(1e-30)).clamp(0.0, 1.0);
            (a + ab * t - at).length_squared() > r2
        };
        let segs = segs.iter().copied().filter(|&s| !(parallel && beside(s)));
        let n = crossings(&self.bins, segs, o, d, f64::from(reach), own, self.radius);
        (self.transmit.powi(n as i32), end)
    }
}
