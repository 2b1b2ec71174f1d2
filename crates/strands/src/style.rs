//! Procedural hairstyles like the paper's test heads: 134 wisps on a
//! spherical head, each wisp made of three guide strands and a number of
//! rendered strands interpolated between them (paper section 5.1).

use glam::Vec3;
use rayon::prelude::*;

use crate::{hair::Hair, rng::Rng};

/// The built-in hairstyles.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Style {
    /// Long straight hair: 15 control segments per strand (about 100K
    /// drawn segments at the default 25 strands per wisp and subdivision 2).
    Smooth,
    /// Coherent curls per wisp: 30 control segments per strand (about 200K
    /// drawn segments at the defaults).
    Curly,
}

impl Style {
    /// The style's name, as scenes spell it.
    pub fn name(self) -> &'static str {
        match self {
            Style::Smooth => "smooth",
            Style::Curly => "curly",
        }
    }

    /// The style named `name`, if any.
    pub fn from_name(name: &str) -> Option<Style> {
        match name {
            "smooth" => Some(Style::Smooth),
            "curly" => Some(Style::Curly),
            _ => None,
        }
    }

    fn control_segments(self) -> usize {
        match self {
            Style::Smooth => 15,
            Style::Curly => 30,
        }
    }
}

/// Everything that determines a procedural hairstyle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StyleParams {
    /// Smooth or curly.
    pub style: Style,
    /// Seed of everything random in the style.
    pub seed: u64,
    /// Wisps (the paper's 134 by default).
    pub wisps: u32,
    /// Drawn strands per wisp.
    pub strands_per_wisp: u32,
    /// Head sphere centre and radius, in scene units (centimetres by convention).
    pub head_center: Vec3,
    /// See `head_center`.
    pub head_radius: f32,
    /// A middle parting: hair rooted in front of the crown sweeps to its
    /// side and back, off the face, and hair over the forehead is cut to
    /// a fringe above the eyes.
    pub parting: bool,
    /// The hair's linear RGB colour (each strand within 20 % of it); the
    /// style's own (dark brown, auburn for curls) when `None`.
    pub color: Option<Vec3>,
}

impl StyleParams {
    /// The paper's defaults for `style`: 134 wisps of 25 strands on a head of radius 10.
    pub fn new(style: Style) -> Self {
        StyleParams {
            style,
            seed: 1,
            wisps: 134,
            strands_per_wisp: 25,
            head_center: Vec3::ZERO,
            head_radius: 10.0,
            parting: false,
            color: None,
        }
    }
}

/// A rendered strand's place in its wisp: barycentric weights on the wisp's
/// three guides.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Member {
    /// Its wisp.
    pub wisp: u32,
    /// Its barycentric weights on the wisp's three guides.
    pub weights: [f32; 3],
}

/// Wisps of three guide strands, and the rendered strands interpolated
/// from them. Guides of wisp `w` are strands `3w .. 3w + 3` of `guides`;
/// members are sorted by wisp.
#[derive(Debug, Clone, PartialEq)]
pub struct WispModel {
    /// Three guide strands per wisp.
    pub guides: Hair,
    /// Every drawn strand's place, sorted by wisp.
    pub members: Vec<Member>,
    /// Linear RGB colour of each member strand.
    pub colors: Vec<Vec3>,
}

/// Guide strands per wisp (the paper's three).
pub const GUIDES_PER_WISP: usize = 3;

impl WispModel {
    /// Wisps.
    pub fn wisp_count(&self) -> usize {
        self.guides.strand_count() / GUIDES_PER_WISP
    }

    /// The rendered strands' control points: each point is the weighted sum
    /// of the same point on the wisp's three guides.
    pub fn interpolate(&self) -> Hair {
        let mut hair = self.interpolate_members(0..self.members.len());
        hair.set_colors(self.colors.clone());
        hair
    }

    /// The members (rendered strands) of wisps `wisps`: a contiguous range,
    /// since members are sorted by wisp.
    pub fn member_range(&self, wisps: std::ops::Range<usize>) -> std::ops::Range<usize> {
        let at = |w: usize| self.members.partition_point(|m| (m.wisp as usize) < w);
        at(wisps.start)..at(wisps.end)
    }

