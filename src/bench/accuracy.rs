//! `wisplight bench accuracy`: every shadow method at a range of settings
//! against the exact reference, error against time.

use std::path::{Path, PathBuf};

use anyhow::Context;
use engine::{Scene, Sequence, Stage};
use image::RgbImage;
use shadow::{Beyond, MethodConfig, OpacityMode};

use super::cycles_truth::{
    BLOCK, CYCLES_PNG, CYCLES_UNSHADOWED_PNG, REFERENCE_PNG, UNSHADOWED_PNG, cycles_truth,
    direct_light, linear, ratio_picture,
};
use super::plot;
use super::scattering::{self, Against};

#[derive(Debug, clap::Args)]
pub struct AccuracyArgs {
    /// Scene file (TOML); the built-in scene when omitted.
    scene: Option<PathBuf>,
    /// Also write one row per method and setting as CSV: method,
    /// parameters, ms, mean_abs, rms, max, image_error.
    #[arg(long, value_name = "FILE")]
    csv: Option<PathBuf>,
    /// Also write a plot of the RMS error against time (PNG, and the same
    /// chart as SVG beside it), with the Pareto front marked.
    #[arg(long, value_name = "FILE.png")]
    plot: Option<PathBuf>,
    /// Timed frames per setting, after one untimed frame; the median counts.
    /// The reference is rendered once.
    #[arg(long, default_value_t = 3, value_name = "N",
          value_parser = clap::value_parser!(u64).range(1..=100_000))]
    runs: u64,
    /// Only these methods (comma separated); all by default.
    #[arg(long, value_delimiter = ',', value_name = "NAME,...",
          value_parser = clap::builder::PossibleValuesParser::new(MethodConfig::NAMES))]
    methods: Vec<String>,
    /// Also compare every setting's picture with Blender Cycles' (the
    /// same strands, camera, light and fiber, direct light only; hair
    /// shaded with Kajiya-Kay is shaded with the physically based fiber of
    /// its colour on both sides): the frame, its script and Cycles'
    /// pictures with and without shadows go into DIR and are reused while
    /// the frame is the same; wisplight's (the exact reference's and the
    /// unshadowed) go beside them as PNG, and Cycles' as PNG too. Needs
    /// `blender` on PATH (or `$WISPLIGHT_BLENDER`).
    #[arg(long, value_name = "DIR")]
    cycles: Option<PathBuf>,
    /// With --cycles: also render Cycles with N light bounces, and every
    /// setting with multiple scattering (`[effects] multiple_scattering`),
    /// and compare the light the fibers pass on to one another: each 8x8
    /// block's direct share (direct light over all of it), the picture's
    /// gain (all over direct) and its colour (red/green, blue/green).
    #[arg(long, default_value_t = 0, value_name = "N", requires = "cycles",
          value_parser = clap::value_parser!(u32).range(0..=1024))]
    bounces: u32,
    /// Cycles samples per pixel.
    #[arg(long, default_value_t = 128, value_name = "N",
          value_parser = clap::value_parser!(u32).range(1..=65_536))]
    cycles_samples: u32,
    #[command(flatten)]
    pub threads: crate::cmd::Threads,
}

/// The settings swept for each method, coarse to fine.
pub fn sweep() -> Vec<MethodConfig> {
    let mut v = Vec::new();
    for cells in [32, 64, 128, 256] {
        for trilinear in [true, false] {
            v.push(MethodConfig::DensityMap {
                cells,
                trilinear,
                contact: 0.0,
            });
        }
    }
    // Contact shadows: 1 to 16 cells at 128^3; the distance of 2 cells at
    // 128^3 at 64^3 and 256^3.
    for (cells, contact) in [
        (128, 1.0),
        (128, 2.0),
        (128, 4.0),
        (128, 8.0),
        (128, 16.0),
        (64, 1.0),
        (256, 4.0),
    ] {
        v.push(MethodConfig::DensityMap {
            cells,
            trilinear: true,
            contact,
        });
    }
    let osm = |slices, mode, offset| MethodConfig::OpacityShadowMap {
        resolution: 128,
        slices,
        mode,
        offset,
        trilinear: true,
    };
    let exp = OpacityMode::Exponential { kappa: 1.0 };
    for slices in [4, 16, 64, 256] {
        v.push(osm(slices, exp, 0.0));
    }
    v.push(osm(64, OpacityMode::Linear, 0.0));
    v.push(osm(64, exp, 0.5));
    let dom = |layers, layer_cells, beyond| MethodConfig::DeepOpacityMap {
        resolution: 128,
        layers,
        layer_cells,
        beyond,
        trilinear: true,
    };
    for layers in [2, 3, 4, 8] {
        v.push(dom(layers, 4.0, Beyond::LastLayer));
    }
    v.push(dom(4, 4.0, Beyond::Ignore));
    v.push(dom(4, 0.0, Beyond::Cover));
    for resolution in [64, 128, 256] {
        v.push(MethodConfig::DensityClustering {
            resolution,
            clusters: 4,
            trilinear: true,
        });
    }
    for (resolution, tolerance) in [(64, 0.01), (128, 0.01), (256, 0.01), (128, 0.05)] {
        v.push(MethodConfig::DeepShadowMap {
            resolution,
            tolerance,
            trilinear: true,
        });
    }
    v
}

