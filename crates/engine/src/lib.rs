//! The scene and the frame pipeline.
//!
//! `scene` reads a TOML scene in two steps: raw serde structs that refuse
//! unknown keys, then a validated [`Scene`] the rest of the engine trusts.
//! `pipeline` builds the hair a scene describes and runs the shadow stages
//! for every light; `part` filters and shades drawn vertices and bins
//! them for drawing; `render` frames, draws and composites a frame.
//! `animate` moves the hair over time (simulated wisps, or rigidly with
//! the head) and cuts it into fixed groups, and `frames` runs an
//! animation's frames, each stage only when the scene's effects call for
//! it and its inputs changed, through an executor (`exec`) that runs the
//! stages which grow with the hair here or elsewhere; `share` is whole
//! groups held elsewhere, run by the same stage code.
//!
//! The engine is synchronous and deterministic: it does no networking, and
//! does not print; the binary decides what the user sees.

mod animate;
mod bands;
mod bounce;
pub mod cache;
mod collide;
mod exec;
mod export;
mod frames;
mod hair;
mod head;
mod part;
mod pipeline;
mod render;
mod scene;
mod share;
mod stats;

pub use animate::{Animator, GROUPS, Groups, split_by};
pub use bands::{BandPlan, BandWork, ResolvedBand, Sort, Stripe};
pub use exec::{
    DrawJob, DrawReport, Drawing, Drawn, Executor, FrameNeeds, FrameTime, LocalExecutor,
    PendingPicture, PosePlan, PoseReport, Site, StepPlan, Strands, step_wisps, step_wisps_while,
};
pub use export::{CYCLES_FORMAT, CYCLES_SCRIPT, CyclesExport, cycles_export};
pub use frames::Sequence;
pub use hair::{MAX_SEGMENTS, build_hair, drawn_segments};
pub use head::Head;
pub use part::{HairPart, Seen, draw_head};
pub use pipeline::ShadowPipeline;
pub use render::{Composite, DEFAULT_HAIR_COLOR, Renderer};
pub use scene::{
    Animation, BodySettings, CameraSettings, CameraView, Collision, Dynamics, Effects, HairSource,
    HeadMesh, HeadSettings, Placement, RenderSettings, Scene, SceneError, SceneSource,
    ShadowSettings, view_direction,
};
pub use share::Share;
pub use stats::{DrawTimes, FrameStats, Stage, StageRecord, running_stage};

/// Errors of the engine, each naming what is wrong and where.
#[derive(Debug, thiserror::Error)]
pub enum EngineError {
    /// The scene cannot be read.
    #[error(transparent)]
    Scene(#[from] SceneError),
    /// The groom a scene's `hair.file` names does not load.
    #[error("{}: hair.file: {error}", scene.display())]
    Load {
        /// The scene.
        scene: std::path::PathBuf,
        /// Why the groom does not load.
        error: strands::LoadError,
    },
    /// The head mesh does not load.
    #[error(transparent)]
    Mesh(#[from] strands::MeshLoadError),
    /// The shadow stages refused their inputs.
    #[error(transparent)]
    Shadow(#[from] shadow::ShadowError),
    /// The picture cannot be made or written.
    #[error(transparent)]
    Raster(#[from] raster::RasterError),
    /// The simulation refused its inputs.
    #[error(transparent)]
    Sim(#[from] sim::SimError),
    /// Something would take more memory than allowed.
    #[error("{what} would need {bytes} bytes, more than the {limit}-byte limit")]
    TooLarge {
        /// What.
        what: String,
        /// The bytes it would take.
        bytes: u64,
        /// The bytes allowed.
        limit: u64,
    },
    /// A change a running sequence cannot take.
    #[error("{0}")]
    Unchangeable(&'static str),
    /// A sample of an animated groom whose strands differ from the
    /// first's in number or length.
    #[error(
        "{}: hair.file: sample {sample} has {strands} strands of {points} points, the first {first_strands} of {first_points}: an animated groom keeps its strands (set hair.sample to render one sample)",
        scene.display()
    )]
    Topology {
        /// The scene file.
        scene: std::path::PathBuf,
        /// The sample.
        sample: u32,
        /// Its strands and points.
        strands: usize,
        /// Its points.
        points: usize,
        /// The first sample's strands.
        first_strands: usize,
        /// The first sample's points.
        first_points: usize,
    },
    /// The executor gave up the drawing part a frame was planned to be
    /// drawn with ([`Site::Elsewhere`]): the frame failed, and the next
    /// attempt is planned anew.
    #[error("the executor can no longer draw where the frame was planned to be drawn")]
    SiteLost,
    /// An executor that runs stages elsewhere (cluster mode) failed: its
    /// own error, kept whole (a `cluster::ClusterError` there, which a
    /// caller may downcast to), or what went wrong in handing stages to it.
    #[error(transparent)]
    Executor(Box<dyn std::error::Error + Send + Sync>),
}

impl EngineError {
    /// An executor's failure described by `message`.
    pub fn executor(message: impl Into<String>) -> EngineError {
        EngineError::Executor(message.into().into())
    }
}
