//! Filling hair density into the light-oriented map (paper 4.1).

use std::ops::Range;

use glam::Vec3;
use rayon::prelude::*;
use strands::Hair;

use crate::{Fiber, LightFrame, Occluder};

/// Optical depth of one fixed-point unit in a cell: 2^-20.
///
/// Cells hold optical depth as integers so that deposits add up to the same
/// bytes in any order (atomic adds from many threads, or partial maps summed
/// from many workers). 2^-20 keeps the rounding of one deposit below 5e-7,
/// and a u32 cell saturates at an optical depth of 4096, where the
/// transmittance `exp(-4096)` is zero in any float format anyway.
pub const DEPTH_QUANTUM: f64 = 1.0 / (1u64 << 20) as f64;

/// The largest map side, in cells. 512^3 cells already take 512 MiB.
pub const MAX_CELLS: u32 = 512;

/// About the most work (points and segment pieces) one run of
/// [`DensityMap::deposit_while`] does between two questions whether to go
/// on: 2^22, some tens of milliseconds (a single strand may be more).
pub const DEPOSIT_RUN_WORK: u64 = 1 << 22;

const EMPTY_LO: u16 = u16::MAX;

/// The density map: per cell, the optical depth `tau = kappa * ds` that hair
/// inside it adds to a light ray crossing it, in units of [`DEPTH_QUANTUM`].
///
/// Cells are stored column-major, `(k * n + j) * n + i`: the transmittance
/// sweep reads each `(j, k)` column as one contiguous run. Each column also
/// knows its first and last occupied slice ([`ColumnMeta`]), so that
/// clearing and sweeping cost time in proportion to the hair, not to `n^3`.
///
/// While depositing, hair mostly keeps that knowledge per block of 2 x 2
/// columns: a piece's tent splat reaches the four columns of one block,
/// and widening one block costs a quarter of widening four columns. A
/// piece that leaves one of the four with nothing (on a column's centre
/// line, or a share that rounds to zero) widens only the columns it
/// reaches, so that no column counts hair it did not get. At the end of a
/// deposit each column takes in its four blocks'.
#[derive(Debug, Clone)]
pub struct DensityMap {
    frame: LightFrame,
    n: usize,
    cells: Vec<u32>,
    meta: Vec<ColumnMeta>,
    /// Hair's meta per block of columns `(j0..=j0 + 1, k0..=k0 + 1)`, for
    /// `j0, k0` in `-1..n`: at `(k0 + 1) * (n + 1) + j0 + 1`.
    blocks: Vec<ColumnMeta>,
    /// Opaque bodies' deposits since the last clear: `(column, slice,
    /// quanta)`, sorted.
    bodies: Vec<(u32, u16, u32)>,
    /// Per column, 1 + the index in `bodies` of its first deposit (0:
    /// none), so that reading hair's own quanta costs no search where no
    /// body is (a self-collision field reads thousands of cells a frame).
    body_at: Vec<u32>,
    /// The deposit's points in map coordinates, and each strand's range of
    /// `z` (cells), kept between fills so that their memory is not
    /// allocated and faulted in again for every frame.
    scratch: Scratch,
}

#[derive(Debug, Clone, Default)]
struct Scratch {
    pts: Vec<Vec3>,
    z_range: Vec<(f32, f32)>,
}

/// What a column knows of its hair: the occupied cells `lo..=hi`, and
/// `front`, the smallest slice coordinate (in cells) reached by any piece
/// deposited there. Hair starts at `front`, not at the face of cell `lo`:
/// a point in front of it has no hair between itself and the light.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ColumnMeta {
    pub lo: u16,
    pub hi: u16,
    pub front: f32,
}

impl ColumnMeta {
    pub const EMPTY: ColumnMeta = ColumnMeta {
        lo: EMPTY_LO,
        hi: 0,
        front: f32::INFINITY,
    };

    pub fn is_empty(&self) -> bool {
        self.lo > self.hi
    }

    /// What both columns know. Min and max do not depend on order.
    #[inline]
    fn union(self, o: ColumnMeta) -> ColumnMeta {
        ColumnMeta {
            lo: self.lo.min(o.lo),
            hi: self.hi.max(o.hi),
            // `min` without `f32::min`'s NaN handling (a NaN front changes
            // nothing either way, and fronts start infinite, never NaN).
            front: if o.front < self.front {
                o.front
            } else {
                self.front
            },
        }
    }

    /// Widens the column to hold a deposit in slice `i` whose piece starts
    /// at slice coordinate `front`.
    #[inline]
    fn include(&mut self, i: u16, front: f32) {
        *self = self.union(ColumnMeta {
            lo: i,
            hi: i,
            front,
        });
    }
}

