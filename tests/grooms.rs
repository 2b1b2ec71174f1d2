//! Studio grooms as a user renders them: an Alembic archive and a USD
//! stage of the real Sintel groom render the same picture as its `.hair`
//! copy; an empty or foreign `.abc` is refused, not rendered; an animated
//! cache plays, the same on workers as in one process.

#[path = "../crates/strands/tests/abc_writer/mod.rs"]
mod abc_writer;
mod common;

use std::path::{Path, PathBuf};

use common::wisplight;

fn scratch(name: &str) -> PathBuf {
    common::scratch("grooms", name)
}

fn sintel() -> strands::Hair {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/data/sintel_hair.tfx");
    strands::load(&path, 0).unwrap()
}

/// The same strands as a USD stage's one BasisCurves prim.
fn usda(h: &strands::Hair) -> String {
    let counts: Vec<String> = h.strands().map(|s| s.len().to_string()).collect();
    // Rust's shortest round-trip form: the same f32 parsed back.
    let points: Vec<String> = h
        .points()
        .iter()
        .map(|p| format!("({:?}, {:?}, {:?})", p.x, p.y, p.z))
        .collect();
    format!(
        "#usda 1.0\ndef BasisCurves \"Hair\"\n{{\n    uniform token type = \"linear\"\n    int[] curveVertexCounts = [{}]\n    point3f[] points = [{}]\n}}\n",
        counts.join(", "),
        points.join(", ")
    )
}

#[test]
fn the_sintel_groom_as_alembic_and_as_usd_renders_as_its_hair_copy() {
    let dir = scratch("same");
    let groom = sintel();
    let flat: Vec<f32> = groom.points().iter().flat_map(|p| p.to_array()).collect();
    let counts: Vec<i32> = groom.strands().map(|s| s.len() as i32).collect();
    let abc = abc_writer::archive(vec![abc_writer::curves(
        "hair",
        vec![flat],
        &counts,
        [1, 0, 0],
        Vec::new(),
    )]);
    std::fs::write(dir.join("sintel.abc"), abc).unwrap();
    std::fs::write(dir.join("sintel.hair"), abc_writer::hair_file(&groom)).unwrap();
    std::fs::write(dir.join("sintel.usda"), usda(&groom)).unwrap();
    let mut pictures = Vec::new();
    for name in ["sintel.hair", "sintel.abc", "sintel.usda"] {
        let out = dir.join(format!("{name}.png"));
        let o = wisplight(&[
            "render",
            dir.join(name).to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
            "-q",
        ]);
        assert!(
            o.status.success(),
            "{name}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
        pictures.push(std::fs::read(out).unwrap());
    }
    assert!(
        pictures[0] == pictures[1],
        "the .abc renders another picture"
    );
    assert!(
        pictures[0] == pictures[2],
        "the .usda renders another picture"
    );
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn an_empty_or_foreign_alembic_file_is_refused_not_rendered() {
    let dir = scratch("refused");
    let empty = dir.join("groom.abc");
    std::fs::write(&empty, b"").unwrap();
    let out = dir.join("x.png");
    let o = wisplight(&[
        "render",
        empty.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && !out.exists(), "{err}");
    assert!(
        err.contains("groom.abc") && err.contains("not an Alembic Ogawa archive"),
        "{err}"
    );
    // A scene naming an archive of a mesh alone: the object is named.
    let head = abc_writer::Obj {
        name: "head".into(),
        meta: "schema=AbcGeom_PolyMesh_v1".into(),
        props: Vec::new(),
        children: Vec::new(),
    };
    std::fs::write(dir.join("head.abc"), abc_writer::archive(vec![head])).unwrap();
    std::fs::write(dir.join("s.toml"), "[hair]\nfile = \"head.abc\"\n").unwrap();
    let o = wisplight(&[
        "render",
        dir.join("s.toml").to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success(), "{err}");
    assert!(
        err.contains("holds no curves (it holds /head, a polygon mesh)"),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn an_animated_alembic_cache_plays_the_same_on_two_workers_as_in_one_process() {
    let dir = scratch("cache");
    // 200 strands of the Sintel groom swaying along x over 4 samples.
    let groom = sintel();
    let counts: Vec<i32> = groom.strands().take(200).map(|s| s.len() as i32).collect();
    let n: usize = counts.iter().map(|&c| c as usize).sum();
    let samples: Vec<Vec<f32>> = (0..4)
        .map(|k| {
            groom.points()[..n]
                .iter()
                .flat_map(|p| {
                    [
                        p.x + 0.5 * k as f32 * (30.0 - p.y).max(0.0) / 10.0,
                        p.y,
                        p.z,
                    ]
                })
                .collect()
        })
        .collect();
    let abc = abc_writer::archive(vec![abc_writer::curves(
        "hair",
        samples,
        &counts,
        [1, 0, 0],
        Vec::new(),
    )]);
    std::fs::write(dir.join("cache.abc"), abc).unwrap();
    let cache = dir.join("cache.abc");
    let (local, remote) = (dir.join("l_%d.png"), dir.join("r_%d.png"));
    let o = wisplight(&[
        "render",
        cache.to_str().unwrap(),
        "--frames",
        "5",
        "-q",
        "-o",
        local.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let workers = [common::Worker::start(), common::Worker::start()];
    let list = format!("{},{}", workers[0].addr, workers[1].addr);
    let frame = |p: &Path, k: usize| {
        std::fs::read(p.display().to_string().replace("%d", &k.to_string())).unwrap()
    };
    // The workers pose (sort-middle) or the coordinator does.
    for draw in ["sort-middle", "coordinator"] {
        let o = wisplight(&[
            "coordinator",
            cache.to_str().unwrap(),
            "--workers",
            &list,
            "--draw",
            draw,
            "--frames",
            "5",
            "-q",
            "-o",
            remote.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        for k in 0..5 {
            assert!(
                frame(&local, k) == frame(&remote, k),
                "frame {k} differs with --draw {draw}"
            );
        }
    }
    // It plays: the first four frames differ; the fifth holds the last
    // sample.
    for k in 1..4 {
        assert!(
            frame(&local, k) != frame(&local, k - 1),
            "frame {k} did not move"
        );
    }
    assert!(frame(&local, 4) == frame(&local, 3));
    let _ = std::fs::remove_dir_all(dir);
}
