//! Multiple scattering between fibers: the dual-scattering approximation of
//! Zinke, Yuksel, Weber and Keyser, "Dual Scattering Approximation for Fast
//! Multiple Scattering in Hair" (2008), on the fiber of [`super::Chiang`],
//! with the paper's symbols.
//!
//! Light reaching a point `x` inside hair met fibers on its way from the
//! light. Part of it never met one: the *direct fraction*, the
//! transmittance `T = exp(-tau)` the shadow stages give, `tau` the optical
//! depth of the density map. The fibers a ray meets are scattered at
//! random along it, at one per unit of `tau` on average, so the number `K`
//! it met is Poisson of mean `tau`; at each, a fraction `a_f` of the light
//! goes on forward (the global part). The paper's product of `a_f` over
//! the fibers in front, averaged over `K`, is
//!
//! ```text
//! T_f = E[a_f^K] = exp(-tau (1 - a_f(theta_i)))   (forward-scattering transmittance)
//! sigma_f^2 = tau beta_f^2                         (its longitudinal spread, radians^2)
//! ```
//!
//! (`T_f` includes the direct light, `K = 0`); of it `T_f - T` arrives
//! scattered, from directions spread around the light's: longitudinally by
//! `sigma_f^2`, and across the fiber evenly over the half circle around
//! the light's azimuth. Around `x`, the neighbours scatter part of what
//! they receive back to it (the local part), `A_b` in all, in a lobe of
//! shift `Delta_b` and variance `sigma_b^2`. With the paper's density
//! factors `d_f` and `d_b`, the radiance towards `w_o` per unit
//! irradiance from the light is
//!
//! ```text
//! L = T (f_s + d_b f_back)  +  d_f max(T_f - T, 0) (f_s^G + d_b f_back^G)
//! ```
//!
//! with `f_s` the fiber's single scattering (the [`super::FiberTable`]),
//! `f_s^G` the same with each lobe's variance widened by `sigma_f^2` and
//! its azimuthal part averaged over the half circle (`N_p^G`), and
//! `f_back` the back-scattering lobe, spread evenly over the back half of
//! the azimuths (`|phi| < pi / 2`, towards the light's side, where the
//! light the hair behind sends back comes out; the edge smoothed over
//! `|cos phi| < 0.2`, [`back_azimuth`]):
//!
//! ```text
//! f_back = A_b M(theta_i - Delta_b, theta_o; sigma_b^2) N_b(phi),  N_b = 1 / pi on the back half
//! ```
//!
//! `M` is the fiber model's own normalized longitudinal lobe, so that each
//! term carries into the outgoing directions just the energy it stands
//! for (the paper writes its lobes as Gaussians in `theta_h` with
//! `1 / cos^2 theta_d`; the energy is the same). `f_back^G` widens
//! `sigma_b^2` by `sigma_f^2`.
//!
//! The averages over the fiber's lobes, per `theta_i`, as the paper
//! defines them (`a` the energy a lobe sends into a hemisphere around the
//! fiber, forward `f` or backward `b` of the light, `s_p` and `v_p` a
//! lobe's shift and variance):
//!
//! ```text
//! a_f, a_b          sums of the lobes' energies per hemisphere
//! alpha_X, beta_X^2 the lobes' s_p and v_p weighted by their energies
//! A_b     = A_1 + A_3,  A_1 = a_b a_f^2 / (1 - a_f^2),  A_3 = a_b^3 a_f^2 / (1 - a_f^2)^3
//! Delta_b = alpha_b (1 - 2 a_b^2 / (1 - a_f^2)^2)
//!         + alpha_f (2 (1 - a_f^2)^2 + 4 a_f^2 a_b^2) / (1 - a_f^2)^3
//! sigma_b = (1 + d_b a_f^2) (A_1 sqrt(2 beta_f^2 + beta_b^2) + A_3 sqrt(2 beta_f^2 + 3 beta_b^2)) / (A_1 + A_3)
//! ```
//!
//! (`sigma_b` weights the paths that turn back once and three times by
//! the energies they carry, `A_1` and `A_3`; the paper's printed weights
//! `a_b` and `a_b^3 (2 beta_f + 3 beta_b)` add an angle to a fraction.)
//! `A_b` is per colour channel; the lobe's shape (`Delta_b`, `sigma_b`)
//! follows the channels' mean.
//!
//! **The energy sent back, `A_b`.** The paper's `A_1 + A_3` counts the
//! paths that turn back once or three times, going as deep as they come
//! back. Here `A_b` is the multiply scattered part of what a deep layer of
//! fibers sends back by the two-stream (Kubelka-Munk) equations along the
//! light, every path counted: per unit of optical depth, the light going
//! in loses `k = 1 - a_f` and feeds `s = a_b` into the light coming out,
//! and the other way round, which gives the reflectance
//!
//! ```text
//! R = (k - mu) / s = s / (k + mu),   mu = sqrt(k^2 - s^2)
//! A_b = R - s / 2
//! ```
//!
//! `s / 2` being the light turned back once by a fiber it reached
//! unscattered, each fiber's own single scattering, which `f_s` already
//! shades.  In black hair (`a_f` near 0) `A_b` is then near 0; in blond
//! hair it is 1.4 times the paper's in red.