/// What one fill did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct FillStats {
    /// Density samples deposited into cells.
    pub samples: u64,
    /// Samples that fell outside the map and were dropped (counted, never
    /// wrapped into another cell).
    pub out_of_map: u64,
}

impl std::ops::Add for FillStats {
    type Output = FillStats;
    fn add(self, o: FillStats) -> FillStats {
        FillStats {
            samples: self.samples + o.samples,
            out_of_map: self.out_of_map + o.out_of_map,
        }
    }
}

impl std::iter::Sum for FillStats {
    fn sum<I: Iterator<Item = FillStats>>(iter: I) -> FillStats {
        iter.fold(FillStats::default(), |a, b| a + b)
    }
}

impl DensityMap {
    /// An empty map in `frame`.
    pub fn new(frame: LightFrame) -> DensityMap {
        let n = frame.n_cells as usize;
        DensityMap {
            frame,
            n,
            cells: vec![0; n * n * n],
            meta: vec![ColumnMeta::EMPTY; n * n],
            blocks: vec![ColumnMeta::EMPTY; (n + 1) * (n + 1)],
            bodies: Vec::new(),
            body_at: vec![0; n * n],
            scratch: Scratch::default(),
        }
    }

    pub fn frame(&self) -> &LightFrame {
        &self.frame
    }

    /// The bytes a map of `n_cells` a side allocates when made (its
    /// deposit scratch apart): the cells' quanta, per column its meta and
    /// body index, per block of columns its meta.
    pub const fn bytes_for(n_cells: u32) -> u64 {
        let n = n_cells as u64;
        let meta = std::mem::size_of::<ColumnMeta>() as u64;
        n * n * n * 4 + n * n * (meta + 4) + (n + 1) * (n + 1) * meta
    }

    /// Frees the deposit scratch if it holds more than `points` points or
    /// strands (at most `20 * points` bytes are kept: 12 a point, 8 a
    /// strand), so that a map kept between calls keeps no memory the next
    /// may not need.
    pub fn trim_scratch(&mut self, points: usize) {
        if self.scratch.pts.capacity() > points || self.scratch.z_range.capacity() > points {
            self.scratch = Scratch::default();
        }
    }

    /// Moves the map to a new frame (a moved light or hair), emptying it and
    /// keeping its memory when the resolution is unchanged.
    pub fn set_frame(&mut self, frame: LightFrame) {
        if frame.n_cells as usize == self.n {
            self.clear();
            self.frame = frame;
        } else {
            *self = DensityMap::new(frame);
        }
    }

    /// Empties the map, touching only the occupied spans.
    pub fn clear(&mut self) {
        for b in &self.bodies {
            self.body_at[b.0 as usize] = 0;
        }
        self.bodies.clear();
        let n = self.n;
        self.cells
            .par_chunks_mut(n * n)
            .zip(self.meta.par_chunks_mut(n))
            .for_each(|(slice, meta)| {
                for (col, m) in slice.chunks_mut(n).zip(meta) {
                    if !m.is_empty() {
                        col[m.lo as usize..=m.hi as usize].fill(0);
                    }
                    *m = ColumnMeta::EMPTY;
                }
            });
        self.blocks.fill(ColumnMeta::EMPTY);
    }

    /// Empties the map and deposits all of `hair`.
    pub fn fill(&mut self, hair: &Hair, fiber: &Fiber) -> FillStats {
        self.clear();
        self.deposit(hair, 0..hair.strand_count(), fiber)
    }

