//! What crosses the wire, and its checks: map frames, strands, occupied
//! density columns and transmittance slabs, cut into chunks well under
//! gRPC's 4 MiB default message size. Everything received is validated
//! before use: a malformed message is an error, never a panic or a wrong
//! map.

use prost::encoding::{decode_varint, encode_varint};
use std::ops::Range;

use glam::{Affine3A, Vec3};
use shadow::{ColumnMeta, ColumnSlab, DensityMap, LightFrame, MAX_CELLS};
use sim::{Body, WispState};
use strands::Hair;

use crate::pb;

mod draw;
mod exchange;
pub(crate) use draw::*;
pub use draw::{job_to_pb, report_from_pb};
pub(crate) use exchange::*;

/// The protocol version this build speaks. A coordinator and a worker of
/// different versions refuse each other.
pub const PROTOCOL_VERSION: u32 = 20;

/// Points per Density chunk: 3 floats each, 1.5 MB.
pub(crate) const POINTS_PER_CHUNK: usize = 128 * 1024;

/// Density cells or depths per column or slab chunk: at most about 1.3 MB.
pub(crate) const CELLS_PER_CHUNK: usize = 256 * 1024;

/// The largest message either side decodes (16 MiB): each call in flight
/// buffers at most one. Chunks stay far below it; a Simulate call's head motions
/// and accelerations, sent whole, are what comes nearest.
pub const MAX_MESSAGE_BYTES: usize = 16 << 20;

/// The largest piece of a text (a scene) one message carries: 1 MiB.
pub const TEXT_PIECE_BYTES: usize = 1 << 20;

/// `text` in pieces of at most `max` bytes (at least one: an empty text
/// is one empty piece), each cut at a character boundary.
pub fn text_pieces(text: &str, max: usize) -> impl Iterator<Item = &str> {
    let max = max.max(4);
    let mut rest = Some(text);
    std::iter::from_fn(move || {
        let t = rest?;
        let mut cut = t.len().min(max);
        while !t.is_char_boundary(cut) {
            cut -= 1;
        }
        let (piece, after) = t.split_at(cut);
        rest = (!after.is_empty()).then_some(after);
        Some(piece)
    })
}

/// The most points (and the most strands) one worker takes in one
/// Density call: 32 M, about 400 MB of points and 128 MB of offsets.
pub(crate) const MAX_POINTS: usize = 32_000_000;

/// The longest scene text an Assign may carry (16 MiB).
pub const MAX_SCENE_TEXT: usize = 16 << 20;

/// The most bytes of data files (grooms, head meshes) one Assign may
/// carry (256 MiB).
pub const MAX_FILE_BYTES: usize = 256 << 20;

/// The most wisp-state values (3 per guide point now and 3 a step ago)
/// one Assign may carry: 64 M values, 256 MB.
pub(crate) const MAX_STATE_FLOATS: usize = 64 << 20;

/// A message that does not hold what the protocol says.
#[derive(Debug, thiserror::Error)]
#[error("malformed message: {0}")]
pub struct Malformed(pub String);

pub(crate) fn bad(what: impl Into<String>) -> Malformed {
    Malformed(what.into())
}

/// A map frame as sent.
pub fn frame_to_pb(f: &LightFrame) -> pb::MapFrame {
    pb::MapFrame {
        origin: f.origin.to_array().to_vec(),
        axes: f.axes.iter().flat_map(|a| a.to_array()).collect(),
        ds: f.ds,
        n_cells: f.n_cells,
        fan: f.fan.map_or_else(Vec::new, |f| {
            [f.source.to_array(), f.start.to_array()]
                .concat()
                .into_iter()
                .chain([f.du])
                .collect()
        }),
    }
}