use std::f32::consts::PI;

use glam::{Vec3, Vec3A, Vec4};

use super::{
    FarField, FiberOptics, P_MAX, SKY_THETA, cell, gauss_legendre, longitudinal, node, over_sphere,
    safe_sqrt,
};

/// `d_f`: the forward-scattering density factor, the paper's 0.7 for
/// human hair. Against Cycles with 16 bounces whose scattered light meets
/// the fibers as the shadow's does, the hair's gain is within 10 % with
/// it on 16 settings (docs/shading.md).
pub const DENSITY_FORWARD: f32 = 0.7;
/// `d_b`: the back-scattering density factor (as `d_f`).
pub const DENSITY_BACK: f32 = 0.7;

/// `|cos phi|` below which the back lobe's azimuthal spread goes smoothly
/// from the back half of the azimuths to none.
const BACK_EDGE: f32 = 0.2;

/// `N_b(phi)`, the back-scattering lobe's azimuthal spread at `cos phi`:
/// `1 / pi` on the back half (`cos phi > 0`, the light's side), 0 on the
/// front, a smoothstep between over `|cos phi| < BACK_EDGE`. It integrates
/// to 1 over the circle: the smoothstep is odd about `cos phi = 0`.
#[inline]
pub(super) fn back_azimuth(cos_phi: f32) -> f32 {
    let x = ((cos_phi + BACK_EDGE) / (2.0 * BACK_EDGE)).clamp(0.0, 1.0);
    x * x * (3.0 - 2.0 * x) / PI
}

/// The deepest optical depth taken from a transmittance (`T` below
/// `exp(-MAX_DEPTH)` counts as that).
pub const MAX_DEPTH: f32 = 200.0;

/// The optical depth from which an opaque body (a head) is taken to stand
/// between the light and a point: the shadow crate deposits a body 30
/// deep. Light a body stops is not scattered on by hair: past it there is
/// no forward-scattered light, only what the transmittance lets through.
pub const BODY_DEPTH: f32 = 29.0;

/// Nodes along `sin theta_i` of the per-angle averages.
const DUAL_THETA: usize = 33;
/// Nodes along `sin theta_o` and `cos phi` of `N_p^G`.
const NG_THETA: usize = 17;
const NG_PHI: usize = 17;
/// Nodes along `sin theta_i` and `sin theta_o` of the widened
/// longitudinal lobes, and along the optical depth (evenly in
/// `sqrt(tau)` up to [`SPREAD_DEPTH`]): 25 x 25 x 12 nodes of 32 bytes,
/// 240 kB, small enough to share a core's cache with the fiber table.
const SPREAD_THETA: usize = 25;
const SPREAD_DEPTH_NODES: usize = 12;
/// The deepest optical depth whose spread is tabulated: past it, the
/// forward-scattered light of the lightest hair (`a_f` < 0.8) is below
/// `exp(-0.2 * 32)`, a six-hundredth of the light, and its lobes are
/// taken as wide as there.
const SPREAD_DEPTH: f32 = 32.0;

