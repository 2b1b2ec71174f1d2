//! The exact reference, fiber by fiber, on arrangements whose shadow is
//! known by hand: what a fiber sees of the fibers in front of it, and that
//! neither the fiber itself nor its neighbours beside it darken it.

use glam::Vec3;
use shadow::{Fiber, Light, MethodConfig, ShadowInput, ShadowMethod};
use strands::Hair;

mod common;
use common::along_z;

const W: f32 = 0.1;
const ALPHA: f32 = 0.6;

fn reference(hair: &Hair, light: &Light, rays: u32) -> ShadowMethod {
    common::built(&MethodConfig::Reference { rays }, hair, light, W, ALPHA)
}

fn close(a: f32, b: f32) -> bool {
    (a - b).abs() < 1e-5
}

#[test]
fn a_fiber_sees_what_covers_it_and_nothing_beside_it() {
    // Light from +y. A at the front; B right behind A; C behind A2, half
    // across its shadow; D beside A at its depth, 3 widths away.
    let light = Light::directional(Vec3::NEG_Y).unwrap();
    let mut hair = Hair::new();
    along_z(&mut hair, 0.0, 0.0); // A
    along_z(&mut hair, 0.0, -1.0); // B
    along_z(&mut hair, 2.0 + 0.5 * W, -1.0); // C
    along_z(&mut hair, 3.0 * W, 0.0); // D
    along_z(&mut hair, 2.0, 0.0); // A2
    along_z(&mut hair, 4.0, 1.0); // F, in front
    along_z(&mut hair, 4.0 + 3.0 * W, 0.0); // G, behind and beside F
    let m = reference(&hair, &light, 4);
    let t = |s: usize, i: usize| m.transmittance_at(hair.strand(s)[i]);
    for i in 0..9 {
        // A and A2 are lit: a fiber is not its own shadow.
        assert_eq!(t(0, i), 1.0, "A point {i}");
        assert_eq!(t(4, i), 1.0, "A2 point {i}");
        // B lies wholly in A's shadow: every ray loses alpha.
        assert!(close(t(1, i), 1.0 - ALPHA), "B point {i}: {}", t(1, i));
        // C: its four rays at 1/8, 3/8, 5/8 and 7/8 of its width from
        // A2's axis on one side; the first two meet A2.
        assert!(
            close(t(2, i), 1.0 - 0.5 * ALPHA),
            "C point {i}: {}",
            t(2, i)
        );
        // D: nothing in front of it, however near A is; G: F passes in
        // front of it 3 widths to the side.
        assert_eq!(t(3, i), 1.0, "D point {i}");
        assert_eq!(t(6, i), 1.0, "G point {i}");
    }
    // The footprint reference spreads F over its footprint: G comes out
    // shadowed there; the exact one does not.
    let fiber = Fiber::new(W, ALPHA).unwrap();
    let mut f = ShadowMethod::new(&MethodConfig::FootprintReference {
        footprint: Some(10.0 * W),
        rays: 16,
    })
    .unwrap();
    f.density(&ShadowInput {
        light: &light,
        hair: &hair,
        fiber: &fiber,
        occluders: &[],
        extent: None,
    })
    .unwrap();
    f.transmittance();
    assert!(f.transmittance_at(hair.strand(6)[4]) < 0.95);
}

#[test]
fn a_fiber_another_runs_through_is_lit_from_where_its_rays_leave_them() {
    // Light from +y. B runs through A, its axis a quarter width nearer the
    // light: every ray from A starts inside B. A point of A that a camera
    // sees lies outside B, so B does not shadow it (counting it made the
    // reference darker than Cycles wherever fibers interpenetrate). A
    // fiber further in front still does: C over A2, through which B2 runs.
    let light = Light::directional(Vec3::NEG_Y).unwrap();
    let mut hair = Hair::new();
    along_z(&mut hair, 0.0, 0.0); // A
    along_z(&mut hair, 0.0, 0.25 * W); // B
    along_z(&mut hair, 2.0, 0.0); // A2
    along_z(&mut hair, 2.0, 0.25 * W); // B2
    along_z(&mut hair, 2.0, 1.0); // C
    let m = reference(&hair, &light, 4);
    let t = |s: usize, i: usize| m.transmittance_at(hair.strand(s)[i]);
    for i in 0..9 {
        assert_eq!(t(0, i), 1.0, "A point {i}");
        assert_eq!(t(1, i), 1.0, "B point {i}");
        assert!(close(t(2, i), 1.0 - ALPHA), "A2 point {i}: {}", t(2, i));
        assert!(close(t(3, i), 1.0 - ALPHA), "B2 point {i}: {}", t(3, i));
    }
    // A probe is a point, not a fiber's surface: inside A and B, both
    // count.
    let probe = Vec3::new(0.0, 0.2 * W, 0.1);
    let t = m.transmittance_at(probe);
    assert!(close(t, (1.0 - ALPHA) * (1.0 - ALPHA)), "probe: {t}");
}