/// One method at one setting, measured.
#[derive(Debug, Clone)]
struct Row {
    config: MethodConfig,
    ms: f64,
    mean_abs: f64,
    rms: f64,
    max: f64,
    image: f64,
    /// At the drawn points the picture shows: mean signed and mean
    /// absolute error of T.
    seen: (f64, f64),
    /// Against Cycles: mean block ratio error and mean ratio.
    cycles: Option<raster::RatioComparison>,
    /// With `--bounces`: multiple scattering against Cycles' bounces.
    scattering: Option<Against>,
}

pub fn run(a: AccuracyArgs) -> anyhow::Result<()> {
    let scene = direct_light(
        &crate::cmd::load_scene(a.scene.as_deref())?,
        a.cycles.is_some(),
    );
    if let Some(p) = &a.plot {
        super::check_plot_path(p)?;
    }
    let blender = match &a.cycles {
        Some(_) => Some(crate::cycles::blender().ok_or_else(|| {
            anyhow::anyhow!(
                "--cycles: blender not found on PATH, nor at $WISPLIGHT_BLENDER (apt-get install blender)"
            )
        })?),
        None => None,
    };
    let hair = crate::cmd::build_hair(&scene)?;
    let (name, threads, cores) = super::machine(a.scene.as_deref());
    let configs: Vec<MethodConfig> = sweep()
        .into_iter()
        .filter(|c| a.methods.is_empty() || a.methods.iter().any(|m| m == c.name()))
        .collect();
    eprintln!(
        "bench accuracy: {name}: {} segments, {} drawn points, {}x{}, {} settings, {threads} threads on {cores} cores, median of {} frames each",
        hair.segment_count(),
        hair.point_count(),
        scene.render.width,
        scene.render.height,
        configs.len(),
        a.runs
    );
    // The path-traced truth first: it is the slow part, and a failure
    // there should come before the sweep.
    let truth = match (&a.cycles, &blender) {
        (Some(dir), Some(b)) => Some(cycles_truth(&scene, b, dir, a.cycles_samples)?),
        _ => None,
    };
    let (w, h) = (scene.render.width as usize, scene.render.height as usize);
    // Cycles' light with bounces: its direct share, gain and colour.
    let bounced = match (&truth, &a.cycles, &blender) {
        (Some(t), Some(dir), Some(b)) if a.bounces > 0 => {
            let (all, seconds) = scattering::cycles_bounced(
                b,
                dir,
                a.cycles_samples,
                a.bounces,
                t.fresh,
                (w as u32, h as u32),
            )?;
            Some((scattering::Light::new(&t.lit, &all, w, h), seconds))
        }
        _ => None,
    };
    // Both of wisplight's pictures in linear RGB, unclamped.
    // `direct`: the setting's direct-light picture its measure drew.
    let scattered = |config: MethodConfig,
                     direct: Option<Vec<glam::Vec3>>|
     -> anyhow::Result<Option<Against>> {
        let (Some((cycles, _)), Some(direct)) = (&bounced, direct) else {
            return Ok(None);
        };
        let (shade_ms, all) = scattering::measure(&scene, config, a.runs as usize)?;
        let mine = scattering::Light::new(&direct, &all, w, h);
        // The reference's pair, to look at beside Cycles'.
        if let (Some(dir), "reference") = (&a.cycles, config.name()) {
            scattering::write_png(&dir.join("wisplight-direct.png"), &direct, w, h)?;
            let name = format!("wisplight-scattered-{}.png", a.bounces);
            scattering::write_png(&dir.join(name), &all, w, h)?;
        }
        Ok(Some(Against::new(&mine, cycles, shade_ms)))
    };
    let unshadowed = match (&truth, &a.cycles) {
        (Some(_), Some(dir)) => {
            let mut s = scene.clone();
            s.effects.self_shadow = false;
            s.animation.motion = sim::Motion::Still;
            let mut seq = Sequence::new(&s)?;
            let img = seq.again().context("cannot render without shadows")?.0;
            // wisplight's pictures beside Cycles', for a look.
            crate::output::write_png(&dir.join(UNSHADOWED_PNG), img)?;
            Some(linear(img))
        }
        _ => None,
    };
    let against_cycles = |img: &RgbImage| match (&truth, &unshadowed) {
        (Some(t), Some(u)) => Some(raster::RatioComparison::new(
            &raster::ShadowRatios::new(
                &linear(img),
                u,
                img.width() as usize,
                img.height() as usize,
                BLOCK,
            ),
            &t.ratios,
        )),
        _ => None,
    };
    let bar = crate::cmd::progress_bar(
        configs.len() as u64 + 1,
        "{bar:30} {pos}/{len} {msg} [{elapsed}]",
    );
    bar.set_message("reference");
    let reference = MethodConfig::with_defaults("reference", 128).expect("a known method");
    let linear_too = bounced.is_some();
    let (ref_ms, ref_t, ref_img, visible, ref_linear) =
        measure(&scene, reference, 1, false, linear_too)?;
    let n_points = hair.point_count();
    bar.inc(1);
    // Where the two disagree, block by block: Cycles' shadow ratio beside
    // the exact reference's, for a look.
    if let (Some(dir), Some(t), Some(u)) = (&a.cycles, &truth, &unshadowed) {
        let mine = raster::ShadowRatios::new(
            &linear(&ref_img),
            u,
            ref_img.width() as usize,
            ref_img.height() as usize,
            BLOCK,
        );
        crate::output::write_png(&dir.join(REFERENCE_PNG), &ref_img)?;
        let side = ratio_picture(&[&t.ratios, &mine]);
        let path = dir.join("ratios.png");
        crate::output::write_png(&path, &side)?;
        eprintln!(
            "wrote {}: shadow ratio per block, Cycles (left) and the reference (right); red where a block does not count; and wisplight's pictures beside Cycles' (direct light, 8-bit sRGB): {REFERENCE_PNG}, {UNSHADOWED_PNG}, {CYCLES_PNG}, {CYCLES_UNSHADOWED_PNG}",
            path.display()
        );
    }
    let bg = scene.render.background;
    let mut rows = vec![Row {
        config: reference,
        ms: ref_ms,
        mean_abs: 0.0,
        rms: 0.0,
        max: 0.0,
        image: 0.0,
        seen: (0.0, 0.0),
        cycles: against_cycles(&ref_img),
        scattering: scattered(reference, ref_linear)?,
    }];
    for c in configs {
        bar.set_message(format!("{} {}", c.name(), c.parameters()));
        let (ms, t, img, _, direct) = measure(&scene, c, a.runs as usize, true, linear_too)?;
        let (mean_abs, rms, max) = errors(&t, &ref_t);
        let seen = visible_errors(&t, &ref_t, &visible, n_points);
        rows.push(Row {
            config: c,
            ms,
            mean_abs,
            rms,
            max,
            image: image_error(&img, &ref_img, bg),
            seen,
            cycles: against_cycles(&img),
            scattering: scattered(c, direct)?,
        });
        bar.inc(1);
    }
    bar.finish_and_clear();
    if let Some(t) = &truth {
        eprintln!(
            "Cycles ({} samples, direct light): {:.1} s shadowed, {:.1} s unshadowed; mean shadow ratio {:.3} over {} blocks of {BLOCK}x{BLOCK} pixels",
            a.cycles_samples,
            t.seconds.0,
            t.seconds.1,
            t.ratios.mean(),
            t.ratios.ratio.iter().flatten().count()
        );
    }

    println!(
        "{:<19} {:<78} {:>9} {:>8} {:>8} {:>8} {:>8} {:>9} {:>8} {:>8} {:>8}",
        "method",
        "parameters",
        "ms",
        "mean_abs",
        "rms",
        "max",
        "image",
        "seen_bias",
        "seen_abs",
        "cycles",
        "ratio"
    );
    let opt = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.4}"));
    for r in &rows {
        println!(
            "{:<19} {:<78} {:>9.2} {:>8.4} {:>8.4} {:>8.4} {:>8.4} {:>9.4} {:>8.4} {:>8} {:>8}",
            r.config.name(),
            r.config.parameters(),
            r.ms,
            r.mean_abs,
            r.rms,
            r.max,
            r.image,
            r.seen.0,
            r.seen.1,
            opt(r.cycles.map(|c| c.mean_abs)),
            opt(r.cycles.map(|c| c.mean)),
        );
    }
    if let Some(t) = &truth {
        println!(
            "{:<19} {:<78} {:>9.0} {:>8} {:>8} {:>8} {:>8} {:>9} {:>8} {:>8} {:>8.4}",
            "cycles",
            format!("samples={} bounces=0", a.cycles_samples),
            1e3 * t.seconds.0,
            "-",
            "-",
            "-",
            "-",
            "-",
            "-",
            "0",
            t.ratios.mean()
        );
    }
    if let Some((cycles, seconds)) = &bounced {
        let measured: Vec<scattering::Measured> = rows
            .iter()
            .filter_map(|r| {
                Some(scattering::Measured {
                    method: r.config.name(),
                    parameters: r.config.parameters(),
                    shadow_ms: r.ms,
                    against: r.scattering?,
                })
            })
            .collect();
        scattering::print_table(&measured, cycles, *seconds, a.cycles_samples, a.bounces);
    }
    if let Some(path) = &a.csv {
        // The csv crate quotes a field where its text calls for it.
        let mut w = csv::Writer::from_writer(Vec::new());
        w.write_record(CSV_HEADER)?;
        let f6 = |v: f64| format!("{v:.6}");
        for r in &rows {
            w.write_record([
                r.config.name().to_string(),
                r.config.parameters(),
                format!("{:.4}", r.ms),
                format!("{:.6}", r.mean_abs),
                format!("{:.6}", r.rms),
                format!("{:.6}", r.max),
                format!("{:.6}", r.image),
                format!("{:.6}", r.seen.0),
                format!("{:.6}", r.seen.1),
                r.cycles
                    .map_or(String::new(), |c| format!("{:.6}", c.mean_abs)),
                r.cycles.map_or(String::new(), |c| format!("{:.6}", c.mean)),
                r.scattering.map_or(String::new(), |s| f6(s.shade_ms)),
                r.scattering.map_or(String::new(), |s| f6(s.share.mean_abs)),
                r.scattering.map_or(String::new(), |s| f6(s.share.mean)),
                r.scattering.map_or(String::new(), |s| f6(s.gain)),
                r.scattering.map_or(String::new(), |s| f6(s.color[0])),
                r.scattering.map_or(String::new(), |s| f6(s.color[1])),
                r.scattering.map_or(String::new(), |s| f6(s.parts.0)),
                r.scattering.map_or(String::new(), |s| f6(s.parts.1)),
            ])?;
        }
        // Cycles' rows: the columns named, the others empty.
        let mut named = |fields: &[(&str, String)]| {
            let mut row = vec![String::new(); CSV_HEADER.len()];
            for (name, value) in fields {
                let k = CSV_HEADER.iter().position(|h| h == name).expect("a column");
                row[k] = value.clone();
            }
            w.write_record(&row)
        };
        if let Some(t) = &truth {
            named(&[
                ("method", "cycles".into()),
                (
                    "parameters",
                    format!("samples={} bounces=0", a.cycles_samples),
                ),
                ("ms", format!("{:.1}", 1e3 * t.seconds.0)),
                ("cycles_error", "0".into()),
                ("mean_ratio", f6(t.ratios.mean())),
            ])?;
        }
        if let Some((c, seconds)) = &bounced {
            named(&[
                ("method", "cycles".into()),
                (
                    "parameters",
                    format!("samples={} bounces={}", a.cycles_samples, a.bounces),
                ),
                ("ms", format!("{:.1}", 1e3 * seconds)),
                ("direct_share_error", "0".into()),
                ("direct_share", f6(c.share.mean())),
                ("gain", f6(c.gain)),
                ("red_green", f6(c.color[0])),
                ("blue_green", f6(c.color[1])),
            ])?;
        }
        let bytes = w.into_inner().context("cannot write the table")?;
        crate::output::write_bytes(path, &bytes).context("cannot save the table")?;
        eprintln!("wrote {}", path.display());
    }
    if let Some(path) = &a.plot {
        super::write_chart(path, &plot_rows(&rows[1..], &name, cores, Metric::Rms))?;
        if truth.is_some() {
            let stem = path.file_stem().unwrap_or_default().to_string_lossy();
            let cycles = path.with_file_name(format!("{stem}-cycles.png"));
            super::write_chart(&cycles, &plot_rows(&rows, &name, cores, Metric::Cycles))?;
        }
        if bounced.is_some() {
            let stem = path.file_stem().unwrap_or_default().to_string_lossy();
            let chart = path.with_file_name(format!("{stem}-scattering.png"));
            super::write_chart(&chart, &plot_rows(&rows, &name, cores, Metric::Scattering))?;
        }
    }
    Ok(())
}