/// The averages at one `theta_i`.
#[derive(Debug, Clone, Copy, Default)]
struct Averages {
    a_f: Vec3A,
    a_b: Vec3A,
    /// `1 - a_f`.
    rest_f: Vec3A,
    /// `A_b`.
    a_back: Vec3A,
    beta_f2: f32,
    delta_b: f32,
    sigma_b2: f32,
}

/// What dual scattering needs of one fiber, tabulated: the averages per
/// `theta_i` and `N_p^G` per `theta_o` and `phi`.
#[derive(Debug, Clone)]
pub struct DualTable {
    at: Vec<Averages>,
    /// `N_p^G` of each lobe: `[(o * NG_PHI + k)]`.
    ng: Vec<[Vec3A; P_MAX + 1]>,
    /// `N_p` of each lobe on the same nodes (not spread).
    np: Vec<[Vec3A; P_MAX + 1]>,
    /// [`Self::sky`] at `(k * SPREAD_DEPTH_NODES + d)`: sky node `k`,
    /// depth node `d`.
    sky: Vec<Vec3A>,
    /// Each lobe's shift `s_p` (radians: its peak is at
    /// `theta_i + theta_o = s_p`) and variance `v_p`.
    shift: [f32; P_MAX + 1],
    var: [f32; P_MAX + 1],
    /// The longitudinal lobes widened by the spread at each depth:
    /// `[(i * SPREAD_THETA + o) * SPREAD_DEPTH_NODES + d]`.
    spread: Vec<Spread>,
}

/// The longitudinal lobes at one node: each single-scattering lobe's
/// `M_p` widened by `sigma_f^2`, and the back-scattering lobe's `M`
/// widened (`back.x`) and not (`back.y`).
#[derive(Debug, Clone, Copy, Default)]
struct Spread {
    lobes: Vec4,
    back: Vec4,
}

/// The optical depth at spread node `d`.
fn depth_node(d: usize) -> f32 {
    let s = d as f32 / (SPREAD_DEPTH_NODES - 1) as f32;
    SPREAD_DEPTH * s * s
}

/// The optical depth `tau = -ln T` in front of a point of transmittance
/// `t`: 0 in full light (or for a `t` that is not a number), at most
/// [`MAX_DEPTH`].
pub fn optical_depth(t: f32) -> f32 {
    if t.is_nan() || t >= 1.0 {
        return 0.0;
    }
    (-t.max(0.0).ln()).clamp(0.0, MAX_DEPTH)
}

/// The spread node at or below optical depth `tau` and the position
/// past it, evenly in `sqrt(tau)` as the nodes are ([`depth_node`]).
#[inline]
fn depth_cell(tau: f32) -> (usize, f32) {
    let top = (SPREAD_DEPTH_NODES - 1) as f32;
    let f = ((tau / SPREAD_DEPTH).clamp(0.0, 1.0).sqrt() * top).min(top - 1e-3);
    (f as usize, f - f.floor())
}

/// Of a transmittance `t` from a light (the direct fraction; 1 if not a
/// number), with the averages `a` at its angle: `t` in [0, 1], its
/// optical depth `tau`, and the light scattered forward that arrives
/// besides, `max(T_f - t, 0)` (none in full light or past a body).
#[inline]
fn direct_and_forward(a: &Averages, t: f32) -> (f32, f32, Vec3) {
    let t = if t.is_finite() {
        t.clamp(0.0, 1.0)
    } else {
        1.0
    };
    let tau = optical_depth(t);
    let forward = if tau > 0.0 && tau < BODY_DEPTH {
        let t_f = Vec3::from((a.rest_f * -tau).exp());
        (t_f - Vec3::splat(t)).max(Vec3::ZERO)
    } else {
        Vec3::ZERO
    };
    (t, tau, forward)
}

/// Gauss-Legendre nodes and weights on [a, b].
fn quadrature(n: usize, a: f32, b: f32) -> Vec<(f32, f32)> {
    let (m, r) = (0.5 * (a + b), 0.5 * (b - a));
    gauss_legendre(n)
        .into_iter()
        .map(|(x, w)| (m + r * x, r * w))
        .collect()
}

