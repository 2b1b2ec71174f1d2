//! The frame pipeline of an animation: which stages run, and what they do
//! to the hair over time.

use std::path::Path;

use engine::{FrameStats, Scene, Sequence, Stage};
use glam::Vec3;

/// A small animated scene: few strands on the default head, a 96x64
/// picture, 48^3 cells, and `extra` TOML.
fn scene(extra: &str) -> Scene {
    let text = format!(
        "[hair]\nstrands_per_wisp = 3\n\n[render]\nwidth = 96\nheight = 64\n\n[shadow]\ncells = 48\n\n[dynamics]\nsettle = 0.2\n\n{extra}"
    );
    Scene::from_toml_str(&text, Path::new("test.toml")).unwrap()
}

fn run(scene: &Scene, frames: usize) -> (Vec<FrameStats>, Vec<image::RgbImage>, Sequence) {
    let mut seq = Sequence::new(scene).unwrap();
    let mut stats = Vec::new();
    let mut images = Vec::new();
    for _ in 0..frames {
        let (img, s) = seq.next_frame().unwrap();
        images.push(img.clone());
        stats.push(s);
    }
    (stats, images, seq)
}

/// The frames in which `stage` ran.
fn ran(stats: &[FrameStats], stage: Stage) -> Vec<u64> {
    stats
        .iter()
        .filter(|f| f.stage(stage).ran)
        .map(|f| f.index)
        .collect()
}

#[test]
fn a_still_scene_never_simulates_and_fills_the_map_once() {
    let s = scene("[animation]\nmotion = \"still\"\n");
    assert!(
        s.effects.dynamics,
        "dynamics is on; only the motion is still"
    );
    let (stats, images, _) = run(&s, 30);
    assert_eq!(stats.len(), 30);
    for stage in [
        Stage::Simulate,
        Stage::SelfCollide,
        Stage::BodyCollide,
        Stage::Pose,
    ] {
        assert!(ran(&stats, stage).is_empty(), "{stage:?} ran");
    }
    for stage in [
        Stage::Density,
        Stage::Transmittance,
        Stage::Filter,
        Stage::Shade,
        Stage::Draw,
    ] {
        assert_eq!(ran(&stats, stage), vec![0], "{stage:?}");
    }
    assert!(
        stats[1..]
            .iter()
            .all(|f| f.total_ms() == 0.0 && f.steps == 0)
    );
    assert!(images.iter().all(|i| i == &images[0]), "the same picture");
}

#[test]
fn without_self_shadow_nothing_is_swept() {
    // Dancing, so the hair moves every frame.
    let (stats, _, _) = run(
        &scene("[animation]\nmotion = \"dance\"\n[effects]\nself_shadow = false\n"),
        6,
    );
    assert!(ran(&stats, Stage::Transmittance).is_empty());
    assert!(ran(&stats, Stage::Filter).is_empty());
    // Self-collisions still read a density map, one fill per frame.
    assert_eq!(ran(&stats, Stage::Density), vec![0, 1, 2, 3, 4, 5]);
    assert_eq!(ran(&stats, Stage::SelfCollide).len(), 6);

    let (stats, _, _) = run(
        &scene(
            "[animation]\nmotion = \"dance\"\n[effects]\nself_shadow = false\nself_collision = false\n",
        ),
        6,
    );
    for stage in [
        Stage::Density,
        Stage::Transmittance,
        Stage::Filter,
        Stage::SelfCollide,
    ] {
        assert!(ran(&stats, stage).is_empty(), "{stage:?} ran");
    }
    assert_eq!(ran(&stats, Stage::Simulate).len(), 6);
}

#[test]
fn a_dance_simulates_every_frame_and_settles_first() {
    let s = scene("[animation]\nmotion = \"dance\"\nfps = 30\n");
    let (stats, images, seq) = run(&s, 5);
    // 30 fps at the default 1/60 s step: two steps a frame; the first
    // frame settles 0.2 s first (6 frames' worth).
    assert_eq!(seq.animator().substeps(), 2);
    assert_eq!(stats[0].steps, 12);
    assert!(stats[1..].iter().all(|f| f.steps == 2));
    for stage in Stage::ALL {
        assert_eq!(ran(&stats, stage).len(), 5, "{stage:?}");
    }
    assert!(images.windows(2).all(|w| w[0] != w[1]), "the hair moves");
    assert!(seq.animator().max_stretch() < 0.01);
}

