//! Physically based scattering from a hair fiber: the model of Chiang,
//! Bitterli, Tappan and Burley, "A Practical and Controllable Hair and Fur
//! Model for Production Path Tracing" (2016), in the formulation pbrt-v4's
//! `HairBxDF` implements (itself after Marschner et al. 2003 and d'Eon et
//! al. 2011), with its symbols.
//!
//! A fiber is a dielectric cylinder of index of refraction `eta` whose
//! interior absorbs `sigma_a` per unit of its diameter. Light leaving it
//! took `p` internal paths: `p = 0` reflects at the surface (R), `p = 1`
//! goes through (TT), `p = 2` reflects once inside (TRT), and one more
//! term sums every longer path. Each lobe is a product
//!
//! ```text
//! f_p(w_o, w_i) = M_p(theta_o, theta_i) A_p(theta_o, h) N_p(phi, h) / |cos theta_i|
//! ```
//!
//! of a longitudinal lobe `M_p` (d'Eon's normalized von Mises-Fisher-like
//! lobe of variance `v_p`, set from the longitudinal roughness `beta_m`,
//! its direction tilted by the cuticle's scales, `alpha`), the attenuation
//! `A_p` (Fresnel reflectance and absorption along the path) and an
//! azimuthal lobe `N_p` (a trimmed logistic of scale `s`, set from the
//! azimuthal roughness `beta_n`, around the deflection `Phi(p, h)`). `h` in
//! [-1, 1] is where across the fiber the ray meets it.
//!
//! Directions are in the fiber's frame: `x` along the fiber, `y` and `z`
//! across it; `sin theta = w.x`, `phi = atan2(w.z, w.y)`.
//!
//! [`FarField`] averages the model over `h` (a fiber seen from afar, thinner
//! than a pixel), which is what a strand drawn as a line needs.

use std::f32::consts::PI;

use glam::{Vec3, Vec3A};

/// Internal paths modelled one by one (R, TT, TRT); the term after them
/// sums all longer ones.
pub const P_MAX: usize = 3;

/// `sqrt(pi / 8)`.
const SQRT_PI_OVER_8: f32 = 0.626_657_07;

/// Absorption coefficients of eumelanin and pheomelanin per unit
/// concentration, per unit of the fiber's diameter (RGB), as pbrt uses
/// them (after d'Eon et al. 2011).
const EUMELANIN_SIGMA_A: Vec3 = Vec3::new(0.419, 0.697, 1.37);
const PHEOMELANIN_SIGMA_A: Vec3 = Vec3::new(0.187, 0.4, 1.05);

/// How a fiber scatters: the settings of [`Chiang`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FiberOptics {
    /// Index of refraction of the fiber (1.55 for keratin).
    pub eta: f32,
    /// Absorption coefficient `sigma_a` per unit of the fiber's diameter,
    /// RGB (see [`sigma_a_from_melanin`], [`sigma_a_from_color`]).
    pub sigma_a: Vec3,
    /// Longitudinal roughness `beta_m` in (0, 1].
    pub beta_m: f32,
    /// Azimuthal roughness `beta_n` in (0, 1].
    pub beta_n: f32,
    /// Tilt of the cuticle's scales, `alpha`, in degrees (about 2).
    pub alpha_deg: f32,
}

impl Default for FiberOptics {
    /// Dark brown hair (eumelanin concentration 1.3), pbrt's defaults.
    fn default() -> FiberOptics {
        FiberOptics {
            eta: 1.55,
            sigma_a: sigma_a_from_melanin(1.3, 0.0),
            beta_m: 0.3,
            beta_n: 0.3,
            alpha_deg: 2.0,
        }
    }
}

