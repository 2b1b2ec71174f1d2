//! Comparing the self-shadow of two renderers picture to picture.
//!
//! Two renderers seldom agree on absolute brightness (another fiber model,
//! another filter, another light unit), but both can render the same frame
//! with and without shadows. The shadow ratio of a block of `b x b` pixels
//! is
//!
//! ```text
//! R = sum Y(shadowed) / sum Y(unshadowed)      (Y: linear luminance)
//! ```
//!
//! the fraction of the direct light that reaches what the block shows.
//! Scale cancels; what is left is visibility. Blocks that show too little
//! (unshadowed mean below a fraction [`LIT_FRACTION`] of the picture's
//! 90th percentile block) are left out: background, and hair lit from
//! behind whose ratio is noise over nothing.

use glam::Vec3;

/// A block counts when its unshadowed mean luminance is at least this
/// fraction of the 90th percentile of the picture's blocks.
pub const LIT_FRACTION: f32 = 0.05;

/// Linear luminance (Rec. 709 weights).
fn luminance(c: Vec3) -> f32 {
    0.2126 * c.x + 0.7152 * c.y + 0.0722 * c.z
}

/// An 8-bit sRGB value in linear units (the inverse of the sRGB curve).
pub fn srgb8_to_linear(v: u8) -> f32 {
    let c = f32::from(v) / 255.0;
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// The shadow ratio of every block of a picture.
#[derive(Debug, Clone, PartialEq)]
pub struct ShadowRatios {
    /// Blocks across and down.
    pub cols: usize,
    /// Blocks down.
    pub rows: usize,
    /// Per block, row by row: `R`, or `None` where it shows too little.
    pub ratio: Vec<Option<f32>>,
    /// Per block, as `ratio`: `sum Y(shadowed)` and `sum Y(unshadowed)`
    /// (a pixel that is not finite counting as dark).
    pub sums: Vec<(f64, f64)>,
}

impl ShadowRatios {
    /// The ratios of `shadowed` over `unshadowed` (linear RGB, `width x
    /// height` pixels row by row) in blocks of `block x block` pixels
    /// (partial blocks at the right and bottom edges are dropped).
    ///
    /// # Panics
    /// When the pictures are not `width * height` pixels or `block` is 0.
    pub fn new(
        shadowed: &[Vec3],
        unshadowed: &[Vec3],
        width: usize,
        height: usize,
        block: usize,
    ) -> ShadowRatios {
        assert!(block > 0, "a block has pixels");
        assert_eq!(
            shadowed.len(),
            width * height,
            "the shadowed picture's size"
        );
        assert_eq!(
            unshadowed.len(),
            width * height,
            "the unshadowed picture's size"
        );
        let (cols, rows) = (width / block, height / block);
        let mut sums = vec![(0.0f64, 0.0f64); cols * rows];
        for y in 0..rows * block {
            for x in 0..cols * block {
                let i = y * width + x;
                // A non-finite pixel counts as dark: no NaN spreads.
                let finite = |c: Vec3| {
                    if c.is_finite() {
                        luminance(c).max(0.0)
                    } else {
                        0.0
                    }
                };
                let s = &mut sums[(y / block) * cols + x / block];
                s.0 += f64::from(finite(shadowed[i]));
                s.1 += f64::from(finite(unshadowed[i]));
            }
        }
        let mut lit: Vec<f64> = sums.iter().map(|s| s.1).collect();
        lit.sort_by(f64::total_cmp);
        let p90 = lit.get(lit.len() * 9 / 10).copied().unwrap_or(0.0);
        let floor = f64::from(LIT_FRACTION) * p90;
        let ratio = sums
            .iter()
            .map(|&(s, u)| (u > floor && u > 0.0).then(|| (s / u) as f32))
            .collect();
        ShadowRatios {
            cols,
            rows,
            ratio,
            sums,
        }
    }

    /// Mean `R` over the blocks that count.
    pub fn mean(&self) -> f64 {
        let v: Vec<f64> = self.ratio.iter().flatten().map(|&r| f64::from(r)).collect();
        v.iter().sum::<f64>() / v.len().max(1) as f64
    }
}

/// Two renderers' shadow ratios, block by block.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RatioComparison {
    /// Blocks counted in both.
    pub blocks: usize,
    /// Mean `|R - R_ref|`.
    pub mean_abs: f64,
    /// Mean `R` over those blocks.
    pub mean: f64,
    /// Mean `R_ref` over those blocks.
    pub mean_ref: f64,
    /// Pearson correlation of `R` and `R_ref` (0 when either is flat).
    pub correlation: f64,
}

