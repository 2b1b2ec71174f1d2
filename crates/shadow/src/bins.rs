//! Segments binned by light-view column: what both references test a ray
//! against.
//!
//! Every drawn segment is a capsule of the fiber's radius. It is listed in
//! every column of a `GRID x GRID` map fitted to the hair that its shadow
//! (the capsule seen from the light) overlaps, so a ray towards the light
//! along a column meets only segments listed in that column. For a light
//! with a source the columns are bundles of rays from it; a long straight
//! fiber is not straight in those cells, so segments are first cut,
//! evenly in the world, into pieces no longer than a cell, as the density
//! map does.

use glam::Vec3;
use rayon::prelude::*;

use crate::input::ShadowInput;
use crate::{FillStats, LightFrame, ShadowError};

/// Columns of the footprint reference's grid per side.
pub(crate) const GRID: u32 = 128;

#[derive(Debug)]
pub(crate) struct SegmentBins {
    pub(crate) frame: LightFrame,
    /// The (cut) hair's points, in map cells and in the world.
    pub(crate) cells: Vec<Vec3>,
    pub(crate) world: Vec<Vec3>,
    /// The strand of each point.
    pub(crate) strand: Vec<u32>,
    /// Per column, the starts of the segments (`cells[s]` to
    /// `cells[s + 1]`) whose capsule's shadow reaches it, ascending.
    start: Vec<u32>,
    segs: Vec<u32>,
    /// Once ordered by depth ([`Self::order_by_depth`]): per entry of
    /// `segs`, where its capsule starts along the light (slice coordinate,
    /// cells), ascending within each column; per column, the longest
    /// extent of its capsules along the light.
    lo: Vec<f32>,
    extent: Vec<f32>,
    /// Fiber radius across the rays, in cells (for a directional light).
    pub(crate) radius: f32,
    pub(crate) stats: FillStats,
}

impl SegmentBins {
    /// The input's hair binned on a grid of `grid` columns a side.
    pub(crate) fn new(input: &ShadowInput, grid: u32) -> Result<SegmentBins, ShadowError> {
        let frame = input.fit(grid)?;
        let n = grid as i32;
        let fine = frame.fan.map(|_| {
            let max_pieces = (4 * grid) as f32;
            let mut fine =
                strands::Hair::with_capacity(input.hair.strand_count(), input.hair.point_count());
            let mut pts = Vec::new();
            for st in input.hair.strands() {
                pts.clear();
                pts.extend(st.first());
                for w in st.windows(2) {
                    let d = frame.to_cells(w[1]) - frame.to_cells(w[0]);
                    let m = crate::density::piece_count(d, max_pieces);
                    pts.extend((1..=m).map(|k| w[0] + (w[1] - w[0]) * (k as f32 / m as f32)));
                }
                fine.push_strand(&pts)
                    .expect("points between finite points are finite");
            }
            fine
        });
        let hair = fine.as_ref().unwrap_or(input.hair);
        let world = hair.points().to_vec();
        let cells: Vec<Vec3> = world.iter().map(|&p| frame.to_cells(p)).collect();
        let mut strand = Vec::with_capacity(cells.len());
        for (s, st) in hair.strands().enumerate() {
            strand.extend(std::iter::repeat_n(s as u32, st.len()));
        }
        let radius = 0.5 * input.fiber.width() / frame.ds;
        let offsets_of_strands = hair.offsets();
        // Segment starts: every point but the last of each strand.
        let seg_starts = || {
            (0..hair.strand_count()).flat_map(move |s| {
                offsets_of_strands[s]..offsets_of_strands[s + 1].saturating_sub(1)
            })
        };
        // Across the rays a fan's fiber is wider in cells nearer the source.
        let radius_at = |a: Vec3, b: Vec3| match &frame.fan {
            None => radius,
            Some(f) => {
                let x = f.start.x + a.x.min(b.x).max(0.0) * frame.ds;
                0.5 * input.fiber.width() / (x.max(1e-30) * f.du)
            }
        };
        let columns = |s: u32| {
            let (a, b) = (cells[s as usize], cells[s as usize + 1]);
            let r = radius_at(a, b);
            let lo = a.min(b) - r;
            let hi = a.max(b) + r;
            let j = (lo.y.max(0.0) as i32).min(n - 1)..=(hi.y.max(0.0) as i32).min(n - 1);
            let k = (lo.z.max(0.0) as i32).min(n - 1)..=(hi.z.max(0.0) as i32).min(n - 1);
            let outside = hi.y < 0.0 || hi.z < 0.0 || lo.y >= n as f32 || lo.z >= n as f32;
            (j, k, outside)
        };
        let mut start = vec![0u32; (n * n) as usize + 1];
        let mut stats = FillStats::default();
        for s in seg_starts() {
            let (js, ks, outside) = columns(s);
            if outside {
                stats.out_of_map += 1;
                continue;
            }
            stats.samples += 1;
            for k in ks {
                for j in js.clone() {
                    start[(k * n + j) as usize + 1] += 1;
                }
            }
        }
        for i in 0..(n * n) as usize {
            start[i + 1] += start[i];
        }
        let mut fill = start.clone();
        let mut segs = vec![0u32; start[(n * n) as usize] as usize];
        for s in seg_starts() {
            let (js, ks, outside) = columns(s);
            if outside {
                continue;
            }
            for k in ks {
                for j in js.clone() {
                    let at = &mut fill[(k * n + j) as usize];
                    segs[*at as usize] = s;
                    *at += 1;
                }
            }
        }
        Ok(SegmentBins {
            frame,
            cells,
            world,
            strand,
            start,
            segs,
            lo: Vec::new(),
            extent: Vec::new(),
            radius,
            stats,
        })
    }

