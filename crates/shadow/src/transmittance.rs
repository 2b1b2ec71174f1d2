//! Transmittance: the per-column sweep (paper 4.2) and filtering (paper 4.3).

use std::ops::Range;
use std::sync::OnceLock;

use glam::Vec3;
use rayon::prelude::*;

use crate::{DEPTH_QUANTUM, DensityMap, LightFrame, OPAQUE_DEPTH, ShadowError};

/// Lookups at drawn fiber points read the map this many cells nearer the
/// light than the point ([`Transmittance::filter`],
/// [`Transmittance::transmittance_at_drawn`]); a point in free space is
/// read where it is ([`Transmittance::transmittance_at`]).
///
/// Why: a drawn point lies in the cell its own fiber and clump were
/// deposited in, so the depth at the point itself counts about half a
/// cell of the hair beside it as in front of it. The fibers a picture
/// shows are mostly the lit outer fibers of their clumps, and the map
/// shadowed them too much: on the Sintel groom (13,908 strands, opaque
/// fibers 0.03 wide, 128^3), T at the visible drawn points was 0.027 below
/// the exact per-fiber reference on average, and the pictures' block
/// shadow ratio 0.195 against Blender Cycles' 0.266. Half a cell turns the
/// bias to +0.029 and the ratio to 0.247 (block error against Cycles 0.079
/// to 0.061); a whole cell overshoots (0.282). Shifting every lookup alike
/// keeps T monotone along the light and exactly 1 in front of the hair.
pub const LIT_EDGE_OFFSET: f32 = 0.5;

/// The occupied span of one `(j, k)` column after the sweep: cells
/// `lo..=hi`, whose back-face depths start at `start` in the slab's `depth`;
/// hair starts at slice coordinate `front`, in `[lo, lo + 1)`. An empty
/// column has `lo > hi`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Span {
    /// First occupied cell.
    pub lo: u16,
    /// Last occupied cell.
    pub hi: u16,
    /// Where the span's depths start in the slab's `depth`.
    pub start: u32,
    /// Where the hair starts, slice coordinate in cells.
    pub front: f32,
}

impl Span {
    /// A column with no hair.
    pub const EMPTY: Span = Span {
        lo: 1,
        hi: 0,
        start: 0,
        front: 0.0,
    };

    /// The latest front inside cell `lo` that keeps its depth ramp finite.
    const FRONT_GAP: f32 = 1.0 / 1024.0;

    /// Whether the column holds no hair.
    pub fn is_empty(&self) -> bool {
        self.lo > self.hi
    }

    /// Occupied cells.
    pub fn len(&self) -> usize {
        if self.is_empty() {
            0
        } else {
            (self.hi - self.lo) as usize + 1
        }
    }
}

/// How many density quanta make one step of stored optical depth: a step
/// is `2^STEP_SHIFT` quanta.
const STEP_SHIFT: u32 = 8;

/// Optical depth of one step of a swept depth: 2^-12.
///
/// The sweep sums a column's cells exactly (integer quanta of
/// [`DEPTH_QUANTUM`]) and rounds each cumulative depth to the nearest step
/// once. The rounding changes `D` by at most 2^-13, so `T = exp(-D)` by a
/// relative 1.2e-4 at most (a thirtieth of one 8-bit level), and it is the
/// same wherever the column is swept. Coarser steps than the density's
/// quanta make a slab about half as many bytes on the wire (cluster mode).
pub const DEPTH_STEP: f64 = DEPTH_QUANTUM * (1u64 << STEP_SHIFT) as f64;

/// A stored depth, in steps, as an optical depth.
#[inline]
fn steps_to_depth(steps: u32) -> f32 {
    (f64::from(steps) * DEPTH_STEP) as f32
}

