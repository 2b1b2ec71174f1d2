//! Hard cases, for every shadow method: extremely dense hair, lights along
//! the grid axes and along the strands, strands on cell boundaries,
//! degenerate strands, hair past a fixed map, hair far from the origin,
//! 1 and 512 cells a side, opacity 0 and 1, clustering with every fragment
//! at one depth and deep opacity layers of zero thickness.
//!
//! Each case checks the invariants every method keeps (finite T in [0, 1],
//! never increasing along the light, exactly 1 in front of all hair) and
//! the known answer where there is one.

use glam::Vec3;
use shadow::{
    Beyond, DensityMap, Fiber, Light, LightFrame, MethodConfig, Occluder, ShadowInput,
    ShadowMethod, Transmittance,
};
use strands::{Hair, Rng, Style, StyleParams, WispModel};

/// Every method at its defaults, `cells` a side.
fn every_method(cells: u32) -> Vec<MethodConfig> {
    MethodConfig::NAMES
        .iter()
        .map(|n| MethodConfig::with_defaults(n, cells).unwrap())
        .collect()
}

fn build(config: &MethodConfig, hair: &Hair, light: &Light, fiber: &Fiber) -> ShadowMethod {
    let mut m = ShadowMethod::new(config).unwrap();
    let stats = m
        .density(&ShadowInput {
            light,
            hair,
            fiber,
            occluders: &[],
            extent: None,
        })
        .unwrap();
    assert_eq!(
        stats.out_of_map,
        0,
        "{}: a fitted map holds all the hair",
        config.name()
    );
    m.transmittance();
    m
}

fn small_curly(seed: u64) -> Hair {
    let mut p = StyleParams::new(Style::Curly);
    p.seed = seed;
    p.strands_per_wisp = 2;
    WispModel::generate(&p).interpolate()
}

/// How far T may rise between successive points along a ray: rounding of
/// the points' own coordinates moves them across the light by up to an ulp,
/// into a column of slightly different depth.
const SLACK: f32 = 1e-5;

/// Checks the invariants of `m` on `rays` rays along the light through the
/// hair's bounds, 32 points each, starting in front of all hair; returns
/// the transmittance at every point, ray by ray.
fn check_invariants(
    what: &str,
    m: &ShadowMethod,
    hair: &Hair,
    light: &Light,
    rays: usize,
) -> Vec<Vec<f32>> {
    check_invariants_within(what, m, hair, light, rays, SLACK)
}

fn check_invariants_within(
    what: &str,
    m: &ShadowMethod,
    hair: &Hair,
    light: &Light,
    rays: usize,
    slack: f32,
) -> Vec<Vec<f32>> {
    let b = hair.bounds();
    let (c, half) = (b.center(), 0.5 * b.size());
    let reach = half.length() + 1e-3 * (1.0 + c.abs().max_element());
    let mut rng = Rng::new(11);
    let mut out = Vec::with_capacity(rays);
    for _ in 0..rays {
        let across = Vec3::new(
            rng.range(-half.x, half.x),
            rng.range(-half.y, half.y),
            rng.range(-half.z, half.z),
        );
        // Start a little beyond the hair's bounding sphere towards the
        // light (for a light with a source, on the ray from it).
        let (start, l, length) = match light.source() {
            None => {
                let l = light.direction();
                (
                    c + across - l * (across.dot(l) + 1.05 * reach),
                    l,
                    2.1 * reach,
                )
            }
            Some(s) => {
                // Before the ray enters the hair's bounding sphere.
                let l = (c + across - s).normalize();
                let d = (c - s).dot(l);
                (s + l * (d - 1.05 * reach).max(0.0), l, 2.1 * reach)
            }
        };
        let mut prev = 1.0f32;
        let mut ray = Vec::with_capacity(32);
        for i in 0..32 {
            let p = start + l * (length * i as f32 / 31.0);
            let t = m.transmittance_at(p);
            assert!(
                t.is_finite() && (0.0..=1.0).contains(&t),
                "{what}: T = {t} at {p}"
            );
            if i == 0 {
                assert_eq!(t, 1.0, "{what}: T = {t} in front of all hair at {p}");
            }
            assert!(
                t <= prev + slack,
                "{what}: T rises from {prev} to {t} at {p}"
            );
            prev = t;
            ray.push(t);
        }
        out.push(ray);
    }
    out
}

