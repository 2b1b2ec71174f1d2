//! The light the head sends back into the hair, with multiple scattering.
//!
//! The head is a diffuse surface of albedo `rho` (its colour). Lit through
//! the hair, it sends radiance `L(x) = rho E(x) / pi` back out, `E(x)` the
//! irradiance at its point `x` (each light's, as the head's own shading
//! takes it: [`crate::part::head_lambert`], with the light the hair
//! scatters forward on its way to the head). A path tracer's bounces carry
//! that light into the hair around the head, tinted by the skin: on every
//! groom of the comparisons against Cycles it is a large share of what
//! light hair shows beyond direct light (docs/shading.md).
//!
//! The head is taken as the surface along 12 x 24 directions from its
//! centre `c`: a sphere's, or a mesh's outermost hit along each ray (found
//! once, at rest). Around each direction it is taken as a sphere of the
//! radius `R` there: a hair vertex `p` at distance `d > R` from `c` sees the
//! cap of the head whose directions lie within `beta` of `n_p = (p - c) /
//! d`, `cos beta = R / d`, filling the solid angle
//!
//! ```text
//! Omega = 2 pi (1 - sqrt(1 - (R / d)^2))
//! ```
//!
//! so the head's irradiance there, perpendicular to the direction `-n_p`
//! towards the head, is `E_h = Omega L_cap(n_p, beta)`, `L_cap` the mean
//! radiance of the cap. [`HeadLight`] samples `L` at the surface's points
//! once a frame (none where a ray leaves a mesh through a hole) and
//! averages it over caps of 7 sizes, so a vertex looks `L_cap` up
//! (bilinear over the directions, linear between the sizes).
//!
//! The head's light travels out from the head, through the hair between:
//! the map oriented to that light is a spherical one about the head,
//! whose columns are the sampled directions. [`HeadLight::through_hair`]
//! fills it from the first light's map, which already holds the hair:
//! along each direction, at 48 radii from the surface out past the hair,
//! the extinction `sigma_t` is what the hair of that map adds to its
//! optical depth across a cell along its light, over the cell's length
//! (the cell the head's own deposit enters left out: [`HairIn`]), and one
//! sweep out along the column sums it into the optical depth
//! `tau_h(r) = int sigma_t dr` from the surface. A vertex looks `tau_h`
//! up at its direction and height (bilinear, linear between radii) and
//! gets `E_h` through `T_h = exp(-tau_h')`, `tau_h'` the depth its rays
//! cross on their slanted paths from the whole cone ([`slant_depth`]).
//! The fiber scatters it as light spread over the cone
//! ([`raster::cone_light`]: from the cone's mean angle along the fiber,
//! every lobe widened as the cone is), multiple scattering included.
//!
//! The same columns hold what lies between a vertex and the open sky
//! beyond the hair: the sky's own transmittance there
//! ([`sky_transmittance`]), which no light's map holds (the sky comes
//! from every direction).

use std::f32::consts::PI;
use std::sync::Arc;

use glam::{Mat3A, Vec3};
use rayon::prelude::*;
use shadow::Light;
use strands::Mesh;

// The fiber tables take an optical depth past `raster::BODY_DEPTH` for a
// body in the way of the light (no forward-scattered light past it): the
// shadow crate must deposit bodies deeper than that, and hair alone
// should seldom reach it.
const _: () = assert!(
    raster::BODY_DEPTH < shadow::OPAQUE_DEPTH && raster::BODY_DEPTH > shadow::OPAQUE_DEPTH - 2.0
);

/// Rows of the sampled directions, pole to pole (about `y`).
const N_THETA: usize = 12;
/// Columns of the sampled directions, around `y`.
const N_PHI: usize = 24;
/// The sampled directions.
const DIRECTIONS: usize = N_THETA * N_PHI;
/// Points a side of each direction's cell its radiance is the mean of.
const SUB: usize = 4;
/// Radii a column of the head's map samples, from the surface out.
const RADII: usize = 48;
/// The column's radii run out this many cells of the light's map past
/// the surface: the hair anywhere in that map lies within them.
const REACH_CELLS: f32 = 1.8;
/// Radii nearer the surface than this many of the light map's cells
/// would look the head's own deposit up, where the map is read through
/// its transmittance alone ([`HairIn::Lookup`]).
const CLEAR_CELLS: f32 = 2.5;