/// The sweep's result for a range of columns: what a worker sends back.
///
/// For each occupied cell, the cumulative optical depth at its back face
/// (the face away from the light), in steps of [`DEPTH_STEP`]:
/// `D(i + 1) = sum over i' <= i of tau(i')`, the paper's equation (3) with
/// `T = exp(-D)`. Non-decreasing along each column. Empty cells and empty
/// columns store nothing: before a span the depth is 0, after it the
/// column's total.
#[derive(Debug, Clone, PartialEq)]
pub struct ColumnSlab {
    /// The columns swept, `k * n + j`.
    pub columns: Range<u32>,
    /// One span per column.
    pub spans: Vec<Span>,
    /// The spans' back-face depths, in steps of `DEPTH_STEP`.
    pub depth: Vec<u32>,
}

impl ColumnSlab {
    /// The spans that sweeping `columns` of `density` gives, with no
    /// depths yet: what a receiver of the depths alone fills in.
    pub fn layout(density: &DensityMap, columns: Range<u32>) -> ColumnSlab {
        let mut total = 0u32;
        let spans = columns
            .clone()
            .map(|col| {
                let s = span_of(density, col as usize, total);
                total += s.len() as u32;
                s
            })
            .collect();
        ColumnSlab {
            columns,
            spans,
            depth: Vec::new(),
        }
    }

    /// Depths the spans call for.
    pub fn cells(&self) -> usize {
        self.spans.iter().map(Span::len).sum()
    }

    /// This slab with only the columns whose bits are set in `keep` (a
    /// bitmap of the map's columns, as [`columns_read`] makes), the others
    /// empty.
    pub fn keep(&self, keep: &[u64]) -> ColumnSlab {
        let mut depth = Vec::new();
        let spans = self
            .columns
            .clone()
            .zip(&self.spans)
            .map(|(col, s)| {
                let kept = keep
                    .get(col as usize / 64)
                    .is_some_and(|w| w >> (col % 64) & 1 == 1);
                if !kept || s.is_empty() {
                    return Span::EMPTY;
                }
                let start = depth.len() as u32;
                depth.extend_from_slice(&self.depth[s.start as usize..s.start as usize + s.len()]);
                Span { start, ..*s }
            })
            .collect();
        ColumnSlab {
            columns: self.columns.clone(),
            spans,
            depth,
        }
    }
}

/// Sweeps columns `columns` of `density` (paper 4.2): along each column from
/// the slice nearest the light, accumulate optical depth. Exact integer
/// sums, each rounded once to a step, make the result independent of how
/// columns are split.
pub fn sweep(density: &DensityMap, columns: Range<u32>) -> ColumnSlab {
    sweep_while(density, columns, || true).expect("never told to stop")
}

/// The most columns [`sweep_while`] sweeps between two questions whether
/// to go on.
pub const SWEEP_RUN_COLUMNS: usize = 4096;

/// [`sweep`], asking `go` before each run of [`SWEEP_RUN_COLUMNS`]
/// columns: `None` when it said stop.
pub fn sweep_while(
    density: &DensityMap,
    columns: Range<u32>,
    go: impl Fn() -> bool,
) -> Option<ColumnSlab> {
    let mut slab = ColumnSlab::layout(density, columns.clone());
    slab.depth = vec![0; slab.cells()];
    for (i, (col, s)) in columns.zip(&slab.spans).enumerate() {
        if i % SWEEP_RUN_COLUMNS == 0 && !go() {
            return None;
        }
        sweep_span(density, col as usize, *s, &mut slab.depth, 0, |x| x);
    }
    Some(slab)
}

/// The span of column `col` of `density` whose depths start at `start`.
#[inline]
fn span_of(density: &DensityMap, col: usize, start: u32) -> Span {
    let m = density.meta(col);
    if m.is_empty() {
        return Span::EMPTY;
    }
    let lo = f32::from(m.lo);
    Span {
        lo: m.lo,
        hi: m.hi,
        start,
        front: m.front.clamp(lo, lo + 1.0 - Span::FRONT_GAP),
    }
}