/// 400 points spread over the middle of `hair`'s bounds (seeded).
fn points_in(hair: &Hair, seed: u64) -> Vec<Vec3> {
    let b = hair.bounds();
    let mut rng = Rng::new(seed);
    (0..400)
        .map(|_| {
            let u = Vec3::new(
                rng.range(-1.0, 1.0),
                rng.range(-1.0, 1.0),
                rng.range(-1.0, 1.0),
            );
            b.center() + 0.5 * b.size() * u
        })
        .collect()
}

/// `count` straight fibers of two points, each through a random point of a
/// ball of radius `r` around `c`, in random directions, `len` long.
fn bundle(count: usize, c: Vec3, r: f32, len: f32, seed: u64) -> Hair {
    let mut rng = Rng::new(seed);
    let mut hair = Hair::new();
    for _ in 0..count {
        let p = c + r * Vec3::new(
            rng.range(-1.0, 1.0),
            rng.range(-1.0, 1.0),
            rng.range(-1.0, 1.0),
        );
        let d = Vec3::new(
            rng.range(-1.0, 1.0),
            rng.range(-1.0, 1.0),
            rng.range(-1.0, 1.0),
        )
        .normalize_or(Vec3::X);
        hair.push_strand(&[p - 0.5 * len * d, p + 0.5 * len * d])
            .unwrap();
    }
    hair
}

#[test]
fn extremely_dense_hair_keeps_optical_depth_finite_and_leaves_no_light() {
    // 4000 opaque fibers 0.05 thick through a ball of radius 0.05: optical
    // depth through the core is in the thousands, far past where exp(-D)
    // underflows to 0.
    let hair = bundle(4000, Vec3::ZERO, 0.05, 1.0, 3);
    let fiber = Fiber::new(0.05, 1.0).unwrap();
    let light = Light::directional(Vec3::new(0.3, -1.0, 0.2)).unwrap();
    let behind = 0.6 * light.direction();
    for c in every_method(32) {
        let m = build(&c, &hair, &light, &fiber);
        check_invariants(c.name(), &m, &hair, &light, 12);
        let t = m.transmittance_at(behind);
        assert!(t < 1e-3, "{}: T = {t} behind the dense core", c.name());
    }
    // The density map stores optical depth, not its exponential: the depth
    // behind the core is finite, large and grows no further past the hair.
    let frame = LightFrame::fit(&light, hair.points(), 32).unwrap();
    let mut map = DensityMap::new(frame);
    map.fill(&hair, &fiber);
    let t = Transmittance::compute(&map);
    let d = t.optical_depth(behind, true);
    assert!(
        d.is_finite() && d > 100.0,
        "optical depth {d} behind the core"
    );
    // Further along the light the across-light coordinates (the filter's
    // weights) may differ in their last bit, nothing more.
    let further = t.optical_depth(behind + light.direction(), true);
    assert!(
        (further - d).abs() <= 1e-6 * d,
        "optical depth {further} further on, {d} behind the core"
    );
}

#[test]
fn lights_along_the_grid_axes_and_straight_up_or_down_do_not_degenerate() {
    let hair = small_curly(1);
    let fiber = Fiber::new(0.01, 0.6).unwrap();
    for d in [
        Vec3::X,
        Vec3::NEG_X,
        Vec3::Y,
        Vec3::NEG_Y,
        Vec3::Z,
        Vec3::NEG_Z,
        Vec3::new(1e-7, -1.0, 0.0),
        Vec3::new(0.0, 1.0, -1e-7),
    ] {
        let light = Light::directional(d).unwrap();
        for c in every_method(24) {
            let m = build(&c, &hair, &light, &fiber);
            let rays = check_invariants(&format!("{} light {d}", c.name()), &m, &hair, &light, 24);
            // Some ray crosses hair and loses light.
            assert!(
                rays.iter().any(|r| r[31] < 0.99),
                "{} light {d}: no ray is shadowed",
                c.name()
            );
        }
    }
}

