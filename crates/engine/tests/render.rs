//! Whole frames: golden pictures, shadow switches and determinism.

use std::path::{Path, PathBuf};

use engine::{Renderer, Scene, build_hair};
use glam::Vec3;

/// A small scene: few strands on the default head, a 96x64 picture.
fn small_scene(extra: &str) -> Scene {
    let text = format!(
        "[hair]\nstrands_per_wisp = 4\n\n[render]\nwidth = 96\nheight = 64\n\n[shadow]\ncells = 64\n{extra}"
    );
    Scene::from_toml_str(&text, Path::new("small.toml")).unwrap()
}

fn render(scene: &Scene, shadows: bool) -> image::RgbImage {
    let hair = build_hair(scene).unwrap();
    Renderer::new(scene)
        .unwrap()
        .render(&hair, shadows)
        .unwrap()
}

fn golden_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/golden")
}

/// Compares `img` with the golden picture `name`: every channel within
/// `tol` of it, except at most `outliers` pixels. On failure writes the
/// picture and an amplified difference beside the golden one. With
/// `WISPLIGHT_BLESS=1` writes `img` as the new golden picture instead
/// (look at it before committing it).
fn check_golden(name: &str, img: &image::RgbImage, tol: u8, outliers: usize) {
    let path = golden_dir().join(name);
    if std::env::var_os("WISPLIGHT_BLESS").is_some() {
        img.save(&path).unwrap();
        return;
    }
    let golden = image::open(&path)
        .unwrap_or_else(|e| {
            panic!(
                "{}: {e} (run with WISPLIGHT_BLESS=1 to create it)",
                path.display()
            )
        })
        .to_rgb8();
    assert_eq!(golden.dimensions(), img.dimensions(), "{name}: size");
    let mut diff = image::RgbImage::new(img.width(), img.height());
    let mut bad = 0;
    for (x, y, p) in img.enumerate_pixels() {
        let g = golden.get_pixel(x, y);
        let d: Vec<u8> = (0..3).map(|k| p[k].abs_diff(g[k])).collect();
        if d.iter().any(|&v| v > tol) {
            bad += 1;
        }
        diff.put_pixel(
            x,
            y,
            image::Rgb([
                d[0].saturating_mul(8),
                d[1].saturating_mul(8),
                d[2].saturating_mul(8),
            ]),
        );
    }
    if bad > outliers {
        let out = std::env::temp_dir();
        img.save(out.join(format!("actual-{name}"))).unwrap();
        diff.save(out.join(format!("diff-{name}"))).unwrap();
        panic!(
            "{name}: {bad} pixels differ by more than {tol}; see {} and {}",
            out.join(format!("actual-{name}")).display(),
            out.join(format!("diff-{name}")).display()
        );
    }
}

#[test]
fn the_small_scene_matches_its_golden_pictures() {
    let scene = small_scene("");
    check_golden("small-shadowed.png", &render(&scene, true), 3, 10);
    check_golden("small-unshadowed.png", &render(&scene, false), 3, 10);
}

#[test]
fn shadows_darken_hair_and_never_brighten_it() {
    let scene = small_scene("");
    let (lit, dark) = (render(&scene, false), render(&scene, true));
    let sum = |img: &image::RgbImage| {
        img.pixels()
            .map(|p| p.0.iter().map(|&v| u64::from(v)).sum::<u64>())
            .sum::<u64>()
    };
    assert!(sum(&dark) < sum(&lit), "self-shadowing must remove light");
    let brighter = lit
        .pixels()
        .zip(dark.pixels())
        .filter(|(a, b)| (0..3).any(|k| b[k] > a[k].saturating_add(1)))
        .count();
    assert_eq!(
        brighter, 0,
        "a shadowed pixel is never brighter than the unshadowed one"
    );
}

#[test]
fn no_shadow_equals_fibers_of_zero_opacity() {
    let off = small_scene("\n[effects]\nhead_shadow = false\n");
    let clear = small_scene("\n[effects]\nhead_shadow = false\n\n[fiber]\nopacity = 0.0\n");
    assert!(render(&off, false) == render(&clear, true));
}

