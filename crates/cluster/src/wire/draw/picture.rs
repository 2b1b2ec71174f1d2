//! Partial pictures on the wire: a worker's hair layer in chunks of
//! pixels with its times, and the stripes of a band the workers composite
//! among themselves, each read back with every count checked.

use prost::encoding::{decode_varint, encode_varint};
use raster::{Fragment, HairLayer, Sums};

use super::super::{Malformed, bad};
use super::PIXELS_PER_CHUNK;
use crate::pb;

/// A partial picture as chunks; the last carries the worker's times (an
/// empty picture is one empty chunk). Workers stream stripes instead
/// ([`StripeEncoder`]); this whole-picture form is what the tests hold
/// them to.
#[cfg(test)]
pub(crate) fn layer_chunks(layer: &HairLayer, times: &engine::DrawTimes) -> Vec<pb::LayerChunk> {
    let n = layer.pixels().len();
    let mut prev = 0;
    let mut chunks: Vec<pb::LayerChunk> = (0..n.max(1))
        .step_by(PIXELS_PER_CHUNK)
        .map(|s| encode_pixels(layer, s..(s + PIXELS_PER_CHUNK).min(n), &mut prev))
        .collect();
    set_times(chunks.last_mut().expect("one chunk at least"), times);
    chunks
}

/// Encodes a partial picture sent a stripe of rows at a time, top to
/// bottom (see [`engine::Share::draw_stripes`]): the chunks of each stripe
/// as it comes, then [`Self::last`]. The chunks are those of the whole
/// picture to a [`LayerReader`].
#[derive(Debug)]
pub(crate) struct StripeEncoder {
    /// The pixel before the next one encoded.
    prev: u32,
}

impl StripeEncoder {
    /// An encoder at the first stripe.
    pub(crate) fn new() -> StripeEncoder {
        StripeEncoder { prev: 0 }
    }

    /// The chunks of `stripe` (none for an empty stripe), whose pixels
    /// follow every earlier stripe's.
    pub(crate) fn chunks(&mut self, stripe: &HairLayer) -> Vec<pb::LayerChunk> {
        let n = stripe.pixels().len();
        (0..n)
            .step_by(PIXELS_PER_CHUNK)
            .map(|s| encode_pixels(stripe, s..(s + PIXELS_PER_CHUNK).min(n), &mut self.prev))
            .collect()
    }

    /// The last chunk, with no pixels: the worker's times.
    pub(crate) fn last(
        &self,
        width: u32,
        height: u32,
        times: &engine::DrawTimes,
    ) -> pb::LayerChunk {
        let mut c = pb::LayerChunk {
            width,
            height,
            ..Default::default()
        };
        set_times(&mut c, times);
        c
    }
}

impl Default for StripeEncoder {
    fn default() -> StripeEncoder {
        StripeEncoder::new()
    }
}

fn set_times(c: &mut pb::LayerChunk, times: &engine::DrawTimes) {
    c.filter_ms = times.filter_ms;
    c.shade_ms = times.shade_ms;
    c.raster_ms = times.raster_ms;
    c.wait_ms = times.wait_ms;
    c.composite_ms = times.composite_ms;
}

/// A chunk's times, when every one is a finite count of milliseconds.
fn times_of(c: &pb::LayerChunk) -> Option<engine::DrawTimes> {
    let t = [
        c.filter_ms,
        c.shade_ms,
        c.raster_ms,
        c.wait_ms,
        c.composite_ms,
    ];
    t.iter()
        .all(|v| v.is_finite() && *v >= 0.0)
        .then_some(engine::DrawTimes {
            filter_ms: t[0],
            shade_ms: t[1],
            raster_ms: t[2],
            wait_ms: t[3],
            composite_ms: t[4],
        })
}

/// Rows of finished pixels a band chunk holds at most (about 250 KB of a
/// 1280-pixel-wide picture).
pub(crate) const ROWS_PER_CHUNK: u32 = 64;

