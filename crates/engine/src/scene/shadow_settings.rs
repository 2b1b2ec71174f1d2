//! `[shadow]`: the shadow method and its settings.

use super::raw::RawShadow;
use super::{DEFAULT_CELLS, Validator};
use crate::{SceneError, ShadowSettings};
use shadow::{Beyond, MethodConfig, OpacityMode};

impl Validator<'_> {
    /// The `[shadow]` table: the method, then the settings it takes; a
    /// setting of another method is refused by name.
    pub(super) fn shadow(&self, s: RawShadow) -> Result<ShadowSettings, SceneError> {
        let name = s.method.as_deref().unwrap_or("density-map");
        let cells = self.int(
            "shadow.cells",
            s.cells,
            DEFAULT_CELLS,
            1..=shadow::MAX_CELLS,
        )?;
        let mut m = MethodConfig::with_defaults(name, cells).ok_or_else(|| {
            self.invalid(
                "shadow.method",
                format!("{name:?}"),
                format!("known methods: {}", MethodConfig::NAMES.join(", ")),
            )
        })?;
        let reference = matches!(
            m,
            MethodConfig::Reference { .. } | MethodConfig::FootprintReference { .. }
        );
        if let Some(f) = s.filter {
            if reference {
                return Err(self.invalid("shadow.filter", f, "the reference does not filter"));
            }
            m.set_trilinear(f);
        }
        if s.cells.is_some() && reference {
            return Err(self.invalid(
                "shadow.cells",
                cells,
                match m {
                    MethodConfig::Reference { .. } => "the reference has no cells",
                    _ => "the footprint reference has no cells; set shadow.footprint",
                },
            ));
        }
        let not_for = |field: &'static str, value: String, owner: &str| {
            self.invalid(
                field,
                value,
                format!("applies to method {owner:?} only, not {name:?}"),
            )
        };
        let count = |field: &'static str, v: i64| {
            u32::try_from(v).map_err(|_| self.invalid(field, v, "must be a whole number >= 0"))
        };
        macro_rules! set {
            ($field:literal, $raw:expr, $owner:literal, $pat:pat => $assign:expr) => {
                if let Some(v) = $raw {
                    match &mut m {
                        $pat => $assign(v)?,
                        _ => return Err(not_for($field, format!("{v:?}"), $owner)),
                    }
                }
            };
        }
        set!("shadow.contact", s.contact, "density-map",
            MethodConfig::DensityMap { contact, .. } => |v| { *contact = v; Ok::<(), SceneError>(()) });
        set!("shadow.slices", s.slices, "opacity-shadow-map",
            MethodConfig::OpacityShadowMap { slices, .. } => |v| count("shadow.slices", v).map(|v| *slices = v));
        set!("shadow.mode", s.mode.clone(), "opacity-shadow-map",
        MethodConfig::OpacityShadowMap { mode, .. } => |v: String| match v.as_str() {
            "linear" => { *mode = OpacityMode::Linear; Ok(()) }
            "exponential" => {
                if !matches!(mode, OpacityMode::Exponential { .. }) {
                    *mode = OpacityMode::Exponential { kappa: 1.0 };
                }
                Ok(())
            }
            _ => Err(self.invalid("shadow.mode", format!("{v:?}"), "must be \"linear\" or \"exponential\"")),
        });
        set!("shadow.kappa", s.kappa, "opacity-shadow-map",
        MethodConfig::OpacityShadowMap { mode, .. } => |v: f32| match mode {
            OpacityMode::Exponential { kappa } => { *kappa = v; Ok(()) }
            OpacityMode::Linear => Err(self.invalid("shadow.kappa", v, "applies to mode \"exponential\" only")),
        });
        set!("shadow.offset", s.offset, "opacity-shadow-map",
            MethodConfig::OpacityShadowMap { offset, .. } => |v| { *offset = v; Ok::<(), SceneError>(()) });
        set!("shadow.layers", s.layers, "deep-opacity-map",
            MethodConfig::DeepOpacityMap { layers, .. } => |v| count("shadow.layers", v).map(|v| *layers = v));
        set!("shadow.layer_cells", s.layer_cells, "deep-opacity-map",
            MethodConfig::DeepOpacityMap { layer_cells, .. } => |v| { *layer_cells = v; Ok::<(), SceneError>(()) });
        set!("shadow.beyond", s.beyond.clone(), "deep-opacity-map",
        MethodConfig::DeepOpacityMap { beyond, .. } => |v: String| match Beyond::from_name(&v) {
            Some(b) => { *beyond = b; Ok(()) }
            None => Err(self.invalid("shadow.beyond", format!("{v:?}"), format!("known: {}", Beyond::NAMES.join(", ")))),
        });
        set!("shadow.clusters", s.clusters, "density-clustering",
            MethodConfig::DensityClustering { clusters, .. } => |v| count("shadow.clusters", v).map(|v| *clusters = v));
        set!("shadow.tolerance", s.tolerance, "deep-shadow-map",
            MethodConfig::DeepShadowMap { tolerance, .. } => |v| { *tolerance = v; Ok::<(), SceneError>(()) });
        set!("shadow.footprint", s.footprint, "footprint-reference",
            MethodConfig::FootprintReference { footprint, .. } => |v| { *footprint = Some(v); Ok::<(), SceneError>(()) });
        set!("shadow.rays", s.rays, "reference or footprint-reference",
            MethodConfig::Reference { rays } | MethodConfig::FootprintReference { rays, .. } => |v| count("shadow.rays", v).map(|v| *rays = v));
        m.validate().map_err(|e| match e {
            shadow::ShadowError::Setting { name, value, why } => {
                self.invalid(setting_field(name), value, why)
            }
            other => self.invalid("shadow", name, other.to_string()),
        })?;
        Ok(ShadowSettings { method: m })
    }
}

/// The scene field of a method setting.
pub(super) fn setting_field(name: &str) -> &'static str {
    match name {
        "contact" => "shadow.contact",
        "slices" => "shadow.slices",
        "kappa" => "shadow.kappa",
        "offset" => "shadow.offset",
        "layers" => "shadow.layers",
        "layer_cells" => "shadow.layer_cells",
        "clusters" => "shadow.clusters",
        "tolerance" => "shadow.tolerance",
        "footprint" => "shadow.footprint",
        "rays" => "shadow.rays",
        _ => "shadow",
    }
}
