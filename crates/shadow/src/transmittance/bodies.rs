//! Lookups that leave opaque bodies out of the map: the hair's own depth
//! along a ray ([`Transmittance::hair_depth_between`]) and at a point of
//! a body's surface ([`Transmittance::surface_depth`]).

use glam::Vec3;
use rayon::prelude::*;

use super::{Lookup, NO_BODY, Transmittance};
use crate::{BODY_CELL_DEPTH, LIT_EDGE_OFFSET, OPAQUE_DEPTH};

impl Transmittance {
    /// The optical depth the hair alone adds to the light's ray from `a`
    /// on to `b` (further from the light on the same ray), filtered as
    /// [`Self::optical_depth`] is at `a`: in each column the lookup blends,
    /// what its cells between the two add, less the deposit of any opaque
    /// body that entered one ([`OPAQUE_DEPTH`] out of a cell whose depth
    /// grows by more than [`BODY_CELL_DEPTH`]; the hair in that cell
    /// stays, spread over it). The extinction of the hair
    /// about a body (the head's own light, which it sends out through
    /// that hair), which [`Self::optical_depth`] mixes with the body's
    /// deposit. 0 where `b` is no further than `a`.
    pub fn hair_depth_between(&self, a: Vec3, b: Vec3, trilinear: bool) -> f32 {
        debug_assert!(a.is_finite() && b.is_finite());
        let at = Lookup::at(&self.frame, a, trilinear);
        let (x1, x2) = (at.x, Lookup::at(&self.frame, b, trilinear).x);
        self.blend(&at, trilinear, |j, k| self.column_hair(j, k, x1, x2))
    }

    /// Optical depth at a point `p` on the surface of an opaque body
    /// deposited in the map, `off` being where its lookup of the map is
    /// clear of the body's own deposit (off the surface, along its
    /// normal; the engine's `off_surface`):
    ///
    /// ```text
    /// D = D_body(off) + D_hair(p)
    /// ```
    ///
    /// `D_body(off)` is what opaque bodies add in front of `off`, read as
    /// [`Self::transmittance_at_drawn`] reads (a body's shadow on itself:
    /// a chin's on the neck); `D_hair(p)` the hair's own depth along
    /// `p`'s ray down to the surface, every body's entry left out as
    /// [`Self::hair_depth_between`] leaves it, and the hair of the cell
    /// the surface enters counted whole (inside a body there is none, so
    /// all of it lies on the surface, in front of `p`). Read at `off`
    /// alone, hair lying on the body less deep than `off` is high was
    /// behind the lookup: under the hair on a head, the head got almost
    /// all of its light.
    pub fn surface_depth(&self, p: Vec3, off: Vec3, trilinear: bool) -> f32 {
        debug_assert!(p.is_finite() && off.is_finite());
        let c = self.frame.to_cells(off);
        let at = Lookup::of_cells(
            &self.frame,
            Vec3::new(c.x - LIT_EDGE_OFFSET, c.y, c.z),
            trilinear,
        );
        let x = if trilinear { at.x } else { at.centre };
        let body = self.blend(&at, trilinear, |j, k| {
            let total = self.column_depth(j, k, x);
            (total - self.column_hair(j, k, f32::NEG_INFINITY, x)).max(0.0)
        });
        let at = Lookup::at(&self.frame, p, trilinear);
        let hair = self.blend(&at, trilinear, |j, k| {
            self.column_hair(j, k, f32::NEG_INFINITY, at.x + 1.0)
        });
        body + hair
    }

    /// [`Self::bodies`], found on first use: each column's cells in turn
    /// until one grows by more than [`BODY_CELL_DEPTH`].
    fn bodies(&self) -> &[u32] {
        self.bodies.get_or_init(|| {
            self.cols
                .par_iter()
                .map(|c| {
                    if c.front.is_infinite() {
                        return NO_BODY;
                    }
                    let cells = &self.depth[c.start as usize..=(c.start + c.last) as usize];
                    let mut before = 0.0;
                    for (i, &d) in cells.iter().enumerate() {
                        if d - before > BODY_CELL_DEPTH {
                            return i as u32;
                        }
                        before = d;
                    }
                    NO_BODY
                })
                .collect()
        })
    }

    /// What the hair of column `c` adds between slice coordinates `x1` and
    /// `x2` (see [`Self::hair_depth_between`]): each cell's growth, linear
    /// within it as [`Self::column_depth`] reads it, for the part of the
    /// cell between the two.
    fn column_hair(&self, j: i32, k: i32, x1: f32, x2: f32) -> f32 {
        let at = self.col_index(j, k);
        let c = self.cols[at];
        let x1 = x1.max(c.front);
        if x2 <= x1 {
            return 0.0;
        }
        // In front of the first body's entry cell the hair is all there
        // is: the depth's own difference.
        let body = self.bodies()[at];
        let entry = if body == NO_BODY {
            f32::INFINITY
        } else {
            c.lo + body as f32
        };
        if x2 <= entry {
            return self.depth_of(c, x2) - self.depth_of(c, x1);
        }
        let (ahead, x1) = if x1 < entry {
            (self.depth_of(c, entry) - self.depth_of(c, x1), entry)
        } else {
            (0.0, x1)
        };
        // x1 >= front >= lo: the cells from x1's to x2's (none past the last).
        let first = (x1 - c.lo) as u32;
        let last = ((x2 - c.lo) as u32).min(c.last);
        let mut sum = ahead;
        for i in first..=last {
            let at = (c.start + i) as usize;
            // The first cell's hair fills [front, lo + 1).
            let (start, before) = if i == 0 {
                (c.front, 0.0)
            } else {
                (c.lo + i as f32, self.depth[at - 1])
            };
            let end = c.lo + i as f32 + 1.0;
            let grow = self.depth[at] - before;
            // A body's entry: its deposit out, the hair in the cell kept
            // (spread over the cell, as the hair of any cell is).
            let hair = if grow > BODY_CELL_DEPTH {
                (grow - OPAQUE_DEPTH).max(0.0)
            } else {
                grow
            };
            let (a, b) = (x1.max(start), x2.min(end));
            if b > a {
                sum += hair * (b - a) / (end - start).max(1e-6);
            }
        }
        sum
    }

    /// Transmittance `T = exp(-D)` at a point `p` on an opaque body's
    /// surface, its lookup moved off it to `off`: [`Self::surface_depth`].
    #[inline]
    pub fn surface_transmittance(&self, p: Vec3, off: Vec3, trilinear: bool) -> f32 {
        (-self.surface_depth(p, off, trilinear)).exp()
    }
}
