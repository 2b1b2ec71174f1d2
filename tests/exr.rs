//! OpenEXR output (`render -o frame.exr`, `%04d.exr` for frames): linear
//! float RGBA with the background left out, read back and checked against
//! the PNG of the same frames.

use std::path::PathBuf;
use std::process::{Command, Output};

fn wisplight(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_wisplight"))
        .args(args)
        .output()
        .expect("the binary runs")
}

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("wisplight-exr-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// A small animated scene over a coloured background, with a head.
const SCENE: &str = "[hair]\nstyle = \"smooth\"\nstrands_per_wisp = 3\n\n\
[render]\nwidth = 96\nheight = 64\nbackground = [0.2, 0.3, 0.4]\n\n\
[animation]\nmotion = \"dance\"\n\n[shadow]\ncells = 64\n";

#[test]
fn exr_frames_are_the_png_frames_before_encoding_with_coverage_as_alpha() {
    let dir = scratch("frames");
    let scene = dir.join("s.toml");
    std::fs::write(&scene, SCENE).unwrap();
    let scene = scene.to_str().unwrap();
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
    // A coordinator's pictures are finished on the workers: refused before
    // any worker is dialled.
    let o = wisplight(&["coordinator", "--workers", "127.0.0.1:9", "-o", &one]);
    assert_eq!(o.status.code(), Some(2));
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(e.contains("OpenEXR") && e.contains(".png"), "{e}");
    assert!(!std::path::Path::new(&one).exists());
}
