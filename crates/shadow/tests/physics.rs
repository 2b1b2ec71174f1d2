//! The density map against physics it must reproduce: Beer-Lambert in a
//! slab of parallel fibers, full light in front of the hair, monotone decay
//! along the light, invariance under rotation and under the map resolution,
//! and the same bytes on any number of threads.

use common::fiber_slab;
use glam::{Quat, Vec3};
use shadow::{DensityMap, Fiber, Light, LightFrame, Transmittance};
use strands::{Hair, Rng, Style, StyleParams, WispModel};

mod common;

fn shadow_of(hair: &Hair, light: &Light, fiber: &Fiber, cells: u32) -> Transmittance {
    let frame = LightFrame::fit(light, hair.points(), cells).unwrap();
    let mut map = DensityMap::new(frame);
    let stats = map.fill(hair, fiber);
    assert_eq!(stats.out_of_map, 0, "a fitted map holds all the hair");
    Transmittance::compute(&map)
}

/// Mean transmittance over a grid of points at depth `x` below the slab's
/// top face (light travels along -y), away from the box's sides.
fn mean_t_at_depth(t: &Transmittance, h: f32, x: f32, inner: f32, rot: Quat) -> f32 {
    let m = 24;
    let mut sum = 0.0;
    for a in 0..m {
        for b in 0..m {
            let px = -inner + 2.0 * inner * (a as f32 + 0.5) / m as f32;
            let pz = -inner + 2.0 * inner * (b as f32 + 0.5) / m as f32;
            sum += t.transmittance_at(rot * Vec3::new(px, h - x, pz), true);
        }
    }
    sum / (m * m) as f32
}

#[test]
fn slabs_of_parallel_fibers_follow_beer_lambert_at_every_angle() {
    let fiber = Fiber::new(0.0004, 0.5).unwrap();
    let (s, h, n) = (0.6, 1.0, 10_000.0);
    let light = Light::directional(Vec3::NEG_Y).unwrap();
    for theta_deg in [0.0f32, 30.0, 60.0, 90.0] {
        let theta = theta_deg.to_radians();
        // The angle between a fiber and the light (-y) is theta.
        let dir = Vec3::new(theta.sin(), -theta.cos(), 0.0);
        let hair = fiber_slab(dir, n, s, h, 7);
        // kappa = n w alpha sin(theta), per unit length along the light.
        let kappa = n * fiber.width() * fiber.opacity() * theta.sin();
        let t = shadow_of(&hair, &light, &fiber, 128);
        for x in [0.1f32, 0.25, 0.5, 0.75, 0.9] {
            let got = mean_t_at_depth(&t, h, x, 0.4, Quat::IDENTITY);
            let want = (-kappa * x).exp();
            // Probes (points in free space) are read where they are.
            assert!(
                (got - want).abs() < 0.01,
                "theta {theta_deg} deg, depth {x}: T = {got}, Beer-Lambert {want}"
            );
        }
    }
}

#[test]
fn the_map_resolution_does_not_change_how_dark_hair_looks() {
    let fiber = Fiber::new(0.0004, 0.5).unwrap();
    let hair = fiber_slab(Vec3::new(1.0, -0.4, 0.3), 8000.0, 0.6, 1.0, 11);
    let light = Light::directional(Vec3::NEG_Y).unwrap();
    let fine = shadow_of(&hair, &light, &fiber, 256);
    for cells in [32, 64, 128] {
        let t = shadow_of(&hair, &light, &fiber, cells);
        for x in [0.2f32, 0.5, 0.8] {
            // Probes are read where they are: the same depth at any
            // resolution.
            let want = mean_t_at_depth(&fine, 1.0, x, 0.4, Quat::IDENTITY);
            let got = mean_t_at_depth(&t, 1.0, x, 0.4, Quat::IDENTITY);
            assert!(
                (got - want).abs() < 0.02,
                "{cells}^3 at depth {x}: {got} vs {want} at 256^3"
            );
        }
    }
}

fn small_style(seed: u64) -> Hair {
    let mut p = StyleParams::new(Style::Smooth);
    p.seed = seed;
    p.strands_per_wisp = 6;
    strands::resample(&WispModel::generate(&p).interpolate(), 2)
}

/// Points scattered through and around the hair.
fn probe_points(hair: &Hair, count: usize, seed: u64) -> Vec<Vec3> {
    let b = hair.bounds();
    let (c, e) = (b.center(), 0.6 * b.size());
    let mut rng = Rng::new(seed);
    (0..count)
        .map(|_| {
            c + Vec3::new(
                rng.range(-e.x, e.x),
                rng.range(-e.y, e.y),
                rng.range(-e.z, e.z),
            )
        })
        .collect()
}

