//! The peer methods: shadow maps over light-view pixels.
//!
//! All four rasterize the hair the same way the density map fills it (so
//! that they estimate the same quantity): each segment is cut into pieces no
//! longer than a pixel along any axis, and each piece becomes a fragment of
//! optical depth
//!
//! ```text
//! beta = alpha * w * |piece x L| / ds^2
//! ```
//!
//! (its projected area times its opacity, over the pixel's area), spread
//! over the four nearest pixels with bilinear weights. The fragment keeps
//! the depth span `[z, z + len]` (in cells along the light) the piece covers.
//! What each method keeps of a pixel's fragments differs:
//!
//! - opacity shadow maps: accumulated opacity at uniform slice planes;
//! - deep opacity maps: accumulated opacity at layers that start at the
//!   pixel's first fragment;
//! - density clustering: a histogram bin per k-means cluster of depths;
//! - deep shadow maps: the whole visibility function, compressed.
//!
//! Lookups blend the four pixels around a point with bilinear weights
//! (non-negative: a blend of non-increasing functions never increases), or
//! take the nearest pixel with filtering off.

mod deep_opacity_map;
mod deep_shadow_map;
mod density_clustering;
mod fragments;
mod opacity_shadow_map;

pub use deep_opacity_map::DeepOpacityMap;
pub use deep_shadow_map::DeepShadowMap;
pub use density_clustering::DensityClustering;
pub use opacity_shadow_map::OpacityShadowMap;

#[cfg(test)]
mod tests;