#[test]
fn with_the_camera_known_rays_start_on_the_side_of_the_fiber_it_sees() {
    // Light from +y, A along z at the origin, C in front of it (y = 1)
    // and to the side: x from 0.4 W to 1.4 W. From A's axis the four rays
    // (x = -3/8 .. 3/8 W) pass C by. Seen by a camera at +x, they start on
    // the surface it sees, where its rays meet the fiber at offsets h =
    // +-1/4, +-3/4 of the radius r = W / 2: x = r sqrt(1 - h^2), 0.48 W
    // for the middle two, which meet C, and 0.33 W for the outer two,
    // which pass it by. A2 and C2 are the same with C2 0.15 W further
    // out (from 0.55 W): no point of the surface the camera sees is
    // behind it.
    let light = Light::directional(Vec3::NEG_Y).unwrap();
    let mut hair = Hair::new();
    along_z(&mut hair, 0.0, 0.0); // A
    along_z(&mut hair, 0.9 * W, 1.0); // C
    along_z(&mut hair, 10.0, 0.0); // A2
    along_z(&mut hair, 10.0 + 1.05 * W, 1.0); // C2
    let mut m = reference(&hair, &light, 4);
    let (a, a2) = (hair.strand(0)[4], hair.strand(2)[4]);
    assert_eq!(m.transmittance_at(a), 1.0);
    m.set_eye(Some(Vec3::new(100.0, 0.0, 0.0)));
    let t = m.transmittance_at(a);
    assert!(close(t, 1.0 - 0.5 * ALPHA), "seen from +x: {t}");
    assert_eq!(m.transmittance_at(a2), 1.0, "A2 seen from +x");
    // Seen end-on (the camera on A's axis): as without a camera, the rays
    // spread across the fiber as the light sees it, and C misses them.
    m.set_eye(Some(Vec3::new(0.0, 0.0, 100.0)));
    assert_eq!(m.transmittance_at(a), 1.0, "A seen end-on");
    m.set_eye(Some(Vec3::new(100.0, 0.0, 0.0)));
    assert!(close(m.transmittance_at(a), 1.0 - 0.5 * ALPHA));
    // From the other side, the rays move away from C.
    m.set_eye(Some(Vec3::new(-100.0, 0.0, 0.0)));
    assert_eq!(m.transmittance_at(a), 1.0);
    // A ray leaving the fiber's far side through the fiber itself: not
    // its shadow (camera at -y, the light at +y).
    m.set_eye(Some(Vec3::new(0.0, -100.0, 0.0)));
    assert_eq!(m.transmittance_at(a), 1.0);
}

#[test]
fn a_fiber_along_the_light_is_not_its_own_shadow() {
    // A strand pointing straight at a light from above: every ray from it
    // runs inside it; nothing else is there.
    let light = Light::directional(Vec3::NEG_Y).unwrap();
    let mut hair = Hair::new();
    let pts: Vec<Vec3> = (0..12)
        .map(|i| Vec3::new(0.0, -0.2 * i as f32, 0.0))
        .collect();
    hair.push_strand(&pts).unwrap();
    // And one at a grazing 5 degrees.
    let g = Vec3::new(5f32.to_radians().sin(), -5f32.to_radians().cos(), 0.0);
    let pts: Vec<Vec3> = (0..12)
        .map(|i| Vec3::new(3.0, 0.0, 0.0) + g * (0.2 * i as f32))
        .collect();
    hair.push_strand(&pts).unwrap();
    let m = reference(&hair, &light, 4);
    for &p in hair.points() {
        assert_eq!(m.transmittance_at(p), 1.0, "at {p}");
    }
}

#[test]
fn a_strand_that_turns_back_shadows_itself() {
    // A hairpin: out along x at y = 0, back along x at y = -1 (behind,
    // from a light above). The lower leg is in the upper leg's shadow; the
    // bend is its own fiber.
    let light = Light::directional(Vec3::NEG_Y).unwrap();
    let mut pts: Vec<Vec3> = (0..=10)
        .map(|i| Vec3::new(0.2 * i as f32, 0.0, 0.0))
        .collect();
    pts.extend((1..=9).map(|i| {
        let a = std::f32::consts::PI * i as f32 / 10.0;
        Vec3::new(2.0 + 0.5 * a.sin(), -0.5 + 0.5 * a.cos(), 0.0)
    }));
    pts.extend((0..=10).map(|i| Vec3::new(2.0 - 0.2 * i as f32, -1.0, 0.0)));
    let mut hair = Hair::new();
    hair.push_strand(&pts).unwrap();
    let m = reference(&hair, &light, 4);
    for (i, &p) in pts[..=10].iter().enumerate() {
        assert_eq!(m.transmittance_at(p), 1.0, "upper leg point {i}");
    }
    // The lower leg away from the bend.
    for p in &pts[pts.len() - 8..] {
        assert!(
            close(m.transmittance_at(*p), 1.0 - ALPHA),
            "lower leg at {p}"
        );
    }
}

