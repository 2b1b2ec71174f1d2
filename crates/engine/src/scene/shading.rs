//! `[shading]`: the shading model and its settings, colours.

use super::Validator;
use super::raw::RawShading;
use crate::SceneError;
use glam::Vec3;

impl Validator<'_> {
    pub(super) fn color(
        &self,
        field: &'static str,
        v: Option<[f32; 3]>,
        default: [f32; 3],
    ) -> Result<Vec3, SceneError> {
        let c = v.unwrap_or(default);
        if c.iter().all(|x| x.is_finite() && (0.0..=1.0).contains(x)) {
            Ok(Vec3::from_array(c))
        } else {
            Err(self.invalid(
                field,
                format!("{c:?}"),
                "each component must be in [0, 1] (linear RGB)",
            ))
        }
    }

    /// `[shading] model` and the fiber's settings: Kajiya-Kay (the
    /// default), or `"marschner"`, a physically based fiber whose
    /// absorption comes from `sigma_a`, from melanin concentrations, or
    /// (neither given) from each strand's colour.
    pub(super) fn shading_model(
        &self,
        sh: &RawShading,
    ) -> Result<raster::ShadingModel, SceneError> {
        let fiber_keys = [
            ("shading.eumelanin", sh.eumelanin.is_some()),
            ("shading.pheomelanin", sh.pheomelanin.is_some()),
            ("shading.sigma_a", sh.sigma_a.is_some()),
            ("shading.eta", sh.eta.is_some()),
            ("shading.beta_m", sh.beta_m.is_some()),
            ("shading.beta_n", sh.beta_n.is_some()),
            ("shading.alpha_deg", sh.alpha_deg.is_some()),
            ("shading.irradiance", sh.irradiance.is_some()),
        ];
        match sh.model.as_deref().unwrap_or("kajiya-kay") {
            "kajiya-kay" => {
                self.refuse_set(&fiber_keys, "is a setting of model = \"marschner\"")?;
                Ok(raster::ShadingModel::KajiyaKay)
            }
            "marschner" => {
                let d = raster::FiberOptics::default();
                let in_range = |field: &'static str,
                                v: Option<f32>,
                                default: f32,
                                lo: f32,
                                hi: f32,
                                open_lo: bool| {
                    let v = v.unwrap_or(default);
                    let ok = v.is_finite() && v <= hi && if open_lo { v > lo } else { v >= lo };
                    if ok {
                        Ok(v)
                    } else {
                        let bracket = if open_lo { "(" } else { "[" };
                        Err(self.invalid(
                            field,
                            v,
                            format!("must be a number in {bracket}{lo}, {hi}]"),
                        ))
                    }
                };
                let beta_n = in_range("shading.beta_n", sh.beta_n, d.beta_n, 0.0, 1.0, true)?;
                let melanin = sh.eumelanin.is_some() || sh.pheomelanin.is_some();
                if melanin && sh.sigma_a.is_some() {
                    return Err(self.invalid(
                        "shading.sigma_a",
                        "(set)",
                        "give sigma_a or melanin concentrations (eumelanin, pheomelanin), not both",
                    ));
                }
                let sigma_a = match sh.sigma_a {
                    Some(s) if s.iter().all(|x| x.is_finite() && (0.0..=100.0).contains(x)) => {
                        Vec3::from_array(s)
                    }
                    Some(s) => {
                        return Err(self.invalid(
                            "shading.sigma_a",
                            format!("{s:?}"),
                            "each component must be in [0, 100] (per unit of the fiber's diameter)",
                        ));
                    }
                    None => raster::sigma_a_from_melanin(
                        in_range("shading.eumelanin", sh.eumelanin, 0.0, 0.0, 50.0, false)?,
                        in_range("shading.pheomelanin", sh.pheomelanin, 0.0, 0.0, 50.0, false)?,
                    ),
                };
                let optics = raster::FiberOptics {
                    eta: in_range("shading.eta", sh.eta, d.eta, 1.0, 3.0, true)?,
                    sigma_a,
                    beta_m: in_range("shading.beta_m", sh.beta_m, d.beta_m, 0.0, 1.0, true)?,
                    beta_n,
                    alpha_deg: in_range(
                        "shading.alpha_deg",
                        sh.alpha_deg,
                        d.alpha_deg,
                        -20.0,
                        20.0,
                        false,
                    )?,
                };
                Ok(raster::ShadingModel::Marschner {
                    optics,
                    multiple: false,
                    from_color: !melanin && sh.sigma_a.is_none(),
                    irradiance: in_range(
                        "shading.irradiance",
                        sh.irradiance,
                        5.0,
                        0.0,
                        1000.0,
                        false,
                    )?,
                })
            }
            other => Err(self.invalid(
                "shading.model",
                other,
                "must be \"kajiya-kay\" or \"marschner\"",
            )),
        }
    }
}
