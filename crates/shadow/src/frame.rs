//! Lights and the light-oriented local frame of a map (paper 3.1, 3.2).

use glam::Vec3;
use rayon::prelude::*;

use crate::ShadowError;

/// The largest map side, in cells. 512^3 cells already take 512 MiB.
pub const MAX_CELLS: u32 = 512;

/// A light source. Each light owns its own map; nothing here assumes a
/// single light.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Light {
    /// Parallel rays travelling along `direction` (unit), as from the sun,
    /// of irradiance 1 (the shading's unit).
    Directional {
        /// Where the rays travel (unit).
        direction: Vec3,
    },
    /// Rays from `position` in every direction; the irradiance at distance
    /// `r` is `intensity / r^2` (`intensity` in irradiance units times
    /// scene units squared: 100 gives the directional light's irradiance
    /// at 10 units).
    Point {
        /// The source, scene units.
        position: Vec3,
        /// Irradiance times distance squared.
        intensity: f32,
    },
    /// A point light whose rays are limited to a cone around `direction`
    /// (unit): full inside `cone_deg - falloff_deg` of it, none past
    /// `cone_deg`, a smooth step between ([`Light::falloff`]).
    Spot {
        /// The source, scene units.
        position: Vec3,
        /// The cone's axis (unit).
        direction: Vec3,
        /// Half-angle of the cone, degrees.
        cone_deg: f32,
        /// Width of the smooth edge inside the cone, degrees.
        falloff_deg: f32,
        /// Irradiance times distance squared, on the axis.
        intensity: f32,
    },
}

impl Light {
    /// A directional light whose rays travel along `direction` (any length but zero).
    pub fn directional(direction: Vec3) -> Result<Light, ShadowError> {
        Ok(Light::Directional {
            direction: unit(direction)?,
        })
    }

    /// A point light at `position` of `intensity` (finite, > 0).
    pub fn point(position: Vec3, intensity: f32) -> Result<Light, ShadowError> {
        check_source(position, intensity)?;
        Ok(Light::Point {
            position,
            intensity,
        })
    }

    /// A spot light: `cone_deg` in (0, 90), `falloff_deg` in [0, cone_deg].
    pub fn spot(
        position: Vec3,
        direction: Vec3,
        cone_deg: f32,
        falloff_deg: f32,
        intensity: f32,
    ) -> Result<Light, ShadowError> {
        check_source(position, intensity)?;
        if !(cone_deg > 0.0 && cone_deg < 90.0) {
            return Err(ShadowError::LightSetting {
                what: "cone_deg",
                value: cone_deg.to_string(),
                why: "must be in (0, 90) degrees",
            });
        }
        if !(falloff_deg >= 0.0 && falloff_deg <= cone_deg) {
            return Err(ShadowError::LightSetting {
                what: "falloff_deg",
                value: falloff_deg.to_string(),
                why: "must be in [0, cone_deg]",
            });
        }
        Ok(Light::Spot {
            position,
            direction: unit(direction)?,
            cone_deg,
            falloff_deg,
            intensity,
        })
    }

    /// Where the light's rays start: `None` for a directional light.
    pub fn source(&self) -> Option<Vec3> {
        match *self {
            Light::Directional { .. } => None,
            Light::Point { position, .. } | Light::Spot { position, .. } => Some(position),
        }
    }

    /// The unit direction light travels at `p`: from the source to `p`
    /// for a point or spot light (straight down at the source itself).
    #[inline]
    pub fn direction_at(&self, p: Vec3) -> Vec3 {
        match self.source() {
            None => self.direction(),
            Some(s) => (p - s).normalize_or(Vec3::NEG_Y),
        }
    }