    /// Adds the density of strands `strands` of `hair` (to the map's current
    /// content). Any split of the strands over calls, threads or machines
    /// gives the same cells: deposits are integers, and integer sums do not
    /// depend on their order.
    ///
    /// Each segment `(a, b)` is cut into `m = ceil(|b - a|_inf / ds)` equal
    /// pieces, so that no piece spans more than a cell along any axis, and
    /// each piece adds to the cells of its midpoint's slice (spread over the
    /// four nearest columns with bilinear weights) the optical depth (see
    /// [`Fiber`])
    ///
    /// ```text
    /// tau = kappa * ds = alpha * w * |piece x L| / ds^2
    /// ```
    ///
    /// where `|piece x L| = dl sin(theta)`. In map coordinates (cells, X_map
    /// along L) that is `alpha * w / ds * sqrt(dy^2 + dz^2)`.
    ///
    /// With several threads the map is cut into slabs of rows `k`, one per
    /// thread, each holding about as many of the hair's points. Each slab
    /// walks the strands that reach it and writes only its own cells. No
    /// atomics, no lists of deposits handed between threads: a strand that
    /// crosses a slab boundary is walked by both slabs, which costs less
    /// than writing and reading back every deposit.
    pub fn deposit(&mut self, hair: &Hair, strands: Range<usize>, fiber: &Fiber) -> FillStats {
        // Fixed-point optical depth per cell of piece length across the
        // light (for a fan, per unit of `across / x`, see `Spread`).
        let width = match &self.frame.fan {
            None => self.frame.ds,
            Some(f) => f.du,
        };
        let k_q = (f64::from(fiber.cross_section()) / f64::from(width) / DEPTH_QUANTUM) as f32;
        let spread = self.frame.fan.map(|f| Spread {
            frame: self.frame,
            start: f.start,
            du: f.du,
            ds: self.frame.ds,
        });
        if k_q == 0.0 || strands.is_empty() {
            return FillStats::default();
        }
        let n = self.n;
        let frame = self.frame;
        let offsets = &hair.offsets()[strands.start..=strands.end];
        let first = offsets[0] as usize;
        let points = &hair.points()[first..offsets[offsets.len() - 1] as usize];
        // The strands' points in map coordinates, and each strand's z range
        // (all of z if a coordinate overflowed to a non-finite value).
        let Scratch { pts, z_range } = &mut self.scratch;
        // Every point is written below: no need to clear the old ones.
        pts.resize(points.len(), Vec3::ZERO);
        pts.par_chunks_mut(4096)
            .zip(points.par_chunks(4096))
            .for_each(|(out, pts)| {
                if frame.fan.is_none() {
                    for (o, &p) in out.iter_mut().zip(pts) {
                        *o = frame.to_cells_parallel(p);
                    }
                } else {
                    for (o, &p) in out.iter_mut().zip(pts) {
                        *o = frame.to_cells(p);
                    }
                }
            });
        let local = |s: usize| offsets[s] as usize - first..offsets[s + 1] as usize - first;
        z_range.clear();
        z_range.par_extend((0..strands.len()).into_par_iter().map(|s| {
            let pts = &pts[local(s)];
            let (lo, hi) = pts
                .iter()
                .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), p| {
                    (lo.min(p.z), hi.max(p.z))
                });
            if pts.iter().all(|p| p.is_finite()) {
                (lo, hi)
            } else {
                (f32::NEG_INFINITY, f32::INFINITY)
            }
        }));
        // One slab of rows k per thread, each holding about as many points.
        // Any split gives the same cells: deposits are integers, and
        // integer sums do not depend on their order.
        let slabs = rayon::current_num_threads().min(n);
        let mut bounds = vec![0];
        if slabs > 1 {
            let row = |p: &Vec3| (p.z as i32).clamp(0, n as i32 - 1) as usize;
            let hist = pts
                .par_chunks(16 * 1024)
                .map(|chunk| {
                    let mut hist = vec![0usize; n];
                    chunk.iter().for_each(|p| hist[row(p)] += 1);
                    hist
                })
                .reduce(
                    || vec![0; n],
                    |mut a, b| {
                        a.iter_mut().zip(b).for_each(|(a, b)| *a += b);
                        a
                    },
                );
            let mut seen = 0;
            for (k, h) in hist.iter().enumerate() {
                seen += h;
                if seen * slabs > bounds.len() * pts.len() && k + 1 < n && bounds.len() < slabs {
                    bounds.push(k + 1);
                }
            }
        }
        bounds.push(n);
        let mut parts = Vec::with_capacity(bounds.len() - 1);
        let (mut cells, mut meta, mut blocks) = (
            &mut self.cells[..],
            &mut self.meta[..],
            &mut self.blocks[..],
        );
        for w in bounds.windows(2) {
            let rows = w[1] - w[0];
            let (c, c_rest) = cells.split_at_mut(rows * n * n);
            let (m, m_rest) = meta.split_at_mut(rows * n);
            // Block rows k0 in k_lo..k_hi, and -1 with the first rows.
            let block_rows = rows + usize::from(w[0] == 0);
            let (b, b_rest) = blocks.split_at_mut(block_rows * (n + 1));
            (cells, meta, blocks) = (c_rest, m_rest, b_rest);
            parts.push(Rows {
                cells: c,
                meta: m,
                blocks: b,
                n: n as i32,
                k_lo: w[0] as i32,
                k_hi: w[1] as i32,
            });
        }
        let (pts, z_range) = (&*pts, &*z_range);
        let stats = parts
            .into_par_iter()
            .map(|mut rows| {
                let mut stats = FillStats::default();
                let (vis_lo, vis_hi) = rows.visits();
                for (s, &(lo, hi)) in z_range.iter().enumerate() {
                    if !(hi < vis_lo || lo >= vis_hi) {
                        stats = stats + strand_pieces(&mut rows, &pts[local(s)], k_q, spread);
                    }
                }
                stats
            })
            .sum::<FillStats>();
        // Each column takes in its blocks' meta (a union: taking it in
        // again after another deposit changes nothing), so that reading a
        // column's meta is one load.
        let blocks = &self.blocks;
        self.meta
            .par_chunks_mut(n)
            .enumerate()
            .for_each(|(k, row)| {
                for (j, m) in row.iter_mut().enumerate() {
                    *m = column_meta(m, blocks, n, k * n + j);
                }
            });
        stats
    }

    /// [`deposit`](Self::deposit) in runs of about [`DEPOSIT_RUN_WORK`]
    /// points and pieces, asking `go` before each: `None` when
    /// it said stop (the map then holds some of the strands). The same
    /// cells as one deposit of them all.
    pub fn deposit_while(
        &mut self,
        hair: &Hair,
        strands: Range<usize>,
        fiber: &Fiber,
        go: impl Fn() -> bool,
    ) -> Option<FillStats> {
        self.deposit_runs(hair, strands, fiber, DEPOSIT_RUN_WORK, go)
    }

    fn deposit_runs(
        &mut self,
        hair: &Hair,
        strands: Range<usize>,
        fiber: &Fiber,
        run_work: u64,
        go: impl Fn() -> bool,
    ) -> Option<FillStats> {
        let offsets = hair.offsets();
        let points = hair.points();
        // A strand's work: a point each, and each segment's pieces (see
        // `deposit`), at most `4 n` a segment, bounded above by its
        // length over `ds`.
        let (inv_ds, cap) = (1.0 / self.frame.ds, 4 * self.n as u64);
        let work = |s: usize| -> u64 {
            let pts = &points[offsets[s] as usize..offsets[s + 1] as usize];
            let pieces: u64 = pts
                .windows(2)
                .map(|w| {
                    let m = (w[1] - w[0]).length() * inv_ds;
                    if m.is_finite() {
                        (m.ceil() as u64).min(cap)
                    } else {
                        cap
                    }
                })
                .sum();
            pts.len() as u64 + pieces
        };
        let mut stats = FillStats::default();
        let mut s = strands.start;
        while s < strands.end {
            if !go() {
                return None;
            }
            let (mut e, mut done) = (s + 1, work(s));
            while e < strands.end {
                let w = work(e);
                if done + w > run_work {
                    break;
                }
                done += w;
                e += 1;
            }
            stats = stats + self.deposit(hair, s..e, fiber);
            s = e;
        }
        Some(stats)
    }

    /// Adds an opaque body (a head) to the map: every column whose centre
    /// line enters the body inside the map gets optical depth `depth` in
    /// the cell where the line enters it, starting exactly at the entry
    /// point. Hair behind the body is then in its shadow. Returns the
    /// columns it covers.
    pub fn deposit_body(&mut self, body: &Occluder, depth: f32) -> usize {
        let n = self.n;
        let q = (f64::from(depth) / DEPTH_QUANTUM).min(f64::from(u32::MAX)) as u32;
        let mut covered = 0;
        for (col, entry) in body.entries(&self.frame) {
            if entry >= 0.0 && entry < n as f32 {
                let (j, k) = (col as usize % n, col as usize / n);
                self.add_cell(entry as usize, j, k, q, entry);
                self.bodies.push((col, entry as u16, q));
                covered += 1;
            }
        }
        self.bodies.sort_unstable();
        for (i, b) in self.bodies.iter().enumerate().rev() {
            self.body_at[b.0 as usize] = i as u32 + 1;
        }
        covered
    }

    /// The quanta of cell `(i, j, k)` that hair deposited: the cell's
    /// quanta without those of the opaque bodies (a self-collision must
    /// not mistake the head's shadow for dense hair).
    pub fn hair_quanta(&self, i: usize, j: usize, k: usize) -> u32 {
        let mut q = self.quanta(i, j, k);
        let col = k * self.n + j;
        let first = self.body_at[col] as usize;
        if first == 0 {
            return q;
        }
        let key = (col as u32, i as u16);
        for b in self.bodies[first - 1..]
            .iter()
            .take_while(|b| b.0 == key.0)
            .filter(|b| b.1 == key.1)
        {
            q = q.saturating_sub(b.2);
        }
        q
    }

    /// Adds raw quanta to cell `(i, j, k)`, as if from a piece starting at
    /// the cell's front face.
    pub fn add_quanta(&mut self, i: usize, j: usize, k: usize, q: u32) {
        if q > 0 {
            self.add_cell(i, j, k, q, i as f32);
        }
    }

    /// Adds `q` quanta to cell `(i, j, k)` from hair starting at slice
    /// coordinate `front`.
    fn add_cell(&mut self, i: usize, j: usize, k: usize, q: u32, front: f32) {
        add_at(
            &mut self.cells,
            &mut self.meta,
            self.n,
            k * self.n + j,
            i as u32,
            q,
            front,
        );
    }

    /// Adds a column of another map over the same frame (a worker's partial
    /// map): its quanta for cells `meta.lo..=meta.hi` and its front.
    /// Merging in any order gives the same map.
    pub fn merge_column(&mut self, col: usize, meta: ColumnMeta, quanta: &[u32]) {
        if meta.is_empty() {
            return;
        }
        let n = self.n;
        let cells = &mut self.cells[col * n + meta.lo as usize..col * n + meta.hi as usize + 1];
        for (c, &q) in cells.iter_mut().zip(quanta) {
            *c = c.saturating_add(q);
        }
        let m = &mut self.meta[col];
        m.include(meta.lo, meta.front);
        m.include(meta.hi, meta.front);
    }

    /// The occupied span `lo..=hi` of column `col = k * n + j`, if any.
    #[inline]
    pub fn span(&self, col: usize) -> Option<(usize, usize)> {
        let m = self.meta(col);
        (!m.is_empty()).then_some((m.lo as usize, m.hi as usize))
    }

    /// What column `col` knows of its hair.
    #[inline]
    pub fn meta(&self, col: usize) -> ColumnMeta {
        self.meta[col]
    }

    /// Quanta of column `col`'s cells `range`.
    pub fn column(&self, col: usize, range: Range<usize>) -> &[u32] {
        &self.cells[col * self.n + range.start..col * self.n + range.end]
    }

    /// Quanta of cell `(i, j, k)`.
    pub fn quanta(&self, i: usize, j: usize, k: usize) -> u32 {
        self.cells[(k * self.n + j) * self.n + i]
    }

    /// Optical depth of cell `(i, j, k)`.
    pub fn cell_depth(&self, i: usize, j: usize, k: usize) -> f64 {
        f64::from(self.quanta(i, j, k)) * DEPTH_QUANTUM
    }
}

