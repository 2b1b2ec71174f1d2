//! `wisplight-bench` (`wisplight bench`): stage timings, medians over
//! repeated runs, the shadow methods' accuracy, scaling over local worker
//! processes with emulated nodes, and their plots. Kept out of the
//! `wisplight` program itself.

pub mod accuracy;
mod cycles_truth;
pub mod nodes;
pub mod plot;
pub mod scaling;
mod scattering;

use std::path::{Path, PathBuf};

use anyhow::Context;
use engine::Stage;

/// The `wisplight-bench` program's command line.
#[derive(Debug, clap::Parser)]
#[command(
    name = "wisplight-bench",
    bin_name = "wisplight bench",
    version,
    about = "Measures wisplight: stage timings, the shadow methods' accuracy, cluster scaling"
)]
pub struct Cli {
    #[command(flatten)]
    pub log: crate::cmd::Log,
    #[command(subcommand)]
    pub bench: Bench,
}

/// Runs the benchmark `cli` names: its exit code.
pub fn run_cli(cli: Cli) -> std::process::ExitCode {
    crate::app::start(cli.log);
    let result = crate::app::init_threads(cli.bench.threads()).and_then(|()| run(cli.bench));
    crate::app::finish(result)
}

#[derive(Debug, clap::Subcommand)]
pub enum Bench {
    /// Median time of the three shadow stages (density, transmittance,
    /// filter at every drawn point) on a scene.
    Shadow(ShadowArgs),
    /// Median time of each stage of whole animated frames (simulation,
    /// collisions, shadow stages, shading, drawing) at the scene's image
    /// size (1280x720 by default), over consecutive frames of its animation.
    Frame(FrameArgs),
    /// Every shadow method at a range of settings against the exact
    /// reference: time and error at every drawn point and in the picture.
    Accuracy(accuracy::AccuracyArgs),
    /// The same animated frames in one process and on 1, 2, 3, ... local
    /// worker processes: median frame time, speedups, where the time went
    /// (workers' steps, density fill, sweep, the coordinator's own work),
    /// bytes on the wire; writes a plot.
    Scaling(scaling::ScalingArgs),
}

#[derive(Debug, clap::Args)]
pub struct FrameArgs {
    /// Scene file (TOML); the built-in scene when omitted.
    scene: Option<PathBuf>,
    /// Timed frames (after 3 untimed frames: the first settles the hair).
    #[arg(long, default_value_t = 20, value_name = "N",
          value_parser = clap::value_parser!(u64).range(1..=100_000))]
    runs: u64,
    /// Also print the result as one JSON object on the last stdout line.
    #[arg(long)]
    json: bool,
    #[command(flatten)]
    pub threads: crate::cmd::Threads,
}

#[derive(Debug, clap::Args)]
pub struct ShadowArgs {
    /// Scene file (TOML); the built-in scene when omitted.
    scene: Option<PathBuf>,
    /// Map cells a side, overriding the scene's `shadow.cells`.
    #[arg(long, value_name = "N",
          value_parser = clap::value_parser!(u32).range(1..=shadow::MAX_CELLS as i64))]
    cells: Option<u32>,
    /// Timed runs (after 5 untimed warm-up runs).
    #[arg(long, default_value_t = 30, value_name = "N",
          value_parser = clap::value_parser!(u64).range(1..=100_000))]
    runs: u64,
    /// Also print the result as one JSON object on the last stdout line.
    #[arg(long)]
    json: bool,
    #[command(flatten)]
    pub threads: crate::cmd::Threads,
}

impl Bench {
    /// The `--threads` the benchmark was given.
    pub fn threads(&self) -> Option<u16> {
        match self {
            Bench::Shadow(a) => a.threads.threads,
            Bench::Frame(a) => a.threads.threads,
            Bench::Accuracy(a) => a.threads.threads,
            Bench::Scaling(a) => a.threads.threads,
        }
    }
}

pub fn run(b: Bench) -> anyhow::Result<()> {
    match b {
        Bench::Shadow(a) => shadow(a),
        Bench::Frame(a) => frame(a),
        Bench::Accuracy(a) => accuracy::run(a),
        Bench::Scaling(a) => scaling::run(a),
    }
}

