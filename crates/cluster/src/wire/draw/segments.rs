//! Sort-middle on the wire: a worker's shaded segments of another
//! worker's bands (see [`raster::BandSegments`]), each band's bytes in
//! pieces, read back and checked band by band.

use raster::BandSegments;

use super::super::{Malformed, bad};
use crate::pb;

/// Bytes of one piece of a band's segments: the chunks stream while the
/// rest is encoded.
pub(crate) const SEGMENT_PIECE_BYTES: usize = 1 << 20;

/// The chunks of `segments` (a band of a `width x height` picture): its
/// bytes in pieces, the last marked.
pub(crate) fn segment_chunks(
    segments: &BandSegments,
    width: u32,
    height: u32,
) -> Vec<pb::LayerChunk> {
    let mut bytes = Vec::new();
    segments.encode(&mut bytes);
    let pieces = bytes.len().div_ceil(SEGMENT_PIECE_BYTES).max(1);
    bytes
        .chunks(SEGMENT_PIECE_BYTES)
        .enumerate()
        .map(|(i, piece)| pb::LayerChunk {
            width,
            height,
            segments: piece.to_vec(),
            segments_end: i + 1 == pieces,
            ..Default::default()
        })
        .collect()
}

/// Receives a Composite call's segments of a `width x height` picture:
/// band after band, each decoded (and checked) once its last piece came.
#[derive(Debug)]
pub(crate) struct SegmentReader {
    width: u32,
    height: u32,
    /// The band being received, so far.
    pending: Vec<u8>,
    bands: Vec<BandSegments>,
}

impl SegmentReader {
    /// A reader of segments of a `width x height` picture.
    pub(crate) fn new(width: u32, height: u32) -> SegmentReader {
        SegmentReader {
            width,
            height,
            pending: Vec::new(),
            bands: Vec::new(),
        }
    }

    /// Adds a chunk, checked: segments alone (and the header's fields).
    pub(crate) fn add(&mut self, c: &pb::LayerChunk) -> Result<(), Malformed> {
        if (c.width, c.height) != (self.width, self.height) {
            return Err(bad(format!(
                "segments of a {}x{} picture for a frame of {}x{}",
                c.width, c.height, self.width, self.height
            )));
        }
        if c.count != 0 || !c.pixels.is_empty() || !c.sums.is_empty() || !c.fronts.is_empty() {
            return Err(bad("pixels in a call of segments"));
        }
        if c.segments.len() > SEGMENT_PIECE_BYTES {
            return Err(bad(format!(
                "a piece of {} bytes of segments (at most {SEGMENT_PIECE_BYTES})",
                c.segments.len()
            )));
        }
        self.pending.extend_from_slice(&c.segments);
        if c.segments_end {
            let band =
                BandSegments::decode(&self.pending, self.height).map_err(|e| bad(e.to_string()))?;
            self.pending.clear();
            self.bands.push(band);
        }
        Ok(())
    }

    /// Every band's segments, once the call ended.
    pub(crate) fn finish(self) -> Result<Vec<BandSegments>, Malformed> {
        if !self.pending.is_empty() {
            return Err(bad("a band's segments end without their last piece"));
        }
        Ok(self.bands)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn segments_cross_the_wire_in_pieces_and_anything_else_is_refused() {
        // An empty band's segments: one piece, marked last.
        let empty = BandSegments::default();
        let chunks = segment_chunks(&empty, 64, 48);
        assert_eq!(chunks.len(), 1);
        assert!(chunks[0].segments_end);
        // Rows 0..0 are no band.
        let mut r = SegmentReader::new(64, 48);
        assert!(r.add(&chunks[0]).is_err());
        // A piece too large, pixels among segments, another picture size,
        // a band without its last piece.
        let mut r = SegmentReader::new(64, 48);
        let big = pb::LayerChunk {
            width: 64,
            height: 48,
            segments: vec![0; SEGMENT_PIECE_BYTES + 1],
            ..Default::default()
        };
        assert!(r.add(&big).is_err());
        let pixels = pb::LayerChunk {
            width: 64,
            height: 48,
            count: 1,
            pixels: vec![1],
            ..Default::default()
        };
        assert!(r.add(&pixels).is_err());
        let other = pb::LayerChunk {
            width: 65,
            height: 48,
            ..Default::default()
        };
        assert!(r.add(&other).is_err());
        let mut r = SegmentReader::new(64, 48);
        let piece = pb::LayerChunk {
            width: 64,
            height: 48,
            segments: vec![0; 8],
            ..Default::default()
        };
        r.add(&piece).unwrap();
        assert!(r.finish().is_err());
    }
}
