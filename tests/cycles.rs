//! Blender Cycles as the independent reference: `wisplight export
//! --blender` and `bench accuracy --cycles` as a user runs them.
//!
//! Needs Blender (`apt-get install blender`; `.ci/run` installs it). Without
//! it the tests that render say so and pass, except under CI, where they
//! fail.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn wisplight(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_wisplight"))
        .args(args)
        .output()
        .expect("the binary runs")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("wisplight-cycles-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn write(dir: &Path, name: &str, text: &str) -> String {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p.display().to_string()
}

/// Blender, or `None` (and a note) where it is missing outside CI.
fn blender() -> Option<PathBuf> {
    let found = std::env::var_os("WISPLIGHT_BLENDER")
        .map(PathBuf::from)
        .or_else(|| {
            std::env::split_paths(&std::env::var_os("PATH")?)
                .map(|d| d.join("blender"))
                .find(|p| p.is_file())
        });
    if found.is_none() {
        if std::env::var_os("CI").is_some() {
            panic!("the Cycles tests need Blender: apt-get install blender");
        }
        eprintln!("skipped: no Blender (apt-get install blender, or set WISPLIGHT_BLENDER)");
    }
    found
}

/// A small groom, lit from the side, opaque fibers, seen at 160x96.
const SCENE: &str = "[hair]\nstyle = \"smooth\"\nstrands_per_wisp = 8\n\n\
[fiber]\nwidth = 0.06\nopacity = 1.0\n\n\
[light]\ndirection = [0.9, -0.35, -0.25]\n\n\
[shadow]\ncells = 64\n\n\
[render]\nwidth = 160\nheight = 96\nhair_alpha = 1.0\nnearest = 8\n\n\
[shading]\nmodel = \"marschner\"\neumelanin = 1.3\n";

#[test]
fn export_writes_a_blender_scene_of_the_frame() {
    let dir = scratch("export");
    let scene = write(&dir, "scene.toml", SCENE);
    let out = dir.join("blend");
    let o = wisplight(&[
        "export",
        &scene,
        "--frame",
        "2",
        "--blender",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("blender -b -noaudio --python"),
        "{}",
        stderr(&o)
    );
    let json: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("scene.json")).unwrap()).unwrap();
    assert_eq!(json["format"], "wisplight-cycles-1");
    assert_eq!(json["frame"], 2);
    assert_eq!(
        (json["width"].as_u64(), json["height"].as_u64()),
        (Some(160), Some(96))
    );
    let strands = json["hair"]["strands"].as_u64().unwrap() as usize;
    let points = json["hair"]["points"].as_u64().unwrap() as usize;
    assert_eq!(json["hair"]["width"].as_f64().map(|w| w as f32), Some(0.06));
    // strands.bin: a count per strand, then the points; the counts add up.
    let bin = std::fs::read(out.join("strands.bin")).unwrap();
    assert_eq!(bin.len(), 4 * strands + 12 * points);
    let total: usize = bin[..4 * strands]
        .chunks_exact(4)
        .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize)
        .sum();
    assert_eq!(total, points);
    // The light travels along (0.9, -0.35, -0.25) normalized, z up in
    // Blender: (x, -z, y).
    let d: Vec<f64> = json["lights"][0]["direction"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    let n = (0.9f64 * 0.9 + 0.35 * 0.35 + 0.25 * 0.25).sqrt();
    for (got, want) in d.iter().zip([0.9 / n, 0.25 / n, -0.35 / n]) {
        assert!((got - want).abs() < 1e-5, "{d:?}");
    }
    assert!(out.join("head.bin").is_file() && out.join("scene.py").is_file());
    // A directory that cannot be made is refused, nothing rendered.
    let blocker = write(&dir, "file", "x");
    let o = wisplight(&["export", &scene, "--blender", &format!("{blocker}/sub")]);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("cannot create"), "{}", stderr(&o));
}

#[test]
fn cycles_and_the_exact_reference_see_the_same_shadow() {
    let Some(_) = blender() else { return };
    let dir = scratch("accuracy");
    let scene = write(&dir, "scene.toml", SCENE);
    let csv = dir.join("acc.csv");
    let cycles = dir.join("cycles");
    let run = || {
        wisplight(&[
            "bench",
            "accuracy",
            &scene,
            "--methods",
            "density-map",
            "--runs",
            "1",
            "--csv",
            csv.to_str().unwrap(),
            "--cycles",
            cycles.to_str().unwrap(),
            "--cycles-samples",
            "16",
        ])
    };
    let o = run();
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(cycles.join("cycles.exr").is_file() && cycles.join("cycles-unshadowed.exr").is_file());
    assert!(cycles.join("ratios.png").is_file());
    let mut reader = csv::Reader::from_path(&csv).unwrap();
    let header = reader.headers().unwrap().clone();
    let col = |name: &str| header.iter().position(|h| h == name).unwrap();
    let rows: Vec<csv::StringRecord> = reader.records().map(|r| r.unwrap()).collect();
    let cycles_row = rows.iter().find(|r| &r[0] == "cycles").unwrap();
    let truth: f64 = cycles_row[col("mean_ratio")].parse().unwrap();
    let reference = rows.iter().find(|r| &r[0] == "reference").unwrap();
    let err: f64 = reference[col("cycles_error")].parse().unwrap();
    let mine: f64 = reference[col("mean_ratio")].parse().unwrap();
    // Hair lit from the side shadows itself: well below 1, above 0.
    assert!(
        (0.1..0.9).contains(&truth),
        "Cycles' mean shadow ratio {truth}"
    );
    // The same frame, camera and light: the exact reference's picture
    // agrees with Cycles' block by block (a camera or light exported wrong
    // is off by far more).
    assert!(
        err < 0.15,
        "block ratio error {err} (Cycles {truth}, reference {mine})"
    );
    assert!(
        (mine - truth).abs() < 0.1,
        "mean ratio {mine} against Cycles' {truth}"
    );
    for r in &rows[1..] {
        if &r[0] == "density-map" {
            let e: f64 = r[col("cycles_error")].parse().unwrap();
            assert!((0.0..1.0).contains(&e), "{r:?}");
        }
    }
    // Run again: the same frame's Cycles pictures are reused.
    let o = run();
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("reusing Cycles' pictures"),
        "{}",
        stderr(&o)
    );
}

#[test]
fn bench_accuracy_without_blender_says_so_before_anything_runs() {
    let dir = scratch("noblender");
    let scene = write(&dir, "scene.toml", SCENE);
    let o = Command::new(env!("CARGO_BIN_EXE_wisplight"))
        .args(["bench", "accuracy", &scene, "--cycles"])
        .arg(dir.join("cycles"))
        .env("PATH", "")
        .env("WISPLIGHT_BLENDER", dir.join("no-such-blender"))
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(stderr(&o).contains("blender not found"), "{}", stderr(&o));
    assert!(!dir.join("cycles").exists(), "nothing exported");
}
