//! A share's drawn hair in some rows of a picture, as its projected and
//! shaded segments: what a cluster worker sends the worker that draws
//! those rows (sort-middle, in Molnar's classification: geometry is
//! shared out by object, pixels by screen region).
//!
//! A canvas bins every segment to the bands of rows its footprint can
//! reach ([`super::Canvas::draw_hair`]); [`super::Canvas::segments_rows`]
//! takes the segments binned to some rows out again, group by group in
//! strand order, and [`super::Canvas::draw_segments`] bins them on another
//! canvas. Drawn there with every other share's segments of those rows, in
//! the order of the groups, the rows are the same bytes as the whole hair
//! drawn on one canvas: each group sums its fragments in floats in strand
//! order, then folds them into exact integers, wherever it is drawn.

use std::ops::Range;

use glam::Vec3;

use super::look::{Look, Projected};
use super::{Canvas, HairLook, NO_REACH, footprint};
use crate::RasterError;

/// The drawn segments of some groups of strands in some rows of a picture:
/// runs of consecutive segments of one strand, as their projected vertices
/// (pixel position, view depth, shaded linear colour) with the look they
/// are drawn with. Made by [`super::Canvas::segments_rows`], drawn by
/// [`super::Canvas::draw_segments`]; [`Self::encode`] and
/// [`Self::decode`] carry it between processes, bit for bit.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct BandSegments {
    /// The rows these segments are drawn in (they may reach others).
    rows: Range<u32>,
    /// The looks the runs are drawn with.
    looks: Vec<Look>,
    /// Each group: its index among the whole hair's groups, and its runs'
    /// end in `runs`.
    groups: Vec<(u32, u32)>,
    /// Each run: its look and its vertex count (at least 2).
    runs: Vec<(u32, u32)>,
    /// The runs' vertices, run after run.
    verts: Vec<Projected>,
}

/// Bytes of one encoded vertex: six `f32`.
const VERTEX_BYTES: usize = 24;
/// Bytes of one encoded look: five `f32`.
const LOOK_BYTES: usize = 20;
/// The most looks one set of segments may carry.
const MAX_LOOKS: usize = 1024;

impl BandSegments {
    /// No segments, for rows `rows`.
    pub(super) fn new(rows: Range<u32>, looks: Vec<Look>) -> BandSegments {
        BandSegments {
            rows,
            looks,
            ..BandSegments::default()
        }
    }

    /// Starts group `id` (after every group so far).
    pub(super) fn begin_group(&mut self, id: u32) {
        self.groups.push((id, self.runs.len() as u32));
    }

    /// Adds a run of segments through `verts` (at least 2), drawn with
    /// look `look`, to the last group.
    pub(super) fn push_run(&mut self, look: u32, verts: impl ExactSizeIterator<Item = Projected>) {
        debug_assert!(verts.len() >= 2 && !self.groups.is_empty());
        self.runs.push((look, verts.len() as u32));
        self.verts.extend(verts);
        if let Some(g) = self.groups.last_mut() {
            g.1 = self.runs.len() as u32;
        }
    }

    /// The rows these segments are drawn in.
    pub fn rows(&self) -> Range<u32> {
        self.rows.clone()
    }

    /// The index of the first group among the whole hair's (`None`: no
    /// group).
    pub fn first_group(&self) -> Option<u32> {
        self.groups.first().map(|g| g.0)
    }

    /// The index of the last group among the whole hair's.
    pub fn last_group(&self) -> Option<u32> {
        self.groups.last().map(|g| g.0)
    }

    /// Segments held.
    pub fn segment_count(&self) -> usize {
        self.runs.iter().map(|r| r.1 as usize - 1).sum()
    }

    /// The looks, the groups (index, runs) and the runs with their
    /// vertices, for drawing.
    pub(super) fn parts(&self) -> (&[Look], GroupRuns<'_>) {
        (
            &self.looks,
            GroupRuns {
                of: self,
                group: 0,
                run: 0,
                vert: 0,
            },
        )
    }

    /// Bytes [`Self::encode`] writes.
    pub fn encoded_len(&self) -> usize {
        16 + LOOK_BYTES * self.looks.len()
            + 8 * self.groups.len()
            + 8 * self.runs.len()
            + VERTEX_BYTES * self.verts.len()
    }

    /// The segments as bytes (little-endian): rows, looks, then each group
    /// with its runs and their vertices. Every float keeps its bits.
    pub fn encode(&self, out: &mut Vec<u8>) {
        out.reserve(self.encoded_len());
        let u32s = |out: &mut Vec<u8>, v: u32| out.extend_from_slice(&v.to_le_bytes());
        let f32s = |out: &mut Vec<u8>, v: f32| out.extend_from_slice(&v.to_bits().to_le_bytes());
        u32s(out, self.rows.start);
        u32s(out, self.rows.end);
        u32s(out, self.looks.len() as u32);
        for l in &self.looks {
            for v in [
                l.look.fiber_width,
                l.look.opacity,
                l.look.depth_ref,
                l.look.simplify,
                l.width_z,
            ] {
                f32s(out, v);
            }
        }
        u32s(out, self.groups.len() as u32);
        let (mut run, mut vert) = (0usize, 0usize);
        for &(id, end) in &self.groups {
            u32s(out, id);
            u32s(out, end - run as u32);
            for &(look, n) in &self.runs[run..end as usize] {
                u32s(out, look);
                u32s(out, n);
                for v in &self.verts[vert..vert + n as usize] {
                    for x in v.p.to_array().into_iter().chain(v.color.to_array()) {
                        f32s(out, x);
                    }
                }
                vert += n as usize;
            }
            run = end as usize;
        }
    }