/// The CSV's columns.
const CSV_HEADER: [&str; 19] = [
    "method",
    "parameters",
    "ms",
    "mean_abs",
    "rms",
    "max",
    "image_error",
    "seen_bias",
    "seen_abs",
    "cycles_error",
    "mean_ratio",
    "scattering_shade_ms",
    "direct_share_error",
    "direct_share",
    "gain",
    "red_green",
    "blue_green",
    "direct_share_error_of_direct",
    "direct_share_error_of_scattered",
];

/// What a plot's vertical axis shows.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Metric {
    /// RMS error of T against the exact reference at the drawn points.
    Rms,
    /// Mean block shadow ratio error against Cycles' picture.
    Cycles,
    /// Mean block direct-share error against Cycles' bounces.
    Scattering,
}

/// The scene's first frame with `config`, rendered `runs` times (after one
/// untimed frame with `warmup`): the median time of the three shadow
/// stages, the transmittance at every drawn point of every light, and the
/// last picture.
fn measure(
    scene: &Scene,
    config: MethodConfig,
    runs: usize,
    warmup: bool,
    linear: bool,
) -> anyhow::Result<Measured> {
    let mut s = scene.clone();
    s.shadow.method = config;
    s.effects.self_shadow = true;
    // The hair at rest, as the scene's groom or style makes it.
    s.animation.motion = sim::Motion::Still;
    let mut seq = Sequence::new(&s)?;
    let mut times = Vec::with_capacity(runs);
    let mut img = None;
    let warmup = usize::from(warmup);
    for i in 0..warmup + runs {
        let (pic, stats) = seq
            .again()
            .with_context(|| format!("cannot render with {}", config.name()))?;
        if i + 1 == warmup + runs {
            img = Some(pic.clone());
        }
        if i >= warmup {
            let shadow = [Stage::Density, Stage::Transmittance, Stage::Filter];
            times.push(shadow.iter().map(|&st| stats.stage(st).ms).sum());
        }
    }
    let img = img.expect("at least one frame");
    let t = seq.renderer().transmittance().concat();
    let visible = match seq.renderer().camera() {
        Some(c) => visible_points(c, seq.hair().points()),
        None => Vec::new(),
    };
    // With `linear`, the last picture unclamped too.
    let px = match linear {
        true => Some(
            seq.renderer()
                .linear_picture()
                .context("no picture drawn")?
                .iter()
                .map(|p| p.truncate())
                .collect(),
        ),
        false => None,
    };
    Ok((crate::cmd::median(&mut times), t, img, visible, px))
}

