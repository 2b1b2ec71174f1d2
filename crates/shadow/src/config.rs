//! The shadow methods' names and settings.

use crate::contact::MAX_CONTACT_CELLS;
use crate::{MAX_CELLS, ShadowError};

/// Koster et al.'s two ways of turning accumulated opacity `Omega` into
/// transmittance.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum OpacityMode {
    /// `T = max(0, 1 - Omega)`.
    Linear,
    /// `T = exp(-kappa Omega)`. With `Omega` an optical depth in physical
    /// units, `kappa = 1` estimates the same quantity as every other method
    /// (Koster's 5.56 made up for opacities in arbitrary units).
    Exponential {
        /// The extinction per unit of accumulated opacity.
        kappa: f32,
    },
}

/// What a deep opacity map does with hair past its last layer (Yuksel and
/// Keyser 2008, section 3.2).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Beyond {
    /// It casts no shadow.
    Ignore,
    /// It counts in the last layer (the paper's choice).
    LastLayer,
    /// Each pixel stretches its layers to end at its last hair.
    Cover,
}

impl Beyond {
    /// Every choice's name, as scenes and the command line spell it.
    pub const NAMES: &[&str] = &["ignore", "last-layer", "cover"];

    /// The choice named `name`, if any.
    pub fn from_name(name: &str) -> Option<Beyond> {
        match name {
            "ignore" => Some(Beyond::Ignore),
            "last-layer" => Some(Beyond::LastLayer),
            "cover" => Some(Beyond::Cover),
            _ => None,
        }
    }

    /// The choice's name.
    pub fn name(self) -> &'static str {
        match self {
            Beyond::Ignore => "ignore",
            Beyond::LastLayer => "last-layer",
            Beyond::Cover => "cover",
        }
    }
}

/// A shadow method and its settings. Resolutions are in cells (or light
/// view pixels) per side of a map fitted to the hair.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum MethodConfig {
    /// Bertails, Ménier and Cani 2005: the light-oriented density map.
    DensityMap {
        /// Cells a side.
        cells: u32,
        /// Trilinear lookups (else the cell's own value).
        trilinear: bool,
        /// Contact shadows: the fibers within this many cells of a drawn
        /// point towards the light counted exactly, one ray a point, the
        /// map beyond them (`crate::contact`); 0: the map alone.
        contact: f32,
    },
    /// Kim and Neumann 2001, as Koster et al. 2004 describe it: `slices`
    /// uniform maps of accumulated opacity between the hair's nearest and
    /// farthest depth, interpolated linearly between maps; lookups shifted
    /// `offset` slice spacings towards the light.
    OpacityShadowMap {
        /// Light-view pixels a side.
        resolution: u32,
        /// Uniform slice planes, 2 to 4096.
        slices: u32,
        /// How accumulated opacity becomes transmittance.
        mode: OpacityMode,
        /// Lookup shift towards the light, in slice spacings.
        offset: f32,
        /// Bilinear lookups between pixels (else the nearest pixel).
        trilinear: bool,
    },
    /// Yuksel and Keyser 2008: per pixel, `layers` layers of
    /// `layer_cells` cells each, starting at the pixel's first hair.
    DeepOpacityMap {
        /// Light-view pixels a side.
        resolution: u32,
        /// Layers per pixel, 1 to 64.
        layers: u32,
        /// Layer thickness, cells (ignored with `Beyond::Cover`).
        layer_cells: f32,
        /// What hair past the last layer does.
        beyond: Beyond,
        /// Bilinear lookups between pixels (else the nearest pixel).
        trilinear: bool,
    },
    /// Mertens et al. 2004: per pixel, one k-means iteration over the
    /// fragments' depths, one histogram bin of `mu +- sqrt(3) sigma` per
    /// cluster.
    DensityClustering {
        /// Light-view pixels a side.
        resolution: u32,
        /// Depth clusters (bins) per pixel, 1 to 16.
        clusters: u32,
        /// Bilinear lookups between pixels (else the nearest pixel).
        trilinear: bool,
    },
    /// Lokovic and Veach 2000: per pixel, the visibility function of all
    /// fragments, compressed to a piecewise linear function within
    /// `tolerance` (in transmittance).
    DeepShadowMap {
        /// Light-view pixels a side.
        resolution: u32,
        /// Largest error of the compressed visibility, in transmittance, [0, 1).
        tolerance: f32,
        /// Bilinear lookups between pixels (else the nearest pixel).
        trilinear: bool,
    },
    /// The exact reference (see [`crate::Reference`]): `rays` rays across
    /// each fiber's width to the light, each tested against the other
    /// fibers as capsules.
    Reference {
        /// Rays across the fiber's width, 1 to 64.
        rays: u32,
    },
    /// Transmittance from the fiber geometry averaged over a footprint (see
    /// [`crate::FootprintReference`]) over a square footprint of side
    /// `footprint` scene units (default: one cell of a 128^3 map fitted to
    /// the hair); `rays` samples of the footprint for opaque occluders.
    FootprintReference {
        /// Side of the square footprint, scene units (default: a cell of a 128^3 map).
        footprint: Option<f32>,
        /// Rays sampling the footprint for opaque occluders, 1 to 4096.
        rays: u32,
    },
}