/// A frame as sent: finite, `1..=MAX_CELLS` cells, `ds > 0`, unit axes.
pub(crate) fn frame_from_pb(m: Option<&pb::MapFrame>) -> Result<LightFrame, Malformed> {
    let m = m.ok_or_else(|| bad("no map frame in the first chunk"))?;
    if m.origin.len() != 3 || m.axes.len() != 9 {
        return Err(bad(format!(
            "map frame with {} origin and {} axis components (expected 3 and 9)",
            m.origin.len(),
            m.axes.len()
        )));
    }
    if !(1..=MAX_CELLS).contains(&m.n_cells) {
        return Err(bad(format!("map of {} cells a side", m.n_cells)));
    }
    if !(m.ds.is_finite() && m.ds > 0.0) {
        return Err(bad(format!("map cell side {}", m.ds)));
    }
    let origin = Vec3::from_slice(&m.origin);
    let axes = [0, 1, 2].map(|i| Vec3::from_slice(&m.axes[3 * i..3 * i + 3]));
    if !origin.is_finite()
        || axes
            .iter()
            .any(|a| !a.is_finite() || (a.length() - 1.0).abs() > 1e-3)
    {
        return Err(bad(
            "map frame with a non-finite origin or an axis that is not a unit vector",
        ));
    }
    let fan = match m.fan.len() {
        0 => None,
        7 => {
            let v = &m.fan;
            let fan = shadow::Fan {
                source: Vec3::from_slice(&v[0..3]),
                start: Vec3::from_slice(&v[3..6]),
                du: v[6],
            };
            let valid = fan.source.is_finite()
                && fan.start.is_finite()
                && fan.start.x > 0.0
                && fan.du.is_finite()
                && fan.du > 0.0;
            if !valid {
                return Err(bad(format!("map fan {v:?}")));
            }
            Some(fan)
        }
        k => return Err(bad(format!("map fan of {k} values (expected 0 or 7)"))),
    };
    Ok(LightFrame {
        origin,
        axes,
        ds: m.ds,
        n_cells: m.n_cells,
        fan,
    })
}

/// Strands `strands` of `hair` as Density chunks; the first carries the
/// ids and the frame.
pub fn density_chunks(
    frame_id: u64,
    light: u32,
    frame: &LightFrame,
    hair: &Hair,
    strands: Range<usize>,
) -> Vec<pb::DensityChunk> {
    let mut out = Vec::new();
    let mut chunk = pb::DensityChunk {
        frame_id,
        light,
        map: Some(frame_to_pb(frame)),
        ..Default::default()
    };
    let offsets = hair.offsets();
    let points = hair.points();
    for s in strands {
        let pts = &points[offsets[s] as usize..offsets[s + 1] as usize];
        if !chunk.strand_lengths.is_empty() && chunk.points.len() / 3 + pts.len() > POINTS_PER_CHUNK
        {
            out.push(std::mem::take(&mut chunk));
        }
        chunk.strand_lengths.push(pts.len() as u32);
        chunk.points.extend(pts.iter().flat_map(|p| p.to_array()));
    }
    out.push(chunk);
    out
}

/// Adds the strands of one Density chunk to `hair`.
pub(crate) fn add_strands(hair: &mut Hair, c: &pb::DensityChunk) -> Result<(), Malformed> {
    let total: u64 = c.strand_lengths.iter().map(|&l| u64::from(l)).sum();
    if total * 3 != c.points.len() as u64 {
        return Err(bad(format!(
            "strand lengths add up to {total} points but {} coordinates came",
            c.points.len()
        )));
    }
    if hair.point_count() as u64 + total > MAX_POINTS as u64 {
        return Err(bad(format!("more than {MAX_POINTS} points in one call")));
    }
    // Strands of no point cost memory too.
    if (hair.strand_count() + c.strand_lengths.len()) as u64 > MAX_POINTS as u64 {
        return Err(bad(format!("more than {MAX_POINTS} strands in one call")));
    }
    let mut at = 0usize;
    let mut buf = Vec::new();
    for &len in &c.strand_lengths {
        let len = len as usize;
        buf.clear();
        buf.extend(
            c.points[3 * at..3 * (at + len)]
                .chunks_exact(3)
                .map(Vec3::from_slice),
        );
        hair.push_strand(&buf).map_err(|e| bad(e.to_string()))?;
        at += len;
    }
    Ok(())
}

/// The occupied columns of `map` among `columns`, as chunks.
pub(crate) fn column_chunks(map: &DensityMap, columns: Range<usize>) -> Vec<pb::ColumnChunk> {
    let mut out = Vec::new();
    let mut chunk = pb::ColumnChunk::default();
    let (mut cells, mut last) = (0usize, 0u32);
    let mut runs = Runs::default();
    for col in columns {
        let meta = map.meta(col);
        if meta.is_empty() {
            continue;
        }
        let column = map.column(col, meta.lo as usize..meta.hi as usize + 1);
        if !chunk.column_steps.is_empty() && cells + column.len() > CELLS_PER_CHUNK {
            runs.finish(&mut chunk.cells);
            out.push(std::mem::take(&mut chunk));
            cells = 0;
        }
        let step = if chunk.column_steps.is_empty() {
            col as u32
        } else {
            col as u32 - last
        };
        last = col as u32;
        chunk.column_steps.push(step);
        chunk.lo.push(u32::from(meta.lo));
        chunk.hi.push(u32::from(meta.hi));
        chunk.front.push(meta.front);
        for &q in column {
            runs.push(q, &mut chunk.cells);
        }
        cells += column.len();
    }
    runs.finish(&mut chunk.cells);
    out.push(chunk);
    out
}