#[test]
fn without_dynamics_hair_moves_rigidly_with_the_head() {
    let s = scene("[animation]\nmotion = \"dance\"\n[effects]\ndynamics = false\n");
    let rest = engine::build_hair(&s).unwrap();
    let (stats, _, seq) = run(&s, 4);
    assert!(ran(&stats, Stage::Simulate).is_empty());
    // Frame 0 is the rest pose; then the head moves every frame.
    assert_eq!(ran(&stats, Stage::Pose), vec![1, 2, 3]);
    assert_eq!(ran(&stats, Stage::Density), vec![0, 1, 2, 3]);
    // The hair is the rest hair under the head's transform at frame 3.
    let head = s.animation.motion.at(3.0 / 30.0, Vec3::ZERO);
    for (a, b) in seq.hair().points().iter().zip(rest.points()) {
        assert!(a.distance(head.transform_point3(*b)) < 1e-4);
    }
}

#[test]
fn keyframes_that_hold_still_stop_the_shadow_work() {
    // The head turns for 0.1 s, then holds: without dynamics nothing moves
    // after the last key, and the last shadow is reused.
    let s = scene(
        "[animation]\nmotion = \"keyframes\"\n[[animation.key]]\ntime = 0.0\n[[animation.key]]\ntime = 0.1\nrotate_deg = [0, 20, 0]\n[effects]\ndynamics = false\n",
    );
    let (stats, _, _) = run(&s, 8);
    assert_eq!(ran(&stats, Stage::Density), vec![0, 1, 2, 3]);
    assert_eq!(ran(&stats, Stage::Draw), vec![0, 1, 2, 3]);
}

#[test]
fn body_spheres_keep_the_hair_out() {
    // A sphere where the hair at the back of the head hangs (a shoulder
    // blade, say), and a strong dance.
    let s = scene(
        "[animation]\nmotion = \"dance\"\namplitude = 1.5\n\n[[body]]\ncenter = [0, -15, -20]\nradius = 5\n",
    );
    let (_, _, seq) = run(&s, 20);
    let head = seq.animator().head();
    let spheres = [
        (head.transform_point3(Vec3::ZERO), 10.0),
        (head.transform_point3(Vec3::new(0.0, -15.0, -20.0)), 5.0),
    ];
    let hair = seq.hair();
    let mut worst = 0.0f32;
    for strand in hair.strands() {
        // The first drawn points sit on the scalp.
        for p in &strand[4..] {
            for (c, r) in spheres {
                worst = worst.max(r - p.distance(c));
            }
        }
    }
    // Drawn strands interpolate between guides and are smoothed: they
    // may cut a little into a sphere the guides stay out of.
    assert!(worst < 0.6, "hair {worst} units inside a body");

    let free = scene(
        "[animation]\nmotion = \"dance\"\namplitude = 1.5\n\n[[body]]\ncenter = [0, -15, -20]\nradius = 5\n[effects]\nbody_collision = false\n",
    );
    let (stats, _, seq) = run(&free, 20);
    assert!(ran(&stats, Stage::BodyCollide).is_empty());
    let inside = seq.hair().strands().flat_map(|s| s[4..].iter()).any(|p| {
        p.distance(
            seq.animator()
                .head()
                .transform_point3(Vec3::new(0.0, -15.0, -20.0)),
        ) < 4.0
    });
    assert!(
        inside,
        "without body collisions the hair goes through the sphere"
    );
}

#[test]
fn the_same_bytes_on_one_thread_and_on_three() {
    let s = scene("[animation]\nmotion = \"dance\"\n");
    let frames = |threads| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| run(&s, 4).1)
    };
    let one = frames(1);
    assert!(one == frames(3));
}

#[test]
fn specular_off_removes_only_the_highlight() {
    let on = run(&scene(""), 1).1.remove(0);
    let off = run(&scene("[effects]\nspecular = false\n"), 1).1.remove(0);
    let zero = run(&scene("[shading]\nspecular = 0.0\n"), 1).1.remove(0);
    assert!(off == zero, "the same as a zero specular weight");
    assert!(on != off);
    // The highlight only adds light.
    let brighter = on
        .pixels()
        .zip(off.pixels())
        .filter(|(a, b)| a.0 != b.0)
        .all(|(a, b)| a.0.iter().zip(b.0).all(|(x, y)| *x + 1 >= y));
    assert!(brighter);
}

