//! Anti-aliased lines: the fragments of a segment, four steps of its major
//! axis at a time.

use glam::{Vec3, Vec4};

/// One vertex of a line strip, in screen space: pixel position and view
/// depth, and its shaded linear colour.
#[derive(Debug, Clone, Copy)]
pub(super) struct ScreenVertex {
    pub(super) p: Vec3,
    pub(super) color: Vec3,
    /// Line width in pixels at this vertex.
    pub(super) width: f32,
    /// Depth weight of its fragments, `(depth_ref / z)^6` (see
    /// [`super::HairLook::depth_ref`]), clamped to [1e-3, 1e3].
    pub(super) weight: f32,
}

/// The fragments of an anti-aliased line from `a` to `b`: for every pixel
/// column (or row, along the major axis) whose centre lies in `[a, b)`, the
/// line's coverage of that step, `width * sqrt(1 + m^2)` pixels (the area of
/// a unit step of a line of slope `m`), split between the two pixels nearest
/// the line in proportion to distance (Wu's method). `emit(x, y, t,
/// coverage)` gets the pixel, the parameter along the line and the
/// coverage. Half-open, so strips cover each joint once.
#[cfg(test)]
fn line_fragments(a: ScreenVertex, b: ScreenVertex, mut emit: impl FnMut(i32, i32, f32, f32)) {
    let all = [i32::MIN, i32::MAX, i32::MIN, i32::MAX];
    let steep = is_steep(a, b);
    let mut each = |s: &Steps| {
        for l in 0..4 {
            let major = s.major + l as i32;
            for (row, share) in s.shares.iter().enumerate() {
                if share[l] > 0.0 {
                    let r = s.minor[l] + row as i32;
                    let (x, y) = if steep { (r, major) } else { (major, r) };
                    emit(x, y, s.t[l], s.cov[l] * share[l]);
                }
            }
        }
    };
    if steep {
        line_steps::<true>(a, b, all, &mut each);
    } else {
        line_steps::<false>(a, b, all, &mut each);
    }
}

/// `ceil(x)` as an integer, by truncation (`ceil` is a libm call on
/// baseline x86-64); saturating far outside the `i32` range.
#[inline]
pub(super) fn ceil_i32(x: f32) -> i32 {
    let c = x as i32;
    if (c as f32) < x {
        c.saturating_add(1)
    } else {
        c
    }
}

/// Four consecutive steps of a line along its major axis, lane `l` being
/// the pixel column (or row) `major + l`: the parameter `t` along the
/// line, the coverage `cov` of the step, and the two pixels across it,
/// `minor` and `minor + 1`, with their shares of the coverage (0 for a
/// pixel outside the clip, and for lanes past the line's last step).
#[derive(Debug, Clone, Copy)]
pub(super) struct Steps {
    pub(super) major: i32,
    pub(super) t: Vec4,
    pub(super) cov: Vec4,
    pub(super) minor: [i32; 4],
    pub(super) shares: [Vec4; 2],
}

/// Whether y is the major axis of the line from `a` to `b`.
#[inline]
pub(super) fn is_steep(a: ScreenVertex, b: ScreenVertex) -> bool {
    let d = b.p - a.p;
    d.y.abs() > d.x.abs()
}