/// The columns of one [`pb::ColumnChunk`], decoded and checked against a
/// map frame: what [`add_columns`] adds.
#[derive(Debug, Clone, Default)]
pub(crate) struct Columns {
    columns: Vec<u32>,
    metas: Vec<ColumnMeta>,
    cells: Vec<u32>,
}

impl Columns {
    /// Whether every column lies in `range`.
    pub(crate) fn within(&self, range: Range<usize>) -> bool {
        self.columns.iter().all(|&c| range.contains(&(c as usize)))
    }
}

/// Adds the columns of one chunk to `map`, after decoding and checking
/// them all ([`decode_columns`]): a bad chunk changes nothing.
pub(crate) fn merge_columns(map: &mut DensityMap, c: &pb::ColumnChunk) -> Result<(), Malformed> {
    let d = decode_columns(map.frame(), c)?;
    add_columns(map, &d);
    Ok(())
}

/// Adds decoded columns to a map of the frame they were checked against.
pub(crate) fn add_columns(map: &mut DensityMap, d: &Columns) {
    let mut at = 0;
    for (&col, &meta) in d.columns.iter().zip(&d.metas) {
        let len = usize::from(meta.hi - meta.lo) + 1;
        map.merge_column(col as usize, meta, &d.cells[at..at + len]);
        at += len;
    }
}

/// How many columns a chunk's parallel lists describe: as many steps as
/// lo, hi and front values, or the chunk is malformed.
pub(crate) fn column_count(
    steps: &[u32],
    lo: &[u32],
    hi: &[u32],
    front: &[f32],
) -> Result<usize, Malformed> {
    let count = steps.len();
    if lo.len() != count || hi.len() != count || front.len() != count {
        return Err(bad(format!(
            "{count} columns with {} lo, {} hi and {} front values",
            lo.len(),
            hi.len(),
            front.len()
        )));
    }
    Ok(count)
}

/// Decodes the columns of one chunk and checks that they fit a map in
/// `frame`: ascending indices in range, spans, fronts, and exactly the
/// cells the spans hold.
pub(crate) fn decode_columns(
    frame: &LightFrame,
    c: &pb::ColumnChunk,
) -> Result<Columns, Malformed> {
    let n = frame.n_cells as usize;
    let count = column_count(&c.column_steps, &c.lo, &c.hi, &c.front)?;
    let mut out = Columns {
        columns: Vec::with_capacity(count),
        metas: Vec::with_capacity(count),
        cells: Vec::new(),
    };
    let mut need = 0usize;
    let mut col = 0u64;
    for i in 0..count {
        if i > 0 && c.column_steps[i] == 0 {
            return Err(bad(format!("column {col} comes twice")));
        }
        col += u64::from(c.column_steps[i]);
        let (lo, hi, front) = (c.lo[i] as usize, c.hi[i] as usize, c.front[i]);
        if col >= (n * n) as u64 || lo > hi || hi >= n {
            return Err(bad(format!(
                "column {col} with cells {lo}..={hi} in a map of {n} a side"
            )));
        }
        if !(front.is_finite() && front >= -1.0 && front <= n as f32 + 1.0) {
            return Err(bad(format!("column {col} starts at slice {front}")));
        }
        need += hi - lo + 1;
        out.columns.push(col as u32);
        out.metas.push(ColumnMeta {
            lo: lo as u16,
            hi: hi as u16,
            front,
        });
    }
    unpack_runs(&c.cells, need, &mut out.cells)?;
    Ok(out)
}

