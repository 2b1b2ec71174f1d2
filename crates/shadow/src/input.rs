//! What a shadow method works from in one frame.

use glam::Vec3;
use strands::Hair;

use crate::{Extent, Fiber, Light, LightFrame, Occluder, ShadowError};

/// Optical depth of an opaque body (a head) along any ray through it:
/// `exp(-30)` is 1e-13, no light.
pub const OPAQUE_DEPTH: f32 = 30.0;

/// What one light's shadow method works from in one frame.
#[derive(Debug, Clone, Copy)]
pub struct ShadowInput<'a> {
    /// The light.
    pub light: &'a Light,
    /// The drawn hair (empty when posed elsewhere, see `extent`).
    pub hair: &'a Hair,
    /// Width and opacity of every fiber.
    pub fiber: &'a Fiber,
    /// Opaque bodies (the head).
    pub occluders: &'a [Occluder],
    /// Where the map is fitted from: the hair's [`Extent`] along this
    /// light's axes from an anchor point near it, when the caller knows
    /// it (for hair posed elsewhere, `hair` is then empty); `None`: from
    /// `hair`'s points, anchored at its first.
    pub extent: Option<(Vec3, Extent)>,
}

impl ShadowInput<'_> {
    /// A map of `n` cells a side fitted to the hair and the occluders.
    pub fn fit(&self, n: u32) -> Result<LightFrame, ShadowError> {
        match self.extent {
            Some(extent) => fit_to_extent(self.light, self.occluders, extent, n),
            None => {
                let corners: Vec<Vec3> = self.occluders.iter().flat_map(|o| o.corners()).collect();
                LightFrame::fit_with(self.light, self.hair.points(), &corners, n)
            }
        }
    }
}

/// A map of `n` cells a side for `light`, fitted to hair of known
/// [`Extent`] along the light's axes from an anchor point (hair held
/// elsewhere) and to the `occluders`.
pub fn fit_to_extent(
    light: &Light,
    occluders: &[Occluder],
    (anchor, extent): (Vec3, Extent),
    n: u32,
) -> Result<LightFrame, ShadowError> {
    let corners: Vec<Vec3> = occluders.iter().flat_map(|o| o.corners()).collect();
    let all = extent.union(Extent::of(light, anchor, &corners));
    LightFrame::fit_extent(light, anchor, all, n)
}