#[test]
fn the_same_scene_gives_the_same_bytes_on_any_number_of_threads() {
    let scene = small_scene("");
    let on = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| render(&scene, true).into_raw())
    };
    let one = on(1);
    assert!(one == on(2));
    assert!(one == on(5));
}

/// Writes a UV sphere of `rings` x `segments` (centre 0, radius `r`) as OBJ.
fn write_uv_sphere(path: &Path, r: f32, rings: u32, segments: u32) {
    use std::fmt::Write;
    let mut obj = String::new();
    writeln!(obj, "v 0 {r} 0\nv 0 {} 0", -r).unwrap();
    for i in 1..rings {
        let theta = std::f32::consts::PI * i as f32 / rings as f32;
        for j in 0..segments {
            let phi = std::f32::consts::TAU * j as f32 / segments as f32;
            let (x, y, z) = (
                theta.sin() * phi.cos(),
                theta.cos(),
                theta.sin() * phi.sin(),
            );
            writeln!(obj, "v {} {} {}", r * x, r * y, r * z).unwrap();
        }
    }
    // 1-based indices.
    let at = |i: u32, j: u32| 3 + (i - 1) * segments + j % segments;
    for j in 0..segments {
        writeln!(obj, "f 1 {} {}", at(1, j + 1), at(1, j)).unwrap();
        writeln!(obj, "f 2 {} {}", at(rings - 1, j), at(rings - 1, j + 1)).unwrap();
        for i in 1..rings - 1 {
            let (a, b, c, d) = (at(i, j), at(i, j + 1), at(i + 1, j + 1), at(i + 1, j));
            writeln!(obj, "f {a} {b} {c} {d}").unwrap();
        }
    }
    std::fs::write(path, obj).unwrap();
}

fn mean_abs_diff(a: &image::RgbImage, b: &image::RgbImage) -> f64 {
    let sum: u64 = a
        .as_raw()
        .iter()
        .zip(b.as_raw())
        .map(|(&x, &y)| u64::from(x.abs_diff(y)))
        .sum();
    sum as f64 / a.as_raw().len() as f64
}

