//! Density clustering (Mertens et al. 2004): per pixel, one k-means
//! iteration over the fragments' depths, one histogram bin of
//! `mu +- sqrt(3) sigma` per cluster.

use glam::Vec3;
use rayon::prelude::*;

use super::fragments::{Frag, Pixels, sample};
use crate::input::ShadowInput;
use crate::{FillStats, LightFrame, ShadowError};

/// The density clustering method (see the module documentation).
#[derive(Debug)]
pub struct DensityClustering {
    resolution: u32,
    /// Clusters (bins) per pixel.
    k: usize,
    trilinear: bool,
    pixels: Pixels,
    /// Per pixel `k` bins, after `prepare`.
    bins: Option<Vec<Bin>>,
}

impl DensityClustering {
    pub(crate) fn new(resolution: u32, clusters: u32, trilinear: bool) -> DensityClustering {
        DensityClustering {
            resolution,
            k: clusters as usize,
            trilinear,
            pixels: Pixels::default(),
            bins: None,
        }
    }

    pub(crate) fn density(&mut self, input: &ShadowInput) -> Result<FillStats, ShadowError> {
        self.bins = None;
        self.pixels.build(input, self.resolution)
    }

    pub(crate) fn transmittance(&mut self) {
        assert!(
            self.pixels.frame.is_some(),
            "the density stage runs before the transmittance stage"
        );
        let k = self.k;
        let frags = &self.pixels.frags;
        let mut bins = vec![Bin::EMPTY; self.pixels.count() * k];
        bins.par_chunks_mut(k)
            .enumerate()
            .for_each(|(pix, out)| cluster_bins(frags.of(pix), out));
        self.bins = Some(bins);
    }

    pub(crate) fn transmittance_at(&self, p: Vec3) -> f32 {
        let frame = self.pixels.frame();
        let bins = self
            .bins
            .as_ref()
            .expect("the transmittance stage runs before lookups");
        let k = self.k;
        let d = sample(frame, p, self.trilinear, 0.0, |pix, x| {
            bins[pix * k..(pix + 1) * k]
                .iter()
                .map(|b| b.depth(x))
                .sum()
        });
        (-d).exp()
    }

    pub(crate) fn frame(&self) -> Option<&LightFrame> {
        self.pixels.frame.as_ref()
    }
}

/// A bin of depths `[lo, hi]` (cells) adding optical depth `b`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Bin {
    pub(super) lo: f32,
    pub(super) hi: f32,
    pub(super) b: f32,
}

impl Bin {
    pub(super) const EMPTY: Bin = Bin {
        lo: f32::INFINITY,
        hi: f32::INFINITY,
        b: 0.0,
    };

    /// The bin's optical depth in front of depth `x`: uniform inside it; a
    /// bin of zero width is a step (all of it lies in front of `x > lo`).
    #[inline]
    pub(super) fn depth(&self, x: f32) -> f32 {
        if x <= self.lo {
            0.0
        } else if x >= self.hi {
            self.b
        } else {
            self.b * ((x - self.lo) / (self.hi - self.lo)).clamp(0.0, 1.0)
        }
    }
}

/// Density clustering of one pixel (Mertens et al. 2004, section 3):
/// `out.len()` initial centres spread uniformly from the nearest to the
/// farthest fragment, one k-means iteration with `beta`-weighted means,
/// `beta`-weighted standard deviations about the means, bins
/// `mu +- sqrt(3) sigma` (a uniform density of width `W` has
/// `sigma^2 = W^2 / 12`), overlaps cut at their midpoint, and every
/// fragment's `beta` in the bin that holds its depth or else in the nearest
/// cluster's.
pub(super) fn cluster_bins(fs: &[Frag], out: &mut [Bin]) {
    const GAMMA: f32 = 1.732_050_8; // sqrt(3)
    out.fill(Bin::EMPTY);
    if fs.is_empty() {
        return;
    }
    let k = out.len();
    // The nearest and farthest fragment centres, and where the pixel's
    // hair begins and ends.
    let (near, far, first, last) = fs.iter().fold(
        (
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::INFINITY,
            f32::NEG_INFINITY,
        ),
        |(a, b, c, d), f| {
            (
                a.min(f.mid()),
                b.max(f.mid()),
                c.min(f.z),
                d.max(f.z + f.len),
            )
        },
    );
    let nearest = |centres: &[f32], m: f32| {
        let mut best = 0;
        for (i, &c) in centres.iter().enumerate() {
            if (m - c).abs() < (m - centres[best]).abs() {
                best = i;
            }
        }
        best
    };
    let init: Vec<f32> = (0..k)
        .map(|i| {
            if k == 1 {
                0.5 * (near + far)
            } else {
                near + (far - near) * i as f32 / (k - 1) as f32
            }
        })
        .collect();
    // One iteration: weighted means of the fragments nearest each centre.
    let mut w = vec![0.0f64; k];
    let mut wm = vec![0.0f64; k];
    for f in fs {
        let c = nearest(&init, f.mid());
        w[c] += f64::from(f.beta);
        wm[c] += f64::from(f.beta) * f64::from(f.mid());
    }
    let mut mu: Vec<f32> = (0..k)
        .filter(|&c| w[c] > 0.0)
        .map(|c| ((wm[c] / w[c]) as f32).clamp(near, far))
        .collect();
    mu.sort_by(f32::total_cmp);
    // Weighted spread about each mean.
    let m = mu.len();
    let mut w = vec![0.0f64; m];
    let mut wv = vec![0.0f64; m];
    for f in fs {
        let c = nearest(&mu, f.mid());
        let d = f64::from(f.mid() - mu[c]);
        w[c] += f64::from(f.beta);
        wv[c] += f64::from(f.beta) * d * d;
    }
    // A bin never reaches past the pixel's hair (`first..last`): a cluster
    // with a wide spread would otherwise start in front of the nearest
    // fragment and shadow points that have no hair between them and the
    // light.
    let mut bins: Vec<Bin> = (0..m)
        .map(|c| {
            let sigma = if w[c] > 0.0 {
                (wv[c] / w[c]).sqrt() as f32
            } else {
                0.0
            };
            let lo = (mu[c] - GAMMA * sigma).max(first);
            Bin {
                lo,
                hi: (mu[c] + GAMMA * sigma).min(last).max(lo),
                b: 0.0,
            }
        })
        .collect();
    // Overlapping neighbours meet at the midpoint of the overlap.
    for c in 1..m {
        let (l, r) = bins.split_at_mut(c);
        let (a, b) = (&mut l[c - 1], &mut r[0]);
        if a.hi > b.lo {
            let mid = (0.5 * (a.hi + b.lo)).clamp(a.lo, b.hi.max(a.lo));
            a.hi = mid;
            b.lo = mid;
            b.hi = b.hi.max(mid);
        }
    }
    for f in fs {
        let x = f.mid();
        let c = bins
            .iter()
            .position(|b| b.lo <= x && x <= b.hi)
            .unwrap_or_else(|| nearest(&mu, x));
        bins[c].b += f.beta;
    }
    out[..m].copy_from_slice(&bins);
}