impl FiberOptics {
    /// Whether every setting is in its range (finite, `eta > 1`,
    /// `sigma_a >= 0`, roughnesses in (0, 1], `|alpha| < 45` degrees).
    pub fn is_valid(&self) -> bool {
        self.eta.is_finite()
            && self.eta > 1.0
            && self.sigma_a.is_finite()
            && self.sigma_a.cmpge(Vec3::ZERO).all()
            && self.beta_m > 0.0
            && self.beta_m <= 1.0
            && self.beta_n > 0.0
            && self.beta_n <= 1.0
            && self.alpha_deg.abs() < 45.0
    }
}

/// `sigma_a` of a fiber with eumelanin and pheomelanin concentrations
/// `eumelanin` and `pheomelanin` (0 to about 8: blond hair is about 0.3
/// eumelanin, brown 1.3, black 8; red hair has pheomelanin).
pub fn sigma_a_from_melanin(eumelanin: f32, pheomelanin: f32) -> Vec3 {
    eumelanin.max(0.0) * EUMELANIN_SIGMA_A + pheomelanin.max(0.0) * PHEOMELANIN_SIGMA_A
}

/// `sigma_a` of a fiber whose hair, many fibers deep, looks of colour
/// `color` (linear RGB in (0, 1]) at azimuthal roughness `beta_n`: Chiang
/// et al.'s fit, eq. 9,
/// `sigma_a = (ln c / (5.969 - 0.215 b + 2.532 b^2 - 10.73 b^3 + 5.574 b^4 + 0.245 b^5))^2`.
pub fn sigma_a_from_color(color: Vec3, beta_n: f32) -> Vec3 {
    let d = color_fit(beta_n);
    let c = color.clamp(Vec3::splat(1e-4), Vec3::ONE);
    let l = Vec3::new(c.x.ln(), c.y.ln(), c.z.ln()) / d;
    l * l
}

/// The colour of hair whose fibers absorb `sigma_a`, at azimuthal
/// roughness `beta_n`: the inverse of [`sigma_a_from_color`],
/// `c = exp(-sqrt(sigma_a) d(beta_n))`.
pub fn color_from_sigma_a(sigma_a: Vec3, beta_n: f32) -> Vec3 {
    let d = color_fit(beta_n);
    let s = sigma_a.max(Vec3::ZERO);
    Vec3::new(
        (-s.x.sqrt() * d).exp(),
        (-s.y.sqrt() * d).exp(),
        (-s.z.sqrt() * d).exp(),
    )
}

/// Chiang et al.'s polynomial `d(beta_n)` of eq. 9.
fn color_fit(b: f32) -> f32 {
    5.969 - 0.215 * b + 2.532 * b.powi(2) - 10.73 * b.powi(3)
        + 5.574 * b.powi(4)
        + 0.245 * b.powi(5)
}

/// The model at one offset `h` across the fiber.
#[derive(Debug, Clone, Copy)]
pub struct Chiang {
    h: f32,
    /// `gamma_o = asin h`.
    gamma_o: f32,
    eta: f32,
    sigma_a: Vec3,
    /// Longitudinal variance of each lobe.
    v: [f32; P_MAX + 1],
    /// Azimuthal logistic scale.
    s: f32,
    /// `sin(2^k alpha)`, `cos(2^k alpha)` for k = 0, 1, 2.
    sin_2k_alpha: [f32; 3],
    cos_2k_alpha: [f32; 3],
}

