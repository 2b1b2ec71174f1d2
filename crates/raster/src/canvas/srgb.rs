//! Linear colour to 8-bit sRGB, through a table.

use glam::Vec3;

/// Steps of the linear-to-sRGB table: fine enough that every 8-bit output
/// is reached exactly as the formula would round it, within one level.
const SRGB_STEPS: usize = 8192;

/// Linear to 8-bit sRGB at `SRGB_STEPS + 1` evenly spaced linear values
/// (`powf` per channel and pixel cost more than the rest of the resolve).
pub(super) fn srgb_table() -> &'static [u8] {
    static TABLE: std::sync::OnceLock<Vec<u8>> = std::sync::OnceLock::new();
    TABLE.get_or_init(|| {
        (0..=SRGB_STEPS)
            .map(|i| srgb8(i as f32 / SRGB_STEPS as f32))
            .collect()
    })
}

/// A linear colour as the 8-bit sRGB pixel [`Canvas::resolve`](super::Canvas::resolve) writes for it.
pub fn to_srgb8(c: Vec3) -> [u8; 3] {
    encode(srgb_table(), c)
}

#[inline]
pub(super) fn encode(lut: &[u8], c: Vec3) -> [u8; 3] {
    let mut px = [0u8; 3];
    for (k, p) in px.iter_mut().enumerate() {
        // The table has SRGB_STEPS + 1 entries over [0, 1].
        let v = if c[k].is_finite() {
            c[k].clamp(0.0, 1.0)
        } else {
            0.0
        };
        // v in [0, 1]: the index fits i32 (a cheaper conversion than to usize).
        *p = lut[(v * SRGB_STEPS as f32 + 0.5) as i32 as usize];
    }
    px
}

/// Linear [0, 1] to 8-bit sRGB.
fn srgb8(v: f32) -> u8 {
    let v = if v.is_finite() {
        v.clamp(0.0, 1.0)
    } else {
        0.0
    };
    let s = if v <= 0.003_130_8 {
        12.92 * v
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    };
    (s * 255.0 + 0.5) as u8
}