#[test]
fn fibers_along_the_light_block_nothing_in_the_density_map() {
    // Extinction per unit length is w alpha sin(theta): zero along the light.
    let light = Light::directional(Vec3::new(0.2, -1.0, 0.1)).unwrap();
    let l = light.direction();
    let (u, v) = l.any_orthonormal_pair();
    let mut hair = Hair::new();
    let mut rng = Rng::new(2);
    for _ in 0..500 {
        let o = rng.range(-1.0, 1.0) * u + rng.range(-1.0, 1.0) * v;
        hair.push_strand(&[o, o + 0.5 * l, o + 2.0 * l]).unwrap();
    }
    let fiber = Fiber::new(0.01, 1.0).unwrap();
    for c in every_method(32) {
        let m = build(&c, &hair, &light, &fiber);
        let rays = check_invariants(c.name(), &m, &hair, &light, 24);
        if matches!(c, MethodConfig::DensityMap { .. }) {
            assert!(
                rays.iter().flatten().all(|&t| t == 1.0),
                "density map: T < 1"
            );
        }
    }
}

#[test]
fn strands_on_cell_boundaries_cast_an_even_shadow() {
    // A sheet of fibers across the light, one per cell, each lying exactly
    // on the boundary between two columns and between two slices. Behind
    // it the optical depth is w alpha / ds everywhere inside the sheet.
    let light = Light::directional(Vec3::NEG_Y).unwrap();
    let n = 32;
    let frame = LightFrame::centered(&light, Vec3::ZERO, 4.0, n).unwrap();
    let mut hair = Hair::new();
    for j in 4..=28 {
        let a = frame.to_world(Vec3::new(16.0, j as f32, 4.0));
        let b = frame.to_world(Vec3::new(16.0, j as f32, 28.0));
        hair.push_strand(&[a, b]).unwrap();
    }
    let fiber = Fiber::new(0.02, 0.5).unwrap();
    let mut map = DensityMap::new(frame);
    let stats = map.fill(&hair, &fiber);
    assert_eq!(stats.out_of_map, 0);
    let t = Transmittance::compute(&map);
    let want = (-fiber.width() * fiber.opacity() / frame.ds).exp();
    for j in [8.0f32, 8.5, 12.25, 20.0, 23.9] {
        for k in [8.0f32, 16.5, 22.0] {
            for trilinear in [true, false] {
                let front = t.transmittance_at(frame.to_world(Vec3::new(14.5, j, k)), trilinear);
                let back = t.transmittance_at(frame.to_world(Vec3::new(18.5, j, k)), trilinear);
                assert_eq!(front, 1.0, "in front of the sheet at ({j}, {k})");
                assert!(
                    (back - want).abs() < 1e-3,
                    "behind the sheet at ({j}, {k}), filter {trilinear}: T = {back}, want {want}"
                );
            }
        }
    }
}

/// `hair` with degenerate pieces added: every point of every other strand
/// repeated (zero-length segments), one-point strands and a strand of one
/// point repeated, all inside the hair's bounds.
fn with_degenerate_strands(hair: &Hair) -> Hair {
    let mut out = Hair::new();
    let b = hair.bounds();
    for (s, st) in hair.strands().enumerate() {
        if s % 2 == 0 {
            let doubled: Vec<Vec3> = st.iter().flat_map(|&p| [p, p]).collect();
            out.push_strand(&doubled).unwrap();
        } else {
            out.push_strand(st).unwrap();
        }
        if s % 7 == 0 {
            out.push_strand(&[b.center()]).unwrap();
            out.push_strand(&[st[0]; 5]).unwrap();
        }
    }
    out.push_strand(&[]).unwrap();
    out
}