impl Chiang {
    /// The model of fiber `o` at offset `h` in [-1, 1].
    pub fn new(o: &FiberOptics, h: f32) -> Chiang {
        debug_assert!(o.is_valid() && (-1.0..=1.0).contains(&h));
        let bm = o.beta_m;
        // Longitudinal variance from beta_m (Chiang et al., eq. 7); TT is
        // narrower, TRT and beyond wider.
        let v0 = (0.726 * bm + 0.812 * bm * bm + 3.7 * bm.powi(20)).powi(2);
        let v = [v0, 0.25 * v0, 4.0 * v0, 4.0 * v0];
        // Azimuthal logistic scale from beta_n (eq. 8).
        let bn = o.beta_n;
        let s = SQRT_PI_OVER_8 * (0.265 * bn + 1.194 * bn * bn + 5.372 * bn.powi(22));
        let mut sin_2k_alpha = [0.0; 3];
        let mut cos_2k_alpha = [0.0; 3];
        sin_2k_alpha[0] = o.alpha_deg.to_radians().sin();
        cos_2k_alpha[0] = safe_sqrt(1.0 - sin_2k_alpha[0] * sin_2k_alpha[0]);
        for i in 1..3 {
            sin_2k_alpha[i] = 2.0 * cos_2k_alpha[i - 1] * sin_2k_alpha[i - 1];
            cos_2k_alpha[i] = cos_2k_alpha[i - 1].powi(2) - sin_2k_alpha[i - 1].powi(2);
        }
        Chiang {
            h,
            gamma_o: safe_asin(h),
            eta: o.eta,
            sigma_a: o.sigma_a,
            v,
            s,
            sin_2k_alpha,
            cos_2k_alpha,
        }
    }

    /// The model's value `f(w_o, w_i)` (pbrt's convention: with the
    /// `1 / |cos theta_i|`, so that outgoing radiance is the integral of
    /// `f L_i |cos theta_i|`), as its lobes R, TT, TRT and the rest.
    pub fn lobes(&self, wo: Vec3, wi: Vec3) -> [Vec3; P_MAX + 1] {
        let sin_theta_o = wo.x.clamp(-1.0, 1.0);
        let phi_o = wo.z.atan2(wo.y);
        let sin_theta_i = wi.x.clamp(-1.0, 1.0);
        let cos_theta_i = safe_sqrt(1.0 - sin_theta_i * sin_theta_i);
        let phi_i = wi.z.atan2(wi.y);
        let inv_cos_i = if cos_theta_i > 0.0 {
            1.0 / cos_theta_i
        } else {
            0.0
        };
        let m = self.longitudinal(sin_theta_i, sin_theta_o);
        let a = self.azimuthal(sin_theta_o, phi_i - phi_o);
        let mut out = [Vec3::ZERO; P_MAX + 1];
        for p in 0..=P_MAX {
            out[p] = m[p] * a[p] * inv_cos_i;
            debug_assert!(out[p].is_finite());
        }
        out
    }

    /// `M_p(theta_o, theta_i)` of each lobe (R, TT, TRT, the rest): the
    /// part of the model that does not depend on `h`. `theta_i` is tilted
    /// by the scales: R's by 2 alpha, TT's by -alpha and TRT's by -4 alpha
    /// (the lobes' peaks move the other way); the rest is not tilted.
    pub fn longitudinal(&self, sin_theta_i: f32, sin_theta_o: f32) -> [f32; P_MAX + 1] {
        let sin_theta_i = sin_theta_i.clamp(-1.0, 1.0);
        let cos_theta_i = safe_sqrt(1.0 - sin_theta_i * sin_theta_i);
        let sin_theta_o = sin_theta_o.clamp(-1.0, 1.0);
        let cos_theta_o = safe_sqrt(1.0 - sin_theta_o * sin_theta_o);
        let mut out = [0.0; P_MAX + 1];
        for (p, o) in out.iter_mut().enumerate().take(P_MAX) {
            let (sa, ca) = match p {
                0 => (self.sin_2k_alpha[1], self.cos_2k_alpha[1]),
                1 => (-self.sin_2k_alpha[0], self.cos_2k_alpha[0]),
                _ => (-self.sin_2k_alpha[2], self.cos_2k_alpha[2]),
            };
            let sin_theta_ip = sin_theta_i * ca + cos_theta_i * sa;
            let cos_theta_ip = (cos_theta_i * ca - sin_theta_i * sa).abs();
            *o = longitudinal(
                cos_theta_ip,
                cos_theta_o,
                sin_theta_ip,
                sin_theta_o,
                self.v[p],
            );
        }
        out[P_MAX] = longitudinal(
            cos_theta_i,
            cos_theta_o,
            sin_theta_i,
            sin_theta_o,
            self.v[P_MAX],
        );
        out
    }

