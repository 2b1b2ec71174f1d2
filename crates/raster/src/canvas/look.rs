//! How strands look on screen: their width, opacity and depth weight as
//! projected, and stochastic simplification, which draws a seeded share
//! of strands thinner than a threshold, each wider.

use glam::Vec3;

use super::line::ScreenVertex;
use crate::Camera;

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
    /// Stochastic simplification, `t` pixels (0: off; at most
    /// [`Self::MAX_SIMPLIFY`]). Where strands are `c < t` pixels wide on
    /// screen, a share `f = 2^-l` of them is drawn, `l = floor(log2(t /
    /// c))` (at most 4), each `c / f` wide, so that in expectation a pixel
    /// is covered as by all of them. Which strands are drawn is a fixed
    /// hash of their index in the whole hair (see
    /// [`Canvas::draw_hair`](super::Canvas::draw_hair)).
    pub simplify: f32,
}

impl HairLook {
    /// The largest [`HairLook::simplify`], pixels.
    pub const MAX_SIMPLIFY: f32 = 4.0;

    /// Whether [`Canvas::draw_hair`](super::Canvas::draw_hair) may draw a
    /// segment of the strand through `points` (strand `strand` of the
    /// whole hair) seen by `camera`: false only where simplification
    /// leaves every segment of it out, so that its colours need not be
    /// shaded. A segment is drawn at the share of its mean width, which is
    /// no larger than the strand's widest vertex's: the shares are nested,
    /// so the share at the widest vertex (the nearest in front of the
    /// camera) decides.
    pub fn may_draw_strand(&self, camera: &Camera, points: &[Vec3], strand: u32) -> bool {
        if self.simplify <= 0.0 {
            return true;
        }
        let look = Look::new(self, camera);
        let nearest = points
            .iter()
            .filter_map(|&p| camera.depth(p))
            .fold(f32::INFINITY, f32::min);
        nearest.is_finite() && strand_drawn(strand, look.share_level(look.width_at(nearest)))
    }
}

/// The fewest strands stochastic simplification draws: one in `2^4`.
pub(super) const MAX_SHARE_LEVEL: u32 = 4;

/// Whether strand `strand` (its index in the whole hair) is among the
/// share `2^-level` of the strands that stochastic simplification draws.
/// The shares are nested: a strand drawn at one level is drawn at every
/// lower one. A fixed hash of the index (SplitMix64's finalizer), so that
/// the same strands are drawn in every frame, on every thread and worker.
#[inline]
pub(super) fn strand_drawn(strand: u32, level: u32) -> bool {
    if level == 0 {
        return true;
    }
    let mut z = u64::from(strand).wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^= z >> 31;
    z.leading_zeros() >= level
}

/// A projected hair vertex as kept for the whole picture: pixel position
/// and view depth (a NaN depth: behind the camera), and linear colour.
/// Its width and depth weight follow from its depth and its look
/// ([`Look::vertex`]): 24 bytes where they would make 36, as a band fetches
/// the ends of its segments from all over the picture's vertices.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Projected {
    pub(super) p: Vec3,
    pub(super) color: Vec3,
}

/// A [`HairLook`] on the camera it was drawn with.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Look {
    pub(super) look: HairLook,
    /// Fiber width times the camera's focal length: the projected width
    /// times the depth, pixels times scene units.
    pub(super) width_z: f32,
}

impl Look {
    /// `look` on `camera`.
    pub(super) fn new(look: &HairLook, camera: &Camera) -> Look {
        Look {
            look: *look,
            width_z: look.fiber_width * camera.focal(),
        }
    }

    /// Whether the segment between view depths `za` and `zb` of strand
    /// `strand` (its index in the whole hair) is drawn: always, unless
    /// simplified, then where its strand is among the share drawn at the
    /// segment's mean width.
    #[inline]
    pub(super) fn draws_segment(&self, za: f32, zb: f32, strand: u32) -> bool {
        if self.look.simplify <= 0.0 {
            return true;
        }
        let c = 0.5 * (self.width_at(za) + self.width_at(zb));
        strand_drawn(strand, self.share_level(c))
    }

    /// Projected width at view depth `z`: `w * focal / z` pixels, at
    /// least a hair's breadth so that distant hair still covers something.
    #[inline]
    fn width_at(&self, z: f32) -> f32 {
        (self.width_z / z).clamp(0.05, 8.0)
    }

    /// Stochastic simplification (Cook, Halstead, Planck and Ryu 2007,
    /// "Stochastic Simplification of Aggregate Detail"): where strands are
    /// `c` pixels wide on screen, `c` below the look's `simplify = t`, a
    /// share `f = 2^-level` of them is drawn, the largest power of two
    /// with `f >= c / t` (at least `2^-4`). Powers of two keep the shares
    /// nested and the widening cheap ([`Self::widened`]).
    #[inline]
    fn share_level(&self, c: f32) -> u32 {
        let t = self.look.simplify;
        if c >= t {
            return 0;
        }
        // level = floor(log2(t / c)), from the float's exponent.
        let ratio = t / c;
        (((ratio.to_bits() >> 23) as i32 - 127).max(0) as u32).min(MAX_SHARE_LEVEL)
    }

    /// The width `c'` a drawn strand takes in place of `c` at share level
    /// `level`: `c' = c / f`, `f = 2^-level`, between `t / 2` and `t`.
    /// Each strand of a pixel's cover `a = o c` (`o` its opacity) is drawn
    /// with probability `f`, independently, so the light a pixel keeps
    /// behind them is, in expectation, what it keeps behind all of them:
    ///
    /// ```text
    /// E[prod_i (1 - X_i a_i / f)] = prod_i (1 - f a_i / f) = prod_i (1 - a_i),   X_i ~ Bernoulli(f)
    /// ```
    ///
    /// and likewise the blended colour sums `sum_i X_i c_i a_i w_i / f`.
    #[inline]
    fn widened(&self, c: f32, level: u32) -> f32 {
        c * (1u32 << level) as f32
    }

    /// The screen vertex of `v`, if it is in front of the camera.
    #[inline]
    pub(super) fn vertex(&self, v: Projected) -> Option<ScreenVertex> {
        let z = v.p.z;
        if z.is_nan() {
            return None;
        }
        let c = self.width_at(z);
        Some(ScreenVertex {
            p: v.p,
            color: v.color,
            width: self.widened(c, self.share_level(c)),
            // The depth weight at the ends, interpolated along a segment
            // (which spans a few pixels; the weight changes little along
            // it).
            weight: (self.look.depth_ref / z).powi(6).clamp(1e-3, 1e3),
        })
    }
}