/// Sweeps column `col`, whose span is `s`, into `depth`, a buffer whose
/// first value is depth number `base` (spans count from the whole buffer),
/// storing each depth (in steps) as `store` makes it.
#[inline]
fn sweep_span<T>(
    density: &DensityMap,
    col: usize,
    s: Span,
    depth: &mut [T],
    base: usize,
    store: impl Fn(u32) -> T,
) {
    if !s.is_empty() {
        let at = s.start as usize - base;
        let cells = density.column(col, s.lo as usize..s.hi as usize + 1);
        sweep_column(cells, &mut depth[at..at + cells.len()], store);
    }
}

/// One column's sweep: `depth[i]` is the optical depth at the back face of
/// cell `i`, the sum of `quanta[..=i]` (units of [`DEPTH_QUANTUM`]) rounded
/// to the nearest step of [`DEPTH_STEP`] (saturating at `u32::MAX` steps,
/// an optical depth of 2^20, where `T` is 0 in any float format).
#[inline]
fn sweep_column<T>(quanta: &[u32], depth: &mut [T], store: impl Fn(u32) -> T) {
    // i64, not u64: a signed conversion is one instruction on x86-64, and a
    // column of at most 512 cells of u32 cannot reach 2^63.
    const HALF: i64 = 1 << (STEP_SHIFT - 1);
    let mut cum: i64 = 0;
    for (d, &q) in depth.iter_mut().zip(quanta) {
        cum += i64::from(q);
        *d = store(((cum + HALF) >> STEP_SHIFT).min(i64::from(u32::MAX)) as u32);
    }
}

/// Cumulative optical depth everywhere in a map, assembled from slabs.
#[derive(Debug, Clone)]
pub struct Transmittance {
    frame: LightFrame,
    n: usize,
    /// Columns as the filter reads them, on a grid padded by
    /// [`COL_PAD`] columns on each side (see [`Col`]).
    cols: Vec<Col>,
    depth: Vec<f32>,
    /// Per column of `cols`, the cell an opaque body first enters it in
    /// ([`BODY_CELL_DEPTH`]), [`NO_BODY`] where none does: found for every
    /// column on the first lookup that leaves the bodies out
    /// ([`Self::hair_depth_between`], [`Self::surface_depth`]), so that
    /// those read the hair in front of it as the depth's own difference.
    bodies: OnceLock<Vec<u32>>,
}

impl PartialEq for Transmittance {
    /// The same map: what was found from it so far does not count.
    fn eq(&self, o: &Transmittance) -> bool {
        self.frame == o.frame && self.n == o.n && self.cols == o.cols && self.depth == o.depth
    }
}

/// [`Transmittance::bodies`] of a column no body enters.
const NO_BODY: u32 = u32::MAX;

/// A cell of a column whose optical depth grows by more than this within
/// it holds an opaque body's entry, not hair alone
/// ([`Transmittance::hair_depth_between`]): a body deposits
/// [`OPAQUE_DEPTH`] (30) in the one cell of a column it enters; hair of
/// shadow opacity 0.5 (optical depth `-ln 0.5 = 0.69` a fiber crossed)
/// adds 15 only with some 22 fibers stacked in one cell of one column.
pub const BODY_CELL_DEPTH: f32 = OPAQUE_DEPTH / 2.0;

/// Padding columns on each side of [`Transmittance::cols`]: lookups reach
/// columns -2 to n + 2 (points outside the map are clamped to 2 cells
/// beyond it), and those outside the map are empty, with no bounds tests.
const COL_PAD: usize = 2;