/// Map coordinates in the piece loop are fixed point: `2^FX` units a cell.
const FX: u32 = 16;
/// Half a cell, in fixed point.
const FX_HALF: i32 = 1 << (FX - 1);
/// The fraction of a cell, in fixed point.
const FX_FRAC: i32 = (1 << FX) - 1;

/// Rows `k_lo..k_hi` of a map's columns: the part of the map one task
/// writes. Deposits into other rows are someone else's and are skipped.
struct Rows<'a> {
    cells: &'a mut [u32],
    meta: &'a mut [ColumnMeta],
    /// Block rows `k_lo..k_hi`, and with the first rows `-1` too.
    blocks: &'a mut [ColumnMeta],
    n: i32,
    k_lo: i32,
    k_hi: i32,
}

impl Rows<'_> {
    /// The range of `z` (cells) of the pieces these rows receive deposits
    /// from or count: a piece at `z` deposits into rows `floor(z - 0.5)`
    /// and the next, and is counted by row `floor(z)` clamped into the map.
    fn visits(&self) -> (f32, f32) {
        let lo = if self.k_lo == 0 {
            f32::NEG_INFINITY
        } else {
            (self.k_lo - 1) as f32
        };
        let hi = if self.k_hi == self.n {
            f32::INFINITY
        } else {
            (self.k_hi + 1) as f32
        };
        (lo, hi)
    }

    /// Index into `meta` of column `(j, k)` if it is in these rows and in
    /// the map (`n` columns a row: its cells start at `n` times that).
    #[inline]
    fn local(&self, j: i32, k: i32) -> Option<usize> {
        ((0..self.n).contains(&j) && (self.k_lo..self.k_hi).contains(&k))
            .then(|| (k - self.k_lo) as usize * self.n as usize + j as usize)
    }

    /// Whether these rows count a piece whose row is `k` (clamped into the
    /// map: pieces beyond it are counted by the first or last rows).
    #[inline]
    fn owns(&self, k: i32) -> bool {
        (self.k_lo..self.k_hi).contains(&k.clamp(0, self.n - 1))
    }

    /// The tent splat of one piece in slice `i` starting at slice
    /// coordinate `front`: `q[0]` quanta into column `(j, k)`, `q[1]` into
    /// `(j + 1, k)`, `q[2]` into `(j, k + 1)`, `q[3]` into `(j + 1, k + 1)`,
    /// each if it is in these rows and in the map.
    #[inline(always)]
    fn splat(&mut self, j: i32, k: i32, i: u32, q: [u32; 4], front: f32) {
        let n = self.n as usize;
        // Block rows stored before row k0: from k_lo, or from -1.
        let first_block_row = if self.k_lo == 0 { -1 } else { self.k_lo };
        // Block (j, k)'s index, where its row is stored here.
        let block = || (k - first_block_row) as usize * (n + 1) + (j + 1) as usize;
        let all = q.iter().all(|&q| q > 0);
        if j >= 0 && j < self.n - 1 && k >= self.k_lo && k + 1 < self.k_hi {
            // All four columns are in these rows and in the map.
            let col = (k - self.k_lo) as usize * n + j as usize;
            let base = col * n + i as usize;
            // One bounds test for the four cells.
            let cells = &mut self.cells[base..=base + n * n + n];
            for (q, c) in q.into_iter().zip([0, n, n * n, n * n + n]) {
                cells[c] = cells[c].saturating_add(q);
            }
            if all {
                // k0 in k_lo..k_hi: its block row is stored here.
                self.blocks[block()].include(i as u16, front);
            } else {
                for (q, c) in q.into_iter().zip([col, col + 1, col + n, col + n + 1]) {
                    if q > 0 {
                        self.meta[c].include(i as u16, front);
                    }
                }
            }
            return;
        }
        let columns = [(j, k), (j + 1, k), (j, k + 1), (j + 1, k + 1)];
        for (q, (j, k)) in q.into_iter().zip(columns) {
            if let Some(col) = self.local(j, k).filter(|_| q > 0) {
                let at = col * n + i as usize;
                self.cells[at] = self.cells[at].saturating_add(q);
            }
        }
        if all {
            if (first_block_row..self.k_hi).contains(&k) {
                self.blocks[block()].include(i as u16, front);
            }
        } else {
            for (q, (j, k)) in q.into_iter().zip(columns) {
                if let Some(col) = self.local(j, k).filter(|_| q > 0) {
                    self.meta[col].include(i as u16, front);
                }
            }
        }
    }
}