#[test]
fn zero_length_segments_repeated_points_and_one_point_strands_add_nothing() {
    let hair = small_curly(4);
    let odd = with_degenerate_strands(&hair);
    assert!(odd.strand_count() > hair.strand_count());
    let fiber = Fiber::new(0.01, 0.6).unwrap();
    let light = Light::directional(Vec3::new(0.4, -1.0, 0.3)).unwrap();
    let mut rng = Rng::new(8);
    let b = hair.bounds();
    let points: Vec<Vec3> = (0..400)
        .map(|_| {
            b.center()
                + 0.5
                    * b.size()
                    * Vec3::new(
                        rng.range(-1.0, 1.0),
                        rng.range(-1.0, 1.0),
                        rng.range(-1.0, 1.0),
                    )
        })
        .collect();
    for c in every_method(32) {
        let a = build(&c, &hair, &light, &fiber);
        let m = build(&c, &odd, &light, &fiber);
        check_invariants(c.name(), &m, &odd, &light, 12);
        for &p in &points {
            let (ta, tm) = (a.transmittance_at(p), m.transmittance_at(p));
            assert!(
                (ta - tm).abs() < 1e-5,
                "{}: T = {tm} with degenerate strands, {ta} without, at {p}",
                c.name()
            );
        }
    }
}

#[test]
fn hair_past_a_fixed_map_is_counted_and_never_wraps_into_it() {
    // A map of side 2 around the origin; light along -y. One strand inside,
    // one past the map's side and one past its back: with the paper's
    // modulo both would land in the columns and slices of the map.
    let light = Light::directional(Vec3::NEG_Y).unwrap();
    let n = 16;
    let frame = LightFrame::centered(&light, Vec3::ZERO, 2.0, n).unwrap();
    let ds = frame.ds;
    let inside = frame.to_world(Vec3::new(8.0, 4.5, 2.0));
    let along = frame.to_world(Vec3::new(8.0, 4.5, 14.0)) - inside;
    let mut hair = Hair::new();
    hair.push_strand(&[inside, inside + along]).unwrap();
    // One map side further across the light: wraps onto column j = 4.5 + 0.
    let side = frame.to_world(Vec3::new(8.0, 4.5 + n as f32, 2.0));
    hair.push_strand(&[side, side + along]).unwrap();
    // One map side further along the light, in column j = 10.5.
    let back = frame.to_world(Vec3::new(8.0 + n as f32, 10.5, 2.0));
    hair.push_strand(&[back, back + along]).unwrap();
    let fiber = Fiber::new(0.05, 1.0).unwrap();
    let mut map = DensityMap::new(frame);
    let stats = map.fill(&hair, &fiber);
    assert!(stats.out_of_map > 0, "samples outside the map are counted");
    assert!(stats.samples > 0);
    let t = Transmittance::compute(&map);
    // The strand inside shadows its own column...
    let behind_inside = t.transmittance_at(frame.to_world(Vec3::new(12.0, 4.5, 8.0)), true);
    assert!(
        behind_inside < 0.9,
        "T = {behind_inside} behind the strand inside"
    );
    // ... and the wrapped positions of the others get no false shadow:
    // nothing lies in column j = 10.5, and the side strand's shadow on j =
    // 4.5 is the inside strand's own.
    let other = t.transmittance_at(frame.to_world(Vec3::new(12.0, 10.5, 8.0)), true);
    assert_eq!(
        other, 1.0,
        "a false shadow from hair past the back of the map"
    );
    let mut only_inside = Hair::new();
    only_inside.push_strand(&[inside, inside + along]).unwrap();
    let mut map1 = DensityMap::new(frame);
    map1.fill(&only_inside, &fiber);
    let t1 = Transmittance::compute(&map1);
    for x in [6.0, 9.0, 15.5] {
        let p = frame.to_world(Vec3::new(x, 4.5, 8.0));
        assert_eq!(
            t.transmittance_at(p, true),
            t1.transmittance_at(p, true),
            "at slice {x}"
        );
    }
    // Points outside the map see no hair (nothing known there) or, behind
    // it, the column's total.
    assert_eq!(
        t.transmittance_at(frame.to_world(Vec3::new(8.0, 4.5 + n as f32, 8.0)), true),
        1.0
    );
    let far_behind = t.transmittance_at(frame.to_world(Vec3::new(40.0, 4.5, 8.0)), true);
    assert!((far_behind - behind_inside).abs() < 1e-6 && ds > 0.0);
}

