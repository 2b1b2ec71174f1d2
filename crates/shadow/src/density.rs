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

const EMPTY_LO: u16 = u16::MAX;

/// The density map: per cell, the optical depth `tau = kappa * ds` that hair
/// inside it adds to a light ray crossing it, in units of [`DEPTH_QUANTUM`].
///
/// Cells are stored column-major, `(k * n + j) * n + i`: the transmittance
/// sweep reads each `(j, k)` column as one contiguous run. Each column also
/// records its first and last occupied slice, so that clearing and sweeping
/// cost time in proportion to the hair, not to `n^3`.
#[derive(Debug, Clone)]
pub struct DensityMap {
    frame: LightFrame,
    n: usize,
    cells: Vec<u32>,
    meta: Vec<ColumnMeta>,
    /// Opaque bodies' deposits since the last clear: `(column, slice,
    /// quanta)`, sorted.
    bodies: Vec<(u32, u16, u32)>,
    /// The parallel deposit's lists (task, then slab of `k`), kept empty
    /// between fills so that their memory is not allocated and faulted in
    /// again for every frame.
    scratch: Vec<Vec<Vec<Deposit>>>,
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

    /// Widens the column to hold a deposit in slice `i` whose piece starts
    /// at slice coordinate `front`. Min and max do not depend on order.
    #[inline]
    fn include(&mut self, i: u16, front: f32) {
        self.lo = self.lo.min(i);
        self.hi = self.hi.max(i);
        // `min` without `f32::min`'s NaN handling (a NaN front changes
        // nothing either way, and `self.front` starts infinite, never NaN).
        if front < self.front {
            self.front = front;
        }
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

/// One piece's deposit into slice `i` of four columns: `q[0]` quanta into
/// column `col = k * n + j`, `q[1]` into `(j + 1, k)`, `q[2]` into
/// `(j, k + 1)`, `q[3]` into `(j + 1, k + 1)`, from a piece that starts at
/// slice coordinate `front`. Zero quanta touch nothing.
#[derive(Debug, Clone, Copy)]
struct Deposit {
    col: u32,
    i: u32,
    q: [u32; 4],
    front: f32,
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
            bodies: Vec::new(),
            scratch: Vec::new(),
        }
    }