/// `cos beta` of the caps the radiance is averaged over, decreasing: from
/// a point (hair on the head, whose horizon hides the rest) to a
/// hemisphere (hair far from it).
const CAPS: [f32; 7] = [1.0, 0.95, 0.85, 0.7, 0.5, 0.25, 0.0];

/// How [`HeadLight::through_hair`] reads the hair in the first light's
/// map.
#[derive(Clone, Copy)]
pub(crate) enum HairIn<'a> {
    /// Its swept map, filtered or not: the hair's own optical depth over
    /// each cell ([`shadow::Transmittance::hair_depth_between`]), the head's
    /// deposit left out, so right down to the surface.
    Swept(&'a shadow::Transmittance, bool),
    /// Its transmittance at drawn points alone (a method that keeps no
    /// swept map), `lookup(points, out)`: the difference of `tau = -ln T`
    /// across a cell, which near the head reads the head's own deposit, so
    /// the radii within [`CLEAR_CELLS`] of it take the first clear one's.
    Lookup(&'a (dyn Fn(&[Vec3], &mut [f32]) + Sync)),
}

/// Where the head's surface lies along each sampled direction from its
/// centre, in the head's own frame (at rest, about the scene's
/// `head.center`): the distance and the outward unit normal; `None`
/// where the ray leaves a mesh through no surface.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Surface {
    at: Vec<Option<(f32, Vec3)>>,
    /// The distances alone, 0 where there is none: what vertices look up.
    radii: Vec<f32>,
}

impl Surface {
    /// A sphere of `radius`.
    pub(crate) fn sphere(radius: f32) -> Surface {
        Surface::new(
            (0..N_THETA)
                .flat_map(|i| (0..N_PHI).map(move |j| direction(i, j).0))
                .map(|n| Some((radius, n)))
                .collect(),
        )
    }

    fn new(at: Vec<Option<(f32, Vec3)>>) -> Surface {
        let radii = at.iter().map(|a| a.map_or(0.0, |(r, _)| r)).collect();
        Surface { at, radii }
    }

    /// `mesh` (at rest), seen from `center`: along each direction the
    /// farthest triangle the ray crosses (Moller-Trumbore), and the
    /// vertex normals there, interpolated, turned outwards.
    pub(crate) fn mesh(mesh: &Mesh, center: Vec3) -> Surface {
        let dirs: Vec<Vec3> = (0..N_THETA)
            .flat_map(|i| (0..N_PHI).map(move |j| direction(i, j).0))
            .collect();
        let (pos, nor) = (mesh.positions(), mesh.normals());
        let at = dirs
            .par_iter()
            .map(|&d| {
                let mut best: Option<(f32, Vec3)> = None;
                for tri in mesh.triangles() {
                    let [a, b, c] = tri.map(|v| pos[v as usize]);
                    let Some((t, u, v)) = shadow::ray_triangle(center, d, a, b, c) else {
                        continue;
                    };
                    if best.is_some_and(|(far, _)| far >= t) {
                        continue;
                    }
                    let [na, nb, nc] = tri.map(|v| nor[v as usize]);
                    let n = (na * (1.0 - u - v) + nb * u + nc * v).normalize_or(d);
                    best = Some((t, if n.dot(d) < 0.0 { -n } else { n }));
                }
                best
            })
            .collect();
        Surface::new(at)
    }

    /// The surface's distance from the centre towards the head's own
    /// direction at grid place `g` (bilinear; 0 where there is none).
    fn radius_at(&self, g: Grid) -> f32 {
        bilinear(g, |i, j| self.radii[i * N_PHI + j])
    }
}

/// Where a direction falls among the sampled ones: rows `i0`, `i1` and
/// the share of the second, columns `j0`, `j1` (wrapping) and the share
/// of the second.
type Grid = ((usize, usize, f32), (usize, usize, f32));

/// `value(row, column)` bilinear at `g`.
#[inline]
fn bilinear<T>(g: Grid, value: impl Fn(usize, usize) -> T) -> T
where
    T: Copy
        + std::ops::Add<Output = T>
        + std::ops::Sub<Output = T>
        + std::ops::Mul<f32, Output = T>,
{
    let ((i0, i1, fu), (j0, j1, fv)) = g;
    let top = value(i0, j0) + (value(i0, j1) - value(i0, j0)) * fv;
    let bottom = value(i1, j0) + (value(i1, j1) - value(i1, j0)) * fv;
    top + (bottom - top) * fu
}

