//! Hair with a known answer, shared by the physics, method, reference
//! and contact tests.

use glam::Vec3;
use shadow::{Fiber, Light, MethodConfig, ShadowInput, ShadowMethod};
use strands::{Hair, Rng};

/// A straight strand along z at `(x, y)`, 9 points over 2 units.
#[allow(dead_code)]
pub(crate) fn along_z(hair: &mut Hair, x: f32, y: f32) {
    let pts: Vec<Vec3> = (0..9)
        .map(|i| Vec3::new(x, y, -1.0 + 0.25 * i as f32))
        .collect();
    hair.push_strand(&pts).unwrap();
}

/// The method `config` built on `hair` under `light`, fibers `w` wide of
/// opacity `alpha`, no head: ready for lookups.
#[allow(dead_code)]
pub(crate) fn built(
    config: &MethodConfig,
    hair: &Hair,
    light: &Light,
    w: f32,
    alpha: f32,
) -> ShadowMethod {
    let fiber = Fiber::new(w, alpha).unwrap();
    let mut m = ShadowMethod::new(config).unwrap();
    m.density(&ShadowInput {
        light,
        hair,
        fiber: &fiber,
        occluders: &[],
        extent: None,
    })
    .unwrap();
    m.transmittance();
    m
}

/// A box `[-s, s] x [0, h] x [-s, s]` filled with straight fibers along
/// `dir`, `n` of them per unit area across the fibers, each clipped to the
/// box. The fibers sit on a square lattice across `dir`, jittered by a
/// quarter of its spacing (seeded): evenly spread, like combed hair, so
/// that a cell-sized column sees the mean density rather than Poisson noise.
#[allow(dead_code)]
pub(crate) fn fiber_slab(dir: Vec3, n: f32, s: f32, h: f32, seed: u64) -> Hair {
    let dir = dir.normalize();
    let (u, v) = dir.any_orthonormal_pair();
    let centre = Vec3::new(0.0, 0.5 * h, 0.0);
    // Lines through a square across `dir` that covers the box's shadow on it.
    let r = Vec3::new(s, 0.5 * h, s).length();
    let spacing = 1.0 / n.sqrt();
    let side = (2.0 * r / spacing).ceil() as i32;
    let (lo, hi) = (Vec3::new(-s, 0.0, -s), Vec3::new(s, h, s));
    let mut rng = Rng::new(seed);
    let mut hair = Hair::new();
    for a in 0..side {
        for b in 0..side {
            let ua = -r + spacing * (a as f32 + 0.5 + rng.range(-0.25, 0.25));
            let vb = -r + spacing * (b as f32 + 0.5 + rng.range(-0.25, 0.25));
            let o = centre + ua * u + vb * v;
            // Slab clipping of o + t dir against the box.
            let (mut t0, mut t1) = (f32::NEG_INFINITY, f32::INFINITY);
            let mut inside = true;
            for a in 0..3 {
                if dir[a].abs() < 1e-7 {
                    inside &= o[a] >= lo[a] && o[a] <= hi[a];
                } else {
                    let (ta, tb) = ((lo[a] - o[a]) / dir[a], (hi[a] - o[a]) / dir[a]);
                    t0 = t0.max(ta.min(tb));
                    t1 = t1.min(ta.max(tb));
                }
            }
            if inside && t1 > t0 {
                hair.push_strand(&[o + t0 * dir, o + t1 * dir]).unwrap();
            }
        }
    }
    hair
}