#[test]
fn a_head_mesh_of_the_sphere_draws_and_shadows_like_the_sphere() {
    let dir = std::env::temp_dir().join(format!("wisplight-mesh-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let obj = dir.join("sphere.obj");
    // The styles' head: radius 10 at the origin.
    write_uv_sphere(&obj, 10.0, 48, 96);
    let size = "\n[render]\nwidth = 192\nheight = 128\n";
    let text = |head: &str| {
        format!("[hair]\nstrands_per_wisp = 4\n\n[shadow]\ncells = 64\n{size}\n[head]\n{head}\n")
    };
    let scene = |head: &str| Scene::from_toml_str(&text(head), &dir.join("s.toml")).unwrap();
    let sphere = scene("");
    let mesh = scene("mesh = \"sphere.obj\"");
    let hidden = scene("visible = false");
    let hair = build_hair(&sphere).unwrap();
    let frame = |s: &Scene| {
        let mut r = Renderer::new(s).unwrap();
        let img = r.render(&hair, true).unwrap();
        (img, r.transmittance()[0].clone())
    };
    let (img_s, t_s) = frame(&sphere);
    let (img_m, t_m) = frame(&mesh);
    let (img_h, t_h) = frame(&hidden);
    std::fs::remove_dir_all(&dir).unwrap();
    // The picture: nearly the same with the mesh, clearly not without a head.
    let (near, far) = (mean_abs_diff(&img_s, &img_m), mean_abs_diff(&img_s, &img_h));
    assert!(near < 0.1, "mean difference {near} of 255 to the sphere");
    assert!(far > 4.0 * near && far > 1.0, "without a head only {far}");
    // The head's shadow on the hair: nearly the same transmittance.
    let mean = |a: &[f32], b: &[f32]| {
        a.iter().zip(b).map(|(x, y)| (x - y).abs()).sum::<f32>() / a.len() as f32
    };
    let (near, far) = (mean(&t_s, &t_m), mean(&t_s, &t_h));
    assert!(near < 0.003, "mean |dT| {near} to the sphere");
    assert!(far > 0.05, "without a head's shadow only {far}");
}

/// The head's own shading, hair made invisible, with the hair's shadow on
/// it and without: the mean |discrete Laplacian| of the difference over the
/// pixels the shadow changes (a smooth shadow has little; acne, dots and
/// stripes of its own deposit, much), and the shadow's mean depth there.
fn head_shadow_roughness(head: &str, dir: &Path) -> (f64, f64) {
    let scene = |on: bool| {
        let text = format!(
            "[hair]\nstyle = \"smooth\"\n\n[render]\nhair_alpha = 0\n\n[effects]\nhead_shadow = {on}\n{head}"
        );
        Scene::from_toml_str(&text, &dir.join("s.toml")).unwrap()
    };
    let gray = |img: &image::RgbImage| -> Vec<f64> {
        img.pixels()
            .map(|p| p.0.iter().map(|&v| f64::from(v)).sum::<f64>() / 3.0)
            .collect()
    };
    let (on, off) = (
        gray(&render(&scene(true), true)),
        gray(&render(&scene(false), true)),
    );
    let (w, h) = (1280, 720);
    let d: Vec<f64> = off.iter().zip(&on).map(|(a, b)| a - b).collect();
    let (mut lap, mut depth, mut changed) = (0.0, 0.0, 0usize);
    for y in 1..h - 1 {
        for x in 1..w - 1 {
            let i = y * w + x;
            if d[i] != 0.0 {
                lap += (4.0 * d[i] - d[i - 1] - d[i + 1] - d[i - w] - d[i + w]).abs();
                depth += d[i];
                changed += 1;
            }
        }
    }
    assert!(
        changed > 1000,
        "{head}: the shadow changes only {changed} pixels"
    );
    (lap / changed as f64, depth / changed as f64)
}

#[test]
fn the_hairs_shadow_on_the_head_is_smooth_and_still_there() {
    let dir = std::env::temp_dir().join(format!("wisplight-acne-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let mesh = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/head.obj");
    let mesh = format!("\n[head]\nmesh = {:?}\n", mesh.to_str().unwrap());
    for (name, head) in [("sphere", ""), ("head mesh", mesh.as_str())] {
        let (rough, depth) = head_shadow_roughness(head, &dir);
        // With the lookups at the surface itself: 5.3 levels on either.
        assert!(
            rough < 3.0,
            "{name}: shadow acne, mean |Laplacian| {rough:.2} levels"
        );
        // The hair's shadow stays: its mean there is 23 to 25 levels (the
        // hair lying on the head read down to the surface).
        assert!(
            depth > 15.0,
            "{name}: the hair's shadow is gone ({depth:.1} levels)"
        );
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_groom_in_millimetres_lying_on_its_side_is_placed_by_the_scene() {
    let dir = std::env::temp_dir().join(format!("wisplight-place-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    // USC-HairSalon layout: strand count, then per strand its point count
    // and points. Hair 40 mm long along +x, 16 strands 2 mm apart in z.
    let (mut mm, mut cm) = (Vec::new(), Vec::<Vec<[f32; 3]>>::new());
    mm.extend(16i32.to_le_bytes());
    for s in 0..16 {
        mm.extend(5i32.to_le_bytes());
        let mut strand = Vec::new();
        for k in 0..5 {
            let p = [10.0 * k as f32, 0.0, 2.0 * s as f32 - 15.0];
            mm.extend(p.iter().flat_map(|v| v.to_le_bytes()));
            // Placed by hand: a tenth, +x turned to -y (about z by -90
            // degrees: (x, y, z) -> (y, -x, z)), raised 2 cm.
            strand.push([p[1] / 10.0, -p[0] / 10.0 + 2.0, p[2] / 10.0]);
        }
        cm.push(strand);
    }
    std::fs::write(dir.join("side.data"), &mm).unwrap();
    let placed = Scene::from_toml_str(
        "[hair]\nfile = \"side.data\"\nscale = 0.1\nrotate_deg = [0, 0, -90]\ntranslate = [0, 2, 0]\n",
        &dir.join("scene.toml"),
    )
    .unwrap();
    let by_hand = Scene::from_toml_str(
        &format!("[hair]\nstrands = {cm:?}\n"),
        &dir.join("scene.toml"),
    )
    .unwrap();
    let (a, b) = (
        engine::build_hair(&placed).unwrap(),
        engine::build_hair(&by_hand).unwrap(),
    );
    assert_eq!(a.point_count(), b.point_count());
    let worst = a
        .points()
        .iter()
        .zip(b.points())
        .map(|(p, q)| p.distance(*q))
        .fold(0.0f32, f32::max);
    assert!(
        worst < 1e-4,
        "placed {worst} cm away from the hand-placed groom"
    );
    // Hanging down from y = 2 cm to -2 cm, 1.5 cm either side in z.
    let bounds = a.bounds();
    assert!(
        (bounds.max.y - 2.0).abs() < 1e-4 && (bounds.min.y + 2.0).abs() < 1e-4,
        "{bounds:?}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn camera_up_rolls_the_picture_about_the_view() {
    let square = |extra: &str| {
        let text = format!(
            "[hair]\nstrands_per_wisp = 4\n[render]\nwidth = 64\nheight = 64\n[shadow]\ncells = 64\n{extra}"
        );
        Scene::from_toml_str(&text, Path::new("square.toml")).unwrap()
    };
    let level = render(&square(""), true);
    // +x up: what was to the right is now at the top.
    let rolled = render(&square("[camera]\nup = [1, 0, 0]\n"), true);
    let turned = image::imageops::rotate270(&level);
    let wrong = image::imageops::rotate90(&level);
    let (d, w) = (
        mean_abs_diff(&rolled, &turned),
        mean_abs_diff(&rolled, &wrong),
    );
    assert!(
        d < 1.5 && w > 4.0 * d,
        "rolled {d:.2} levels from the turned picture, {w:.2} from the other way"
    );
    // Along the view: refused, naming it.
    let e = Renderer::new(&small_scene(
        "[camera]\nposition = [0, 0, 90]\nlook_at = [0, 0, 0]\nup = [0, 0, 1]\n",
    ))
    .unwrap()
    .render(&build_hair(&small_scene("")).unwrap(), true)
    .unwrap_err();
    assert!(e.to_string().contains("up"), "{e}");
}

#[test]
fn the_default_view_turns_to_three_quarters_for_a_groom_seen_edge_on() {
    use engine::CameraView;
    use glam::Vec3;
    use strands::Bounds;
    let head = Bounds {
        min: Vec3::new(-10.0, -20.0, -8.0),
        max: Vec3::new(10.0, 12.0, 9.0),
    };
    let front = engine::view_direction(head, CameraView::Auto);
    assert!(front.x == 0.0 && front.z > 0.9, "{front}");
    // A mohawk: 3 wide, 24 deep.
    let mohawk_bounds = Bounds {
        min: Vec3::new(-1.5, 0.0, -12.0),
        max: Vec3::new(1.5, 10.0, 12.0),
    };
    let mohawk = engine::view_direction(mohawk_bounds, CameraView::Auto);
    assert!(
        (mohawk.x - mohawk.z).abs() < 1e-6 && mohawk.x > 0.6,
        "{mohawk}"
    );
    assert!((mohawk.length() - 1.0).abs() < 1e-6 && (front.length() - 1.0).abs() < 1e-6);
    // A view asked for is kept, edge-on or not.
    let asked = engine::view_direction(mohawk_bounds, CameraView::Front);
    assert!(asked.x == 0.0 && asked.z > 0.9, "{asked}");
    let left = engine::view_direction(head, CameraView::ThreeQuarterLeft);
    assert!((left.x + left.z).abs() < 1e-6 && left.z > 0.6, "{left}");
    let side = engine::view_direction(head, CameraView::Right);
    assert!(side.x > 0.9 && side.z == 0.0, "{side}");
}

/// Mean of each channel over the pixels that differ from the background.
fn hair_mean(img: &image::RgbImage, background: [u8; 3]) -> [f64; 3] {
    let (mut sum, mut n) = ([0.0f64; 3], 0.0f64);
    for p in img.pixels() {
        if p.0 != background {
            for k in 0..3 {
                sum[k] += f64::from(p[k]);
            }
            n += 1.0;
        }
    }
    assert!(n > 100.0, "hair in the picture");
    sum.map(|s| s / n)
}

#[test]
fn a_physically_based_fiber_lets_light_through_as_its_absorption_says() {
    // Lit from behind (towards the camera), no shadow: light hair glows,
    // its fibers passing the light on (TT); dark hair absorbs it; and the
    // light that comes through is reddest, eumelanin absorbing blue most.
    // Kajiya-Kay has no such term. No head, so that only hair is drawn.
    let lit = |shading: &str| {
        let text = format!(
            "[hair]\nstrands_per_wisp = 4\n[render]\nwidth = 96\nheight = 64\nbackground = [0, 0, 0]\n\
             [[light]]\ndirection = [0.1, -0.2, -1]\n[head]\nvisible = false\n\
             [effects]\nself_shadow = false\n{shading}"
        );
        let s = Scene::from_toml_str(&text, Path::new("backlit.toml")).unwrap();
        render(&s, false)
    };
    let marschner = |eumelanin: f32| {
        lit(&format!(
            "[shading]\nmodel = \"marschner\"\neumelanin = {eumelanin}\nambient = 0\n"
        ))
    };
    let (light, dark) = (marschner(0.2), marschner(8.0));
    let (l, d) = (hair_mean(&light, [0, 0, 0]), hair_mean(&dark, [0, 0, 0]));
    let sum = |m: [f64; 3]| m.iter().sum::<f64>();
    assert!(sum(l) > 2.0 * sum(d), "light {l:?}, dark {d:?}");
    assert!(l[0] > l[2], "reddish: {l:?}");
    let kk = lit("[shading]\nambient = 0\n");
    assert!(mean_abs_diff(&kk, &light) > 2.0);
}

#[test]
fn multiple_scattering_gives_self_shadowed_blond_hair_back_its_light() {
    // Lit from the side through the whole head of hair, with its shadow:
    // single scattering alone leaves light hair dark wherever other hair
    // is in front; the light the fibers scatter on brightens blond hair
    // much more than dark brown, whose fibers absorb what passes through.
    let shot = |eumelanin: f32, multiple: bool| {
        let text = format!(
            "[hair]\nstrands_per_wisp = 4\n[render]\nwidth = 96\nheight = 64\nbackground = [0, 0, 0]\n\
             [[light]]\ndirection = [-1, -0.3, -0.2]\n[head]\nvisible = false\n\
             [shading]\nmodel = \"marschner\"\neumelanin = {eumelanin}\nambient = 0\n\
             [effects]\nmultiple_scattering = {multiple}\n"
        );
        let s = Scene::from_toml_str(&text, Path::new("side.toml")).unwrap();
        let m = hair_mean(&render(&s, true), [0, 0, 0]);
        m.iter().sum::<f64>()
    };
    let gain = |eumelanin: f32| shot(eumelanin, true) / shot(eumelanin, false);
    let (blond, brown) = (gain(0.3), gain(1.3));
    // (1.22x with the fiber averaged across its width with enough
    // offsets; 1.3x with the 8 that made single scattering too dark at
    // some angles.)
    assert!(
        blond > 1.15,
        "blond: {blond}x brighter with multiple scattering"
    );
    assert!(
        brown >= 1.0 && brown - 1.0 < 0.5 * (blond - 1.0),
        "brown {brown}x, blond {blond}x"
    );
}

#[test]
fn nothing_is_lit_outside_a_spot_lights_cone() {
    // A narrow hard-edged spot on part of the hair, no ambient light: a
    // vertex outside the cone is black, whatever the shading model; one
    // well inside it, in front of all hair, is lit.
    for model in ["", "[shading]\nmodel = \"marschner\"\nambient = 0\n"] {
        let text = format!(
            "[hair]\nstrands_per_wisp = 2\n[render]\nwidth = 96\nheight = 64\n\
             [[light]]\nposition = [40, 10, 30]\ndirection = [-0.8, -0.2, -0.6]\n\
             cone_deg = 10\nfalloff_deg = 0\n{}",
            if model.is_empty() {
                "[shading]\nambient = 0\n"
            } else {
                model
            }
        );
        let s = Scene::from_toml_str(&text, Path::new("spot.toml")).unwrap();
        let mut seq = engine::Sequence::new(&s).unwrap();
        seq.next_frame().unwrap();
        let light = s.lights[0];
        let (pos, dir) = (light.source().unwrap(), light.direction());
        let cos_cone = 10f32.to_radians().cos();
        let (mut dark, mut lit) = (0, 0);
        for (p, c) in seq.hair().points().iter().zip(seq.renderer().colors()) {
            let cos = (*p - pos).normalize().dot(dir);
            if cos < cos_cone - 1e-4 {
                assert_eq!(*c, Vec3::ZERO, "{p} outside the cone: {c}");
                dark += 1;
            } else if c.max_element() > 0.0 {
                lit += 1;
            }
        }
        assert!(
            dark > 1000 && lit > 100,
            "{model:?}: {dark} dark, {lit} lit"
        );
    }
}

#[test]
fn a_light_inside_the_hair_is_refused_with_a_clear_error() {
    let text = "[hair]\nstrands_per_wisp = 2\n[[light]]\nposition = [0, 0, 0]\n";
    let s = Scene::from_toml_str(text, Path::new("inside.toml")).unwrap();
    let mut seq = engine::Sequence::new(&s).unwrap();
    let e = seq.next_frame().unwrap_err().to_string();
    assert!(e.contains("inside the hair"), "{e}");
}

#[test]
fn the_sky_lights_the_hair_through_its_fiber_under_its_shadow() {
    // The same side-lit hair with and without a sky of radiance 0.3:
    // what the sky adds is in the fiber's colour (blond: red over blue),
    // less where the hair shadows it, and more with multiple scattering,
    // which carries the sky's light into the hair as it carries the
    // sun's.
    let shot = |ambient: f32, multiple: bool, shadow: bool| {
        let text = format!(
            "[hair]\nstrands_per_wisp = 4\n[render]\nwidth = 96\nheight = 64\nbackground = [0, 0, 0]\n\
             [[light]]\ndirection = [-1, -0.3, -0.2]\n[head]\nvisible = false\n\
             [shading]\nmodel = \"marschner\"\neumelanin = 0.3\nambient = {ambient}\nirradiance = 2\n\
             [effects]\nmultiple_scattering = {multiple}\nself_shadow = {shadow}\n"
        );
        let s = Scene::from_toml_str(&text, Path::new("sky.toml")).unwrap();
        // Summed in linear RGB: the sky's share adds there.
        let hair = build_hair(&s).unwrap();
        let mut r = Renderer::new(&s).unwrap();
        r.render(&hair, shadow).unwrap();
        let px = r.linear_picture().unwrap();
        px.iter().fold([0.0f64; 3], |a, p| {
            [
                a[0] + f64::from(p.x),
                a[1] + f64::from(p.y),
                a[2] + f64::from(p.z),
            ]
        })
    };
    let sky = |multiple: bool, shadow: bool| {
        let (with, without) = (shot(0.3, multiple, shadow), shot(0.0, multiple, shadow));
        [
            with[0] - without[0],
            with[1] - without[1],
            with[2] - without[2],
        ]
    };
    let single = sky(false, true);
    assert!(single[0] > 0.0 && single[0] > single[2], "{single:?}");
    let open = sky(false, false);
    let sum = |m: [f64; 3]| m.iter().sum::<f64>();
    assert!(
        sum(open) > 1.2 * sum(single),
        "open {open:?}, shadowed {single:?}"
    );
    let multiple = sky(true, true);
    assert!(
        sum(multiple) > 1.1 * sum(single),
        "multiple {multiple:?}, single {single:?}"
    );
}
