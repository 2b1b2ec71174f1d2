//! The `wisplight` program as a user runs it: arguments, files, output and
//! exit codes.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn wisplight(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_wisplight"))
        .args(args)
        .output()
        .expect("the binary runs")
}

fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// A fresh directory for one test's files.
fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("wisplight-cli-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn write(dir: &Path, name: &str, text: &str) -> String {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p.display().to_string()
}

/// A small scene: few strands, coarse map, light straight down.
const SMALL: &str = "[hair]\nstyle = \"smooth\"\nstrands_per_wisp = 3\n\n[light]\ndirection = [0, -1, 0]\n\n[shadow]\ncells = 64\n";

#[test]
fn probe_prints_one_row_per_point_in_order_and_full_light_above_the_hair() {
    let dir = scratch("probe");
    let scene = write(&dir, "scene.toml", SMALL);
    // The head is centred at the origin with radius 10: y = 100 is above all
    // hair for light travelling down; y = 0 is inside the head, under hair.
    let points = write(
        &dir,
        "points.csv",
        "x,y,z\n0,100,0\n3,100,-2\n0,0,0\n0,-11,0\n",
    );
    let o = wisplight(&["probe", &scene, "--points", &points]);
    assert!(o.status.success(), "{}", stderr(&o));
    let out = stdout(&o);
    let rows: Vec<&str> = out.lines().collect();
    assert_eq!(rows[0], "x,y,z,transmittance");
    assert_eq!(rows.len(), 5, "{out}");
    assert_eq!(rows[1], "0,100,0,1");
    assert_eq!(rows[2], "3,100,-2,1");
    let t: Vec<f32> = rows[3..]
        .iter()
        .map(|r| r.rsplit(',').next().unwrap().parse().unwrap())
        .collect();
    assert!(t[0] < 1.0, "the crown of the head is under hair: {out}");
    assert!(t.iter().all(|v| (0.0..=1.0).contains(v)), "{out}");
    // Further along the light: never brighter.
    assert!(t[1] <= t[0], "{out}");
}

#[test]
fn probe_reports_point_and_spot_lights_one_column_each() {
    // A point light above the head and a spot light beside it, after a
    // directional light: a column each; full light between each source and
    // the hair, shadow under it. (Transmittance is the shadow alone; the
    // falloff and the cone are the shading's.)
    let dir = scratch("probe-point");
    let scene = write(
        &dir,
        "scene.toml",
        "[hair]\nstyle = \"smooth\"\nstrands_per_wisp = 3\n\n[shadow]\ncells = 64\n\n\
         [[light]]\ndirection = [0, -1, 0]\n\n[[light]]\nposition = [0, 40, 0]\n\n\
         [[light]]\nposition = [40, 0, 0]\ndirection = [-1, 0, 0]\ncone_deg = 40\n",
    );
    let points = write(&dir, "points.csv", "x,y,z\n0,30,0\n35,0,0\n0,0,0\n");
    let o = wisplight(&["probe", &scene, "--points", &points]);
    assert!(o.status.success(), "{}", stderr(&o));
    let out = stdout(&o);
    let rows: Vec<Vec<f32>> = out
        .lines()
        .skip(1)
        .map(|r| r.split(',').map(|v| v.parse().unwrap()).collect())
        .collect();
    assert_eq!(
        out.lines().next().unwrap(),
        "x,y,z,transmittance_0,transmittance_1,transmittance_2"
    );
    // Between the point light and the crown; between the spot and the side.
    assert_eq!(rows[0][4], 1.0, "{out}");
    assert_eq!(rows[1][5], 1.0, "{out}");
    // The head's centre is under hair from above and from the side.
    assert!(rows[2][4] < 1.0 && rows[2][5] < 1.0, "{out}");
}

#[test]
fn probe_names_the_file_line_and_field_of_bad_points() {
    let dir = scratch("badpoints");
    let scene = write(&dir, "scene.toml", SMALL);
    let points = write(&dir, "points.csv", "x,y,z\n0,1,2\n0,nan,2\n");
    let o = wisplight(&["probe", &scene, "--points", &points]);
    assert_eq!(o.status.code(), Some(1));
    let e = stderr(&o);
    assert!(
        e.contains("points.csv") && e.contains("line 3") && e.contains("nan"),
        "{e}"
    );
    assert!(!e.contains("panicked"), "{e}");
    assert!(stdout(&o).is_empty(), "no partial output: {}", stdout(&o));
}

#[test]
fn unknown_scene_keys_are_refused_by_name() {
    let dir = scratch("unknown");
    let scene = write(&dir, "scene.toml", "[fiber]\nwidht = 0.1\n");
    let points = write(&dir, "points.csv", "x,y,z\n0,0,0\n");
    let o = wisplight(&["probe", &scene, "--points", &points]);
    assert_eq!(o.status.code(), Some(1));
    let e = stderr(&o);
    assert!(e.contains("scene.toml") && e.contains("widht"), "{e}");
    assert_eq!(e.trim().lines().count(), 1, "one line: {e}");
}

#[test]
fn bad_values_name_the_field_and_value() {
    let dir = scratch("values");
    let points = write(&dir, "points.csv", "x,y,z\n0,0,0\n");
    for (text, field, value) in [
        ("[shadow]\ncells = 0\n", "shadow.cells", "0"),
        ("[shadow]\ncells = 100000\n", "shadow.cells", "100000"),
        ("[fiber]\nopacity = 1.5\n", "fiber.opacity", "1.5"),
        ("[fiber]\nwidth = -1.0\n", "fiber.width", "-1"),
        ("[light]\ndirection = [0, 0, 0]\n", "light", "0"),
        ("[hair]\nstyle = \"frizzy\"\n", "hair.style", "frizzy"),
        ("[hair]\nfile = \"missing.hair\"\n", "missing.hair", ""),
    ] {
        let scene = write(&dir, "scene.toml", text);
        let o = wisplight(&["probe", &scene, "--points", &points]);
        let e = stderr(&o);
        assert_eq!(o.status.code(), Some(1), "{text}: {e}");
        assert!(
            e.contains(field) && e.contains(value),
            "{text}: expected {field} and {value} in {e}"
        );
        assert!(!e.contains("panicked"), "{e}");
    }
}

#[test]
fn a_truncated_hair_file_is_a_clear_error() {
    let dir = scratch("truncated");
    // A HAIR header that promises 10^9 points, and nothing after it.
    let mut h = vec![0u8; 128];
    h[..4].copy_from_slice(b"HAIR");
    h[4..8].copy_from_slice(&1u32.to_le_bytes());
    h[8..12].copy_from_slice(&1_000_000_000u32.to_le_bytes());
    h[12..16].copy_from_slice(&2u32.to_le_bytes());
    std::fs::write(dir.join("big.hair"), &h).unwrap();
    let scene = write(&dir, "scene.toml", "[hair]\nfile = \"big.hair\"\n");
    let points = write(&dir, "points.csv", "x,y,z\n0,0,0\n");
    let o = wisplight(&["probe", &scene, "--points", &points]);
    let e = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{e}");
    assert!(e.contains("big.hair") && e.contains("truncated"), "{e}");
}