#[test]
fn hair_far_from_the_origin_shadows_like_hair_at_the_origin() {
    let hair = small_curly(5);
    let offset = Vec3::new(1e5, -1e5, 1e5);
    let mut far = Hair::new();
    for st in hair.strands() {
        let moved: Vec<Vec3> = st.iter().map(|&p| p + offset).collect();
        far.push_strand(&moved).unwrap();
    }
    let fiber = Fiber::new(0.01, 0.6).unwrap();
    let light = Light::directional(Vec3::new(0.4, -1.0, 0.3)).unwrap();
    let points = points_in(&hair, 9);
    for c in every_method(32) {
        let near = build(&c, &hair, &light, &fiber);
        let m = build(&c, &far, &light, &fiber);
        // At 1e5 a point's coordinates are multiples of 1/128: successive
        // points of a ray zigzag across it by up to that much.
        check_invariants_within(c.name(), &m, &far, &light, 12, 5e-3);
        // Coordinates near 1e5 carry 1/128 of a unit of rounding: compare
        // the mean, which such jitter moves little.
        let diff: f32 = points
            .iter()
            .map(|&p| (near.transmittance_at(p) - m.transmittance_at(p + offset)).abs())
            .sum::<f32>()
            / points.len() as f32;
        assert!(
            diff < 0.02,
            "{}: mean |dT| = {diff} at offset {offset}",
            c.name()
        );
    }
}

#[test]
fn one_cell_and_512_cells_a_side_keep_every_invariant() {
    let hair = small_curly(6);
    let fiber = Fiber::new(0.01, 0.6).unwrap();
    let light = Light::directional(Vec3::new(0.4, -1.0, 0.3)).unwrap();
    for cells in [1, 2, 512] {
        for c in every_method(cells) {
            if cells == 512 && matches!(c, MethodConfig::FootprintReference { .. }) {
                continue; // no resolution
            }
            let m = build(&c, &hair, &light, &fiber);
            // 512 cells: a coordinate's rounding is a larger share of a cell.
            let slack = SLACK * cells.max(64) as f32 / 64.0;
            let what = format!("{} at {cells}", c.name());
            let rays = check_invariants_within(&what, &m, &hair, &light, 12, slack);
            assert!(
                rays.iter().any(|r| r[31] < 0.999),
                "{} at {cells}: no shadow",
                c.name()
            );
        }
    }
}

#[test]
fn opacity_zero_casts_no_shadow_and_opacity_one_the_darkest() {
    let hair = small_curly(7);
    let light = Light::directional(Vec3::new(0.4, -1.0, 0.3)).unwrap();
    let points = points_in(&hair, 10);
    for c in every_method(32) {
        let clear = build(&c, &hair, &light, &Fiber::new(0.01, 0.0).unwrap());
        let half = build(&c, &hair, &light, &Fiber::new(0.01, 0.5).unwrap());
        let full = build(&c, &hair, &light, &Fiber::new(0.01, 1.0).unwrap());
        check_invariants(c.name(), &full, &hair, &light, 12);
        for &p in &points {
            assert_eq!(
                clear.transmittance_at(p),
                1.0,
                "{}: opacity 0 casts a shadow at {p}",
                c.name()
            );
            let (h, f) = (half.transmittance_at(p), full.transmittance_at(p));
            assert!(
                f <= h + 1e-5,
                "{}: opacity 1 gives T = {f} > {h} at opacity 0.5",
                c.name()
            );
        }
    }
}