    /// [`Self::interpolate`] of members `members` only, without colours:
    /// the same points, for a share of the wisps simulated elsewhere.
    pub fn interpolate_members(&self, members: std::ops::Range<usize>) -> Hair {
        let per = self.guides.strand(0).len();
        let mut hair = Hair::with_capacity(members.len(), members.len() * per);
        let mut pts = Vec::with_capacity(per);
        for m in &self.members[members] {
            let g = m.wisp as usize * GUIDES_PER_WISP;
            let (a, b, c) = (
                self.guides.strand(g),
                self.guides.strand(g + 1),
                self.guides.strand(g + 2),
            );
            pts.clear();
            pts.extend((0..per).map(|k| member_point(m, a[k], b[k], c[k])));
            hair.push_strand(&pts)
                .expect("weighted sums of finite points are finite");
        }
        hair
    }

    /// [`Self::interpolate_members`] into `out`, reusing its memory when it
    /// holds those members already (the next frame of a share of the
    /// wisps), otherwise replacing it: the same points, and no colours.
    pub fn interpolate_members_into(&self, members: std::ops::Range<usize>, out: &mut Hair) {
        let per = self.guides.strand(0).len();
        if out.strand_count() != members.len() || out.point_count() != members.len() * per {
            *out = self.interpolate_members(members);
            return;
        }
        self.fill_members(&self.members[members], out.points_mut());
    }

    /// [`Self::interpolate`] into `out`, which must be its earlier result
    /// (same members): the next frame's points without allocating.
    pub fn interpolate_into(&self, out: &mut Hair) {
        let per = self.guides.strand(0).len();
        assert_eq!(
            out.point_count(),
            self.members.len() * per,
            "out comes from interpolate()"
        );
        self.fill_members(&self.members, out.points_mut());
    }

    /// The points of `members`, strand after strand, into `points`;
    /// strands in parallel.
    fn fill_members(&self, members: &[Member], points: &mut [Vec3]) {
        let per = self.guides.strand(0).len();
        points
            .par_chunks_mut(per)
            .zip(members)
            .with_min_len(16)
            .for_each(|(pts, m)| {
                let g = m.wisp as usize * GUIDES_PER_WISP;
                let (a, b, c) = (
                    self.guides.strand(g),
                    self.guides.strand(g + 1),
                    self.guides.strand(g + 2),
                );
                for (k, p) in pts.iter_mut().enumerate() {
                    *p = member_point(m, a[k], b[k], c[k]);
                }
            });
    }