fn shadow(a: ShadowArgs) -> anyhow::Result<()> {
    let mut scene = crate::cmd::load_scene(a.scene.as_deref())?;
    if let Some(c) = a.cells {
        scene.shadow.set_cells(c);
    }
    // The hair at rest, its shadows rendered again and again.
    scene.effects.self_shadow = true;
    scene.animation.motion = sim::Motion::Still;
    let mut seq = engine::Sequence::new(&scene).context("cannot set up the scene")?;
    let (name, threads, cores) = machine(a.scene.as_deref());
    eprintln!(
        "bench shadow: {name}: {} segments, {} points, {}^3 cells, {} light(s), {threads} threads on {cores} cores, {} runs",
        seq.hair().segment_count(),
        seq.hair().point_count(),
        scene.shadow.cells(),
        scene.lights.len(),
        a.runs
    );
    const WARMUP: u64 = 5;
    let shadow_stages = [Stage::Density, Stage::Transmittance, Stage::Filter];
    let mut times = [Vec::new(), Vec::new(), Vec::new()];
    let mut samples = 0;
    for r in 0..WARMUP + a.runs {
        let (_, stats) = seq.again()?;
        if r >= WARMUP {
            for (v, s) in times.iter_mut().zip(shadow_stages) {
                v.push(stats.stage(s).ms);
            }
        }
        samples = stats.samples;
    }
    let [density_ms, transmittance_ms, filter_ms] = times.map(|mut v| crate::cmd::median(&mut v));
    let total_ms = density_ms + transmittance_ms + filter_ms;
    println!("stage           median ms");
    println!("density         {density_ms:9.3}");
    println!("transmittance   {transmittance_ms:9.3}");
    println!("filter          {filter_ms:9.3}");
    println!("total           {total_ms:9.3}");
    eprintln!("bench shadow: {samples} density samples per run");
    if a.json {
        let j = serde_json::json!({
            "scene": name,
            "segments": seq.hair().segment_count(),
            "points": seq.hair().point_count(),
            "cells": scene.shadow.cells(),
            "lights": scene.lights.len(),
            "threads": threads,
            "cores": cores,
            "runs": a.runs,
            "samples": samples,
            "density_ms": density_ms,
            "transmittance_ms": transmittance_ms,
            "filter_ms": filter_ms,
            "total_ms": total_ms,
        });
        println!("{j}");
    }
    Ok(())
}

fn frame(a: FrameArgs) -> anyhow::Result<()> {
    let scene = crate::cmd::load_scene(a.scene.as_deref())?;
    let (name, threads, cores) = machine(a.scene.as_deref());
    let mut seq = engine::Sequence::new(&scene).context("cannot set up the scene")?;
    eprintln!(
        "bench frame: {name}: {} segments, {}x{}, {}^3 cells, {} motion, {threads} threads on {cores} cores, {} runs",
        seq.hair().segment_count(),
        scene.render.width,
        scene.render.height,
        scene.shadow.cells(),
        match &scene.animation.motion {
            sim::Motion::Still => "still",
            sim::Motion::Dance { .. } => "dance",
            sim::Motion::Keyframes(_) => "keyframed",
        },
        a.runs
    );
    if scene.animation.motion.is_still() {
        eprintln!(
            "bench frame: the scene does not move: after the first frame every stage is reused"
        );
    }
    // Frame 0 settles the hair; frames 1 and 2 warm up.
    let mut per_stage: Vec<Vec<f64>> = vec![Vec::new(); Stage::ALL.len()];
    let mut whole = Vec::new();
    for r in 0..3 + a.runs {
        let t0 = std::time::Instant::now();
        let (_, stats) = seq.next_frame()?;
        let ms = t0.elapsed().as_secs_f64() * 1e3;
        if r >= 3 {
            for (v, (_, rec)) in per_stage.iter_mut().zip(stats.stages()) {
                v.push(rec.ms);
            }
            whole.push(ms);
        }
    }
    let medians: Vec<f64> = per_stage
        .iter_mut()
        .map(|v| crate::cmd::median(v))
        .collect();
    let frame_ms = crate::cmd::median(&mut whole);
    println!("stage           median ms");
    for (s, m) in Stage::ALL.iter().zip(&medians) {
        println!("{:<15} {m:9.3}", s.name());
    }
    println!("{:<15} {frame_ms:9.3}", "frame");
    if a.json {
        let mut j = serde_json::json!({
            "scene": name,
            "segments": seq.hair().segment_count(),
            "width": scene.render.width,
            "height": scene.render.height,
            "cells": scene.shadow.cells(),
            "threads": threads,
            "cores": cores,
            "runs": a.runs,
            "frame_ms": frame_ms,
        });
        for (s, m) in Stage::ALL.iter().zip(&medians) {
            j[format!("{}_ms", s.name())] = serde_json::json!(m);
        }
        println!("{j}");
    }
    Ok(())
}

/// Checks a `--plot` path: a `.png`, which gets the same chart as SVG
/// beside it (`.svg`).
pub fn check_plot_path(path: &Path) -> anyhow::Result<()> {
    if path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("png"))
    {
        Ok(())
    } else {
        Err(crate::cmd::usage(format!(
            "--plot {}: the plot is a .png (the SVG goes beside it)",
            path.display()
        )))
    }
}

/// Writes `chart` to `path` (a PNG) and as SVG beside it, each whole or
/// not at all; says where on stderr.
pub fn write_chart(path: &Path, chart: &plot::Chart) -> anyhow::Result<()> {
    crate::output::write_png(path, &chart.png()?).context("cannot save the plot")?;
    let svg = path.with_extension("svg");
    crate::output::write_bytes(&svg, chart.svg()?.as_bytes()).context("cannot save the plot")?;
    eprintln!("wrote {} and {}", path.display(), svg.display());
    Ok(())
}

/// What a benchmark reports beside its times: the scene's name, the worker
/// threads, and the machine's cores.
pub fn machine(scene: Option<&std::path::Path>) -> (String, usize, usize) {
    let name = scene.map_or("built-in".to_string(), |p| p.display().to_string());
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    (name, rayon::current_num_threads(), cores)
}