    /// `f(w_o, w_i)`: the sum of [`Self::lobes`].
    pub fn f(&self, wo: Vec3, wi: Vec3) -> Vec3 {
        self.lobes(wo, wi).iter().copied().sum()
    }

    /// `A_p(theta_o, h) N_p(phi, h)` of each lobe at `sin theta_o` and
    /// azimuth `phi = phi_i - phi_o`: the lobes without their longitudinal
    /// part (the last, all longer paths, spread evenly, `A_p / 2 pi`).
    pub fn azimuthal(&self, sin_theta_o: f32, phi: f32) -> [Vec3; P_MAX + 1] {
        let sin_theta_o = sin_theta_o.clamp(-1.0, 1.0);
        let cos_theta_o = safe_sqrt(1.0 - sin_theta_o * sin_theta_o);
        let (ap, gamma_t) = self.paths(sin_theta_o, cos_theta_o);
        let mut out = [Vec3::ZERO; P_MAX + 1];
        for (p, o) in out.iter_mut().enumerate().take(P_MAX) {
            *o = ap[p] * azimuthal(phi, p, self.s, self.gamma_o, gamma_t);
        }
        out[P_MAX] = ap[P_MAX] / (2.0 * PI);
        out
    }

    /// `A_p` of every lobe for light leaving at `theta_o`, and the
    /// refracted ray's `gamma_t`.
    fn paths(&self, sin_theta_o: f32, cos_theta_o: f32) -> ([Vec3; P_MAX + 1], f32) {
        // The refracted ray's theta_t and gamma_t (Bravais' modified index
        // eta' for the projection across the fiber).
        let sin_theta_t = sin_theta_o / self.eta;
        let cos_theta_t = safe_sqrt(1.0 - sin_theta_t * sin_theta_t);
        let etap = (self.eta * self.eta - sin_theta_o * sin_theta_o).sqrt() / cos_theta_o.max(1e-6);
        let sin_gamma_t = self.h / etap;
        let cos_gamma_t = safe_sqrt(1.0 - sin_gamma_t * sin_gamma_t);
        let gamma_t = safe_asin(sin_gamma_t);
        // One pass through the interior: T = exp(-sigma_a 2 cos gamma_t / cos theta_t).
        let path = 2.0 * cos_gamma_t / cos_theta_t.max(1e-6);
        let t = Vec3::new(
            (-self.sigma_a.x * path).exp(),
            (-self.sigma_a.y * path).exp(),
            (-self.sigma_a.z * path).exp(),
        );
        (attenuation(cos_theta_o, self.eta, self.h, t), gamma_t)
    }

    /// The variance `v_p` of each lobe's longitudinal part.
    pub fn variances(&self) -> [f32; P_MAX + 1] {
        self.v
    }
}

/// The model averaged over the offset `h` across the fiber, `1/2 int f dh`
/// (Gauss-Legendre quadrature): a fiber seen whole, as a strand drawn
/// thinner than a pixel is.
#[derive(Debug, Clone)]
pub struct FarField {
    at: Vec<(Chiang, f32)>,
}

impl FarField {
    /// Fiber `o` averaged with `n` Gauss-Legendre nodes in `h` across it
    /// (1 to 4096). [`FarField::nodes`] says how many are enough.
    pub fn new(o: &FiberOptics, n: usize) -> FarField {
        let at = gauss_legendre(n.clamp(1, 4096))
            .into_iter()
            .map(|(x, w)| (Chiang::new(o, x), 0.5 * w))
            .collect();
        FarField { at }
    }

    /// The fiber `o` averaged with [`FarField::nodes`] nodes.
    pub fn of(o: &FiberOptics) -> FarField {
        FarField::new(o, FarField::nodes(o))
    }