    /// Grows a procedural hairstyle; the same parameters give the same bytes.
    pub fn generate(p: &StyleParams) -> WispModel {
        let roots = scalp_points(p.wisps as usize);
        // Wisps in order of their root's azimuth about the vertical axis,
        // so that a contiguous range of wisps is a sector of the head: a
        // compact part of the picture (a cluster worker draws a few such
        // sectors, and their partial pictures overlap little). Each wisp
        // keeps the random numbers of its root's place on the scalp.
        let mut order: Vec<usize> = (0..roots.len()).collect();
        order.sort_by(|&a, &b| {
            let (a, b) = (roots[a], roots[b]);
            a.x.atan2(a.z).total_cmp(&b.x.atan2(b.z))
        });
        let segs = p.style.control_segments();
        let mut guides = Hair::with_capacity(
            roots.len() * GUIDES_PER_WISP,
            roots.len() * GUIDES_PER_WISP * (segs + 1),
        );
        let mut members = Vec::with_capacity(roots.len() * p.strands_per_wisp as usize);
        let mut colors = Vec::with_capacity(members.capacity());
        let base_color = p.color.unwrap_or(match p.style {
            Style::Smooth => Vec3::new(0.16, 0.075, 0.03),
            Style::Curly => Vec3::new(0.42, 0.10, 0.035),
        });
        for (w, &at) in order.iter().enumerate() {
            let n = &roots[at];
            let mut rng = Rng::fork(p.seed, at as u64);
            let wisp = WispShape {
                length: match p.style {
                    Style::Smooth => rng.range(22.0, 30.0),
                    Style::Curly => rng.range(18.0, 24.0),
                },
                bend: rng.range(0.22, 0.34),
                clearance: if p.parting {
                    rng.range(0.1, 0.7)
                } else {
                    rng.range(0.15, 1.4)
                },
                curl_phase: rng.range(0.0, std::f32::consts::TAU),
            };
            let (t1, t2) = n.any_orthonormal_pair();
            let spin = rng.range(0.0, std::f32::consts::TAU);
            for g in 0..GUIDES_PER_WISP {
                let a = spin + std::f32::consts::TAU * g as f32 / GUIDES_PER_WISP as f32;
                let r = if p.parting { PARTED_WISP_RADIUS } else { 1.1 } * p.head_radius / 10.0;
                let dir = (*n * p.head_radius + r * (a.cos() * t1 + a.sin() * t2)).normalize();
                let jitter = GuideJitter {
                    length: rng.range(-0.6, 0.6),
                    bend: rng.range(-0.02, 0.02),
                };
                let pts = grow_guide(p, &wisp, &jitter, dir, segs);
                guides
                    .push_strand(&pts)
                    .expect("procedural points are finite");
            }
            for _ in 0..p.strands_per_wisp {
                // Uniform in the triangle of the three guides.
                let (r1, r2) = (rng.f32().sqrt(), rng.f32());
                members.push(Member {
                    wisp: w as u32,
                    weights: [1.0 - r1, r1 * (1.0 - r2), r1 * r2],
                });
                colors.push(base_color * rng.range(0.8, 1.2));
            }
        }
        WispModel {
            guides,
            members,
            colors,
        }
    }
}

/// A member's point from the same point `a`, `b`, `c` of its wisp's guides.
#[inline]
fn member_point(m: &Member, a: Vec3, b: Vec3, c: Vec3) -> Vec3 {
    m.weights[0] * a + m.weights[1] * b + m.weights[2] * c
}

/// The radius, in centimetres on a head of radius 10, of the circle the
/// guides of a parted style's wisps start on: wide enough that
/// neighbouring wisps overlap and the scalp is covered.
const PARTED_WISP_RADIUS: f32 = 1.7;

struct WispShape {
    length: f32,
    bend: f32,
    clearance: f32,
    curl_phase: f32,
}

struct GuideJitter {
    length: f32,
    bend: f32,
}

/// `n` root directions spread evenly over the scalp of a unit sphere
/// (+y up, +z the face): a Fibonacci lattice with the face and the neck
/// cut away, densified until it holds `n` points.
fn scalp_points(n: usize) -> Vec<Vec3> {
    let on_scalp = |d: Vec3| d.y > -0.25 && !(d.z > 0.3 && d.y < 0.5);
    let mut total = n.max(1);
    loop {
        let golden = std::f32::consts::PI * (3.0 - 5f32.sqrt());
        let pts: Vec<Vec3> = (0..total)
            .map(|i| {
                let y = 1.0 - 2.0 * (i as f32 + 0.5) / total as f32;
                let r = (1.0 - y * y).max(0.0).sqrt();
                let phi = golden * i as f32;
                Vec3::new(r * phi.cos(), y, r * phi.sin())
            })
            .filter(|&d| on_scalp(d))
            .collect();
        if pts.len() >= n {
            return pts.into_iter().take(n).collect();
        }
        total += (n - pts.len()).max(1);
    }
}