/// `atan2(y, x)` in `[-pi, pi]` to within 0.005 radians (a twentieth of
/// a grid cell), from a polynomial: no library call in the per-vertex
/// path (Rajan et al.'s `pi/4 x + 0.273 x (1 - |x|)` on each octant).
#[inline]
fn atan2_approx(y: f32, x: f32) -> f32 {
    let (ax, ay) = (x.abs(), y.abs());
    if ax == 0.0 && ay == 0.0 {
        return 0.0;
    }
    let (r, swap) = if ay > ax {
        (ax / ay, true)
    } else {
        (ay / ax, false)
    };
    let mut a = r * (0.25 * PI + 0.273 * (1.0 - r));
    if swap {
        a = 0.5 * PI - a;
    }
    if x < 0.0 {
        a = PI - a;
    }
    if y < 0.0 { -a } else { a }
}

/// The sampled directions around `n` (unit).
#[inline]
fn grid(n: Vec3) -> Grid {
    let theta = atan2_approx((n.x * n.x + n.z * n.z).sqrt(), n.y);
    let mut phi = atan2_approx(n.z, n.x);
    if phi < 0.0 {
        phi += 2.0 * PI;
    }
    let u = (theta / PI * N_THETA as f32 - 0.5).clamp(0.0, (N_THETA - 1) as f32);
    let v = phi / (2.0 * PI) * N_PHI as f32 - 0.5;
    let (i0, fu) = (u.floor() as usize, u.fract());
    let i1 = (i0 + 1).min(N_THETA - 1);
    let vf = v.floor();
    let j0 = (vf as i32).rem_euclid(N_PHI as i32) as usize;
    ((i0, i1, fu), (j0, (j0 + 1) % N_PHI, v - vf))
}

/// Steps of the [`slant_depth`] table along `sin alpha` and `sqrt(tau)`.
const SLANT_STEPS: usize = 32;
/// The deepest radial optical depth the table holds (past it, deeper
/// hair takes that depth's ratio).
const SLANT_DEPTH: f32 = 32.0;

/// The optical depth of the hair between a point and the head, for its
/// light as a whole: the point at distance `d` from the head's centre sees
/// the head (radius `R`, `sin alpha = R / d`) over a cone, and a ray at
/// `gamma` from the cone's axis crosses the hair between over a path
/// longer than the radial one, `h = d - R`, by
///
/// ```text
/// k(gamma) = (d cos gamma - sqrt(R^2 - d^2 sin^2 gamma)) / h
///          = (1 + s) / (cos gamma + sqrt(s^2 - sin^2 gamma)),   s = sin alpha
/// ```
///
/// (1 along the axis, `1 / cos gamma` over a flat layer). With the hair's
/// extinction even along the way, the radial depth `tau` becomes `tau k`
/// along each ray, and the head's light, even over the cone's solid
/// angle, arrives as through the depth
///
/// ```text
/// tau_h = -ln < exp(-tau k(gamma)) >
/// ```
///
/// (`E_2(tau)` under a flat layer: at `tau = 1`, 0.15 where the radial
/// path alone lets 0.37 through). Tabulated as `tau_h / tau` once
/// (midpoint rule, uniform in solid angle), looked up bilinear.
pub(crate) fn slant_depth(sin_alpha: f32, tau: f32) -> f32 {
    static TABLE: std::sync::OnceLock<Vec<f32>> = std::sync::OnceLock::new();
    let table = TABLE.get_or_init(|| {
        let mut out = Vec::with_capacity((SLANT_STEPS + 1) * (SLANT_STEPS + 1));
        let n = 256;
        for a in 0..=SLANT_STEPS {
            let s = a as f64 / SLANT_STEPS as f64;
            let ca = (1.0 - s * s).max(0.0).sqrt();
            for k in 0..=SLANT_STEPS {
                let x = k as f64 / SLANT_STEPS as f64;
                let tau = (SLANT_DEPTH as f64 * x * x).max(1e-3);
                let mut sum = 0.0;
                for i in 0..n {
                    // cos gamma uniform over [cos alpha, 1].
                    let cg = ca + (1.0 - ca) * (i as f64 + 0.5) / n as f64;
                    let sg2 = 1.0 - cg * cg;
                    let path = (1.0 + s) / (cg + (s * s - sg2).max(0.0).sqrt()).max(1e-9);
                    sum += (-tau * path).exp();
                }
                let t = (sum / n as f64).max(1e-300);
                out.push((-t.ln() / tau) as f32);
            }
        }
        out
    });
    if tau.is_nan() || tau <= 0.0 {
        return 0.0;
    }
    let x = sin_alpha.clamp(0.0, 1.0) * SLANT_STEPS as f32;
    let y = (tau / SLANT_DEPTH).min(1.0).sqrt() * SLANT_STEPS as f32;
    let (a, k) = (
        (x as usize).min(SLANT_STEPS - 1),
        (y as usize).min(SLANT_STEPS - 1),
    );
    let (fa, fk) = (x - a as f32, y - k as f32);
    let at = |a: usize, k: usize| table[a * (SLANT_STEPS + 1) + k];
    let top = at(a, k) + (at(a, k + 1) - at(a, k)) * fk;
    let bottom = at(a + 1, k) + (at(a + 1, k + 1) - at(a + 1, k)) * fk;
    tau * (top + (bottom - top) * fa)
}

