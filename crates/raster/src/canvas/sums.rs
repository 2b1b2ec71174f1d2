//! Exact per-pixel hair sums: what makes a picture the same bytes however
//! its strands are split across threads, workers or calls.
//!
//! A group of strands is rasterized in floating point, in strand order,
//! into per-pixel sums of weighted blended transparency: colour times
//! alpha times depth weight, alpha times weight, and the product of
//! `1 - alpha`. When the group is done, each pixel it touched is rounded
//! once into integers: colour and weight in units of 2^-24, and the
//! absorbance `A = -log2(prod (1 - alpha))` in units of 2^-16. Integers add
//! up to the same value in any order, so groups can be rasterized on any
//! thread or machine and added anywhere; the picture is composited from
//! the integers alone.

use std::sync::OnceLock;

use glam::{DVec4, Vec3, Vec4};

/// Units per unit of colour and weight sums: 2^24, so that a float sum of
/// 1 or more converts without rounding (f32 has 24 bits of mantissa).
const SUM_SCALE: f32 = (1u32 << 24) as f32;
/// The largest float sum a group adds at a pixel (2^26: 6.7e7, where a
/// real pixel's sums stay below 1e4): 2^50 units, so that 2^13 groups add
/// up without overflow.
const MAX_GROUP_SUM: f32 = (1u32 << 26) as f32;
/// Units per unit of absorbance: 2^16 (the revealed fraction `2^-A` to
/// a relative 1.1e-5).
const ABSORB_SHIFT: u32 = 16;
/// Absorbance beyond which nothing shows through: `2^-126` is the smallest
/// normal f32, a millionth of a millionth of an 8-bit level.
const MAX_ABSORB: u64 = 126 << ABSORB_SHIFT;

/// One pixel's hair sums in exact integers: `rgbw` holds colour times
/// alpha times weight (`x`, `y`, `z`) and alpha times weight (`w`), in
/// units of 2^-24; `absorb` the absorbance in units of 2^-16.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Sums {
    /// Colour times alpha times weight (red, green, blue) and alpha times weight, units of 2^-24.
    pub rgbw: [i64; 4],
    /// Absorbance `-log2 prod(1 - alpha)`, units of 2^-16.
    pub absorb: u64,
}

impl Sums {
    /// No hair.
    pub const ZERO: Sums = Sums {
        rgbw: [0; 4],
        absorb: 0,
    };

    /// Whether no hair touched the pixel (or only hair too faint to count).
    pub fn is_zero(&self) -> bool {
        *self == Sums::ZERO
    }

    /// Adds one group's float sums at a pixel: `rgbw` (every lane >= 0)
    /// and `reveal`, the product of `1 - alpha`, each rounded once.
    #[inline]
    pub(super) fn fold(&mut self, rgbw: Vec4, reveal: f32) {
        // `v + 2^52` holds `v` rounded to the nearest integer in the low
        // bits of its mantissa, for 0 <= v < 2^51: a conversion with no
        // branch, two lanes to an instruction. Clamping first bounds every
        // term (NaN goes to 0), so the sums cannot overflow.
        const MAGIC: f64 = (1u64 << 52) as f64;
        let v = rgbw
            .clamp(Vec4::ZERO, Vec4::splat(MAX_GROUP_SUM))
            .as_dvec4()
            * f64::from(SUM_SCALE)
            + DVec4::splat(MAGIC);
        for (a, b) in self.rgbw.iter_mut().zip(v.to_array()) {
            *a = a.wrapping_add((b.to_bits() - MAGIC.to_bits()) as i64);
        }
        self.absorb = self.absorb.wrapping_add(absorb_units(reveal));
    }

    /// Adds `other`: exact, and the same in any order.
    #[inline]
    pub fn add(&mut self, other: &Sums) {
        for (a, b) in self.rgbw.iter_mut().zip(other.rgbw) {
            *a = a.wrapping_add(b);
        }
        self.absorb = self.absorb.wrapping_add(other.absorb);
    }

    /// The fraction of what lies behind that these fragments let through:
    /// `2^-A`, 1 without any.
    #[inline]
    pub fn reveal(&self) -> f32 {
        if self.rgbw[3] <= 0 {
            return 1.0;
        }
        revealed(self.absorb)
    }

    /// The pixel's colour over `base`: the weighted mean hair colour
    /// `rgb / w` covering `1 - 2^-A` of it.
    #[inline]
    pub fn over(&self, base: Vec3) -> Vec3 {
        let w = self.rgbw[3];
        if w <= 0 {
            return base;
        }
        // Integers to floats, and one division: correctly rounded IEEE
        // operations, the same on every machine.
        let [r, g, b, _] = self.rgbw.map(|v| v as f32);
        let hair = Vec3::new(r, g, b) / w as f32;
        let reveal = revealed(self.absorb);
        hair * (1.0 - reveal) + base * reveal
    }
}