    /// Nodes across the fiber that bring the average of `A_p N_p` within
    /// about 0.1 % of its limit: `4 / s`, `s` the azimuthal logistic's
    /// scale, at least 32, a multiple of 8. Across the fiber the
    /// deflection `Phi(p, h)` sweeps a lobe's whole circle, fastest near
    /// the edges (`gamma_o = asin h`), so the integrand has bumps of width
    /// `s` in `gamma_o`: measured against 20,000 nodes, at `beta_n = 0.3`
    /// (s = 0.12) 8 nodes were 48 % off at worst, 16 were 5 %, 32 were
    /// 0.1 %; at `beta_n = 0.15` 64 were 0.5 % and 96 0.02 %.
    pub fn nodes(o: &FiberOptics) -> usize {
        let s = Chiang::new(o, 0.0).s;
        let n = (4.0 / s).ceil().min(4096.0) as usize;
        n.next_multiple_of(8).clamp(32, 4096)
    }

    /// The scattering by lobe (R, TT, TRT, the rest) from `wi` to `wo`,
    /// averaged across the fiber, per channel.
    pub fn lobes(&self, wo: Vec3, wi: Vec3) -> [Vec3; P_MAX + 1] {
        let mut out = [Vec3::ZERO; P_MAX + 1];
        for (c, w) in &self.at {
            for (o, l) in out.iter_mut().zip(c.lobes(wo, wi)) {
                *o += *w * l;
            }
        }
        out
    }

    /// The scattering function from `wi` to `wo` averaged across the
    /// fiber: the sum of [`Self::lobes`].
    pub fn f(&self, wo: Vec3, wi: Vec3) -> Vec3 {
        self.lobes(wo, wi).iter().copied().sum()
    }

    /// [`Chiang::azimuthal`] averaged across the fiber.
    pub fn azimuthal(&self, sin_theta_o: f32, phi: f32) -> [Vec3; P_MAX + 1] {
        let mut out = [Vec3::ZERO; P_MAX + 1];
        for (c, w) in &self.at {
            for (o, l) in out.iter_mut().zip(c.azimuthal(sin_theta_o, phi)) {
                *o += *w * l;
            }
        }
        out
    }
}

/// `A_p`: the fraction of light taking path `p`, from the Fresnel
/// reflectance at the first hit and `t`, one pass through the interior;
/// the last term sums every longer path (a geometric series).
fn attenuation(cos_theta_o: f32, eta: f32, h: f32, t: Vec3) -> [Vec3; P_MAX + 1] {
    let cos_gamma_o = safe_sqrt(1.0 - h * h);
    let f = fresnel_dielectric(cos_theta_o * cos_gamma_o, eta);
    let mut ap = [Vec3::ZERO; P_MAX + 1];
    ap[0] = Vec3::splat(f);
    ap[1] = (1.0 - f) * (1.0 - f) * t;
    for p in 2..P_MAX {
        ap[p] = ap[p - 1] * t * f;
    }
    let rest = Vec3::ONE - t * f;
    ap[P_MAX] = ap[P_MAX - 1] * f * t / rest.max(Vec3::splat(1e-6));
    ap
}

/// `M_p`: d'Eon et al.'s longitudinal lobe of variance `v`,
/// `exp(-sin_i sin_o / v) I0(cos_i cos_o / v) / (2 v sinh(1 / v))`,
/// in logarithms where `v` is small enough for it to overflow.
fn longitudinal(cos_i: f32, cos_o: f32, sin_i: f32, sin_o: f32, v: f32) -> f32 {
    let a = cos_i * cos_o / v;
    let b = sin_i * sin_o / v;
    let mp = if v <= 0.1 {
        (log_i0(a) - b - 1.0 / v + std::f32::consts::LN_2 + (1.0 / (2.0 * v)).ln()).exp()
    } else {
        ((-b).exp() * i0(a)) / ((1.0 / v).sinh() * 2.0 * v)
    };
    debug_assert!(mp.is_finite());
    mp
}