/// A fan's cells in the deposit (see [`crate::Fan`]): a piece spanning
/// `(dj, dk)` cells across the rays at tangent-plane coordinates `(u, v)`
/// and depth `x` crosses the rays of its column over the length
///
/// ```text
/// |piece x e| = x du sqrt(Q / q),   Q = q (dj^2 + dk^2) - (u dj + v dk)^2,   q = 1 + u^2 + v^2
/// ```
///
/// (`e` the unit ray; the piece's extent along the ray does not count),
/// and the column's cross-section normal to the rays there is
/// `x^2 du^2 / sqrt(q)` (the cell's area `x^2 du^2` in the plane of depth
/// `x`, which the rays cross at `cos = 1 / sqrt(q)`), so that the optical
/// depth the piece adds to each ray of the column is
///
/// ```text
/// tau = alpha w |piece x e| sqrt(q) / (x^2 du^2) = alpha w sqrt(Q) / (x du)
/// ```
///
/// which for parallel rays (`u = v = 0`, `x du = ds`) is the cubic map's
/// `alpha w sqrt(dj^2 + dk^2) / ds`.
///
/// A straight fiber is not straight in map coordinates (depth and
/// tangent-plane coordinates vary projectively along it), so its pieces
/// are cut evenly in the world and each mapped on its own.
#[derive(Debug, Clone, Copy)]
struct Spread {
    frame: LightFrame,
    start: Vec3,
    du: f32,
    ds: f32,
}