impl DualTable {
    /// The table of fiber `o` (a few milliseconds).
    pub fn new(o: &FiberOptics) -> DualTable {
        use rayon::prelude::*;
        let far = FarField::of(o);
        let var = super::Chiang::new(o, 0.0).variances();
        let alpha = o.alpha_deg.to_radians();
        // Peaks at theta_i + theta_o = s_p: R -2 alpha, TT alpha, TRT
        // 4 alpha (see Chiang::lobes); the rest is not tilted.
        let shift = [-2.0 * alpha, alpha, 4.0 * alpha, 0.0];
        // The lobes' energies into the back (|phi| < pi/2) and forward
        // half of azimuths: the energy single scattering sends, per unit
        // of the light the fiber receives,
        //   e_p = int M_p cos^2 theta_o dtheta_o / cos theta_i  int_half A_p N_p dphi,
        // the azimuthal part taken on the specular cone (theta_o =
        // -theta_i), where the longitudinal lobe has most of its weight.
        let back = quadrature(32, 0.0, 0.5 * PI);
        let fwd = quadrature(32, 0.5 * PI, PI);
        let along = quadrature(96, -0.5 * PI, 0.5 * PI);
        let at = (0..DUAL_THETA)
            .into_par_iter()
            .map(|i| {
                let ui = node(i, DUAL_THETA).clamp(-0.999, 0.999);
                let ci = safe_sqrt(1.0 - ui * ui);
                let longitudinal_share = |p: usize| {
                    along
                        .iter()
                        .map(|&(theta_o, w)| {
                            let (uo, co) = theta_o.sin_cos();
                            w * lobe(ui, uo, shift[p], var[p]) * co * co
                        })
                        .sum::<f32>()
                        / ci
                };
                let m: Vec<f32> = (0..=P_MAX).map(longitudinal_share).collect();
                let half = |q: &[(f32, f32)]| {
                    let mut e = [Vec3::ZERO; P_MAX + 1];
                    for &(phi, w) in q {
                        // Both signs of phi: the far field is even in it.
                        let a = far.azimuthal(-ui, phi);
                        let b = far.azimuthal(-ui, -phi);
                        for p in 0..=P_MAX {
                            e[p] += w * m[p] * (a[p] + b[p]);
                        }
                    }
                    e
                };
                averages(&half(&back), &half(&fwd), &shift, &var)
            })
            .collect();
        // N_p^G(theta_o, phi) = 1/pi int_{-pi/2}^{pi/2} N_p(theta_o, phi + u) du.
        let spread = quadrature(32, -0.5 * PI, 0.5 * PI);
        let ng = (0..NG_THETA * NG_PHI)
            .into_par_iter()
            .map(|c| {
                let uo = node(c / NG_PHI, NG_THETA);
                let phi = node(c % NG_PHI, NG_PHI).clamp(-1.0, 1.0).acos();
                let mut sum = [Vec3A::ZERO; P_MAX + 1];
                for &(u, w) in &spread {
                    for (s, l) in sum.iter_mut().zip(far.azimuthal(uo, phi + u)) {
                        *s += Vec3A::from(l * (w / PI));
                    }
                }
                sum
            })
            .collect();
        let np = (0..NG_THETA * NG_PHI)
            .into_par_iter()
            .map(|c| {
                let uo = node(c / NG_PHI, NG_THETA);
                let phi = node(c % NG_PHI, NG_PHI).clamp(-1.0, 1.0).acos();
                far.azimuthal(uo, phi).map(Vec3A::from)
            })
            .collect();
        let mut table = DualTable {
            at,
            ng,
            np,
            sky: Vec::new(),
            shift,
            var,
            spread: Vec::new(),
        };
        table.spread = (0..SPREAD_THETA * SPREAD_THETA * SPREAD_DEPTH_NODES)
            .into_par_iter()
            .map(|c| {
                let d = c % SPREAD_DEPTH_NODES;
                let o = (c / SPREAD_DEPTH_NODES) % SPREAD_THETA;
                let i = c / (SPREAD_DEPTH_NODES * SPREAD_THETA);
                table.spread_at(node(i, SPREAD_THETA), node(o, SPREAD_THETA), depth_node(d))
            })
            .collect();
        let single = super::FiberTable::new(o);
        table.sky = (0..SKY_THETA * SPREAD_DEPTH_NODES)
            .into_par_iter()
            .map(|c| {
                let (uo, t) = (
                    node(c / SPREAD_DEPTH_NODES, SKY_THETA),
                    (-depth_node(c % SPREAD_DEPTH_NODES)).exp(),
                );
                Vec3A::from(over_sphere(|ui, cp| {
                    table.radiance(single.radiance(ui, uo, cp), t, ui, uo, cp)
                }))
            })
            .collect();
        table
    }

