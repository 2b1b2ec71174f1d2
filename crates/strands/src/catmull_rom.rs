//! Catmull-Rom resampling (paper section 4.1): each strand becomes the
//! smooth polyline whose points are both filled into the density map and
//! drawn, so every drawn vertex has a density sample next to it.

use glam::Vec3;

use rayon::prelude::*;

use crate::hair::Hair;

/// Resamples every strand with a uniform Catmull-Rom spline through its
/// points, cutting each segment into `subdivide` pieces (`subdivide = 1`
/// returns the points unchanged).
///
/// Uniform rather than centripetal parameterisation: it is a fixed
/// polynomial in the control points, with no division by segment length,
/// so repeated points and zero-length segments cannot produce NaN. The
/// missing neighbours at the ends are reflected (`P[-1] = 2 P[0] - P[1]`),
/// which keeps the end tangents equal to the end segments.
pub fn resample(hair: &Hair, subdivide: u32) -> Hair {
    let sub = subdivide.max(1) as usize;
    let mut out = Hair::with_capacity(
        hair.strand_count(),
        hair.segment_count() * sub + hair.strand_count(),
    );
    let mut zeros = Vec::new();
    for strand in hair.strands() {
        zeros.resize(resampled_len(strand.len(), sub), Vec3::ZERO);
        out.push_strand(&zeros)
            .expect("as many points as the hair already holds");
    }
    if let Some(c) = hair.colors() {
        out.set_colors(c.to_vec());
    }
    resample_into(hair, subdivide, &mut out);
    out
}

/// [`resample`] into `out`, reusing its memory when it already has the
/// shape of the result (the next frame of an animation); strands in
/// parallel. Otherwise `out` is replaced.
pub fn resample_into(hair: &Hair, subdivide: u32, out: &mut Hair) {
    let sub = subdivide.max(1) as usize;
    let same_shape = out.strand_count() == hair.strand_count()
        && hair
            .strands()
            .zip(out.strands())
            .all(|(a, b)| b.len() == resampled_len(a.len(), sub));
    if !same_shape {
        *out = resample(hair, subdivide);
        return;
    }
    out.strands_mut()
        .into_par_iter()
        .enumerate()
        .with_min_len(16)
        .for_each(|(s, o)| resample_strand(hair.strand(s), sub, o));
}

/// Points of a strand of `n` points after resampling.
fn resampled_len(n: usize, sub: usize) -> usize {
    if n < 2 { n } else { (n - 1) * sub + 1 }
}

fn resample_strand(p: &[Vec3], sub: usize, out: &mut [Vec3]) {
    let n = p.len();
    if n < 2 || sub == 1 {
        out.copy_from_slice(p);
        return;
    }
    let at = |i: isize| -> Vec3 {
        if i < 0 {
            2.0 * p[0] - p[1]
        } else if i as usize >= n {
            2.0 * p[n - 1] - p[n - 2]
        } else {
            p[i as usize]
        }
    };
    for i in 0..n - 1 {
        let (p0, p1, p2, p3) = (at(i as isize - 1), p[i], p[i + 1], at(i as isize + 2));
        let o = &mut out[i * sub..(i + 1) * sub];
        o[0] = p1;
        for (s, q) in o.iter_mut().enumerate().skip(1) {
            let t = s as f32 / sub as f32;
            *q = catmull_rom(p0, p1, p2, p3, t);
        }
    }
    out[(n - 1) * sub] = p[n - 1];
}

/// The uniform Catmull-Rom segment between `p1` (t = 0) and `p2` (t = 1):
/// C(t) = 1/2 [2 p1 + (p2 - p0) t + (2 p0 - 5 p1 + 4 p2 - p3) t^2 + (3 p1 - p0 - 3 p2 + p3) t^3].
fn catmull_rom(p0: Vec3, p1: Vec3, p2: Vec3, p3: Vec3, t: f32) -> Vec3 {
    let t2 = t * t;
    let t3 = t2 * t;
    0.5 * (2.0 * p1
        + (p2 - p0) * t
        + (2.0 * p0 - 5.0 * p1 + 4.0 * p2 - p3) * t2
        + (3.0 * p1 - p0 - 3.0 * p2 + p3) * t3)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn passes_through_control_points_and_reproduces_straight_lines() {
        let mut h = Hair::new();
        let line: Vec<Vec3> = (0..4)
            .map(|i| Vec3::new(i as f32, 2.0 * i as f32, 0.0))
            .collect();
        h.push_strand(&line).unwrap();
        let r = resample(&h, 4);
        assert_eq!(r.point_count(), 13);
        for (k, p) in r.points().iter().enumerate() {
            // A uniform spline through evenly spaced collinear points is the line itself.
            let t = k as f32 / 4.0;
            assert!(p.distance(Vec3::new(t, 2.0 * t, 0.0)) < 1e-5, "{k}: {p}");
        }
        assert_eq!(r.points()[4], line[1]);
    }

    #[test]
    fn midpoint_matches_the_spline_formula_by_hand() {
        // p0..p3 = (0,0), (1,0), (1,1), (0,1): C(1/2) = (-p0 + 9 p1 + 9 p2 - p3) / 16.
        let p = [Vec3::ZERO, Vec3::X, Vec3::new(1.0, 1.0, 0.0), Vec3::Y];
        let want = (-p[0] + 9.0 * p[1] + 9.0 * p[2] - p[3]) / 16.0;
        assert!(catmull_rom(p[0], p[1], p[2], p[3], 0.5).distance(want) < 1e-6);
    }

    #[test]
    fn degenerate_strands_stay_finite() {
        let mut h = Hair::new();
        h.push_strand(&[Vec3::ONE]).unwrap();
        h.push_strand(&[Vec3::ONE, Vec3::ONE, Vec3::ONE]).unwrap();
        h.push_strand(&[]).unwrap();
        let r = resample(&h, 3);
        assert_eq!(r.strand(0), &[Vec3::ONE]);
        assert!(r.strand(1).iter().all(|p| *p == Vec3::ONE));
        assert_eq!(r.strand(1).len(), 7);
        assert_eq!(r.strand(2).len(), 0);
    }

    #[test]
    fn resampling_into_last_frames_hair_gives_the_same_points() {
        let mut h = Hair::new();
        h.push_strand(&[Vec3::ZERO, Vec3::X, Vec3::new(2.0, 1.0, 0.0)])
            .unwrap();
        h.push_strand(&[Vec3::Z, Vec3::ONE]).unwrap();
        let mut out = resample(&h, 3);
        let mut moved = h.clone();
        for p in moved.points_mut() {
            *p = *p * 2.0 + Vec3::Y;
        }
        resample_into(&moved, 3, &mut out);
        assert_eq!(out, resample(&moved, 3));
        // A different shape is rebuilt, not written out of bounds.
        resample_into(&moved, 5, &mut out);
        assert_eq!(out, resample(&moved, 5));
    }
}