    /// Segments [`Self::encode`] wrote, checked: for a picture of `height`
    /// rows, rows within it, groups ascending, every run of at least two
    /// vertices with a look that exists, every number finite (a depth
    /// positive), nothing left over. Nothing is allocated beyond what the
    /// bytes hold.
    pub fn decode(bytes: &[u8], height: u32) -> Result<BandSegments, RasterError> {
        let bad = |why: String| RasterError::Segments(why);
        let mut r = Reader { bytes, at: 0 };
        let rows = r.u32()?..r.u32()?;
        if rows.start >= rows.end || rows.end > height {
            return Err(bad(format!("rows {rows:?} of a picture of {height} rows")));
        }
        let n_looks = r.u32()? as usize;
        if n_looks > MAX_LOOKS || n_looks * LOOK_BYTES > r.left() {
            return Err(bad(format!("{n_looks} looks (at most {MAX_LOOKS})")));
        }
        let mut looks = Vec::with_capacity(n_looks);
        for _ in 0..n_looks {
            let f = [r.f32()?, r.f32()?, r.f32()?, r.f32()?, r.f32()?];
            let ok = f.iter().all(|x| x.is_finite())
                && (0.0..=HairLook::MAX_SIMPLIFY).contains(&f[3])
                && f[4] > 0.0;
            if !ok {
                return Err(bad(format!("look {} is out of range: {f:?}", looks.len())));
            }
            looks.push(Look {
                look: HairLook {
                    fiber_width: f[0],
                    opacity: f[1],
                    depth_ref: f[2],
                    simplify: f[3],
                },
                width_z: f[4],
            });
        }
        let n_groups = r.u32()? as usize;
        if n_groups * 8 > r.left() {
            return Err(bad(format!("{n_groups} groups in {} bytes", r.left())));
        }
        let mut out = BandSegments::new(rows, looks);
        out.groups.reserve(n_groups);
        for _ in 0..n_groups {
            let id = r.u32()?;
            if out.last_group().is_some_and(|last| id <= last) {
                return Err(bad(format!(
                    "group {id} after group {:?}",
                    out.last_group()
                )));
            }
            let n_runs = r.u32()? as usize;
            if n_runs * (8 + 2 * VERTEX_BYTES) > r.left() {
                return Err(bad(format!("{n_runs} runs in {} bytes", r.left())));
            }
            out.begin_group(id);
            for _ in 0..n_runs {
                let look = r.u32()?;
                let n = r.u32()? as usize;
                if look as usize >= out.looks.len() || n < 2 || n * VERTEX_BYTES > r.left() {
                    return Err(bad(format!(
                        "a run of {n} vertices with look {look} of {} ({} bytes left)",
                        out.looks.len(),
                        r.left()
                    )));
                }
                out.runs.push((look, n as u32));
                for _ in 0..n {
                    let p = Vec3::new(r.f32()?, r.f32()?, r.f32()?);
                    let color = Vec3::new(r.f32()?, r.f32()?, r.f32()?);
                    if !p.is_finite() || !color.is_finite() || p.z <= 0.0 {
                        return Err(bad(format!("a vertex at {p} of colour {color}")));
                    }
                    out.verts.push(Projected { p, color });
                }
                let end = out.runs.len() as u32;
                if let Some(g) = out.groups.last_mut() {
                    g.1 = end;
                }
            }
        }
        if r.left() != 0 {
            return Err(bad(format!("{} bytes after the last group", r.left())));
        }
        Ok(out)
    }
}

