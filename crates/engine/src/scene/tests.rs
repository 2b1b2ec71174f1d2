use super::*;
use shadow::{Beyond, OpacityMode};
use strands::Style;

fn parse(text: &str) -> Result<Scene, SceneError> {
    Scene::from_toml_str(text, Path::new("dir/scene.toml"))
}

#[test]
fn the_shading_model_and_its_fiber_settings_are_read_and_checked() {
    use raster::ShadingModel;
    // Kajiya-Kay by default.
    assert_eq!(parse("").unwrap().shading.model, ShadingModel::KajiyaKay);
    // A fiber from melanin, with pbrt's defaults for the rest.
    let s = parse("[shading]\nmodel = \"marschner\"\neumelanin = 1.3\n").unwrap();
    let ShadingModel::Marschner {
        optics,
        from_color,
        irradiance,
        ..
    } = s.shading.model
    else {
        panic!("{:?}", s.shading.model)
    };
    assert!(!from_color && irradiance == 5.0);
    assert_eq!(optics.sigma_a, raster::sigma_a_from_melanin(1.3, 0.0));
    assert_eq!(
        (optics.eta, optics.beta_m, optics.alpha_deg),
        (1.55, 0.3, 2.0)
    );
    // Neither sigma_a nor melanin: each strand's colour sets it.
    let s = parse("[shading]\nmodel = \"marschner\"\nbeta_n = 0.5\n").unwrap();
    assert!(matches!(
        s.shading.model,
        ShadingModel::Marschner { from_color: true, optics, .. } if optics.beta_n == 0.5
    ));
    // Refused, naming the field.
    for (text, field, why) in [
        ("model = \"phong\"", "shading.model", "kajiya-kay"),
        ("eumelanin = 1", "shading.eumelanin", "marschner"),
        (
            "model = \"marschner\"\nbeta_m = 0",
            "shading.beta_m",
            "(0, 1]",
        ),
        ("model = \"marschner\"\neta = 0.9", "shading.eta", "(1, 3]"),
        (
            "model = \"marschner\"\nsigma_a = [0, -1, 0]",
            "shading.sigma_a",
            "[0, 100]",
        ),
        (
            "model = \"marschner\"\nsigma_a = [1, 1, 1]\neumelanin = 1",
            "shading.sigma_a",
            "not both",
        ),
        (
            "model = \"marschner\"\nirradiance = nan",
            "shading.irradiance",
            "[0, 1000]",
        ),
    ] {
        let e = parse(&format!("[shading]\n{text}\n"))
            .unwrap_err()
            .to_string();
        assert!(e.contains(field) && e.contains(why), "{text}: {e}");
    }
}

#[test]
fn lights_are_directional_point_or_spot_as_their_keys_say() {
    let s = parse(
        "[[light]]\ndirection = [0, -1, 0]\n\
         [[light]]\nposition = [0, 30, 40]\n\
         [[light]]\nposition = [30, 0, 0]\ndirection = [-1, 0, 0]\ncone_deg = 20\nintensity = 500\n",
    )
    .unwrap();
    assert!(matches!(s.lights[0], Light::Directional { .. }));
    // Irradiance 1 at the head's centre by default: intensity = r^2.
    assert!(matches!(s.lights[1], Light::Point { intensity, .. } if intensity == 2500.0));
    assert!(matches!(
        s.lights[2],
        Light::Spot { cone_deg, falloff_deg, intensity, .. }
            if cone_deg == 20.0 && falloff_deg == DEFAULT_FALLOFF_DEG && intensity == 500.0
    ));
    for (text, field, why) in [
        (
            "cone_deg = 20\ndirection = [0, -1, 0]",
            "light.cone_deg",
            "point and spot",
        ),
        (
            "position = [0, 30, 0]\ncone_deg = 20",
            "light.cone_deg",
            "spot lights",
        ),
        (
            "position = [0, 30, 0]\ndirection = [0, -1, 0]\ncone_deg = 90",
            "light.cone_deg",
            "(0, 90)",
        ),
        (
            "position = [0, 30, 0]\ndirection = [0, -1, 0]\ncone_deg = 20\nfalloff_deg = 30",
            "light.falloff_deg",
            "[0, cone_deg]",
        ),
        (
            "position = [0, 30, 0]\nintensity = 0",
            "light.intensity",
            "(0, 1e12]",
        ),
        ("position = [0, inf, 0]", "light.position", "finite"),
        ("", "light", "give direction"),
    ] {
        let e = parse(&format!("[[light]]\n{text}\n"))
            .unwrap_err()
            .to_string();
        assert!(e.contains(field) && e.contains(why), "{text}: {e}");
    }
}

