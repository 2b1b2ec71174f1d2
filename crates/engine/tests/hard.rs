//! Every scene of `scenes/hard/` through the whole frame pipeline: the
//! hair, the transmittance and the shaded colours stay finite, T stays in
//! [0, 1], and the cases with a known answer give it.

use std::path::{Path, PathBuf};

use engine::{Scene, Sequence};

mod common;

fn hard_scenes() -> Vec<PathBuf> {
    let v = common::scene_files("scenes/hard");
    assert!(v.len() >= 12, "the hard scenes are in scenes/hard");
    v
}

/// Renders `frames` frames of `path` and checks every number of the last.
fn run(path: &Path, frames: usize) -> Sequence {
    let scene = Scene::load(path).unwrap();
    let mut seq = Sequence::new(&scene).unwrap();
    for _ in 0..frames {
        seq.next_frame().unwrap();
    }
    let name = path.file_name().unwrap().to_string_lossy().into_owned();
    for p in seq.hair().points() {
        assert!(p.is_finite(), "{name}: hair point {p}");
    }
    let r = seq.renderer();
    for (l, t) in r.transmittance().iter().enumerate() {
        assert_eq!(t.len(), seq.hair().point_count(), "{name}: light {l}");
        for &t in t {
            assert!(t.is_finite() && (0.0..=1.0).contains(&t), "{name}: T = {t}");
        }
    }
    for c in r.colors() {
        assert!(
            c.is_finite() && c.min_element() >= 0.0,
            "{name}: colour {c}"
        );
    }
    seq
}

#[test]
fn every_hard_scene_renders_finite_numbers() {
    for path in hard_scenes() {
        let frames = if Scene::load(&path).unwrap().animation.motion.is_still() {
            1
        } else {
            3
        };
        run(&path, frames);
    }
}

fn scene(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../scenes/hard")
        .join(name)
}

#[test]
fn opacity_zero_lets_all_light_through_but_the_head_still_blocks_it() {
    let path = scene("opacity0.toml");
    let s = Scene::load(&path).unwrap();
    let head = s.head.unwrap();
    let dir = s.lights[0].direction();
    let seq = run(&path, 1);
    let t = &seq.renderer().transmittance()[0];
    let mut behind_head = 0;
    for (p, &t) in seq.hair().points().iter().zip(t) {
        // Points within a cell or so of the head's silhouette are blurred by
        // the map; away from it T is exact.
        let near = (p.distance(head.center) - head.radius).abs() < 1.0;
        let grown = shadow::Occluder::sphere(head.center, head.radius + 1.5);
        let shrunk = shadow::Occluder::sphere(head.center, head.radius - 1.5);
        if !grown.blocks(*p, dir) && !near {
            assert_eq!(t, 1.0, "T = {t} at {p}, in the open");
        } else if shrunk.blocks(*p, dir) && !near {
            assert!(t < 1e-3, "T = {t} at {p}, behind the head");
            behind_head += 1;
        }
    }
    assert!(behind_head > 0);
}

#[test]
fn dense_hair_leaves_its_core_in_the_dark_and_its_front_lit() {
    let seq = run(&scene("dense.toml"), 1);
    let t = &seq.renderer().transmittance()[0];
    let dark = t.iter().filter(|&&t| t < 1e-6).count();
    let lit = t.iter().filter(|&&t| t > 0.5).count();
    // The points past the first of their column's four cells, less those
    // within the half cell that lookups read nearer the light
    // (shadow::LIT_EDGE_OFFSET): a fifth of them at least.
    assert!(
        dark > t.len() / 5,
        "{dark} of {} points in the dark",
        t.len()
    );
    assert!(lit > 0, "no point faces the light");
}

#[test]
fn degenerate_strands_shadow_like_their_real_parts() {
    // The last strand, a loop hanging from y = 1 under light straight
    // down, is shadowed at its bottom by its own two legs above it; its
    // top points see the light directly.
    let seq = run(&scene("degenerate.toml"), 1);
    let hair = seq.hair();
    let t = &seq.renderer().transmittance()[0];
    let last = hair.strand_count() - 1;
    let start = hair.offsets()[last] as usize;
    let pts = &hair.points()[start..];
    let ts = &t[start..];
    let top = pts
        .iter()
        .zip(ts)
        .filter(|(p, _)| p.y > 0.9)
        .map(|(_, &t)| t)
        .fold(0.0f32, f32::max);
    let bottom = pts
        .iter()
        .zip(ts)
        .filter(|(p, _)| p.y < -5.9)
        .map(|(_, &t)| t)
        .fold(1.0f32, f32::min);
    assert_eq!(top, 1.0);
    assert!(bottom < 0.999, "the loop's bottom is lit: T = {bottom}");
}

#[test]
fn stiff_links_at_the_largest_step_hold_their_length() {
    let seq = run(&scene("big_step.toml"), 5);
    assert!(seq.animator().simulates());
    let stretch = seq.animator().max_stretch();
    assert!(stretch < 0.01, "a link is off by {stretch}");
}

#[test]
fn extreme_repulsion_keeps_the_hair_attached_and_links_at_length() {
    let seq = run(&scene("crowd.toml"), 3);
    let stretch = seq.animator().max_stretch();
    assert!(stretch < 0.01, "a link is off by {stretch}");
}
