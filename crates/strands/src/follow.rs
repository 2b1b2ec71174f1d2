//! Follow strands grown around guide strands, as TressFX does: a real groom
//! stores a few hundred guides, and each becomes a small wisp.

use glam::Vec3;

use crate::{hair::Hair, rng::Rng};

/// How follow strands spread around their guide.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FollowParams {
    /// Follow strands per guide (the guide itself is kept too).
    pub followers: u32,
    /// Radius of the disc around the root where follow strands start, in scene units.
    pub radius: f32,
    /// How much wider the wisp is at the tip than at the root (1 = a cylinder).
    pub tip_spread: f32,
    /// Seed of the follow strands' offsets.
    pub seed: u64,
}

/// Returns the guides followed each by `followers` offset copies. A follow
/// strand keeps its guide's shape, shifted by an offset that lies in the
/// plane across the root tangent and grows linearly from root to tip by
/// `tip_spread`.
pub fn grow_followers(guides: &Hair, p: &FollowParams) -> Hair {
    let per = p.followers as usize + 1;
    let mut out = Hair::with_capacity(guides.strand_count() * per, guides.point_count() * per);
    let mut colors = Vec::new();
    let mut pts = Vec::new();
    for (g, strand) in guides.strands().enumerate() {
        let mut rng = Rng::fork(p.seed, g as u64);
        let tangent = match strand {
            [a, b, ..] => (*b - *a).normalize_or(Vec3::Y),
            _ => Vec3::Y,
        };
        let (u, v) = tangent.any_orthonormal_pair();
        let last = strand.len().saturating_sub(1).max(1) as f32;
        for f in 0..per {
            let offset = if f == 0 {
                Vec3::ZERO
            } else {
                // Uniform in the disc: radius sqrt(r), angle uniform.
                let r = p.radius * rng.f32().sqrt();
                let phi = std::f32::consts::TAU * rng.f32();
                r * (phi.cos() * u + phi.sin() * v)
            };
            pts.clear();
            pts.extend(
                strand
                    .iter()
                    .enumerate()
                    .map(|(k, &q)| q + offset * (1.0 + (p.tip_spread - 1.0) * k as f32 / last)),
            );
            out.push_strand(&pts)
                .expect("offsets of finite points are finite");
            if let Some(c) = guides.colors() {
                colors.push(c[g]);
            }
        }
    }
    if guides.colors().is_some() {
        out.set_colors(colors);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn followers_keep_the_guide_and_stay_within_the_spread() {
        let mut g = Hair::new();
        let strand: Vec<Vec3> = (0..5).map(|i| Vec3::new(0.0, -(i as f32), 0.0)).collect();
        g.push_strand(&strand).unwrap();
        let p = FollowParams {
            followers: 20,
            radius: 0.5,
            tip_spread: 2.0,
            seed: 3,
        };
        let h = grow_followers(&g, &p);
        assert_eq!(h.strand_count(), 21);
        assert_eq!(h.strand(0), strand.as_slice());
        for s in h.strands() {
            let root = s[0] - strand[0];
            let tip = s[4] - strand[4];
            assert!(
                root.length() <= 0.5 + 1e-6 && root.y.abs() < 1e-6,
                "root offset {root} lies across the tangent"
            );
            assert!((tip - 2.0 * root).length() < 1e-5, "tip offset doubles");
        }
    }
}
