//! `[[light]]`: directional, point and spot lights.

use super::raw::RawLight;
use super::{DEFAULT_CONE_DEG, DEFAULT_FALLOFF_DEG, Validator};
use crate::SceneError;
use glam::Vec3;
use shadow::Light;

impl Validator<'_> {
    /// One `[[light]]`: directional (`direction`), point (`position`) or
    /// spot (`position`, `direction`, `cone_deg`, `falloff_deg`); a light
    /// with a source has an `intensity` (default: irradiance 1 at
    /// `head_center`, `intensity = r^2`).
    pub(super) fn light(&self, l: &RawLight, head_center: Vec3) -> Result<Light, SceneError> {
        let finite = |field: &'static str, v: [f32; 3]| {
            if v.iter().all(|x| x.is_finite()) {
                Ok(Vec3::from_array(v))
            } else {
                Err(self.invalid(field, format!("{v:?}"), "must be finite"))
            }
        };
        let Some(position) = l.position else {
            for (field, set) in [
                ("light.cone_deg", l.cone_deg.is_some()),
                ("light.falloff_deg", l.falloff_deg.is_some()),
                ("light.intensity", l.intensity.is_some()),
            ] {
                if set {
                    return Err(self.invalid(
                        field,
                        "(set)",
                        "applies to point and spot lights (with light.position)",
                    ));
                }
            }
            let d = l.direction.ok_or_else(|| {
                self.invalid(
                    "light",
                    "(no direction or position)",
                    "give direction (a directional light) or position (a point or spot light)",
                )
            })?;
            return Light::directional(Vec3::from_array(d)).map_err(|_| {
                self.invalid(
                    "light.direction",
                    format!("{d:?}"),
                    "must be finite and not zero",
                )
            });
        };
        let position = finite("light.position", position)?;
        let intensity = match l.intensity {
            Some(i) if !(i.is_finite() && i > 0.0 && i <= 1e12) => {
                return Err(self.invalid("light.intensity", i, "must be in (0, 1e12]"));
            }
            Some(i) => i,
            None => (head_center - position).length_squared().max(1e-6),
        };
        let Some(direction) = l.direction else {
            for (field, set) in [
                ("light.cone_deg", l.cone_deg.is_some()),
                ("light.falloff_deg", l.falloff_deg.is_some()),
            ] {
                if set {
                    return Err(self.invalid(
                        field,
                        "(set)",
                        "applies to spot lights (a position and a direction)",
                    ));
                }
            }
            return Light::point(position, intensity)
                .map_err(|e| self.invalid("light.position", format!("{position}"), e.to_string()));
        };
        let direction = finite("light.direction", direction)?;
        let cone = l.cone_deg.unwrap_or(DEFAULT_CONE_DEG);
        if !(cone > 0.0 && cone < 90.0) {
            return Err(self.invalid("light.cone_deg", cone, "must be in (0, 90) degrees"));
        }
        let falloff = l.falloff_deg.unwrap_or(DEFAULT_FALLOFF_DEG.min(cone));
        if !(falloff >= 0.0 && falloff <= cone) {
            return Err(self.invalid("light.falloff_deg", falloff, "must be in [0, cone_deg]"));
        }
        Light::spot(position, direction, cone, falloff, intensity).map_err(|_| {
            self.invalid(
                "light.direction",
                format!("{direction}"),
                "must be finite and not zero",
            )
        })
    }
}