#[test]
fn light_reaches_points_in_front_of_all_hair_untouched() {
    let hair = small_style(3);
    let fiber = Fiber::new(0.1, 0.8).unwrap();
    for d in [
        Vec3::new(0.6, -0.8, -0.35),
        Vec3::NEG_Y,
        Vec3::X,
        Vec3::new(-0.2, 0.3, 1.0),
    ] {
        let light = Light::directional(d).unwrap();
        let t = shadow_of(&hair, &light, &fiber, 64);
        let l = light.direction();
        let first = hair
            .points()
            .iter()
            .map(|p| p.dot(l))
            .fold(f32::INFINITY, f32::min);
        for p in probe_points(&hair, 2000, 5) {
            // Move each point in front of the nearest hair along the light.
            let q = p - (p.dot(l) - first + 0.01) * l;
            for trilinear in [true, false] {
                assert_eq!(
                    t.transmittance_at(q, trilinear),
                    1.0,
                    "{q} in front of the hair, light {d}, filter {trilinear}"
                );
            }
        }
        // And far outside the map on every side.
        let b = hair.bounds();
        for far in [b.max + Vec3::splat(100.0), b.min - Vec3::splat(100.0)] {
            let behind = far.dot(l) > first;
            let tf = t.transmittance_at(far, true);
            assert!(tf == 1.0 || behind, "{far}: {tf}");
        }
    }
}

#[test]
fn transmittance_stays_in_range_and_never_increases_along_the_light() {
    let hair = small_style(4);
    let fiber = Fiber::new(0.1, 0.9).unwrap();
    for d in [
        Vec3::new(0.6, -0.8, -0.35),
        Vec3::NEG_Y,
        Vec3::new(0.0, 0.0, 1.0),
        Vec3::new(1.0, 1.0, 1.0),
    ] {
        let light = Light::directional(d).unwrap();
        let l = light.direction();
        let t = shadow_of(&hair, &light, &fiber, 48);
        let size = hair.bounds().size().length();
        let mut darkest = 1.0f32;
        for start in probe_points(&hair, 300, 6) {
            for trilinear in [true, false] {
                let mut prev = 1.0f32;
                for s in 0..200 {
                    let p = start + l * (size * (s as f32 / 100.0 - 1.0));
                    let v = t.transmittance_at(p, trilinear);
                    assert!((0.0..=1.0).contains(&v), "T({p}) = {v}");
                    // The test's points drift off the ray by float rounding
                    // (a few ulps of |p|), which moves the bilinear weights
                    // across columns: allow that much, no more.
                    assert!(
                        v <= prev + 1e-5,
                        "T rose from {prev} to {v} at {p}, light {d}, filter {trilinear}"
                    );
                    prev = v;
                }
                darkest = darkest.min(prev);
            }
        }
        assert!(
            darkest < 0.5,
            "the hair casts a real shadow (darkest {darkest})"
        );
    }
}

/// Mean transmittance over a square patch of 8 x 8 points, `side` wide,
/// across the light (-y before rotation) at height `y`.
fn patch_mean(t: &Transmittance, centre: Vec3, side: f32, rot: Quat) -> f32 {
    let mut sum = 0.0;
    for a in 0..8 {
        for b in 0..8 {
            let off = Vec3::new(
                side * ((a as f32 + 0.5) / 8.0 - 0.5),
                0.0,
                side * ((b as f32 + 0.5) / 8.0 - 0.5),
            );
            sum += t.transmittance_at(rot * (centre + off), true);
        }
    }
    sum / 64.0
}

/// The map's grid is laid out across the light in whatever orientation the
/// frame picks, so one vertex's T depends on where cell boundaries fall
/// relative to individual fibers (up to 0.05 here at 128^3: the map knows
/// density only at the scale of a cell). Over a patch of about 16 x 16
/// columns the answer must not depend on the orientation.
#[test]
fn rotating_hair_light_and_points_together_changes_nothing() {
    let fiber = Fiber::new(0.0004, 0.5).unwrap();
    let hair = fiber_slab(Vec3::new(1.0, -0.3, 0.2), 10_000.0, 0.6, 1.0, 13);
    let light_dir = Vec3::NEG_Y;
    let base = shadow_of(&hair, &Light::directional(light_dir).unwrap(), &fiber, 128);
    let centres: Vec<Vec3> = [0.9f32, 0.6, 0.3, 0.05]
        .iter()
        .flat_map(|&y| {
            [
                Vec3::new(-0.25, y, -0.2),
                Vec3::new(0.2, y, 0.25),
                Vec3::new(0.0, y, 0.0),
            ]
        })
        .collect();
    for (axis, angle) in [
        (Vec3::Z, 0.7f32),
        (Vec3::new(1.0, 2.0, -0.5), 2.1),
        (Vec3::X, 0.25),
    ] {
        let r = Quat::from_axis_angle(axis.normalize(), angle);
        let mut rotated = hair.clone();
        for p in rotated.points_mut() {
            *p = r * *p;
        }
        let t = shadow_of(
            &rotated,
            &Light::directional(r * light_dir).unwrap(),
            &fiber,
            128,
        );
        for &c in &centres {
            let (a, b) = (
                patch_mean(&base, c, 0.16, Quat::IDENTITY),
                patch_mean(&t, c, 0.16, r),
            );
            assert!(
                (a - b).abs() <= 0.01,
                "rotation {angle} about {axis}: mean T around {c} {a} became {b}"
            );
        }
    }
}

