//! Hair shading: Kajiya-Kay, as in the paper,
//! `Phi = Phi_ambient + T (Phi_diffuse + Phi_specular)`, or a physically
//! based fiber (Chiang et al. 2016, see [`crate::FiberOptics`]),
//! `Phi = k_a S(theta_o, T_sky) + T E f(w_o, w_i) |cos theta_i|` (the sky
//! of radiance `k_a` from every direction, `S` the fiber's light under it,
//! [`crate::FiberTable::sky`], shadowed by the sky's transmittance
//! `T_sky`: through the hair about the head where the engine maps it,
//! else the lights' mean transmittance), with light scattered between
//! fibers as well if asked (dual scattering, see [`crate::DualTable`],
//! the sky's too: [`crate::DualTable::sky`]).

use glam::Vec3;

use crate::FiberOptics;

/// How strands are shaded.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum ShadingModel {
    /// Kajiya and Kay (1989), the paper's choice, with the weights of
    /// [`Shading`].
    #[default]
    KajiyaKay,
    /// Chiang et al.'s fiber (2016), averaged across its width, lit by
    /// each light with irradiance `irradiance`; the ambient term is a sky
    /// of radiance `k_a` from every direction, scattered by the fiber as
    /// the lights are and shadowed by the sky's transmittance (the
    /// engine's: through the hair about the head, or the lights' mean).
    /// With `from_color`, each strand's `sigma_a` follows
    /// its colour ([`crate::sigma_a_from_color`]) and `optics.sigma_a` is
    /// unused.
    Marschner {
        /// The fiber's optical properties.
        optics: FiberOptics,
        /// Whether each strand's colour sets its absorption.
        from_color: bool,
        /// Irradiance of each light.
        irradiance: f32,
        /// Light scattered between fibers too (dual scattering from the
        /// transmittance, see [`crate::DualTable`]); else single
        /// scattering only.
        multiple: bool,
    },
}

/// Shading weights. Setting `specular` to 0 turns the highlight off.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Shading {
    /// `k_a`: light reaching hair regardless of shadow.
    pub ambient: f32,
    /// `k_d`: weight of the diffuse term `sin(t, l)`.
    pub diffuse: f32,
    /// `k_s`: weight of the specular term `cos(phi)^p`.
    pub specular: f32,
    /// `p`: specular exponent; higher is a tighter highlight.
    pub shininess: f32,
    /// Colour of the highlight (the light's colour: white by default).
    pub specular_color: Vec3,
    /// The model the weights above are for (the ambient weight serves
    /// both).
    pub model: ShadingModel,
}

impl Default for Shading {
    fn default() -> Shading {
        Shading {
            ambient: 0.25,
            diffuse: 0.75,
            specular: 0.3,
            shininess: 40.0,
            specular_color: Vec3::ONE,
            model: ShadingModel::KajiyaKay,
        }
    }
}

/// Kajiya and Kay's model for a hair of colour `color` with unit tangent
/// `t`, lit along unit `to_light` (towards the light) and seen along unit
/// `to_eye`, with transmittance `trans` from the shadow stage:
///
/// ```text
/// Phi_diffuse  = k_d * color * sin(t, l)
/// Phi_specular = k_s * specular_color * max(0, sin(t,l) sin(t,e) - cos(t,l) cos(t,e))^p
///              (cos of the angle between e and the cone of mirror directions
///              of l about the fiber, where t.e = -t.l)
/// Phi          = k_a * color + trans * (Phi_diffuse + Phi_specular)
/// ```
#[inline]
pub fn kajiya_kay(
    s: &Shading,
    color: Vec3,
    t: Vec3,
    to_light: Vec3,
    to_eye: Vec3,
    trans: f32,
) -> Vec3 {
    debug_assert!(trans.is_finite());
    let tl = t.dot(to_light).clamp(-1.0, 1.0);
    let te = t.dot(to_eye).clamp(-1.0, 1.0);
    let sin_tl = (1.0 - tl * tl).max(0.0).sqrt();
    let sin_te = (1.0 - te * te).max(0.0).sqrt();
    let diffuse = s.diffuse * sin_tl * color;
    let cos_phi = (sin_tl * sin_te - tl * te).max(0.0);
    let specular = if s.specular > 0.0 {
        s.specular * power(cos_phi, s.shininess) * s.specular_color
    } else {
        Vec3::ZERO
    };
    s.ambient * color + trans * (diffuse + specular)
}

/// `x^p` for `x` in [0, 1]: by repeated squaring when `p` is a whole
/// number up to 64 (the default 40 is one), in two thirds of the time of
/// `powf`; `powf` otherwise. Squaring doubles a relative rounding error, so
/// the result is within a relative `p * 2^-23` (5e-6 at 40, far below an
/// 8-bit level) of the exact power.
#[inline]
fn power(x: f32, p: f32) -> f32 {
    if p.fract() == 0.0 && (0.0..=64.0).contains(&p) {
        x.powi(p as i32)
    } else {
        x.powf(p)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shadow_leaves_only_ambient_and_the_highlight_peaks_on_the_mirror_cone() {
        let s = Shading::default();
        let c = Vec3::new(0.5, 0.3, 0.2);
        let (t, l) = (Vec3::X, Vec3::Y);
        assert_eq!(kajiya_kay(&s, c, t, l, Vec3::Y, 0.0), s.ambient * c);
        // A tangent along the light gets no diffuse light.
        let along = kajiya_kay(
            &Shading { specular: 0.0, ..s },
            c,
            Vec3::Y,
            Vec3::Y,
            Vec3::Z,
            1.0,
        );
        assert!((along - s.ambient * c).length() < 1e-6);
        // The eye on the mirror cone (t.e = -t.l) sees the full highlight.
        let e = Vec3::new(-0.6, 0.8, 0.0);
        let l2 = Vec3::new(0.6, 0.8, 0.0);
        let peak = kajiya_kay(&s, Vec3::ZERO, t, l2, e, 1.0);
        assert!((peak - Vec3::splat(s.specular)).length() < 1e-5, "{peak}");
        let off = kajiya_kay(&s, Vec3::ZERO, t, l2, Vec3::new(0.6, 0.8, 0.0), 1.0);
        assert!(off.x < 0.01 * s.specular, "{off}");
    }

    #[test]
    fn the_highlight_power_agrees_with_double_precision() {
        for p in [1.0f32, 2.0, 7.0, 40.0, 40.5, 64.0, 65.0, 1024.0] {
            for i in 0..=1000 {
                let x = i as f32 / 1000.0;
                let exact = f64::from(x).powf(f64::from(p));
                let got = f64::from(power(x, p));
                // Relative to the value, and absolutely where it underflows.
                let rel = f64::from(p) * 2f64.powi(-23);
                assert!(
                    (got - exact).abs() <= rel * exact + 1e-37,
                    "{x}^{p}: {got} against {exact}"
                );
            }
        }
        assert_eq!(power(0.0, 40.0), 0.0);
        assert_eq!(power(1.0, 40.0), 1.0);
    }
}