    /// The radiance towards `sin theta_o = uo` under a sky of unit
    /// radiance from every direction, at transmittance `t` from it (the
    /// direct fraction, as [`Self::radiance`] takes it), multiply
    /// scattered light included: `int L(w_i, w_o) dw_i` over the sphere,
    /// `L` [`Self::radiance`] with the fiber's single scattering (at
    /// `t = 1`, [`super::FiberTable::sky`] and the light the hair behind
    /// sends back).
    pub fn sky(&self, uo: f32, t: f32) -> Vec3 {
        let (k, tk) = cell(uo, SKY_THETA);
        let tau = optical_depth(if t.is_finite() { t } else { 1.0 });
        let (d, td) = depth_cell(tau);
        let at = |k: usize| {
            let row = &self.sky[k * SPREAD_DEPTH_NODES + d..];
            row[0] + (row[1] - row[0]) * td
        };
        let (a, b) = (at(k), at(k + 1));
        let v = Vec3::from(a + (b - a) * tk);
        // Past the deepest node, what passes straight through goes on
        // falling with it.
        if tau > SPREAD_DEPTH {
            v * (SPREAD_DEPTH - tau).exp()
        } else {
            v
        }
    }

    /// The lobes of [`Spread`] at `sin theta_i = ui`, `sin theta_o = uo`
    /// and optical depth `tau`, evaluated.
    fn spread_at(&self, ui: f32, uo: f32, tau: f32) -> Spread {
        let a = self.averages(ui);
        let spread = tau * a.beta_f2;
        let m = |p: usize| lobe(ui, uo, self.shift[p], self.var[p] + spread);
        Spread {
            lobes: Vec4::new(m(0), m(1), m(2), m(3)),
            back: Vec4::new(
                lobe(ui, uo, a.delta_b, a.sigma_b2 + spread),
                lobe(ui, uo, a.delta_b, a.sigma_b2),
                0.0,
                0.0,
            ),
        }
    }

    /// [`Spread`] interpolated (trilinear weights).
    #[inline]
    fn spread(&self, ui: f32, uo: f32, tau: f32) -> Spread {
        let (i, ti) = cell(ui, SPREAD_THETA);
        let (o, to) = cell(uo, SPREAD_THETA);
        let (d, td) = depth_cell(tau);
        let at = |i: usize, o: usize| {
            let k = (i * SPREAD_THETA + o) * SPREAD_DEPTH_NODES + d;
            let (a, b) = (&self.spread[k], &self.spread[k + 1]);
            (
                a.lobes + (b.lobes - a.lobes) * td,
                a.back + (b.back - a.back) * td,
            )
        };
        let mix =
            |(a, b): (Vec4, Vec4), (c, d): (Vec4, Vec4), t: f32| (a + (c - a) * t, b + (d - b) * t);
        let near = mix(at(i, o), at(i, o + 1), to);
        let far = mix(at(i + 1, o), at(i + 1, o + 1), to);
        let (lobes, back) = mix(near, far, ti);
        Spread { lobes, back }
    }

    fn averages(&self, ui: f32) -> Averages {
        let (i, t) = cell(ui, DUAL_THETA);
        let (a, b) = (&self.at[i], &self.at[i + 1]);
        let mix = |x: Vec3A, y: Vec3A| x + (y - x) * t;
        let mixf = |x: f32, y: f32| x + (y - x) * t;
        Averages {
            a_f: mix(a.a_f, b.a_f),
            a_b: mix(a.a_b, b.a_b),
            rest_f: mix(a.rest_f, b.rest_f),
            a_back: mix(a.a_back, b.a_back),
            beta_f2: mixf(a.beta_f2, b.beta_f2),
            delta_b: mixf(a.delta_b, b.delta_b),
            sigma_b2: mixf(a.sigma_b2, b.sigma_b2),
        }
    }