/// What [`measure`] gives: the median time of the shadow stages, the
/// transmittance at every drawn point, the last picture, the points it
/// shows, and that picture in linear RGB when asked.
type Measured = (f64, Vec<f32>, RgbImage, Vec<usize>, Option<Vec<glam::Vec3>>);

/// The drawn points the picture shows: at each pixel, the point nearest
/// the camera of those that project into it (the head not counted).
fn visible_points(camera: &raster::Camera, points: &[glam::Vec3]) -> Vec<usize> {
    let (w, h) = (camera.width() as usize, camera.height() as usize);
    let mut nearest = vec![(f32::INFINITY, usize::MAX); w * h];
    for (i, &p) in points.iter().enumerate() {
        if let Some(s) = camera.project(p)
            && s.x >= 0.0
            && s.y >= 0.0
            && (s.x as usize) < w
            && (s.y as usize) < h
        {
            let px = &mut nearest[s.y as usize * w + s.x as usize];
            if s.z < px.0 {
                *px = (s.z, i);
            }
        }
    }
    let mut v: Vec<usize> = nearest
        .into_iter()
        .filter(|n| n.1 != usize::MAX)
        .map(|n| n.1)
        .collect();
    v.sort_unstable();
    v
}

/// Mean signed and mean absolute difference of `t` from `reference` at
/// the points `at` (of each light's `n` points).
fn visible_errors(t: &[f32], reference: &[f32], at: &[usize], n: usize) -> (f64, f64) {
    let lights = t.len() / n.max(1);
    let (mut sum, mut abs, mut count) = (0.0f64, 0.0f64, 0usize);
    for l in 0..lights {
        for &i in at {
            let d = f64::from(t[l * n + i] - reference[l * n + i]);
            sum += d;
            abs += d.abs();
            count += 1;
        }
    }
    let c = count.max(1) as f64;
    (sum / c, abs / c)
}

