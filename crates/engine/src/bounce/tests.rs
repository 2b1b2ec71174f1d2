use super::*;

#[test]
fn a_uniform_head_gives_its_radiance_times_the_solid_angle() {
    // A head of radiance 1 everywhere: E_h = Omega, from the cone's
    // half-angle alone.
    let c = Vec3::new(1.0, 2.0, 3.0);
    let h = HeadLight::new(HeadShape::sphere(c, 2.0), |_, _| Vec3::ONE);
    for d in [2.0f32, 2.5, 4.0, 20.0] {
        for n in [
            Vec3::X,
            Vec3::Y,
            -Vec3::Y,
            Vec3::new(0.3, -0.5, 0.8).normalize(),
        ] {
            let (to, e, height) = h.at(c + d * n).unwrap();
            let alpha = (2.0 / d).asin();
            let omega = 2.0 * PI * (1.0 - alpha.cos());
            assert!(
                (e - Vec3::splat(omega)).abs().max_element() < 1e-4,
                "{d} {n}: {e}"
            );
            assert!((to + n).length() < 1e-6);
            assert!((height - (d - 2.0)).abs() < 1e-5);
        }
    }
    // On the surface, a hemisphere: 2 pi.
    let (_, e, _) = h.at(c + 2.0 * Vec3::Z).unwrap();
    assert!((e.x - 2.0 * PI).abs() < 1e-4);
    assert!(h.at(c).is_none());
}

#[test]
fn a_head_lit_from_one_side_sends_light_to_that_side() {
    // Radiance max(n . x, 0): the far side's hair gets none. Hair on
    // the lit pole sees the point under it (radiance 1) fill a
    // hemisphere of directions; hair far off sees the lit hemisphere
    // of the head, whose mean radiance by area is 1/2.
    let h = HeadLight::new(HeadShape::sphere(Vec3::ZERO, 1.0), |_, n| {
        Vec3::splat(n.x.max(0.0))
    });
    let (_, far, _) = h.at(-3.0 * Vec3::X).unwrap();
    assert!(far.x < 1e-3, "{far}");
    let (_, near, _) = h.at(1.0 * Vec3::X).unwrap();
    let mean = near.x / (2.0 * PI);
    assert!((mean - 1.0).abs() < 0.03, "{mean}");
    let (_, distant, _) = h.at(50.0 * Vec3::X).unwrap();
    let omega = 2.0 * PI * (1.0 - (1.0f32 - 1.0 / 2500.0).sqrt());
    let mean = distant.x / omega;
    assert!((mean - 0.5).abs() < 0.04, "{mean}");
}

#[test]
fn a_mesh_head_is_its_outermost_surface_and_none_through_a_hole() {
    // A cube of side 2 about (0, 1, 0), its bottom face left open.
    let obj = "v -1 0 -1\nv 1 0 -1\nv 1 0 1\nv -1 0 1\nv -1 2 -1\nv 1 2 -1\nv 1 2 1\nv -1 2 1\n\
               f 5 6 7\nf 5 7 8\nf 1 2 6\nf 1 6 5\nf 2 3 7\nf 2 7 6\nf 3 4 8\nf 3 8 7\n\
               f 4 1 5\nf 4 5 8\n";
    let mesh = strands::load_mesh_bytes(std::path::Path::new("cube.obj"), obj.as_bytes()).unwrap();
    let s = Surface::mesh(&mesh, Vec3::Y);
    for (k, at) in s.at.iter().enumerate() {
        let (d, _) = direction(k / N_PHI, k % N_PHI);
        // Rays through the open bottom find nothing; the others the
        // face they leave by, at 1 / max |d_i|.
        let leaves_by_bottom = -d.y >= d.x.abs().max(d.z.abs());
        match at {
            None => assert!(leaves_by_bottom, "{d}"),
            Some((r, n)) => {
                assert!(!leaves_by_bottom, "{d}");
                let want = 1.0 / d.abs().max_element();
                assert!((r - want).abs() < 1e-4, "{d}: {r} against {want}");
                assert!(n.dot(d) > 0.0 && (n.length() - 1.0).abs() < 1e-5);
            }
        }
    }
    // No light from under the hole: the radius there is 0.
    let shape = HeadShape {
        center: Vec3::Y,
        to_own: Mat3A::IDENTITY,
        from_own: Mat3A::IDENTITY,
        surface: Arc::new(s),
    };
    let h = HeadLight::new(shape, |_, _| Vec3::ONE);
    assert!(h.at(Vec3::new(0.0, -5.0, 0.0)).is_none());
    let (_, _, height) = h.at(Vec3::new(0.0, 4.0, 0.0)).unwrap();
    assert!((height - 2.0).abs() < 0.05, "{height}");
    let (_, e, _) = h.at(Vec3::new(0.0, 1.0, 1.0)).unwrap();
    assert!((e.x - 2.0 * PI).abs() < 1e-3, "{e}");
}

