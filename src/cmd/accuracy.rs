//! `wisplight bench accuracy`: every shadow method at a range of settings
//! against the exact reference, error against time.

use std::path::{Path, PathBuf};

use anyhow::Context;
use engine::{Scene, Sequence, Stage};
use image::RgbImage;
use shadow::{Beyond, MethodConfig, OpacityMode};

use crate::plot;

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
    #[command(flatten)]
    pub threads: super::Threads,
}

/// The settings swept for each method, coarse to fine.
pub fn sweep() -> Vec<MethodConfig> {
    let mut v = Vec::new();
    for cells in [32, 64, 128, 256] {
        for filter in [true, false] {
            v.push(MethodConfig::DensityMap { cells, filter });
        }
    }
    let osm = |slices, mode, offset| MethodConfig::OpacityShadowMap {
        resolution: 128,
        slices,
        mode,
        offset,
        filter: true,
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
        filter: true,
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
            filter: true,
        });
    }
    for (resolution, tolerance) in [(64, 0.01), (128, 0.01), (256, 0.01), (128, 0.05)] {
        v.push(MethodConfig::DeepShadowMap {
            resolution,
            tolerance,
            filter: true,
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
}

pub fn run(a: AccuracyArgs) -> anyhow::Result<()> {
    let scene = super::load_scene(a.scene.as_deref())?;
    if let Some(p) = &a.plot {
        super::check_plot_path(p)?;
    }
    let hair = super::build_hair(&scene)?;
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
    let bar = super::progress_bar(
        configs.len() as u64 + 1,
        "{bar:30} {pos}/{len} {msg} [{elapsed}]",
    );
    bar.set_message("reference");
    let reference = MethodConfig::with_defaults("reference", 128).expect("a known method");
    let (ref_ms, ref_t, ref_img) = measure(&scene, reference, 1, false)?;
    bar.inc(1);
    let bg = scene.render.background;
    let mut rows = vec![Row {
        config: reference,
        ms: ref_ms,
        mean_abs: 0.0,
        rms: 0.0,
        max: 0.0,
        image: 0.0,
    }];
    for c in configs {
        bar.set_message(format!("{} {}", c.name(), c.parameters()));
        let (ms, t, img) = measure(&scene, c, a.runs as usize, true)?;
        let (mean_abs, rms, max) = errors(&t, &ref_t);
        rows.push(Row {
            config: c,
            ms,
            mean_abs,
            rms,
            max,
            image: image_error(&img, &ref_img, bg),
        });
        bar.inc(1);
    }
    bar.finish_and_clear();

    println!(
        "{:<19} {:<78} {:>9} {:>8} {:>8} {:>8} {:>8}",
        "method", "parameters", "ms", "mean_abs", "rms", "max", "image"
    );
    for r in &rows {
        println!(
            "{:<19} {:<78} {:>9.2} {:>8.4} {:>8.4} {:>8.4} {:>8.4}",
            r.config.name(),
            r.config.parameters(),
            r.ms,
            r.mean_abs,
            r.rms,
            r.max,
            r.image
        );
    }
    if let Some(path) = &a.csv {
        // The csv crate quotes a field where its text calls for it.
        let mut w = csv::Writer::from_writer(Vec::new());
        w.write_record([
            "method",
            "parameters",
            "ms",
            "mean_abs",
            "rms",
            "max",
            "image_error",
        ])?;
        for r in &rows {
            w.write_record([
                r.config.name().to_string(),
                r.config.parameters(),
                format!("{:.4}", r.ms),
                format!("{:.6}", r.mean_abs),
                format!("{:.6}", r.rms),
                format!("{:.6}", r.max),
                format!("{:.6}", r.image),
            ])?;
        }
        let bytes = w.into_inner().context("cannot write the table")?;
        crate::output::write_bytes(path, &bytes).context("cannot save the table")?;
        eprintln!("wrote {}", path.display());
    }
    if let Some(path) = &a.plot {
        super::write_chart(path, &plot_rows(&rows[1..], &name, cores))?;
    }
    Ok(())
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
) -> anyhow::Result<(f64, Vec<f32>, RgbImage)> {
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
    Ok((super::median(&mut times), t, img))
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

fn plot_rows(rows: &[Row], scene: &str, cores: usize) -> plot::Chart {
    let series: Vec<String> = MethodConfig::NAMES
        .iter()
        .filter(|n| **n != "reference" && rows.iter().any(|r| r.config.name() == **n))
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
            x_ms: r.ms,
            y: r.rms,
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
    plot::scatter(
        &format!("shadow error vs time: {scene}, {cores} cores"),
        "three shadow stages, ms (log scale)",
        "RMS error of T at the drawn points",
        &series,
        &points,
    )
}