impl RatioComparison {
    /// Compares `a` with `reference` over the blocks both count.
    ///
    /// # Panics
    /// When the two are not of the same blocks.
    pub fn new(a: &ShadowRatios, reference: &ShadowRatios) -> RatioComparison {
        assert_eq!(
            (a.cols, a.rows),
            (reference.cols, reference.rows),
            "the same blocks"
        );
        let pairs: Vec<(f64, f64)> = a
            .ratio
            .iter()
            .zip(&reference.ratio)
            .filter_map(|(x, y)| Some((f64::from((*x)?), f64::from((*y)?))))
            .collect();
        let n = pairs.len().max(1) as f64;
        let mean = pairs.iter().map(|p| p.0).sum::<f64>() / n;
        let mean_ref = pairs.iter().map(|p| p.1).sum::<f64>() / n;
        let mean_abs = pairs.iter().map(|p| (p.0 - p.1).abs()).sum::<f64>() / n;
        let (mut sxy, mut sxx, mut syy) = (0.0, 0.0, 0.0);
        for &(x, y) in &pairs {
            sxy += (x - mean) * (y - mean_ref);
            sxx += (x - mean) * (x - mean);
            syy += (y - mean_ref) * (y - mean_ref);
        }
        let correlation = if sxx > 0.0 && syy > 0.0 {
            sxy / (sxx * syy).sqrt()
        } else {
            0.0
        };
        RatioComparison {
            blocks: pairs.len(),
            mean_abs,
            mean,
            mean_ref,
            correlation,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn srgb_round_trips_through_the_encoder() {
        for v in 0..=255u8 {
            assert_eq!(crate::to_srgb8(Vec3::splat(srgb8_to_linear(v)))[0], v);
        }
    }

    #[test]
    fn ratios_ignore_scale_and_dark_blocks() {
        // 4x2 blocks of 2x2 pixels: left half lit at 1, right half at 0.001
        // (under 5 % of the lit blocks: left out); the shadowed picture
        // keeps 30 % of the light at half the brightness scale.
        let (w, h) = (8, 4);
        let un: Vec<Vec3> = (0..w * h)
            .map(|i| Vec3::splat(if i % w < 4 { 1.0 } else { 0.001 }))
            .collect();
        let sh: Vec<Vec3> = un.iter().map(|&c| c * 0.3).collect();
        let r = ShadowRatios::new(&sh, &un, w, h, 2);
        assert_eq!((r.cols, r.rows), (4, 2));
        let counted: Vec<f32> = r.ratio.iter().flatten().copied().collect();
        assert_eq!(counted.len(), 4);
        assert!(counted.iter().all(|&x| (x - 0.3).abs() < 1e-6));
        // Another renderer twice as bright with the same shadow agrees.
        let un2: Vec<Vec3> = un.iter().map(|&c| c * 2.0).collect();
        let sh2: Vec<Vec3> = sh.iter().map(|&c| c * 2.0).collect();
        let r2 = ShadowRatios::new(&sh2, &un2, w, h, 2);
        let c = RatioComparison::new(&r2, &r);
        assert_eq!(c.blocks, 4);
        assert!(c.mean_abs < 1e-6 && (c.mean - 0.3).abs() < 1e-6);
    }

    #[test]
    fn a_shadow_twice_as_dark_is_measured_so() {
        let (w, h) = (16, 16);
        // A gradient of shadow across the picture.
        let un = vec![Vec3::ONE; w * h];
        let sh: Vec<Vec3> = (0..w * h)
            .map(|i| Vec3::splat(0.2 + 0.6 * (i % w) as f32 / w as f32))
            .collect();
        let half: Vec<Vec3> = sh.iter().map(|&c| c * 0.5).collect();
        let r = ShadowRatios::new(&sh, &un, w, h, 4);
        let r_half = ShadowRatios::new(&half, &un, w, h, 4);
        let c = RatioComparison::new(&r_half, &r);
        assert_eq!(c.blocks, 16);
        assert!((c.mean / c.mean_ref - 0.5).abs() < 1e-6);
        assert!((c.mean_abs - 0.5 * c.mean_ref).abs() < 1e-6);
        assert!((c.correlation - 1.0).abs() < 1e-9);
    }

    #[test]
    fn non_finite_pixels_count_as_dark() {
        let un = vec![Vec3::ONE; 4];
        let sh = vec![Vec3::NAN, Vec3::ONE, Vec3::ONE, Vec3::ONE];
        let r = ShadowRatios::new(&sh, &un, 2, 2, 2);
        assert_eq!(r.ratio, vec![Some(0.75)]);
    }
}
