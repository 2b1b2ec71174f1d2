//! Pictures: a perspective camera, Kajiya-Kay hair shading, a software
//! renderer for anti-aliased, semi-transparent line strips over a
//! depth-tested sphere, and PNG and GIF encoding (into memory or any
//! writer: the caller decides how a file is written).
//!
//! This crate knows nothing of density maps or scenes: it is handed shaded
//! vertices (colour per vertex) and a head, and turns them into pixels. Its
//! results are the same bytes whatever the thread count, and whether groups
//! of strands are drawn on one canvas or on several whose partial pictures
//! ([`HairLayer`]) are composited together: each group's fragments are
//! summed in floating point, the groups' sums in exact integers.

mod camera;
mod canvas;
mod fiber;
mod gif;
mod png;
mod ratio;
mod shade;

pub use camera::Camera;
pub use canvas::{
    BandSegments, Canvas, Fragment, HairLayer, HairLook, MAX_NEAREST, MAX_PIXELS, Sphere, Sums,
    to_srgb8,
};
pub use fiber::{
    BODY_DEPTH, Chiang, ConeLight, DENSITY_BACK, DENSITY_FORWARD, DualTable, FarField, FiberOptics,
    FiberTable, MAX_DEPTH, P_MAX, color_from_sigma_a, cone_light, optical_depth,
    sigma_a_from_color, sigma_a_from_melanin,
};
pub use gif::GifWriter;
pub use png::encode_png;
pub use ratio::{LIT_FRACTION, RatioComparison, ShadowRatios, srgb8_to_linear};
pub use shade::{Shading, ShadingModel, kajiya_kay};

/// The largest image side, in pixels.
pub const fn canvas_max_side() -> u32 {
    canvas::MAX_SIDE
}

/// Errors of picture making.
#[derive(Debug, thiserror::Error)]
pub enum RasterError {
    /// An image size out of range.
    #[error("image size {width}x{height}: must be 1..={max} pixels a side and at most {pixels} pixels", max = canvas::MAX_SIDE, pixels = MAX_PIXELS)]
    Size {
        /// Asked width, pixels.
        width: u32,
        /// Asked height, pixels.
        height: u32,
    },
    /// A partial picture that does not fit the canvas or is malformed.
    #[error("partial picture: {0}")]
    Layer(String),
    /// Segments of a band that are malformed.
    #[error("band segments: {0}")]
    Segments(String),
    /// A camera that cannot be made.
    #[error("camera: {0}")]
    Camera(String),
    /// A picture the encoder refused, or the writer it encodes into
    /// failed.
    #[error("cannot encode the {format}: {message}")]
    Encode {
        /// The image format ("PNG", "GIF").
        format: &'static str,
        /// The encoder's reason.
        message: String,
    },
}