    /// `a_f` and `a_b` at `sin theta_i = ui`: the fractions of the light a
    /// fiber scatters forward and backward.
    pub fn attenuations(&self, ui: f32) -> (Vec3, Vec3) {
        let a = self.averages(ui);
        (a.a_f.into(), a.a_b.into())
    }

    /// `A_b`, `Delta_b` and `sigma_b^2` at `sin theta_i = ui`.
    pub fn back_scattering(&self, ui: f32) -> (Vec3, f32, f32) {
        let a = self.averages(ui);
        (a.a_back.into(), a.delta_b, a.sigma_b2)
    }

    /// `T_f`: the light that reaches a point of transmittance `t` from a
    /// light at `sin theta_i = ui`, directly or scattered forward by the
    /// fibers in front, `exp(-tau (1 - a_f))` with `tau = -ln t`.
    pub fn forward_transmittance(&self, t: f32, ui: f32) -> Vec3 {
        let tau = optical_depth(t);
        if tau >= BODY_DEPTH {
            return Vec3::splat(t.clamp(0.0, 1.0));
        }
        Vec3::from((self.averages(ui).rest_f * -tau).exp())
    }

    /// `N_p^G` at `sin theta_o = uo` and `cos phi`.
    pub fn azimuthal_spread(&self, uo: f32, cos_phi: f32) -> [Vec3; P_MAX + 1] {
        azimuthal_at(&self.ng, uo, cos_phi)
    }

    /// `N_p` at `sin theta_o = uo` and `cos phi`, from the same nodes as
    /// [`Self::azimuthal_spread`].
    fn azimuthal_point(&self, uo: f32, cos_phi: f32) -> [Vec3; P_MAX + 1] {
        azimuthal_at(&self.np, uo, cos_phi)
    }

    /// The back-scattering lobe `f_back` widened by `spread` (radians^2),
    /// towards `sin theta_o = uo` and `cos phi` from `sin theta_i = ui`.
    pub fn back_lobe(&self, ui: f32, uo: f32, cos_phi: f32, spread: f32) -> Vec3 {
        let a = self.averages(ui);
        Vec3::from(a.a_back) * lobe(ui, uo, a.delta_b, a.sigma_b2 + spread) * back_azimuth(cos_phi)
    }

    /// The radiance towards `w_o` per unit irradiance from the light with
    /// multiple scattering, at a point of transmittance `t` (the direct
    /// fraction): `single` is the fiber's single scattering there
    /// ([`super::FiberTable::radiance`]), `ui`, `uo` and `cos_phi` the
    /// directions as for it.
    pub fn radiance(&self, single: Vec3, t: f32, ui: f32, uo: f32, cos_phi: f32) -> Vec3 {
        let a = self.averages(ui);
        let a_back = Vec3::from(a.a_back) * (DENSITY_BACK * back_azimuth(cos_phi));
        let (t, tau, forward) = direct_and_forward(&a, t);
        let m = self.spread(ui, uo, tau);
        let mut l = t * (single + a_back * m.back.y);
        if forward.max_element() > 0.0 {
            let ng = self.azimuthal_spread(uo, cos_phi);
            let single_g =
                ng[0] * m.lobes.x + ng[1] * m.lobes.y + ng[2] * m.lobes.z + ng[3] * m.lobes.w;
            l += DENSITY_FORWARD * forward * (single_g + a_back * m.back.x);
        }
        debug_assert!(l.is_finite(), "{l}");
        l
    }