/// The modified Bessel function of the first kind, order 0, by its series
/// `sum x^(2i) / (4^i (i!)^2)`: to 24 terms (pbrt stops at 10, which
/// falls 2 % short at x = 12, where [`log_i0`] switches to its asymptotic
/// form, and loses as much of a narrow lobe's energy; 24 terms are within
/// 1e-7 there).
fn i0(x: f32) -> f32 {
    let (mut val, mut term) = (0.0f32, 1.0f32);
    let x2 = x * x;
    for i in 0..24 {
        if i > 0 {
            term *= x2 / (4.0 * (i * i) as f32);
        }
        val += term;
    }
    val
}

/// `ln I0(x)`: its asymptotic expansion past 12.
fn log_i0(x: f32) -> f32 {
    if x > 12.0 {
        x + 0.5 * (-(2.0 * PI).ln() + (1.0 / x).ln() + 1.0 / (8.0 * x))
    } else {
        i0(x).ln()
    }
}

/// `N_p`: a logistic of scale `s` trimmed to [-pi, pi], around the
/// azimuthal deflection `Phi(p) = 2 p gamma_t - 2 gamma_o + p pi`.
fn azimuthal(phi: f32, p: usize, s: f32, gamma_o: f32, gamma_t: f32) -> f32 {
    let deflection = 2.0 * p as f32 * gamma_t - 2.0 * gamma_o + p as f32 * PI;
    let mut dphi = phi - deflection;
    // Into [-pi, pi].
    dphi -= (2.0 * PI) * ((dphi + PI) / (2.0 * PI)).floor();
    trimmed_logistic(dphi, s)
}

fn trimmed_logistic(x: f32, s: f32) -> f32 {
    let logistic = |x: f32| {
        let e = (-x.abs() / s).exp();
        e / (s * (1.0 + e) * (1.0 + e))
    };
    let cdf = |x: f32| 1.0 / (1.0 + (-x / s).exp());
    logistic(x) / (cdf(PI) - cdf(-PI))
}

/// Fresnel reflectance of unpolarized light meeting a dielectric of
/// relative index `eta` at `cos_i` to its normal.
fn fresnel_dielectric(cos_i: f32, eta: f32) -> f32 {
    let cos_i = cos_i.clamp(-1.0, 1.0);
    let (cos_i, eta) = if cos_i < 0.0 {
        (-cos_i, 1.0 / eta)
    } else {
        (cos_i, eta)
    };
    let sin2_t = (1.0 - cos_i * cos_i) / (eta * eta);
    if sin2_t >= 1.0 {
        return 1.0;
    }
    let cos_t = safe_sqrt(1.0 - sin2_t);
    let r_parl = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
    let r_perp = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
    0.5 * (r_parl * r_parl + r_perp * r_perp)
}

fn safe_sqrt(x: f32) -> f32 {
    x.max(0.0).sqrt()
}

fn safe_asin(x: f32) -> f32 {
    x.clamp(-1.0, 1.0).asin()
}

/// Gauss-Legendre nodes and weights on [-1, 1] (Newton's method on the
/// Legendre polynomial from Chebyshev guesses; weights sum to 2).
fn gauss_legendre(n: usize) -> Vec<(f32, f32)> {
    let mut out = Vec::with_capacity(n);
    for i in 0..n {
        let mut x = (PI as f64 * (i as f64 + 0.75) / (n as f64 + 0.5)).cos();
        let mut dp = 1.0;
        for _ in 0..100 {
            // P_n(x) and P_n'(x) by the recurrence.
            let (mut p0, mut p1) = (1.0f64, x);
            for k in 2..=n {
                let k = k as f64;
                let p2 = ((2.0 * k - 1.0) * x * p1 - (k - 1.0) * p0) / k;
                p0 = p1;
                p1 = p2;
            }
            let pn = if n == 1 { x } else { p1 };
            let pn1 = if n == 1 { 1.0 } else { p0 };
            dp = n as f64 * (x * pn - pn1) / (x * x - 1.0);
            let dx = pn / dp;
            x -= dx;
            if dx.abs() < 1e-15 {
                break;
            }
        }
        let w = 2.0 / ((1.0 - x * x) * dp * dp);
        out.push((x as f32, w as f32));
    }
    out
}