/// Where a lookup of `p` reads a map (see [`Transmittance::optical_depth`]):
/// columns `(j, k)` (and, filtered, `(j + 1, k)`, `(j, k + 1)` and
/// `(j + 1, k + 1)`, with bilinear weights `ty`, `tz`), at slice
/// coordinate `x`; unfiltered, at the centre slice `centre` of `p`'s cell.
/// Points far outside the map are clamped to 2 cells beyond it (padding
/// columns, all empty), so that the casts cannot overflow.
#[derive(Debug, Clone, Copy)]
struct Lookup {
    j: i32,
    k: i32,
    x: f32,
    ty: f32,
    tz: f32,
    centre: f32,
}

impl Lookup {
    #[inline(always)]
    fn at(frame: &LightFrame, p: Vec3, trilinear: bool) -> Lookup {
        Lookup::of_cells(frame, frame.to_cells(p), trilinear)
    }

    /// The lookup at map coordinates `c` (cells).
    #[inline(always)]
    fn of_cells(frame: &LightFrame, c: Vec3, trilinear: bool) -> Lookup {
        let n = frame.n_cells as f32;
        // Shifting by 2 cells keeps the coordinates positive, so truncating
        // casts are floors (`floor` is a libm call on baseline x86-64).
        let c = c.clamp(Vec3::splat(-2.0), Vec3::splat(n + 2.0)) + 2.0;
        let x = c.x - 2.0;
        let centre = (c.x as i32 - 2) as f32 + 0.5;
        if trilinear {
            let (fy, fz) = (c.y - 0.5, c.z - 0.5);
            let (j, k) = (fy as i32, fz as i32);
            let (ty, tz) = (fy - j as f32, fz - k as f32);
            Lookup {
                j: j - 2,
                k: k - 2,
                x,
                ty,
                tz,
                centre,
            }
        } else {
            Lookup {
                j: c.y as i32 - 2,
                k: c.z as i32 - 2,
                x,
                ty: 0.0,
                tz: 0.0,
                centre,
            }
        }
    }
}

/// Every column of `frame`'s map that looking up `points` (filtered or
/// not) reads, as a bitmap of its `n_cells^2` columns (bit `c % 64` of word
/// `c / 64`): what hair drawn elsewhere needs of a map swept elsewhere. A
/// [`Transmittance`] that holds these columns (and any others) looks the
/// points up exactly as the whole map does.
pub fn columns_read(frame: &LightFrame, points: &[Vec3], trilinear: bool) -> Vec<u64> {
    let n = frame.n_cells as i32;
    let words = frame.columns().div_ceil(64);
    points
        .par_chunks(8192)
        .fold(
            || vec![0u64; words],
            |mut bits, pts| {
                let mut mark = |j: i32, k: i32| {
                    if (0..n).contains(&j) && (0..n).contains(&k) {
                        let c = (k * n + j) as usize;
                        bits[c / 64] |= 1 << (c % 64);
                    }
                };
                for &p in pts {
                    let at = Lookup::at(frame, p, trilinear);
                    mark(at.j, at.k);
                    if trilinear {
                        mark(at.j + 1, at.k);
                        mark(at.j, at.k + 1);
                        mark(at.j + 1, at.k + 1);
                    }
                }
                bits
            },
        )
        .reduce(
            || vec![0u64; words],
            |mut a, b| {
                a.iter_mut().zip(b).for_each(|(a, b)| *a |= b);
                a
            },
        )
}

/// One column's span in the form the filter reads fastest: no hair in
/// front of `front` (infinite for an empty column), depths of cells
/// `lo..=lo + last` from `start` on.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Col {
    front: f32,
    lo: f32,
    start: u32,
    last: u32,
}

impl Col {
    const EMPTY: Col = Col {
        front: f32::INFINITY,
        lo: 0.0,
        start: 0,
        last: 0,
    };
}

/// The padded column table of a map of `n^2` columns with `spans`.
fn col_table(n: usize, spans: &[Span]) -> Vec<Col> {
    let side = n + 2 * COL_PAD + 1;
    let mut cols = vec![Col::EMPTY; side * side];
    for (col, s) in spans.iter().enumerate() {
        if !s.is_empty() {
            let (j, k) = (col % n, col / n);
            cols[(k + COL_PAD) * side + j + COL_PAD] = Col {
                front: s.front,
                lo: f32::from(s.lo),
                start: s.start,
                last: u32::from(s.hi - s.lo),
            };
        }
    }
    cols
}

