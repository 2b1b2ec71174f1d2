//! The draw stage alone, timed: a scene's hair at rest, shaded once with
//! its shadows, then drawn (head, hair and resolve) again and again, in
//! as many groups of strands as animated frames are. For
//! comparing two builds of the draw on the same picture: it prints the
//! median and a hash of the picture's bytes.
//!
//! ```text
//! cargo run --release -p engine --example draw_time [SCENE.toml] [RUNS]
//! ```
use std::hash::{Hash, Hasher};
use std::time::Instant;

use engine::{Renderer, Scene, build_hair};

fn main() {
    let mut args = std::env::args().skip(1);
    let path = args.next().unwrap_or_else(|| "scenes/smooth.toml".into());
    let runs: usize = args.next().map_or(15, |r| r.parse().expect("a run count"));
    let scene = Scene::load(std::path::Path::new(&path)).expect("a scene");
    let hair = build_hair(&scene).expect("hair");
    let mut renderer = Renderer::new(&scene).expect("a renderer");
    // Drawn in groups, as animated frames are (see `engine::GROUPS`).
    let n = hair.strand_count() as u32;
    let g = engine::GROUPS as u32;
    renderer.set_groups((0..=g).map(|i| n * i / g).collect());
    let first = renderer.render(&hair, true).expect("a picture");
    let mut times = Vec::with_capacity(runs);
    for _ in 0..runs {
        let t0 = Instant::now();
        let img = renderer.draw(&hair, true).expect("a picture");
        times.push(t0.elapsed().as_secs_f64() * 1e3);
        assert_eq!(img, first, "the same picture every draw");
    }
    times.sort_by(f64::total_cmp);
    let mut h = std::collections::hash_map::DefaultHasher::new();
    first.as_raw().hash(&mut h);
    println!(
        "draw {path}: {} segments, {}x{}: median {:.1} ms of {runs} (min {:.1}), picture {:016x}",
        hair.segment_count(),
        first.width(),
        first.height(),
        times[runs / 2],
        times[0],
        h.finish()
    );
}