impl MethodConfig {
    /// Every method's name, as scenes and the command line spell it.
    pub const NAMES: &[&str] = &[
        "density-map",
        "opacity-shadow-map",
        "deep-opacity-map",
        "density-clustering",
        "deep-shadow-map",
        "reference",
        "footprint-reference",
    ];

    /// The method `name` with its default settings at `cells` a side.
    pub fn with_defaults(name: &str, cells: u32) -> Option<MethodConfig> {
        Some(match name {
            "density-map" => MethodConfig::DensityMap {
                cells,
                trilinear: true,
                contact: 0.0,
            },
            "opacity-shadow-map" => MethodConfig::OpacityShadowMap {
                resolution: cells,
                slices: 64,
                mode: OpacityMode::Exponential { kappa: 1.0 },
                offset: 0.0,
                trilinear: true,
            },
            "deep-opacity-map" => MethodConfig::DeepOpacityMap {
                resolution: cells,
                layers: 4,
                layer_cells: 4.0,
                beyond: Beyond::LastLayer,
                trilinear: true,
            },
            "density-clustering" => MethodConfig::DensityClustering {
                resolution: cells,
                clusters: 4,
                trilinear: true,
            },
            "deep-shadow-map" => MethodConfig::DeepShadowMap {
                resolution: cells,
                tolerance: 0.01,
                trilinear: true,
            },
            "reference" => MethodConfig::Reference { rays: 4 },
            "footprint-reference" => MethodConfig::FootprintReference {
                footprint: None,
                rays: 64,
            },
            _ => return None,
        })
    }

