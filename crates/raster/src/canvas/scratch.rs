//! What one thread keeps while it rasterizes bands of rows: float sums
//! and nearest fragments of the group being drawn, and exact sums and
//! nearest fragments of the groups before it, at the pixels they reached.

use super::front;
use super::{Acc, Fragment, Sums};

/// What one thread keeps between the bands it draws: the float sums of
/// the group being rasterized (`acc`), and exact sums of the groups before
/// it, kept only at the pixels some group reached: `slot` names a pixel's
/// place in `sums`, `marked` has a bit for each (a word per 64 pixels of a
/// row). A band's few thousand exact sums stay in cache where a full band
/// of them would not.
#[derive(Debug, Default)]
pub(super) struct Scratch {
    pub(super) acc: Vec<Acc>,
    pub(super) slot: Vec<u32>,
    pub(super) sums: Vec<Sums>,
    pub(super) marked: Vec<u64>,
    /// Words of `marked` per row.
    pub(super) words: usize,
    /// Nearest fragments kept per pixel.
    pub(super) k: usize,
    /// The group being rasterized: its `k` nearest fragments per band
    /// pixel (how many, and the farthest's depth: in `acc`).
    pub(super) near: Vec<Fragment>,
    /// Per slot of `sums`, the `k` nearest of the groups before it.
    pub(super) fronts: Vec<Fragment>,
    pub(super) front_len: Vec<u8>,
}

/// No exact sums at a pixel yet.
pub(super) const NO_SLOT: u32 = u32::MAX;

/// A fragment slot no fragment is in yet.
const NO_FRAGMENT: Fragment = Fragment::NONE;

impl Scratch {
    /// Sized for `rows` rows of `w` pixels keeping `k` nearest fragments,
    /// everything empty.
    pub(super) fn ready(&mut self, rows: usize, w: usize, k: usize) {
        let pixels = rows * w;
        if self.acc.len() < pixels {
            self.acc.resize(pixels, Acc::EMPTY);
            self.slot.resize(pixels, NO_SLOT);
        }
        if self.near.len() < pixels * k {
            self.near.resize(pixels * k, NO_FRAGMENT);
        }
        self.k = k;
        self.words = w.div_ceil(64);
        if self.marked.len() < rows * self.words {
            self.marked.resize(rows * self.words, 0);
        }
        self.sums.clear();
        self.fronts.clear();
        self.front_len.clear();
    }

    /// The exact sums' slot of band pixel `px`, made empty if it had none.
    #[inline]
    pub(super) fn slot_at(&mut self, px: usize) -> usize {
        let s = self.slot[px];
        if s != NO_SLOT {
            return s as usize;
        }
        self.slot[px] = self.sums.len() as u32;
        self.sums.push(Sums::ZERO);
        self.front_len.push(0);
        self.fronts.extend(std::iter::repeat_n(NO_FRAGMENT, self.k));
        self.sums.len() - 1
    }

    /// [`Self::slot_at`] of pixel `x` of row `r` (band pixel `px`), marked
    /// as touched.
    #[inline]
    pub(super) fn slot_of(&mut self, px: usize, r: usize, x: usize) -> usize {
        if self.slot[px] == NO_SLOT {
            self.marked[r * self.words + x / 64] |= 1 << (x % 64);
        }
        self.slot_at(px)
    }

    /// Merges `front` (sorted) into slot `s`'s nearest fragments; those
    /// left out go into its sums, each on its own.
    #[inline]
    pub(super) fn merge_front(&mut self, s: usize, front: &[Fragment]) {
        let k = self.k;
        front::merge(
            &mut self.fronts[s * k..(s + 1) * k],
            &mut self.front_len[s],
            k,
            front,
            &mut self.sums[s],
        );
    }

    /// Folds band pixel `px`'s group (its float sums, rounded once, and
    /// its nearest fragments) into slot `s`.
    #[inline]
    pub(super) fn fold_pixel(&mut self, px: usize, s: usize) {
        let cell = &mut self.acc[px];
        if cell.rgbw.w != 0.0 {
            self.sums[s].fold(cell.rgbw, cell.reveal);
            (cell.rgbw, cell.reveal) = (Acc::EMPTY.rgbw, Acc::EMPTY.reveal);
        }
        let n = std::mem::take(&mut cell.len) as usize;
        if n > 0 {
            cell.far = f32::INFINITY;
            let k = self.k;
            // Fields borrowed apart: the group's list merges in place.
            front::merge(
                &mut self.fronts[s * k..(s + 1) * k],
                &mut self.front_len[s],
                k,
                &self.near[px * k..px * k + n],
                &mut self.sums[s],
            );
        }
    }

    /// Whether band pixel `px` holds anything of the group being
    /// rasterized.
    #[inline]
    pub(super) fn touched(&self, px: usize) -> bool {
        self.acc[px].rgbw.w != 0.0 || self.acc[px].len != 0
    }

    /// Rounds the float sums of columns `x0..x1` of rows `0..rows` (a band
    /// `w` wide) into the exact ones, merges the group's nearest
    /// fragments, and empties them.
    pub(super) fn fold(&mut self, rows: usize, w: usize, [x0, x1]: [u32; 2]) {
        let (x0, x1) = (x0 as usize, (x1 as usize).min(w));
        for r in 0..rows {
            for x in x0..x1 {
                let px = r * w + x;
                // w > 0 wherever a fragment landed (alpha > 0, weight >= 1e-3).
                if self.touched(px) {
                    let s = self.slot_of(px, r, x);
                    self.fold_pixel(px, s);
                }
            }
        }
    }

    /// Adds exact sums and nearest fragments at pixel `x` of row `r`
    /// (band pixel `px`).
    pub(super) fn add(&mut self, px: usize, r: usize, x: usize, sums: &Sums, front: &[Fragment]) {
        let s = self.slot_of(px, r, x);
        self.sums[s].add(sums);
        self.merge_front(s, front);
    }

    /// Takes everything at band pixel `px` into its slot, leaving the
    /// pixel empty: the slot, or `None` where no hair reached it.
    #[inline]
    pub(super) fn take(&mut self, px: usize) -> Option<usize> {
        let had = self.slot[px] != NO_SLOT;
        if !had && !self.touched(px) {
            return None;
        }
        let s = self.slot_at(px);
        self.fold_pixel(px, s);
        self.slot[px] = NO_SLOT;
        Some(s)
    }

    /// Slot `s`'s nearest fragments.
    #[inline]
    pub(super) fn front(&self, s: usize) -> &[Fragment] {
        &self.fronts[s * self.k..s * self.k + self.front_len[s] as usize]
    }
}
