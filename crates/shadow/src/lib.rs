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
//! 3. [`Transmittance::filter`]: trilinear filtering of the transmittance at
//!    each point (or the unfiltered cell value, for comparison).
//!
//! The crate knows nothing of cameras, shading, files or networks.

mod bins;
mod config;
mod contact;
mod density;
mod fiber;
mod footprint_reference;
mod frame;
mod input;
mod method;
mod occluder;
mod peers;
mod reference;
mod transmittance;

pub use config::{Beyond, MethodConfig, OpacityMode};
pub use contact::MAX_CONTACT_CELLS;
pub use density::{ColumnMeta, DEPOSIT_RUN_WORK, DEPTH_QUANTUM, DensityMap, FillStats};
pub use fiber::Fiber;
pub use footprint_reference::FootprintReference;
pub use frame::{Extent, Fan, Light, LightFrame, MAX_CELLS, MAX_FAN_TAN};
pub use input::{OPAQUE_DEPTH, ShadowInput, fit_to_extent};
pub use method::{DensityMapMethod, ShadowMethod};
pub use occluder::{Occluder, OccluderView, ray_triangle};
pub use peers::{DeepOpacityMap, DeepShadowMap, DensityClustering, OpacityShadowMap};
pub use reference::{AcrossFiber, Reference};
pub use transmittance::{
    BODY_CELL_DEPTH, ColumnSlab, DEPTH_STEP, LIT_EDGE_OFFSET, SWEEP_RUN_COLUMNS, Span,
    Transmittance, columns_read, sweep, sweep_while,
};

/// Errors of the shadow stages.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum ShadowError {
    /// A fiber width that is not a finite number > 0.
    #[error("fiber width {0} is not a finite number > 0")]
    FiberWidth(f32),
    /// A fiber opacity outside [0, 1].
    #[error("fiber opacity {0} is not in [0, 1]")]
    FiberOpacity(f32),
    /// A zero or non-finite light direction.
    #[error("light direction {0} is zero or not finite")]
    LightDirection(glam::Vec3),
    /// A light setting out of range.
    #[error("light {what} = {value}: {why}")]
    LightSetting {
        /// The setting.
        what: &'static str,
        /// Its value.
        value: String,
        /// The range it must be in.
        why: &'static str,
    },
    #[error(
        "the light at {position} is inside the hair or too close to it: all of it must lie \
         within {max_deg:.1} degrees of the direction from the light to the hair, in front of the light"
    )]
    /// A point or spot light inside the hair, or too close to fan over it.
    LightInside {
        /// The light's position.
        position: glam::Vec3,
        /// The widest angle a fan may open, degrees.
        max_deg: f32,
    },
    /// A map side outside 1..=`MAX_CELLS`.
    #[error("map of {0} cells a side is outside 1..={MAX_CELLS}")]
    Cells(u32),
    /// A map size that is not a finite number > 0.
    #[error("map size {0} is not a finite number > 0")]
    MapSize(f32),
    /// A shadow method's setting out of range.
    #[error("shadow setting {name} = {value}: {why}")]
    Setting {
        /// The setting.
        name: &'static str,
        /// Its value.
        value: String,
        /// The range it must be in.
        why: &'static str,
    },
    /// Swept slabs that do not tile the map's columns.
    #[error("slabs do not tile the map's {expected} columns: {detail}")]
    Slabs {
        /// The map's columns.
        expected: usize,
        /// What is missing or doubled.
        detail: String,
    },
}