    /// The method's name.
    pub fn name(&self) -> &'static str {
        match self {
            MethodConfig::DensityMap { .. } => "density-map",
            MethodConfig::OpacityShadowMap { .. } => "opacity-shadow-map",
            MethodConfig::DeepOpacityMap { .. } => "deep-opacity-map",
            MethodConfig::DensityClustering { .. } => "density-clustering",
            MethodConfig::DeepShadowMap { .. } => "deep-shadow-map",
            MethodConfig::Reference { .. } => "reference",
            MethodConfig::FootprintReference { .. } => "footprint-reference",
        }
    }

    /// Cells (or light-view pixels) a side; the reference bins its segments
    /// on a 128-column grid.
    pub fn resolution(&self) -> u32 {
        match *self {
            MethodConfig::DensityMap { cells, .. } => cells,
            MethodConfig::OpacityShadowMap { resolution, .. }
            | MethodConfig::DeepOpacityMap { resolution, .. }
            | MethodConfig::DensityClustering { resolution, .. }
            | MethodConfig::DeepShadowMap { resolution, .. } => resolution,
            MethodConfig::Reference { .. } => crate::reference::GRID,
            MethodConfig::FootprintReference { .. } => 128,
        }
    }

    /// Sets the resolution (the reference has none to set).
    pub fn set_resolution(&mut self, n: u32) {
        match self {
            MethodConfig::DensityMap { cells: r, .. }
            | MethodConfig::OpacityShadowMap { resolution: r, .. }
            | MethodConfig::DeepOpacityMap { resolution: r, .. }
            | MethodConfig::DensityClustering { resolution: r, .. }
            | MethodConfig::DeepShadowMap { resolution: r, .. } => *r = n,
            MethodConfig::Reference { .. } | MethodConfig::FootprintReference { .. } => {}
        }
    }

    /// Whether lookups interpolate between cells (the reference always
    /// averages over its footprint).
    pub fn trilinear(&self) -> bool {
        match *self {
            MethodConfig::DensityMap { trilinear, .. }
            | MethodConfig::OpacityShadowMap { trilinear, .. }
            | MethodConfig::DeepOpacityMap { trilinear, .. }
            | MethodConfig::DensityClustering { trilinear, .. }
            | MethodConfig::DeepShadowMap { trilinear, .. } => trilinear,
            MethodConfig::Reference { .. } | MethodConfig::FootprintReference { .. } => true,
        }
    }

    /// Turns filtering on or off (the reference has no switch).
    pub fn set_trilinear(&mut self, on: bool) {
        match self {
            MethodConfig::DensityMap { trilinear, .. }
            | MethodConfig::OpacityShadowMap { trilinear, .. }
            | MethodConfig::DeepOpacityMap { trilinear, .. }
            | MethodConfig::DensityClustering { trilinear, .. }
            | MethodConfig::DeepShadowMap { trilinear, .. } => *trilinear = on,
            MethodConfig::Reference { .. } | MethodConfig::FootprintReference { .. } => {}
        }
    }

    /// Whether the method needs every strand in one place at once (the
    /// peer methods and the references rasterize or trace all of it; the
    /// density map's contact shadows test the strands near each point):
    /// all but the density map without contact shadows, whose fill and
    /// sweep any split of the strands can share.
    pub fn needs_all_hair(&self) -> bool {
        !matches!(*self, MethodConfig::DensityMap { contact, .. } if contact == 0.0)
    }

    /// Checks the settings, naming the first that is out of range.
    pub fn validate(&self) -> Result<(), ShadowError> {
        let bad = |name: &'static str, value: String, why: &'static str| {
            Err(ShadowError::Setting { name, value, why })
        };
        let res = |r: u32| {
            if (1..=MAX_CELLS).contains(&r) {
                Ok(())
            } else {
                Err(ShadowError::Cells(r))
            }
        };
        match *self {
            MethodConfig::DensityMap { cells, contact, .. } => {
                res(cells)?;
                if !(contact.is_finite() && (0.0..=MAX_CONTACT_CELLS).contains(&contact)) {
                    return bad(
                        "contact",
                        contact.to_string(),
                        "must be a number of cells in 0..=16",
                    );
                }
                Ok(())
            }
            MethodConfig::OpacityShadowMap {
                resolution,
                slices,
                mode,
                offset,
                ..
            } => {
                res(resolution)?;
                if !(2..=4096).contains(&slices) {
                    return bad("slices", slices.to_string(), "must be in 2..=4096");
                }
                if let OpacityMode::Exponential { kappa } = mode
                    && !(kappa.is_finite() && kappa >= 0.0)
                {
                    return bad("kappa", kappa.to_string(), "must be finite and >= 0");
                }
                if !(offset.is_finite() && offset >= 0.0) {
                    return bad("offset", offset.to_string(), "must be finite and >= 0");
                }
                Ok(())
            }
            MethodConfig::DeepOpacityMap {
                resolution,
                layers,
                layer_cells,
                ..
            } => {
                res(resolution)?;
                if !(1..=64).contains(&layers) {
                    return bad("layers", layers.to_string(), "must be in 1..=64");
                }
                if !(layer_cells.is_finite() && layer_cells >= 0.0) {
                    return bad(
                        "layer_cells",
                        layer_cells.to_string(),
                        "must be finite and >= 0",
                    );
                }
                Ok(())
            }
            MethodConfig::DensityClustering {
                resolution,
                clusters,
                ..
            } => {
                res(resolution)?;
                if !(1..=16).contains(&clusters) {
                    return bad("clusters", clusters.to_string(), "must be in 1..=16");
                }
                Ok(())
            }
            MethodConfig::DeepShadowMap {
                resolution,
                tolerance,
                ..
            } => {
                res(resolution)?;
                if !(tolerance.is_finite() && (0.0..1.0).contains(&tolerance)) {
                    return bad("tolerance", tolerance.to_string(), "must be in [0, 1)");
                }
                Ok(())
            }
            MethodConfig::Reference { rays } => {
                if !(1..=64).contains(&rays) {
                    return bad("rays", rays.to_string(), "must be in 1..=64");
                }
                Ok(())
            }
            MethodConfig::FootprintReference { footprint, rays } => {
                if let Some(f) = footprint
                    && !(f.is_finite() && f > 0.0)
                {
                    return bad("footprint", f.to_string(), "must be finite and > 0");
                }
                if !(1..=4096).contains(&rays) {
                    return bad("rays", rays.to_string(), "must be in 1..=4096");
                }
                Ok(())
            }
        }
    }

    /// The settings as `key=value` pairs, for tables and CSV.
    pub fn parameters(&self) -> String {
        match *self {
            MethodConfig::DensityMap {
                cells,
                trilinear,
                contact,
            } => {
                if contact > 0.0 {
                    format!("cells={cells} filter={trilinear} contact={contact}")
                } else {
                    format!("cells={cells} filter={trilinear}")
                }
            }
            MethodConfig::OpacityShadowMap {
                resolution,
                slices,
                mode,
                offset,
                trilinear,
            } => {
                let mode = match mode {
                    OpacityMode::Linear => "linear".to_string(),
                    OpacityMode::Exponential { kappa } => format!("exponential kappa={kappa}"),
                };
                format!(
                    "resolution={resolution} slices={slices} mode={mode} offset={offset} filter={trilinear}"
                )
            }
            MethodConfig::DeepOpacityMap {
                resolution,
                layers,
                layer_cells,
                beyond,
                trilinear,
            } => format!(
                "resolution={resolution} layers={layers} layer_cells={layer_cells} beyond={} filter={trilinear}",
                beyond.name()
            ),
            MethodConfig::DensityClustering {
                resolution,
                clusters,
                trilinear,
            } => format!("resolution={resolution} clusters={clusters} filter={trilinear}"),
            MethodConfig::DeepShadowMap {
                resolution,
                tolerance,
                trilinear,
            } => format!("resolution={resolution} tolerance={tolerance} filter={trilinear}"),
            MethodConfig::Reference { rays } => format!("rays={rays}"),
            MethodConfig::FootprintReference { footprint, rays } => match footprint {
                Some(f) => format!("footprint={f} rays={rays}"),
                None => format!("footprint=auto rays={rays}"),
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_name_has_defaults_that_validate_and_round_trip() {
        for name in MethodConfig::NAMES {
            let c = MethodConfig::with_defaults(name, 64).unwrap();
            assert_eq!(c.name(), *name);
            c.validate().unwrap();
        }
        assert!(MethodConfig::with_defaults("raytrace", 64).is_none());
        let bad = MethodConfig::OpacityShadowMap {
            resolution: 64,
            slices: 1,
            mode: OpacityMode::Linear,
            offset: 0.0,
            trilinear: true,
        };
        assert!(matches!(
            bad.validate(),
            Err(ShadowError::Setting { name: "slices", .. })
        ));
    }
}
