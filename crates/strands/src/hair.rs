//! The hair container: every strand's points in one array.

use glam::{Vec3, Vec3A};

/// Hair as polylines: all points strand after strand, with strand `s`
/// spanning `points[offsets[s]..offsets[s + 1]]`.
///
/// One flat array rather than a `Vec` per strand: the density fill and the
/// filter walk every point once per frame, and a flat array keeps that walk
/// contiguous.
#[derive(Debug, Clone, PartialEq)]
pub struct Hair {
    points: Vec<Vec3>,
    offsets: Vec<u32>,
    /// Linear RGB colour of each strand, when the source gives one.
    colors: Option<Vec<Vec3>>,
    /// Width (diameter) of each strand, the points' units, when the source
    /// gives one (Alembic and USD curves' widths).
    widths: Option<Vec<f32>>,
}

/// Errors building hair from points.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum HairError {
    /// A point with a coordinate that is NaN or infinite.
    #[error("strand {strand}, point {point}: coordinate ({x}, {y}, {z}) is not finite")]
    NonFinite {
        /// Its strand.
        strand: usize,
        /// Its index in the strand.
        point: usize,
        /// Its x.
        x: f32,
        /// Its y.
        y: f32,
        /// Its z.
        z: f32,
    },
    /// More points than 32-bit offsets index.
    #[error("hair has {points} points, more than the 4294967295 one model can index")]
    TooManyPoints {
        /// The points asked for.
        points: usize,
    },
}

/// An axis-aligned box.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Bounds {
    /// Smallest coordinates.
    pub min: Vec3,
    /// Largest coordinates.
    pub max: Vec3,
}

impl Bounds {
    /// The bounds of nothing: every union with it is the other.
    pub fn empty() -> Self {
        Bounds {
            min: Vec3::splat(f32::INFINITY),
            max: Vec3::splat(f32::NEG_INFINITY),
        }
    }
    /// The smallest box holding `points` (empty for none). A coordinate
    /// that is NaN is passed over, as [`Bounds::include`] does.
    pub fn of(points: &[Vec3]) -> Self {
        // Four running boxes a lane wide (`Vec3A`: one SIMD min and max a
        // point), so that the loop is not one chain of dependent min/max;
        // `p.min(lo)` keeps `lo` where `p` is NaN. Min and max pick one
        // of their inputs, so any grouping gives the same box.
        let mut lo = [Vec3A::INFINITY; 4];
        let mut hi = [Vec3A::NEG_INFINITY; 4];
        let mut quads = points.chunks_exact(4);
        for q in &mut quads {
            for (i, &p) in q.iter().enumerate() {
                let p = Vec3A::from(p);
                lo[i] = p.min(lo[i]);
                hi[i] = p.max(hi[i]);
            }
        }
        for &p in quads.remainder() {
            let p = Vec3A::from(p);
            lo[0] = p.min(lo[0]);
            hi[0] = p.max(hi[0]);
        }
        Bounds {
            min: lo[0].min(lo[1]).min(lo[2].min(lo[3])).into(),
            max: hi[0].max(hi[1]).max(hi[2].max(hi[3])).into(),
        }
    }
    /// Whether nothing is inside.
    pub fn is_empty(&self) -> bool {
        self.min.x > self.max.x
    }
    /// Grows the box to hold `p`.
    pub fn include(&mut self, p: Vec3) {
        self.min = self.min.min(p);
        self.max = self.max.max(p);
    }
    /// The box holding both.
    pub fn union(self, o: Bounds) -> Bounds {
        Bounds {
            min: self.min.min(o.min),
            max: self.max.max(o.max),
        }
    }
    /// The box's centre.
    pub fn center(&self) -> Vec3 {
        0.5 * (self.min + self.max)
    }
    /// The box's side lengths.
    pub fn size(&self) -> Vec3 {
        self.max - self.min
    }
}

impl Default for Hair {
    fn default() -> Self {
        Hair::new()
    }
}

impl Hair {
    /// No strands.
    pub fn new() -> Self {
        Hair {
            points: Vec::new(),
            offsets: vec![0],
            colors: None,
            widths: None,
        }
    }

    /// No strands, with room for `strands` strands of `points` points in all.
    pub fn with_capacity(strands: usize, points: usize) -> Self {
        let mut offsets = Vec::with_capacity(strands + 1);
        offsets.push(0);
        Hair {
            points: Vec::with_capacity(points),
            offsets,
            colors: None,
            widths: None,
        }
    }

    /// Appends a strand. Non-finite points are refused: a NaN that reached the
    /// density map would poison a whole column.
    pub fn push_strand(&mut self, points: &[Vec3]) -> Result<(), HairError> {
        let strand = self.strand_count();
        if let Some((point, p)) = points.iter().enumerate().find(|(_, p)| !p.is_finite()) {
            return Err(HairError::NonFinite {
                strand,
                point,
                x: p.x,
                y: p.y,
                z: p.z,
            });
        }
        let total = self.points.len() + points.len();
        let end = u32::try_from(total).map_err(|_| HairError::TooManyPoints { points: total })?;
        self.points.extend_from_slice(points);
        self.offsets.push(end);
        Ok(())
    }

    /// Sets one colour per strand; `colors.len()` must equal the strand count.
    pub fn set_colors(&mut self, colors: Vec<Vec3>) {
        assert_eq!(colors.len(), self.strand_count(), "one colour per strand");
        self.colors = Some(colors);
    }

    /// Each strand's linear RGB colour, when the hair has them.
    pub fn colors(&self) -> Option<&[Vec3]> {
        self.colors.as_deref()
    }

    /// Sets one width per strand (points' units); `widths.len()` must
    /// equal the strand count.
    pub fn set_widths(&mut self, widths: Vec<f32>) {
        assert_eq!(widths.len(), self.strand_count(), "one width per strand");
        self.widths = Some(widths);
    }