/// A swept slab as chunks, each the depths of whole columns
/// `first_column..end_column`: per occupied cell, the growth of the
/// column's depth (in steps) since the cell before, from 0 at the column's
/// first cell. The spans do not travel: the receiver knows them, as it
/// sent the density they were swept from.
pub(crate) fn slab_chunks(slab: &ColumnSlab) -> Vec<pb::SlabChunk> {
    let mut out = Vec::new();
    let start = slab.columns.start;
    let mut chunk = pb::SlabChunk {
        first_column: start,
        end_column: start,
        ..Default::default()
    };
    let (mut cells, mut runs) = (0usize, Runs::default());
    for (i, s) in slab.spans.iter().enumerate() {
        let len = s.len();
        if cells > 0 && cells + len > CELLS_PER_CHUNK {
            runs.finish(&mut chunk.depth_steps);
            let next = start + i as u32;
            out.push(std::mem::replace(
                &mut chunk,
                pb::SlabChunk {
                    first_column: next,
                    end_column: next,
                    ..Default::default()
                },
            ));
            cells = 0;
        }
        chunk.end_column += 1;
        if len > 0 {
            let first = s.start as usize;
            let mut prev = 0u32;
            for &d in &slab.depth[first..first + len] {
                // Depths never decrease along a column.
                runs.push(d - prev, &mut chunk.depth_steps);
                prev = d;
            }
            cells += len;
        }
    }
    runs.finish(&mut chunk.depth_steps);
    out.push(chunk);
    out
}

/// Receives a slab's chunks into the spans the receiver expects
/// ([`ColumnSlab::layout`] of the density it sent): each chunk must
/// continue where the last ended, carry exactly the depths of its
/// columns' spans, and keep every depth within 32 bits.
#[derive(Debug)]
pub(crate) struct SlabReader {
    slab: ColumnSlab,
    next: u32,
}

impl SlabReader {
    /// Expects the depths of `layout`'s spans (any depths it holds are
    /// dropped).
    pub(crate) fn new(mut layout: ColumnSlab) -> SlabReader {
        layout.depth.clear();
        let next = layout.columns.start;
        SlabReader { slab: layout, next }
    }

    /// Adds a chunk's columns, checked: in order, within the slab.
    pub(crate) fn add(&mut self, c: &pb::SlabChunk) -> Result<(), Malformed> {
        let cols = &self.slab.columns;
        if c.first_column != self.next || c.end_column < c.first_column || c.end_column > cols.end {
            return Err(bad(format!(
                "slab chunk of columns {}..{}, expected {}.. up to {}",
                c.first_column, c.end_column, self.next, cols.end
            )));
        }
        let spans = &self.slab.spans
            [(c.first_column - cols.start) as usize..(c.end_column - cols.start) as usize];
        let need: usize = spans.iter().map(|s| s.len()).sum();
        let mut steps = Vec::new();
        unpack_runs(&c.depth_steps, need, &mut steps)?;
        self.slab.depth.reserve(need);
        let mut at = 0;
        for s in spans {
            let mut depth = 0u32;
            for &step in &steps[at..at + s.len()] {
                depth = depth.checked_add(step).ok_or_else(|| {
                    bad(format!(
                        "a depth past 2^32 steps in the slab chunk of columns {}..{}",
                        c.first_column, c.end_column
                    ))
                })?;
                self.slab.depth.push(depth);
            }
            at += s.len();
        }
        self.next = c.end_column;
        Ok(())
    }

    /// The slab, once every column came.
    pub(crate) fn finish(self) -> Result<ColumnSlab, Malformed> {
        if self.next != self.slab.columns.end {
            return Err(bad(format!(
                "slab ends at column {}, expected {}",
                self.next, self.slab.columns.end
            )));
        }
        Ok(self.slab)
    }
}

/// Zero-run varint packing of 32-bit values: each nonzero value `v` is
/// the LEB128 varint of `v << 1`, each run of `r` zeros the varint of
/// `r << 1 | 1` (protobuf's varints, prost's functions). Most cells of a column's span are empty (about 60 % in
/// the built-in scene), so runs save most of them.
#[derive(Debug, Default)]
pub(crate) struct Runs {
    zeros: u64,
}

impl Runs {
    pub(crate) fn push(&mut self, v: u32, out: &mut Vec<u8>) {
        if v == 0 {
            self.zeros += 1;
        } else {
            self.finish(out);
            encode_varint(u64::from(v) << 1, out);
        }
    }

    /// Writes the pending run of zeros.
    pub(crate) fn finish(&mut self, out: &mut Vec<u8>) {
        if self.zeros > 0 {
            encode_varint(self.zeros << 1 | 1, out);
            self.zeros = 0;
        }
    }
}

/// `values` packed as zero-run varints (the `cells` and `depth_steps`
/// fields).
pub fn pack(values: &[u32]) -> Vec<u8> {
    let mut out = Vec::new();
    let mut runs = Runs::default();
    for &v in values {
        runs.push(v, &mut out);
    }
    runs.finish(&mut out);
    out
}