/// Hair density above `threshold` (length per volume), summed over the
/// cells more than 3 units outside the head: how much the wisps crowd.
fn crowding(scene: &Scene, hair: &strands::Hair, threshold: f32) -> f32 {
    let mut s = scene.clone();
    s.effects.head_shadow = false;
    let mut p = engine::ShadowPipeline::new(&s).unwrap();
    p.density(hair).unwrap();
    let map = p.density_map().unwrap();
    let f = *map.frame();
    let n = f.n_cells as usize;
    let to_density = 1.0 / (s.fiber.cross_section() * f.ds);
    let mut excess = 0.0;
    for k in 0..n {
        for j in 0..n {
            for i in 0..n {
                let c = Vec3::new(i as f32, j as f32, k as f32) + 0.5;
                let world = f.to_world(c);
                let head = seq_head_distance(world);
                if head < 13.0 {
                    continue;
                }
                let rho =
                    (map.hair_quanta(i, j, k) as f64 * shadow::DEPTH_QUANTUM) as f32 * to_density;
                excess += (rho - threshold).max(0.0);
            }
        }
    }
    excess
}

fn seq_head_distance(p: Vec3) -> f32 {
    // The head turns about its centre at the origin and sways by at most
    // 3 units: distance from the centre is what counts.
    p.length()
}

#[test]
fn self_collisions_thin_out_crowded_hair() {
    // 3 strands a wisp instead of 25: the threshold scales with them.
    let text = "[animation]\nmotion = \"dance\"\n[collision]\ndensity = 2.4\nrepulsion = 5000\nmax_acceleration = 10000\n";
    let with = scene(text);
    let mut without = with.clone();
    without.effects.self_collision = false;
    let (_, _, a) = run(&with, 20);
    let (_, _, b) = run(&without, 20);
    let (ca, cb) = (
        crowding(&with, a.hair(), 2.4),
        crowding(&without, b.hair(), 2.4),
    );
    assert!(cb > 0.0, "the groom crowds somewhere");
    assert!(ca < 0.95 * cb, "with {ca}, without {cb}");
}

#[test]
fn the_default_camera_keeps_the_whole_animation_in_the_picture() {
    // A head that walks 40 units to the right and turns, framed by
    // default: 31 frames at 30 fps (framed on the first frame alone, the
    // hair leaves the picture half-way).
    let s = Scene::from_toml_str(
        "[hair]\nstrands_per_wisp = 4\n[render]\nwidth = 400\nheight = 225\n\
         [animation]\nmotion = \"keyframes\"\nfps = 30\n\
         [[animation.key]]\ntime = 0\ntranslate = [0, 0, 0]\n\
         [[animation.key]]\ntime = 1\ntranslate = [40, 0, 0]\nrotate_deg = [0, 60, 0]\n",
        Path::new("walk.toml"),
    )
    .unwrap();
    let mut seq = Sequence::new(&s).unwrap();
    seq.expect_frames(31);
    let mut cut = Vec::new();
    for f in 0..31 {
        seq.next_frame().unwrap();
        let cam = *seq.renderer().camera().unwrap();
        let outside = seq
            .hair()
            .points()
            .iter()
            .filter(|&&p| {
                cam.project(p).is_none_or(|q| {
                    q.x < 0.0 || q.y < 0.0 || q.x > cam.width() as f32 || q.y > cam.height() as f32
                })
            })
            .count();
        if outside > 0 {
            cut.push((f, outside));
        }
    }
    assert!(
        cut.is_empty(),
        "frames with hair outside the picture (frame, points): {cut:?}"
    );
}

#[test]
fn a_frame_rendered_again_runs_its_shadows_and_picture_anew_and_leaves_the_animation_alone() {
    let s = scene("[animation]\nmotion = \"dance\"\n");
    let (_, images, _) = run(&s, 3);
    let mut seq = Sequence::new(&s).unwrap();
    // The first call renders frame 0.
    let (img, first) = seq.again().unwrap();
    assert_eq!(first.index, 0);
    assert!(*img == images[0]);
    seq.next_frame().unwrap();
    for _ in 0..2 {
        let (img, st) = seq.again().unwrap();
        assert_eq!(st.index, 1);
        assert!(
            *img == images[1],
            "frame 1 rendered again is another picture"
        );
        for stage in [Stage::Simulate, Stage::SelfCollide, Stage::Pose] {
            assert!(!st.stage(stage).ran, "{stage:?} ran again");
        }
        for stage in [
            Stage::Density,
            Stage::Transmittance,
            Stage::Filter,
            Stage::Shade,
            Stage::Draw,
        ] {
            assert!(st.stage(stage).ran, "{stage:?} did not run again");
        }
        assert!(st.samples > 0, "the fill deposited nothing");
    }
    // The animation goes on as though nothing had been rendered again.
    let (img, st) = seq.next_frame().unwrap();
    assert_eq!(st.index, 2);
    assert!(*img == images[2]);
}

