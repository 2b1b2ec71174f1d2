//! An animated groom file (here USD; Alembic reads through the same
//! path): frame `k` takes the rest hair from sample `k`, the last sample
//! held past the last, each frame the picture of that sample rendered
//! alone; `hair.sample` fixes one sample for every frame.

use std::path::{Path, PathBuf};

use engine::{Scene, Sequence, Stage};

/// 40 strands hanging down, swaying along x by `0.6 k` at time sample
/// `k` of 3.
fn groom() -> String {
    let mut samples = Vec::new();
    for k in 0..3 {
        let mut points = Vec::new();
        for s in 0..40 {
            let x = (s % 8) as f32 * 0.5 - 2.0;
            let z = (s / 8) as f32 * 0.5 - 1.0;
            for i in 0..5 {
                let sway = 0.6 * k as f32 * i as f32 / 4.0;
                points.push(format!("({}, {}, {z})", x + sway, 5.0 - 2.0 * i as f32));
            }
        }
        samples.push(format!("{}: [{}]", k + 1, points.join(", ")));
    }
    format!(
        "#usda 1.0\ndef BasisCurves \"Hair\"\n{{\n    uniform token type = \"linear\"\n    int[] curveVertexCounts = [{}]\n    point3f[] points.timeSamples = {{\n        {}\n    }}\n}}\n",
        vec!["5"; 40].join(", "),
        samples.join(",\n        ")
    )
}

fn dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("wisplight-anim-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn scene(dir: &Path, extra: &str) -> Scene {
    let text = format!(
        "[hair]\nfile = \"anim.usda\"\n{extra}\n[render]\nwidth = 96\nheight = 64\n\n[shadow]\ncells = 48\n\n[light]\ndirection = [0.3, -1, 0.2]\n\n[camera]\nposition = [0, 1, 30]\nlook_at = [0, 1, 0]\nfov_deg = 30\n"
    );
    Scene::from_toml_str(&text, &dir.join("s.toml")).unwrap()
}

fn frames(scene: &Scene, n: usize) -> (Vec<image::RgbImage>, Vec<bool>) {
    let mut seq = Sequence::new(scene).unwrap();
    let (mut images, mut posed) = (Vec::new(), Vec::new());
    for _ in 0..n {
        let (img, stats) = seq.next_frame().unwrap();
        images.push(img.clone());
        posed.push(stats.stage(Stage::Pose).ran);
    }
    (images, posed)
}

#[test]
fn each_frame_of_an_animated_groom_is_its_sample_rendered_alone() {
    let d = dir("frames");
    std::fs::write(d.join("anim.usda"), groom()).unwrap();
    let (animated, posed) = frames(&scene(&d, ""), 5);
    // The samples differ, so do the frames; each new sample is posed
    // (frame 0's, the rest, was posed when the sequence began), and past
    // the last sample the last is held and nothing is posed again.
    assert!(animated[0] != animated[1] && animated[1] != animated[2]);
    assert!(animated[3] == animated[2] && animated[4] == animated[2]);
    assert_eq!(posed, [false, true, true, false, false]);
    // Frame k is sample k rendered alone: a still of hair.sample = k
    // (the camera placed by the scene), which every frame repeats.
    for (k, frame) in animated.iter().take(3).enumerate() {
        let (fixed, posed) = frames(&scene(&d, &format!("sample = {k}\n")), 3);
        assert!(fixed[0] == *frame, "frame {k} is not sample {k}");
        assert!(
            fixed.iter().all(|f| *f == fixed[0]),
            "sample {k} fixed moves"
        );
        assert_eq!(posed, [false, false, false]);
    }
    let _ = std::fs::remove_dir_all(d);
}

#[test]
fn a_sample_whose_strands_change_is_refused_naming_it() {
    let d = dir("topology");
    // Sample 2 splits the first strand's points differently.
    let usda = "#usda 1.0\ndef BasisCurves \"Hair\"\n{\n    uniform token type = \"linear\"\n    \
        int[] curveVertexCounts.timeSamples = { 1: [2, 2], 2: [3, 1] }\n    \
        point3f[] points.timeSamples = {\n        \
        1: [(0, 5, 0), (0, 0, 0), (1, 5, 0), (1, 0, 0)],\n        \
        2: [(0, 5, 0), (0, 2, 0), (0, 0, 0), (1, 5, 0)],\n    }\n}\n";
    std::fs::write(d.join("anim.usda"), usda).unwrap();
    let mut seq = Sequence::new(&scene(&d, "")).unwrap();
    seq.next_frame().unwrap();
    let e = seq.next_frame().unwrap_err().to_string();
    assert!(
        e.contains("sample 1 has") && e.contains("an animated groom keeps its strands"),
        "{e}"
    );
    let _ = std::fs::remove_dir_all(d);
}