/// The head as it stands in a frame: its centre, its frame, and its
/// surface about its centre.
#[derive(Debug, Clone)]
pub(crate) struct HeadShape {
    center: Vec3,
    /// The head's own frame from the world's, and back (the pose's linear
    /// part).
    to_own: Mat3A,
    from_own: Mat3A,
    surface: Arc<Surface>,
}

impl HeadShape {
    /// The head whose centre stands at `center`, turned by `from_own`
    /// (its pose's linear part), of `surface` about its centre at rest.
    pub(crate) fn new(center: Vec3, from_own: Mat3A, surface: Arc<Surface>) -> HeadShape {
        HeadShape {
            center,
            to_own: from_own.inverse(),
            from_own,
            surface,
        }
    }

    /// A sphere at `center` of `radius`, unturned.
    #[cfg(test)]
    fn sphere(center: Vec3, radius: f32) -> HeadShape {
        HeadShape {
            center,
            to_own: Mat3A::IDENTITY,
            from_own: Mat3A::IDENTITY,
            surface: Arc::new(Surface::sphere(radius)),
        }
    }

    /// `p` in the head's own frame, about its centre: the unit direction
    /// and the distance (`None` at the centre or not finite).
    fn own(&self, p: Vec3) -> Option<(Vec3, f32)> {
        let v = self.to_own * (p - self.center);
        let d = v.length();
        (d > 1e-6 && d.is_finite()).then(|| (v / d, d))
    }
}

/// The head's light on the hair around it, for one frame.
#[derive(Debug, Clone)]
pub(crate) struct HeadLight {
    shape: HeadShape,
    /// Per cap size and sampled direction, the mean radiance of the cap
    /// around that direction: `[cap][direction]`, linear RGB.
    caps: Vec<Vec3>,
    /// The hair's optical depth from the surface out along each sampled
    /// direction, at [`RADII`] heights `reach (j / (RADII - 1))^2`:
    /// `[direction][j]`; empty until [`Self::through_hair`].
    depth: Vec<f32>,
    /// The height of the last radius.
    reach: f32,
}

/// The sampled direction of row `i` and column `j`, and its row's share
/// of the sphere's area (`sin theta`).
fn direction(i: usize, j: usize) -> (Vec3, f32) {
    direction_at(i as f32, j as f32)
}

/// [`direction`] at a fractional row and column.
fn direction_at(i: f32, j: f32) -> (Vec3, f32) {
    let theta = (i + 0.5) * PI / N_THETA as f32;
    let phi = (j + 0.5) * 2.0 * PI / N_PHI as f32;
    let (st, ct) = theta.sin_cos();
    let (sp, cp) = phi.sin_cos();
    (Vec3::new(st * cp, ct, st * sp), st)
}

/// What a vertex gets of the head's light ([`HeadLight::through_at`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Through {
    /// The head's irradiance `E_h` across the vertex (linear RGB).
    pub(crate) e: Vec3,
    /// Its transmittance `T_h` through the hair between.
    pub(crate) t: f32,
    /// `sin alpha` of the cone the head fills.
    pub(crate) sin_alpha: f32,
    /// The sky's transmittance `T_sky` ([`sky_transmittance`]), once the
    /// head's map holds the hair.
    pub(crate) sky: Option<f32>,
}