#[test]
fn the_polynomial_atan2_is_within_its_bound_all_round() {
    for k in 0..3600 {
        let a = k as f32 * 0.1f32.to_radians() - PI;
        for r in [1e-3f32, 1.0, 7.0] {
            let (y, x) = (r * a.sin(), r * a.cos());
            let d = (atan2_approx(y, x) - y.atan2(x)).abs();
            let d = d.min((d - 2.0 * PI).abs());
            assert!(d < 0.005, "{a}: off by {d}");
        }
    }
    assert_eq!(atan2_approx(0.0, 0.0), 0.0);
}

#[test]
fn the_heads_light_crosses_the_hair_on_slanted_paths() {
    // From a point (far from the head) every ray is radial.
    for tau in [0.1f32, 1.0, 5.0] {
        assert!((slant_depth(0.0, tau) - tau).abs() < 1e-3 * tau.max(1.0));
    }
    // At the surface, a flat layer under a hemisphere: exp(-tau_h) =
    // E_2(tau) = exp(-tau) - tau E_1(tau), from tables of E_1.
    for (tau, e2) in [(0.5f32, 0.326_644f32), (1.0, 0.148_496), (2.0, 0.037_534)] {
        let t = (-slant_depth(1.0, tau)).exp();
        assert!((t / e2 - 1.0).abs() < 0.02, "tau {tau}: {t} against {e2}");
    }
    // The nearer the head, the wider the cone and the longer the paths.
    let mut last = 0.0;
    for k in 0..=10 {
        let d = slant_depth(k as f32 / 10.0, 2.0);
        assert!(d >= last - 1e-4 && d.is_finite(), "{k}: {d}");
        last = d;
    }
    assert_eq!(slant_depth(0.7, 0.0), 0.0);
    assert_eq!(slant_depth(0.7, f32::NAN), 0.0);
}

#[test]
fn the_sky_comes_through_the_hair_over_both_halves_of_the_sphere() {
    // No hair: all of it; on the bare surface of the head under no
    // hair, the outer half (the inner is the head's, taken off apart).
    assert!((sky_transmittance(0.0, 0.0) - 1.0).abs() < 1e-6);
    // Each half through a flat layer: E_2 (tables: E_2(0.25) =
    // 0.517730, E_2(1) = 0.148496, E_2(4) = 0.003198).
    let cases = [
        (0.25f32, 1.0f32, 0.5 * (0.517_730 + 0.148_496)),
        (1.0, 4.0, 0.5 * (0.148_496 + 0.003_198)),
        (0.0, 1.0, 0.5 * (1.0 + 0.148_496)),
    ];
    for (tau_in, tau_out, want) in cases {
        for (a, b) in [(tau_in, tau_out), (tau_out, tau_in)] {
            let t = sky_transmittance(a, b);
            assert!((t / want - 1.0).abs() < 0.02, "{a} {b}: {t} against {want}");
        }
    }
    // Deep in hair on both sides, none; never more than 1 or below 0.
    assert!(sky_transmittance(40.0, 40.0) < 1e-6);
    for tau in [0.0f32, 0.3, 3.0, 30.0, f32::INFINITY] {
        let t = sky_transmittance(tau, 0.5 * tau);
        assert!((0.0..=1.0).contains(&t), "{tau}: {t}");
    }
}