impl Spread {
    /// The `m` pieces of a segment from world point `aw` in world steps
    /// `dw` (map coordinates `a` to `b`): `f(mid, step)` for each, in
    /// cells, each piece mapped on its own.
    #[inline]
    fn pieces(&self, aw: Vec3, dw: Vec3, a: Vec3, b: Vec3, m: u32, mut f: impl FnMut(Vec3, Vec3)) {
        let mut p0 = a;
        for k in 0..m {
            let p1 = if k + 1 == m {
                b
            } else {
                self.frame.to_cells(aw + (k + 1) as f32 * dw)
            };
            let mid = self.frame.to_cells(aw + (k as f32 + 0.5) * dw);
            f(mid, p1 - p0);
            p0 = p1;
        }
    }

    /// `tau / (alpha w / du)` of a piece at `mid` spanning `step` (cells).
    #[inline]
    fn weight(&self, mid: Vec3, step: Vec3) -> f32 {
        let x = self.start.x + mid.x * self.ds;
        let u = self.start.y + mid.y * self.du;
        let v = self.start.z + mid.z * self.du;
        let q = 1.0 + u * u + v * v;
        let cross = u * step.y + v * step.z;
        let across = (q * (step.y * step.y + step.z * step.z) - cross * cross).max(0.0);
        across.sqrt() / x.max(1e-30)
    }
}

