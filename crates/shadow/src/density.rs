//! Filling hair density into the light-oriented map (paper 4.1).

use std::ops::Range;

use glam::Vec3;
use rayon::prelude::*;

use crate::{LightFrame, Occluder};

mod deposit;

pub(crate) use deposit::{for_each_fan_piece, for_each_segment, piece_count};

/// Optical depth of one fixed-point unit in a cell: 2^-20.
///
/// Cells hold optical depth as integers so that deposits add up to the same
/// bytes in any order (atomic adds from many threads, or partial maps summed
/// from many workers). 2^-20 keeps the rounding of one deposit below 5e-7,
/// and a u32 cell saturates at an optical depth of 4096, where the
/// transmittance `exp(-4096)` is zero in any float format anyway.
pub const DEPTH_QUANTUM: f64 = 1.0 / (1u64 << 20) as f64;

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
    /// First occupied cell.
    pub lo: u16,
    /// Last occupied cell.
    pub hi: u16,
    /// Where the hair starts, slice coordinate in cells.
    pub front: f32,
}

impl ColumnMeta {
    /// A column with no hair.
    pub const EMPTY: ColumnMeta = ColumnMeta {
        lo: EMPTY_LO,
        hi: 0,
        front: f32::INFINITY,
    };

    /// Whether the column holds no hair.
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

    /// The map's frame.
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
