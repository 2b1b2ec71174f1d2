//! Lights and the light-oriented local frame of a map (paper 3.1, 3.2).

use glam::Vec3;
use rayon::prelude::*;

use crate::{MAX_CELLS, ShadowError};

/// A light source. Each light owns its own map; nothing here assumes a
/// single light.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Light {
    /// Parallel rays travelling along `direction` (unit), as from the sun.
    Directional { direction: Vec3 },
}

impl Light {
    pub fn directional(direction: Vec3) -> Result<Light, ShadowError> {
        let d = direction.normalize_or_zero();
        if !direction.is_finite() || d == Vec3::ZERO {
            return Err(ShadowError::LightDirection(direction));
        }
        Ok(Light::Directional { direction: d })
    }

    /// The unit direction light travels, which becomes the map's first axis.
    pub fn direction(&self) -> Vec3 {
        match *self {
            Light::Directional { direction } => direction,
        }
    }
}

/// The map frame R = (O, X_map, Y_map, Z_map): X_map is the direction the
/// light travels, and the map is `n_cells` cubic cells of side `ds` along
/// each axis from the corner `origin`.
///
/// Unlike the paper's mapping function, there is no modulo: a point outside
/// `[0, n_cells)` on any axis is outside the map, and the stages say so
/// rather than wrapping it into a cell on the other side (which would cast
/// a false shadow).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LightFrame {
    pub origin: Vec3,
    /// X_map (= light direction), Y_map, Z_map: orthonormal.
    pub axes: [Vec3; 3],
    /// Cell side, in scene units.
    pub ds: f32,
    pub n_cells: u32,
}

impl LightFrame {
    /// The smallest cubic map around `points` (a still frame: the map may fit
    /// the hair), with a spare cell on each side so that the hair and its
    /// deposits lie strictly inside.
    pub fn fit(light: &Light, points: &[Vec3], n_cells: u32) -> Result<LightFrame, ShadowError> {
        LightFrame::fit_with(light, points, &[], n_cells)
    }

    /// Like [`Self::fit`], around `points` and `extra` (say, the corners of
    /// a head's bounding box).
    pub fn fit_with(
        light: &Light,
        points: &[Vec3],
        extra: &[Vec3],
        n_cells: u32,
    ) -> Result<LightFrame, ShadowError> {
        check_cells(n_cells)?;
        let Some(&c) = points.first().or(extra.first()) else {
            return LightFrame::centered(light, Vec3::ZERO, 1.0, n_cells);
        };
        let extent = Extent::of(light, c, points).union(Extent::of(light, c, extra));
        LightFrame::fit_extent(light, c, extent, n_cells)
    }

    /// The smallest cubic map around `extent` (measured from `anchor`, see
    /// [`Extent::of`]), with a spare cell on each side so that the hair and
    /// its deposits lie strictly inside.
    pub fn fit_extent(
        light: &Light,
        anchor: Vec3,
        extent: Extent,
        n_cells: u32,
    ) -> Result<LightFrame, ShadowError> {
        check_cells(n_cells)?;
        if extent.is_empty() {
            return LightFrame::centered(light, anchor, 1.0, n_cells);
        }
        let axes = light_axes(light.direction());
        let (lo, hi) = (extent.lo, extent.hi);
        let c = anchor;
        let extent = (hi - lo).max_element();
        // A map must be wider than float noise at this distance from the origin.
        let floor = 1e-3 * (1.0 + c.abs().max_element() * 1e-2);
        // One spare cell on every side: the density deposit spreads hair
        // half a cell across the light, and all of it must stay inside.
        let n = n_cells as f32;
        let size = ((extent * 1.002).max(extent + 2.0 * floor) * n / (n - 2.0).max(1.0))
            .max(extent + 2.0 * floor);
        let mid = 0.5 * (lo + hi);
        let center = c + mid.x * axes[0] + mid.y * axes[1] + mid.z * axes[2];
        LightFrame::centered(light, center, size, n_cells)
    }

    /// A cubic map of side `size` centred on `center`. For animated hair the
    /// paper's bound `size >= 2 l_max + h_max` (longest strand, largest head
    /// dimension) around the head keeps every strand inside at every frame.
    pub fn centered(
        light: &Light,
        center: Vec3,
        size: f32,
        n_cells: u32,
    ) -> Result<LightFrame, ShadowError> {
        check_cells(n_cells)?;
        if !(size.is_finite() && size > 0.0) {
            return Err(ShadowError::MapSize(size));
        }
        let axes = light_axes(light.direction());
        let origin = center - 0.5 * size * (axes[0] + axes[1] + axes[2]);
        Ok(LightFrame {
            origin,
            axes,
            ds: size / n_cells as f32,
            n_cells,
        })
    }

    /// The paper's bound for animated hair: `2 l_max + h_max`.
    pub fn animated_size(l_max: f32, h_max: f32) -> f32 {
        2.0 * l_max + h_max
    }

    /// Continuous map coordinates of `p`, in cells: `(x_map, y_map, z_map) / ds`.
    /// Cell `(i, j, k)` covers `[i, i+1) x [j, j+1) x [k, k+1)`.
    #[inline]
    pub fn to_cells(&self, p: Vec3) -> Vec3 {
        let q = (p - self.origin) * self.ds.recip();
        Vec3::new(
            q.dot(self.axes[0]),
            q.dot(self.axes[1]),
            q.dot(self.axes[2]),
        )
    }