#[test]
fn a_vertex_learns_the_skys_transmittance_once_the_map_holds_the_hair() {
    let c = Vec3::ZERO;
    let mut h = HeadLight::new(HeadShape::sphere(c, 1.0), |_, _| Vec3::ONE);
    let p = Vec3::new(0.0, 1.2, 0.0);
    assert_eq!(h.through_at(p).unwrap().sky, None);
    // A map whose every cell along the light holds optical depth 0.5
    // per cell: a uniform layer about the head.
    let light = Light::directional(Vec3::NEG_Y).unwrap();
    let cell = 0.1;
    let lookup = |pts: &[Vec3], out: &mut [f32]| {
        for (o, q) in out.iter_mut().zip(pts) {
            // Depth grows along the light (-y): exp(-0.5 per cell).
            *o = (-(0.5 / cell) * (10.0 - q.y)).exp();
        }
    };
    h.through_hair(&light, cell, 32, HairIn::Lookup(&lookup));
    let at = h.through_at(p).unwrap();
    let sky = at.sky.expect("the map holds the hair");
    // Extinction 5 per unit length every way: 0.2 over the surface,
    // tau_in = 1; the column reaches REACH_CELLS * 0.1 * 32 = 5.76
    // out, tau_out = 5 * 5.56 = 27.8, through which no sky comes.
    let want = 0.5 * 0.148_496;
    assert!((sky / want - 1.0).abs() < 0.03, "{sky} against {want}");
    // The head's own light comes through the same tau_in over its cone.
    let t = (-slant_depth(1.0 / 1.2, 1.0)).exp();
    assert!((at.t / t - 1.0).abs() < 0.01, "{} against {t}", at.t);
}

#[test]
fn the_swept_map_gives_the_hair_right_down_to_the_head() {
    // A sphere of radius 1 in a shell of hair 0.2 deep (extinction 5 a
    // unit), lit from above by the sun and by a point light: the map
    // holds the hair and the head's opaque deposit where the light enters
    // it.
    for light in [
        Light::directional(Vec3::NEG_Y).unwrap(),
        // (Far enough that the fan's cells are about as wide as deep.)
        Light::point(Vec3::new(1.0, 10.0, 0.5), 1.0).unwrap(),
    ] {
        let frame = shadow::LightFrame::centered(&light, Vec3::ZERO, 3.2, 32).unwrap();
        let cell = frame.ds;
        let mut map = shadow::DensityMap::new(frame);
        for i in 0..32 {
            for j in 0..32 {
                for k in 0..32 {
                    let c = Vec3::new(i as f32, j as f32, k as f32) + 0.5;
                    let x = map.frame().to_world(c);
                    // A ray crosses `cell` of the map's depth over a path
                    // as much longer as it slants (a fan's rays do).
                    let slant = match light.source() {
                        Some(s) => (x - s).length() / (x - s).dot(-s.normalize()),
                        None => 1.0,
                    };
                    if (1.0..1.2).contains(&x.length()) {
                        let q = (5.0 * cell * slant) as f64 / shadow::DEPTH_QUANTUM;
                        map.add_quanta(i, j, k, q as u32);
                    }
                }
            }
        }
        map.deposit_body(
            &shadow::Occluder::sphere(Vec3::ZERO, 1.0),
            shadow::OPAQUE_DEPTH,
        );
        let t = shadow::Transmittance::compute(&map);
        let mut h = HeadLight::new(HeadShape::sphere(Vec3::ZERO, 1.0), |_, _| Vec3::ONE);
        h.through_hair(&light, cell, 32, HairIn::Swept(&t, true));
        // Half way through the shell, on the lit top, at the side and in
        // the head's shadow below: 0.1 of hair between the vertex and the
        // head (tau 0.5), over the cone the head fills (the first clear
        // radius's extinction gave none).
        for n in [Vec3::Y, Vec3::X, Vec3::new(0.0, -0.6, 0.8), Vec3::NEG_Y] {
            let at = h.through_at(1.1 * n).unwrap();
            let tau = -at.t.ln();
            let want = slant_depth(1.0 / 1.1, 0.5);
            // (The shell is two cells deep in the map: its cells' centres
            // within it, so the depth along a line is within a third.)
            assert!(
                (tau / want - 1.0).abs() < 0.35,
                "{light:?} {n}: tau {tau} against {want}"
            );
        }
    }
}