/// [`line_fragments`] restricted to the pixels `x0..x1`, `y0..y1` of
/// `clip`, four steps at a time: `emit(steps)`, along y when `STEEP`
/// (which must be [`is_steep`]), else along x. The same fragments inside
/// the clip, and no work spent outside (a segment that reaches far off
/// screen costs only its visible steps). Each lane computes what one step
/// would on its own, with the same operations in the same order, so the
/// fragments do not depend on how steps are grouped.
#[inline(always)]
pub(super) fn line_steps<const STEEP: bool>(
    a: ScreenVertex,
    b: ScreenVertex,
    clip: [i32; 4],
    mut emit: impl FnMut(&Steps),
) {
    let d = b.p - a.p;
    let steep = STEEP;
    // Major axis u, minor axis v, and the clip along each.
    let (ua, va, du, dv, (u_lo, u_hi), (v_lo, v_hi)) = if steep {
        (
            a.p.y,
            a.p.x,
            d.y,
            d.x,
            (clip[2], clip[3]),
            (clip[0], clip[1]),
        )
    } else {
        (
            a.p.x,
            a.p.y,
            d.x,
            d.y,
            (clip[0], clip[1]),
            (clip[2], clip[3]),
        )
    };
    if du == 0.0 || !du.is_finite() || !dv.is_finite() {
        return;
    }
    let (u0, u1) = if du > 0.0 {
        (ua, ua + du)
    } else {
        (ua + du, ua)
    };
    let inv_du = 1.0 / du;
    if !inv_du.is_finite() {
        // Shorter than a float can invert: no pixel centre lies on it.
        return;
    }
    let m = dv * inv_du;
    let stretch = (1.0 + m * m).sqrt();
    // Pixel centres k + 0.5 in [u0, u1), within the clip.
    let mut first = ceil_i32(u0 - 0.5).max(u_lo);
    let mut last = ceil_i32(u1 - 0.5).min(u_hi);
    // A line wider than a pixel across its steps covers more than two
    // rows: its footprint is a box of its width (see `wide_steps`).
    let half = 0.5 * (a.width.max(b.width) * stretch).max(1.0);
    let wide = half > 0.5;
    // Minor rows r0 = floor(v - 0.5) and r0 + 1 reach the clip only where
    // v lies in [v_lo - 0.5, v_hi + 0.5) (a wide line's rows: `half`
    // instead of 0.5): the steps k where that holds, a step wider on each
    // side (v is clamped at the ends).
    if m != 0.0 {
        let k_at = |v: f32| ua + (v - va) / m - 0.5;
        let (ka, kb) = (k_at(v_lo as f32 - half), k_at(v_hi as f32 + half));
        let (lo, hi) = (ka.min(kb), ka.max(kb));
        if lo.is_finite() {
            first = first.max(ceil_i32(lo).saturating_sub(1));
        }
        if hi.is_finite() {
            last = last.min(ceil_i32(hi).saturating_add(1));
        }
    }
    let dw = b.width - a.width;
    // The clip across, and the steps' end, as floats: exact, as pixel
    // coordinates are far below 2^24.
    let (v_lo, v_hi, end) = (
        Vec4::splat(v_lo as f32),
        Vec4::splat(v_hi as f32),
        Vec4::splat(last as f32),
    );
    let mut k = first;
    while k < last {
        let ks = Vec4::splat(k as f32) + Vec4::new(0.0, 1.0, 2.0, 3.0);
        let t = ((ks + 0.5 - ua) * inv_du).clamp(Vec4::ZERO, Vec4::ONE);
        let v = Vec4::splat(va) + t * dv;
        let cov = (Vec4::splat(a.width) + t * dw) * stretch;
        if wide {
            let lane = ks.cmplt(end);
            wide_steps(k, t, v, cov, half, lane, (v_lo, v_hi), &mut emit);
            k = k.saturating_add(4);
            continue;
        }
        let vc = v - 0.5;
        let r0 = vc.floor();
        let f = vc - r0;
        let r1 = r0 + 1.0;
        let lane = ks.cmplt(end);
        let shares = [
            Vec4::select(lane & r0.cmpge(v_lo) & r0.cmplt(v_hi), 1.0 - f, Vec4::ZERO),
            Vec4::select(lane & r1.cmpge(v_lo) & r1.cmplt(v_hi), f, Vec4::ZERO),
        ];
        if (shares[0].cmpgt(Vec4::ZERO) | shares[1].cmpgt(Vec4::ZERO)).any() {
            emit(&Steps {
                major: k,
                t,
                cov,
                minor: r0.as_ivec4().to_array(),
                shares,
            });
        }
        k = k.saturating_add(4);
    }
}