mod cone;
mod dual;
#[cfg(test)]
mod tests;

pub use cone::{ConeLight, cone_light};
pub use dual::{BODY_DEPTH, DENSITY_BACK, DENSITY_FORWARD, DualTable, MAX_DEPTH, optical_depth};

/// [`FarField`] tabulated for shading many vertices: the radiance a fiber
/// sends towards `w_o` per unit irradiance from `w_i`,
/// `f(w_o, w_i) |cos theta_i|` averaged across the fiber, on a grid of
/// `sin theta_i`, `sin theta_o` and `cos phi` (the far-field model is even
/// in `phi`), RGB, looked up with trilinear weights.
#[derive(Debug, Clone)]
pub struct FiberTable {
    /// In SIMD lanes: the seven interpolations of a lookup run a vector
    /// at a time (about a third faster than `Vec3`).
    values: Vec<Vec3A>,
    /// [`Self::sky`] at `SKY_THETA` nodes of `sin theta_o`.
    sky: Vec<Vec3A>,
}

/// Nodes along `sin theta_o` of the fibers' light from a uniform sky.
const SKY_THETA: usize = 17;

/// A node of `n` evenly spaced over [-1, 1], and the cell and position
/// in it of `x`.
fn node(k: usize, n: usize) -> f32 {
    -1.0 + 2.0 * k as f32 / (n - 1) as f32
}

#[inline]
fn cell(x: f32, n: usize) -> (usize, f32) {
    let top = (n - 1) as f32;
    let f = ((x + 1.0) * (0.5 * top)).clamp(0.0, top - 1e-3);
    let k = f as usize;
    (k, f - k as f32)
}

/// `int g(w) dw` over the sphere of directions about a fiber (`u = sin
/// theta` along it, `dw = du dphi`): Gauss-Legendre in `u`, midpoint in
/// `phi` over the half circle (the fiber is even in `phi`), `g(u, cos
/// phi)`.
fn over_sphere(g: impl Fn(f32, f32) -> Vec3) -> Vec3 {
    const PHI: usize = 24;
    let mut sum = Vec3::ZERO;
    for (u, w) in gauss_legendre(32) {
        for k in 0..PHI {
            let phi = (k as f32 + 0.5) * PI / PHI as f32;
            sum += g(u, phi.cos()) * (w * 2.0 * PI / PHI as f32);
        }
    }
    sum
}

/// Grid nodes along `sin theta_i` and `sin theta_o`: 2.9 degrees apart at
/// the equator, a third of the narrowest lobe's width at the default
/// roughness (TT's, sqrt(v_1) = 8 degrees at beta_m = 0.3). With 25 along
/// `cos phi` the table (670 kB) stays in a core's 1 MB cache: 49 x 49 x 33
/// did not, and shading took half as long again.
const TABLE_THETA: usize = 41;
/// Grid nodes along `cos phi`.
const TABLE_PHI: usize = 25;