impl Transmittance {
    /// Bytes its columns and depths hold (for a memory budget).
    pub fn bytes(&self) -> usize {
        self.cols.len() * std::mem::size_of::<Col>() + self.depth.len() * 4
    }

    /// Sweeps every column of `density`, in parallel, straight into the
    /// result: the same values as [`sweep`] over any split, [`Self::assemble`]d,
    /// without the copies and checks that slabs from elsewhere need.
    pub fn compute(density: &DensityMap) -> Transmittance {
        let frame = *density.frame();
        let n = frame.n_cells as usize;
        let cols = frame.columns();
        let layout = ColumnSlab::layout(density, 0..cols as u32);
        let mut depth = vec![0.0f32; layout.cells()];
        let spans = layout.spans;
        // Groups of columns, each sweeping into its own part of `depth`.
        let group = cols.div_ceil(64).max(256);
        let mut parts = Vec::with_capacity(cols.div_ceil(group));
        let mut rest: &mut [f32] = &mut depth;
        let mut base = 0;
        for g in (0..cols).step_by(group) {
            let end = (g + group).min(cols);
            let len = spans[g..end].iter().map(Span::len).sum::<usize>();
            let (part, tail) = rest.split_at_mut(len);
            parts.push((g..end, base, part));
            rest = tail;
            base += len;
        }
        parts.into_par_iter().for_each(|(range, base, part)| {
            for col in range {
                sweep_span(density, col, spans[col], part, base, steps_to_depth);
            }
        });
        Transmittance {
            frame,
            n,
            cols: col_table(n, &spans),
            depth,
            bodies: OnceLock::new(),
        }
    }

    /// Checks one slab on its own: a span per column, each inside the
    /// map and its depths, exactly the depths the spans call for, and
    /// depths that never decrease along a column.
    pub fn check_slab(frame: &LightFrame, slab: &ColumnSlab) -> Result<(), ShadowError> {
        let n = frame.n_cells as usize;
        let bad = |detail: String| ShadowError::Slabs {
            expected: frame.columns(),
            detail,
        };
        if slab.spans.len() != slab.columns.len() || slab.columns.end as usize > frame.columns() {
            return Err(bad(format!(
                "slab {:?} has {} spans",
                slab.columns,
                slab.spans.len()
            )));
        }
        for s in &slab.spans {
            let front_ok =
                s.front >= f32::from(s.lo) && s.front <= f32::from(s.lo) + 1.0 - Span::FRONT_GAP;
            if !s.is_empty()
                && (s.hi as usize >= n
                    || s.start as usize + s.len() > slab.depth.len()
                    || !front_ok)
            {
                return Err(bad(format!(
                    "slab {:?} has span {s:?} outside its {} depths",
                    slab.columns,
                    slab.depth.len()
                )));
            }
        }
        if slab.depth.len() != slab.cells() {
            return Err(bad(format!(
                "slab {:?} holds {} depths, its spans {}",
                slab.columns,
                slab.depth.len(),
                slab.cells()
            )));
        }
        for s in slab.spans.iter().filter(|s| !s.is_empty()) {
            let d = &slab.depth[s.start as usize..s.start as usize + s.len()];
            if d.windows(2).any(|w| w[1] < w[0]) {
                return Err(bad(format!(
                    "slab {:?} holds a depth that decreases along the light in span {s:?}",
                    slab.columns
                )));
            }
        }
        Ok(())
    }

