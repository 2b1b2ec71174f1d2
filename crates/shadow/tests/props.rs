//! Property tests: random hair (with repeated points, one-point strands,
//! points on a lattice of round coordinates), random lights (axis-aligned
//! ones among them, point and spot lights) and random points, for every shadow method. Every
//! result is finite and in [0, 1], never increases along the light, and is
//! exactly 1 in front of all hair.

use glam::Vec3;
use proptest::prelude::*;
use shadow::{Fiber, Light, MethodConfig, Occluder, ShadowInput};
use strands::Hair;

/// A coordinate: mostly anywhere in [-5, 5], sometimes on a lattice of
/// halves (cell boundaries of round maps), sometimes exactly 0.
fn coord() -> impl Strategy<Value = f32> {
    prop_oneof![
        6 => -5.0f32..5.0,
        2 => (-10i32..=10).prop_map(|i| i as f32 * 0.5),
        1 => Just(0.0f32),
    ]
}

fn point() -> impl Strategy<Value = Vec3> {
    (coord(), coord(), coord()).prop_map(|(x, y, z)| Vec3::new(x, y, z))
}

/// A strand of 0 to 8 points, some repeated.
fn strand() -> impl Strategy<Value = Vec<Vec3>> {
    prop::collection::vec((point(), 1usize..=2), 0..8).prop_map(|pts| {
        pts.into_iter()
            .flat_map(|(p, n)| std::iter::repeat_n(p, n))
            .collect()
    })
}

fn hair() -> impl Strategy<Value = Hair> {
    prop::collection::vec(strand(), 1..24).prop_map(|strands| {
        let mut h = Hair::new();
        for s in &strands {
            h.push_strand(s).unwrap();
        }
        h
    })
}

/// A light direction: any, or along an axis (either way).
fn light() -> impl Strategy<Value = Light> {
    let any = (-1.0f32..1.0, -1.0f32..1.0, -1.0f32..1.0)
        .prop_filter("not zero", |(x, y, z)| x * x + y * y + z * z > 1e-4)
        .prop_map(|(x, y, z)| Vec3::new(x, y, z));
    let axis = (0usize..6).prop_map(|i| {
        [
            Vec3::X,
            Vec3::NEG_X,
            Vec3::Y,
            Vec3::NEG_Y,
            Vec3::Z,
            Vec3::NEG_Z,
        ][i]
    });
    let directional = prop_oneof![any.clone(), axis].prop_map(|d| Light::directional(d).unwrap());
    // Point and spot lights 20 to 60 away: outside the hair (within 9 of
    // the origin), which they see within 30 degrees of their axis.
    let at = (any.clone(), 20.0f32..60.0).prop_map(|(d, r)| d.normalize() * r);
    let point = (at.clone(), 1.0f32..1e4).prop_map(|(p, i)| Light::point(p, i).unwrap());
    let spot = (at, any, 1.0f32..89.0, 0.0f32..1.0, 1.0f32..1e4)
        .prop_map(|(p, d, cone, f, i)| Light::spot(p, d, cone, f * cone, i).unwrap());
    prop_oneof![2 => directional, 1 => point, 1 => spot]
}

fn method() -> impl Strategy<Value = MethodConfig> {
    (0..MethodConfig::NAMES.len(), 1u32..40)
        .prop_map(|(i, cells)| MethodConfig::with_defaults(MethodConfig::NAMES[i], cells).unwrap())
}

proptest! {
    #![proptest_config(ProptestConfig {
        cases: 512,
        // The same cases on every run (CI gates on them); set
        // PROPTEST_RNG_SEED to explore others.
        rng_seed: match ProptestConfig::default().rng_seed {
            proptest::test_runner::RngSeed::Random => proptest::test_runner::RngSeed::Fixed(0x5eed),
            chosen => chosen,
        },
        ..ProptestConfig::default()
    })]

    #[test]
    fn every_method_keeps_its_invariants_on_random_hair(
        hair in hair(),
        light in light(),
        config in method(),
        // A fiber has a width: Fiber::new refuses 0.
        width in 1e-4f32..0.5,
        opacity in 0.0f32..=1.0,
        starts in prop::collection::vec(point(), 1..8),
        head in prop::option::of((point(), 0.1f32..1.0)),
    ) {
        let fiber = Fiber::new(width, opacity).unwrap();
        let occluders: Vec<Occluder> = head.map(|(center, radius)| Occluder::sphere(center, radius)).into_iter().collect();
        let mut m = shadow::ShadowMethod::new(&config).unwrap();
        let stats = m.density(&ShadowInput { light: &light, hair: &hair, fiber: &fiber, occluders: &occluders, extent: None }).unwrap();
        prop_assert_eq!(stats.out_of_map, 0);
        m.transmittance();
        let l = light.direction();
        // Successive points of a ray are rounded across the light by an
        // ulp, and their map coordinates (up to 40 cells) by a few more:
        // about 1e-5 of a cell, which moves the bilinear weights between
        // columns by as much. Between a head's opaque column (optical depth
        // 30) and an empty one that is worth up to 3e-4; between columns of
        // fibers as wide as a cell, up to 1e-4. The reference's square footprint moves
        // with the points, and a fiber grazing its edge gains or loses
        // length in proportion; its head is sampled by `rays` rays, one of
        // which may flip where it grazes the sphere's silhouette.
        // The exact reference answers per ray: a fiber the ray grazes
        // within rounding (the points of a ray lie on it to an ulp, not
        // exactly) is met by one point's ray and missed by the next's, a
        // step of one fiber's opacity.
        let slack = match (config, occluders.is_empty()) {
            (MethodConfig::Reference { .. }, _) => opacity + 5e-4,
            (MethodConfig::FootprintReference { rays, .. }, false) => 1e-3 + 1.0 / rays as f32,
            (MethodConfig::FootprintReference { .. }, true) => 1e-3,
            (_, false) => 5e-4,
            (_, true) => 1e-4,
        };
        // Far enough along the light to cross all hair and the head
        // (coordinates lie in [-5, 5]^3, within 9 of the origin; the head's
        // radius is below 1).
        // For a light with a source, along rays from it.
        let ray = |s: Vec3| match light.source() {
            None => (s - l * (s.dot(l) + 10.0), l, 20.0),
            Some(src) => {
                let e = (s - src).normalize_or(Vec3::Y);
                (src + e, e, (s - src).length() + 10.0)
            }
        };
        for s in starts {
            let (front, l, reach) = ray(s);
            prop_assert_eq!(m.transmittance_at(front), 1.0, "{} in front of the hair", config.name());
            let mut prev = 1.0f32;
            for i in 0..=40 {
                let p = front + l * (reach * i as f32 / 40.0);
                // The exact reference answers a drawn point for its fiber:
                // rays spread across the fiber's width, the fiber itself
                // not counted. A probe is one ray that counts every fiber
                // it starts in. The property is about probes along a ray.
                if matches!(config, MethodConfig::Reference { .. }) && hair.points().contains(&p) {
                    continue;
                }
                let t = m.transmittance_at(p);
                prop_assert!(t.is_finite() && (0.0..=1.0).contains(&t), "{}: T = {} at {}", config.name(), t, p);
                prop_assert!(t <= prev + slack, "{}: T rises from {} to {} at {}", config.name(), prev, t, p);
                prev = t;
            }
        }
    }
}