    /// The world position of continuous map coordinates (inverse of [`Self::to_cells`]).
    pub fn to_world(&self, c: Vec3) -> Vec3 {
        self.origin + self.ds * (c.x * self.axes[0] + c.y * self.axes[1] + c.z * self.axes[2])
    }

    /// Number of `(j, k)` columns: `n_cells^2`.
    pub fn columns(&self) -> usize {
        (self.n_cells as usize).pow(2)
    }
}

/// Where points lie along a light's map axes, measured from an anchor
/// point near them (which keeps precision for hair far from the world
/// origin): the smallest and largest coordinate along each axis. Extents
/// of parts of the hair combine with [`Extent::union`], exactly and in any
/// order, into the extent of all of it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Extent {
    pub lo: Vec3,
    pub hi: Vec3,
}

impl Extent {
    pub const EMPTY: Extent = Extent {
        lo: Vec3::splat(f32::INFINITY),
        hi: Vec3::splat(f32::NEG_INFINITY),
    };

    pub fn is_empty(&self) -> bool {
        !(self.lo.cmple(self.hi).all())
    }

    /// The extent of `points` along `light`'s map axes, from `anchor`.
    /// Min and max are exact in any order, so the parallel reduction is
    /// deterministic.
    pub fn of(light: &Light, anchor: Vec3, points: &[Vec3]) -> Extent {
        let axes = light_axes(light.direction());
        points
            .par_chunks(16 * 1024)
            .map(|chunk| {
                let mut e = Extent::EMPTY;
                for &p in chunk {
                    let q = p - anchor;
                    let m = Vec3::new(q.dot(axes[0]), q.dot(axes[1]), q.dot(axes[2]));
                    e.lo = e.lo.min(m);
                    e.hi = e.hi.max(m);
                }
                e
            })
            .reduce(|| Extent::EMPTY, Extent::union)
    }

    /// The extent of both.
    pub fn union(self, o: Extent) -> Extent {
        Extent {
            lo: self.lo.min(o.lo),
            hi: self.hi.max(o.hi),
        }
    }
}

fn check_cells(n: u32) -> Result<(), ShadowError> {
    if (1..=MAX_CELLS).contains(&n) {
        Ok(())
    } else {
        Err(ShadowError::Cells(n))
    }
}

/// An orthonormal frame whose first axis is `l`, by Duff et al.'s branchless
/// construction: stable for every direction, straight up and down included.
fn light_axes(l: Vec3) -> [Vec3; 3] {
    let (y, z) = l.any_orthonormal_pair();
    [l, y, z]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn axes_are_orthonormal_for_axis_aligned_and_vertical_lights() {
        for d in [
            Vec3::X,
            Vec3::Y,
            Vec3::NEG_Y,
            Vec3::Z,
            Vec3::NEG_Z,
            Vec3::new(1.0, 1e-9, 0.0),
            Vec3::new(0.3, -0.9, 0.1),
        ] {
            let l = Light::directional(d).unwrap();
            let a = light_axes(l.direction());
            for i in 0..3 {
                assert!((a[i].length() - 1.0).abs() < 1e-6);
                for j in 0..i {
                    assert!(a[i].dot(a[j]).abs() < 1e-6);
                }
            }
            assert!(
                (a[0].cross(a[1]).dot(a[2]) - 1.0).abs() < 1e-5,
                "right-handed"
            );
        }
    }

    #[test]
    fn refuses_zero_and_nan_lights_and_bad_cells() {
        assert!(Light::directional(Vec3::ZERO).is_err());
        assert!(Light::directional(Vec3::new(f32::NAN, 0.0, 1.0)).is_err());
        let l = Light::directional(Vec3::X).unwrap();
        assert_eq!(
            LightFrame::fit(&l, &[Vec3::ZERO], 0),
            Err(ShadowError::Cells(0))
        );
        assert_eq!(
            LightFrame::fit(&l, &[Vec3::ZERO], MAX_CELLS + 1),
            Err(ShadowError::Cells(MAX_CELLS + 1))
        );
        assert!(LightFrame::centered(&l, Vec3::ZERO, f32::NAN, 8).is_err());
    }

    #[test]
    fn fit_contains_every_point_strictly() {
        let l = Light::directional(Vec3::new(1.0, -2.0, 0.5)).unwrap();
        let pts: Vec<Vec3> = (0..100)
            .map(|i| {
                Vec3::new(
                    (i as f32).sin() * 5.0,
                    i as f32 * 0.1,
                    (i as f32 * 0.7).cos(),
                )
            })
            .collect();
        for n in [1, 7, 128] {
            let f = LightFrame::fit(&l, &pts, n).unwrap();
            for &p in &pts {
                let c = f.to_cells(p);
                assert!(
                    c.min_element() > 0.0 && c.max_element() < n as f32,
                    "{p} -> {c} at n = {n}"
                );
                assert!(f.to_world(c).distance(p) < 1e-4);
            }
        }
    }

    #[test]
    fn a_single_point_far_from_the_origin_gets_a_usable_map() {
        let l = Light::directional(Vec3::Y).unwrap();
        let p = Vec3::splat(1e5);
        let f = LightFrame::fit(&l, &[p], 64).unwrap();
        assert!(f.ds > 0.0 && f.ds.is_finite());
        let c = f.to_cells(p);
        assert!(c.min_element() > 0.0 && c.max_element() < 64.0, "{c}");
    }
}