    /// Each strand's width (diameter, the points' units), when the file
    /// gives widths.
    pub fn widths(&self) -> Option<&[f32]> {
        self.widths.as_deref()
    }

    /// The median of the strands' widths, when the file gives widths and
    /// one is above 0.
    pub fn median_width(&self) -> Option<f32> {
        let mut w: Vec<f32> = self
            .widths()?
            .iter()
            .copied()
            .filter(|w| *w > 0.0)
            .collect();
        if w.is_empty() {
            return None;
        }
        let mid = w.len() / 2;
        Some(*w.select_nth_unstable_by(mid, f32::total_cmp).1)
    }

    /// Strands.
    pub fn strand_count(&self) -> usize {
        self.offsets.len() - 1
    }

    /// Points, over all strands.
    pub fn point_count(&self) -> usize {
        self.points.len()
    }

    /// Number of line segments: each strand of n points has n - 1.
    pub fn segment_count(&self) -> usize {
        self.offsets
            .windows(2)
            .map(|w| (w[1] - w[0]).saturating_sub(1) as usize)
            .sum()
    }

    /// Every point, strand after strand.
    pub fn points(&self) -> &[Vec3] {
        &self.points
    }

    /// Every point, mutable (the strands keep their lengths).
    pub fn points_mut(&mut self) -> &mut [Vec3] {
        &mut self.points
    }

    /// Every strand's points, mutable, in strand order (for filling them in
    /// parallel).
    pub fn strands_mut(&mut self) -> Vec<&mut [Vec3]> {
        let mut out = Vec::with_capacity(self.strand_count());
        let mut rest: &mut [Vec3] = &mut self.points;
        for w in self.offsets.windows(2) {
            let (a, b) = rest.split_at_mut((w[1] - w[0]) as usize);
            out.push(a);
            rest = b;
        }
        out
    }

    /// Strand boundaries: strand `s` is `points[offsets[s]..offsets[s + 1]]`.
    pub fn offsets(&self) -> &[u32] {
        &self.offsets
    }

    /// The points of strand `s`.
    pub fn strand(&self, s: usize) -> &[Vec3] {
        &self.points[self.offsets[s] as usize..self.offsets[s + 1] as usize]
    }

    /// Every strand's points, in order.
    pub fn strands(&self) -> impl ExactSizeIterator<Item = &[Vec3]> + '_ {
        self.offsets
            .windows(2)
            .map(|w| &self.points[w[0] as usize..w[1] as usize])
    }

    /// The box around every point.
    pub fn bounds(&self) -> Bounds {
        Bounds::of(&self.points)
    }

    /// Length of the longest strand, `l_max` in the paper's map bound.
    pub fn max_strand_length(&self) -> f32 {
        self.strands()
            .map(|s| s.windows(2).map(|w| w[0].distance(w[1])).sum::<f32>())
            .fold(0.0, f32::max)
    }

    /// Moves every point by `delta`.
    pub fn translate(&mut self, delta: Vec3) {
        for p in &mut self.points {
            *p += delta;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_strands_points_and_segments() {
        let mut h = Hair::new();
        h.push_strand(&[Vec3::ZERO, Vec3::X, Vec3::Y]).unwrap();
        h.push_strand(&[Vec3::Z]).unwrap();
        h.push_strand(&[]).unwrap();
        assert_eq!(h.strand_count(), 3);
        assert_eq!(h.point_count(), 4);
        assert_eq!(h.segment_count(), 2);
        assert_eq!(h.strand(1), &[Vec3::Z]);
        assert_eq!(h.max_strand_length(), 1.0 + 2f32.sqrt());
    }

    #[test]
    fn bounds_hold_every_point_whatever_the_count() {
        // Points on a known pattern: coordinate extremes land at every
        // position modulo four, and in the remainder.
        for n in 0..=11usize {
            let pts: Vec<Vec3> = (0..n)
                .map(|i| {
                    let f = i as f32;
                    Vec3::new(f - 5.0, (f * 7.0) % 5.0 - 2.0, -(f * f) + 3.0 * f)
                })
                .collect();
            let b = Bounds::of(&pts);
            if n == 0 {
                assert!(b.is_empty());
                continue;
            }
            // Each axis's extremes worked out one coordinate at a time.
            let axis = |a: usize| {
                let v = pts.iter().map(|p| p.to_array()[a]);
                (
                    v.clone().fold(f32::INFINITY, f32::min),
                    v.fold(f32::NEG_INFINITY, f32::max),
                )
            };
            for a in 0..3 {
                assert_eq!(
                    (b.min.to_array()[a], b.max.to_array()[a]),
                    axis(a),
                    "{n} points, axis {a}"
                );
            }
        }
        // A NaN coordinate is passed over, as `include` does.
        let mut with_nan = vec![Vec3::ONE; 6];
        with_nan[4] = Vec3::new(f32::NAN, 2.0, 0.0);
        let b = Bounds::of(&with_nan);
        assert_eq!(
            (b.min, b.max),
            (Vec3::new(1.0, 1.0, 0.0), Vec3::new(1.0, 2.0, 1.0))
        );
    }

    #[test]
    fn refuses_nan_and_names_the_point() {
        let mut h = Hair::new();
        let err = h
            .push_strand(&[Vec3::ZERO, Vec3::new(0.0, f32::NAN, 0.0)])
            .unwrap_err();
        assert!(matches!(
            err,
            HairError::NonFinite {
                strand: 0,
                point: 1,
                ..
            }
        ));
        assert_eq!(
            h.strand_count(),
            0,
            "a refused strand leaves the hair unchanged"
        );
    }
}