/// A band's finished rows (8-bit sRGB, row after row, from `first_row`)
/// as Draw reply chunks: runs of the pixels that are not `background`.
pub(crate) fn band_chunks(
    width: u32,
    height: u32,
    first_row: u32,
    rgb: &[u8],
    background: [u8; 3],
) -> Vec<pb::LayerChunk> {
    let row_bytes = 3 * width as usize;
    rgb.chunks(ROWS_PER_CHUNK as usize * row_bytes.max(1))
        .enumerate()
        .map(|(k, part)| {
            let mut c = pb::LayerChunk {
                width,
                height,
                first_row: first_row + k as u32 * ROWS_PER_CHUNK,
                rows: (part.len() / row_bytes.max(1)) as u32,
                background: background.to_vec(),
                ..Default::default()
            };
            let mut skip = 0u64;
            let mut px = part.chunks_exact(3).peekable();
            while px.peek().is_some() {
                let mut run = 0u64;
                while px.next_if(|p| *p == background).is_some() {
                    skip += 1;
                }
                while let Some(p) = px.next_if(|p| *p != background) {
                    c.rgb.extend_from_slice(p);
                    run += 1;
                }
                if run > 0 {
                    encode_varint(skip, &mut c.spans);
                    encode_varint(run, &mut c.spans);
                    skip = 0;
                }
            }
            c
        })
        .collect()
}

/// Receives one worker's bands of finished rows (`bands`, top to bottom,
/// each rows of a picture `width` x `height`), in order.
#[derive(Debug)]
pub(crate) struct BandReader {
    width: u32,
    height: u32,
    bands: Vec<(std::ops::Range<u32>, Vec<u8>)>,
    /// The band being received.
    at: usize,
    background: Option<[u8; 3]>,
    /// The worker's times, from the last chunk.
    pub times: engine::DrawTimes,
    /// Bytes of stripes the worker sent the others, from the last chunk.
    pub stripes_sent: u64,
    /// What drawing each band took on the worker, ms, from the last chunk.
    pub band_ms: Vec<f64>,
}

impl BandReader {
    /// A reader of the finished `bands` of a `width x height` picture.
    pub(crate) fn new(width: u32, height: u32, bands: Vec<std::ops::Range<u32>>) -> BandReader {
        BandReader {
            width,
            height,
            bands: bands.into_iter().map(|r| (r, Vec::new())).collect(),
            at: 0,
            background: None,
            times: engine::DrawTimes::default(),
            stripes_sent: 0,
            band_ms: Vec::new(),
        }
    }

    /// The next row band `b` needs.
    fn next_row(&self, b: usize) -> u32 {
        let (rows, rgb) = &self.bands[b];
        rows.start + (rgb.len() / (3 * self.width as usize).max(1)) as u32
    }

    /// Adds a chunk, checked.
    pub(crate) fn add(&mut self, c: &pb::LayerChunk) -> Result<(), Malformed> {
        if (c.width, c.height) != (self.width, self.height) {
            return Err(bad(format!(
                "a band of a {}x{} picture for a frame of {}x{}",
                c.width, c.height, self.width, self.height
            )));
        }
        if c.count != 0 || !c.pixels.is_empty() || !c.sums.is_empty() {
            return Err(bad("partial-picture pixels in a band of finished rows"));
        }
        if c.rows == 0 && c.spans.is_empty() && c.rgb.is_empty() {
            if let Some(t) = times_of(c) {
                if c.drawn {
                    self.times = engine::DrawTimes {
                        wait_ms: self.times.wait_ms,
                        composite_ms: self.times.composite_ms,
                        ..t
                    };
                } else {
                    self.times = t;
                }
            }
            if !c.drawn {
                self.stripes_sent = c.stripes_sent;
                if !c.band_ms.is_empty() {
                    if c.band_ms.len() != self.bands.len()
                        || c.band_ms.iter().any(|m| !m.is_finite() || *m < 0.0)
                    {
                        return Err(bad(format!(
                            "{} band times for {} bands",
                            c.band_ms.len(),
                            self.bands.len()
                        )));
                    }
                    self.band_ms = c.band_ms.clone();
                }
            }
            return Ok(());
        }
        while self.at < self.bands.len() && self.next_row(self.at) == self.bands[self.at].0.end {
            self.at += 1;
        }
        let Some((rows, _)) = self.bands.get(self.at) else {
            return Err(bad("rows past the worker's bands"));
        };
        let next = self.next_row(self.at);
        if c.first_row != next || c.rows > rows.end - next {
            return Err(bad(format!(
                "rows {}..{} where the band {rows:?} needs row {next}",
                c.first_row,
                u64::from(c.first_row) + u64::from(c.rows),
            )));
        }
        let bg: [u8; 3] = c
            .background
            .as_slice()
            .try_into()
            .map_err(|_| bad(format!("a background of {} bytes", c.background.len())))?;
        if self.background.is_some_and(|b| b != bg) {
            return Err(bad("the bands' background changes"));
        }
        self.background = Some(bg);
        let n = c.rows as usize * self.width as usize;
        let out = &mut self.bands[self.at].1;
        out.reserve(3 * n);
        let (mut spans, mut colors, mut at) = (&c.spans[..], &c.rgb[..], 0usize);
        let varint =
            |b: &mut &[u8]| decode_varint(b).map_err(|e| bad(format!("a band's runs: {e}")));
        while !spans.is_empty() {
            let (skip, run) = (varint(&mut spans)?, varint(&mut spans)?);
            let end = (at as u64).saturating_add(skip).saturating_add(run);
            if run == 0 || end > n as u64 || run.saturating_mul(3) > colors.len() as u64 {
                return Err(bad(format!(
                    "a run of {run} pixels after {skip} at pixel {at} of a chunk of {n}"
                )));
            }
            for _ in 0..skip {
                out.extend_from_slice(&bg);
            }
            let (sent, rest) = colors.split_at(3 * run as usize);
            out.extend_from_slice(sent);
            colors = rest;
            at = end as usize;
        }
        if !colors.is_empty() {
            return Err(bad("colours left over in a band chunk"));
        }
        for _ in at..n {
            out.extend_from_slice(&bg);
        }
        Ok(())
    }

