//! Self-shadowing of hair by a light-oriented density map (Bertails, Ménier
//! and Cani 2005, sections 3 and 4).
//!
//! Three stages, each usable on its own so that a cluster can split them:
//!
//! 1. [`DensityMap::deposit`]: hair is sampled into a cubic grid whose first
//!    axis is the light direction ([`LightFrame`]). Each cell accumulates
//!    optical depth in fixed point, so partial maps add up to the same bytes
//!    in any order, on any thread or machine.
//! 2. [`sweep`]: one pass along each `(j, k)` column turns density into
//!    cumulative optical depth; any range of columns can be swept alone, and
//!    [`Transmittance::assemble`] joins the slabs.
//! 3. [`Transmittance::lookup`]: trilinear filtering of the transmittance at
//!    each point (or the unfiltered cell value, for comparison).
//!
//! The crate knows nothing of cameras, shading, files or networks.

#![warn(unreachable_pub)]

mod config;
mod density;
mod fiber;
mod frame;
mod input;
mod method;
mod occluder;
mod peers;
mod reference;
mod transmittance;

pub use config::{Beyond, MethodConfig, OpacityMode};
pub use density::{ColumnMeta, DEPOSIT_RUN_WORK, DEPTH_QUANTUM, DensityMap, FillStats};
pub use fiber::Fiber;
pub use frame::{Extent, Fan, Light, LightFrame, MAX_CELLS, MAX_FAN_TAN};
pub use input::{OPAQUE_DEPTH, ShadowInput};
pub use method::{DensityMapMethod, ShadowMethod};
pub use occluder::{Occluder, OccluderView};
pub use peers::{DeepOpacityMap, DeepShadowMap, DensityClustering, OpacityShadowMap};
pub use reference::Reference;
pub use transmittance::{
    ColumnSlab, DEPTH_STEP, SWEEP_RUN_COLUMNS, Span, Transmittance, columns_read, sweep,
    sweep_while,
};

/// Errors of the shadow stages.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum ShadowError {
    #[error("fiber width {0} is not a finite number > 0")]
    FiberWidth(f32),
    #[error("fiber opacity {0} is not in [0, 1]")]
    FiberOpacity(f32),
    #[error("light direction {0} is zero or not finite")]
    LightDirection(glam::Vec3),
    #[error("light {what} = {value}: {why}")]
    LightSetting {
        what: &'static str,
        value: String,
        why: &'static str,
    },
    #[error(
        "the light at {position} is inside the hair or too close to it: all of it must lie \
         within {max_deg:.1} degrees of the direction from the light to the hair, in front of the light"
    )]
    LightInside { position: glam::Vec3, max_deg: f32 },
    #[error("map of {0} cells a side is outside 1..={MAX_CELLS}")]
    Cells(u32),
    #[error("map size {0} is not a finite number > 0")]
    MapSize(f32),
    #[error("shadow setting {name} = {value}: {why}")]
    Setting {
        name: &'static str,
        value: String,
        why: &'static str,
    },
    #[error("slabs do not tile the map's {expected} columns: {detail}")]
    Slabs { expected: usize, detail: String },
}