/// One guide: rises off the scalp along its normal, then bends toward a
/// falling direction swept slightly back, and is kept `clearance` outside
/// the head sphere. Curly guides add a helix around that path.
fn grow_guide(p: &StyleParams, w: &WispShape, j: &GuideJitter, n: Vec3, segs: usize) -> Vec<Vec3> {
    let c = p.head_center;
    let scale = p.head_radius / 10.0;
    let outward = Vec3::new(n.x, 0.0, n.z).normalize_or(Vec3::NEG_Z);
    let falling = 0.35 * outward + Vec3::NEG_Y + 0.25 * Vec3::NEG_Z;
    let (target, start, length) = if p.parting {
        // Rooted in front of the crown: swept to its side of the parting
        // (x = 0) and back, off the face.
        let front = n.z.max(0.0).powi(2);
        let side = if n.x < 0.0 { Vec3::NEG_X } else { Vec3::X };
        let target = (falling + front * (0.9 * side + 0.3 * Vec3::NEG_Z)).normalize();
        // Out of the scalp at a low angle, along it towards where it
        // falls: the hair lies on the head and covers it.
        let along = (target - n * n.dot(target)).normalize_or(Vec3::NEG_Y);
        // Over the forehead: a fringe ending above the eyes (0.15 R above
        // the centre), whatever the style's length.
        let fringe = ((n.z - 0.2) / 0.3).clamp(0.0, 1.0);
        let to_brow = (17.0 * (n.y - 0.15)).max(2.5);
        let full = w.length + j.length;
        let length = full + fringe * (to_brow.min(full) - full);
        (target, (0.45 * n + along).normalize(), length)
    } else {
        (falling.normalize(), n, w.length + j.length)
    };
    let h = length * scale / segs as f32;
    let bend = w.bend + j.bend;
    let keep_out = |q: Vec3| {
        let r = q - c;
        let min = p.head_radius + w.clearance * scale;
        if r.length() < min {
            c + r.normalize_or(Vec3::Y) * min
        } else {
            q
        }
    };
    let mut pts = Vec::with_capacity(segs + 1);
    let mut q = c + n * p.head_radius;
    let mut d = start;
    pts.push(q);
    for _ in 0..segs {
        d = d.lerp(target, bend).normalize();
        q = keep_out(q + h * d);
        pts.push(q);
    }
    if p.style == Style::Curly {
        // Helix of radius A(s) = 1.2 cm (ramping in over the first 3 cm) and
        // wavelength 4.5 cm around the path; the wisp's guides share the phase.
        let (amp, wavelength) = (1.2 * scale, 4.5 * scale);
        let base = pts.clone();
        let mut s = 0.0;
        for k in 1..=segs {
            s += base[k].distance(base[k - 1]);
            let t = (base[(k + 1).min(segs)] - base[k - 1]).normalize_or(Vec3::NEG_Y);
            let u = t.cross(base[k] - c).normalize_or(t.any_orthogonal_vector());
            let v = t.cross(u);
            let a = amp * (s / (3.0 * scale)).min(1.0);
            let phase = w.curl_phase + std::f32::consts::TAU * s / wavelength;
            pts[k] = keep_out(base[k] + a * (phase.cos() * u + phase.sin() * v));
        }
    }
    pts
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn smooth_and_curly_have_the_papers_sizes() {
        for (style, segments) in [(Style::Smooth, 100_500), (Style::Curly, 201_000)] {
            let m = WispModel::generate(&StyleParams::new(style));
            assert_eq!(m.wisp_count(), 134);
            let hair = crate::resample(&m.interpolate(), 2);
            assert_eq!(hair.strand_count(), 3350);
            assert_eq!(hair.segment_count(), segments, "{style:?}");
        }
    }

    #[test]
    fn roots_lie_on_the_scalp_and_hair_stays_outside_the_head() {
        let p = StyleParams::new(Style::Curly);
        let m = WispModel::generate(&p);
        for s in m.guides.strands() {
            assert!((s[0].length() - 10.0).abs() < 1e-4, "root on the sphere");
            assert!(
                s.iter().all(|q| q.length() >= 10.0 - 1e-3),
                "no point inside the head"
            );
        }
    }

    #[test]
    fn interpolating_in_place_matches_interpolating_anew() {
        let mut m = WispModel::generate(&StyleParams::new(Style::Smooth));
        let mut out = m.interpolate();
        for p in m.guides.points_mut() {
            p.y -= 1.5;
        }
        m.interpolate_into(&mut out);
        assert_eq!(out, m.interpolate());
    }

    #[test]
    fn deterministic_from_the_seed() {
        let p = StyleParams::new(Style::Smooth);
        assert_eq!(WispModel::generate(&p), WispModel::generate(&p));
        let other = WispModel::generate(&StyleParams { seed: 2, ..p });
        assert_ne!(
            other.guides.points(),
            WispModel::generate(&p).guides.points()
        );
    }
}