#[test]
fn a_sheet_at_one_depth_gives_its_known_shadow_in_every_method() {
    // Fibers in one plane across the light, spacing `gap`: every fragment
    // at the same depth (clustering's sigma = 0, a deep opacity layer of
    // no thickness). Behind the sheet D = w alpha / gap.
    let light = Light::directional(Vec3::NEG_Y).unwrap();
    let gap = 0.02;
    let mut hair = Hair::new();
    for a in 0..=100 {
        let x = -1.0 + gap * a as f32;
        hair.push_strand(&[Vec3::new(x, 0.0, -1.0), Vec3::new(x, 0.0, 1.0)])
            .unwrap();
    }
    let fiber = Fiber::new(0.01, 0.6).unwrap();
    let want = (-fiber.width() * fiber.opacity() / gap).exp();
    let mut configs = every_method(32);
    for beyond in [Beyond::Ignore, Beyond::LastLayer, Beyond::Cover] {
        configs.push(MethodConfig::DeepOpacityMap {
            resolution: 32,
            layers: 3,
            layer_cells: 0.0,
            beyond,
            trilinear: true,
        });
    }
    configs.push(MethodConfig::DensityClustering {
        resolution: 32,
        clusters: 1,
        trilinear: false,
    });
    // The reference over a footprint of many fiber spacings: the mean.
    for c in configs.iter_mut() {
        if let MethodConfig::FootprintReference { footprint, .. } = c {
            *footprint = Some(20.0 * gap);
        }
    }
    for c in &configs {
        let m = build(c, &hair, &light, &fiber);
        let what = format!("{} {}", c.name(), c.parameters());
        check_invariants(&what, &m, &hair, &light, 12);
        for x in [-0.5f32, 0.0, 0.31] {
            for z in [-0.5f32, 0.2] {
                assert_eq!(
                    m.transmittance_at(Vec3::new(x, 0.5, z)),
                    1.0,
                    "{what}: in front"
                );
                // The exact reference is exact per ray: a point behind a
                // fiber is in its shadow, one between two is not; the mean
                // over many points is the sheet's shadow.
                let t = if matches!(c, MethodConfig::Reference { .. }) {
                    (0..200)
                        .map(|i| m.transmittance_at(Vec3::new(x + gap * i as f32 / 97.0, -0.5, z)))
                        .sum::<f32>()
                        / 200.0
                } else {
                    m.transmittance_at(Vec3::new(x, -0.5, z))
                };
                assert!(t.is_finite());
                let ignores = matches!(
                    c,
                    MethodConfig::DeepOpacityMap {
                        beyond: Beyond::Ignore,
                        ..
                    }
                );
                if matches!(c, MethodConfig::Reference { .. }) {
                    // Exact for one sheet: a ray meets a fiber with
                    // probability w / gap, and loses alpha of its light.
                    let exact = 1.0 - fiber.opacity() * fiber.width() / gap;
                    assert!(
                        (t - exact).abs() < 0.02,
                        "{what}: T = {t} behind the sheet, want {exact}"
                    );
                } else if !ignores {
                    assert!(
                        (t - want).abs() < 0.05,
                        "{what}: T = {t} behind the sheet, want {want}"
                    );
                }
            }
        }
    }
}

#[test]
fn a_widely_spread_cluster_casts_nothing_in_front_of_its_hair() {
    // Two sheets far apart along the light, one cluster per pixel: its
    // histogram bin (mean +- sqrt(3) sigma) would start well in front of
    // the first sheet.
    let light = Light::directional(Vec3::NEG_Y).unwrap();
    let mut hair = Hair::new();
    for y in [0.0f32, -10.0] {
        for a in 0..=20 {
            let x = -1.0 + 0.1 * a as f32;
            hair.push_strand(&[Vec3::new(x, y, -1.0), Vec3::new(x, y, 1.0)])
                .unwrap();
        }
    }
    let fiber = Fiber::new(0.01, 0.6).unwrap();
    let c = MethodConfig::DensityClustering {
        resolution: 16,
        clusters: 1,
        trilinear: true,
    };
    let m = build(&c, &hair, &light, &fiber);
    for y in [3.0f32, 1.0, 0.05] {
        assert_eq!(
            m.transmittance_at(Vec3::new(0.05, y, 0.0)),
            1.0,
            "T < 1 at y = {y}, in front of all hair"
        );
    }
    assert!(m.transmittance_at(Vec3::new(0.05, -11.0, 0.0)) < 1.0);
}

