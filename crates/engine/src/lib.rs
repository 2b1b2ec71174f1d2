//! The scene and the frame pipeline.
//!
//! [`scene`] reads a TOML scene in two steps: raw serde structs that refuse
//! unknown keys, then a validated [`Scene`] the rest of the engine trusts.
//! [`pipeline`] builds the hair a scene describes and runs the shadow stages
//! for every light; [`render`] shades and draws a frame.
//!
//! The engine is synchronous and deterministic: it does no networking, and
//! does not print; the binary decides what the user sees.

pub mod collide;
pub mod pipeline;
pub mod render;
pub mod scene;

pub use pipeline::{ShadowPipeline, StageTimes, build_hair};
pub use render::{FrameTimes, Renderer};
pub use scene::{HairSource, HeadSettings, Scene, SceneError, ShadowSettings};

/// Errors of the engine, each naming what is wrong and where.
#[derive(Debug, thiserror::Error)]
pub enum EngineError {
    #[error(transparent)]
    Scene(#[from] SceneError),
    #[error(transparent)]
    Load(#[from] strands::LoadError),
    #[error(transparent)]
    Shadow(#[from] shadow::ShadowError),
    #[error(transparent)]
    Raster(#[from] raster::RasterError),
    #[error("{what} would need {bytes} bytes, more than the {limit}-byte limit")]
    TooLarge {
        what: String,
        bytes: u64,
        limit: u64,
    },
}