/// `-log2(reveal)` in units of 2^-16, for `reveal` in [0, 1] (NaN and
/// anything below the smallest normal float count as nothing revealed).
///
/// From the float's bits: `reveal = m 2^e` with `m` in `[1, 2)`, and
/// `log2(m)` interpolated linearly in a table of 257 values (within 2.2e-6,
/// a seventh of a unit): table lookups and arithmetic only, so every
/// machine gives the same bits, where libm's `log2f` may differ between
/// systems.
#[inline]
fn absorb_units(reveal: f32) -> u64 {
    if reveal >= 1.0 {
        return 0;
    }
    // NaN fails this test too.
    if reveal.partial_cmp(&f32::MIN_POSITIVE) != Some(std::cmp::Ordering::Greater) {
        return MAX_ABSORB;
    }
    let bits = reveal.to_bits();
    // reveal < 1: e >= 1 below.
    let e = 127 - ((bits >> 23) & 0xff) as i64;
    let mantissa = bits & 0x007f_ffff;
    let (i, t) = (
        (mantissa >> 15) as usize,
        (mantissa & 0x7fff) as f32 * (1.0 / 32768.0),
    );
    let table = log2_table();
    // log2(m) in units, within [0, 2^16]: rounded by adding 2^23 (the low
    // bits of the float then hold the integer).
    let l = (table[i] + t * (table[i + 1] - table[i])) * (1u32 << ABSORB_SHIFT) as f32;
    const MAGIC: f32 = (1u32 << 23) as f32;
    let l = i64::from((l + MAGIC).to_bits() - MAGIC.to_bits());
    ((e << ABSORB_SHIFT) - l).clamp(0, MAX_ABSORB as i64) as u64
}

/// `log2(1 + i / 256)` for `i` in `0..=256`.
fn log2_table() -> &'static [f32; 257] {
    static TABLE: OnceLock<[f32; 257]> = OnceLock::new();
    TABLE.get_or_init(|| {
        let mut t = [0.0; 257];
        for (i, v) in t.iter_mut().enumerate() {
            *v = (1.0 + i as f64 / 256.0).log2() as f32;
        }
        t
    })
}

/// `2^(-units / 2^16)`: the fraction of the background the hair reveals.
#[inline]
fn revealed(units: u64) -> f32 {
    if units >= MAX_ABSORB {
        return 0.0;
    }
    let [coarse, fine] = exp2_tables();
    let whole = (units >> ABSORB_SHIFT) as u32;
    let frac = units as usize & 0xffff;
    // 2^-whole exactly, times 2^-(frac / 2^16) from two tables of 256.
    f32::from_bits((127 - whole) << 23) * (coarse[frac >> 8] * fine[frac & 0xff])
}

/// `2^(-h / 256)` and `2^(-l / 65536)` for `h, l` in `0..256`.
fn exp2_tables() -> &'static [[f32; 256]; 2] {
    static TABLES: OnceLock<[[f32; 256]; 2]> = OnceLock::new();
    TABLES.get_or_init(|| {
        let table = |step: f64| std::array::from_fn(|i| (-(i as f64) * step).exp2() as f32);
        [table(1.0 / 256.0), table(1.0 / 65536.0)]
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn absorbance_is_within_a_unit_of_the_true_value() {
        let mut x = 1.0f32;
        while x > 1e-37 {
            let exact = -f64::from(x).log2() * 65536.0;
            let got = absorb_units(x) as f64;
            // Rounding (half a unit) and the polynomial (a seventh of one).
            assert!((got - exact).abs() <= 0.7, "reveal {x}: {got} vs {exact}");
            x *= 0.937;
        }
        assert_eq!(absorb_units(1.0), 0);
        assert_eq!(absorb_units(0.5), 65536);
    }

    #[test]
    fn absorbance_round_trips_to_the_revealed_fraction() {
        for reveal in [1.0f32, 0.999, 0.9, 0.5, 0.2, 1e-3, 1e-9, 1e-30] {
            let back = revealed(absorb_units(reveal));
            assert!((back - reveal).abs() <= 2e-5 * reveal, "{reveal} -> {back}");
        }
        assert_eq!(revealed(absorb_units(0.0)), 0.0);
        assert_eq!(revealed(absorb_units(f32::NAN)), 0.0);
        // Absorbances add: two layers of 0.5 reveal a quarter.
        let a = absorb_units(0.5);
        assert!((revealed(2 * a) - 0.25).abs() < 1e-6);
    }

    #[test]
    fn sums_add_in_any_order_and_composite_the_mean_colour() {
        let mut parts = Vec::new();
        for i in 0..5 {
            let mut s = Sums::ZERO;
            let f = i as f32 * 0.1;
            s.fold(Vec4::new(0.3 + f, 0.2, 0.1, 0.7 + f), 0.4 + f);
            parts.push(s);
        }
        let mut forward = Sums::ZERO;
        parts.iter().for_each(|p| forward.add(p));
        let mut backward = Sums::ZERO;
        parts.iter().rev().for_each(|p| backward.add(p));
        assert_eq!(forward, backward);
        // One fold: colour rgb / w covering 1 - reveal of the base.
        let mut one = Sums::ZERO;
        one.fold(Vec4::new(0.25, 0.5, 0.125, 0.5), 0.25);
        let c = one.over(Vec3::ONE);
        let expect = Vec3::new(0.5, 1.0, 0.25) * 0.75 + Vec3::ONE * 0.25;
        assert!((c - expect).abs().max_element() < 1e-5, "{c} vs {expect}");
        assert_eq!(Sums::ZERO.over(Vec3::X), Vec3::X);
    }
}
