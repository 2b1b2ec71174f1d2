//! Opacity shadow maps (Kim and Neumann 2001, as Koster et al. 2004 describe
//! them): accumulated opacity at `slices` uniform planes between the hair's
//! nearest and farthest depth, interpolated linearly between planes.

use glam::Vec3;
use rayon::prelude::*;

use super::fragments::{Pixels, accumulate, ceil_index, lerp, sample};
use crate::config::OpacityMode;
use crate::input::ShadowInput;
use crate::{FillStats, LightFrame, ShadowError};

/// The opacity shadow map method (see the module documentation).
#[derive(Debug)]
pub struct OpacityShadowMap {
    resolution: u32,
    slices: usize,
    mode: OpacityMode,
    /// Lookups shift this many slice spacings towards the light.
    offset: f32,
    trilinear: bool,
    pixels: Pixels,
    prepared: Option<Slices>,
}

/// Accumulated optical depth `omega` per pixel at `slices` planes
/// `d0 + s delta` (cells along the light).
#[derive(Debug)]
struct Slices {
    d0: f32,
    delta: f32,
    omega: Vec<f32>,
}

impl OpacityShadowMap {
    pub(crate) fn new(
        resolution: u32,
        slices: u32,
        mode: OpacityMode,
        offset: f32,
        trilinear: bool,
    ) -> OpacityShadowMap {
        OpacityShadowMap {
            resolution,
            slices: slices as usize,
            mode,
            offset,
            trilinear,
            pixels: Pixels::default(),
            prepared: None,
        }
    }

    pub(crate) fn density(&mut self, input: &ShadowInput) -> Result<FillStats, ShadowError> {
        self.prepared = None;
        self.pixels.build(input, self.resolution)
    }

    pub(crate) fn transmittance(&mut self) {
        assert!(
            self.pixels.frame.is_some(),
            "the density stage runs before the transmittance stage"
        );
        let slices = self.slices;
        let frags = &self.pixels.frags;
        // The hair's depth range (Koster et al.: the bounding box).
        let (lo, hi) = frags
            .frags
            .iter()
            .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), f| {
                (lo.min(f.z), hi.max(f.z + f.len))
            });
        let (d0, delta) = if lo.is_finite() {
            (lo, ((hi - lo) / (slices - 1) as f32).max(1e-6))
        } else {
            (0.0, 1.0)
        };
        let mut omega = vec![0.0f32; self.pixels.count() * slices];
        omega
            .par_chunks_mut(slices)
            .enumerate()
            .for_each(|(pix, o)| {
                // A fragment between planes s - 1 and s counts from plane s on.
                for f in frags.of(pix) {
                    let u = ((f.mid() - d0) / delta).max(0.0);
                    let s = ceil_index(u).min(slices - 1);
                    o[s] += f.beta;
                }
                accumulate(o);
            });
        self.prepared = Some(Slices { d0, delta, omega });
    }

    pub(crate) fn transmittance_at(&self, p: Vec3) -> f32 {
        let frame = self.pixels.frame();
        let Slices { d0, delta, omega } = self
            .prepared
            .as_ref()
            .expect("the transmittance stage runs before lookups");
        let (d0, delta, slices) = (*d0, *delta, self.slices);
        let offset = self.offset;
        let om = sample(frame, p, self.trilinear, 0.0, |pix, x| {
            let o = &omega[pix * slices..(pix + 1) * slices];
            let u = (x - offset * delta - d0) / delta;
            if u <= 0.0 {
                // At or in front of the first plane: no hair lies between
                // the point and the light (plane 0 holds hair at exactly
                // `d0`, as in a sheet across it).
                return 0.0;
            }
            if u >= (slices - 1) as f32 {
                return o[slices - 1];
            }
            let s = u as usize;
            lerp(o[s], o[s + 1], u - s as f32)
        });
        match self.mode {
            OpacityMode::Linear => (1.0 - om).clamp(0.0, 1.0),
            OpacityMode::Exponential { kappa } => (-kappa * om).exp(),
        }
    }

    pub(crate) fn frame(&self) -> Option<&LightFrame> {
        self.pixels.frame.as_ref()
    }
}
