//! OpenEXR output (`render -o frame.exr`, `%04d.exr` for frames): linear
//! float RGBA with the background left out, read back and checked against
//! the PNG of the same frames, and from a coordinator the same bytes.

mod common;

use std::path::PathBuf;

use common::wisplight;

fn scratch(name: &str) -> PathBuf {
    common::scratch("exr", name)
}

/// A fresh folder for test `name` holding `text` as its scene `s.toml`:
/// the folder and the scene's path.
fn with_scene(name: &str, text: &str) -> (PathBuf, String) {
    let dir = scratch(name);
    let scene = dir.join("s.toml");
    std::fs::write(&scene, text).unwrap();
    (dir, scene.display().to_string())
}

/// A small animated scene over a coloured background, with a head.
const SCENE: &str = "[hair]\nstyle = \"smooth\"\nstrands_per_wisp = 3\n\n\
[render]\nwidth = 96\nheight = 64\nbackground = [0.2, 0.3, 0.4]\n\n\
[animation]\nmotion = \"dance\"\n\n[shadow]\ncells = 64\n";

#[test]
fn exr_frames_are_the_png_frames_before_encoding_with_coverage_as_alpha() {
    let (dir, scene) = with_scene("frames", SCENE);
    let scene = scene.as_str();
    let at = |name: &str| dir.join(name).display().to_string();
    for out in ["f_%04d.png", "f_%04d.exr"] {
        let o = wisplight(&["-q", "render", scene, "--frames", "3", "-o", &at(out)]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    }
    let bg = glam::Vec3::new(0.2, 0.3, 0.4);
    for frame in 0..3 {
        let png = image::open(at(&format!("f_{frame:04}.png")))
            .unwrap()
            .into_rgb8();
        let exr = image::open(at(&format!("f_{frame:04}.exr")))
            .unwrap()
            .into_rgba32f();
        assert_eq!(exr.dimensions(), (96, 64));
        let (mut same, mut clear, mut solid, mut partial) = (0, 0, 0, 0);
        for (p, e) in png.pixels().zip(exr.pixels()) {
            let [r, g, b, a] = e.0;
            assert!((0.0..=1.0).contains(&a), "alpha {a}");
            assert!([r, g, b].iter().all(|c| c.is_finite() && *c >= 0.0));
            match a {
                0.0 => {
                    clear += 1;
                    // Nothing covers it: no colour either.
                    assert_eq!([r, g, b], [0.0; 3]);
                }
                1.0 => solid += 1,
                _ => partial += 1,
            }
            // Over the scene's background, encoded: the PNG's pixel.
            let over = glam::Vec3::new(r, g, b) + bg * (1.0 - a);
            let want = raster::to_srgb8(over);
            let off = (0..3).map(|c| p.0[c].abs_diff(want[c])).max().unwrap();
            assert!(off <= 1, "frame {frame}: {:?} vs {want:?}", p.0);
            same += usize::from(off == 0);
        }
        let n = 96 * 64;
        assert!(same * 1000 >= n * 999, "frame {frame}: {same} of {n} exact");
        // The background, the head and the hair's edges.
        assert!(
            clear > 0 && solid > 0 && partial > 0,
            "{clear} {solid} {partial}"
        );
    }
}

#[test]
fn exr_output_is_refused_where_it_cannot_be_made() {
    let dir = scratch("refused");
    let one = dir.join("one.exr").display().to_string();
    // Several frames need a numbered name.
    let o = wisplight(&["render", "--frames", "2", "-o", &one]);
    assert_eq!(o.status.code(), Some(2));
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(e.contains("%04d.exr"), "{e}");
    // The workers finish their bands as 8-bit: a coordinator asked to
    // draw there is refused before any worker is dialled.
    for draw in ["sort-middle", "sort-last"] {
        let o = wisplight(&[
            "coordinator",
            "--workers",
            "127.0.0.1:9",
            "--draw",
            draw,
            "-o",
            &one,
        ]);
        assert_eq!(o.status.code(), Some(2));
        let e = String::from_utf8_lossy(&o.stderr);
        assert!(e.contains("OpenEXR") && e.contains(draw), "{e}");
    }
    assert!(!std::path::Path::new(&one).exists());
}

#[test]
fn a_coordinator_writes_the_same_openexr_bytes_as_one_process_passes_included() {
    let (dir, scene) = with_scene("cluster", PASSES);
    let workers = [common::Worker::start(), common::Worker::start()];
    let list = format!("{},{}", workers[0].addr, workers[1].addr);
    let (local, remote) = (dir.join("local_%04d.exr"), dir.join("remote_%04d.exr"));
    let args = |out: &PathBuf| -> Vec<String> {
        [
            &scene,
            "--frames",
            "3",
            "--passes",
            "direct,scattered,sky,shadow,depth",
            "-o",
        ]
        .iter()
        .map(|a| a.to_string())
        .chain([out.display().to_string()])
        .collect()
    };
    let mut render = vec!["render".to_string()];
    render.extend(args(&local));
    let render: Vec<&str> = render.iter().map(String::as_str).collect();
    let o = wisplight(&render);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let mut coordinator = vec!["coordinator".to_string(), "--workers".into(), list];
    coordinator.extend(args(&remote));
    let coordinator: Vec<&str> = coordinator.iter().map(String::as_str).collect();
    let o = wisplight(&coordinator);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    for k in 0..3 {
        let name = |p: &PathBuf| p.display().to_string().replace("%04d", &format!("{k:04}"));
        let (a, b) = (
            std::fs::read(name(&local)).unwrap(),
            std::fs::read(name(&remote)).unwrap(),
        );
        assert!(a == b, "frame {k}: the coordinator's OpenEXR differs");
        // And it holds every pass asked for.
        let c = channels(&name(&remote));
        for layer in [
            "direct.R",
            "scattered.G",
            "sky.B",
            "shadow.R",
            "depth.Z",
            "A",
        ] {
            assert!(c.contains_key(layer), "frame {k}: no {layer}");
        }
    }
    let _ = std::fs::remove_dir_all(dir);
}

/// Light hair with every light term: the fiber model, multiple
/// scattering and a sky.
const PASSES: &str = "[hair]\nstyle = \"smooth\"\nstrands_per_wisp = 3\n\n\
[render]\nwidth = 96\nheight = 64\nbackground = [0.1, 0.2, 0.3]\n\n[animation]\nmotion = \"dance\"\n\n\
[shadow]\ncells = 64\n\n[shading]\nmodel = \"marschner\"\neumelanin = 0.3\nambient = 0.3\n\n\
[effects]\nmultiple_scattering = true\n";

/// The channels of the first layer of an OpenEXR file, by name.
fn channels(path: &str) -> std::collections::HashMap<String, Vec<f32>> {
    let img = exr::prelude::read_all_flat_layers_from_file(path).unwrap();
    let layer = &img.layer_data[0];
    layer
        .channel_data
        .list
        .iter()
        .map(|c| {
            let v = match &c.sample_data {
                exr::prelude::FlatSamples::F32(v) => v.clone(),
                other => panic!("{}: not f32 {other:?}", c.name),
            };
            (c.name.to_string(), v)
        })
        .collect()
}

#[test]
fn the_light_passes_add_up_to_the_beauty_and_the_frames_stay_the_same() {
    let (dir, scene) = with_scene("passes", PASSES);
    let scene = scene.as_str();
    let at = |name: &str| dir.join(name).display().to_string();
    let o = wisplight(&[
        "-q",
        "render",
        scene,
        "--frames",
        "2",
        "-o",
        &at("f_%04d.png"),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    // The same frames without the sky: direct + scattered.
    let plain = dir.join("plain.toml");
    std::fs::write(&plain, PASSES.replace("ambient = 0.3", "ambient = 0")).unwrap();
    let plain = plain.to_str().unwrap();
    let o = wisplight(&[
        "-q",
        "render",
        plain,
        "--frames",
        "2",
        "-o",
        &at("p_%04d.png"),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let o = wisplight(&[
        "-q",
        "render",
        scene,
        "--frames",
        "2",
        "-o",
        &at("f_%04d.exr"),
        "--passes",
        "direct,scattered,sky,shadow,depth",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    for frame in 0..2 {
        let c = channels(&at(&format!("f_{frame:04}.exr")));
        let mut names: Vec<&String> = c.keys().collect();
        names.sort();
        assert_eq!(
            names,
            [
                "A",
                "B",
                "G",
                "R",
                "depth.Z",
                "direct.B",
                "direct.G",
                "direct.R",
                "scattered.B",
                "scattered.G",
                "scattered.R",
                "shadow.B",
                "shadow.G",
                "shadow.R",
                "sky.B",
                "sky.G",
                "sky.R"
            ]
        );
        // The beauty is the PNG's frame: the passes changed no frame.
        let png = image::open(at(&format!("f_{frame:04}.png")))
            .unwrap()
            .into_rgb8();
        let bg = glam::Vec3::new(0.1, 0.2, 0.3);
        let no_sky = image::open(at(&format!("p_{frame:04}.png")))
            .unwrap()
            .into_rgb8();
        let (mut sky_lit, mut scattered_lit, mut shadowed) = (0, 0, 0);
        for (i, (got, plain)) in png
            .as_raw()
            .chunks_exact(3)
            .zip(no_sky.as_raw().chunks_exact(3))
            .enumerate()
        {
            let get = |k: &str| c[k][i];
            let a = get("A");
            for ch in ["R", "G", "B"] {
                let beauty = get(ch);
                let (d, s, k_) = (
                    get(&format!("direct.{ch}")),
                    get(&format!("scattered.{ch}")),
                    get(&format!("sky.{ch}")),
                );
                assert!(
                    (d + s + k_ - beauty).abs() <= 1e-5 + 1e-5 * beauty.abs(),
                    "pixel {i} {ch}: {d} + {s} + {k_} != {beauty}"
                );
                assert!(
                    d >= -1e-6 && k_ >= -1e-4 && s >= -1e-3,
                    "pixel {i}: {d} {s} {k_}"
                );
                let shadow = get(&format!("shadow.{ch}"));
                assert!(shadow >= -1e-3, "pixel {i}: shadow {shadow}");
                sky_lit += usize::from(k_ > 1e-3);
                scattered_lit += usize::from(s > 1e-3);
                shadowed += usize::from(shadow > 1e-3);
            }
            let over = glam::Vec3::new(get("R"), get("G"), get("B")) + bg * (1.0 - a);
            let want = raster::to_srgb8(over);
            let off = (0..3).map(|k| got[k].abs_diff(want[k])).max().unwrap();
            assert!(off <= 1, "frame {frame} pixel {i}: {got:?} vs {want:?}");
            // Direct and scattered alone are the picture without the sky.
            let lit = |ch: &str| get(&format!("direct.{ch}")) + get(&format!("scattered.{ch}"));
            let over = glam::Vec3::new(lit("R"), lit("G"), lit("B")) + bg * (1.0 - a);
            let want = raster::to_srgb8(over);
            let off = (0..3).map(|k| plain[k].abs_diff(want[k])).max().unwrap();
            assert!(off <= 1, "frame {frame} pixel {i}: {plain:?} vs {want:?}");
            // Nothing drawn: no depth; the head: a depth.
            let z = get("depth.Z");
            if a == 0.0 {
                assert_eq!(z, 1e10, "pixel {i}");
            } else {
                assert!(z > 0.0 && z < 1e9, "pixel {i}: {z}");
            }
        }
        assert!(sky_lit > 0 && scattered_lit > 0 && shadowed > 0);
    }
    // Passes belong in an OpenEXR file.
    let o = wisplight(&["render", scene, "-o", &at("x.png"), "--passes", "direct"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("write .exr"));
}
