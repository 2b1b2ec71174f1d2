//! Cubic curves as grooms store them (Alembic's and USD's bases), turned
//! into points along them; and widths given a curve, a control point or a
//! span end turned into one width a strand.

use glam::DVec3;

/// Points each span of a cubic curve becomes (its start and those between;
/// the curve's last point ends it). Two for B-spline and Catmull-Rom spans
/// (one control point a span), three for Bezier (three a span): about as
/// many points as control points, and wisplight's own Catmull-Rom
/// resampling smooths between them.
const STEPS_ONE: usize = 2;
const STEPS_BEZIER: usize = 3;

/// A cubic basis: the weights of a span's four control points at `t`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Basis {
    Bezier,
    BSpline,
    CatmullRom,
}

impl Basis {
    pub(crate) fn from_code(code: u8) -> Option<Basis> {
        match code {
            1 => Some(Basis::Bezier),
            2 => Some(Basis::BSpline),
            3 => Some(Basis::CatmullRom),
            _ => None,
        }
    }
    /// Control points between spans' starts.
    pub(crate) fn step(self) -> usize {
        match self {
            Basis::Bezier => 3,
            _ => 1,
        }
    }
    fn steps(self) -> usize {
        match self {
            Basis::Bezier => STEPS_BEZIER,
            _ => STEPS_ONE,
        }
    }
    /// The weights `b_i(t)` with `p(t) = sum b_i(t) P_i`, `t` in [0, 1].
    fn weights(self, t: f64) -> [f64; 4] {
        let (t2, t3, s) = (t * t, t * t * t, 1.0 - t);
        match self {
            Basis::Bezier => [s * s * s, 3.0 * t * s * s, 3.0 * t2 * s, t3],
            Basis::BSpline => [
                s * s * s / 6.0,
                (3.0 * t3 - 6.0 * t2 + 4.0) / 6.0,
                (-3.0 * t3 + 3.0 * t2 + 3.0 * t + 1.0) / 6.0,
                t3 / 6.0,
            ],
            Basis::CatmullRom => [
                (-t3 + 2.0 * t2 - t) / 2.0,
                (3.0 * t3 - 5.0 * t2 + 2.0) / 2.0,
                (-3.0 * t3 + 4.0 * t2 + t) / 2.0,
                (t3 - t2) / 2.0,
            ],
        }
    }
    /// The points along the curve of control points `cv`: each span's
    /// [`Basis::steps`] points, then the end. A curve too short for one
    /// span is its control points.
    pub(crate) fn evaluate(self, cv: &[DVec3], out: &mut Vec<DVec3>) {
        if cv.len() < 4 {
            out.extend_from_slice(cv);
            return;
        }
        let spans = (cv.len() - 4) / self.step() + 1;
        let span = |i: usize, t: f64| {
            let w = self.weights(t);
            let p = &cv[i * self.step()..i * self.step() + 4];
            w[0] * p[0] + w[1] * p[1] + w[2] * p[2] + w[3] * p[3]
        };
        for i in 0..spans {
            for k in 0..self.steps() {
                out.push(span(i, k as f64 / self.steps() as f64));
            }
        }
        out.push(span(spans - 1, 1.0));
    }
}

/// Appends to `hair` the strand of control points `cv` (in place: a
/// cubic curve of basis `basis` is evaluated, `None` is linear), using
/// `along` for the points; the error is the hair's.
pub(crate) fn push_curve(
    hair: &mut crate::Hair,
    cv: &[DVec3],
    basis: Option<Basis>,
    along: &mut Vec<DVec3>,
) -> Result<(), crate::HairError> {
    along.clear();
    match basis {
        Some(b) => b.evaluate(cv, along),
        None => along.extend_from_slice(cv),
    }
    let strand: Vec<glam::Vec3> = along.iter().map(|p| p.as_vec3()).collect();
    hair.push_strand(&strand)
}