#[test]
fn a_still_frame_rendered_again_is_the_hair_at_rest() {
    // What `bench shadow` and `bench accuracy` time: the same
    // transmittance at every drawn point as the three stages run alone on
    // the groom the scene builds.
    let s = scene("[animation]\nmotion = \"still\"\n");
    let hair = engine::build_hair(&s).unwrap();
    let mut p = engine::ShadowPipeline::new(&s).unwrap();
    let alone = p.run(&hair, hair.points()).unwrap();
    let mut seq = Sequence::new(&s).unwrap();
    seq.again().unwrap();
    seq.again().unwrap();
    assert!(seq.hair().points() == hair.points(), "not the hair at rest");
    // The sequence fits its maps to the hair's extent measured from the
    // head's anchor, the stages alone to the hair's points: maps placed
    // apart by rounding, the same shadow.
    let got = seq.renderer().transmittance();
    assert_eq!(got.len(), alone.len());
    let (mut sum, mut n) = (0.0f64, 0usize);
    for (a, b) in got.iter().flatten().zip(alone.iter().flatten()) {
        sum += f64::from((a - b).abs());
        n += 1;
    }
    let mean = sum / n as f64;
    assert!(mean < 1e-4, "mean |dT| {mean} from the stages alone");
}

#[test]
fn the_built_in_scene_shows_a_face_under_a_fringe_and_hides_the_scalp() {
    // The first frame with the hair drawn, and with the hair invisible
    // (only the head): where hair covers the head they differ.
    let mut s = Scene::default();
    s.render.width = 320;
    s.render.height = 180;
    let mut bare = s.clone();
    bare.render.hair_alpha = 0.0;
    // The scalp is held against the head alone without the hair's shadow
    // too: the hair lying on it darkens it towards the hair's own colour.
    let mut unshadowed = bare.clone();
    unshadowed.effects.head_shadow = false;
    let first = |s: &Scene| {
        let mut seq = Sequence::new(s).unwrap();
        let img = seq.next_frame().unwrap().0.clone();
        let camera = *seq.renderer().camera().unwrap();
        (img, camera, seq.animator().head_at(0.0))
    };
    let (hair, camera, head) = first(&s);
    let (head_only, ..) = first(&bare);
    let (head_lit, ..) = first(&unshadowed);
    // Mean difference (levels) from `head_only` over the 5x5 pixels
    // around where the head's surface point `p` (at rest) is seen.
    let cover_of = |head_only: &image::RgbImage, p: Vec3| {
        let q = camera.project(head.transform_point3(p)).unwrap();
        let (x0, y0) = (q.x as i64, q.y as i64);
        let mut sum = 0u64;
        for y in y0 - 2..=y0 + 2 {
            for x in x0 - 2..=x0 + 2 {
                let (a, b) = (
                    hair.get_pixel(x as u32, y as u32),
                    head_only.get_pixel(x as u32, y as u32),
                );
                sum +=
                    a.0.iter()
                        .zip(b.0)
                        .map(|(&u, v)| u64::from(u.abs_diff(v)))
                        .sum::<u64>();
            }
        }
        sum as f64 / 75.0
    };
    let cover = |p: Vec3| cover_of(&head_only, p);
    // On the head mesh (scenes/make_head.py): above the middle the sphere
    // of radius 10; below, y stretched by 1.3 and x narrowed by 12 % a unit.
    let on_head = |d: Vec3| {
        let d = d.normalize();
        if d.y >= 0.0 {
            10.0 * d
        } else {
            10.0 * Vec3::new(
                d.x * (1.0 + 0.12 * d.y * 1.3),
                1.3 * d.y,
                d.z * (1.0 + 0.05 * d.y * 1.3),
            )
        }
    };
    // The scalp on either side of the parting, behind the ear and under
    // the fringe: covered (a see-through scalp differs by a few levels).
    for d in [
        Vec3::new(-0.5, 0.7, 0.45),
        Vec3::new(-0.7, 0.6, 0.1),
        Vec3::new(-0.75, 0.3, -0.4),
        Vec3::new(-0.15, 0.55, 0.8),
    ] {
        let c = cover_of(&head_lit, on_head(d));
        assert!(
            c > 40.0,
            "the scalp at {d} shows through: {c:.1} levels of hair"
        );
    }
    // The face below the fringe: left visible, and the head is there.
    let bg = raster::to_srgb8(s.render.background);
    for d in [Vec3::new(-0.3, -0.25, 0.92), Vec3::new(-0.1, -0.45, 0.88)] {
        let p = on_head(d);
        let c = cover(p);
        assert!(c < 8.0, "hair over the face at {d}: {c:.1} levels");
        let q = camera.project(head.transform_point3(p)).unwrap();
        assert_ne!(
            head_only.get_pixel(q.x as u32, q.y as u32).0,
            bg,
            "no head at {d}"
        );
    }
}