    /// The light's irradiance at `p`, in units of a directional light's:
    /// 1 for a directional light; `intensity / r^2` for a point light at
    /// distance `r`; times, for a spot light, the cone's smooth step
    /// `s(t) = t^2 (3 - 2 t)` of `t = (cos a - cos c) / (cos(c - f) - cos c)`
    /// clamped to [0, 1], with `a` the angle of `p` from the spot's
    /// direction, `c = cone_deg` and `f = falloff_deg` (a hard edge when
    /// `f = 0`).
    #[inline]
    pub fn falloff(&self, p: Vec3) -> f32 {
        match *self {
            Light::Directional { .. } => 1.0,
            Light::Point {
                position,
                intensity,
            } => intensity / (p - position).length_squared().max(1e-12),
            Light::Spot {
                position,
                direction,
                cone_deg,
                falloff_deg,
                intensity,
            } => {
                let r = p - position;
                let r2 = r.length_squared().max(1e-12);
                let cos_a = r.dot(direction) / r2.sqrt();
                let cos_c = cone_deg.to_radians().cos();
                let cos_in = (cone_deg - falloff_deg).to_radians().cos();
                let t = if cos_in > cos_c {
                    ((cos_a - cos_c) / (cos_in - cos_c)).clamp(0.0, 1.0)
                } else if cos_a >= cos_c {
                    1.0
                } else {
                    0.0
                };
                intensity / r2 * t * t * (3.0 - 2.0 * t)
            }
        }
    }

    /// The direction of a directional or spot light; for a point light,
    /// which has none, straight down (its maps take their axis from the
    /// hair: see [`Self::axis`]).
    pub fn direction(&self) -> Vec3 {
        match *self {
            Light::Directional { direction } | Light::Spot { direction, .. } => direction,
            Light::Point { .. } => Vec3::NEG_Y,
        }
    }

    /// The first axis of this light's map for hair near `anchor`: the
    /// direction light travels, or for a light with a source the direction
    /// from the source to `anchor` (so that the hair is seen straight on).
    pub fn axis(&self, anchor: Vec3) -> Vec3 {
        match self.source() {
            None => self.direction(),
            Some(s) => (anchor - s).normalize_or(self.direction()),
        }
    }
}

fn unit(direction: Vec3) -> Result<Vec3, ShadowError> {
    let d = direction.normalize_or_zero();
    if !direction.is_finite() || d == Vec3::ZERO {
        return Err(ShadowError::LightDirection(direction));
    }
    Ok(d)
}

fn check_source(position: Vec3, intensity: f32) -> Result<(), ShadowError> {
    if !position.is_finite() {
        return Err(ShadowError::LightSetting {
            what: "position",
            value: position.to_string(),
            why: "must be finite",
        });
    }
    if !(intensity.is_finite() && intensity > 0.0) {
        return Err(ShadowError::LightSetting {
            what: "intensity",
            value: intensity.to_string(),
            why: "must be a finite number > 0",
        });
    }
    Ok(())
}

/// Where [`LightFrame::to_cells`] puts a point that is not in front of a
/// fan's source: in front of the map, outside it.
pub(crate) const BEHIND: Vec3 = Vec3::splat(-3.0);

/// The widest a map from a source may open: hair at most `atan` of this
/// (71.6 degrees) from its axis.
pub const MAX_FAN_TAN: f32 = 3.0;

/// The partition of a map from a point source (the paper's "angular space
/// partition starting from the source point"): a point `p` with
/// `r = p - source` has depth `x = r . X_map` along the axis and
/// tangent-plane coordinates `u = r . Y_map / x`, `v = r . Z_map / x` (where
/// its ray meets the plane `x = 1`), and map coordinates
///
/// ```text
/// (i, j, k) = ((x - x0) / ds, (u - u0) / du, (v - v0) / du)
/// ```
///
/// A column `(j, k)` is the bundle of rays through one square cell of that
/// plane, so the sweep along it follows the rays; slices are planes of
/// equal `x`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Fan {
    /// The light's position, scene units.
    pub source: Vec3,
    /// `(x0, u0, v0)`: cell `(0, 0, 0)`'s corner.
    pub start: Vec3,
    /// Cell side `du` in the tangent plane (dimensionless).
    pub du: f32,
}