/// Mean absolute, RMS and largest difference between `t` and `reference`.
fn errors(t: &[f32], reference: &[f32]) -> (f64, f64, f64) {
    assert_eq!(t.len(), reference.len());
    let n = t.len().max(1) as f64;
    let (mut sum, mut sq, mut max) = (0.0f64, 0.0f64, 0.0f64);
    for (&a, &b) in t.iter().zip(reference) {
        let d = f64::from((a - b).abs());
        sum += d;
        sq += d * d;
        max = max.max(d);
    }
    (sum / n, (sq / n).sqrt(), max)
}

/// Mean absolute difference (0 to 1) over the colour channels of the
/// pixels where either picture shows something other than the background.
fn image_error(a: &RgbImage, b: &RgbImage, background: glam::Vec3) -> f64 {
    let bg = raster::to_srgb8(background);
    let (mut sum, mut n) = (0u64, 0u64);
    for (p, q) in a.pixels().zip(b.pixels()) {
        if p.0 == bg && q.0 == bg {
            continue;
        }
        for c in 0..3 {
            sum += u64::from(p.0[c].abs_diff(q.0[c]));
        }
        n += 3;
    }
    if n == 0 {
        0.0
    } else {
        sum as f64 / n as f64 / 255.0
    }
}

fn plot_rows(rows: &[Row], scene: &str, cores: usize, metric: Metric) -> plot::Chart {
    let rows: Vec<&Row> = rows
        .iter()
        .filter(|r| match metric {
            Metric::Rms => true,
            Metric::Cycles => r.cycles.is_some(),
            Metric::Scattering => r.scattering.is_some(),
        })
        .collect();
    let series: Vec<String> = MethodConfig::NAMES
        .iter()
        .filter(|n| {
            (metric != Metric::Rms || **n != "reference")
                && rows.iter().any(|r| r.config.name() == **n)
        })
        .map(|n| n.to_string())
        .collect();
    // Each point labelled with the settings that differ between its
    // method's rows (what the method was run at).
    let label = |r: &Row| {
        let mine: Vec<String> = r
            .config
            .parameters()
            .split(' ')
            .map(str::to_string)
            .collect();
        let varies = |kv: &String| {
            rows.iter()
                .filter(|o| o.config.name() == r.config.name())
                .any(|o| !o.config.parameters().split(' ').any(|x| x == kv))
        };
        let shown: Vec<&str> = mine
            .iter()
            .filter(|kv| varies(kv))
            .map(String::as_str)
            .collect();
        shown.join(" ")
    };
    let points: Vec<plot::Point> = rows
        .iter()
        .map(|r| plot::Point {
            x_ms: r.ms + r.scattering.map_or(0.0, |s| s.shade_ms),
            y: match metric {
                Metric::Rms => r.rms,
                Metric::Cycles => r.cycles.map_or(0.0, |c| c.mean_abs),
                Metric::Scattering => r.scattering.map_or(0.0, |s| s.share.mean_abs),
            },
            series: series
                .iter()
                .position(|s| s == r.config.name())
                .unwrap_or(0),
            label: label(r),
        })
        .collect();
    let scene = Path::new(scene)
        .file_stem()
        .map_or(scene.to_string(), |s| s.to_string_lossy().into_owned());
    let (title, y) = match metric {
        Metric::Rms => (
            format!("shadow error vs time: {scene}, {cores} cores"),
            "RMS error of T at the drawn points",
        ),
        Metric::Cycles => (
            format!("error against Cycles vs time: {scene}, {cores} cores"),
            "mean error of the 8x8 block shadow ratio",
        ),
        Metric::Scattering => (
            format!("scattered light against Cycles' bounces vs time: {scene}, {cores} cores"),
            "mean error of the 8x8 block direct share",
        ),
    };
    let x = match metric {
        Metric::Scattering => "three shadow stages and the shade stage, ms (log scale)",
        _ => "three shadow stages, ms (log scale)",
    };
    plot::scatter(&title, x, y, &series, &points)
}
