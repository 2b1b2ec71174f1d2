//! Deep opacity maps (Yuksel and Keyser 2008): per pixel, `layers` layers
//! of accumulated opacity starting at the pixel's first hair.

use glam::Vec3;
use rayon::prelude::*;

use super::fragments::{Frag, Pixels, accumulate, ceil_index, lerp, sample};
use crate::config::Beyond;
use crate::input::ShadowInput;
use crate::{FillStats, LightFrame, ShadowError};

/// The deep opacity map method (see the module documentation).
#[derive(Debug)]
pub struct DeepOpacityMap {
    resolution: u32,
    layers: usize,
    /// Layer thickness, cells (unless `beyond` is [`Beyond::Cover`]).
    layer_cells: f32,
    beyond: Beyond,
    trilinear: bool,
    pixels: Pixels,
    prepared: Option<Layers>,
}

/// Per pixel: the first hair `z0`, the layer thickness `delta`, and
/// `layers` accumulated optical depths at `z0 + (l + 1) delta`.
#[derive(Debug)]
struct Layers {
    z0: Vec<f32>,
    delta: Vec<f32>,
    omega: Vec<f32>,
}

impl DeepOpacityMap {
    pub(crate) fn new(
        resolution: u32,
        layers: u32,
        layer_cells: f32,
        beyond: Beyond,
        trilinear: bool,
    ) -> DeepOpacityMap {
        DeepOpacityMap {
            resolution,
            layers: layers as usize,
            layer_cells,
            beyond,
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
        let (layers, beyond) = (self.layers, self.beyond);
        let pixels = self.pixels.count();
        let frags = &self.pixels.frags;
        let mut z0 = vec![f32::INFINITY; pixels];
        let mut delta = vec![self.layer_cells; pixels];
        let mut omega = vec![0.0f32; pixels * layers];
        omega
            .par_chunks_mut(layers)
            .zip(z0.par_iter_mut().zip(delta.par_iter_mut()))
            .enumerate()
            .for_each(|(pix, (o, (z0, delta)))| {
                let fs = frags.of(pix);
                // The depth map: where the pixel's hair begins.
                *z0 = fs.iter().map(|f| f.z).fold(f32::INFINITY, f32::min);
                if beyond == Beyond::Cover {
                    let far = fs.iter().map(Frag::mid).fold(*z0, f32::max);
                    *delta = (far - *z0) / layers as f32;
                }
                for f in fs {
                    let u = (f.mid() - *z0) / *delta;
                    // Layer l (0-based) spans (z0 + l delta, z0 + (l + 1) delta].
                    let l = if u.is_finite() {
                        ceil_index(u).max(1) - 1
                    } else if f.mid() <= *z0 {
                        0
                    } else {
                        usize::MAX
                    };
                    let l = if l < layers {
                        l
                    } else if beyond == Beyond::Ignore {
                        continue;
                    } else {
                        layers - 1
                    };
                    o[l] += f.beta;
                }
                accumulate(o);
            });
        self.prepared = Some(Layers { z0, delta, omega });
    }

    pub(crate) fn transmittance_at(&self, p: Vec3) -> f32 {
        let frame = self.pixels.frame();
        let Layers { z0, delta, omega } = self
            .prepared
            .as_ref()
            .expect("the transmittance stage runs before lookups");
        let layers = self.layers;
        let d = sample(frame, p, self.trilinear, 0.0, |pix, x| {
            let z = z0[pix];
            if x <= z {
                return 0.0;
            }
            let o = &omega[pix * layers..(pix + 1) * layers];
            let u = (x - z) / delta[pix];
            if u.is_nan() || u >= layers as f32 {
                return o[layers - 1];
            }
            let l = u as usize;
            let before = if l == 0 { 0.0 } else { o[l - 1] };
            lerp(before, o[l], u - l as f32)
        });
        (-d).exp()
    }

    pub(crate) fn frame(&self) -> Option<&LightFrame> {
        self.pixels.frame.as_ref()
    }
}