#[test]
fn a_style_takes_the_hair_colour_it_is_given() {
    let c = Vec3::new(0.6, 0.45, 0.25);
    let s = parse("[hair]\nstrands_per_wisp = 2\ncolor = [0.6, 0.45, 0.25]\n").unwrap();
    let hair = crate::build_hair(&s).unwrap();
    let colors = hair.colors().unwrap();
    assert_eq!(colors.len(), hair.strand_count());
    for k in colors {
        let r = *k / c;
        assert!(r.min_element() >= 0.8 && r.max_element() <= 1.2, "{k}");
        assert!(
            (r.x - r.y).abs() < 1e-5 && (r.y - r.z).abs() < 1e-5,
            "{k}: one hue"
        );
    }
    // Brown by default.
    let d = crate::build_hair(&parse("[hair]\nstrands_per_wisp = 2\n").unwrap()).unwrap();
    assert!(d.colors().unwrap().iter().all(|k| k.x < 0.25));
    for (text, why) in [
        ("color = [0.5, 2, 0.5]", "[0, 1]"),
        ("color = [0.5, nan, 0.5]", "[0, 1]"),
        (
            "strands = [[[0, 0, 0], [0, -1, 0]]]\ncolor = [0.5, 0.5, 0.5]",
            "hair.style only",
        ),
    ] {
        let e = parse(&format!("[hair]\n{text}\n")).unwrap_err().to_string();
        assert!(e.contains("hair.color") && e.contains(why), "{text}: {e}");
    }
}

#[test]
fn multiple_scattering_needs_the_fiber_model_and_the_shadow() {
    let on = "[effects]\nmultiple_scattering = true\n";
    let s = parse(&format!("{on}[shading]\nmodel = \"marschner\"\n")).unwrap();
    assert!(s.effects.multiple_scattering);
    assert!(
        !parse("").unwrap().effects.multiple_scattering,
        "off by default"
    );
    for (text, why) in [
        ("", "marschner"),
        (
            "self_shadow = false\n[shading]\nmodel = \"marschner\"\n",
            "self_shadow",
        ),
    ] {
        let e = parse(&format!("{on}{text}")).unwrap_err().to_string();
        assert!(
            e.contains("effects.multiple_scattering") && e.contains(why),
            "{text}: {e}"
        );
    }
}

#[test]
fn the_heads_light_is_on_by_default_and_a_switch() {
    assert!(parse("").unwrap().effects.head_bounce);
    let off = parse("[effects]\nhead_bounce = false\n").unwrap();
    assert!(!off.effects.head_bounce);
    let e = parse("[effects]\nhead_bounce = 1\n")
        .unwrap_err()
        .to_string();
    assert!(e.contains("head_bounce"), "{e}");
}

