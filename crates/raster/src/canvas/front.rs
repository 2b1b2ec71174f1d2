//! The nearest fragments of a pixel, kept whole and composited front to
//! back (a k-buffer, as TressFX keeps per-pixel lists of the nearest hair
//! fragments); the fragments behind them are blended order-independently
//! ([`super::Sums`]).
//!
//! Weighted blended transparency mixes every fragment of a pixel in
//! proportion to its coverage, whatever its depth: in dense hair the
//! shadowed fibers at the back show through the lit ones in front (a gauze
//! look, and shadows too dark). With the `K` nearest fragments composited
//! in depth order,
//!
//! ```text
//! C = sum_{i < K} c_i a_i prod_{j < i} (1 - a_j) + prod_{i < K} (1 - a_i) C_rest
//! ```
//!
//! with `C_rest` the blended rest over what lies behind.
//!
//! Exact whatever the split. Fragments are ordered by a total order (depth,
//! then colour, opacity and weight bits: two fragments equal in all of
//! them are interchangeable). Each group of strands keeps its own `K`
//! nearest while it is rasterized, the others going into its float sums in
//! strand order as before; groups' lists then merge into the `K` nearest of
//! their union, and a fragment a merge leaves out is rounded into the
//! exact sums on its own. Which fragments a merge leaves out does not
//! depend on the order of merges, so one canvas, many threads and many
//! workers give the same bytes.

use glam::{Vec3, Vec4};

use super::Sums;

/// The most nearest fragments a pixel keeps.
pub const MAX_NEAREST: usize = 16;

/// One hair fragment: its view depth, linear colour, opacity (coverage
/// times the strand's opacity) and depth weight.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Fragment {
    /// View depth, scene units (> 0).
    pub z: f32,
    /// Linear RGB (>= 0).
    pub color: Vec3,
    /// Opacity in (0, 1).
    pub alpha: f32,
    /// Depth weight of weighted blended transparency.
    pub weight: f32,
}

impl Fragment {
    /// A place no fragment is in yet.
    pub(super) const NONE: Fragment = Fragment {
        z: 0.0,
        color: Vec3::ZERO,
        alpha: 0.0,
        weight: 0.0,
    };

    /// The total order fragments are kept in: nearer first, then by the
    /// bits of the rest. Every field is finite and >= 0, so its bits
    /// order as its value.
    #[inline]
    fn key(&self) -> [u32; 6] {
        [
            self.z.to_bits(),
            self.color.x.to_bits(),
            self.color.y.to_bits(),
            self.color.z.to_bits(),
            self.alpha.to_bits(),
            self.weight.to_bits(),
        ]
    }

    /// Whether `self` comes before `other`.
    #[inline]
    pub fn precedes(&self, other: &Fragment) -> bool {
        // Depths nearly always differ: the rest of the key only for ties.
        let (a, b) = (self.z.to_bits(), other.z.to_bits());
        if a != b {
            return a < b;
        }
        self.key() < other.key()
    }

    /// The fragment's weighted blended sums: colour times alpha times
    /// weight, alpha times weight; and `1 - alpha`.
    #[inline]
    pub(super) fn blended(&self) -> (Vec4, f32) {
        (
            self.color.extend(1.0) * (self.alpha * self.weight),
            1.0 - self.alpha,
        )
    }

    /// Whether every field is in its range.
    pub fn is_valid(&self) -> bool {
        self.z.is_finite()
            && self.z > 0.0
            && self.color.is_finite()
            && self.color.cmpge(Vec3::ZERO).all()
            && self.alpha > 0.0
            && self.alpha < 1.0
            && self.weight.is_finite()
            && self.weight > 0.0
    }
}

/// Puts `f` into `list` (sorted, `*len` of `k` used), keeping the `k`
/// nearest: returns the fragment left out, if any (`f` itself, or the
/// farthest of the list).
#[inline]
pub(super) fn insert(
    list: &mut [Fragment],
    len: &mut u8,
    k: usize,
    f: Fragment,
) -> Option<Fragment> {
    let n = *len as usize;
    if n == k && (k == 0 || !f.precedes(&list[k - 1])) {
        return Some(f);
    }
    let out = (n == k).then(|| list[k - 1]);
    let keep = n.min(k - 1);
    // Shift the farther ones back by one.
    let mut i = keep;
    while i > 0 && f.precedes(&list[i - 1]) {
        list[i] = list[i - 1];
        i -= 1;
    }
    list[i] = f;
    if n < k {
        *len += 1;
    }
    out
}