/// This process's stages, said to run elsewhere (as remote workers that
/// leave the drawing here do), counting the frames they simulated.
#[derive(Debug)]
struct Elsewhere {
    steps: std::sync::Arc<std::sync::atomic::AtomicU32>,
}

impl engine::Executor for Elsewhere {
    fn simulate(
        &mut self,
        anim: &mut engine::Animator,
        plan: &engine::StepPlan,
        stats: &mut FrameStats,
    ) -> Result<Option<engine::PoseReport>, engine::EngineError> {
        self.steps.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
        engine::LocalExecutor.simulate(anim, plan, stats)
    }

    fn density(
        &mut self,
        light: usize,
        map: &mut shadow::DensityMap,
        strands: engine::Strands<'_>,
        fiber: &shadow::Fiber,
    ) -> Result<shadow::FillStats, engine::EngineError> {
        engine::LocalExecutor.density(light, map, strands, fiber)
    }

    fn transmittance(
        &mut self,
        light: usize,
        map: &shadow::DensityMap,
    ) -> Result<shadow::Transmittance, engine::EngineError> {
        engine::LocalExecutor.transmittance(light, map)
    }

    fn runs_elsewhere(&self) -> bool {
        true
    }
}

#[test]
fn stages_elsewhere_run_the_next_frame_while_this_one_is_drawn_here_to_the_same_bytes() {
    for extra in [
        "[animation]\nmotion = \"dance\"\n",
        "[animation]\nmotion = \"dance\"\n[shading]\nmodel = \"marschner\"\n\
         [[light]]\ndirection = [0.9, -0.35, -0.25]\n[[light]]\ndirection = [-0.3, -1, 0.2]\n",
    ] {
        let s = scene(extra);
        // This process, told of the frames to come (the camera framed on
        // their motion): its stages run after each drawing.
        let mut here = Sequence::new(&s).unwrap();
        here.expect_frames(4);
        let want: Vec<_> = (0..4)
            .map(|_| here.next_frame().unwrap().0.clone())
            .collect();
        let steps = std::sync::Arc::new(std::sync::atomic::AtomicU32::new(0));
        let mut seq = Sequence::new(&s).unwrap();
        seq.set_executor(Box::new(Elsewhere {
            steps: steps.clone(),
        }))
        .unwrap();
        seq.expect_frames(4);
        let mut ahead = Vec::new();
        for (f, want) in want.iter().enumerate() {
            let before = steps.load(std::sync::atomic::Ordering::SeqCst);
            let (img, stats) = seq.next_frame().unwrap();
            assert_eq!(stats.index, f as u64);
            assert!(img == want, "frame {f} of {extra:?} is another picture");
            ahead.push(steps.load(std::sync::atomic::Ordering::SeqCst) > before);
        }
        // Each call steps the wisps: frame 0 settles, and every frame but
        // the last steps the next one's wisps while it is drawn. Frame 3's
        // steps ran in frame 2's call, so frame 3's call steps nothing
        // (drawn without the overlap, it would step its own).
        assert_eq!(ahead, [true, true, true, false], "{extra:?}");
    }
}

#[test]
fn the_scene_cannot_change_once_the_next_frames_stages_ran_ahead() {
    // Changing it would render the last frame again with the next
    // frame's hair: a picture of neither (an OpenEXR pass once was).
    let s = scene("[animation]\nmotion = \"dance\"\n");
    let mut seq = Sequence::new(&s).unwrap();
    seq.set_executor(Box::new(Elsewhere {
        steps: Default::default(),
    }))
    .unwrap();
    seq.expect_frames(3);
    seq.next_frame().unwrap();
    let mut other = s.clone();
    other.shading.ambient = 0.0;
    let e = seq.set_scene(&other).unwrap_err();
    assert!(e.to_string().contains("ran ahead"), "{e}");
    // One frame at a time, it changes, and the frame renders again.
    let mut seq = Sequence::new(&s).unwrap();
    seq.set_executor(Box::new(Elsewhere {
        steps: Default::default(),
    }))
    .unwrap();
    seq.next_frame().unwrap();
    seq.set_scene(&other).unwrap();
    assert_eq!(seq.again().unwrap().1.index, 0);
}

