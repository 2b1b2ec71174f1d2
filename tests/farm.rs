//! A shot rendered in chunks as a farm renders it: a simulation cache
//! written once, then each chunk in a process of its own (or through a
//! cluster) from the cache, with the frames of one full run; a cache that
//! does not fit is refused by name, and a chunk killed on the way leaves
//! only whole frames.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};

mod common;

use common::Worker;

fn bin() -> &'static str {
    env!("CARGO_BIN_EXE_wisplight")
}

fn run(args: &[&str]) -> Output {
    Command::new(bin()).args(args).output().unwrap()
}

fn ok(o: Output) -> String {
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(o.status.success(), "{err}");
    err
}

fn fails(o: Output) -> String {
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(!o.status.success(), "succeeded: {err}");
    assert_ne!(o.status.code(), Some(101), "panicked: {err}");
    err
}

fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("wisplight-farm-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// The smooth style, small, simulated on a dancing head with self- and
/// body collisions.
const SCENE: &str = "[hair]\nstyle = \"smooth\"\nstrands_per_wisp = 4\n\n[render]\nwidth = 160\nheight = 90\n\n[shadow]\ncells = 64\n\n[animation]\nmotion = \"dance\"\n\n[dynamics]\nsettle = 0.1\n";

/// Frame `k` of the files `dir/f_%04d.png`.
fn frame(dir: &Path, k: u64) -> Vec<u8> {
    let p = dir.join(format!("f_{k:04}.png"));
    std::fs::read(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

/// The PNGs in `dir`, by name.
fn pngs(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .map(|d| {
            d.map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
                .filter(|n| n.ends_with(".png"))
                .collect()
        })
        .unwrap_or_default();
    v.sort();
    v
}

#[test]
fn a_shot_in_three_chunks_from_the_cache_is_the_full_run_frame_for_frame() {
    let dir = scratch("chunks");
    let scene = dir.join("scene.toml");
    std::fs::write(&scene, SCENE).unwrap();
    let (full, cache, chunks) = (dir.join("full"), dir.join("cache"), dir.join("chunks"));
    ok(run(&[
        "render",
        s(&scene),
        "--frames",
        "9",
        "-o",
        &format!("{}/f_%04d.png", s(&full)),
    ]));
    let err = ok(run(&[
        "simulate",
        s(&scene),
        "--frames",
        "9",
        "-o",
        s(&cache),
    ]));
    assert!(err.contains("9 frames"), "{err}");
    assert_eq!(
        std::fs::read_dir(&cache).unwrap().count(),
        9,
        "one file a frame"
    );
    // Three processes, each a chunk, in any order.
    for range in ["6..9", "0..3", "3..=5"] {
        ok(run(&[
            "render",
            s(&scene),
            "--cache",
            s(&cache),
            "--frames",
            range,
            "-o",
            &format!("{}/f_%04d.png", s(&chunks)),
        ]));
    }
    assert_eq!(pngs(&chunks), pngs(&full));
    for k in 0..9 {
        assert!(frame(&chunks, k) == frame(&full, k), "frame {k}");
    }
    // Without a cache: the frames before simulated, then the range.
    let alone = dir.join("alone");
    ok(run(&[
        "render",
        s(&scene),
        "--frames",
        "4..6",
        "-o",
        &format!("{}/f_%04d.png", s(&alone)),
    ]));
    assert_eq!(pngs(&alone), ["f_0004.png", "f_0005.png"]);
    assert!(frame(&alone, 4) == frame(&full, 4) && frame(&alone, 5) == frame(&full, 5));
    // One frame alone, the last of the shot.
    let one = dir.join("one.png");
    ok(run(&[
        "render",
        s(&scene),
        "--frames",
        "8..9",
        "-o",
        s(&one),
    ]));
    assert!(std::fs::read(&one).unwrap() == frame(&full, 8));
}

#[test]
fn a_cache_that_does_not_fit_is_refused_by_name() {
    let dir = scratch("refused");
    let scene = dir.join("scene.toml");
    std::fs::write(&scene, SCENE).unwrap();
    let cache = dir.join("cache");
    ok(run(&[
        "simulate",
        s(&scene),
        "--frames",
        "3",
        "-o",
        s(&cache),
    ]));
    let out = dir.join("f_%04d.png");
    let chunk = |scene: &Path, range: &str| {
        run(&[
            "render",
            s(scene),
            "--cache",
            s(&cache),
            "--frames",
            range,
            "-o",
            s(&out),
        ])
    };
    // Another scene (a stiffer hair).
    let other = dir.join("other.toml");
    std::fs::write(&other, format!("{SCENE}stiffness = 0.5\n")).unwrap();
    let err = fails(chunk(&other, "0..2"));
    assert!(
        err.contains("frame_000000.wlsim") && err.contains("another scene"),
        "{err}"
    );
    // A frame the cache lacks.
    let err = fails(chunk(&scene, "5..6"));
    assert!(
        err.contains("frame_000005.wlsim") && err.contains("wisplight simulate"),
        "{err}"
    );
    // Cut short, and a byte changed.
    let f1 = cache.join("frame_000001.wlsim");
    let bytes = std::fs::read(&f1).unwrap();
    std::fs::write(&f1, &bytes[..bytes.len() / 2]).unwrap();
    let err = fails(chunk(&scene, "1..3"));
    assert!(
        err.contains("frame_000001.wlsim") && err.contains("not a whole"),
        "{err}"
    );
    let mut flipped = bytes.clone();
    let last = flipped.len() - 5;
    flipped[last] ^= 0x10;
    std::fs::write(&f1, &flipped).unwrap();
    let err = fails(chunk(&scene, "1..3"));
    assert!(err.contains("checksum"), "{err}");
    // Frame 2's file renamed as frame 1: it says which frame it holds.
    std::fs::copy(cache.join("frame_000002.wlsim"), &f1).unwrap();
    let err = fails(chunk(&scene, "1..2"));
    assert!(err.contains("holds frame 2, not frame 1"), "{err}");
    // Nothing was written by the refused runs, and the good frames still
    // render.
    assert!(pngs(&dir).is_empty(), "{:?}", pngs(&dir));
    std::fs::write(&f1, &bytes).unwrap();
    ok(chunk(&scene, "1..3"));
    // Hair that is not simulated needs no cache and gets none.
    let rigid = dir.join("rigid.toml");
    std::fs::write(&rigid, format!("{SCENE}\n[effects]\ndynamics = false\n")).unwrap();
    let err = fails(run(&["simulate", s(&rigid), "-o", s(&dir.join("c2"))]));
    assert!(err.contains("not simulated"), "{err}");
}

#[test]
fn a_chunk_killed_on_the_way_leaves_whole_frames_and_runs_again() {
    let dir = scratch("killed");
    let scene = dir.join("scene.toml");
    // Larger, so that the kill lands mid-run.
    std::fs::write(
        &scene,
        SCENE.replace("width = 160\nheight = 90", "width = 640\nheight = 360"),
    )
    .unwrap();
    let cache = dir.join("cache");
    ok(run(&[
        "simulate",
        s(&scene),
        "--frames",
        "40",
        "-o",
        s(&cache),
    ]));
    let out = dir.join("out");
    let args = [
        "render",
        s(&scene),
        "--cache",
        s(&cache),
        "--frames",
        "10..40",
        "-o",
        &format!("{}/f_%04d.png", s(&out)),
    ];
    let mut child: Child = Command::new(bin())
        .args(args)
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    // Killed outright once its first frames are out.
    let t = std::time::Instant::now();
    while pngs(&out).len() < 2 && t.elapsed().as_secs() < 120 {
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    child.kill().unwrap();
    child.wait().unwrap();
    let first = pngs(&out);
    assert!(!first.is_empty());
    // Every file named as a frame is a whole picture.
    for name in &first {
        let img = image::open(out.join(name));
        assert!(img.is_ok(), "{name}: {img:?}");
    }
    // Run again: every frame, the same bytes as frames of one run.
    ok(run(&args));
    let again = pngs(&out);
    assert_eq!(again.len(), 30, "{again:?}");
    let all: Vec<_> = std::fs::read_dir(&out).unwrap().collect();
    assert_eq!(all.len(), 30, "a temporary left: {all:?}");
    let check = dir.join("check");
    ok(run(&[
        "render",
        s(&scene),
        "--frames",
        "39..40",
        "-o",
        &format!("{}/f_%04d.png", s(&check)),
    ]));
    assert!(frame(&check, 39) == frame(&out, 39));
}

#[test]
fn a_chunk_through_the_cluster_from_the_cache_is_the_full_run() {
    let dir = scratch("cluster");
    let scene = dir.join("scene.toml");
    std::fs::write(&scene, SCENE).unwrap();
    let (full, cache, chunk) = (dir.join("full"), dir.join("cache"), dir.join("chunk"));
    ok(run(&[
        "render",
        s(&scene),
        "--frames",
        "7",
        "-o",
        &format!("{}/f_%04d.png", s(&full)),
    ]));
    ok(run(&[
        "simulate",
        s(&scene),
        "--frames",
        "7",
        "-o",
        s(&cache),
    ]));
    let workers: Vec<Worker> = (0..3).map(|_| Worker::start()).collect();
    let list = workers
        .iter()
        .map(|w| w.addr.as_str())
        .collect::<Vec<_>>()
        .join(",");
    ok(run(&[
        "coordinator",
        s(&scene),
        "--workers",
        &list,
        "--cache",
        s(&cache),
        "--frames",
        "3..7",
        "-o",
        &format!("{}/f_%04d.png", s(&chunk)),
    ]));
    assert_eq!(
        pngs(&chunk),
        ["f_0003.png", "f_0004.png", "f_0005.png", "f_0006.png"]
    );
    for k in 3..7 {
        assert!(frame(&chunk, k) == frame(&full, k), "frame {k}");
    }
}