/// The map frame R = (O, X_map, Y_map, Z_map): X_map is the direction the
/// light travels, and the map is `n_cells` cubic cells of side `ds` along
/// each axis from the corner `origin`; or, for a light with a source
/// (`fan`), cells of depth `ds` along X_map from the source that open
/// with the rays (see [`Fan`]; `origin` is then the source).
///
/// Unlike the paper's mapping function, there is no modulo: a point outside
/// `[0, n_cells)` on any axis is outside the map, and the stages say so
/// rather than wrapping it into a cell on the other side (which would cast
/// a false shadow).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LightFrame {
    /// The corner of cell `(0, 0, 0)` (for a fan, the source), scene units.
    pub origin: Vec3,
    /// X_map (= light direction), Y_map, Z_map: orthonormal.
    pub axes: [Vec3; 3],
    /// Cell side, in scene units.
    pub ds: f32,
    /// Cells a side.
    pub n_cells: u32,
    /// The partition from a point source, for point and spot lights.
    pub fan: Option<Fan>,
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
        // A light with a source looks at the middle of what it lights.
        let c = if light.source().is_some() {
            let (lo, hi) = points
                .iter()
                .chain(extra)
                .fold((c, c), |(lo, hi), &p| (lo.min(p), hi.max(p)));
            0.5 * (lo + hi)
        } else {
            c
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
        if let Some(source) = light.source() {
            return LightFrame::fan(light, source, anchor, extent, n_cells);
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

    /// The map of a light from `source` around `extent` (depths and
    /// tangent-plane coordinates, see [`Extent::of`]), with a spare cell on
    /// each side as for a directional light. Refuses hair behind the
    /// source or wider than [`MAX_FAN_TAN`] from the axis.
    fn fan(
        light: &Light,
        source: Vec3,
        anchor: Vec3,
        extent: Extent,
        n_cells: u32,
    ) -> Result<LightFrame, ShadowError> {
        let (lo, hi) = (extent.lo, extent.hi);
        let inside = ShadowError::LightInside {
            position: source,
            max_deg: MAX_FAN_TAN.atan().to_degrees(),
        };
        let wide = lo.y.abs().max(hi.y.abs()).max(lo.z.abs()).max(hi.z.abs());
        if !(lo.x > 0.0 && hi.x.is_finite() && wide <= MAX_FAN_TAN) {
            return Err(inside);
        }
        let n = n_cells as f32;
        let pad = |e: f32, floor: f32| {
            ((e * 1.002).max(e + 2.0 * floor) * n / (n - 2.0).max(1.0)).max(e + 2.0 * floor)
        };
        // Depth: from just past the source at most.
        let depth = pad(hi.x - lo.x, 1e-3 * (1.0 + hi.x * 1e-2));
        let mid_x = 0.5 * (lo.x + hi.x);
        let x0 = (mid_x - 0.5 * depth).max(0.5 * lo.x);
        let ds = (mid_x + 0.5 * depth - x0) / n;
        let side = pad((hi.y - lo.y).max(hi.z - lo.z), 1e-5);
        let (mu, mv) = (0.5 * (lo.y + hi.y), 0.5 * (lo.z + hi.z));
        Ok(LightFrame {
            origin: source,
            axes: light_axes(light.axis(anchor)),
            ds,
            n_cells,
            fan: Some(Fan {
                source,
                start: Vec3::new(x0, mu - 0.5 * side, mv - 0.5 * side),
                du: side / n,
            }),
        })
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
        if let Some(source) = light.source() {
            // The fan around a cube of side `size` at `center`.
            let x = (center - source).length();
            let h = 0.5 * size;
            let t = h / (x - h).max(1e-6);
            let extent = Extent {
                lo: Vec3::new(x - h, -t, -t),
                hi: Vec3::new(x + h, t, t),
            };
            return LightFrame::fan(light, source, center, extent, n_cells);
        }
        let axes = light_axes(light.direction());
        let origin = center - 0.5 * size * (axes[0] + axes[1] + axes[2]);
        Ok(LightFrame {
            origin,
            axes,
            ds: size / n_cells as f32,
            n_cells,
            fan: None,
        })
    }

    /// The paper's bound for animated hair: `2 l_max + h_max`.
    pub fn animated_size(l_max: f32, h_max: f32) -> f32 {
        2.0 * l_max + h_max
    }

    /// Continuous map coordinates of `p`, in cells: `(x_map, y_map, z_map) / ds`.
    /// Cell `(i, j, k)` covers `[i, i+1) x [j, j+1) x [k, k+1)`.
    /// For a fan ([`Fan`]), the depth and the tangent-plane coordinates
    /// in cells; a point not in front of the source maps in front of the
    /// map, to `(-3, -3, -3)`, outside it.
    #[inline]
    pub fn to_cells(&self, p: Vec3) -> Vec3 {
        match &self.fan {
            None => self.to_cells_parallel(p),
            Some(f) => {
                let r = p - f.source;
                let x = r.dot(self.axes[0]);
                if x.is_nan() || x <= 0.0 {
                    return BEHIND;
                }
                let inv = x.recip();
                Vec3::new(
                    (x - f.start.x) / self.ds,
                    (r.dot(self.axes[1]) * inv - f.start.y) / f.du,
                    (r.dot(self.axes[2]) * inv - f.start.z) / f.du,
                )
            }
        }
    }

    /// [`Self::to_cells`] of a map of parallel rays (`fan` is `None`): for
    /// loops that have looked at `fan` once.
    #[inline(always)]
    pub fn to_cells_parallel(&self, p: Vec3) -> Vec3 {
        let q = (p - self.origin) * self.ds.recip();
        Vec3::new(
            q.dot(self.axes[0]),
            q.dot(self.axes[1]),
            q.dot(self.axes[2]),
        )
    }

    /// The world position of continuous map coordinates (inverse of [`Self::to_cells`]).
    pub fn to_world(&self, c: Vec3) -> Vec3 {
        match &self.fan {
            None => {
                self.origin
                    + self.ds * (c.x * self.axes[0] + c.y * self.axes[1] + c.z * self.axes[2])
            }
            Some(f) => {
                let x = f.start.x + c.x * self.ds;
                let (u, v) = (f.start.y + c.y * f.du, f.start.z + c.z * f.du);
                f.source + x * (self.axes[0] + u * self.axes[1] + v * self.axes[2])
            }
        }
    }

    /// The width across the rays of a cell at map depth `i` (cells), in
    /// scene units: `ds` for parallel rays, `x du` for a fan, `x` the
    /// depth from the source.
    #[inline]
    pub fn cell_width(&self, i: f32) -> f32 {
        match &self.fan {
            None => self.ds,
            Some(f) => (f.start.x + i * self.ds) * f.du,
        }
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
    /// Smallest coordinate along each axis.
    pub lo: Vec3,
    /// Largest coordinate along each axis.
    pub hi: Vec3,
}

impl Extent {
    /// The extent of no points.
    pub const EMPTY: Extent = Extent {
        lo: Vec3::splat(f32::INFINITY),
        hi: Vec3::splat(f32::NEG_INFINITY),
    };

    /// Whether no point is in it.
    pub fn is_empty(&self) -> bool {
        !(self.lo.cmple(self.hi).all())
    }

    /// The extent of `points` along `light`'s map axes, from `anchor`;
    /// for a light with a source, of their depth and tangent-plane
    /// coordinates from the source (see [`Fan`]; a point not in front of
    /// it makes the low depth 0 or less). Min and max are exact in any
    /// order, so the parallel reduction is deterministic.
    pub fn of(light: &Light, anchor: Vec3, points: &[Vec3]) -> Extent {
        let axes = light_axes(light.axis(anchor));
        if let Some(s) = light.source() {
            return points
                .par_chunks(16 * 1024)
                .map(|chunk| {
                    let mut e = Extent::EMPTY;
                    for &p in chunk {
                        let r = p - s;
                        let x = r.dot(axes[0]);
                        let m = if x > 0.0 {
                            Vec3::new(x, r.dot(axes[1]) / x, r.dot(axes[2]) / x)
                        } else {
                            Vec3::new(x.min(0.0), 0.0, 0.0)
                        };
                        e.lo = e.lo.min(m);
                        e.hi = e.hi.max(m);
                    }
                    e
                })
                .reduce(|| Extent::EMPTY, Extent::union);
        }
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