/// Cuts one strand (points in map coordinates) into pieces no longer than
/// a cell, deposits those that reach `rows` and counts those it owns. For
/// a fan each piece's weight is its own ([`Spread`]).
///
/// A segment well inside the map (both ends within a cell of it) walks its
/// pieces in fixed point, with integer cells and weights; one reaching
/// further out walks them in floating point, where a far coordinate cannot
/// overflow an integer.
#[inline]
fn strand_pieces(rows: &mut Rows, pts: &[Vec3], k_q: f32, spread: Option<Spread>) -> FillStats {
    let mut stats = FillStats::default();
    let n = rows.n as f32;
    let max_pieces = (4 * rows.n) as f32;
    let (vis_lo, vis_hi) = rows.visits();
    let near = |p: Vec3| p.cmpge(Vec3::splat(-1.0)).all() && p.cmple(Vec3::splat(n + 1.0)).all();
    for w in pts.windows(2) {
        let (a, b) = (w[0], w[1]);
        let finite = a.z.is_finite() && b.z.is_finite();
        if finite && (a.z.max(b.z) < vis_lo || a.z.min(b.z) >= vis_hi) {
            continue;
        }
        let d = b - a;
        let across = (d.y * d.y + d.z * d.z).sqrt();
        let m = piece_count(d, max_pieces);
        let inv_m = 1.0 / m as f32;
        // Quanta of one piece; below half a quantum it rounds to nothing.
        let q = (k_q * across * inv_m).min(u32::MAX as f32);
        if q < 0.5 && spread.is_none() {
            continue;
        }
        let step = d * inv_m;
        if let Some(f) = spread {
            // Pieces cut evenly in the world, each mapped on its own; none
            // of a segment reaching behind the source.
            if a == crate::frame::BEHIND || b == crate::frame::BEHIND {
                stats.out_of_map += u64::from(m) * u64::from(rows.owns(a.z.floor() as i32));
                continue;
            }
            let (aw, bw) = (f.frame.to_world(a), f.frame.to_world(b));
            f.pieces(aw, (bw - aw) * inv_m, a, b, m, |mid, step| {
                let own = rows.owns(mid.z.floor() as i32);
                if !(mid.cmpge(Vec3::ZERO).all() && mid.cmplt(Vec3::splat(n)).all()) {
                    stats.out_of_map += u64::from(own);
                    return;
                }
                let q = (k_q * f.weight(mid, step)).min(u32::MAX as f32);
                tent_splat(rows, mid, step, q);
                stats.samples += u64::from(own);
            });
            continue;
        }
        if near(a) && near(b) {
            let fx = |v: Vec3| (v * (1 << FX) as f32).as_ivec3();
            let s = fx(step);
            let mut p = fx(a) + s / 2;
            // The front in floating point, as the other path has it: a
            // front truncated to fixed point could start the hair in front
            // of its own first point.
            let mut mid_x = a.x + 0.5 * step.x;
            let half_dx = 0.5 * step.x.abs();
            let lim = (rows.n as u32) << FX;
            // q + 0.5 truncated rounds to nearest; 32 bits of weight
            // (16 across each axis) times 32 of quanta fit in a u64.
            let q = u64::from((q + 0.5) as u32);
            for _ in 0..m {
                let own = rows.owns(p.z >> FX);
                if (p.x as u32) < lim && (p.y as u32) < lim && (p.z as u32) < lim {
                    // The piece starts half a step before its midpoint.
                    let front = mid_x - half_dx;
                    // Tent splat across the light, bilinear weights of
                    // the four columns around the midpoint (see below).
                    let (fy, fz) = (p.y - FX_HALF, p.z - FX_HALF);
                    let (ty, tz) = (
                        u64::from((fy & FX_FRAC) as u32),
                        u64::from((fz & FX_FRAC) as u32),
                    );
                    let (sy, sz) = ((1 << FX) - ty, (1 << FX) - tz);
                    let part = |w: u64| ((q * w + (1 << 31)) >> 32) as u32;
                    let qs = [part(sy * sz), part(ty * sz), part(sy * tz), part(ty * tz)];
                    rows.splat(fy >> FX, fz >> FX, (p.x >> FX) as u32, qs, front);
                    stats.samples += u64::from(own);
                } else {
                    stats.out_of_map += u64::from(own);
                }
                p += s;
                mid_x += step.x;
            }
        } else {
            let mut mid = a + 0.5 * step;
            for _ in 0..m {
                let own = rows.owns(mid.z.floor() as i32);
                if mid.cmpge(Vec3::ZERO).all() && mid.cmplt(Vec3::splat(n)).all() {
                    tent_splat(rows, mid, step, q);
                    stats.samples += u64::from(own);
                } else {
                    stats.out_of_map += u64::from(own);
                }
                mid += step;
            }
        }
    }
    stats
}