impl Through {
    /// None of the head's light, and no sky's transmittance known.
    pub(crate) const NONE: Through = Through {
        e: Vec3::ZERO,
        t: 1.0,
        sin_alpha: 0.0,
        sky: None,
    };

    /// `self` and `b` mixed linearly (`f` of the way to `b`).
    pub(crate) fn lerp(self, b: Through, f: f32) -> Through {
        let mix = |a: f32, b: f32| a + (b - a) * f;
        Through {
            e: self.e + (b.e - self.e) * f,
            t: mix(self.t, b.t),
            sin_alpha: mix(self.sin_alpha, b.sin_alpha),
            sky: match (self.sky, b.sky) {
                (Some(x), Some(y)) => Some(mix(x, y)),
                (x, y) => x.or(y),
            },
        }
    }
}

/// The sky's transmittance at a point of the hair about the head, from
/// the head's map: the radial optical depth `tau_in` between the point
/// and the head, and `tau_out` between it and the open sky beyond the
/// hair. The sky's light comes from every direction; taking the hair
/// about the point as a flat layer along the head's surface, a ray at
/// `gamma` from the normal crosses `tau / cos gamma` of it, and the outer
/// half of the sky comes through `tau_out`, the inner half (the head's
/// cone of it taken off apart, [`crate::part`]) through `tau_in`, each
/// as `E_2(tau) = < exp(-tau / cos gamma) >` over its hemisphere
/// ([`slant_depth`] at `sin alpha = 1`):
///
/// ```text
/// T_sky = (E_2(tau_out) + E_2(tau_in)) / 2
/// ```
///
/// (1 in free space, 1/2 on the head's bare surface).
pub(crate) fn sky_transmittance(tau_in: f32, tau_out: f32) -> f32 {
    let half = |tau: f32| (-slant_depth(1.0, tau)).exp();
    0.5 * (half(tau_out) + half(tau_in))
}

/// The sky's transmittance at a point of the head's bare surface under a
/// flat layer of hair of optical depth `tau` (along the surface's
/// normal): the sky's irradiance there is cosine-weighted over the
/// hemisphere over it, so, with `E_n` the exponential integrals,
///
/// ```text
/// T_surface = 2 E_3(tau) = exp(-tau) - tau E_2(tau)
/// ```
///
/// (1 with no hair; at `tau = 1`, 0.22).
pub(crate) fn surface_sky_transmittance(tau: f32) -> f32 {
    if tau.is_nan() || tau <= 0.0 {
        return 1.0;
    }
    let e2 = (-slant_depth(1.0, tau)).exp();
    ((-tau).exp() - tau * e2).clamp(0.0, 1.0)
}

impl HeadLight {
    /// The head `shape`, of radiance `radiance(x, n)` ([`Self::caps_of`]).
    #[cfg(test)]
    pub(crate) fn new(shape: HeadShape, radiance: impl Fn(Vec3, Vec3) -> Vec3) -> HeadLight {
        let mut light = HeadLight::unlit(shape);
        light.caps = light.caps_of(radiance);
        light
    }

    /// The head `shape`, sending no light until [`Self::light_with`]: its
    /// map ([`Self::through_hair`]) may be filled first, for the sky over
    /// the head ([`Self::sky_over`]) that its radiance holds.
    pub(crate) fn unlit(shape: HeadShape) -> HeadLight {
        HeadLight {
            shape,
            caps: vec![Vec3::ZERO; CAPS.len() * DIRECTIONS],
            depth: Vec::new(),
            reach: 0.0,
        }
    }

    /// Sets the head's light: [`Self::caps_of`] its radiance.
    pub(crate) fn light_with(&mut self, caps: Vec<Vec3>) {
        debug_assert_eq!(caps.len(), CAPS.len() * DIRECTIONS);
        self.caps = caps;
    }