/// The rows of four steps of a line wider than a pixel: the box of width
/// `max(cov, 1)` centred on the line at `v` covers row `r` by its overlap
/// with `[r, r + 1)`, and the row's share of `cov` is that overlap over the
/// box's width (for a box of width 1 this is Wu's split, which thinner
/// lines use). Emitted two rows at a time, from the first row the box
/// reaches; `half` is the largest half-width along the line.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn wide_steps(
    major: i32,
    t: Vec4,
    v: Vec4,
    cov: Vec4,
    half: f32,
    lane: glam::BVec4A,
    (v_lo, v_hi): (Vec4, Vec4),
    emit: &mut impl FnMut(&Steps),
) {
    let h = cov.max(Vec4::ONE) * 0.5;
    let inv_width = (2.0 * h).recip();
    let (lo, hi) = (v - h, v + h);
    let first = lo.floor();
    let pairs = ((2.0 * half).ceil() as i32 + 2) / 2;
    for p in 0..pairs {
        let r0 = first + Vec4::splat(2.0 * p as f32);
        let r1 = r0 + 1.0;
        let share = |r: Vec4| {
            let over = ((r + 1.0).min(hi) - r.max(lo)).max(Vec4::ZERO) * inv_width;
            Vec4::select(lane & r.cmpge(v_lo) & r.cmplt(v_hi), over, Vec4::ZERO)
        };
        let shares = [share(r0), share(r1)];
        if (shares[0].cmpgt(Vec4::ZERO) | shares[1].cmpgt(Vec4::ZERO)).any() {
            emit(&Steps {
                major,
                t,
                cov,
                minor: r0.as_ivec4().to_array(),
                shares,
            });
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn vertex(x: f32, y: f32, width: f32) -> ScreenVertex {
        ScreenVertex {
            p: Vec3::new(x, y, 1.0),
            color: Vec3::ONE,
            width,
            weight: 1.0,
        }
    }

    #[test]
    fn a_lines_coverage_adds_up_to_its_area() {
        for (a, b) in [
            ((3.2, 4.7), (40.9, 11.3)),
            ((10.0, 2.0), (12.5, 50.25)),
            ((30.0, 30.0), (5.5, 5.5)),
            ((0.5, 7.0), (20.5, 7.0)),
        ] {
            let mut sum = 0.0;
            line_fragments(
                vertex(a.0, a.1, 0.8),
                vertex(b.0, b.1, 0.8),
                |_, _, _, c| sum += c,
            );
            let len = ((b.0 - a.0).powi(2) + (b.1 - a.1).powi(2)).sqrt();
            // The half-open steps may miss or add part of one step at the ends.
            let step = 0.8
                * (1.0
                    + ((b.1 - a.1) / (b.0 - a.0))
                        .powi(2)
                        .min(((b.0 - a.0) / (b.1 - a.1)).powi(2)))
                .sqrt();
            assert!(
                (sum - 0.8 * len).abs() <= step,
                "{a:?}-{b:?}: coverage {sum}, area {}",
                0.8 * len
            );
        }
    }

    #[test]
    fn a_line_wider_than_a_pixel_covers_every_row_its_width_reaches() {
        // Along x at y = 10.3, 4 pixels wide: rows 8 to 12 covered by the
        // box [8.3, 12.3), whatever the column.
        let mut by_row = std::collections::BTreeMap::new();
        line_fragments(
            vertex(2.0, 10.3, 4.0),
            vertex(22.0, 10.3, 4.0),
            |x, y, _, c| {
                assert!((2..22).contains(&x));
                *by_row.entry(y).or_insert(0.0f32) += c / 20.0;
            },
        );
        let want = [(8, 0.7), (9, 1.0), (10, 1.0), (11, 1.0), (12, 0.3)];
        assert_eq!(by_row.len(), want.len(), "{by_row:?}");
        for (row, c) in want {
            assert!((by_row[&row] - c).abs() < 1e-4, "row {row}: {by_row:?}");
        }
        // Slanted and thick: the area still adds up, and no pixel is
        // covered more than once.
        let mut sum = 0.0;
        let mut px = std::collections::HashMap::new();
        line_fragments(
            vertex(3.0, 4.0, 3.0),
            vertex(40.0, 21.0, 3.0),
            |x, y, _, c| {
                sum += c;
                *px.entry((x, y)).or_insert(0.0f32) += c;
            },
        );
        let len = (37.0f32 * 37.0 + 17.0 * 17.0).sqrt();
        assert!(
            (sum - 3.0 * len).abs() < 3.0 * 1.2,
            "{sum} against {}",
            3.0 * len
        );
        assert!(px.values().all(|&c| c <= 1.0 + 1e-5), "{px:?}");
    }

    #[test]
    fn a_strip_covers_each_joint_once() {
        let pts = [
            vertex(2.0, 2.0, 1.0),
            vertex(12.0, 5.0, 1.0),
            vertex(30.0, 9.0, 1.0),
        ];
        let mut whole = 0.0;
        line_fragments(pts[0], pts[2], |_, _, _, c| whole += c);
        let mut parts = 0.0;
        line_fragments(pts[0], pts[1], |_, _, _, c| parts += c);
        line_fragments(pts[1], pts[2], |_, _, _, c| parts += c);
        assert!((whole - parts).abs() < 0.2, "{whole} vs {parts}");
    }

    #[test]
    fn zero_length_segments_draw_nothing() {
        let mut n = 0;
        line_fragments(
            vertex(3.0, 3.0, 1.0),
            vertex(3.0, 3.0, 1.0),
            |_, _, _, _| n += 1,
        );
        assert_eq!(n, 0);
    }
}
