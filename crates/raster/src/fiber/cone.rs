//! Light that fills a cone of directions, as a lit surface seen from
//! near by (the head from the hair around it), taken by a fiber.
//!
//! A fiber of tangent `t` under light of radiance `L` spread evenly over
//! the directions `w` within `alpha` of an axis `c` (`u = c . t`) takes
//!
//! ```text
//! L_o = L int_cone R(w, w_o) dw
//! ```
//!
//! `R` the radiance it sends towards `w_o` per unit irradiance from `w`
//! ([`super::FiberTable`], [`super::DualTable`]), which holds the
//! fiber's `cos theta_i`. Its lobes are narrow along the fiber (`beta_m`
//! about 0.3 radians): taking all of the cone's light from its axis puts
//! the peak of one direction where the cone has none, and measured against
//! the integral over a hemisphere that is 0.2 to 8 times the light
//! (`the_cone_stands_for_its_light_as_the_integral_does`). Instead the cone
//! is taken as its irradiance `Omega L` (`Omega = 2 pi (1 - cos alpha)`)
//! from its mean angle along the fiber, `theta_c`, with
//!
//! ```text
//! factor   = <cos theta_i> / cos theta_c          the fiber's share of it
//! theta_c  = <theta_i cos theta_i> / <cos theta_i>
//! spread   = <theta_i^2 cos theta_i> / <cos theta_i> - theta_c^2
//! across   = min(1, asin(min(1, sin alpha / sin gamma)) / (pi / 2)),  cos gamma = u
//! ```
//!
//! (`<>` the mean over the cone's directions, `theta_i = asin(w . t)`):
//! every lobe widened by `spread` along the fiber ([`super::DualTable::radiance_spread`]),
//! and across it spread over the half circle about the axis's azimuth
//! for the share `across` of the half-width the cone spans there (all of
//! it around a fiber under a hemisphere, none from a point).

use std::sync::OnceLock;

/// What a fiber takes of a cone's light: see the module's notes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ConeLight {
    /// `<cos theta_i> / cos theta_c`: the cone's irradiance times it is
    /// what the fiber takes, as from `theta_c`.
    pub factor: f32,
    /// `sin theta_c`, of the sign of `u`.
    pub sin_theta: f32,
    /// The variance of `theta_i` about `theta_c` (radians^2).
    pub spread: f32,
    /// The share of the half circle of azimuths the cone spans across the
    /// fiber, 0 to 1.
    pub across: f32,
}

/// Steps of the table along `sin alpha` and `|u|`.
const STEPS: usize = 16;

/// [`ConeLight`] of a cone of half-angle `alpha` (`sin_alpha`, the cone
/// no more than a hemisphere) whose axis makes `u = c . t` with the
/// fiber's tangent. Integrated once on a table (midpoint rule, uniform in
/// solid angle), looked up bilinear.
pub fn cone_light(sin_alpha: f32, u: f32) -> ConeLight {
    static TABLE: OnceLock<Vec<[f32; 4]>> = OnceLock::new();
    let table = TABLE.get_or_init(|| {
        let mut out = Vec::with_capacity((STEPS + 1) * (STEPS + 1));
        for a in 0..=STEPS {
            let sa = a as f64 / STEPS as f64;
            for k in 0..=STEPS {
                out.push(integrate(sa, k as f64 / STEPS as f64));
            }
        }
        out
    });
    let x = sin_alpha.clamp(0.0, 1.0) * STEPS as f32;
    let y = u.abs().min(1.0) * STEPS as f32;
    let (a, k) = ((x as usize).min(STEPS - 1), (y as usize).min(STEPS - 1));
    let (fa, fk) = (x - a as f32, y - k as f32);
    let at = |a: usize, k: usize| table[a * (STEPS + 1) + k];
    let mut v = [0.0f32; 4];
    for (i, v) in v.iter_mut().enumerate() {
        let top = at(a, k)[i] + (at(a, k + 1)[i] - at(a, k)[i]) * fk;
        let bottom = at(a + 1, k)[i] + (at(a + 1, k + 1)[i] - at(a + 1, k)[i]) * fk;
        *v = top + (bottom - top) * fa;
    }
    ConeLight {
        factor: v[0],
        sin_theta: v[1].copysign(u),
        spread: v[2].max(0.0),
        across: v[3].clamp(0.0, 1.0),
    }
}

/// `[factor, sin theta_c, spread, across]` of the cone of `sin alpha = sa`
/// about an axis at `u = c . t` (`u >= 0`).
fn integrate(sa: f64, u: f64) -> [f32; 4] {
    let n = 64;
    let ca = (1.0 - sa * sa).max(0.0).sqrt();
    let w = (1.0 - u * u).max(0.0).sqrt();
    let (mut cos_sum, mut th, mut th2) = (0.0f64, 0.0f64, 0.0f64);
    for i in 0..n {
        // cos gamma' uniform over [cos alpha, 1]: uniform in solid angle.
        let cg = ca + (1.0 - ca) * (i as f64 + 0.5) / n as f64;
        let sg = (1.0 - cg * cg).max(0.0).sqrt();
        for j in 0..n {
            let psi = 2.0 * std::f64::consts::PI * (j as f64 + 0.5) / n as f64;
            let ut = (cg * u + sg * psi.cos() * w).clamp(-1.0, 1.0);
            let (theta, cos_i) = (ut.asin(), (1.0 - ut * ut).max(0.0).sqrt());
            cos_sum += cos_i;
            th += cos_i * theta;
            th2 += cos_i * theta * theta;
        }
    }
    let m = (n * n) as f64;
    if cos_sum <= 1e-9 {
        // Only along the fiber: it takes no light.
        return [0.0, 1.0, 0.0, 1.0];
    }
    let theta_c = th / cos_sum;
    let spread = th2 / cos_sum - theta_c * theta_c;
    let factor = (cos_sum / m) / theta_c.cos().max(1e-3);
    let half = if sa >= w {
        std::f64::consts::FRAC_PI_2
    } else {
        (sa / w).min(1.0).asin()
    };
    [
        factor as f32,
        theta_c.sin() as f32,
        spread.max(0.0) as f32,
        (half / std::f64::consts::FRAC_PI_2).min(1.0) as f32,
    ]
}