impl FiberTable {
    /// The table of fiber `o`: the azimuthal part averaged across the
    /// fiber ([`FarField::nodes`] offsets) at `TABLE_THETA TABLE_PHI`
    /// nodes, times the longitudinal lobes at `TABLE_THETA^2` (a few
    /// milliseconds; in parallel).
    pub fn new(o: &FiberOptics) -> FiberTable {
        use rayon::prelude::*;
        // f |cos theta_i| = sum_p M_p(theta_i, theta_o) <A_p N_p>(theta_o, phi):
        // the longitudinal lobes do not depend on h, so only the
        // azimuthal part is averaged across the fiber, once per
        // (theta_o, phi) node.
        let far = FarField::of(o);
        let m = Chiang::new(o, 0.0);
        let across: Vec<[Vec3; P_MAX + 1]> = (0..TABLE_THETA * TABLE_PHI)
            .into_par_iter()
            .map(|c| {
                let uo = node(c / TABLE_PHI, TABLE_THETA);
                let phi = node(c % TABLE_PHI, TABLE_PHI).clamp(-1.0, 1.0).acos();
                far.azimuthal(uo, phi)
            })
            .collect();
        let mut values = vec![Vec3A::ZERO; TABLE_THETA * TABLE_THETA * TABLE_PHI];
        values
            .par_chunks_mut(TABLE_THETA * TABLE_PHI)
            .enumerate()
            .for_each(|(i, row)| {
                let ui = node(i, TABLE_THETA);
                for (o_, cell) in row.chunks_mut(TABLE_PHI).enumerate() {
                    let mp = m.longitudinal(ui, node(o_, TABLE_THETA));
                    let az = &across[o_ * TABLE_PHI..(o_ + 1) * TABLE_PHI];
                    for (v, a) in cell.iter_mut().zip(az) {
                        let f: Vec3 = (0..=P_MAX).map(|p| mp[p] * a[p]).sum();
                        *v = Vec3A::from(f);
                    }
                }
            });
        let mut table = FiberTable {
            values,
            sky: Vec::new(),
        };
        table.sky = (0..SKY_THETA)
            .map(|k| {
                let uo = node(k, SKY_THETA);
                Vec3A::from(over_sphere(|ui, cos_phi| table.radiance(ui, uo, cos_phi)))
            })
            .collect();
        table
    }

    /// The radiance towards `sin theta_o = uo` under a sky of unit
    /// radiance from every direction, nothing in the way:
    /// `int R(w_i, w_o) dw_i` over the sphere, `R` [`Self::radiance`]
    /// (1 for a fiber that absorbs nothing, the white furnace).
    pub fn sky(&self, uo: f32) -> Vec3 {
        let (k, t) = cell(uo, SKY_THETA);
        Vec3::from(self.sky[k] + (self.sky[k + 1] - self.sky[k]) * t)
    }

    /// The radiance towards `sin theta_o = uo` per unit irradiance from
    /// `sin theta_i = ui`, at `cos phi` between their projections across
    /// the fiber.
    #[inline]
    pub fn radiance(&self, ui: f32, uo: f32, cos_phi: f32) -> Vec3 {
        // The cell and the position in it along each axis (the last node
        // of an axis falls in its last cell).
        #[inline(always)]
        fn at(x: f32, n: usize) -> (usize, f32) {
            let top = (n - 1) as f32;
            let f = ((x + 1.0) * (0.5 * top)).clamp(0.0, top - 1e-3);
            let k = f as usize;
            (k, f - k as f32)
        }
        let (i, ti) = at(ui, TABLE_THETA);
        let (o, to) = at(uo, TABLE_THETA);
        let (p, tp) = at(cos_phi, TABLE_PHI);
        let base = (i * TABLE_THETA + o) * TABLE_PHI + p;
        // The four pairs of neighbours along phi, each one slice.
        let pair = |at: usize| {
            let w = &self.values[at..at + 2];
            w[0] + (w[1] - w[0]) * tp
        };
        let row = TABLE_PHI;
        let plane = TABLE_THETA * TABLE_PHI;
        let (a0, a1) = (pair(base), pair(base + row));
        let (b0, b1) = (pair(base + plane), pair(base + plane + row));
        let a = a0 + (a1 - a0) * to;
        let b = b0 + (b1 - b0) * to;
        Vec3::from(a + (b - a) * ti)
    }
}