/// Unpacks exactly `count` values packed by [`Runs`] into `out`: a
/// truncated or overlong varint, a value past 32 bits, an empty run, more
/// or fewer values than `count`, or bytes left over are refused. Never
/// allocates more than `count` values.
pub(crate) fn unpack_runs(bytes: &[u8], count: usize, out: &mut Vec<u32>) -> Result<(), Malformed> {
    // A value takes at least one byte, a run can stand for many.
    out.reserve(count.min(bytes.len().saturating_mul(64)));
    let end = out.len() + count;
    let mut rest = bytes;
    while !rest.is_empty() {
        let x = decode_varint(&mut rest).map_err(|e| bad(format!("a packed varint: {e}")))?;
        let left = (end - out.len()) as u64;
        if x & 1 == 1 {
            let run = x >> 1;
            if run == 0 || run > left {
                return Err(bad(format!(
                    "a run of {run} zeros where {left} values remain"
                )));
            }
            out.resize(out.len() + run as usize, 0);
        } else {
            let v = u32::try_from(x >> 1)
                .map_err(|_| bad(format!("packed value {} exceeds 32 bits", x >> 1)))?;
            if left == 0 {
                return Err(bad(format!("more than {count} packed values")));
            }
            out.push(v);
        }
    }
    if out.len() != end {
        return Err(bad(format!(
            "{count} packed values expected, {} came",
            count - (end - out.len())
        )));
    }
    Ok(())
}

/// Guide points per wisp-state chunk: 6 floats each (now and one step
/// ago), 1.5 MB.
pub(crate) const GUIDE_POINTS_PER_CHUNK: usize = 64 * 1024;

/// The most time steps one Simulate call may ask for.
pub const MAX_STEPS: usize = 100_000;

/// The most work one Simulate call may ask for, in nanoseconds of one core as
/// [`step_work`] estimates it: 6 s.
pub const MAX_STEP_WORK: u64 = 6_000_000_000;

/// A Simulate call's cost on one core, nanoseconds: `points` guide points stepped
/// `steps` times with `bodies` bodies over all the steps,
///
/// ```text
/// work = points * (70 * steps + 2.5 * bodies)
/// ```
///
/// Measured on a 2-core VM (one thread, 192K guide points, the default
/// four constraint iterations): 68 ns per point and step without bodies,
/// 99 with one, 125 with 16 and 687 with 256 (2.4 ns per point, step and
/// body). A frame of 1000 steps then fits on 85K guide points, of 2
/// steps on 42M.
pub fn step_work(points: u64, steps: u64, bodies: u64) -> u64 {
    points.saturating_mul(
        70u64
            .saturating_mul(steps)
            .saturating_add(bodies.saturating_mul(5) / 2),
    )
}

/// The most bodies one time step may hold.
pub(crate) const MAX_BODIES: usize = 1024;

/// A transform as 12 floats: the matrix's columns, then the translation.
pub(crate) fn affine_to_floats(a: &Affine3A, out: &mut Vec<f32>) {
    out.extend_from_slice(&a.to_cols_array());
}

/// The transforms of `f` (12 floats each), every one finite.
pub(crate) fn affines_from_floats(f: &[f32]) -> Result<Vec<Affine3A>, Malformed> {
    if !f.len().is_multiple_of(12) || f.len() / 12 > MAX_STEPS {
        return Err(bad(format!(
            "{} head transform values: not a whole number of 12-float transforms, or more than {MAX_STEPS} steps",
            f.len()
        )));
    }
    if f.iter().any(|v| !v.is_finite()) {
        return Err(bad("a head transform is not finite"));
    }
    Ok(f.chunks_exact(12).map(Affine3A::from_cols_slice).collect())
}

/// Body spheres as four floats each (centre, radius), appended to `out`.
pub(crate) fn bodies_to_floats(bodies: &[Body], out: &mut Vec<f32>) {
    for b in bodies {
        out.extend_from_slice(&[b.center.x, b.center.y, b.center.z, b.radius]);
    }
}

