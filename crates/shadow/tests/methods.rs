//! Every shadow method against the slab's Beer-Lambert answer, and the
//! invariants all of them keep: T in [0, 1], never increasing along the
//! light.

use common::fiber_slab;
use glam::Vec3;
use shadow::{
    Beyond, Fiber, Light, MethodConfig, Occluder, OpacityMode, ShadowInput, ShadowMethod,
};
use strands::{Hair, Rng, Style, StyleParams, WispModel};

mod common;

const FIBER: (f32, f32) = (0.0004, 0.5);
const SLAB: (f32, f32, f32) = (0.6, 1.0, 10_000.0);
const THETA_DEG: f32 = 60.0;

fn run(config: &MethodConfig, hair: &Hair, light: &Light, occluders: &[Occluder]) -> ShadowMethod {
    let fiber = Fiber::new(FIBER.0, FIBER.1).unwrap();
    let mut m = ShadowMethod::new(config).unwrap();
    let stats = m
        .density(&ShadowInput {
            light,
            hair,
            fiber: &fiber,
            occluders,
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

fn slab() -> (Hair, f32) {
    let (s, h, n) = SLAB;
    let theta = THETA_DEG.to_radians();
    let hair = fiber_slab(Vec3::new(theta.sin(), -theta.cos(), 0.0), n, s, h, 7);
    let kappa = n * FIBER.0 * FIBER.1 * theta.sin();
    (hair, kappa)
}

/// The fibers of `hair` (straight, two points each) clipped to `lo <= y <= hi`.
fn clip_y(hair: &Hair, lo: f32, hi: f32, out: &mut Hair) {
    for st in hair.strands() {
        let (a, b) = (st[0], st[st.len() - 1]);
        let at = |y: f32| a + (b - a) * ((y - a.y) / (b.y - a.y));
        let (ylo, yhi) = (a.y.min(b.y).max(lo), a.y.max(b.y).min(hi));
        if yhi > ylo {
            out.push_strand(&[at(ylo), at(yhi)]).unwrap();
        }
    }
}

/// Two layers of the slab, `0.75 <= y <= 1` and `0 <= y <= 0.4`, with
/// empty space between: the optical depth at depth `x` below the top is
/// `kappa` times the fiber layers' thickness above `1 - x`.
fn two_layers() -> (Hair, impl Fn(f32) -> f32) {
    let (slab, kappa) = slab();
    let mut hair = Hair::new();
    clip_y(&slab, 0.75, 1.0, &mut hair);
    clip_y(&slab, 0.0, 0.4, &mut hair);
    let truth = move |x: f32| {
        let y = 1.0 - x;
        let above = (1.0 - y.max(0.75)).max(0.0) + (0.4 - y.max(0.0)).max(0.0);
        (-kappa * above).exp()
    };
    (hair, truth)
}

/// Largest difference from `truth` of the mean T over a grid of points at
/// each of `depths` below the top face.
fn depth_error(m: &ShadowMethod, depths: &[f32], truth: impl Fn(f32) -> f32) -> f32 {
    let h = SLAB.1;
    let grid = 16;
    let inner = 0.4;
    depths
        .iter()
        .map(|&x| {
            let points: Vec<Vec3> = (0..grid * grid)
                .map(|i| {
                    let (a, b) = ((i % grid) as f32, (i / grid) as f32);
                    Vec3::new(
                        -inner + 2.0 * inner * (a + 0.5) / grid as f32,
                        h - x,
                        -inner + 2.0 * inner * (b + 0.5) / grid as f32,
                    )
                })
                .collect();
            let mut t = vec![0.0; points.len()];
            m.filter(&points, &mut t);
            let mean = t.iter().sum::<f32>() / t.len() as f32;
            (mean - truth(x)).abs()
        })
        .fold(0.0, f32::max)
}

fn slab_error(m: &ShadowMethod, kappa: f32) -> f32 {
    depth_error(m, &[0.1, 0.25, 0.5, 0.75, 0.9], |x| (-kappa * x).exp())
}

/// Settings of each method from coarse to fine.
fn ladders() -> Vec<Vec<MethodConfig>> {
    let osm = |slices| MethodConfig::OpacityShadowMap {
        resolution: 64,
        slices,
        mode: OpacityMode::Exponential { kappa: 1.0 },
        offset: 0.0,
        trilinear: true,
    };
    let dom = |layers| MethodConfig::DeepOpacityMap {
        resolution: 64,
        layers,
        layer_cells: 0.0,
        beyond: Beyond::Cover,
        trilinear: true,
    };
    let clu = |clusters| MethodConfig::DensityClustering {
        resolution: 64,
        clusters,
        trilinear: true,
    };
    let dsm = |tolerance| MethodConfig::DeepShadowMap {
        resolution: 64,
        tolerance,
        trilinear: true,
    };
    let dm = |cells| MethodConfig::DensityMap {
        cells,
        trilinear: true,
        contact: 0.0,
    };
    vec![
        vec![dm(8), dm(32), dm(128)],
        vec![osm(2), osm(8), osm(64)],
        vec![dom(1), dom(3), dom(8)],
        vec![clu(1), clu(2), clu(4)],
        vec![dsm(0.3), dsm(0.05), dsm(0.005)],
    ]
}

#[test]
fn every_method_matches_beer_lambert_in_a_uniform_slab() {
    let (hair, kappa) = slab();
    let light = Light::directional(Vec3::NEG_Y).unwrap();
    for ladder in ladders() {
        let finest = ladder.last().unwrap();
        let err = slab_error(&run(finest, &hair, &light, &[]), kappa);
        assert!(
            err < 0.02,
            "{} {}: off by {err}",
            finest.name(),
            finest.parameters()
        );
    }
}

#[test]
fn every_method_converges_to_beer_lambert_as_its_resolution_grows() {
    // Two fiber layers with a gap: coarse settings smear the gap's edges.
    let (hair, truth) = two_layers();
    let light = Light::directional(Vec3::NEG_Y).unwrap();
    let depths = [0.1, 0.2, 0.4, 0.5, 0.7, 0.85];
    for ladder in ladders() {
        let errors: Vec<f32> = ladder
            .iter()
            .map(|c| depth_error(&run(c, &hair, &light, &[]), &depths, &truth))
            .collect();
        let name = ladder[0].name();
        eprintln!("{name}: {errors:?}");
        assert!(
            errors[2] < 0.025,
            "{name}: error {errors:?} at the finest setting"
        );
        assert!(
            errors[2] < errors[0] && errors[1] < errors[0],
            "{name}: finer settings do not get closer: {errors:?}"
        );
    }
}

#[test]
fn coarse_opacity_maps_show_their_known_layering_error() {
    // Two slices put all the slab's opacity at its back plane and
    // interpolate linearly: exact for uniform density. A front-heavy slab
    // (fibers only in the top half) is where the coarse maps must fail.
    let (s, h, n) = SLAB;
    let theta = THETA_DEG.to_radians();
    let hair = fiber_slab(Vec3::new(theta.sin(), -theta.cos(), 0.0), n, s, h, 7);
    let top: Vec<Vec<Vec3>> = hair
        .strands()
        .filter_map(|st| {
            let (a, b) = (st[0], st[st.len() - 1]);
            // Clip each fiber to y >= 0.5.
            let clip = |p: Vec3, q: Vec3| p + (q - p) * ((0.5 - p.y) / (q.y - p.y));
            match (a.y >= 0.5, b.y >= 0.5) {
                (true, true) => Some(vec![a, b]),
                (true, false) => Some(vec![a, clip(a, b)]),
                (false, true) => Some(vec![clip(b, a), b]),
                _ => None,
            }
        })
        .collect();
    let mut half = Hair::new();
    for st in &top {
        half.push_strand(st).unwrap();
    }
    let light = Light::directional(Vec3::NEG_Y).unwrap();
    let coarse = MethodConfig::OpacityShadowMap {
        resolution: 64,
        slices: 2,
        mode: OpacityMode::Exponential { kappa: 1.0 },
        offset: 0.0,
        trilinear: true,
    };
    let m = run(&coarse, &half, &light, &[]);
    // Depth 0.25 into the half slab the truth is exp(-kappa 0.25). With the
    // half slab alone, the two planes are its own top and bottom and the
    // linear interpolation is exact for its uniform density.
    let truth = (-kappa_of() * 0.25).exp();
    let got = m.transmittance_at(Vec3::new(0.0, h - 0.25, 0.0));
    assert!(
        (got - truth).abs() < 0.05,
        "half slab alone: {got} vs {truth}"
    );
    let mut stretched = Hair::new();
    for st in &top {
        stretched.push_strand(st).unwrap();
    }
    stretched
        .push_strand(&[Vec3::new(-s, -3.0, 0.0), Vec3::new(s, -3.0, 0.0)])
        .unwrap();
    // A bundle far below stretches the planes: the interpolation now
    // spreads the slab's opacity over the whole range.
    let m = run(&coarse, &stretched, &light, &[]);
    let got = m.transmittance_at(Vec3::new(0.0, h - 0.25, 0.0));
    assert!(
        got - truth > 0.1,
        "two slices over a stretched range must underestimate the shadow: {got} vs {truth}"
    );
}

fn kappa_of() -> f32 {
    let theta = THETA_DEG.to_radians();
    SLAB.2 * FIBER.0 * FIBER.1 * theta.sin()
}

#[test]
fn the_reference_matches_the_slab_within_sampling_noise() {
    let (hair, kappa) = slab();
    let light = Light::directional(Vec3::NEG_Y).unwrap();
    let m = run(
        &MethodConfig::FootprintReference {
            footprint: None,
            rays: 64,
        },
        &hair,
        &light,
        &[],
    );
    // 256 points a depth, each footprint crossed by dozens of fibers: the
    // mean's sampling noise is well below the tolerance.
    let err = slab_error(&m, kappa);
    eprintln!("reference {err}");
    assert!(err < 0.02, "reference off Beer-Lambert by {err}");
}

#[test]
fn every_method_keeps_t_in_unit_range_and_non_increasing_along_the_light() {
    let hair = WispModel::generate(&StyleParams {
        strands_per_wisp: 4,
        ..StyleParams::new(Style::Curly)
    })
    .interpolate();
    let head = Occluder::sphere(Vec3::ZERO, 10.0);
    let mut rng = Rng::new(5);
    for dir in [Vec3::new(0.9, -0.35, -0.25), Vec3::NEG_Y, Vec3::X] {
        let light = Light::directional(dir).unwrap();
        let l = light.direction();
        let bounds = hair.bounds();
        // Rays of 40 points each along the light through the hair.
        let starts: Vec<Vec3> = (0..30)
            .map(|_| {
                let c = bounds.center();
                let s = bounds.size() * 0.5;
                c + Vec3::new(
                    rng.range(-s.x, s.x),
                    rng.range(-s.y, s.y),
                    rng.range(-s.z, s.z),
                ) - l * s.length()
            })
            .collect();
        let len = 2.0 * bounds.size().length();
        for name in MethodConfig::NAMES {
            let mut configs = vec![MethodConfig::with_defaults(name, 48).unwrap()];
            if *name == "opacity-shadow-map" {
                configs.push(MethodConfig::OpacityShadowMap {
                    resolution: 48,
                    slices: 8,
                    mode: OpacityMode::Linear,
                    offset: 0.5,
                    trilinear: false,
                });
            }
            if *name == "deep-opacity-map" {
                for beyond in [Beyond::Ignore, Beyond::Cover] {
                    configs.push(MethodConfig::DeepOpacityMap {
                        resolution: 48,
                        layers: 3,
                        layer_cells: 0.0,
                        beyond,
                        trilinear: true,
                    });
                }
            }
            for c in &configs {
                let m = run(c, &hair, &light, std::slice::from_ref(&head));
                for &s in &starts {
                    let mut prev = 1.0f32;
                    for i in 0..40 {
                        let p = s + l * (len * i as f32 / 39.0);
                        let t = m.transmittance_at(p);
                        assert!(
                            (0.0..=1.0).contains(&t),
                            "{} {}: T = {t} at {p}",
                            c.name(),
                            c.parameters()
                        );
                        assert!(
                            t <= prev + 1e-5,
                            "{} {}: T rises from {prev} to {t} at {p}",
                            c.name(),
                            c.parameters()
                        );
                        prev = t;
                    }
                }
            }
        }
    }
}

#[test]
fn every_method_gives_the_same_bytes_on_any_number_of_threads() {
    let hair = WispModel::generate(&StyleParams {
        strands_per_wisp: 3,
        ..StyleParams::new(Style::Smooth)
    })
    .interpolate();
    let head = [Occluder::sphere(Vec3::ZERO, 10.0)];
    let light = Light::directional(Vec3::new(0.9, -0.35, -0.25)).unwrap();
    let points: Vec<Vec3> = hair.points().iter().step_by(7).copied().collect();
    for name in MethodConfig::NAMES {
        let c = MethodConfig::with_defaults(name, 48).unwrap();
        let results: Vec<Vec<u32>> = [1, 2, 3]
            .into_iter()
            .map(|threads| {
                let pool = rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .build()
                    .unwrap();
                pool.install(|| {
                    let m = run(&c, &hair, &light, &head);
                    let mut t = vec![0.0f32; points.len()];
                    m.filter(&points, &mut t);
                    t.iter().map(|x| x.to_bits()).collect()
                })
            })
            .collect();
        assert!(
            results.windows(2).all(|w| w[0] == w[1]),
            "{name}: results differ between thread counts"
        );
    }
}

#[test]
fn every_method_and_the_reference_follow_a_close_point_light_along_every_ray() {
    // The slab lit by a point light half its thickness above it: each
    // ray's exact attenuation exp(-n w alpha sin(theta) L), averaged over
    // points of equal depth. The peer methods through the same partition
    // from the source (a perspective light view); the reference from the
    // fibers themselves.
    let (s, h, n) = SLAB;
    let theta = THETA_DEG.to_radians();
    let source = Vec3::new(0.0, h + 0.5, 0.0);
    let light = Light::point(source, 1.0).unwrap();
    let kappa_per_sin = n * FIBER.0 * FIBER.1;
    let grid = 16;
    let inner = 0.35;
    let error = |m: &ShadowMethod, dir: Vec3| {
        [0.1f32, 0.25, 0.5, 0.75, 0.9]
            .iter()
            .map(|&x| {
                let points: Vec<Vec3> = (0..grid * grid)
                    .map(|i| {
                        let (a, b) = ((i % grid) as f32, (i / grid) as f32);
                        Vec3::new(
                            -inner + 2.0 * inner * (a + 0.5) / grid as f32,
                            h - x,
                            -inner + 2.0 * inner * (b + 0.5) / grid as f32,
                        )
                    })
                    .collect();
                let want = points
                    .iter()
                    .map(|&p| {
                        let e = (p - source).normalize();
                        (-kappa_per_sin * e.cross(dir).length() * x / e.y.abs()).exp()
                    })
                    .sum::<f32>()
                    / points.len() as f32;
                let mut t = vec![0.0; points.len()];
                m.filter(&points, &mut t);
                let got = t.iter().sum::<f32>() / t.len() as f32;
                (got - want).abs()
            })
            .fold(0.0, f32::max)
    };
    let mut configs: Vec<MethodConfig> = ladders().into_iter().map(|l| l[2]).collect();
    configs.push(MethodConfig::FootprintReference {
        footprint: None,
        rays: 64,
    });
    // Slanted fibers, and fibers pointing up at the light.
    for dir in [Vec3::new(theta.sin(), -theta.cos(), 0.0), Vec3::Y] {
        let hair = fiber_slab(dir, n, s, h, 7);
        for c in &configs {
            let err = error(&run(c, &hair, &light, &[]), dir);
            assert!(
                err < 0.025,
                "fibers along {dir}: {} {}: off by {err}",
                c.name(),
                c.parameters()
            );
        }
    }
}