#[test]
fn results_are_the_same_bytes_on_any_number_of_threads() {
    let hair = small_style(9);
    let fiber = Fiber::new(0.1, 0.7).unwrap();
    let light = Light::directional(Vec3::new(0.3, -1.0, 0.2)).unwrap();
    let points = probe_points(&hair, 5000, 1);
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            let t = shadow_of(&hair, &light, &fiber, 96);
            let mut out = vec![0.0; points.len()];
            t.filter(&points, true, &mut out);
            (t, out.iter().map(|v| v.to_bits()).collect::<Vec<u32>>())
        })
    };
    let (t1, v1) = run(1);
    for threads in [2, 3, 8] {
        let (t, v) = run(threads);
        assert!(t == t1, "the swept depths differ on {threads} threads");
        assert!(
            v == v1,
            "filtered transmittance differs on {threads} threads"
        );
    }
}

/// Transmittance of a point light at `source` over a grid of points at
/// depth `x` below the slab's top face `y = h`, away from the sides: the
/// map's mean, and the mean of each ray's exact Beer-Lambert attenuation
/// `exp(-n w alpha sin(theta) L)`, `L` the ray's length in the slab and
/// `theta` its angle to the fibers (along `dir`).
fn point_lit_means(
    t: &Transmittance,
    source: Vec3,
    kappa_per_sin: f32,
    dir: Vec3,
    h: f32,
    x: f32,
    inner: f32,
) -> (f32, f32) {
    let m = 24;
    let (mut got, mut want) = (0.0, 0.0);
    for a in 0..m {
        for b in 0..m {
            let px = -inner + 2.0 * inner * (a as f32 + 0.5) / m as f32;
            let pz = -inner + 2.0 * inner * (b as f32 + 0.5) / m as f32;
            let p = Vec3::new(px, h - x, pz);
            let e = (p - source).normalize();
            let length = x / e.y.abs();
            let sin = e.cross(dir.normalize()).length();
            got += t.transmittance_at(p, true);
            want += (-kappa_per_sin * sin * length).exp();
        }
    }
    let k = (m * m) as f32;
    (got / k, want / k)
}

#[test]
fn a_point_light_close_to_a_slab_follows_beer_lambert_along_every_ray() {
    let fiber = Fiber::new(0.0004, 0.5).unwrap();
    let (s, h, n) = (0.6, 1.0, 10_000.0);
    // Half the slab's thickness above its top face: rays cross it at up
    // to 40 degrees from the axis.
    let source = Vec3::new(0.0, h + 0.5, 0.0);
    let light = Light::point(source, 1.0).unwrap();
    let kappa_per_sin = n * fiber.width() * fiber.opacity();
    // Fibers across the axis, slanted, and pointing at the light (along
    // y: a directional light along -y would see no fiber at all).
    for dir in [Vec3::X, Vec3::new(1.0, -1.0, 0.3), Vec3::Y] {
        let hair = fiber_slab(dir, n, s, h, 7);
        let t = shadow_of(&hair, &light, &fiber, 128);
        for x in [0.1f32, 0.25, 0.5, 0.75, 0.9] {
            let (got, want) = point_lit_means(&t, source, kappa_per_sin, dir, h, x, 0.35);
            assert!(
                (got - want).abs() < 0.01,
                "fibers along {dir}, depth {x}: T = {got}, Beer-Lambert {want}"
            );
            if dir == Vec3::Y && x >= 0.5 {
                assert!(
                    want < 0.9,
                    "off the axis, rays cross upright fibers: {want}"
                );
            }
        }
        // Between the light and the hair the light is whole.
        for p in [Vec3::new(0.0, h + 0.01, 0.0), Vec3::new(0.2, h + 0.3, -0.1)] {
            assert_eq!(t.transmittance_at(p, true), 1.0, "{p}");
            assert_eq!(t.transmittance_at(p, false), 1.0, "{p}");
        }
    }
}

#[test]
fn a_point_light_far_away_casts_the_directional_shadow() {
    let fiber = Fiber::new(0.0004, 0.5).unwrap();
    let hair = fiber_slab(Vec3::new(1.0, -0.4, 0.3), 8000.0, 0.6, 1.0, 11);
    let far = Light::point(Vec3::new(0.0, 1e4, 0.0), 1e8).unwrap();
    let sun = Light::directional(Vec3::NEG_Y).unwrap();
    let (a, b) = (
        shadow_of(&hair, &far, &fiber, 128),
        shadow_of(&hair, &sun, &fiber, 128),
    );
    for x in [0.1f32, 0.5, 0.9] {
        let got = mean_t_at_depth(&a, 1.0, x, 0.4, Quat::IDENTITY);
        let want = mean_t_at_depth(&b, 1.0, x, 0.4, Quat::IDENTITY);
        assert!(
            (got - want).abs() < 0.01,
            "depth {x}: point {got}, directional {want}"
        );
    }
}
