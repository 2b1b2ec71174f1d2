//! Filling hair density into the light-oriented map (paper 4.1).

use std::ops::Range;
use std::sync::atomic::{AtomicU16, AtomicU32, Ordering::Relaxed};

use glam::Vec3;
use rayon::prelude::*;
use strands::Hair;

use crate::{Fiber, LightFrame};

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
#[derive(Debug)]
pub struct DensityMap {
    frame: LightFrame,
    n: usize,
    cells: Vec<AtomicU32>,
    col_lo: Vec<AtomicU16>,
    col_hi: Vec<AtomicU16>,
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
        FillStats { samples: self.samples + o.samples, out_of_map: self.out_of_map + o.out_of_map }
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
            cells: std::iter::repeat_with(|| AtomicU32::new(0)).take(n * n * n).collect(),
            col_lo: std::iter::repeat_with(|| AtomicU16::new(EMPTY_LO)).take(n * n).collect(),
            col_hi: std::iter::repeat_with(|| AtomicU16::new(0)).take(n * n).collect(),
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
        let n = self.n;
        self.cells.par_chunks_mut(n).zip(self.col_lo.par_iter_mut().zip(self.col_hi.par_iter_mut())).for_each(|(col, (lo, hi))| {
            let (l, h) = (*lo.get_mut(), *hi.get_mut());
            if l <= h {
                for c in &mut col[l as usize..=h as usize] {
                    *c.get_mut() = 0;
                }
            }
            *lo.get_mut() = EMPTY_LO;
            *hi.get_mut() = 0;
        });
    }

    /// Empties the map and deposits all of `hair`.
    pub fn fill(&mut self, hair: &Hair, fiber: &Fiber) -> FillStats {
        self.clear();
        self.deposit(hair, 0..hair.strand_count(), fiber)
    }

    /// Adds the density of strands `strands` of `hair` (to the map's current
    /// content). Any split of the strands over calls, threads or machines
    /// gives the same cells.
    ///
    /// Each segment `(a, b)` is cut into `m = ceil(|b - a| / ds)` pieces, so
    /// that no piece is longer than a cell, and each piece adds to the cell
    /// holding its midpoint the optical depth (see [`Fiber`])
    ///
    /// ```text
    /// tau = kappa * ds = alpha * w * |piece x L| / ds^2
    /// ```
    ///
    /// where `|piece x L| = dl sin(theta)`. In map coordinates (cells, X_map
    /// along L) that is `alpha * w / ds * sqrt(dy^2 + dz^2)`.
    pub fn deposit(&self, hair: &Hair, strands: Range<usize>, fiber: &Fiber) -> FillStats {
        // Fixed-point optical depth per cell of piece length across the light.
        let k_q = (f64::from(fiber.cross_section()) / f64::from(self.frame.ds) / DEPTH_QUANTUM) as f32;
        if k_q == 0.0 {
            return FillStats::default();
        }
        let offsets = hair.offsets();
        strands
            .into_par_iter()
            .with_min_len(32)
            .map(|s| {
                let pts = &hair.points()[offsets[s] as usize..offsets[s + 1] as usize];
                self.deposit_strand(pts, k_q)
            })
            .sum()
    }

    fn deposit_strand(&self, pts: &[Vec3], k_q: f32) -> FillStats {
        let mut stats = FillStats::default();
        let n = self.n as f32;
        // A segment longer than the map diagonal is cut no finer than this.
        let max_pieces = 4 * self.n;
        let mut prev = match pts.first() {
            Some(&p) => self.frame.to_cells(p),
            None => return stats,
        };
        for &p in &pts[1..] {
            let cur = self.frame.to_cells(p);
            let d = cur - prev;
            let across = (d.y * d.y + d.z * d.z).sqrt();
            let m = (d.length().ceil() as usize).clamp(1, max_pieces);
            let q = (k_q * across / m as f32).round();
            if q >= 1.0 {
                let q = if q >= u32::MAX as f32 { u32::MAX } else { q as u32 };
                let step = d / m as f32;
                let mut mid = prev + 0.5 * step;
                for _ in 0..m {
                    if mid.cmpge(Vec3::ZERO).all() && mid.cmplt(Vec3::splat(n)).all() {
                        self.add(mid.x as usize, mid.y as usize, mid.z as usize, q);
                        stats.samples += 1;
                    } else {
                        stats.out_of_map += 1;
                    }
                    mid += step;
                }
            }
            prev = cur;
        }
        stats
    }

    /// Adds `q` quanta to cell `(i, j, k)`, saturating: for non-negative
    /// terms, a saturating sum is still independent of order.
    #[inline]
    fn add(&self, i: usize, j: usize, k: usize, q: u32) {
        let col = k * self.n + j;
        let prev = self.cells[col * self.n + i]
            .fetch_update(Relaxed, Relaxed, |v| Some(v.saturating_add(q)))
            .expect("the update closure always returns Some");
        if prev == 0 {
            // First deposit in this cell: widen the column's occupied span.
            self.col_lo[col].fetch_min(i as u16, Relaxed);
            self.col_hi[col].fetch_max(i as u16, Relaxed);
        }
    }

    /// Adds raw quanta to cell `(i, j, k)`: for merging partial maps.
    pub fn add_quanta(&self, i: usize, j: usize, k: usize, q: u32) {
        if q > 0 {
            self.add(i, j, k, q);
        }
    }

    /// The occupied span `lo..=hi` of column `col = k * n + j`, if any.
    pub fn span(&self, col: usize) -> Option<(usize, usize)> {
        let lo = self.col_lo[col].load(Relaxed);
        let hi = self.col_hi[col].load(Relaxed);
        (lo <= hi).then_some((lo as usize, hi as usize))
    }

    /// Quanta of column `col`'s cells `range`.
    pub fn column(&self, col: usize, range: Range<usize>) -> impl Iterator<Item = u32> + '_ {
        self.cells[col * self.n + range.start..col * self.n + range.end].iter().map(|c| c.load(Relaxed))
    }

    /// Quanta of cell `(i, j, k)`.
    pub fn quanta(&self, i: usize, j: usize, k: usize) -> u32 {
        self.cells[(k * self.n + j) * self.n + i].load(Relaxed)
    }

    /// Optical depth of cell `(i, j, k)`.
    pub fn cell_depth(&self, i: usize, j: usize, k: usize) -> f64 {
        f64::from(self.quanta(i, j, k)) * DEPTH_QUANTUM
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
        // Along z through the column centres j = 4, at slice i = 4: 8 cells long.
        hair.push_strand(&[Vec3::new(0.1, 0.1, -1.0), Vec3::new(0.1, 0.1, 1.0)]).unwrap();
        let fiber = Fiber::new(0.01, 0.5).unwrap();
        let stats = map.fill(&hair, &fiber);
        assert_eq!(stats, FillStats { samples: 8, out_of_map: 0 });
        let total: f64 = (0..8).flat_map(|k| (0..8).flat_map(move |j| (0..8).map(move |i| (i, j, k)))).map(|(i, j, k)| map.cell_depth(i, j, k)).sum();
        // alpha * w * length / ds^2 = 0.005 * 2 / 0.0625
        assert!((total - 0.005 * 2.0 / (ds * ds)).abs() < 1e-5, "{total}");
        let c = map.frame().to_cells(Vec3::new(0.1, 0.1, 0.0));
        let occupied: Vec<_> = (0..64).filter_map(|col| map.span(col)).collect();
        assert_eq!(occupied, vec![(c.x as usize, c.x as usize); 8], "one cell in each of 8 columns, at slice i");
    }

    #[test]
    fn a_fiber_along_the_light_casts_nothing() {
        let mut map = DensityMap::new(frame(8));
        let mut hair = Hair::new();
        hair.push_strand(&[Vec3::new(-0.9, 0.1, 0.1), Vec3::new(0.9, 0.1, 0.1)]).unwrap();
        map.fill(&hair, &Fiber::new(0.01, 1.0).unwrap());
        assert!((0..64).all(|c| map.span(c).is_none()));
    }

    #[test]
    fn hair_outside_the_map_is_counted_not_wrapped() {
        let mut map = DensityMap::new(frame(4));
        let mut hair = Hair::new();
        hair.push_strand(&[Vec3::new(0.0, 5.0, -0.5), Vec3::new(0.0, 5.0, 0.5)]).unwrap();
        let stats = map.fill(&hair, &Fiber::new(0.1, 1.0).unwrap());
        assert_eq!(stats.samples, 0);
        assert!(stats.out_of_map > 0);
        assert!((0..16).all(|c| map.span(c).is_none()), "nothing wrapped into the map");
    }

    #[test]
    fn clear_resets_cells_and_spans() {
        let mut map = DensityMap::new(frame(8));
        let mut hair = Hair::new();
        hair.push_strand(&[Vec3::new(0.1, 0.1, -1.0), Vec3::new(0.1, 0.1, 1.0)]).unwrap();
        map.fill(&hair, &Fiber::new(0.01, 0.5).unwrap());
        map.clear();
        assert!((0..64).all(|c| map.span(c).is_none()));
        assert!((0..8).all(|k| map.quanta(4, 4, k) == 0));
    }

    #[test]
    fn saturates_instead_of_wrapping() {
        let map = DensityMap::new(frame(2));
        map.add_quanta(0, 0, 0, u32::MAX - 1);
        map.add_quanta(0, 0, 0, 5);
        assert_eq!(map.quanta(0, 0, 0), u32::MAX);
    }
}