    /// Each band's rows and their pixels, once every row came.
    #[allow(clippy::type_complexity)]
    pub(crate) fn finish(self) -> Result<Vec<(std::ops::Range<u32>, Vec<u8>)>, Malformed> {
        for b in 0..self.bands.len() {
            if self.next_row(b) != self.bands[b].0.end {
                return Err(bad(format!(
                    "the band {:?} ended at row {}",
                    self.bands[b].0,
                    self.next_row(b)
                )));
            }
        }
        Ok(self.bands)
    }
}

/// Pixel entries `range` of `layer` as a chunk: each pixel's step from the
/// one before (`prev`, updated), then its sums, as varints.
fn encode_pixels(
    layer: &HairLayer,
    range: std::ops::Range<usize>,
    prev: &mut u32,
) -> pb::LayerChunk {
    let mut c = pb::LayerChunk {
        width: layer.width(),
        height: layer.height(),
        count: range.len() as u32,
        ..Default::default()
    };
    c.pixels.reserve(2 * range.len());
    c.sums.reserve(16 * range.len());
    for (&p, s) in layer.pixels()[range.clone()]
        .iter()
        .zip(&layer.sums()[range.clone()])
    {
        encode_varint(u64::from(p - *prev), &mut c.pixels);
        *prev = p;
        for v in s.rgbw {
            encode_varint(v as u64, &mut c.sums);
        }
        encode_varint(s.absorb, &mut c.sums);
    }
    if layer.fragments() > 0 {
        c.fronts
            .reserve(range.len() + 24 * layer.fragments().min(16 * range.len()));
        for i in range {
            let front = layer.front(i);
            c.fronts.push(front.len() as u8);
            for f in front {
                let mut bytes = [0u8; 24];
                for (b, v) in bytes
                    .chunks_exact_mut(4)
                    .zip([f.z, f.color.x, f.color.y, f.color.z, f.alpha, f.weight])
                {
                    b.copy_from_slice(&v.to_le_bytes());
                }
                c.fronts.extend_from_slice(&bytes);
            }
        }
    }
    c
}

/// Receives a partial picture's chunks for a frame of `width` x `height`.
#[derive(Debug)]
pub(crate) struct LayerReader {
    width: u32,
    height: u32,
    pixels: Vec<u32>,
    sums: Vec<Sums>,
    /// Each pixel's count of nearest fragments, and the fragments.
    counts: Vec<u8>,
    fronts: Vec<Fragment>,
    /// The worker's times, from the last chunk.
    pub times: engine::DrawTimes,
}

