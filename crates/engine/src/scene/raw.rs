//! The scene file as TOML holds it, before validation: every table and key
//! (unknown keys refused by name).

use std::path::PathBuf;

use serde::Deserialize;

use super::motion;

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawScene {
    #[serde(default)]
    pub(super) hair: RawHair,
    #[serde(default)]
    pub(super) fiber: RawFiber,
    #[serde(default)]
    pub(super) light: Option<OneOrMany<RawLight>>,
    #[serde(default)]
    pub(super) shadow: RawShadow,
    #[serde(default)]
    pub(super) camera: RawCamera,
    #[serde(default)]
    pub(super) render: RawRender,
    #[serde(default)]
    pub(super) head: RawHead,
    #[serde(default)]
    pub(super) shading: RawShading,
    #[serde(default)]
    pub(super) effects: motion::RawEffects,
    #[serde(default)]
    pub(super) animation: motion::RawAnimation,
    #[serde(default)]
    pub(super) dynamics: motion::RawDynamics,
    #[serde(default)]
    pub(super) collision: motion::RawCollision,
    #[serde(default)]
    pub(super) body: Option<Vec<motion::RawBody>>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawCamera {
    pub(super) view: Option<String>,
    pub(super) position: Option<[f32; 3]>,
    pub(super) look_at: Option<[f32; 3]>,
    pub(super) fov_deg: Option<f32>,
    pub(super) up: Option<[f32; 3]>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawRender {
    pub(super) width: Option<i64>,
    pub(super) height: Option<i64>,
    pub(super) background: Option<[f32; 3]>,
    pub(super) hair_alpha: Option<f32>,
    pub(super) nearest: Option<i64>,
    pub(super) simplify: Option<f32>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawHead {
    pub(super) visible: Option<bool>,
    pub(super) center: Option<[f32; 3]>,
    pub(super) radius: Option<f32>,
    pub(super) color: Option<[f32; 3]>,
    pub(super) mesh: Option<PathBuf>,
    pub(super) mesh_scale: Option<f32>,
    pub(super) mesh_offset: Option<[f32; 3]>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawShading {
    pub(super) ambient: Option<f32>,
    pub(super) diffuse: Option<f32>,
    pub(super) specular: Option<f32>,
    pub(super) shininess: Option<f32>,
    pub(super) model: Option<String>,
    pub(super) eumelanin: Option<f32>,
    pub(super) pheomelanin: Option<f32>,
    pub(super) sigma_a: Option<[f32; 3]>,
    pub(super) eta: Option<f32>,
    pub(super) beta_m: Option<f32>,
    pub(super) beta_n: Option<f32>,
    pub(super) alpha_deg: Option<f32>,
    pub(super) irradiance: Option<f32>,
}

/// One table (`[light]`) or an array of them (`[[light]]`), told apart
/// by what TOML holds, so that an error inside either names its key (an
/// untagged enum would only say that neither matched).
#[derive(Debug)]
pub(super) enum OneOrMany<T> {
    One(T),
    Many(Vec<T>),
}

impl<'de, T: Deserialize<'de>> Deserialize<'de> for OneOrMany<T> {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        use serde::de::value::{MapAccessDeserializer, SeqAccessDeserializer};
        struct Either<T>(std::marker::PhantomData<T>);
        impl<'de, T: Deserialize<'de>> serde::de::Visitor<'de> for Either<T> {
            type Value = OneOrMany<T>;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("a table or an array of tables")
            }
            fn visit_map<A: serde::de::MapAccess<'de>>(
                self,
                a: A,
            ) -> Result<Self::Value, A::Error> {
                T::deserialize(MapAccessDeserializer::new(a)).map(OneOrMany::One)
            }
            fn visit_seq<A: serde::de::SeqAccess<'de>>(
                self,
                a: A,
            ) -> Result<Self::Value, A::Error> {
                Vec::<T>::deserialize(SeqAccessDeserializer::new(a)).map(OneOrMany::Many)
            }
        }
        d.deserialize_any(Either(std::marker::PhantomData))
    }
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawHair {
    pub(super) style: Option<String>,
    pub(super) file: Option<PathBuf>,
    pub(super) sample: Option<i64>,
    pub(super) strands: Option<Vec<Vec<[f32; 3]>>>,
    pub(super) seed: Option<u64>,
    pub(super) strands_per_wisp: Option<i64>,
    pub(super) parting: Option<bool>,
    pub(super) color: Option<[f32; 3]>,
    pub(super) subdivide: Option<i64>,
    pub(super) followers: Option<i64>,
    pub(super) follow_radius: Option<f32>,
    pub(super) tip_spread: Option<f32>,
    pub(super) scale: Option<f32>,
    pub(super) rotate_deg: Option<[f32; 3]>,
    pub(super) translate: Option<[f32; 3]>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawFiber {
    pub(super) width: Option<f32>,
    pub(super) opacity: Option<f32>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawLight {
    pub(super) direction: Option<[f32; 3]>,
    pub(super) position: Option<[f32; 3]>,
    pub(super) cone_deg: Option<f32>,
    pub(super) falloff_deg: Option<f32>,
    pub(super) intensity: Option<f32>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawShadow {
    pub(super) method: Option<String>,
    pub(super) cells: Option<i64>,
    pub(super) filter: Option<bool>,
    pub(super) contact: Option<f32>,
    pub(super) slices: Option<i64>,
    pub(super) mode: Option<String>,
    pub(super) kappa: Option<f32>,
    pub(super) offset: Option<f32>,
    pub(super) layers: Option<i64>,
    pub(super) layer_cells: Option<f32>,
    pub(super) beyond: Option<String>,
    pub(super) clusters: Option<i64>,
    pub(super) tolerance: Option<f32>,
    pub(super) footprint: Option<f32>,
    pub(super) rays: Option<i64>,
}