    /// The mean radiance over each cap of each sampled direction (see the
    /// module's notes) of the head of radiance `radiance(x, n)` at its
    /// point `x` of outward normal `n` (world; linear RGB, as the head is
    /// shaded; asked at each sampled point once): what
    /// [`Self::light_with`] takes.
    pub(crate) fn caps_of(&self, radiance: impl Fn(Vec3, Vec3) -> Vec3) -> Vec<Vec3> {
        let shape = &self.shape;
        let dirs: Vec<(Vec3, f32)> = (0..N_THETA)
            .flat_map(|i| (0..N_PHI).map(move |j| direction(i, j)))
            .collect();
        // Each direction's radiance, the mean of SUB x SUB points over its
        // cell of directions (the surface there taken at the cell's
        // distance, its normal turned with the direction): a lit parting
        // narrower than a cell counts for the share of the cell it is.
        let l: Vec<Vec3> = shape
            .surface
            .at
            .iter()
            .enumerate()
            .map(|(k, at)| {
                let Some((r, n)) = *at else {
                    return Vec3::ZERO;
                };
                let (d, _) = direction(k / N_PHI, k % N_PHI);
                let (mut sum, mut w) = (Vec3::ZERO, 0.0f32);
                for a in 0..SUB {
                    for b in 0..SUB {
                        let (i, j) = (k / N_PHI, k % N_PHI);
                        let sub = |x: usize| (x as f32 + 0.5) / SUB as f32 - 0.5;
                        let (ds, area) = direction_at(i as f32 + sub(a), j as f32 + sub(b));
                        let turn = glam::Quat::from_rotation_arc(d, ds);
                        let x = shape.center + shape.from_own * (r * ds);
                        let m = (shape.from_own * (turn * n)).normalize_or(n);
                        let c = radiance(x, m);
                        if c.is_finite() {
                            sum += area * c.max(Vec3::ZERO);
                        }
                        w += area;
                    }
                }
                sum / w
            })
            .collect();
        let mut caps = Vec::with_capacity(CAPS.len() * DIRECTIONS);
        for &cos_beta in &CAPS {
            for &(n, _) in &dirs {
                let (mut sum, mut w) = (Vec3::ZERO, 0.0f32);
                for (&(m, area), &lm) in dirs.iter().zip(&l) {
                    // The direction itself is always in its cap.
                    if n.dot(m) >= cos_beta - 1e-5 {
                        sum += area * lm;
                        w += area;
                    }
                }
                caps.push(sum / w);
            }
        }
        caps
    }

    /// Fills the head's map from the hair in the map of `light` (cells
    /// of `cell` scene units, `cells` a side), read as `hair` says.
    pub(crate) fn through_hair(&mut self, light: &Light, cell: f32, cells: u32, hair: HairIn<'_>) {
        let reach = REACH_CELLS * cell * cells as f32;
        let height = |j: usize| reach * (j as f32 / (RADII - 1) as f32).powi(2);
        let shape = &self.shape;
        // The radii's points, and half a cell along the light at each.
        let mut points = Vec::with_capacity(DIRECTIONS * RADII);
        for (k, at) in shape.surface.at.iter().enumerate() {
            let (d, _) = direction(k / N_PHI, k % N_PHI);
            let r = at.map_or(0.0, |(r, _)| r);
            for j in 0..RADII {
                let x = shape.center + shape.from_own * ((r + height(j)) * d);
                points.push((x, light.direction_at(x) * (0.5 * cell)));
            }
        }
        // The extinction `sigma_t` at each, over the cell about it along
        // the light; and the first radius whose value is the hair's alone.
        let (sigma, clear): (Vec<f32>, usize) = match hair {
            HairIn::Swept(map, trilinear) => (
                points
                    .iter()
                    .map(|&(x, u)| map.hair_depth_between(x - u, x + u, trilinear) / cell)
                    .collect(),
                0,
            ),
            HairIn::Lookup(lookup) => {
                let pairs: Vec<Vec3> = points.iter().flat_map(|&(x, u)| [x - u, x + u]).collect();
                let mut t = vec![0.0; pairs.len()];
                lookup(&pairs, &mut t);
                let tau = |t: f32| -t.max(1e-30).ln();
                let sigma = t
                    .chunks_exact(2)
                    .map(|t| (tau(t[1]) - tau(t[0])).max(0.0) / cell)
                    .collect();
                // Radii too near the head take the first clear one's.
                let clear = (0..RADII)
                    .find(|&j| height(j) >= CLEAR_CELLS * cell)
                    .unwrap_or(RADII - 1);
                (sigma, clear)
            }
        };
        self.depth.clear();
        for k in 0..DIRECTIONS {
            let sigma = |j: usize| sigma[k * RADII + j.max(clear)];
            let mut sum = 0.0f32;
            self.depth.push(0.0);
            for j in 1..RADII {
                // The trapezoid rule between radii.
                sum += 0.5 * (sigma(j - 1) + sigma(j)) * (height(j) - height(j - 1));
                self.depth.push(sum);
            }
        }
        self.reach = reach;
    }

