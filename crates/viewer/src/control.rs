//! What a page may ask of the session: one JSON object per WebSocket text
//! message, `{"type": ..., ...}`, checked here before the session sees it.
//!
//! | `type` | fields | does |
//! |---|---|---|
//! | `play`, `pause` | | runs or stops the animation |
//! | `step` | | renders the next frame (paused) |
//! | `orbit` | `yaw_deg`, `pitch_deg` | turns the camera about its target by these amounts |
//! | `zoom` | `factor` | multiplies the camera's distance to its target |
//! | `reset_camera` | | the framed camera again |
//! | `light` | `index`, `azimuth_deg`, `elevation_deg`, `distance`? | places light `index`: where it comes from, seen from the hair's centre (a point or spot light also at `distance`, aimed at the centre) |
//! | `effect` | `name`, `on` | turns an `[effects]` switch on or off |
//! | `shadow` | `method`, `setting`?, `cells`? | the shadow method, its main setting, the map's cells a side |

use serde::Deserialize;

use crate::ViewerError;

/// The longest message a page may send, bytes.
pub const MAX_MESSAGE: usize = 4096;

/// The `[effects]` switches a page can turn, as named in scene files.
pub const EFFECTS: [&str; 8] = [
    "dynamics",
    "self_collision",
    "body_collision",
    "self_shadow",
    "specular",
    "head_shadow",
    "multiple_scattering",
    "head_bounce",
];

/// A request from a page, checked.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case", deny_unknown_fields)]
pub enum Control {
    /// Play the animation.
    Play {},
    /// Stop it.
    Pause {},
    /// Render the next frame.
    Step {},
    /// Turn the camera about its target.
    Orbit {
        /// About the vertical, degrees.
        yaw_deg: f32,
        /// Up or down, degrees.
        pitch_deg: f32,
    },
    /// Move the camera towards its target or away.
    Zoom {
        /// The distance is multiplied by this.
        factor: f32,
    },
    /// The camera the first frame framed.
    ResetCamera {},
    /// Place light `index`, seen from the hair's centre.
    Light {
        /// Which light, in the scene's order.
        index: usize,
        /// About +y from the front (+z) towards +x, degrees.
        azimuth_deg: f32,
        /// Above the horizon, degrees.
        elevation_deg: f32,
        /// A point or spot light's distance from the centre, scene units; kept when absent.
        #[serde(default)]
        distance: Option<f32>,
    },
    /// Switch an effect of the scene's `[effects]`.
    Effect {
        /// The effect's key.
        name: String,
        /// On or off.
        on: bool,
    },
    /// Choose the shadow method and its settings.
    Shadow {
        /// The method's name.
        method: String,
        /// Its main setting (slices, layers, clusters, tolerance, rays); kept when absent.
        #[serde(default)]
        setting: Option<f64>,
        /// Cells (or light-view pixels) a side; kept when absent.
        #[serde(default)]
        cells: Option<u32>,
    },
}

impl Control {
    /// Reads and checks one message: a JSON object of a known `type`
    /// with its fields, each in range. The error names what is wrong.
    pub fn parse(text: &str) -> Result<Control, ViewerError> {
        if text.len() > MAX_MESSAGE {
            return Err(ViewerError::BadMessage(format!(
                "{} bytes, more than the {MAX_MESSAGE}-byte limit",
                text.len()
            )));
        }
        let c: Control =
            serde_json::from_str(text).map_err(|e| ViewerError::BadMessage(e.to_string()))?;
        c.check()?;
        Ok(c)
    }

    fn check(&self) -> Result<(), ViewerError> {
        let range = |name: &str, v: f32, lo: f32, hi: f32| {
            if v.is_finite() && (lo..=hi).contains(&v) {
                Ok(())
            } else {
                Err(ViewerError::BadMessage(format!(
                    "{name} = {v}: must be in [{lo}, {hi}]"
                )))
            }
        };
        match self {
            Control::Orbit { yaw_deg, pitch_deg } => {
                range("yaw_deg", *yaw_deg, -360.0, 360.0)?;
                range("pitch_deg", *pitch_deg, -180.0, 180.0)
            }
            Control::Zoom { factor } => range("factor", *factor, 0.1, 10.0),
            Control::Light {
                azimuth_deg,
                elevation_deg,
                distance,
                ..
            } => {
                range("azimuth_deg", *azimuth_deg, -360.0, 360.0)?;
                range("elevation_deg", *elevation_deg, -90.0, 90.0)?;
                match distance {
                    Some(d) => range("distance", *d, 1e-3, 1e6),
                    None => Ok(()),
                }
            }
            Control::Effect { name, .. } if !EFFECTS.contains(&name.as_str()) => {
                Err(ViewerError::BadMessage(format!(
                    "effect {name:?}: not one of {}",
                    EFFECTS.join(", ")
                )))
            }
            Control::Shadow {
                method,
                setting,
                cells,
            } => {
                if !shadow::MethodConfig::NAMES.contains(&method.as_str()) {
                    return Err(ViewerError::BadMessage(format!(
                        "method {method:?}: not one of {}",
                        shadow::MethodConfig::NAMES.join(", ")
                    )));
                }
                if let Some(s) = setting
                    && !s.is_finite()
                {
                    return Err(ViewerError::BadMessage(format!(
                        "setting = {s}: must be a finite number"
                    )));
                }
                if let Some(c) = cells
                    && !(1..=shadow::MAX_CELLS).contains(c)
                {
                    return Err(ViewerError::BadMessage(format!(
                        "cells = {c}: must be in 1..={}",
                        shadow::MAX_CELLS
                    )));
                }
                Ok(())
            }
            _ => Ok(()),
        }
    }
}