impl LayerReader {
    /// A reader of a `width x height` partial picture.
    pub(crate) fn new(width: u32, height: u32) -> LayerReader {
        LayerReader {
            width,
            height,
            pixels: Vec::new(),
            sums: Vec::new(),
            counts: Vec::new(),
            fronts: Vec::new(),
            times: engine::DrawTimes::default(),
        }
    }

    /// Adds a chunk, checked.
    pub(crate) fn add(&mut self, c: &pb::LayerChunk) -> Result<(), Malformed> {
        if (c.width, c.height) != (self.width, self.height) {
            return Err(bad(format!(
                "a partial picture of {}x{} for a frame of {}x{}",
                c.width, c.height, self.width, self.height
            )));
        }
        let total = u64::from(self.width) * u64::from(self.height);
        let count = c.count as usize;
        // Each pixel takes a byte at least, and there are no more than the picture's.
        if count > c.pixels.len() || self.pixels.len() as u64 + count as u64 > total {
            return Err(bad(format!("{count} pixels in {} bytes", c.pixels.len())));
        }
        let mut px = &c.pixels[..];
        let mut sums = &c.sums[..];
        let mut at = self.pixels.last().copied();
        self.pixels.reserve(count);
        self.sums.reserve(count);
        let varint =
            |b: &mut &[u8]| decode_varint(b).map_err(|e| bad(format!("a partial picture: {e}")));
        for _ in 0..count {
            let step = varint(&mut px)?;
            let p = match at {
                Some(a) if step == 0 => return Err(bad(format!("pixel {a} comes twice"))),
                Some(a) => u64::from(a).saturating_add(step),
                None => step,
            };
            if p >= total {
                return Err(bad(format!("pixel {p} outside the picture")));
            }
            let mut s = Sums::ZERO;
            for v in &mut s.rgbw {
                *v = varint(&mut sums)? as i64;
            }
            s.absorb = varint(&mut sums)?;
            self.pixels.push(p as u32);
            self.sums.push(s);
            at = Some(p as u32);
        }
        if !px.is_empty() || !sums.is_empty() {
            return Err(bad("bytes left over in a partial picture chunk"));
        }
        self.read_fronts(count, &c.fronts)?;
        if let Some(t) = times_of(c) {
            self.times = t;
        }
        Ok(())
    }

    /// The nearest fragments of a chunk's `count` pixels (none at all, or
    /// a count byte for each); checked when the layer is finished.
    fn read_fronts(&mut self, count: usize, mut bytes: &[u8]) -> Result<(), Malformed> {
        if bytes.is_empty() {
            self.counts.resize(self.pixels.len(), 0);
            return Ok(());
        }
        for _ in 0..count {
            let (&n, rest) = bytes
                .split_first()
                .ok_or_else(|| bad("a partial picture's fragments end early"))?;
            if n as usize > raster::MAX_NEAREST {
                return Err(bad(format!(
                    "{n} nearest fragments at a pixel, at most {}",
                    raster::MAX_NEAREST
                )));
            }
            let need = 24 * n as usize;
            if rest.len() < need {
                return Err(bad("a partial picture's fragments end early"));
            }
            for f in rest[..need].chunks_exact(24) {
                let v = |i: usize| {
                    f32::from_le_bytes([f[4 * i], f[4 * i + 1], f[4 * i + 2], f[4 * i + 3]])
                };
                self.fronts.push(Fragment {
                    z: v(0),
                    color: glam::Vec3::new(v(1), v(2), v(3)),
                    alpha: v(4),
                    weight: v(5),
                });
            }
            self.counts.push(n);
            bytes = &rest[need..];
        }
        if !bytes.is_empty() {
            return Err(bad("bytes left over in a partial picture's fragments"));
        }
        Ok(())
    }

    /// The partial picture, once every chunk is in.
    pub(crate) fn finish(self) -> Result<HairLayer, Malformed> {
        if self.fronts.is_empty() {
            return HairLayer::from_parts(self.width, self.height, self.pixels, self.sums)
                .map_err(|e| bad(e.to_string()));
        }
        HairLayer::from_parts_with_fronts(
            self.width,
            self.height,
            self.pixels,
            self.sums,
            &self.counts,
            self.fronts,
        )
        .map_err(|e| bad(e.to_string()))
    }
}
