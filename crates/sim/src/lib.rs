//! Hair dynamics (Bertails, Ménier and Cani 2005, section 5.1): wisps of
//! three guide strands, each a chain of rigid links stepped by position-based
//! dynamics; the head's motion; collisions with body spheres; and, through
//! [`ForceField`], self-collisions driven by the density map.
//!
//! Synchronous and deterministic: a wisp's step depends only on its own
//! state and its inputs, so any split of wisps over threads or machines
//! gives the same bytes. Knows nothing of light, pictures or files.

mod dynamics;
mod motion;

pub use dynamics::{Body, ForceField, HairSim, SimParams, WispState, push_out};
pub use motion::{Keyframe, Motion};

/// Errors of the simulation's inputs.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum SimError {
    /// A setting out of range.
    #[error("simulation settings: {0}")]
    Params(String),
    /// Guide strands that cannot be simulated.
    #[error("guide strands: {0}")]
    Guides(String),
    /// A head motion that cannot be played.
    #[error("head motion: {0}")]
    Motion(String),
}