/// Frames `from..to` of `scene` as a run that renders only them draws
/// them: the frames before simulated, not drawn, and `expect_frames`
/// told the range's length (as `render --frames A..B` does).
fn run_range(scene: &Scene, from: u64, to: u64) -> Vec<image::RgbImage> {
    let mut seq = Sequence::new(scene).unwrap();
    for _ in 0..from {
        seq.skip_frame().unwrap();
    }
    seq.expect_frames(to - from);
    (from..to)
        .map(|k| {
            let (img, s) = seq.next_frame().unwrap();
            assert_eq!(s.index, k);
            img.clone()
        })
        .collect()
}

#[test]
fn frame_k_is_the_same_whatever_range_is_rendered() {
    // Simulated and rigid hair, with the camera framed by the scene (the
    // dance's span) and by a declared shot.
    for extra in [
        "[animation]\nmotion = \"dance\"\n",
        "[animation]\nmotion = \"dance\"\nframes = 40\n",
        "[animation]\nmotion = \"dance\"\n[effects]\ndynamics = false\n",
    ] {
        let s = scene(extra);
        let all = run_range(&s, 0, 8);
        assert_eq!(run_range(&s, 0, 3)[..], all[..3], "{extra}: 0..3");
        assert_eq!(run_range(&s, 5, 8)[..], all[5..], "{extra}: 5..8");
        assert_eq!(run_range(&s, 6, 7)[0], all[6], "{extra}: 6 alone");
        assert_ne!(all[0], all[7], "{extra}: the head moved");
    }
}

#[test]
fn a_run_resumed_from_saved_wisps_gives_the_same_frames() {
    let s = scene("[animation]\nmotion = \"dance\"\n");
    let mut seq = Sequence::new(&s).unwrap();
    let mut saved = Vec::new();
    let mut all = Vec::new();
    for _ in 0..7 {
        all.push(seq.next_frame().unwrap().0.clone());
        saved.push(seq.wisp_states().expect("simulated"));
    }
    // From frame 4's wisps: frame 4 posed as it was, 5 and 6 stepped on.
    let mut resumed = Sequence::new(&s).unwrap();
    resumed.resume_at(4, saved[4].clone()).unwrap();
    for k in 4..7 {
        let (img, stats) = resumed.next_frame().unwrap();
        assert_eq!(stats.index, k);
        assert_eq!(*img, all[k as usize], "frame {k}");
        assert_eq!(stats.stage(Stage::Simulate).ran, k > 4, "frame {k}");
        assert_eq!(
            resumed.wisp_states().unwrap(),
            saved[k as usize],
            "frame {k}"
        );
    }
    // Wisps of another shape are refused and change nothing.
    let mut other = saved[2].clone();
    other.pop();
    assert!(resumed.resume_at(2, other).is_err());
    assert_eq!(resumed.next_index(), 7);
    // Rigid hair has no wisps to save or resume.
    let rigid = scene("[animation]\nmotion = \"dance\"\n[effects]\ndynamics = false\n");
    let mut seq = Sequence::new(&rigid).unwrap();
    assert!(seq.wisp_states().is_none());
    assert!(seq.resume_at(1, saved[1].clone()).is_err());
}

#[test]
fn the_camera_keeps_the_whole_dance_in_the_picture() {
    // Every frame of a dance's span: hair in every frame, none of it on
    // the picture's edge (the camera is framed on all of them).
    let s = scene("[animation]\nmotion = \"dance\"\nfps = 4\n[effects]\ndynamics = false\n");
    let bg = |p: &image::Rgb<u8>, img: &image::RgbImage| *p == *img.get_pixel(0, 0);
    for (k, img) in run_range(&s, 0, 25).iter().enumerate() {
        let (w, h) = img.dimensions();
        let edge = (0..w)
            .flat_map(|x| [(x, 0), (x, h - 1)])
            .chain((0..h).flat_map(|y| [(0, y), (w - 1, y)]));
        for (x, y) in edge {
            assert!(
                bg(img.get_pixel(x, y), img),
                "frame {k}: hair or head at ({x}, {y})"
            );
        }
        assert!(
            img.pixels().any(|p| !bg(p, img)),
            "frame {k}: nothing drawn"
        );
    }
}