/// Merges `other` (sorted, at most [`MAX_NEAREST`]) into `list` (sorted,
/// `*len` of `k` used), keeping the `k` nearest of both; every fragment
/// left out is rounded into `sums` on its own.
pub(super) fn merge(
    list: &mut [Fragment],
    len: &mut u8,
    k: usize,
    other: &[Fragment],
    sums: &mut Sums,
) {
    let n = *len as usize;
    debug_assert!(other.len() <= MAX_NEAREST && n <= k);
    if other.is_empty() {
        return;
    }
    // The first list a pixel gets (most pixels get one group's): a copy.
    if n == 0 && other.len() <= k {
        list[..other.len()].copy_from_slice(other);
        *len = other.len() as u8;
        return;
    }
    // Both lists in order, then the nearest `k` kept.
    let mut all = [Fragment::NONE; 2 * MAX_NEAREST];
    let (mut i, mut j, mut o) = (0, 0, 0);
    while i < n && j < other.len() {
        if other[j].precedes(&list[i]) {
            all[o] = other[j];
            j += 1;
        } else {
            all[o] = list[i];
            i += 1;
        }
        o += 1;
    }
    for f in list[i..n].iter().chain(&other[j..]) {
        all[o] = *f;
        o += 1;
    }
    let keep = o.min(k);
    list[..keep].copy_from_slice(&all[..keep]);
    *len = keep as u8;
    for f in &all[keep..o] {
        let (rgbw, reveal) = f.blended();
        sums.fold(rgbw, reveal);
    }
}

/// The pixel's colour: `front` (sorted, nearest first) over the blended
/// rest `sums` over `base`.
#[inline]
pub(super) fn composite(front: &[Fragment], sums: Option<&Sums>, base: Vec3) -> Vec3 {
    let behind = sums.map_or(base, |s| s.over(base));
    let mut c = Vec3::ZERO;
    let mut t = 1.0f32;
    for f in front {
        c += f.color * (f.alpha * t);
        t *= 1.0 - f.alpha;
    }
    c + behind * t
}

/// The fraction of what lies behind `front` (and `sums`, behind it) that
/// they let through: `prod_i (1 - a_i)` times the sums' reveal.
#[inline]
pub(super) fn reveal(front: &[Fragment], sums: Option<&Sums>) -> f32 {
    let behind = sums.map_or(1.0, Sums::reveal);
    front.iter().fold(behind, |t, f| t * (1.0 - f.alpha))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frag(z: f32, a: f32) -> Fragment {
        Fragment {
            z,
            color: Vec3::splat(z),
            alpha: a,
            weight: 1.0,
        }
    }

    #[test]
    fn insert_keeps_the_nearest_in_order() {
        let mut list = [frag(0.0, 0.5); 3];
        let mut len = 0u8;
        for z in [5.0, 2.0, 9.0] {
            assert_eq!(insert(&mut list, &mut len, 3, frag(z, 0.5)), None);
        }
        assert_eq!(list.map(|f| f.z), [2.0, 5.0, 9.0]);
        // A nearer one pushes the farthest out; a farther one is left out.
        assert_eq!(
            insert(&mut list, &mut len, 3, frag(1.0, 0.5)).unwrap().z,
            9.0
        );
        assert_eq!(
            insert(&mut list, &mut len, 3, frag(7.0, 0.5)).unwrap().z,
            7.0
        );
        assert_eq!(list.map(|f| f.z), [1.0, 2.0, 5.0]);
        assert_eq!(len, 3);
        // K = 0 keeps nothing.
        let mut none: [Fragment; 0] = [];
        let mut zero = 0u8;
        assert!(insert(&mut none, &mut zero, 0, frag(1.0, 0.5)).is_some());
    }

    #[test]
    fn merging_in_any_order_keeps_the_same_fragments_and_sums() {
        // Three groups' lists of a pixel, merged in every order.
        let groups: Vec<Vec<Fragment>> = vec![
            vec![frag(1.0, 0.3), frag(4.0, 0.2), frag(6.0, 0.1)],
            vec![frag(2.0, 0.4), frag(3.0, 0.5)],
            vec![frag(0.5, 0.2), frag(4.0, 0.6), frag(8.0, 0.7)],
        ];
        let orders = [[0, 1, 2], [2, 1, 0], [1, 2, 0], [1, 0, 2]];
        let mut seen = None;
        for order in orders {
            let mut list = [frag(0.0, 0.5); 4];
            let mut len = 0u8;
            let mut sums = Sums::ZERO;
            for g in order {
                merge(&mut list, &mut len, 4, &groups[g], &mut sums);
            }
            let got = (list, len, sums);
            assert_eq!(list.map(|f| f.z), [0.5, 1.0, 2.0, 3.0]);
            if let Some(s) = &seen {
                assert_eq!(s, &got);
            }
            seen = Some(got);
        }
    }

    #[test]
    fn front_to_back_composites_as_over() {
        // Red at half opacity over green at half over a blue base: a
        // quarter green, a half red, a quarter blue.
        let red = Fragment {
            z: 1.0,
            color: Vec3::X,
            alpha: 0.5,
            weight: 1.0,
        };
        let green = Fragment {
            z: 2.0,
            color: Vec3::Y,
            alpha: 0.5,
            weight: 1.0,
        };
        let c = composite(&[red, green], None, Vec3::Z);
        assert!((c - Vec3::new(0.5, 0.25, 0.25)).length() < 1e-6, "{c}");
    }
}
