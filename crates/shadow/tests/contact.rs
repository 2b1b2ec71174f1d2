//! The density map's contact shadows: the fibers just in front of a drawn
//! point counted exactly, the map beyond; on arrangements whose shadow is
//! known by hand.

use glam::Vec3;
use shadow::{Light, MethodConfig, ShadowError, ShadowMethod};
use strands::Hair;

mod common;
use common::along_z;

const W: f32 = 0.1;
const ALPHA: f32 = 0.6;
const CELLS: u32 = 16;

fn map(hair: &Hair, light: &Light, contact: f32) -> ShadowMethod {
    let config = MethodConfig::DensityMap {
        cells: CELLS,
        trilinear: true,
        contact,
    };
    common::built(&config, hair, light, W, ALPHA)
}

/// Transmittance at every drawn point, by strand: `t[strand][point]`.
fn filtered(m: &ShadowMethod, hair: &Hair) -> Vec<Vec<f32>> {
    let mut out = vec![0.0; hair.point_count()];
    m.filter(hair.points(), &mut out);
    hair.offsets()
        .windows(2)
        .map(|w| out[w[0] as usize..w[1] as usize].to_vec())
        .collect()
}

#[test]
fn fibers_within_reach_shadow_exactly_and_the_map_counts_the_rest() {
    // Light from +y. A in front; B right behind it; D beside B, 3 widths
    // from A's shadow; far to the side, F high in front of E.
    let light = Light::directional(Vec3::NEG_Y).unwrap();
    let mut hair = Hair::new();
    along_z(&mut hair, 0.0, 0.0); // A
    along_z(&mut hair, 0.0, -0.3); // B
    along_z(&mut hair, 3.0 * W, -0.3); // D
    along_z(&mut hair, 5.0, 4.0); // F
    along_z(&mut hair, 5.0, -0.3); // E
    let contact = 4.0;
    let with = map(&hair, &light, contact);
    let without = map(&hair, &light, 0.0);
    let ds = with.frame().unwrap().ds;
    let reach = contact * ds;
    // What the arrangement needs: B and D within reach of A, D within a
    // cell of A's shadow (where the map alone blurs it), F out of reach.
    assert!(0.3 < reach && 3.0 * W < ds && 4.3 > reach + ds, "ds {ds}");
    let (t, plain) = (filtered(&with, &hair), filtered(&without, &hair));
    for i in 0..9 {
        // Nothing in front of A and F: no fiber, and the map in front of
        // all hair is exactly 0.
        assert_eq!(t[0][i], 1.0, "A point {i}");
        assert_eq!(t[3][i], 1.0, "F point {i}");
        // B lies wholly in A's shadow.
        assert!((t[1][i] - (1.0 - ALPHA)).abs() < 1e-5, "B {i}: {}", t[1][i]);
        // D: A passes 3 widths to the side.
        assert_eq!(t[2][i], 1.0, "D point {i}");
        // The map alone spreads A's shadow over its cells: B and D alike,
        // both nearly lit.
        assert!(
            (plain[1][i] - plain[2][i]).abs() < 0.05 && plain[1][i] > 0.9,
            "the map alone at B and D {i}: {} {}",
            plain[1][i],
            plain[2][i]
        );
        // E: F is beyond reach, so the map counts it, as without contact.
        assert!(t[4][i] < 0.99, "E point {i}: {}", t[4][i]);
        assert!(
            (t[4][i] - plain[4][i]).abs() < 0.02,
            "E point {i}: {} against the map's {}",
            t[4][i],
            plain[4][i]
        );
    }
}

#[test]
fn a_ray_from_the_camera_side_of_a_fiber_sees_what_covers_that_side() {
    // Light from +y, camera far along +x. Q's contact ray starts on its
    // side towards the camera, half a width along +x: P, in front of Q
    // and a width towards the camera, covers that side; P2, as far the
    // other way, does not.
    let light = Light::directional(Vec3::NEG_Y).unwrap();
    let fiber_pair = |dx: f32| {
        let mut hair = Hair::new();
        along_z(&mut hair, 0.0, -0.2); // Q
        along_z(&mut hair, dx, 0.0); // P
        along_z(&mut hair, 6.0, 3.0); // far away: the map's extent
        hair
    };
    for (dx, lit) in [(W, false), (-W, true)] {
        let hair = fiber_pair(dx);
        let mut m = map(&hair, &light, 4.0);
        m.set_eye(Some(Vec3::new(1000.0, -0.2, 0.0)));
        let t = filtered(&m, &hair);
        let want = if lit { 1.0 } else { 1.0 - ALPHA };
        for (i, &q) in t[0].iter().enumerate().take(8).skip(1) {
            assert!((q - want).abs() < 1e-5, "P at dx = {dx}, Q point {i}: {q}");
        }
    }
}

#[test]
fn contact_distances_out_of_range_are_refused_by_name() {
    for bad in [-1.0, f32::NAN, f32::INFINITY, 16.5] {
        let e = ShadowMethod::new(&MethodConfig::DensityMap {
            cells: 64,
            trilinear: true,
            contact: bad,
        })
        .unwrap_err();
        assert!(
            matches!(
                e,
                ShadowError::Setting {
                    name: "contact",
                    ..
                }
            ),
            "{bad}: {e}"
        );
    }
    let ok = MethodConfig::DensityMap {
        cells: 64,
        trilinear: true,
        contact: 16.0,
    };
    ok.validate().unwrap();
    assert_eq!(ok.parameters(), "cells=64 filter=true contact=16");
}
