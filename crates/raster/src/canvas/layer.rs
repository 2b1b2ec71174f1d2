//! A partial picture: the exact hair sums of some of a frame's strands at
//! the pixels they touch, for compositing elsewhere (sort-last, as IceT
//! composites the partial images of a cluster).

use super::{Fragment, MAX_NEAREST, Sums};
use crate::RasterError;

/// The exact hair sums of the strands one canvas drew, at the pixels they
/// touched, with each pixel's nearest fragments (none unless the canvas
/// keeps some, see [`super::Canvas::set_nearest`]): sparse, in ascending
/// pixel order (row-major). Layers of disjoint sets of strand groups add
/// up, in any order, to the sums of all of them;
/// [`super::Canvas::resolve_layers`] composites them.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct HairLayer {
    width: u32,
    height: u32,
    /// Row-major pixel indices, strictly ascending.
    pixels: Vec<u32>,
    sums: Vec<Sums>,
    /// Where each pixel's nearest fragments start in `fronts` (one more
    /// than the pixels; empty when no pixel has any).
    front_start: Vec<u32>,
    fronts: Vec<Fragment>,
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
            front_start: Vec::new(),
            fronts: Vec::new(),
        })
    }

    /// [`Self::from_parts`] with each pixel's nearest fragments: `counts`
    /// per pixel (at most [`MAX_NEAREST`]), `fronts` all of them in pixel
    /// order, each pixel's nearest first; refuses a fragment out of range
    /// or out of order.
    pub fn from_parts_with_fronts(
        width: u32,
        height: u32,
        pixels: Vec<u32>,
        sums: Vec<Sums>,
        counts: &[u8],
        fronts: Vec<Fragment>,
    ) -> Result<HairLayer, RasterError> {
        let mut layer = HairLayer::from_parts(width, height, pixels, sums)?;
        let bad = |why: String| RasterError::Layer(why);
        if counts.len() != layer.pixels.len() {
            return Err(bad(format!(
                "{} pixels with {} fragment counts",
                layer.pixels.len(),
                counts.len()
            )));
        }
        let mut start = Vec::with_capacity(counts.len() + 1);
        let mut at = 0usize;
        start.push(0);
        for &n in counts {
            if n as usize > MAX_NEAREST {
                return Err(bad(format!(
                    "{n} nearest fragments at a pixel, at most {MAX_NEAREST}"
                )));
            }
            at += n as usize;
            start.push(at as u32);
        }
        if at != fronts.len() {
            return Err(bad(format!(
                "{at} fragments counted, {} given",
                fronts.len()
            )));
        }
        for w in start.windows(2) {
            let list = &fronts[w[0] as usize..w[1] as usize];
            if let Some(f) = list.iter().find(|f| !f.is_valid()) {
                return Err(bad(format!("a fragment out of range: {f:?}")));
            }
            if list.windows(2).any(|p| p[1].precedes(&p[0])) {
                return Err(bad("a pixel's fragments out of depth order".into()));
            }
        }
        if at > 0 {
            layer.front_start = start;
            layer.fronts = fronts;
        }
        Ok(layer)
    }

    pub(super) fn new(width: u32, height: u32) -> HairLayer {
        HairLayer {
            width,
            height,
            pixels: Vec::new(),
            sums: Vec::new(),
            front_start: Vec::new(),
            fronts: Vec::new(),
        }
    }

    pub(super) fn push(&mut self, pixel: u32, sums: Sums, front: &[Fragment]) {
        debug_assert!(self.pixels.last().is_none_or(|&p| p < pixel));
        if !front.is_empty() && self.front_start.is_empty() {
            self.front_start = vec![0; self.pixels.len() + 1];
        }
        self.pixels.push(pixel);
        self.sums.push(sums);
        if !self.front_start.is_empty() {
            self.fronts.extend_from_slice(front);
            self.front_start.push(self.fronts.len() as u32);
        }
    }

    /// Appends `other`, whose pixels all follow this layer's.
    pub(super) fn append(&mut self, other: HairLayer) {
        debug_assert!(
            self.pixels
                .last()
                .zip(other.pixels.first())
                .is_none_or(|(a, b)| a < b)
        );
        if other.front_start.is_empty() && self.front_start.is_empty() {
            self.pixels.extend(other.pixels);
            self.sums.extend(other.sums);
            return;
        }
        for i in 0..other.pixels.len() {
            let front = other.front(i).to_vec();
            self.push(other.pixels[i], other.sums[i], &front);
        }
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

    /// The nearest fragments of entry `i` (of [`Self::pixels`]), nearest
    /// first.
    pub fn front(&self, i: usize) -> &[Fragment] {
        if self.front_start.is_empty() {
            return &[];
        }
        &self.fronts[self.front_start[i] as usize..self.front_start[i + 1] as usize]
    }

    /// Every nearest fragment of the layer.
    pub fn fragments(&self) -> usize {
        self.fronts.len()
    }

    /// The entries `a..b` whose pixels lie in `first..end` (row-major
    /// indices).
    pub(super) fn range(&self, first: u32, end: u32) -> (usize, usize) {
        let a = self.pixels.partition_point(|&p| p < first);
        let b = a + self.pixels[a..].partition_point(|&p| p < end);
        (a, b)
    }
}
