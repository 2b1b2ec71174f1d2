//! The real groom shipped in `scenes/data/`: the Sintel Lite hair as 228
//! TressFX guides of 32 vertices (see `scenes/data/NOTICE.md`). The
//! expected values were decoded from the file by a separate script
//! (Python's `struct`), not by this crate.

use std::path::Path;

use glam::Vec3;
use strands::{FollowParams, grow_followers, load};

fn groom() -> strands::Hair {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/data/sintel_hair.tfx");
    load(&path, 0).unwrap_or_else(|e| panic!("{e}"))
}

#[test]
fn the_sintel_groom_loads_as_228_guides_of_32_vertices() {
    let hair = groom();
    assert_eq!(hair.strand_count(), 228);
    assert_eq!(hair.point_count(), 228 * 32);
    assert!(hair.strands().all(|s| s.len() == 32));
    assert!(hair.points().iter().all(|p| p.is_finite()));
    let close = |a: Vec3, b: Vec3| (a - b).abs().max_element() < 1e-5;
    // The first strand's root and tip, and the last vertex of the file.
    assert!(close(
        hair.strand(0)[0],
        Vec3::new(-8.315_415, 34.929_554, -2.681_878)
    ));
    assert!(close(
        hair.strand(0)[31],
        Vec3::new(-6.334_358, 27.996_248, -2.829_32)
    ));
    assert!(close(
        hair.strand(227)[31],
        Vec3::new(6.379_44, 25.338_478, -1.754_187)
    ));
    let mut lo = Vec3::splat(f32::INFINITY);
    let mut hi = Vec3::splat(f32::NEG_INFINITY);
    for &p in hair.points() {
        lo = lo.min(p);
        hi = hi.max(p);
    }
    assert!(
        close(lo, Vec3::new(-10.617_483, 20.715_918, -12.951_793)),
        "{lo}"
    );
    assert!(
        close(hi, Vec3::new(9.826_918, 47.686_337, 11.655_979)),
        "{hi}"
    );
}

#[test]
fn follow_strands_make_the_228_guides_a_full_head() {
    let guides = groom();
    let p = FollowParams {
        followers: 15,
        radius: 0.4,
        tip_spread: 1.5,
        seed: 1,
    };
    let hair = grow_followers(&guides, &p);
    assert_eq!(hair.strand_count(), 228 * 16);
    assert_eq!(hair.segment_count(), 228 * 16 * 31);
    assert!(hair.points().iter().all(|p| p.is_finite()));
    // Every follow strand keeps its guide's vertex count and starts near
    // its guide's root (within the follow radius).
    for (g, guide) in guides.strands().enumerate() {
        for f in 0..16 {
            let s = hair.strand(g * 16 + f);
            assert_eq!(s.len(), 32);
            let d = s[0].distance(guide[0]);
            assert!(
                d <= p.radius * 1.0001,
                "guide {g} follower {f}: root {d} away"
            );
        }
    }
}