/// Bodies as x, y, z, radius: finite, radius not negative.
pub(crate) fn bodies_from_floats(f: &[f32]) -> Result<Vec<Body>, Malformed> {
    if !f.len().is_multiple_of(4) || f.len() / 4 > MAX_BODIES * MAX_STEPS {
        return Err(bad(format!(
            "{} body values: not x, y, z, radius quadruples",
            f.len()
        )));
    }
    f.chunks_exact(4)
        .map(|b| {
            let body = Body {
                center: Vec3::new(b[0], b[1], b[2]),
                radius: b[3],
            };
            if body.center.is_finite() && body.radius.is_finite() && body.radius >= 0.0 {
                Ok(body)
            } else {
                Err(bad(format!(
                    "body at {} of radius {}",
                    body.center, body.radius
                )))
            }
        })
        .collect()
}

/// Sparse accelerations: for each non-zero one, the count of zero ones
/// skipped before it, then its x, y, z.
pub(crate) fn accel_to_pb(accel: &[Vec3]) -> (Vec<u32>, Vec<f32>) {
    let (mut skip, mut xyz) = (Vec::new(), Vec::new());
    let mut zeros = 0u32;
    for a in accel {
        if *a == Vec3::ZERO {
            zeros += 1;
        } else {
            skip.push(zeros);
            xyz.extend_from_slice(&a.to_array());
            zeros = 0;
        }
    }
    (skip, xyz)
}

/// [`accel_to_pb`] undone, for `len` points; every value finite.
pub(crate) fn accel_from_pb(skip: &[u32], xyz: &[f32], len: usize) -> Result<Vec<Vec3>, Malformed> {
    if xyz.len() != 3 * skip.len() {
        return Err(bad(format!(
            "{} accelerations with {} components",
            skip.len(),
            xyz.len()
        )));
    }
    let mut out = vec![Vec3::ZERO; len];
    let mut at = 0usize;
    for (i, &s) in skip.iter().enumerate() {
        at = at.saturating_add(s as usize);
        let a = Vec3::from_slice(&xyz[3 * i..3 * i + 3]);
        if at >= len || !a.is_finite() {
            return Err(bad(format!(
                "acceleration {a} at guide point {at} of {len}"
            )));
        }
        out[at] = a;
        at += 1;
    }
    Ok(out)
}

/// The states of wisps `first..` in `states`, as chunks of whole wisps.
pub fn wisp_chunks<'a>(
    first: usize,
    states: impl IntoIterator<Item = &'a WispState>,
) -> Vec<pb::WispChunk> {
    let mut out = Vec::new();
    let mut chunk = pb::WispChunk {
        first_wisp: first as u32,
        ..Default::default()
    };
    for (i, s) in states.into_iter().enumerate() {
        if !chunk.pos.is_empty() && chunk.pos.len() / 3 + s.pos.len() > GUIDE_POINTS_PER_CHUNK {
            let next = pb::WispChunk {
                first_wisp: (first + i) as u32,
                ..Default::default()
            };
            out.push(std::mem::replace(&mut chunk, next));
        }
        chunk.pos.extend(s.pos.iter().flat_map(|p| p.to_array()));
        chunk.prev.extend(s.prev.iter().flat_map(|p| p.to_array()));
    }
    out.push(chunk);
    out
}

/// The wisps of one chunk, each of `per` guide points, all inside
/// `wisps`: `(wisp, state)` pairs. Finiteness is checked where the state
/// is set.
pub(crate) fn wisps_from_chunk(
    c: &pb::WispChunk,
    per: usize,
    wisps: &Range<usize>,
) -> Result<Vec<(usize, WispState)>, Malformed> {
    let floats = 3 * per;
    if per == 0 || c.pos.len() != c.prev.len() || !c.pos.len().is_multiple_of(floats) {
        return Err(bad(format!(
            "wisp states of {} and {} values, not whole wisps of {per} points",
            c.pos.len(),
            c.prev.len()
        )));
    }
    let first = c.first_wisp as usize;
    let count = c.pos.len() / floats;
    if first < wisps.start || first + count > wisps.end {
        return Err(bad(format!(
            "states of wisps {first}..{} outside wisps {}..{}",
            first + count,
            wisps.start,
            wisps.end
        )));
    }
    let points = |f: &[f32]| f.chunks_exact(3).map(Vec3::from_slice).collect::<Vec<_>>();
    Ok((0..count)
        .map(|i| {
            let at = i * floats..(i + 1) * floats;
            (
                first + i,
                WispState {
                    pos: points(&c.pos[at.clone()]),
                    prev: points(&c.prev[at]),
                },
            )
        })
        .collect())
}

#[cfg(test)]
mod fuzz;
#[cfg(test)]
mod tests;