    pub fn frame(&self) -> &LightFrame {
        &self.frame
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
    /// With several threads the strands are cut into tasks that list their
    /// deposits by slab of `k`; then each slab applies its deposits alone.
    /// No atomics: a locked add per deposit would serialize the cache misses
    /// that dominate this stage.
    pub fn deposit(&mut self, hair: &Hair, strands: Range<usize>, fiber: &Fiber) -> FillStats {
        // Fixed-point optical depth per cell of piece length across the light.
        let k_q =
            (f64::from(fiber.cross_section()) / f64::from(self.frame.ds) / DEPTH_QUANTUM) as f32;
        if k_q == 0.0 || strands.is_empty() {
            return FillStats::default();
        }
        let n = self.n;
        let offsets = hair.offsets();
        let points = hair.points();
        let strand_points = |s: usize| &points[offsets[s] as usize..offsets[s + 1] as usize];
        let threads = rayon::current_num_threads();
        if threads == 1 {
            let mut stats = FillStats::default();
            for s in strands {
                stats = stats
                    + pieces(&self.frame, strand_points(s), k_q, |_, d| {
                        apply(&mut self.cells, &mut self.meta, n, 0, d)
                    });
            }
            return stats;
        }
        // Phase 1: deposits of each task, bucketed by slab of k.
        let slabs = (threads * 4).min(n);
        let slab_k = n.div_ceil(slabs);
        let slabs = n.div_ceil(slab_k);
        let tasks = (threads * 4).min(strands.len());
        let per_task = strands.len().div_ceil(tasks);
        let frame = self.frame;
        let mut lists = std::mem::take(&mut self.scratch);
        lists.resize_with(tasks, Vec::new);
        let stats: FillStats = lists
            .par_iter_mut()
            .enumerate()
            .map(|(t, buckets)| {
                let lo = strands.start + t * per_task;
                let hi = (lo + per_task).min(strands.end);
                buckets.resize_with(slabs, Vec::new);
                let mut stats = FillStats::default();
                for s in lo..hi {
                    stats = stats
                        + pieces(&frame, strand_points(s), k_q, |k, d| {
                            buckets[k / slab_k].push(d)
                        });
                }
                stats
            })
            .sum();
        // Phase 2: each slab of k applies its deposits, which also reach the
        // first row of the next slab (k + 1). Even slabs first, then odd
        // ones, each together with its successor: no two tasks share a cell.
        for parity in [0, 1] {
            let (skip_cells, skip_cols) = (parity * n * n * slab_k, parity * n * slab_k);
            self.cells[skip_cells..]
                .par_chunks_mut(2 * n * n * slab_k)
                .zip(self.meta[skip_cols..].par_chunks_mut(2 * n * slab_k))
                .enumerate()
                .for_each(|(pair, (cells, meta))| {
                    let b = 2 * pair + parity;
                    let base = b * n * slab_k;
                    for buckets in &lists {
                        for &d in &buckets[b] {
                            apply(cells, meta, n, base, d);
                        }
                    }
                });
        }
        for buckets in &mut lists {
            buckets.iter_mut().for_each(Vec::clear);
        }
        self.scratch = lists;
        stats
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
        covered
    }

    /// The quanta of cell `(i, j, k)` that hair deposited: the cell's
    /// quanta without those of the opaque bodies (a self-collision must
    /// not mistake the head's shadow for dense hair).
    pub fn hair_quanta(&self, i: usize, j: usize, k: usize) -> u32 {
        let mut q = self.quanta(i, j, k);
        let key = ((k * self.n + j) as u32, i as u16);
        let from = self.bodies.partition_point(|b| (b.0, b.1) < key);
        for b in self.bodies[from..].iter().take_while(|b| (b.0, b.1) == key) {
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
        let n = self.n;
        let d = Deposit {
            col: (k * n + j) as u32,
            i: i as u32,
            q: [q, 0, 0, 0],
            front,
        };
        apply(&mut self.cells, &mut self.meta, n, 0, d);
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
        let m = self.meta[col];
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

/// Cuts one strand into pieces no longer than a cell and hands each
/// piece's deposit to `emit`.
#[inline]
fn pieces(
    frame: &LightFrame,
    pts: &[Vec3],
    k_q: f32,
    mut emit: impl FnMut(usize, Deposit),
) -> FillStats {
    let mut stats = FillStats::default();
    let nu = frame.n_cells as usize;
    let n = frame.n_cells as f32;
    for_each_segment(frame, pts, |prev, d, across, m| {
        let inv_m = 1.0 / m as f32;
        // Quanta of one piece; below half a quantum it rounds to nothing.
        let q = (k_q * across * inv_m).min(u32::MAX as f32);
        if q >= 0.5 {
            let step = d * inv_m;
            let mut mid = prev + 0.5 * step;
            for _ in 0..m {
                if mid.cmpge(Vec3::ZERO).all() && mid.cmplt(Vec3::splat(n)).all() {
                    // The piece starts half a step before its midpoint.
                    let front = mid.x - 0.5 * step.x.abs();
                    let i = mid.x as u32;
                    // Tent splat across the light: the piece's quanta go to
                    // the four columns around its midpoint with bilinear
                    // weights, so that the map is a smooth function of where
                    // a fiber lies. A nearest-column deposit aliases against
                    // combed hair into stripes that move with the grid.
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
                    let last = nu as i32 - 1;
                    if j0 >= 0 && k0 >= 0 && j0 < last && k0 < last {
                        emit(
                            k0 as usize,
                            Deposit {
                                col: (k0 as usize * nu + j0 as usize) as u32,
                                i,
                                q: qs,
                                front,
                            },
                        );
                    } else {
                        // At the map's edge: each column that exists on its own.
                        for (x, (dj, dk)) in
                            [(0, 0), (1, 0), (0, 1), (1, 1)].into_iter().enumerate()
                        {
                            let (j, k) = (j0 + dj, k0 + dk);
                            if qs[x] > 0 && (0..=last).contains(&j) && (0..=last).contains(&k) {
                                let (j, k) = (j as usize, k as usize);
                                emit(
                                    k,
                                    Deposit {
                                        col: (k * nu + j) as u32,
                                        i,
                                        q: [qs[x], 0, 0, 0],
                                        front,
                                    },
                                );
                            }
                        }
                    }
                    stats.samples += 1;
                } else {
                    stats.out_of_map += 1;
                }
                mid += step;
            }
        }
    });
    stats
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

/// Adds a deposit to `cells` (whose first column is column `base`),
/// saturating: for non-negative terms a saturating sum is still independent
/// of order. Widens the column's occupied span and front.
#[inline]
fn apply(cells: &mut [u32], meta: &mut [ColumnMeta], n: usize, base: usize, d: Deposit) {
    let col = d.col as usize - base;
    for (q, c) in d.q.into_iter().zip([col, col + 1, col + n, col + n + 1]) {
        if q > 0 {
            let cell = &mut cells[c * n + d.i as usize];
            *cell = cell.saturating_add(q);
            meta[c].include(d.i as u16, d.front);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Light;

    fn frame(n: u32) -> LightFrame {
        LightFrame::centered(&Light::directional(Vec3::X).unwrap(), Vec3::ZERO, 2.0, n).unwrap()
    }

    #[test]
    fn a_fiber_across_the_light_deposits_alpha_w_length_over_ds_squared() {
        let mut map = DensityMap::new(frame(8));
        let ds = 0.25;
        let mut hair = Hair::new();
        // Along z, a quarter cell off the column centres in y, at slice i = 4: 8 cells long.
        hair.push_strand(&[Vec3::new(0.1, 0.1, -1.0), Vec3::new(0.1, 0.1, 1.0)])
            .unwrap();
        let fiber = Fiber::new(0.01, 0.5).unwrap();
        let stats = map.fill(&hair, &fiber);
        assert_eq!(
            stats,
            FillStats {
                samples: 8,
                out_of_map: 0
            }
        );
        let all = || (0..8).flat_map(|k| (0..8).flat_map(move |j| (0..8).map(move |i| (i, j, k))));
        let total: f64 = all().map(|(i, j, k)| map.cell_depth(i, j, k)).sum();
        // alpha * w * length / ds^2 = 0.005 * 2 / 0.0625
        assert!((total - 0.005 * 2.0 / (ds * ds)).abs() < 1e-5, "{total}");
        // Every deposit lies in the fiber's slice, in 8 columns along it and
        // 2 across it: the fiber is 0.4 cells past a column centre across,
        // so the tent splat weighs the two sides 0.9 and 0.1.
        let c = map.frame().to_cells(Vec3::new(0.1, 0.1, 0.0));
        assert!(all().all(|(i, j, k)| i == c.x as usize || map.quanta(i, j, k) == 0));
        let cols: Vec<f64> = (0..64)
            .filter(|&col| map.span(col).is_some())
            .map(|col| map.cell_depth(c.x as usize, col % 8, col / 8))
            .collect();
        assert_eq!(cols.len(), 16);
        let per_col = total / 8.0;
        assert_eq!(
            cols.iter()
                .filter(|&&d| (d - 0.9 * per_col).abs() < 1e-5)
                .count(),
            8,
            "{cols:?}"
        );
        assert_eq!(
            cols.iter()
                .filter(|&&d| (d - 0.1 * per_col).abs() < 1e-5)
                .count(),
            8,
            "{cols:?}"
        );
    }

    #[test]
    fn a_fiber_along_the_light_casts_nothing() {
        let mut map = DensityMap::new(frame(8));
        let mut hair = Hair::new();
        hair.push_strand(&[Vec3::new(-0.9, 0.1, 0.1), Vec3::new(0.9, 0.1, 0.1)])
            .unwrap();
        map.fill(&hair, &Fiber::new(0.01, 1.0).unwrap());
        assert!((0..64).all(|c| map.span(c).is_none()));
    }

    #[test]
    fn hair_outside_the_map_is_counted_not_wrapped() {
        let mut map = DensityMap::new(frame(4));
        let mut hair = Hair::new();
        hair.push_strand(&[Vec3::new(0.0, 5.0, -0.5), Vec3::new(0.0, 5.0, 0.5)])
            .unwrap();
        let stats = map.fill(&hair, &Fiber::new(0.1, 1.0).unwrap());
        assert_eq!(stats.samples, 0);
        assert!(stats.out_of_map > 0);
        assert!(
            (0..16).all(|c| map.span(c).is_none()),
            "nothing wrapped into the map"
        );
    }

    #[test]
    fn clear_resets_cells_and_spans() {
        let mut map = DensityMap::new(frame(8));
        let mut hair = Hair::new();
        hair.push_strand(&[Vec3::new(0.1, 0.1, -1.0), Vec3::new(0.1, 0.1, 1.0)])
            .unwrap();
        map.fill(&hair, &Fiber::new(0.01, 0.5).unwrap());
        map.clear();
        assert!((0..64).all(|c| map.span(c).is_none()));
        assert!((0..8).all(|k| map.quanta(4, 4, k) == 0));
    }

    #[test]
    fn saturates_instead_of_wrapping() {
        let mut map = DensityMap::new(frame(2));
        map.add_quanta(0, 0, 0, u32::MAX - 1);
        map.add_quanta(0, 0, 0, 5);
        assert_eq!(map.quanta(0, 0, 0), u32::MAX);
    }
}