    /// Joins slabs that together cover every column once, in order.
    pub fn assemble(
        frame: LightFrame,
        slabs: impl IntoIterator<Item = ColumnSlab>,
    ) -> Result<Transmittance, ShadowError> {
        let n = frame.n_cells as usize;
        let expected = frame.columns();
        let mut spans = Vec::with_capacity(expected);
        let mut depth = Vec::new();
        for slab in slabs {
            if slab.columns.start as usize != spans.len() {
                return Err(ShadowError::Slabs {
                    expected,
                    detail: format!("slab {:?} follows column {}", slab.columns, spans.len()),
                });
            }
            Transmittance::check_slab(&frame, &slab)?;
            let base = depth.len() as u32;
            spans.extend(slab.spans.iter().map(|s| {
                if s.is_empty() {
                    Span::EMPTY
                } else {
                    Span {
                        start: s.start + base,
                        ..*s
                    }
                }
            }));
            depth.extend(slab.depth.iter().map(|&d| steps_to_depth(d)));
        }
        if spans.len() != expected {
            return Err(ShadowError::Slabs {
                expected,
                detail: format!("slabs end at column {}", spans.len()),
            });
        }
        Ok(Transmittance {
            frame,
            n,
            cols: col_table(n, &spans),
            depth,
            bodies: OnceLock::new(),
        })
    }

    /// The frame of the map swept.
    pub fn frame(&self) -> &LightFrame {
        &self.frame
    }

    /// Cumulative optical depth along column `(j, k)` at slice coordinate `x`
    /// (in cells, `x >= -2`): exact for density uniform inside each cell,
    /// i.e. linear between the depths at a cell's front and back faces; in
    /// the first occupied cell, uniform between where the hair starts and
    /// the back face. Exactly 0 in front of the column's hair.
    #[inline(always)]
    fn column_depth(&self, j: i32, k: i32, x: f32) -> f32 {
        self.depth_of(self.col(j, k), x)
    }

    /// [`Self::column_depth`] of column `c`.
    #[inline(always)]
    fn depth_of(&self, c: Col, x: f32) -> f32 {
        if x <= c.front {
            return 0.0;
        }
        let rel = x - c.lo;
        // The same as `rel as usize` (truncating, saturating at 0), but
        // float-to-i32 is one instruction and a check, float-to-usize a
        // branchy sequence on x86-64.
        let i = (rel as i32).max(0) as u32;
        if i > c.last {
            return self.depth[(c.start + c.last) as usize];
        }
        let at = (c.start + i) as usize;
        if i == 0 {
            // The first cell's hair fills [front, lo + 1).
            return self.depth[at] * ((x - c.front) / (c.lo + 1.0 - c.front));
        }
        let t = rel - i as f32;
        let front = self.depth[at - 1];
        front + t * (self.depth[at] - front)
    }

    /// Optical depth `D(p)` between the light and `p`; transmittance is
    /// `exp(-D)`.
    ///
    /// Filtered (paper 4.3): trilinear on the map's staggered grid, linear in
    /// depth along the light within the column and bilinear across columns
    /// between column centres. The paper interpolates transmittance; we
    /// interpolate optical depth and exponentiate once, which equals it to
    /// first order, never underflows in dense hair, and gives exactly 0 in
    /// front of all hair. Unfiltered: the value at the centre of `p`'s cell
    /// (0 in front of the hair of `p`'s column).
    #[inline(always)]
    pub fn optical_depth(&self, p: Vec3, trilinear: bool) -> f32 {
        debug_assert!(p.is_finite());
        self.depth_in_cells(self.frame.to_cells(p), trilinear, 0.0)
    }