    /// The column `(j, k)` of the grid a ray from `o` (world) runs in; a
    /// ray beside the grid, in the edge column (which lists every capsule
    /// that reaches past it, so a ray there can still graze a fiber).
    pub(crate) fn column_of(&self, o: Vec3) -> (i32, i32) {
        let c = self.frame.to_cells(o);
        let n = self.frame.n_cells as i32;
        let col = |v: f32| {
            if v.is_nan() {
                0
            } else {
                (v.max(0.0) as i32).min(n - 1)
            }
        };
        (col(c.y), col(c.z))
    }

    /// Orders each column's segments by where their capsule starts along
    /// the light, for [`Self::column_between`]. `margin`: the fiber's
    /// radius in cells along the light.
    pub(crate) fn order_by_depth(&mut self, margin: f32) {
        let cells = &self.cells;
        let range = |s: u32| {
            let (a, b) = (cells[s as usize].x, cells[s as usize + 1].x);
            (a.min(b) - margin, a.max(b) + margin)
        };
        // Sort keys: the start's bits made to order as the numbers do (a
        // finite f32's bits, flipped for negatives), then the segment, so
        // the order is total and the same on any number of threads.
        let key = |s: u32| {
            let b = range(s).0.to_bits();
            let b = if b >> 31 == 1 { !b } else { b | 1 << 31 };
            (u64::from(b) << 32) | u64::from(s)
        };
        let mut entries: Vec<u64> = self.segs.par_iter().map(|&s| key(s)).collect();
        let n = self.frame.n_cells as usize;
        // One task per row of columns.
        let mut rows = Vec::with_capacity(n);
        let mut rest = &mut entries[..];
        for k in 0..n {
            let len = (self.start[(k + 1) * n] - self.start[k * n]) as usize;
            let (row, tail) = rest.split_at_mut(len);
            rows.push((k, row));
            rest = tail;
        }
        let start = &self.start;
        let extent: Vec<Vec<f32>> = rows
            .into_par_iter()
            .map(|(k, row)| {
                let base = start[k * n];
                (0..n)
                    .map(|j| {
                        let col = &mut row[(start[k * n + j] - base) as usize
                            ..(start[k * n + j + 1] - base) as usize];
                        col.sort_unstable();
                        col.iter()
                            .map(|&e| {
                                let (lo, hi) = range(e as u32);
                                hi - lo
                            })
                            .fold(0.0, f32::max)
                    })
                    .collect()
            })
            .collect();
        self.extent = extent.concat();
        self.segs = entries.iter().map(|&e| e as u32).collect();
        self.lo = self.segs.iter().map(|&s| range(s).0).collect();
    }

    /// The segments of column `(j, k)` whose capsule may reach slice
    /// coordinates `x0..=x1` (cells) along the light; after
    /// [`Self::order_by_depth`].
    pub(crate) fn column_between(&self, j: i32, k: i32, x0: f32, x1: f32) -> &[u32] {
        let col = (k * self.frame.n_cells as i32 + j) as usize;
        let (a, b) = (self.start[col] as usize, self.start[col + 1] as usize);
        let lo = &self.lo[a..b];
        // A capsule starting before x0 - extent ends before x0.
        let first = lo.partition_point(|&x| x < x0 - self.extent[col]);
        let end = lo.partition_point(|&x| x <= x1);
        &self.segs[a + first..a + end.max(first)]
    }

    /// The segments listed in column `(j, k)` (inside the grid), ascending.
    pub(crate) fn column(&self, j: i32, k: i32) -> &[u32] {
        let col = (k * self.frame.n_cells as i32 + j) as usize;
        &self.segs[self.start[col] as usize..self.start[col + 1] as usize]
    }
}