    /// [`Self::radiance`] for light that arrives spread about its
    /// direction, as from a lit surface filling a cone: along the fiber
    /// over a variance `spread` (radians^2) of `theta_i`, and across it
    /// over the half circle of azimuths about the light's for a share
    /// `across` of it (the rest along the light's azimuth). Every lobe is
    /// widened by `spread`, the forward-scattered light's by its own
    /// spread as well; without the single-scattering table's narrow
    /// lobes, whose peak a light of one direction has and a spread one
    /// has not. One radiance for each transmittance of `t`, sharing the
    /// lookups.
    pub fn radiance_spread<const N: usize>(
        &self,
        t: [f32; N],
        (ui, uo, cos_phi): (f32, f32, f32),
        spread: f32,
        across: f32,
    ) -> [Vec3; N] {
        let a = self.averages(ui);
        let a_back = Vec3::from(a.a_back) * (DENSITY_BACK * back_azimuth(cos_phi));
        // The spread as the depth whose forward scattering spreads as much.
        let tau_c = spread.max(0.0) / a.beta_f2.max(1e-4);
        let (ng, np) = (
            self.azimuthal_spread(uo, cos_phi),
            self.azimuthal_point(uo, cos_phi),
        );
        let w = across.clamp(0.0, 1.0);
        let n: [Vec3; P_MAX + 1] = std::array::from_fn(|p| np[p] + (ng[p] - np[p]) * w);
        let dot =
            |n: &[Vec3; P_MAX + 1], m: Vec4| n[0] * m.x + n[1] * m.y + n[2] * m.z + n[3] * m.w;
        let m = self.spread(ui, uo, tau_c);
        let direct = dot(&n, m.lobes) + a_back * m.back.x;
        // Each transmittance: what the lookups above share, and its own
        // forward-scattered light.
        t.map(|t| {
            let (t, tau, forward) = direct_and_forward(&a, t);
            let mut l = t * direct;
            if forward.max_element() > 0.0 {
                let m = self.spread(ui, uo, tau_c + tau);
                l += DENSITY_FORWARD * forward * (dot(&ng, m.lobes) + a_back * m.back.x);
            }
            debug_assert!(l.is_finite(), "{l}");
            l
        })
    }

    /// [`Self::radiance`] with every lobe evaluated rather than looked up
    /// (what the table is tested against).
    #[cfg(test)]
    pub(super) fn radiance_exact(
        &self,
        single: Vec3,
        t: f32,
        ui: f32,
        uo: f32,
        cos_phi: f32,
    ) -> Vec3 {
        let a = self.averages(ui);
        let a_back = Vec3::from(a.a_back);
        let back = |spread: f32| {
            a_back * lobe(ui, uo, a.delta_b, a.sigma_b2 + spread) * back_azimuth(cos_phi)
        };
        let (t, tau, forward) = direct_and_forward(&a, t);
        let mut l = t * (single + DENSITY_BACK * back(0.0));
        if forward.max_element() > 0.0 {
            let spread = tau * a.beta_f2;
            let ng = self.azimuthal_spread(uo, cos_phi);
            let mut single_g = Vec3::ZERO;
            for (p, n) in ng.iter().enumerate() {
                single_g += *n * lobe(ui, uo, self.shift[p], self.var[p] + spread);
            }
            l += DENSITY_FORWARD * forward * (single_g + DENSITY_BACK * back(spread));
        }
        debug_assert!(l.is_finite(), "{l}");
        l
    }
}

/// An azimuthal table on the nodes of `N_p^G` at `sin theta_o = uo` and
/// `cos phi` (bilinear).
fn azimuthal_at(table: &[[Vec3A; P_MAX + 1]], uo: f32, cos_phi: f32) -> [Vec3; P_MAX + 1] {
    let (o, to) = cell(uo, NG_THETA);
    let (k, tk) = cell(cos_phi, NG_PHI);
    let at = |o: usize, k: usize| &table[o * NG_PHI + k];
    let mut out = [Vec3::ZERO; P_MAX + 1];
    for (p, v) in out.iter_mut().enumerate() {
        let a = at(o, k)[p] + (at(o, k + 1)[p] - at(o, k)[p]) * tk;
        let b = at(o + 1, k)[p] + (at(o + 1, k + 1)[p] - at(o + 1, k)[p]) * tk;
        *v = (a + (b - a) * to).into();
    }
    out
}