#[test]
fn a_probe_is_one_ray_and_a_point_light_sends_rays_to_its_source() {
    // A point light above two fibers along z, one above the other.
    let light = Light::point(Vec3::new(0.0, 5.0, 0.0), 100.0).unwrap();
    let mut hair = Hair::new();
    along_z(&mut hair, 0.0, 1.0);
    along_z(&mut hair, 0.0, 3.0);
    let m = reference(&hair, &light, 4);
    // Straight below the light, under both fibers.
    assert!(close(
        m.transmittance_at(Vec3::new(0.0, 0.0, 0.0)),
        (1.0 - ALPHA) * (1.0 - ALPHA)
    ));
    // Off to the side: the ray to the light passes both fibers by.
    assert_eq!(m.transmittance_at(Vec3::new(1.0, 0.0, 0.0)), 1.0);
    // The upper fiber is lit; the lower one is in its shadow all along
    // (its rays converge on the light, across the upper fiber).
    for i in 0..9 {
        assert_eq!(m.transmittance_at(hair.strand(1)[i]), 1.0);
        assert!(
            close(m.transmittance_at(hair.strand(0)[i]), 1.0 - ALPHA),
            "point {i}"
        );
    }
}

/// A fiber whose light comes only from offsets `h` with `lo <= |h| < hi`
/// (in the fiber's frame), recording what it is asked.
#[derive(Debug)]
struct Band {
    lo: f32,
    hi: f32,
    asked: std::sync::Mutex<Vec<(Vec3, Vec3, f32, f32)>>,
}

impl shadow::AcrossFiber for Band {
    fn weight(&self, wo: Vec3, wi: Vec3, h0: f32, h1: f32) -> f32 {
        self.asked.lock().unwrap().push((wo, wi, h0, h1));
        let mid = 0.5 * (h0 + h1);
        if (self.lo..self.hi).contains(&mid.abs()) {
            h1 - h0
        } else {
            0.0
        }
    }
}

#[test]
fn a_fibers_rays_count_as_much_as_the_light_its_width_sends_there() {
    // The arrangement of the test above: seen from +x, A's middle two
    // rays (h = +-1/4) meet C in front of it, the outer two pass it by.
    let light = Light::directional(Vec3::NEG_Y).unwrap();
    let mut hair = Hair::new();
    along_z(&mut hair, 0.0, 0.0); // A
    along_z(&mut hair, 0.9 * W, 1.0); // C
    let mut m = reference(&hair, &light, 4);
    m.set_eye(Some(Vec3::new(100.0, 0.0, 0.0)));
    let a = hair.strand(0)[4];
    let band = |lo: f32, hi: f32| {
        std::sync::Arc::new(Band {
            lo,
            hi,
            asked: Default::default(),
        })
    };
    // Evenly (no profile): half the rays lose alpha.
    assert!(close(m.transmittance_at(a), 1.0 - 0.5 * ALPHA));
    // All the light from the middle of the width: what the middle rays see.
    let middle = band(0.0, 0.5);
    m.set_across(Some(middle.clone()));
    let t = m.transmittance_at(a);
    assert!(close(t, 1.0 - ALPHA), "bright in the middle: {t}");
    // The fiber's frame: x along it (+z), z towards the eye (+x), y = z x x
    // (-y); the light (+y) at -y there. Each ray asked for its quarter.
    let asked = middle.asked.lock().unwrap().clone();
    assert_eq!(asked.len(), 4);
    let mut quarters = Vec::new();
    for (wo, wi, h0, h1) in asked {
        assert!((wo - Vec3::Z).length() < 1e-4, "wo {wo}");
        assert!((wi - Vec3::NEG_Y).length() < 1e-4, "wi {wi}");
        quarters.push((h0, h1));
    }
    quarters.sort_by(|x, y| x.0.total_cmp(&y.0));
    for (q, (h0, h1)) in quarters.iter().enumerate() {
        let start = -1.0 + 0.5 * q as f32;
        assert!(close(*h0, start) && close(*h1, start + 0.5), "{quarters:?}");
    }
    // All of it from the edges: what the outer rays see.
    m.set_across(Some(band(0.5, 1.01)));
    assert_eq!(m.transmittance_at(a), 1.0, "bright at the edges");
    // A fiber that sends the eye nothing: evenly.
    m.set_across(Some(band(2.0, 3.0)));
    assert!(close(m.transmittance_at(a), 1.0 - 0.5 * ALPHA));
    // Without the camera the profile is not used: rays across the fiber
    // as the light sees it, all passing C by.
    m.set_eye(None);
    m.set_across(Some(band(0.0, 0.5)));
    assert_eq!(m.transmittance_at(a), 1.0);
}