#[test]
fn counts_a_scene_multiplies_are_bounded_before_any_work() {
    let many = |table: &str, body: &str, n: usize| {
        (0..n)
            .map(|i| format!("[[{table}]]\n{}\n", body.replace("{i}", &i.to_string())))
            .collect::<String>()
    };
    let cases = [
        (
            many("light", "direction = [1, -1, {i}]", MAX_LIGHTS + 1),
            "at most 16 lights",
        ),
        (
            many("body", "center = [0, {i}, 0]\nradius = 1", MAX_BODIES + 1),
            "at most 256 bodies",
        ),
        (
            format!(
                "[animation]\nmotion = \"keyframes\"\n{}",
                many("animation.key", "time = {i}", MAX_KEYFRAMES + 1)
            ),
            "at most 10000 keyframes",
        ),
        (
            format!(
                "[shadow]\ncells = 512\n{}",
                many("light", "direction = [1, -1, {i}]", 3)
            ),
            "map cells",
        ),
    ];
    for (text, says) in cases {
        let e = parse(&text).unwrap_err().to_string();
        assert!(e.contains(says), "{e}");
    }
    assert!(
        parse(&format!(
            "[shadow]\ncells = 512\n{}",
            many("light", "direction = [1, -1, {i}]", 2)
        ))
        .is_ok()
    );
    // Too long a text, and too big a file: refused before parsing.
    let long = "#".repeat(MAX_SCENE_BYTES + 1);
    let e = Scene::from_toml_str(&long, Path::new("big.toml"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("at most"), "{e}");
    let dir = std::env::temp_dir().join(format!("wisplight-scene-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("big.toml");
    std::fs::File::create(&file)
        .unwrap()
        .set_len(MAX_SCENE_BYTES as u64 + 1)
        .unwrap();
    let e = Scene::load(&file).unwrap_err().to_string();
    assert!(e.contains("hair.file"), "{e}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn empty_scene_gets_the_documented_defaults() {
    let s = parse("").unwrap();
    assert_eq!(
        s.shadow,
        ShadowSettings {
            method: MethodConfig::DensityMap {
                cells: 128,
                trilinear: true,
                contact: 0.0,
            }
        }
    );
    assert_eq!(s.fiber, Fiber::new(0.1, 0.5).unwrap());
    assert_eq!(s.subdivide, 2);
    assert_eq!(
        s.lights,
        vec![Light::directional(Vec3::from_array(DEFAULT_LIGHT_DIRECTION)).unwrap()]
    );
    assert!(
        matches!(s.hair, HairSource::Style(p) if p.style == Style::Smooth && p.strands_per_wisp == 25)
    );
}

#[test]
fn unknown_keys_are_refused_by_name() {
    let e = parse("[shadow]\ncells = 64\nresolution = 3\n")
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("resolution") && e.starts_with("dir/scene.toml"),
        "{e}"
    );
    assert!(!e.contains('\n'), "one line: {e}");
    let e = parse("[lights]\ndirection = [1, 0, 0]\n")
        .unwrap_err()
        .to_string();
    assert!(e.contains("lights"), "{e}");
}

#[test]
fn bad_values_name_field_and_value() {
    let e = parse("[shadow]\ncells = 100000\n").unwrap_err().to_string();
    assert_eq!(
        e,
        "dir/scene.toml: shadow.cells = 100000: must be a whole number in 1..=512"
    );
    let e = parse("[fiber]\nwidth = nan\n").unwrap_err().to_string();
    assert_eq!(
        e,
        "dir/scene.toml: fiber.width = NaN: must be a finite number > 0"
    );
    let e = parse("[light]\ndirection = [0, 0, 0]\n")
        .unwrap_err()
        .to_string();
    assert!(e.contains("light.direction = [0.0, 0.0, 0.0]"), "{e}");
    let e = parse("[shadow]\nmethod = \"raytrace\"\n")
        .unwrap_err()
        .to_string();
    assert!(e.contains("shadow.method = \"raytrace\""), "{e}");
    let e = parse("[camera]\nup = [0, 0, 0]\n").unwrap_err().to_string();
    assert!(e.contains("camera.up") && e.contains("zero"), "{e}");
    let s = parse("[camera]\nup = [0, 0, 2]\n").unwrap();
    assert_eq!(s.camera.up, Some(Vec3::new(0.0, 0.0, 2.0)));
    let e = parse("[hair]\nstyle = \"wavy\"\n").unwrap_err().to_string();
    assert!(e.contains("hair.style"), "{e}");
    let e = parse("[hair]\nstrands_per_wisp = -3\n")
        .unwrap_err()
        .to_string();
    assert!(e.contains("hair.strands_per_wisp = -3"), "{e}");
}

#[test]
fn a_groom_is_scaled_then_turned_about_x_y_z_then_moved() {
    let points = |extra: &str| {
        let text = format!("[hair]\nstrands = [[[0, 0, 1], [1, 0, 0], [0, 1, 0]]]\n{extra}");
        match parse(&text).unwrap().hair {
            HairSource::Inline(h) => h.points().to_vec(),
            other => panic!("{other:?}"),
        }
    };
    let near = |a: &[Vec3], b: &[[f32; 3]]| {
        a.len() == b.len()
            && a.iter()
                .zip(b)
                .all(|(p, q)| (*p - Vec3::from_array(*q)).length() < 1e-4)
    };
    assert!(near(
        &points(""),
        &[[0., 0., 1.], [1., 0., 0.], [0., 1., 0.]]
    ));
    // Millimetres with +z up: a tenth, stood up (+z to +y), raised.
    let p = points("scale = 10\nrotate_deg = [-90, 0, 0]\ntranslate = [0, 1, 0]\n");
    assert!(
        near(&p, &[[0., 11., 0.], [10., 1., 0.], [0., 1., -10.]]),
        "{p:?}"
    );
    // About x first, then y: +y goes to +z, then to +x.
    let p = points("rotate_deg = [90, 90, 0]\n");
    assert!(near(&p[2..], &[[1., 0., 0.]]), "{p:?}");
    for (bad, field) in [
        ("scale = 0", "hair.scale"),
        ("scale = -2", "hair.scale"),
        ("scale = nan", "hair.scale"),
        ("rotate_deg = [0, inf, 0]", "hair.rotate_deg"),
        ("translate = [1e30, 0, 0]", "hair.translate"),
    ] {
        let e = parse(&format!("[hair]\nfile = \"g.hair\"\n{bad}\n")).unwrap_err();
        assert!(e.to_string().contains(field), "{bad}: {e}");
    }
    let e = parse("[hair]\nstyle = \"curly\"\nscale = 2\n").unwrap_err();
    assert!(e.to_string().contains("hair.scale"), "{e}");
    let s = parse("[hair]\nfile = \"g.data\"\nscale = 0.1\n[fiber]\nwidth = 0.1\n").unwrap();
    assert!(
        matches!(s.hair, HairSource::File { place, .. } if place.scale == 0.1),
        "{:?}",
        s.hair
    );
}

#[test]
fn files_are_relative_to_the_scene_and_tfx_grows_followers() {
    // Widths given: the groom is not read here.
    let s =
        parse("[hair]\nfile = \"groom.tfx\"\nfollow_radius = 0.4\n[fiber]\nwidth = 0.1\n").unwrap();
    match s.hair {
        HairSource::File { path, follow, .. } => {
            assert_eq!(path, Path::new("dir/groom.tfx"));
            assert_eq!(follow.unwrap().followers, 15);
        }
        other => panic!("{other:?}"),
    }
    let s = parse("[hair]\nfile = \"/abs/x.hair\"\n[fiber]\nwidth = 0.1\n").unwrap();
    assert!(
        matches!(s.hair, HairSource::File { ref path, follow: None, .. } if path == Path::new("/abs/x.hair"))
    );
}

#[test]
fn length_defaults_follow_the_groom_unit_and_a_mesh_alone_fits_the_head() {
    let dir = std::env::temp_dir().join(format!("wisplight-unit-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    // USC-HairSalon .data: one strand `len` long down from y = 0.
    let groom = |name: &str, len: f32| {
        let mut b = 1i32.to_le_bytes().to_vec();
        b.extend(2i32.to_le_bytes());
        for v in [0.0f32, 0.0, 0.0, 0.0, -len, 0.0] {
            b.extend(v.to_le_bytes());
        }
        std::fs::write(dir.join(name), b).unwrap();
    };
    let scene = |text: &str| Scene::from_toml_str(text, &dir.join("s.toml"));
    // 25 cm, 250 mm, 0.25 m: the same hair, the same look.
    for (name, len, unit) in [
        ("cm.data", 25.0, 1.0),
        ("mm.data", 250.0, 10.0),
        ("m.data", 0.25, 0.01),
    ] {
        groom(name, len);
        let s = scene(&format!("[hair]\nfile = \"{name}\"\nfollowers = 4\n")).unwrap();
        let close = |a: f32, b: f32| (a - b).abs() <= 1e-6 * b;
        assert!(
            close(s.fiber.width(), 0.1 * unit),
            "{name}: width {}",
            s.fiber.width()
        );
        match s.hair {
            HairSource::File {
                follow: Some(f), ..
            } => assert!(close(f.radius, 0.4 * unit), "{name}: {}", f.radius),
            other => panic!("{other:?}"),
        }
        // A head of hair's strands draw as real hairs, 70 um; half as
        // many, twice as wide (the same coverage).
        let many = format!("100-{name}");
        let mut b = 100i32.to_le_bytes().to_vec();
        for i in 0..100 {
            b.extend(2i32.to_le_bytes());
            let x = i as f32 * len / 1000.0;
            for v in [x, 0.0, 0.0, x, -len, 0.0] {
                b.extend(v.to_le_bytes());
            }
        }
        std::fs::write(dir.join(&many), b).unwrap();
        for (followers, want) in [(999, 0.007), (499, 0.014), (99, 0.07)] {
            let s = scene(&format!(
                "[hair]\nfile = \"{many}\"\nfollowers = {followers}\n"
            ))
            .unwrap();
            assert!(
                close(s.fiber.width(), want * unit),
                "{name}, {followers}: width {}",
                s.fiber.width()
            );
        }
        // Given, a width stays; scaled, the groom's unit follows.
        let s = scene(&format!(
            "[hair]\nfile = \"{name}\"\n[fiber]\nwidth = 0.3\n"
        ))
        .unwrap();
        assert_eq!(s.fiber.width(), 0.3);
        let s = scene(&format!(
            "[hair]\nfile = \"{name}\"\nscale = {}\n",
            1.0 / unit
        ))
        .unwrap();
        assert!(
            close(s.fiber.width(), 0.1),
            "{name} scaled: width {}",
            s.fiber.width()
        );
    }
    // A groom that does not load is named with hair.file.
    let e = scene("[hair]\nfile = \"nowhere.data\"\n")
        .unwrap_err()
        .to_string();
    assert!(e.contains("hair.file") && e.contains("nowhere.data"), "{e}");
    // A head mesh alone: the sphere fitted to its crown, as placed.
    let obj = concat!(env!("CARGO_MANIFEST_DIR"), "/../../scenes/head.obj");
    std::fs::copy(obj, dir.join("head.obj")).unwrap();
    let s = scene("[hair]\nfile = \"cm.data\"\n[head]\nmesh = \"head.obj\"\nmesh_scale = 2\nmesh_offset = [0, 30, 0]\n").unwrap();
    let h = s.head.unwrap();
    assert!(
        h.center.distance(Vec3::new(0.0, 30.0, 0.0)) < 0.5,
        "{}",
        h.center
    );
    assert!((h.radius - 20.0).abs() < 0.5, "{}", h.radius);
    // Half a head given is still refused.
    let e =
        scene("[hair]\nfile = \"cm.data\"\n[head]\nmesh = \"head.obj\"\nradius = 3\n").unwrap_err();
    assert!(e.to_string().contains("head.center"), "{e}");
    let e = scene("[hair]\nfile = \"cm.data\"\n[head]\nmesh = \"gone.ply\"\n").unwrap_err();
    assert!(
        e.to_string().contains("head.mesh") && e.to_string().contains("gone.ply"),
        "{e}"
    );
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_camera_view_is_named_and_needs_no_position() {
    let s = parse("[camera]\nview = \"three-quarter-right\"\n").unwrap();
    assert_eq!(s.camera.view, CameraView::ThreeQuarterRight);
    assert_eq!(parse("").unwrap().camera.view, CameraView::Auto);
    let e = parse("[camera]\nview = \"top\"\n").unwrap_err().to_string();
    assert!(
        e.contains("camera.view = \"top\"") && e.contains("three-quarter-left"),
        "{e}"
    );
    let e = parse("[camera]\nview = \"left\"\nposition = [0, 0, 50]\n").unwrap_err();
    assert!(e.to_string().contains("camera.position"), "{e}");
}

#[test]
fn animation_settings_are_checked() {
    let s = parse("[animation]\nmotion = \"keyframes\"\n[[animation.key]]\ntime = 0.0\n[[animation.key]]\ntime = 1.0\nrotate_deg = [0, 90, 0]\n").unwrap();
    assert!(matches!(s.animation.motion, sim::Motion::Keyframes(ref k) if k.len() == 2));
    for (text, field) in [
        ("[animation]\nmotion = \"keyframes\"\n", "animation.key"),
        (
            "[animation]\nmotion = \"keyframes\"\n[[animation.key]]\ntime = 1.0\n[[animation.key]]\ntime = 0.5\n",
            "animation.key",
        ),
        ("[animation]\namplitude = 2.0\n", "animation.amplitude"),
        ("[animation]\nfps = 0\n", "animation.fps"),
        ("[dynamics]\ntime_step = 0.0000001\n", "dynamics.time_step"),
        (
            "[dynamics]\nsettle = 60\ntime_step = 0.0001\n",
            "dynamics.settle",
        ),
        ("[dynamics]\nstiffness = 2\n", "dynamics.stiffness"),
        ("[collision]\ndensity = 0\n", "collision.density"),
        ("[[body]]\ncenter = [0, 0, 0]\nradius = -1\n", "body.radius"),
        ("[effects]\nshadows = true\n", "shadows"),
    ] {
        let e = parse(text).unwrap_err().to_string();
        assert!(e.contains(field), "{text:?}: {e}");
    }
}

#[test]
fn several_lights() {
    let s = parse("[[light]]\ndirection = [1, 0, 0]\n[[light]]\ndirection = [0, -2, 0]\n").unwrap();
    assert_eq!(s.lights.len(), 2);
    assert_eq!(s.lights[1].direction(), Vec3::NEG_Y);
}

#[test]
fn method_settings_parse_and_settings_of_other_methods_are_refused() {
    let s = parse(
        "[shadow]\nmethod = \"opacity-shadow-map\"\ncells = 64\nslices = 16\nmode = \"linear\"\noffset = 0.5\n",
    )
    .unwrap();
    assert_eq!(
        s.shadow.method,
        MethodConfig::OpacityShadowMap {
            resolution: 64,
            slices: 16,
            mode: OpacityMode::Linear,
            offset: 0.5,
            trilinear: true
        }
    );
    let s = parse("[shadow]\ncontact = 2.5\n").unwrap();
    assert!(matches!(
        s.shadow.method,
        MethodConfig::DensityMap { contact: 2.5, .. }
    ));
    let s =
        parse("[shadow]\nmethod = \"deep-opacity-map\"\nlayers = 3\nbeyond = \"cover\"\n").unwrap();
    assert!(matches!(
        s.shadow.method,
        MethodConfig::DeepOpacityMap {
            layers: 3,
            beyond: Beyond::Cover,
            ..
        }
    ));
    for (text, field, says) in [
        (
            "[shadow]\nslices = 16\n",
            "shadow.slices",
            "opacity-shadow-map",
        ),
        (
            "[shadow]\nmethod = \"deep-opacity-map\"\nbeyond = \"nowhere\"\n",
            "shadow.beyond",
            "last-layer",
        ),
        (
            "[shadow]\nmethod = \"opacity-shadow-map\"\nslices = 1\n",
            "shadow.slices",
            "2..=4096",
        ),
        (
            "[shadow]\nmethod = \"footprint-reference\"\ncells = 64\n",
            "shadow.cells",
            "footprint",
        ),
        (
            "[shadow]\nmethod = \"reference\"\ncells = 64\n",
            "shadow.cells",
            "has no cells",
        ),
        (
            "[shadow]\nmethod = \"reference\"\nfootprint = 0.5\n",
            "shadow.footprint",
            "footprint-reference",
        ),
        (
            "[shadow]\nmethod = \"deep-shadow-map\"\ntolerance = -1.0\n",
            "shadow.tolerance",
            "[0, 1)",
        ),
        ("[shadow]\ncontact = 17.0\n", "shadow.contact", "0..=16"),
        (
            "[render]\nsimplify = 4.5\n",
            "render.simplify",
            "[0, 4] pixels",
        ),
        ("[render]\nsimplify = -0.5\n", "render.simplify", "0: off"),
        ("[render]\nsimplify = nan\n", "render.simplify", "[0, 4]"),
        (
            "[shadow]\nmethod = \"reference\"\ncontact = 2.0\n",
            "shadow.contact",
            "density-map",
        ),
    ] {
        let e = parse(text).unwrap_err().to_string();
        assert!(e.contains(field) && e.contains(says), "{text:?}: {e}");
    }
}

#[test]
fn a_value_of_the_wrong_shape_is_named_by_its_field() {
    for (text, field) in [
        ("[light]\ndirection = [1, 0]\n", "light.direction"),
        ("[render]\nwidth = \"wide\"\n", "render.width"),
        ("[[body]]\ncenter = [0, 1]\nradius = 2\n", "body.center"),
    ] {
        let e = parse(text).unwrap_err().to_string();
        assert!(e.starts_with(&format!("dir/scene.toml: {field}: ")), "{e}");
        assert!(e.contains("line"), "{e}");
    }
}

#[test]
fn a_usd_grooms_widths_set_the_fiber_width_and_hair_sample_picks_its_time() {
    let dir = std::env::temp_dir().join(format!("wisplight-usd-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    // Two curves 20 units long, widths 0.01 and 0.03 (constant a curve),
    // points at times 1 and 2, the second 5 units along x.
    let usda = r#"#usda 1.0
def BasisCurves "Hair"
{
    uniform token type = "linear"
    int[] curveVertexCounts = [2, 2]
    point3f[] points.timeSamples = {
        1: [(0, 0, 0), (0, -20, 0), (1, 0, 0), (1, -20, 0)],
        2: [(5, 0, 0), (5, -20, 0), (6, 0, 0), (6, -20, 0)],
    }
    float[] widths = [0.01, 0.03, 0.03] (interpolation = "uniform")
}
"#;
    std::fs::write(dir.join("g.usda"), usda.replace("0.03, 0.03", "0.03")).unwrap();
    let scene = |text: &str| Scene::from_toml_str(text, &dir.join("s.toml"));
    // The median of the strands' widths (0.01, 0.03: the upper one),
    // times hair.scale.
    let s = scene("[hair]\nfile = \"g.usda\"\nscale = 2\n").unwrap();
    assert!((s.fiber.width() - 0.06).abs() < 1e-7, "{}", s.fiber.width());
    // A fiber width given wins.
    let s = scene("[hair]\nfile = \"g.usda\"\n[fiber]\nwidth = 0.5\n").unwrap();
    assert_eq!(s.fiber.width(), 0.5);
    // hair.sample: kept, checked against the file, refused elsewhere.
    let s = scene("[hair]\nfile = \"g.usda\"\nsample = 1\n").unwrap();
    assert!(matches!(
        s.hair,
        HairSource::File {
            sample: Some(1),
            ..
        }
    ));
    let e = scene("[hair]\nfile = \"g.usda\"\nsample = 2\n").unwrap_err();
    assert!(e.to_string().contains("2 time samples (0 to 1)"), "{e}");
    let e = scene("[hair]\nfile = \"x.hair\"\nsample = 1\n").unwrap_err();
    assert!(e.to_string().contains("hair.sample"), "{e}");
    let e = scene("[hair]\nstyle = \"curly\"\nsample = 1\n").unwrap_err();
    assert!(e.to_string().contains("applies to hair.file only"), "{e}");
    let _ = std::fs::remove_dir_all(dir);
}