    /// [`Self::optical_depth`] at map coordinates `c` (cells), read
    /// `towards_light` cells nearer the light.
    #[inline(always)]
    fn depth_in_cells(&self, c: Vec3, trilinear: bool, towards_light: f32) -> f32 {
        let c = Vec3::new(c.x - towards_light, c.y, c.z);
        let at = Lookup::of_cells(&self.frame, c, trilinear);
        let (j, k, x) = (at.j, at.k, at.x);
        if trilinear {
            // Non-negative weights: for fixed weights the sum never
            // decreases when any column's depth grows (monotone along the
            // light, rounding included).
            self.blend(&at, true, |j, k| self.column_depth(j, k, x))
        } else {
            // The value at the centre of p's cell, but none in front of the
            // column's hair: monotone along the light, and exactly 0 where
            // no hair lies between p and the light.
            if self.column_depth(j, k, x) == 0.0 {
                return 0.0;
            }
            self.column_depth(j, k, at.centre)
        }
    }

    /// `value(j, k)` of the columns `at` reads, blended as its weights say
    /// (bilinear across the four about it, or its own column).
    #[inline(always)]
    fn blend(&self, at: &Lookup, trilinear: bool, value: impl Fn(i32, i32) -> f32) -> f32 {
        let (j, k) = (at.j, at.k);
        if trilinear {
            let (ty, tz) = (at.ty, at.tz);
            let (sy, sz) = (1.0 - ty, 1.0 - tz);
            sz * (sy * value(j, k) + ty * value(j + 1, k))
                + tz * (sy * value(j, k + 1) + ty * value(j + 1, k + 1))
        } else {
            value(j, k)
        }
    }

    /// Column `(j, k)`: `j, k >= -2` (see [`COL_PAD`]); past `n + 2` the
    /// index fails loudly.
    #[inline(always)]
    fn col(&self, j: i32, k: i32) -> Col {
        self.cols[self.col_index(j, k)]
    }

    /// Where column `(j, k)` is in [`Self::cols`].
    #[inline(always)]
    fn col_index(&self, j: i32, k: i32) -> usize {
        let side = self.n + 2 * COL_PAD + 1;
        (k + COL_PAD as i32) as usize * side + (j + COL_PAD as i32) as usize
    }

    /// Transmittance `T(p) = exp(-D(p))` in [0, 1] at a point in free
    /// space (a probe): the light that reaches `p` through the map.
    #[inline]
    pub fn transmittance_at(&self, p: Vec3, trilinear: bool) -> f32 {
        (-self.optical_depth(p, trilinear)).exp()
    }

    /// Transmittance `T(p) = exp(-D(p'))` in [0, 1] at a drawn point (of a
    /// fiber, or on the head's surface), `p'` being `p` moved
    /// [`LIT_EDGE_OFFSET`] cells towards the light: what [`Self::filter`]
    /// gives each point.
    #[inline]
    pub fn transmittance_at_drawn(&self, p: Vec3, trilinear: bool) -> f32 {
        debug_assert!(p.is_finite());
        let c = self.frame.to_cells(p);
        (-self.depth_in_cells(c, trilinear, LIT_EDGE_OFFSET)).exp()
    }

    /// Transmittance at every drawn point (the filtering stage), in
    /// parallel: [`Self::transmittance_at_drawn`] of each.
    pub fn filter(&self, points: &[Vec3], trilinear: bool, out: &mut [f32]) {
        assert_eq!(points.len(), out.len());
        out.par_chunks_mut(4096)
            .zip(points.par_chunks(4096))
            .for_each(|(o, p)| {
                // Parallel rays or a fan, decided once a chunk.
                if self.frame.fan.is_none() {
                    for (o, &p) in o.iter_mut().zip(p) {
                        let c = self.frame.to_cells_parallel(p);
                        *o = (-self.depth_in_cells(c, trilinear, LIT_EDGE_OFFSET)).exp();
                    }
                } else {
                    for (o, &p) in o.iter_mut().zip(p) {
                        *o = self.transmittance_at_drawn(p, trilinear);
                    }
                }
            });
    }

    /// Number of cells that store a depth: a measure of the occupied volume.
    pub fn stored_cells(&self) -> usize {
        self.depth.len()
    }
}

mod bodies;
#[cfg(test)]
mod tests;
