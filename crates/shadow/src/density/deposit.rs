//! Depositing hair into the map: each segment cut into pieces no longer
//! than a cell, each piece splatted into the four columns around it (paper
//! 4.1), with slabs of rows written in parallel.

use std::ops::Range;

use glam::Vec3;
use rayon::prelude::*;
use strands::Hair;

use super::{
    ColumnMeta, DEPOSIT_RUN_WORK, DEPTH_QUANTUM, DensityMap, FillStats, Scratch, column_meta,
};
use crate::{Fiber, LightFrame};

impl DensityMap {
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

    pub(super) fn deposit_runs(
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