    /// At `p`: the unit direction towards the head's centre, the head's
    /// irradiance `E_h` across it (linear RGB), and the height of `p`
    /// over the head's surface (0 inside). `None` at the centre, or where
    /// no surface lies below `p`.
    #[cfg(test)]
    fn at(&self, p: Vec3) -> Option<(Vec3, Vec3, f32)> {
        let (_, e, _, height) = self.light(p)?;
        Some(((self.shape.center - p).normalize_or_zero(), e, height))
    }

    /// The head's light at `p` through the hair between (after
    /// [`Self::through_hair`]; unattenuated before), and the sky's
    /// transmittance there.
    #[inline]
    pub(crate) fn through_at(&self, p: Vec3) -> Option<Through> {
        let (g, e, s, height) = self.light(p)?;
        if self.depth.is_empty() || self.reach <= 0.0 {
            return Some(Through {
                e,
                t: 1.0,
                sin_alpha: s,
                sky: None,
            });
        }
        // The radius index of the height: j = (RADII - 1) sqrt(h / reach).
        let x = (RADII - 1) as f32 * (height / self.reach).min(1.0).sqrt();
        let (j, f) = ((x as usize).min(RADII - 2), x.fract());
        let f = if x >= (RADII - 1) as f32 { 1.0 } else { f };
        // The depth up to `p`, and through all of the hair.
        let depths = bilinear(g, |i, jj| {
            let col = &self.depth[(i * N_PHI + jj) * RADII..][..RADII];
            glam::Vec2::new(col[j] + (col[j + 1] - col[j]) * f, col[RADII - 1])
        });
        let (tau, total) = (depths.x, depths.y);
        Some(Through {
            e,
            t: (-slant_depth(s, tau)).exp(),
            sin_alpha: s,
            sky: Some(sky_transmittance(tau, (total - tau).max(0.0))),
        })
    }

    /// The sky's transmittance at `p` on the head's surface, through the
    /// hair of the head's map over it ([`surface_sky_transmittance`]):
    /// `None` before [`Self::through_hair`], at the centre, or where no
    /// surface lies in `p`'s direction.
    pub(crate) fn sky_over(&self, p: Vec3) -> Option<f32> {
        if self.depth.is_empty() {
            return None;
        }
        let (n, _) = self.shape.own(p)?;
        let g = grid(n);
        let r = self.shape.surface.radius_at(g);
        if r.is_nan() || r <= 0.0 {
            return None;
        }
        let total = bilinear(g, |i, j| self.depth[(i * N_PHI + j) * RADII + RADII - 1]);
        Some(surface_sky_transmittance(total))
    }

    /// At `p`: where its direction falls among the sampled ones, the
    /// head's irradiance `E_h`, `sin alpha` of the cone the head fills (=
    /// `cos beta` of the cap it sees) and the height over the surface.
    #[inline]
    fn light(&self, p: Vec3) -> Option<(Grid, Vec3, f32, f32)> {
        let (n, d) = self.shape.own(p)?;
        let g = grid(n);
        let r = self.shape.surface.radius_at(g);
        if r.is_nan() || r <= 0.0 {
            return None;
        }
        let s = (r / d).min(1.0);
        let omega = 2.0 * PI * (1.0 - (1.0 - s * s).max(0.0).sqrt());
        Some((g, omega * self.cap(g, s), s, (d - r).max(0.0)))
    }

    /// The head's centre now.
    pub(crate) fn center(&self) -> Vec3 {
        self.shape.center
    }

    /// The mean radiance over the cap of directions within `acos(cos_beta)`
    /// of the head's own direction at grid place `g`.
    fn cap(&self, g: Grid, cos_beta: f32) -> Vec3 {
        // Between which cap sizes, and how far.
        let c = CAPS
            .windows(2)
            .position(|w| cos_beta >= w[1])
            .unwrap_or(CAPS.len() - 2);
        let t = ((CAPS[c] - cos_beta) / (CAPS[c] - CAPS[c + 1])).clamp(0.0, 1.0);
        let at = |c: usize| bilinear(g, |i, j| self.caps[c * DIRECTIONS + i * N_PHI + j]);
        let (a, b) = (at(c), at(c + 1));
        a + (b - a) * t
    }
}

#[cfg(test)]
mod tests;