/// Sort-middle on a canvas: its segments of some rows out, and another
/// canvas's in.
impl Canvas {
    /// The hair binned to rows `rows` (starting and ending on a multiple
    /// of [`Self::band_rows`], or at the last row) as its segments, each
    /// group in strand order, the groups numbered from `first_group` on
    /// (the index of this canvas's first group among the whole hair's):
    /// what [`Self::draw_segments`] draws on another canvas.
    pub fn segments_rows(&self, rows: std::ops::Range<u32>, first_group: u32) -> BandSegments {
        let (h, band_rows) = (self.height, self.band);
        let end_row = (rows.end as usize).min(h);
        let first = rows.start as usize / band_rows;
        let end = end_row.div_ceil(band_rows).max(first);
        let mut out = BandSegments::new(rows.start..end_row as u32, self.looks.clone());
        let mut ids = Vec::new();
        let mut chunks = self.bins.iter().zip(&self.chunk_group).peekable();
        for g in 0..self.groups {
            out.begin_group(first_group + g);
            while let Some((bins, _)) = chunks.next_if(|c| *c.1 == g) {
                // The segments of the rows' bands, each once, in strand
                // order (ascending first vertex; one look a vertex).
                ids.clear();
                for bin in &bins[first..end] {
                    ids.extend_from_slice(bin);
                }
                // One bin is in order already, each segment once.
                if end - first > 1 {
                    ids.sort_unstable();
                    ids.dedup();
                }
                // Runs of consecutive segments: segments `i` and `i + 1`
                // both drawn are of one strand, and share vertex `i + 1`.
                let mut k = 0;
                while k < ids.len() {
                    let (start, look) = ids[k];
                    let mut n = 1;
                    while k + n < ids.len() && ids[k + n] == (start + n as u32, look) {
                        n += 1;
                    }
                    let at = start as usize;
                    out.push_run(look, self.verts[at..at + n + 1].iter().copied());
                    k += n;
                }
            }
        }
        out
    }

    /// Bins `segments` (see [`Self::segments_rows`]) as groups after those
    /// drawn so far, each in its order, in the rows they were taken for
    /// alone: drawn after the other shares' segments of those rows, in the
    /// order of the groups, the rows resolve to the same bytes as all the
    /// hair drawn here. Refuses segments of rows that do not start on one
    /// of this canvas's bands.
    pub fn draw_segments(&mut self, segments: &BandSegments) -> Result<(), RasterError> {
        let (w, h, band_rows) = (self.width, self.height, self.band);
        let rows = segments.rows();
        if !(rows.start as usize).is_multiple_of(band_rows)
            || rows.end as usize > h
            || (rows.end as usize != h && !(rows.end as usize).is_multiple_of(band_rows))
        {
            return Err(RasterError::Segments(format!(
                "rows {rows:?} do not cut a picture of {h} rows in its bands of {band_rows}"
            )));
        }
        let (looks, groups) = segments.parts();
        let look_base = self.looks.len() as u32;
        self.looks.extend_from_slice(looks);
        let bands = h.div_ceil(band_rows);
        let (first, end) = (
            rows.start as usize / band_rows,
            (rows.end as usize).div_ceil(band_rows),
        );
        for runs in groups {
            let chunk = self.chunk_group.len();
            if self.bins.len() <= chunk {
                self.bins.push(vec![Vec::new(); bands]);
                self.reach.push(vec![NO_REACH; bands]);
            }
            self.chunk_group.push(self.groups);
            self.groups += 1;
            let (bins, reach) = (&mut self.bins[chunk], &mut self.reach[chunk]);
            for (look, verts) in runs {
                let at = &self.looks[(look_base + look) as usize];
                let base = self.verts.len();
                self.verts.extend_from_slice(verts);
                let mut prev = None;
                for (j, &v) in verts.iter().enumerate() {
                    let end_v = at.vertex(v);
                    let (Some(a), Some(b)) = (std::mem::replace(&mut prev, end_v), end_v) else {
                        continue;
                    };
                    let Some((span, cols)) = footprint(a, b, w, h, band_rows) else {
                        continue;
                    };
                    // Only the rows taken: a segment also reaching a band
                    // of other rows comes with those rows' segments.
                    let span = span.start.max(first)..span.end.min(end);
                    for (bin, r) in bins[span.clone()].iter_mut().zip(&mut reach[span]) {
                        bin.push(((base + j - 1) as u32, look_base + look));
                        *r = [r[0].min(cols[0]), r[1].max(cols[1])];
                    }
                }
            }
        }
        Ok(())
    }
}

/// Walks a [`BandSegments`]' groups.
pub(super) struct GroupRuns<'a> {
    of: &'a BandSegments,
    group: usize,
    run: usize,
    vert: usize,
}

impl<'a> Iterator for GroupRuns<'a> {
    /// A group: its runs, each as its look and its vertices.
    type Item = Vec<(u32, &'a [Projected])>;

    fn next(&mut self) -> Option<Self::Item> {
        let &(_, end) = self.of.groups.get(self.group)?;
        self.group += 1;
        let mut out = Vec::with_capacity(end as usize - self.run);
        for &(look, n) in &self.of.runs[self.run..end as usize] {
            out.push((look, &self.of.verts[self.vert..self.vert + n as usize]));
            self.vert += n as usize;
        }
        self.run = end as usize;
        Some(out)
    }
}

/// Reads little-endian numbers off bytes, refusing to run past them.
struct Reader<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl Reader<'_> {
    fn left(&self) -> usize {
        self.bytes.len() - self.at
    }

    fn u32(&mut self) -> Result<u32, RasterError> {
        let b = self
            .bytes
            .get(self.at..self.at + 4)
            .ok_or_else(|| RasterError::Segments("the bytes end early".into()))?;
        self.at += 4;
        Ok(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    }

    fn f32(&mut self) -> Result<f32, RasterError> {
        self.u32().map(f32::from_bits)
    }
}