#[test]
fn point_and_spot_lights_keep_every_invariant_in_the_hard_cases() {
    // Dense hair, degenerate strands, hair far from the origin, one cell
    // and 512 cells, lit by a point light close to the hair and by a spot
    // light: every method finite, in [0, 1], 1 in front of all hair and
    // never rising along a ray from the source.
    let fiber = Fiber::new(0.05, 1.0).unwrap();
    let dense = bundle(4000, Vec3::ZERO, 0.05, 1.0, 3);
    let curly = small_curly(2);
    let degenerate = with_degenerate_strands(&curly);
    let far = {
        let mut h = Hair::new();
        for st in curly.strands() {
            let moved: Vec<Vec3> = st.iter().map(|&p| p + Vec3::splat(1e4)).collect();
            h.push_strand(&moved).unwrap();
        }
        h
    };
    for (what, hair) in [
        ("dense", &dense),
        ("degenerate", &degenerate),
        ("far", &far),
    ] {
        let b = hair.bounds();
        let r = 0.5 * b.size().length();
        let lights = [
            Light::point(
                b.center() + Vec3::new(0.3, 1.0, 0.2).normalize() * 1.5 * r,
                1.0,
            )
            .unwrap(),
            Light::spot(
                b.center() + Vec3::new(-1.0, 0.5, 0.3).normalize() * 3.0 * r,
                Vec3::new(1.0, -0.5, -0.3),
                30.0,
                5.0,
                1.0,
            )
            .unwrap(),
        ];
        for light in &lights {
            for cells in [1, 32] {
                for c in every_method(cells) {
                    let m = build(&c, hair, light, &fiber);
                    // The reference's footprint moves with the points, which
                    // at 1e4 from the origin round by 1e-3 across the ray.
                    let slack = if c.name().ends_with("reference") {
                        2e-3
                    } else {
                        1e-4
                    };
                    check_invariants_within(
                        &format!("{what} {} {cells}", c.name()),
                        &m,
                        hair,
                        light,
                        8,
                        slack,
                    );
                }
            }
        }
    }
    // 512 cells a side, the density map.
    let light = Light::point(Vec3::new(0.0, 40.0, 0.0), 1.0).unwrap();
    let m = build(
        &MethodConfig::DensityMap {
            cells: 512,
            trilinear: true,
            contact: 0.0,
        },
        &curly,
        &light,
        &Fiber::new(0.01, 0.6).unwrap(),
    );
    check_invariants("512", &m, &curly, &light, 8);
}

#[test]
fn a_head_casts_its_shadow_along_the_rays_of_a_point_light() {
    // A sphere under a point light: points inside its shadow cone are dark
    // in every method, one outside it is lit.
    let mut hair = Hair::new();
    hair.push_strand(&[Vec3::new(-3.0, -2.0, -3.0), Vec3::new(3.0, -2.5, 3.0)])
        .unwrap();
    let fiber = Fiber::new(0.01, 0.5).unwrap();
    let head = [Occluder::sphere(Vec3::ZERO, 1.0)];
    let light = Light::point(Vec3::new(0.0, 3.0, 0.0), 9.0).unwrap();
    // Behind the sphere from the source, and 1.3 off the axis: the
    // shadow cone from the source has half-angle asin(1 / 3), so at
    // y = -2.2 (5.2 from it) its radius is 5.2 tan(19.5 deg) = 1.84, where
    // parallel rays along -y would leave a shadow of radius 1.
    let (behind, spread) = (Vec3::new(0.0, -2.2, 0.0), Vec3::new(1.3, -2.2, 0.0));
    let outside = Vec3::new(2.6, -2.2, 0.0);
    for c in every_method(64) {
        let mut m = ShadowMethod::new(&c).unwrap();
        m.density(&ShadowInput {
            light: &light,
            hair: &hair,
            fiber: &fiber,
            occluders: &head,
            extent: None,
        })
        .unwrap();
        m.transmittance();
        let name = c.name();
        assert!(
            m.transmittance_at(behind) < 0.05,
            "{name}: behind the head {}",
            m.transmittance_at(behind)
        );
        assert!(
            m.transmittance_at(spread) < 0.05,
            "{name}: in the spreading shadow {}",
            m.transmittance_at(spread)
        );
        assert!(
            m.transmittance_at(outside) > 0.95,
            "{name}: outside it {}",
            m.transmittance_at(outside)
        );
    }
}