/// The fiber model's longitudinal lobe of variance `v` peaking at
/// `theta_i + theta_o = shift`, for `sin theta_i = ui`, `sin theta_o = uo`.
fn lobe(ui: f32, uo: f32, shift: f32, v: f32) -> f32 {
    let ci = safe_sqrt(1.0 - ui * ui);
    let co = safe_sqrt(1.0 - uo * uo);
    // theta_i - shift.
    let (ss, cs) = shift.sin_cos();
    let sin_ip = ui * cs - ci * ss;
    let cos_ip = (ci * cs + ui * ss).abs();
    longitudinal(cos_ip, co, sin_ip, uo, v.clamp(1e-4, 1e4))
}

/// `A_b`: the light a deep layer of fibers, each sending `a_f` on and
/// `a_b` back of what it meets, sends back scattered more than once: the
/// two-stream reflectance less single scattering (see the module's
/// notes), `R = s / (k + mu)` (stable as `s -> 0`) less `s / 2`.
pub(super) fn multiple_back(a_f: Vec3, a_b: Vec3) -> Vec3 {
    let (k, s) = (Vec3::ONE - a_f, a_b);
    let mu = (k * k - s * s).max(Vec3::ZERO).powf(0.5);
    (s / (k + mu).max(Vec3::splat(1e-6)) - 0.5 * s).max(Vec3::ZERO)
}

/// The averages at one angle from each lobe's energies into the back and
/// forward halves.
fn averages(
    back: &[Vec3; P_MAX + 1],
    fwd: &[Vec3; P_MAX + 1],
    shift: &[f32; P_MAX + 1],
    var: &[f32; P_MAX + 1],
) -> Averages {
    // No more than the fiber received (the longitudinal share can pass 1
    // where light comes nearly along the fiber).
    let (mut a_b, mut a_f): (Vec3, Vec3) = (back.iter().copied().sum(), fwd.iter().copied().sum());
    let excess = (a_b + a_f).max(Vec3::ONE);
    a_b /= excess;
    a_f /= excess;
    // Energy-weighted shift and variance of a half's lobes (by the
    // channels' mean energy).
    let weighted = |e: &[Vec3; P_MAX + 1]| {
        let w: Vec<f32> = e.iter().map(|x| x.element_sum() / 3.0).collect();
        let total: f32 = w.iter().sum::<f32>().max(1e-12);
        let s = (0..=P_MAX).map(|p| w[p] * shift[p]).sum::<f32>() / total;
        let v = (0..=P_MAX).map(|p| w[p] * var[p]).sum::<f32>() / total;
        (s, v)
    };
    let (alpha_f, beta_f2) = weighted(fwd);
    let (alpha_b, beta_b2) = weighted(back);
    let a_back = multiple_back(a_f, a_b);
    // The lobe's shape from the channels' mean: A_1 and A_3.
    let (af, ab) = (a_f.element_sum() / 3.0, a_b.element_sum() / 3.0);
    let (af2, ab2) = (af * af, ab * ab);
    let r = (1.0 - af2).max(1e-4);
    let delta_b = alpha_b * (1.0 - 2.0 * ab2 / (r * r))
        + alpha_f * (2.0 * r * r + 4.0 * af2 * ab2) / (r * r * r);
    let (m1, m3) = (ab * af2 / r, ab * ab2 * af2 / (r * r * r));
    let width1 = (2.0 * beta_f2 + beta_b2).sqrt();
    let width3 = (2.0 * beta_f2 + 3.0 * beta_b2).sqrt();
    let sigma_b = if m1 + m3 > 0.0 {
        (1.0 + DENSITY_BACK * af2) * (m1 * width1 + m3 * width3) / (m1 + m3)
    } else {
        width1
    };
    Averages {
        a_f: a_f.into(),
        a_b: a_b.into(),
        rest_f: (Vec3::ONE - a_f).into(),
        a_back: a_back.into(),
        beta_f2,
        // Bounded: the formula's terms grow without bound as a_f -> 1.
        delta_b: delta_b.clamp(-0.5 * PI, 0.5 * PI),
        sigma_b2: (sigma_b * sigma_b).min(PI * PI),
    }
}