/// The main setting of each shadow method a page can set: its name in
/// scene files, and its value in `method`.
pub(crate) fn main_setting(method: &shadow::MethodConfig) -> Option<(&'static str, f64)> {
    use shadow::MethodConfig as M;
    match *method {
        M::DensityMap { .. } => None,
        M::OpacityShadowMap { slices, .. } => Some(("slices", f64::from(slices))),
        M::DeepOpacityMap { layers, .. } => Some(("layers", f64::from(layers))),
        M::DensityClustering { clusters, .. } => Some(("clusters", f64::from(clusters))),
        M::DeepShadowMap { tolerance, .. } => Some(("tolerance", f64::from(tolerance))),
        M::Reference { rays } | M::FootprintReference { rays, .. } => {
            Some(("rays", f64::from(rays)))
        }
    }
}

/// `method` with its main setting set to `value` (rounded for counts),
/// checked by the method's own validation.
pub(crate) fn with_main_setting(
    mut method: shadow::MethodConfig,
    value: f64,
) -> Result<shadow::MethodConfig, ViewerError> {
    use shadow::MethodConfig as M;
    let count = || {
        let v = value.round();
        if (0.0..=f64::from(u32::MAX)).contains(&v) {
            Ok(v as u32)
        } else {
            Err(ViewerError::BadMessage(format!(
                "setting = {value}: out of range"
            )))
        }
    };
    match &mut method {
        M::DensityMap { .. } => {
            return Err(ViewerError::BadMessage(
                "the density map has no setting beside its cells".into(),
            ));
        }
        M::OpacityShadowMap { slices, .. } => *slices = count()?,
        M::DeepOpacityMap { layers, .. } => *layers = count()?,
        M::DensityClustering { clusters, .. } => *clusters = count()?,
        M::DeepShadowMap { tolerance, .. } => *tolerance = value as f32,
        M::Reference { rays } | M::FootprintReference { rays, .. } => *rays = count()?,
    }
    method
        .validate()
        .map_err(|e| ViewerError::BadMessage(e.to_string()))?;
    Ok(method)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_message_of_the_table_parses() {
        for (text, want) in [
            (r#"{"type":"play"}"#, Control::Play {}),
            (r#"{"type":"pause"}"#, Control::Pause {}),
            (r#"{"type":"step"}"#, Control::Step {}),
            (
                r#"{"type":"orbit","yaw_deg":10,"pitch_deg":-5}"#,
                Control::Orbit {
                    yaw_deg: 10.0,
                    pitch_deg: -5.0,
                },
            ),
            (
                r#"{"type":"zoom","factor":0.5}"#,
                Control::Zoom { factor: 0.5 },
            ),
            (r#"{"type":"reset_camera"}"#, Control::ResetCamera {}),
            (
                r#"{"type":"light","index":0,"azimuth_deg":30,"elevation_deg":45}"#,
                Control::Light {
                    index: 0,
                    azimuth_deg: 30.0,
                    elevation_deg: 45.0,
                    distance: None,
                },
            ),
            (
                r#"{"type":"effect","name":"self_shadow","on":false}"#,
                Control::Effect {
                    name: "self_shadow".into(),
                    on: false,
                },
            ),
            (
                r#"{"type":"shadow","method":"deep-opacity-map","setting":6,"cells":64}"#,
                Control::Shadow {
                    method: "deep-opacity-map".into(),
                    setting: Some(6.0),
                    cells: Some(64),
                },
            ),
        ] {
            assert_eq!(Control::parse(text).unwrap(), want, "{text}");
        }
    }

    #[test]
    fn bad_messages_are_refused_naming_what_is_wrong() {
        for (text, names) in [
            ("not json", "expected"),
            (r#"{"type":"fly"}"#, "fly"),
            (r#"{"type":"play","speed":2}"#, "speed"),
            (r#"{"type":"zoom"}"#, "factor"),
            (r#"{"type":"zoom","factor":0}"#, "factor"),
            (r#"{"type":"zoom","factor":"big"}"#, "string"),
            (
                r#"{"type":"orbit","yaw_deg":1e30,"pitch_deg":0}"#,
                "yaw_deg",
            ),
            (
                r#"{"type":"light","index":0,"azimuth_deg":0,"elevation_deg":91}"#,
                "elevation_deg",
            ),
            (r#"{"type":"effect","name":"fur","on":true}"#, "fur"),
            (r#"{"type":"shadow","method":"magic"}"#, "magic"),
            (
                r#"{"type":"shadow","method":"density-map","cells":100000}"#,
                "cells",
            ),
            (
                r#"{"type":"shadow","method":"density-map","cells":-1}"#,
                "-1",
            ),
            (r#"[1,2]"#, "type"),
        ] {
            let e = Control::parse(text).unwrap_err().to_string();
            assert!(e.contains(names), "{text}: {e}");
        }
        let long = format!(r#"{{"type":"play","x":"{}"}}"#, "a".repeat(MAX_MESSAGE));
        assert!(
            Control::parse(&long)
                .unwrap_err()
                .to_string()
                .contains("limit")
        );
    }

    #[test]
    fn main_settings_are_set_and_checked_by_the_method() {
        let osm = shadow::MethodConfig::with_defaults("opacity-shadow-map", 64).unwrap();
        let set = with_main_setting(osm, 16.0).unwrap();
        assert_eq!(main_setting(&set), Some(("slices", 16.0)));
        let e = with_main_setting(osm, 1.0).unwrap_err().to_string();
        assert!(e.contains("slices"), "{e}");
        let dm = shadow::MethodConfig::with_defaults("density-map", 64).unwrap();
        assert!(with_main_setting(dm, 3.0).is_err());
        assert_eq!(main_setting(&dm), None);
    }
}