/// Deposits `q` quanta of a piece at `mid` (inside the map) spanning
/// `step` (cells), starting half its step along the light before `mid`.
///
/// Tent splat across the light: the piece's quanta go to the four columns
/// around its midpoint with bilinear weights, so that the map is a smooth
/// function of where a fiber lies. A nearest-column deposit aliases
/// against combed hair into stripes that move with the grid.
#[inline(always)]
fn tent_splat(rows: &mut Rows, mid: Vec3, step: Vec3, q: f32) {
    let front = mid.x - 0.5 * step.x.abs();
    // (fy + 1) > 0, so the truncating cast is a floor.
    let (fy, fz) = (mid.y - 0.5, mid.z - 0.5);
    let (j0, k0) = ((fy + 1.0) as i32 - 1, (fz + 1.0) as i32 - 1);
    let (ty, tz) = (fy - j0 as f32, fz - k0 as f32);
    // q w >= 0: adding 0.5 and truncating rounds to nearest.
    let (sy, sz) = (1.0 - ty, 1.0 - tz);
    let qs = [
        (q * sy * sz + 0.5) as u32,
        (q * ty * sz + 0.5) as u32,
        (q * sy * tz + 0.5) as u32,
        (q * ty * tz + 0.5) as u32,
    ];
    rows.splat(j0, k0, mid.x as u32, qs, front);
}

/// Walks a strand's segments in map coordinates (cells): `f(start, d,
/// across, m)` for each, with `d` the segment, `across` its length across
/// the light and `m` the pieces it is cut into ([`piece_count`]; a segment
/// longer than the map diagonal is cut no finer than that).
#[inline]
pub(crate) fn for_each_segment(
    frame: &LightFrame,
    pts: &[Vec3],
    mut f: impl FnMut(Vec3, Vec3, f32, u32),
) {
    let max_pieces = (4 * frame.n_cells) as f32;
    let Some(&first) = pts.first() else {
        return;
    };
    let mut prev = frame.to_cells(first);
    for &p in &pts[1..] {
        let cur = frame.to_cells(p);
        let d = cur - prev;
        let across = (d.y * d.y + d.z * d.z).sqrt();
        f(prev, d, across, piece_count(d, max_pieces));
        prev = cur;
    }
}

/// Walks a strand's pieces in a fan's map (see [`Spread`]): `f(mid,
/// step, weight)` for each, `mid` and `step` in cells, `weight` its
/// optical depth per `alpha w / du`; pieces cut evenly in the world, as
/// many a segment as cells it spans (at most `4 n`). Segments reaching
/// behind the source are skipped, and `behind` counts their pieces.
pub(crate) fn for_each_fan_piece(
    frame: &LightFrame,
    pts: &[Vec3],
    mut f: impl FnMut(Vec3, Vec3, f32),
    mut behind: impl FnMut(u32),
) {
    let Some(fan) = frame.fan else {
        return;
    };
    let spread = Spread {
        frame: *frame,
        start: fan.start,
        du: fan.du,
        ds: frame.ds,
    };
    let max_pieces = (4 * frame.n_cells) as f32;
    for w in pts.windows(2) {
        let (a, b) = (frame.to_cells(w[0]), frame.to_cells(w[1]));
        let m = piece_count(b - a, max_pieces);
        if a == crate::frame::BEHIND || b == crate::frame::BEHIND {
            behind(m);
            continue;
        }
        let dw = (w[1] - w[0]) / m as f32;
        spread.pieces(w[0], dw, a, b, m, |mid, step| {
            f(mid, step, spread.weight(mid, step))
        });
    }
}

/// Pieces a segment spanning `d` cells is cut into: `m = ceil` of its
/// longest axis (at most `max_pieces`), at least 1, so that every piece
/// spans at most one cell along each axis. (Truncating casts instead of
/// `ceil`, which is a libm call on baseline x86-64.)
#[inline]
pub(crate) fn piece_count(d: Vec3, max_pieces: f32) -> u32 {
    let len = d.abs().max_element().min(max_pieces);
    let whole = len as u32;
    (whole + u32::from((whole as f32) < len)).max(1)
}

/// Column `col`'s meta: its own, `own`, joined with its four blocks' (see
/// [`DensityMap`]).
#[inline]
fn column_meta(own: &ColumnMeta, blocks: &[ColumnMeta], n: usize, col: usize) -> ColumnMeta {
    let (j, k) = (col % n, col / n);
    // Blocks (j0, k0) for j0 in {j - 1, j}, k0 in {k - 1, k}.
    let b = k * (n + 1) + j;
    own.union(blocks[b])
        .union(blocks[b + 1])
        .union(blocks[b + n + 1])
        .union(blocks[b + n + 2])
}

/// Adds `q` quanta to cell `i` of column `col` of `cells` (columns of `n`
/// cells), saturating: for non-negative terms a saturating sum is still
/// independent of order. Widens the column's occupied span and front.
#[inline]
fn add_at(
    cells: &mut [u32],
    meta: &mut [ColumnMeta],
    n: usize,
    col: usize,
    i: u32,
    q: u32,
    front: f32,
) {
    let cell = &mut cells[col * n + i as usize];
    *cell = cell.saturating_add(q);
    meta[col].include(i as u16, front);
}

#[cfg(test)]
mod tests;