/// A USC-HairSalon `.data` file: an i32 strand count, then per strand an
/// i32 vertex count and f32 xyz per vertex.
fn usc_data(strands: &[Vec<[f32; 3]>]) -> Vec<u8> {
    let mut b = (strands.len() as i32).to_le_bytes().to_vec();
    for s in strands {
        b.extend_from_slice(&(s.len() as i32).to_le_bytes());
        for c in s.iter().flatten() {
            b.extend_from_slice(&c.to_le_bytes());
        }
    }
    b
}

#[test]
fn a_usc_hairsalon_groom_renders_and_a_cut_one_names_its_strand_and_byte() {
    let dir = scratch("usc");
    // A fringe of 200 strands hanging from a ring, and a root-only strand.
    let mut strands: Vec<Vec<[f32; 3]>> = (0..200)
        .map(|i| {
            let a = i as f32 * std::f32::consts::TAU / 200.0;
            (0..12)
                .map(|k| [8.0 * a.cos(), 6.0 - 2.0 * k as f32, 8.0 * a.sin()])
                .collect()
        })
        .collect();
    strands.push(vec![[0.0, 9.0, 0.0]]);
    let bytes = usc_data(&strands);
    std::fs::write(dir.join("groom.data"), &bytes).unwrap();
    let scene = write(&dir, "scene.toml", "[hair]\nfile = \"groom.data\"\n");
    let out = dir.join("groom.png");
    let o = wisplight(&["render", &scene, "-o", out.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    // Hair is drawn: a good share of the picture is not the background.
    let img = image::open(&out).unwrap().to_rgb8();
    let bg = *img.get_pixel(0, 0);
    let covered = img.pixels().filter(|p| **p != bg).count();
    assert!(
        covered * 50 > img.pixels().len(),
        "{covered} pixels of hair"
    );
    // The same strands as a CT2Hair .bin (four more floats a vertex): the
    // same picture.
    let mut bin = (strands.len() as i32).to_le_bytes().to_vec();
    for st in &strands {
        bin.extend((st.len() as i32).to_le_bytes());
        for p in st {
            for v in p.iter().chain(&[0.5, 0.5, 0.5, 1.0]) {
                bin.extend(v.to_le_bytes());
            }
        }
    }
    std::fs::write(dir.join("groom.bin"), &bin).unwrap();
    let scene_bin = write(&dir, "bin.toml", "[hair]\nfile = \"groom.bin\"\n");
    let out_bin = dir.join("bin.png");
    let o = wisplight(&["render", &scene_bin, "-o", out_bin.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(std::fs::read(&out_bin).unwrap() == std::fs::read(&out).unwrap());
    // And as an ASCII PLY with hairutil's per-strand segment counts.
    let points: usize = strands.iter().map(Vec::len).sum();
    let mut ply = format!(
        "ply\nformat ascii 1.0\nelement vertex {points}\nproperty float x\nproperty float y\n\
         property float z\nelement strand {}\nproperty ushort nsegs\nend_header\n",
        strands.len()
    );
    for p in strands.iter().flatten() {
        ply.push_str(&format!("{:?} {:?} {:?}\n", p[0], p[1], p[2]));
    }
    for st in &strands {
        ply.push_str(&format!("{}\n", st.len() - 1));
    }
    std::fs::write(dir.join("groom.ply"), ply).unwrap();
    let scene_ply = write(&dir, "ply.toml", "[hair]\nfile = \"groom.ply\"\n");
    let o = wisplight(&["render", &scene_ply, "-o", out_bin.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(std::fs::read(&out_bin).unwrap() == std::fs::read(&out).unwrap());
    // Cut inside strand 150's vertices.
    let at = 4 + 150 * (4 + 12 * 12) + 4 + 20;
    std::fs::write(dir.join("cut.data"), &bytes[..at]).unwrap();
    let scene = write(&dir, "cut.toml", "[hair]\nfile = \"cut.data\"\n");
    let o = wisplight(&["render", &scene, "-o", out.to_str().unwrap()]);
    let e = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{e}");
    let strand_at = 4 + 150 * (4 + 12 * 12);
    assert!(
        e.contains("cut.data")
            && e.contains("strand 150")
            && e.contains(&format!("byte {strand_at}")),
        "{e}"
    );
}

#[test]
fn a_millimetre_groom_on_a_ply_head_alone_is_drawn_at_its_scale_and_the_same_as_on_its_obj() {
    let dir = scratch("mm-head");
    // A fringe in millimetres: 300 strands on a ring 105 mm round the
    // project's head mesh (a sphere of radius 10 above its middle, placed
    // 10 times larger), 240 mm long.
    let strands: Vec<Vec<[f32; 3]>> = (0..300)
        .map(|i| {
            let a = i as f32 * std::f32::consts::TAU / 300.0;
            (0..13)
                .map(|k| [105.0 * a.cos(), 80.0 - 20.0 * k as f32, 105.0 * a.sin()])
                .collect()
        })
        .collect();
    std::fs::write(dir.join("groom.data"), usc_data(&strands)).unwrap();
    let obj =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/scenes/head.obj")).unwrap();
    std::fs::write(dir.join("head.obj"), &obj).unwrap();
    // The same mesh as a binary PLY.
    let v: Vec<[f32; 3]> = obj
        .lines()
        .filter_map(|l| l.strip_prefix("v "))
        .map(|l| {
            let c: Vec<f32> = l.split_whitespace().map(|x| x.parse().unwrap()).collect();
            [c[0], c[1], c[2]]
        })
        .collect();
    let f: Vec<Vec<u32>> = obj
        .lines()
        .filter_map(|l| l.strip_prefix("f "))
        .map(|l| {
            l.split_whitespace()
                .map(|x| x.parse::<u32>().unwrap() - 1)
                .collect()
        })
        .collect();
    let mut ply = format!(
        "ply\nformat binary_little_endian 1.0\nelement vertex {}\nproperty float x\n\
         property float y\nproperty float z\nelement face {}\n\
         property list uchar int vertex_indices\nend_header\n",
        v.len(),
        f.len()
    )
    .into_bytes();
    v.iter().flatten().for_each(|c| ply.extend(c.to_le_bytes()));
    for face in &f {
        ply.push(face.len() as u8);
        face.iter().for_each(|i| ply.extend(i.to_le_bytes()));
    }
    std::fs::write(dir.join("head.ply"), ply).unwrap();
    let render = |mesh: &str| {
        let scene = write(
            &dir,
            &format!("{mesh}.toml"),
            &format!(
                "[hair]\nfile = \"groom.data\"\n[head]\nmesh = \"{mesh}\"\nmesh_scale = 10\n\
                 [render]\nwidth = 240\nheight = 180\n"
            ),
        );
        let out = dir.join(format!("{mesh}.png"));
        let o = wisplight(&["render", &scene, "-o", out.to_str().unwrap(), "-v"]);
        assert!(o.status.success(), "{}", stderr(&o));
        (std::fs::read(out).unwrap(), stderr(&o))
    };
    let (from_obj, said) = render("head.obj");
    let (from_ply, _) = render("head.ply");
    assert!(from_obj == from_ply, "the PLY head drew another picture");
    // A millimetre strand width (0.1 cm), and the collision sphere fitted to
    // the mesh's crown: radius 10, times 10.
    assert!(said.contains("fiber: width 1.0000 scene units"), "{said}");
    let radius: f32 = said
        .split("collision sphere at [0.000, 0.000, 0.000], radius ")
        .nth(1)
        .and_then(|r| r.split(',').next())
        .and_then(|r| r.parse().ok())
        .unwrap_or_else(|| panic!("no fitted sphere said: {said}"));
    assert!((radius - 100.0).abs() < 1.0, "radius {radius}");
    // Not a faint wireframe: the hair alone at its own width puts over twice
    // the ink (summed difference from the background) of the same
    // hair at the centimetre default's 0.1.
    let ink = |fiber: &str| {
        let scene = write(
            &dir,
            "alone.toml",
            &format!("[hair]\nfile = \"groom.data\"\n{fiber}[render]\nwidth = 240\nheight = 180\n"),
        );
        let out = dir.join("alone.png");
        let o = wisplight(&["render", &scene, "-o", out.to_str().unwrap()]);
        assert!(o.status.success(), "{}", stderr(&o));
        let img = image::open(&out).unwrap().to_rgb8();
        let bg = *img.get_pixel(0, 0);
        img.pixels()
            .flat_map(|p| p.0.iter().zip(bg.0).map(|(&a, b)| u64::from(a.abs_diff(b))))
            .sum::<u64>()
    };
    let (own, cm) = (ink(""), ink("[fiber]\nwidth = 0.1\n"));
    assert!(own > 2 * cm, "ink {own} at the groom's width, {cm} at 0.1");
}

#[test]
fn usage_errors_exit_with_2() {
    assert_eq!(wisplight(&["probe"]).status.code(), Some(2));
    assert_eq!(wisplight(&["frobnicate"]).status.code(), Some(2));
    assert_eq!(
        wisplight(&["bench", "shadow", "--cells", "lots"])
            .status
            .code(),
        Some(2)
    );
}

#[test]
fn bench_shadow_json_is_the_last_line() {
    let dir = scratch("bench");
    let scene = write(&dir, "scene.toml", SMALL);
    let o = wisplight(&[
        "bench", "shadow", &scene, "--runs", "2", "--cells", "32", "--json",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let out = stdout(&o);
    let last = out.lines().last().unwrap();
    let j: serde_json::Value = serde_json::from_str(last).unwrap();
    assert_eq!(j["cells"], 32);
    for key in ["segments", "density_ms", "transmittance_ms", "filter_ms"] {
        assert!(j[key].as_f64().is_some_and(|v| v >= 0.0), "{key} in {last}");
    }
    assert!(j["segments"].as_u64().unwrap() > 1000);
}

#[test]
fn render_without_a_scene_writes_the_built_in_picture() {
    let dir = scratch("render-default");
    let out = dir.join("hair.png");
    let o = wisplight(&["render", "-o", out.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    let img = image::open(&out).unwrap().to_rgb8();
    assert_eq!(img.dimensions(), (1280, 720));
    // Hair and head cover a good part of the frame, not just background.
    let bg = img.get_pixel(0, 0);
    let covered = img.pixels().filter(|p| p != &bg).count();
    assert!(
        covered > 50_000,
        "{covered} pixels differ from the background"
    );
    let names: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(
        names,
        vec![std::ffi::OsString::from("hair.png")],
        "no temporary file left"
    );
    // The summary line names the output; -q leaves stderr empty.
    assert!(stderr(&o).contains("wrote "), "{}", stderr(&o));
    let o = wisplight(&["render", "-q", "-o", out.to_str().unwrap()]);
    assert!(o.status.success() && o.stderr.is_empty(), "{}", stderr(&o));
    // -v says what the run renders: the groom, the map, the camera.
    let o = wisplight(&["render", "-v", "-o", out.to_str().unwrap()]);
    let e = stderr(&o);
    assert!(o.status.success(), "{e}");
    for said in [
        "hair: bounds",
        "strands=3350",
        "map: 128^3 cells",
        "camera: at",
    ] {
        assert!(e.contains(said), "-v does not say {said:?}: {e}");
    }
}

#[test]
fn render_makes_a_missing_output_folder_for_every_kind_of_output_and_checks_it_first() {
    let dir = scratch("render-missing");
    let scene = write(
        &dir,
        "scene.toml",
        &format!("{SMALL}\n[render]\nwidth = 64\nheight = 48\n\n[animation]\nmotion = \"dance\"\n"),
    );
    for (out, frames, made) in [
        ("png/a/x.png", "1", vec!["png/a/x.png"]),
        ("gif/a/x.gif", "2", vec!["gif/a/x.gif"]),
        (
            "seq/a/f_%02d.png",
            "2",
            vec!["seq/a/f_00.png", "seq/a/f_01.png"],
        ),
    ] {
        let o = wisplight(&[
            "render",
            &scene,
            "--frames",
            frames,
            "-o",
            dir.join(out).to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{out}: {}", stderr(&o));
        for m in made {
            assert!(dir.join(m).is_file(), "{out}: {m} missing");
        }
    }
    // A folder that cannot be made (a file stands in its way) is named
    // before anything renders, the same way for each kind.
    std::fs::write(dir.join("file"), b"x").unwrap();
    for out in ["file/x.png", "file/x.gif", "file/f_%02d.png"] {
        let o = wisplight(&["render", &scene, "-o", dir.join(out).to_str().unwrap()]);
        assert_eq!(o.status.code(), Some(1), "{out}");
        let e = stderr(&o);
        assert!(
            e.contains("cannot create the folder") && e.contains("file"),
            "{out}: {e}"
        );
        assert!(
            !e.contains("wrote") && !e.contains("panicked"),
            "{out}: {e}"
        );
    }
}

#[test]
fn a_scene_that_never_ends_or_is_too_big_or_not_text_is_refused_by_name() {
    let dir = scratch("render-caps");
    let out = dir.join("x.png");
    let big = dir.join("big.toml");
    let f = std::fs::File::create(&big).unwrap();
    f.set_len(17 << 20).unwrap();
    let binary = dir.join("binary.toml");
    std::fs::write(&binary, b"\x00\xff\xfe").unwrap();
    for (scene, said) in [
        (Path::new("/dev/zero"), "a device or a FIFO"),
        (big.as_path(), "more than the limit"),
        (binary.as_path(), "not text"),
    ] {
        let o = wisplight(&[
            "render",
            scene.to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
        ]);
        assert_eq!(o.status.code(), Some(1), "{}", scene.display());
        let e = stderr(&o);
        assert!(
            e.contains(scene.to_str().unwrap()) && e.contains(said),
            "{e}"
        );
        assert!(!out.exists());
    }
}

#[test]
fn a_scene_from_a_fifo_that_never_ends_is_refused_at_the_limit() {
    let dir = scratch("render-fifo");
    let fifo = dir.join("endless.toml");
    let made = Command::new("mkfifo").arg(&fifo).status().unwrap();
    assert!(made.success());
    // A writer that never stops (until the reader goes: a broken pipe).
    let path = fifo.clone();
    let writer = std::thread::spawn(move || {
        use std::io::Write;
        let mut f = std::fs::OpenOptions::new().write(true).open(path).unwrap();
        let line = b"# a comment, over and over\n".repeat(4096);
        // Count what each write handed over, a part of a chunk included.
        let mut sent = 0usize;
        loop {
            match f.write(&line[sent % line.len()..]) {
                Ok(0) | Err(_) => break sent,
                Ok(n) => sent += n,
            }
        }
    });
    let out = dir.join("x.png");
    let o = wisplight(&[
        "render",
        fifo.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
    ]);
    let e = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{e}");
    assert!(
        e.contains(fifo.to_str().unwrap()) && e.contains("a device or a FIFO"),
        "{e}"
    );
    assert!(!out.exists());
    // The reader stopped one byte past the 16 MiB limit (what the pipe
    // held beyond that was written but never read).
    let sent = writer.join().unwrap();
    assert!((16 << 20..64 << 20).contains(&sent), "{sent} bytes written");
}

#[test]
fn render_takes_a_groom_file_alone() {
    let dir = scratch("render-groom");
    // Two strands of four points in the .hair format (Yuksel): the header,
    // then the points as f32 triples.
    let mut bytes = Vec::new();
    bytes.extend_from_slice(b"HAIR");
    bytes.extend_from_slice(&2u32.to_le_bytes()); // strands
    bytes.extend_from_slice(&8u32.to_le_bytes()); // points
    bytes.extend_from_slice(&2u32.to_le_bytes()); // fields: points
    bytes.extend_from_slice(&3u32.to_le_bytes()); // default segments
    bytes.extend_from_slice(&1f32.to_le_bytes()); // thickness
    bytes.extend_from_slice(&1f32.to_le_bytes()); // transparency
    for c in [0.5f32, 0.4, 0.3] {
        bytes.extend_from_slice(&c.to_le_bytes());
    }
    bytes.resize(128, 0);
    for s in 0..2 {
        for i in 0..4 {
            for c in [s as f32, -(i as f32), 0.0] {
                bytes.extend_from_slice(&c.to_le_bytes());
            }
        }
    }
    let groom = dir.join("two.hair");
    std::fs::write(&groom, &bytes).unwrap();
    let out = dir.join("two.png");
    let o = wisplight(&[
        "render",
        groom.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("segments"), "{}", stderr(&o));
    // Something was drawn over the background.
    let img = image::open(&out).unwrap().to_rgb8();
    let bg = img.get_pixel(0, 0);
    assert!(img.pixels().any(|p| p != bg));
}

#[test]
fn render_keeps_an_existing_picture_when_the_scene_is_bad() {
    let dir = scratch("render-keep");
    let out = dir.join("keep.png");
    std::fs::write(&out, b"old picture").unwrap();
    let scene = write(&dir, "scene.toml", "[render]\nwidth = -5\n");
    let o = wisplight(&["render", &scene, "-o", out.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("render.width"), "{}", stderr(&o));
    assert_eq!(std::fs::read(&out).unwrap(), b"old picture");
}

#[test]
fn probe_takes_every_method_by_name_and_each_agrees_on_lit_and_shadowed_points() {
    let dir = scratch("probe-methods");
    let scene = write(&dir, "scene.toml", SMALL);
    // Above all hair; and below the head (in its shadow: light travels down).
    let points = write(&dir, "points.csv", "x,y,z\n0,100,0\n0,-11,0\n");
    for method in [
        "density-map",
        "opacity-shadow-map",
        "deep-opacity-map",
        "density-clustering",
        "deep-shadow-map",
        "reference",
    ] {
        let o = wisplight(&["probe", &scene, "--points", &points, "--method", method]);
        assert!(o.status.success(), "{method}: {}", stderr(&o));
        let t: Vec<f32> = stdout(&o)
            .lines()
            .skip(1)
            .map(|r| r.rsplit(',').next().unwrap().parse().unwrap())
            .collect();
        assert!(t[0] > 0.99, "{method}: above the hair T = {}", t[0]);
        assert!(t[1] < 0.01, "{method}: under the head T = {}", t[1]);
    }
    let o = wisplight(&["probe", &scene, "--points", &points, "--method", "raytrace"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("raytrace"), "{}", stderr(&o));
}

#[test]
fn bench_accuracy_writes_a_table_a_csv_and_a_plot() {
    let dir = scratch("accuracy");
    let scene = write(&dir, "scene.toml", SMALL);
    let csv = dir.join("acc.csv");
    let plot = dir.join("acc.png");
    // A plot that is not a .png is refused before anything runs (its SVG
    // would take the same name).
    let o = wisplight(&["bench", "accuracy", &scene, "--plot", "acc.svg"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("acc.svg: the plot is a .png"),
        "{}",
        stderr(&o)
    );
    let o = wisplight(&[
        "bench",
        "accuracy",
        &scene,
        "--methods",
        "density-map,deep-shadow-map",
        "--runs",
        "1",
        "--csv",
        csv.to_str().unwrap(),
        "--plot",
        plot.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = std::fs::read_to_string(&csv).unwrap();
    let rows: Vec<&str> = text.lines().collect();
    assert_eq!(
        rows[0],
        "method,parameters,ms,mean_abs,rms,max,image_error,seen_bias,seen_abs,cycles_error,mean_ratio,\
         scattering_shade_ms,direct_share_error,direct_share,gain,red_green,blue_green,\
         direct_share_error_of_direct,direct_share_error_of_scattered"
    );
    // --bounces compares with Cycles' bounces: it needs --cycles.
    let b = wisplight(&["bench", "accuracy", &scene, "--bounces", "16"]);
    assert_eq!(b.status.code(), Some(2), "{}", stderr(&b));
    assert!(stderr(&b).contains("--cycles"), "{}", stderr(&b));
    // The reference, 15 density-map settings (8 of resolution and filter,
    // 7 with contact shadows) and 4 deep-shadow-map settings.
    assert_eq!(rows.len(), 1 + 1 + 15 + 4, "{text}");
    assert_eq!(
        rows.iter().filter(|r| r.contains(" contact=")).count(),
        7,
        "{text}"
    );
    assert!(rows[1].starts_with("reference,"));
    // As a CSV reader sees it: nineteen fields a row, the parameters
    // whole, no Cycles columns without --cycles.
    let mut reader = csv::Reader::from_path(&csv).unwrap();
    for (i, r) in reader.records().enumerate() {
        let r = r.unwrap();
        assert_eq!(r.len(), 19, "{r:?}");
        assert!(r[1].contains('=') && !r[1].starts_with('"'), "{r:?}");
        assert!((9..19).all(|k| r[k].is_empty()), "{r:?}");
        if i == 0 {
            continue;
        }
        let f: Vec<f64> = (2..9).map(|k| r[k].parse().unwrap()).collect();
        // ms, mean_abs, rms, max, image, seen_bias, seen_abs.
        assert!(f[0] > 0.0, "{r:?}");
        assert!(f[1..5].iter().all(|&e| (0.0..=1.0).contains(&e)), "{r:?}");
        assert!(
            f[1] <= f[2] + 1e-9 && f[2] <= f[3] + 1e-9,
            "mean <= rms <= max: {r:?}"
        );
        assert!(
            f[5].abs() <= f[6] + 1e-9 && f[6] <= 1.0,
            "|bias| <= mean abs: {r:?}"
        );
    }
    let img = image::open(&plot).unwrap();
    assert!(img.width() > 400 && img.height() > 300);
    // The same chart as SVG beside it, naming the methods.
    let svg = std::fs::read_to_string(plot.with_extension("svg")).unwrap();
    assert!(svg.starts_with("<svg") && svg.contains("deep-shadow-map"));
    assert!(stdout(&o).contains("deep-shadow-map"));
}

/// The small scene, dancing, at 96x64 with a short settle.
fn dancing(dir: &Path) -> String {
    write(
        dir,
        "dance.toml",
        &format!(
            "{SMALL}\n[render]\nwidth = 96\nheight = 64\n\n[animation]\nmotion = \"dance\"\n\n[dynamics]\nsettle = 0.1\n"
        ),
    )
}

#[test]
fn render_frames_writes_numbered_pictures_and_per_stage_stats() {
    let dir = scratch("frames");
    let scene = dancing(&dir);
    let pattern = dir.join("out/frame_%04d.png");
    let stats = dir.join("stats.json");
    let o = wisplight(&[
        "render",
        &scene,
        "--frames",
        "4",
        "-o",
        pattern.to_str().unwrap(),
        "--stats",
        stats.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let frames: Vec<image::RgbImage> = (0..4)
        .map(|i| {
            image::open(dir.join(format!("out/frame_{i:04}.png")))
                .unwrap()
                .to_rgb8()
        })
        .collect();
    assert!(frames.windows(2).all(|w| w[0] != w[1]), "the hair moves");
    let j: serde_json::Value = serde_json::from_slice(&std::fs::read(&stats).unwrap()).unwrap();
    let list = j["frames"].as_array().unwrap();
    assert_eq!(list.len(), 4);
    for (i, f) in list.iter().enumerate() {
        assert_eq!(f["index"], i);
        for stage in [
            "simulate",
            "self_collide",
            "body_collide",
            "density",
            "transmittance",
            "filter",
            "shade",
            "draw",
        ] {
            let s = &f["stages"][stage];
            assert_eq!(s["ran"], true, "frame {i} {stage}");
            assert!(s["ms"].as_f64().unwrap() >= 0.0);
        }
    }
    // Not a terminal: no progress bar, one summary line.
    assert_eq!(stderr(&o).lines().count(), 1, "{}", stderr(&o));
}

#[test]
fn a_still_scene_skips_every_stage_after_the_first_frame() {
    let dir = scratch("still");
    let scene = write(
        &dir,
        "still.toml",
        &format!("{SMALL}\n[render]\nwidth = 96\nheight = 64\n"),
    );
    let stats = dir.join("stats.json");
    let o = wisplight(&[
        "render",
        &scene,
        "--frames",
        "30",
        "-o",
        dir.join("f%d.png").to_str().unwrap(),
        "--stats",
        stats.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let j: serde_json::Value = serde_json::from_slice(&std::fs::read(&stats).unwrap()).unwrap();
    let ran = |stage: &str| {
        j["frames"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|f| f["stages"][stage]["ran"] == true)
            .count()
    };
    assert_eq!(ran("simulate"), 0);
    assert_eq!(ran("density"), 1);
    assert_eq!(ran("transmittance"), 1);
    assert!(dir.join("f29.png").exists());
}

#[test]
fn render_writes_an_animated_gif() {
    let dir = scratch("gif");
    let scene = dancing(&dir);
    let gif = dir.join("dance.gif");
    let o = wisplight(&[
        "render",
        &scene,
        "--frames",
        "3",
        "-o",
        gif.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let mut d = gif::DecodeOptions::new()
        .read_info(std::fs::File::open(&gif).unwrap())
        .unwrap();
    assert_eq!((d.width(), d.height()), (96, 64));
    let mut delays = Vec::new();
    while let Some(f) = d.read_next_frame().unwrap() {
        delays.push(f.delay);
    }
    // 30 fps: 3 frames are 10 hundredths of a second, as 3, 4, 3.
    assert_eq!(delays, vec![3, 4, 3]);
    assert_eq!(
        std::fs::read_dir(&dir).unwrap().count(),
        2,
        "scene and GIF only"
    );
}

#[test]
fn several_frames_need_a_numbered_name_and_files_cannot_simulate() {
    let dir = scratch("frames-bad");
    let scene = dancing(&dir);
    let o = wisplight(&[
        "render",
        &scene,
        "--frames",
        "2",
        "-o",
        dir.join("one.png").to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("%04d"), "{}", stderr(&o));

    let bad = write(
        &dir,
        "file.toml",
        "[hair]\nfile = \"groom.hair\"\n\n[effects]\ndynamics = true\n",
    );
    let o = wisplight(&["render", &bad]);
    assert_eq!(o.status.code(), Some(1));
    let e = stderr(&o);
    assert!(
        e.contains("effects.dynamics") && e.contains("rigidly"),
        "{e}"
    );

    let bad = write(&dir, "motion.toml", "[animation]\nmotion = \"twist\"\n");
    let o = wisplight(&["render", &bad]);
    assert!(
        stderr(&o).contains("animation.motion = \"twist\""),
        "{}",
        stderr(&o)
    );
}

/// A `.hair` header (128 bytes) with the given counts and flags, then `body`.
fn hair_file(strands: u32, points: u32, flags: u32, body: &[u8]) -> Vec<u8> {
    let mut h = vec![0u8; 128];
    h[..4].copy_from_slice(b"HAIR");
    h[4..8].copy_from_slice(&strands.to_le_bytes());
    h[8..12].copy_from_slice(&points.to_le_bytes());
    h[12..16].copy_from_slice(&flags.to_le_bytes());
    // Default segments per strand, when there is no segment array.
    h[16..20].copy_from_slice(&(points / strands.max(1)).saturating_sub(1).to_le_bytes());
    h.extend_from_slice(body);
    h
}

#[test]
fn every_bad_input_gets_one_line_naming_it_and_the_right_exit_status() {
    let dir = scratch("bad-inputs");
    let d = |name: &str| dir.join(name).display().to_string();
    let points = write(&dir, "points.csv", "x,y,z\n0,0,0\n");
    std::fs::write(dir.join("garbage.hair"), b"HAIR but not really").unwrap();
    std::fs::write(dir.join("garbage.tfx"), [7u8; 300]).unwrap();
    std::fs::write(
        dir.join("magic.hair"),
        hair_file(1, 2, 2, &[0; 24])
            .iter()
            .enumerate()
            .map(|(i, &b)| if i == 0 { b'X' } else { b })
            .collect::<Vec<u8>>(),
    )
    .unwrap();
    // Segment counts that add up to 3 points for a header that says 4.
    let mut body = 2u16.to_le_bytes().to_vec();
    body.extend_from_slice(&[0u8; 48]);
    std::fs::write(dir.join("counts.hair"), hair_file(1, 4, 1 | 2, &body)).unwrap();
    // A point that is NaN.
    let mut body = Vec::new();
    for v in [0.0f32, 0.0, 0.0, f32::NAN, 1.0, 0.0] {
        body.extend_from_slice(&v.to_le_bytes());
    }
    std::fs::write(dir.join("nan.hair"), hair_file(1, 2, 2, &body)).unwrap();
    std::fs::write(dir.join("latin1.toml"), b"[hair]\nstyle = \"\xe9\"\n").unwrap();

    // (scene text or None for a file named below, extra arguments, exit
    // status, words the message must hold)
    let scene_cases: &[(&str, &[&str])] = &[
        ("[hair\nstyle = 1\n", &["scene.toml", "line 1"]),
        ("[render]\nwdith = 10\n", &["scene.toml", "wdith"]),
        ("[effects]\nhair_glow = true\n", &["hair_glow"]),
        ("[[body]]\ncentre = [0, 0, 0]\nradius = 1\n", &["centre"]),
        ("[fiber]\nwidth = nan\n", &["fiber.width", "NaN"]),
        ("[fiber]\nopacity = inf\n", &["fiber.opacity", "inf"]),
        ("[render]\nwidth = -5\n", &["render.width", "-5"]),
        ("[render]\nwidth = 1000000\n", &["render.width", "1000000"]),
        ("[render]\nwidth = 16384\nheight = 16384\n", &["16384"]),
        ("[shadow]\ncells = 513\n", &["shadow.cells", "513"]),
        ("[camera]\nfov_deg = 0\n", &["camera.fov_deg", "0"]),
        ("[light]\ndirection = [nan, 1, 0]\n", &["light", "NaN"]),
        ("[dynamics]\ntime_step = 5\n", &["dynamics.time_step", "5"]),
        ("[animation]\nfps = 0\n", &["animation.fps", "0"]),
        (
            "[hair]\nstrands = [[[0, 0, 0], [0, nan, 0]]]\n",
            &["hair.strands", "strand 0, point 1"],
        ),
        (
            "[hair]\nstyle = \"smooth\"\nstrands = [[[0, 0, 0]]]\n",
            &["hair.style", "hair.strands"],
        ),
        (
            "[hair]\nfile = \"garbage.hair\"\n",
            &["garbage.hair", "header"],
        ),
        ("[hair]\nfile = \"garbage.tfx\"\n", &["garbage.tfx"]),
        ("[hair]\nfile = \"magic.hair\"\n", &["magic.hair", "magic"]),
        (
            "[hair]\nfile = \"counts.hair\"\n",
            &["counts.hair", "add up"],
        ),
        ("[hair]\nfile = \"nan.hair\"\n", &["nan.hair", "not finite"]),
        (
            "[hair]\nfile = \"nowhere.hair\"\n",
            &["scene.toml: hair.file", "nowhere.hair", "cannot read"],
        ),
        (
            "[hair]\nfile = \"groom.obj\"\n",
            &["groom.obj", "file type"],
        ),
    ];
    for (text, words) in scene_cases {
        let scene = write(&dir, "scene.toml", text);
        for cmd in [
            vec!["render", &scene, "-o", &d("out.png")],
            vec!["probe", &scene, "--points", &points],
        ] {
            let o = wisplight(&cmd);
            let e = stderr(&o);
            assert_eq!(o.status.code(), Some(1), "{text:?} {cmd:?}: {e}");
            assert_eq!(e.trim_end().lines().count(), 1, "{text:?}: one line: {e}");
            assert!(e.starts_with("error: "), "{e}");
            for w in *words {
                assert!(e.contains(w), "{text:?}: {w:?} not in {e}");
            }
            assert!(
                !dir.join("out.png").exists(),
                "{text:?}: an output appeared"
            );
        }
    }

    // Files and arguments: (arguments, exit status, words).
    let latin1 = d("latin1.toml");
    let ok_scene = write(&dir, "ok.toml", SMALL);
    let nan_points = write(&dir, "nan.csv", "x,y,z\n1,2,3\n1,inf,3\n");
    let short_points = write(&dir, "short.csv", "x,y,z\n1,2\n");
    let arg_cases: Vec<(Vec<String>, i32, Vec<&str>)> = vec![
        (
            vec!["render".into(), d("missing.toml")],
            1,
            vec!["missing.toml", "cannot read"],
        ),
        (
            vec!["render".into(), latin1.clone()],
            1,
            vec!["latin1.toml", "UTF-8"],
        ),
        (
            vec![
                "probe".into(),
                ok_scene.clone(),
                "--points".into(),
                nan_points,
            ],
            1,
            vec!["nan.csv", "line 3", "inf"],
        ),
        (
            vec![
                "probe".into(),
                ok_scene.clone(),
                "--points".into(),
                short_points,
            ],
            1,
            vec!["short.csv", "line 2"],
        ),
        (
            vec![
                "probe".into(),
                ok_scene.clone(),
                "--points".into(),
                d("none.csv"),
            ],
            1,
            vec!["none.csv"],
        ),
        (
            vec!["render".into(), "--threads".into(), "0".into()],
            2,
            vec!["--threads", "0"],
        ),
        // Options only where they mean something.
        (
            vec!["certs".into(), d("pki"), "--threads".into(), "2".into()],
            2,
            vec!["--threads"],
        ),
        (
            vec!["render".into(), "--frames".into(), "0".into()],
            2,
            vec!["--frames", "0"],
        ),
        (
            vec!["render".into(), "--frames".into(), "-3".into()],
            2,
            vec!["-3"],
        ),
        (
            vec!["render".into(), "-o".into(), d("x.bmp")],
            2,
            vec!["x.bmp", ".png"],
        ),
        (
            vec!["render".into(), "-o".into(), d("x%s.png")],
            2,
            vec!["x%s.png", "%d"],
        ),
        (
            vec!["render".into(), "--method".into(), "ray-magic".into()],
            2,
            vec!["ray-magic"],
        ),
        (
            vec!["bench".into(), "shadow".into(), "--runs".into(), "0".into()],
            2,
            vec!["--runs", "0"],
        ),
        (
            vec![
                "bench".into(),
                "shadow".into(),
                "--cells".into(),
                "513".into(),
            ],
            2,
            vec!["--cells", "513"],
        ),
    ];
    for (args, code, words) in arg_cases {
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let o = wisplight(&args);
        let e = stderr(&o);
        assert_eq!(o.status.code(), Some(code), "{args:?}: {e}");
        let first = e.lines().next().unwrap_or_default();
        assert!(first.starts_with("error: "), "{args:?}: {e}");
        for w in words {
            assert!(first.contains(w), "{args:?}: {w:?} not in {first}");
        }
        assert!(
            !e.contains("panicked") && !e.contains("RUST_BACKTRACE"),
            "{e}"
        );
    }
    assert!(!dir.join("x.bmp").exists());
}

#[test]
fn a_head_mesh_renders_and_a_bad_one_is_named_with_its_line() {
    let dir = scratch("mesh-head");
    let repo = Path::new(env!("CARGO_MANIFEST_DIR"));
    // The shipped mesh scene, made small.
    let obj = repo.join("scenes/head.obj");
    let scene = write(
        &dir,
        "mesh.toml",
        &format!(
            "{SMALL}\n[render]\nwidth = 160\nheight = 90\n\n[head]\nmesh = {:?}\n",
            obj.display().to_string()
        ),
    );
    let out = dir.join("mesh.png");
    let o = wisplight(&["render", &scene, "-o", out.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    let img = image::open(&out).unwrap().to_rgb8();
    // The neck hangs below the hair: straight under the head's centre,
    // 3/4 of the way down the picture, is head colour, not background.
    let background = img.get_pixel(2, 2);
    let neck = (60..88)
        .filter(|&y| img.get_pixel(80, y) != background)
        .count();
    assert!(neck > 5, "{neck} rows of neck");

    // A broken mesh: named, with its line; the old picture stays.
    std::fs::write(dir.join("bad.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n").unwrap();
    let bad = write(
        &dir,
        "bad.toml",
        &format!("{SMALL}\n[head]\nmesh = \"bad.obj\"\n"),
    );
    let o = wisplight(&["render", &bad, "-o", out.to_str().unwrap()]);
    let e = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{e}");
    assert!(
        e.contains("bad.obj") && e.contains("line 4") && e.contains("face index 9"),
        "{e}"
    );
    assert!(!e.contains("panicked"), "{e}");
    assert_eq!(image::open(&out).unwrap().to_rgb8(), img);
    let missing = write(
        &dir,
        "missing.toml",
        &format!("{SMALL}\n[head]\nmesh = \"nope.obj\"\n"),
    );
    let e = stderr(&wisplight(&[
        "probe",
        &missing,
        "--points",
        &write(&dir, "p.csv", "x,y,z\n0,0,0\n"),
    ]));
    assert!(e.contains("nope.obj"), "{e}");
    let stray = write(
        &dir,
        "stray.toml",
        &format!("{SMALL}\n[head]\nmesh_scale = 2\n"),
    );
    let e = stderr(&wisplight(&["render", &stray, "-o", out.to_str().unwrap()]));
    assert!(
        e.contains("head.mesh_scale") && e.contains("needs head.mesh"),
        "{e}"
    );
}

/// The files in `dir`, hidden ones included, sorted.
fn names_in(dir: &Path) -> Vec<String> {
    let mut n: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    n.sort();
    n
}

#[test]
fn a_render_stopped_by_a_signal_leaves_no_file_and_a_killed_ones_leftover_goes() {
    for (signal, code) in [("TERM", 143), ("INT", 130)] {
        let dir = scratch(&format!("signal-{signal}"));
        // What a render killed outright (SIGKILL) left behind: a process
        // that is gone (pids stay below 2^22 on Linux).
        std::fs::write(dir.join(".out.gif.4999999.x7Kq2Z.tmp"), b"half a gif").unwrap();
        let child = Command::new(env!("CARGO_BIN_EXE_wisplight"))
            .args(["render", "--frames", "1000", "-o"])
            .arg(dir.join("out.gif"))
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        // Until this render's own temporary file is there (and the old one gone).
        let own = format!(".out.gif.{}.", child.id());
        let mut seen = false;
        for _ in 0..600 {
            let names = names_in(&dir);
            if names.len() == 1 && names[0].starts_with(&own) && names[0].ends_with(".tmp") {
                seen = true;
                break;
            }
            std::thread::sleep(std::time::Duration::from_millis(100));
        }
        assert!(seen, "{:?}", names_in(&dir));
        let kill = Command::new("kill")
            .args([format!("-{signal}"), child.id().to_string()])
            .status()
            .unwrap();
        assert!(kill.success());
        let out = child.wait_with_output().unwrap();
        assert_eq!(out.status.code(), Some(code), "{}", stderr(&out));
        assert!(
            stderr(&out).contains(&format!("SIG{signal}")),
            "{}",
            stderr(&out)
        );
        assert!(names_in(&dir).is_empty(), "{:?}", names_in(&dir));
    }
}

/// `wisplight view` as started from a shell: its first stdout line, and
/// the page it serves; stopped with SIGTERM, exit 0.
#[test]
fn view_prints_the_page_address_serves_the_page_and_stops_on_sigterm() {
    use std::io::{BufRead, BufReader, Read, Write};
    let dir = scratch("view");
    let scene = write(&dir, "s.toml", SMALL);
    for (listen, token) in [("127.0.0.1:0", false), ("0.0.0.0:0", true)] {
        let mut child = Command::new(env!("CARGO_BIN_EXE_wisplight"))
            .args(["view", &scene, "--listen", listen])
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        let mut line = String::new();
        BufReader::new(child.stdout.take().unwrap())
            .read_line(&mut line)
            .unwrap();
        let url = line
            .trim()
            .strip_prefix("viewing on ")
            .unwrap_or_else(|| panic!("{line}"));
        assert_eq!(url.contains("?token="), token, "{url}");
        let rest = url.strip_prefix("http://").unwrap();
        let (host, path) = rest.split_once('/').unwrap();
        let port = host.rsplit_once(':').unwrap().1;
        let mut s = std::net::TcpStream::connect(format!("127.0.0.1:{port}")).unwrap();
        write!(
            s,
            "GET /{path} HTTP/1.1\r\nHost: {host}\r\nConnection: close\r\n\r\n"
        )
        .unwrap();
        let mut page = String::new();
        s.read_to_string(&mut page).unwrap();
        assert!(page.starts_with("HTTP/1.1 200"), "{page}");
        assert!(page.contains("<title>wisplight</title>"));
        let pid = child.id().to_string();
        assert!(
            Command::new("kill")
                .args(["-TERM", &pid])
                .status()
                .unwrap()
                .success()
        );
        let out = child.wait_with_output().unwrap();
        assert!(out.status.success(), "{:?} {}", out.status, stderr(&out));
        // Beyond loopback, a warning.
        assert_eq!(
            stderr(&out).contains("beyond loopback"),
            token,
            "{}",
            stderr(&out)
        );
    }
}

#[test]
fn view_refuses_a_bad_scene_an_address_in_use_and_unreachable_workers() {
    let dir = scratch("view-bad");
    let bad = write(&dir, "bad.toml", "[hair]\nstyle = \"wavy\"\n");
    let o = wisplight(&["view", &bad, "--listen", "127.0.0.1:0"]);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("wavy"), "{}", stderr(&o));

    let taken = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = taken.local_addr().unwrap().to_string();
    let scene = write(&dir, "s.toml", SMALL);
    let o = wisplight(&["view", &scene, "--listen", &addr]);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        stderr(&o).contains(&format!("cannot listen on {addr}"))
            && stderr(&o).contains("--listen 127.0.0.1:0 for a free one"),
        "{}",
        stderr(&o)
    );

    let closed = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let gone = closed.local_addr().unwrap().to_string();
    drop(closed);
    let o = wisplight(&[
        "view",
        &scene,
        "--listen",
        "127.0.0.1:0",
        "--workers",
        &gone,
        "--connect-timeout",
        "2",
    ]);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains(&gone), "{}", stderr(&o));
    assert!(stdout(&o).is_empty(), "nothing listened: {}", stdout(&o));

    let o = wisplight(&["view", "--deadline", "0", "--workers", "127.0.0.1:1"]);
    assert_eq!(o.status.code(), Some(2));
}

#[test]
fn bench_runs_the_benchmark_program_and_says_how_to_get_it_when_it_is_missing() {
    // Beside wisplight (as cargo builds and installs them): its exit code
    // and its help come through, under the name `wisplight bench`.
    let o = wisplight(&["bench", "--help"]);
    assert!(o.status.success());
    let help = String::from_utf8_lossy(&o.stdout);
    assert!(
        help.contains("Usage: wisplight bench") && help.contains("scaling"),
        "{help}"
    );
    assert_eq!(wisplight(&["bench", "nonsense"]).status.code(), Some(2));
    // A copy of wisplight alone, with nothing on PATH: a usage error that
    // says what to install.
    let dir = scratch("bench-alone");
    let alone = dir.join("wisplight");
    std::fs::copy(env!("CARGO_BIN_EXE_wisplight"), &alone).unwrap();
    let o = Command::new(&alone)
        .args(["bench", "frame"])
        .env("PATH", "")
        .output()
        .unwrap();
    let e = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{e}");
    assert!(
        e.contains("wisplight-bench") && e.contains("cargo install --path . --locked"),
        "{e}"
    );
}

#[test]
fn first_hour_mistakes_get_a_message_that_says_what_to_do() {
    let dir = scratch("first-hour");
    let d = |name: &str| dir.join(name).display().to_string();
    // A string where a number goes: said in words, not as a Rust type.
    let scene = write(&dir, "s.toml", "[shadow]\ncells = \"64\"\n");
    let o = wisplight(&["render", &scene, "-o", &d("x.png")]);
    assert_eq!(o.status.code(), Some(1));
    let e = stderr(&o);
    assert!(
        e.contains("shadow.cells") && e.contains("expected an integer"),
        "{e}"
    );
    assert!(!e.contains("i64"), "{e}");
    // A mesh, an Alembic or USD groom, even empty, given as the scene:
    // named for what it is, and nothing rendered.
    write(&dir, "head.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
    write(&dir, "groom.abc", "");
    write(&dir, "groom.usda", "#usda 1.0\n");
    for (file, says) in [
        ("head.obj", "a mesh"),
        ("groom.abc", "Alembic"),
        ("groom.usda", "USD"),
    ] {
        let o = wisplight(&["render", &d(file), "-o", &d("x.png")]);
        assert_eq!(o.status.code(), Some(1), "{file}");
        let e = stderr(&o);
        assert!(e.contains(file) && e.contains(says), "{file}: {e}");
        assert!(!e.contains("TOML parse error"), "{file}: {e}");
    }
    assert!(!dir.join("x.png").exists());
    // A file where the output's folder should be.
    let small = write(&dir, "small.toml", SMALL);
    write(&dir, "afile", "not a folder");
    let o = wisplight(&["render", &small, "-o", &d("afile/x.png")]);
    assert_eq!(o.status.code(), Some(1));
    let e = stderr(&o);
    assert!(
        e.contains("afile is a file, not a folder") && !e.contains("File exists"),
        "{e}"
    );
    // A read-only output is kept, and said before any work.
    let ro = write(&dir, "ro.png", "keep me");
    let mut perm = std::fs::metadata(&ro).unwrap().permissions();
    perm.set_readonly(true);
    std::fs::set_permissions(&ro, perm).unwrap();
    let o = wisplight(&["render", &small, "-o", &ro]);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("read-only"), "{}", stderr(&o));
    assert_eq!(std::fs::read_to_string(&ro).unwrap(), "keep me");
}