/// One width a strand (the mean of its values) from `values` given one
/// for all, one a curve, one a control point, or one a span end (a
/// control point for linear curves), told apart by their count; the
/// curves have `counts` control points each, of basis `basis` (`None`
/// linear). The error says what does not fit.
pub(crate) fn strand_widths(
    values: &[f32],
    counts: &[usize],
    basis: Option<Basis>,
) -> Result<Vec<f32>, String> {
    if values.iter().any(|w| !w.is_finite() || *w < 0.0) {
        return Err("a width that is negative or not finite".into());
    }
    let points: usize = counts.iter().sum();
    // Span ends a curve has: its spans + 1 (a control point each, linear).
    let ends = |n: usize| match basis {
        Some(b) if n >= 4 => (n - 4) / b.step() + 2,
        _ => n,
    };
    let varying: usize = counts.iter().map(|&n| ends(n)).sum();
    let per = |c: usize| -> usize {
        match values.len() {
            n if n == points => counts[c],
            _ => ends(counts[c]),
        }
    };
    match values.len() {
        1 => return Ok(vec![values[0]; counts.len()]),
        n if n == counts.len() => return Ok(values.to_vec()),
        n if n == points || n == varying => {}
        n => {
            return Err(format!(
                "{n} widths for {} curves of {points} control points",
                counts.len()
            ));
        }
    }
    let mut out = Vec::with_capacity(counts.len());
    let mut at = 0;
    for c in 0..counts.len() {
        let n = per(c);
        let w = &values[at..at + n];
        at += n;
        out.push(if n == 0 {
            0.0
        } else {
            w.iter().sum::<f32>() / n as f32
        });
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn widths_are_told_apart_by_their_count() {
        let counts = [2, 3];
        assert_eq!(strand_widths(&[0.5], &counts, None), Ok(vec![0.5, 0.5]));
        assert_eq!(
            strand_widths(&[1.0, 2.0], &counts, None),
            Ok(vec![1.0, 2.0])
        );
        assert_eq!(
            strand_widths(&[1.0, 3.0, 2.0, 2.0, 5.0], &counts, None),
            Ok(vec![2.0, 3.0])
        );
        // Bezier curves of 4 and 7 control points: 2 and 3 span ends.
        let counts = [4, 7];
        assert_eq!(
            strand_widths(&[1.0, 3.0, 1.0, 1.0, 4.0], &counts, Some(Basis::Bezier)),
            Ok(vec![2.0, 2.0])
        );
        assert!(
            strand_widths(&[1.0; 3], &counts, None)
                .unwrap_err()
                .contains("3 widths")
        );
        assert!(strand_widths(&[f32::NAN], &counts, None).is_err());
    }

    #[test]
    fn each_basis_weights_sum_to_one_and_bezier_and_catmull_rom_meet_their_points() {
        for b in [Basis::Bezier, Basis::BSpline, Basis::CatmullRom] {
            for k in 0..=10 {
                let w = b.weights(f64::from(k) / 10.0);
                assert!((w.iter().sum::<f64>() - 1.0).abs() < 1e-12, "{b:?}");
            }
        }
        let cv: Vec<DVec3> = (0..7)
            .map(|i| DVec3::new(f64::from(i), f64::from(i * i), 0.0))
            .collect();
        // Bezier: the ends of each span are control points 0, 3, 6.
        let mut out = Vec::new();
        Basis::Bezier.evaluate(&cv, &mut out);
        assert_eq!(out.len(), 2 * STEPS_BEZIER + 1);
        assert_eq!(out[0], cv[0]);
        assert!((out[STEPS_BEZIER] - cv[3]).length() < 1e-12);
        assert!((out[out.len() - 1] - cv[6]).length() < 1e-12);
        // Catmull-Rom runs through control points 1 to n - 2.
        out.clear();
        Basis::CatmullRom.evaluate(&cv, &mut out);
        assert_eq!(out.len(), 4 * STEPS_ONE + 1);
        for (k, p) in out.iter().step_by(STEPS_ONE).enumerate() {
            assert!((*p - cv[k + 1]).length() < 1e-12, "{k}");
        }
        // A uniform B-spline of points on a line is that line, starting
        // at (P0 + 4 P1 + P2) / 6.
        let line: Vec<DVec3> = (0..5).map(|i| DVec3::splat(f64::from(i))).collect();
        out.clear();
        Basis::BSpline.evaluate(&line, &mut out);
        assert!((out[0] - DVec3::splat(1.0)).length() < 1e-12);
        assert!((out[out.len() - 1] - DVec3::splat(3.0)).length() < 1e-12);
    }
}
