//! A partial picture: the exact hair sums of some of a frame's strands at
//! the pixels they touch, for compositing elsewhere (sort-last, as IceT
//! composites the partial images of a cluster).

use super::Sums;
use crate::RasterError;

/// The exact hair sums of the strands one canvas drew, at the pixels they
/// touched: sparse, in ascending pixel order (row-major). Layers of
/// disjoint sets of strand groups add up, in any order, to the sums of
/// all of them; [`super::Canvas::resolve_layers`] composites them.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct HairLayer {
    width: u32,
    height: u32,
    /// Row-major pixel indices, strictly ascending.
    pixels: Vec<u32>,
    sums: Vec<Sums>,
}

impl HairLayer {
    /// A layer of an image `width` x `height` from its touched pixels
    /// (row-major indices, strictly ascending) and their sums; refuses
    /// anything else.
    pub fn from_parts(
        width: u32,
        height: u32,
        pixels: Vec<u32>,
        sums: Vec<Sums>,
    ) -> Result<HairLayer, RasterError> {
        let n = u64::from(width) * u64::from(height);
        let bad = |why: String| RasterError::Layer(why);
        if pixels.len() != sums.len() {
            return Err(bad(format!(
                "{} pixels with {} sums",
                pixels.len(),
                sums.len()
            )));
        }
        if pixels.windows(2).any(|w| w[1] <= w[0]) {
            return Err(bad("pixels not in strictly ascending order".into()));
        }
        if let Some(&last) = pixels.last()
            && u64::from(last) >= n
        {
            return Err(bad(format!(
                "pixel {last} outside a {width}x{height} picture"
            )));
        }
        Ok(HairLayer {
            width,
            height,
            pixels,
            sums,
        })
    }

    pub(super) fn new(width: u32, height: u32) -> HairLayer {
        HairLayer {
            width,
            height,
            pixels: Vec::new(),
            sums: Vec::new(),
        }
    }

    pub(super) fn push(&mut self, pixel: u32, sums: Sums) {
        debug_assert!(self.pixels.last().is_none_or(|&p| p < pixel));
        self.pixels.push(pixel);
        self.sums.push(sums);
    }

    /// Appends `other`, whose pixels all follow this layer's.
    pub(super) fn append(&mut self, other: HairLayer) {
        debug_assert!(
            self.pixels
                .last()
                .zip(other.pixels.first())
                .is_none_or(|(a, b)| a < b)
        );
        self.pixels.extend(other.pixels);
        self.sums.extend(other.sums);
    }

    /// Appends `other`, a layer of the same picture whose pixels all
    /// follow this layer's (say, the next band of rows down).
    pub fn append_layer(&mut self, other: HairLayer) {
        assert!(
            self.pixels
                .last()
                .zip(other.pixels.first())
                .is_none_or(|(a, b)| a < b)
                && (self.width, self.height) == (other.width, other.height),
            "appended layers follow each other in one picture"
        );
        self.append(other);
    }

    /// Picture width, pixels.
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Picture height, pixels.
    pub fn height(&self) -> u32 {
        self.height
    }

    /// The touched pixels, row-major indices in ascending order.
    pub fn pixels(&self) -> &[u32] {
        &self.pixels
    }

    /// The sums at [`Self::pixels`].
    pub fn sums(&self) -> &[Sums] {
        &self.sums
    }

    /// The entries whose pixels lie in `first..end` (row-major indices).
    pub(super) fn range(&self, first: u32, end: u32) -> (&[u32], &[Sums]) {
        let a = self.pixels.partition_point(|&p| p < first);
        let b = a + self.pixels[a..].partition_point(|&p| p < end);
        (&self.pixels[a..b], &self.sums[a..b])
    }
}
