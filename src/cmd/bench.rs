//! `wisplight bench`: stage timings, medians over repeated runs.

use std::path::PathBuf;

use engine::{ShadowPipeline, StageTimes};

#[derive(Debug, clap::Subcommand)]
pub enum Bench {
    /// Median time of the three shadow stages (density, transmittance,
    /// filter at every drawn point) on a scene.
    Shadow(ShadowArgs),
    /// Median time of each stage of a whole rendered frame (shadow stages,
    /// shading, drawing) at the scene's image size (1280x720 by default).
    Frame(FrameArgs),
    /// Every shadow method at a range of settings against the exact
    /// reference: time and error at every drawn point and in the picture.
    Accuracy(super::accuracy::AccuracyArgs),
}

#[derive(Debug, clap::Args)]
pub struct FrameArgs {
    /// Scene file (TOML); the built-in scene when omitted.
    scene: Option<PathBuf>,
    /// Timed frames (after 3 untimed warm-up frames).
    #[arg(long, default_value_t = 20, value_name = "N")]
    runs: usize,
    /// Also print the result as one JSON object on the last stdout line.
    #[arg(long)]
    json: bool,
}

#[derive(Debug, clap::Args)]
pub struct ShadowArgs {
    /// Scene file (TOML); the built-in scene when omitted.
    scene: Option<PathBuf>,
    /// Map cells a side, overriding the scene's `shadow.cells`.
    #[arg(long, value_name = "N")]
    cells: Option<u32>,
    /// Timed runs (after 5 untimed warm-up runs).
    #[arg(long, default_value_t = 30, value_name = "N")]
    runs: usize,
    /// Also print the result as one JSON object on the last stdout line.
    #[arg(long)]
    json: bool,
}

pub fn run(b: Bench) -> anyhow::Result<()> {
    match b {
        Bench::Shadow(a) => shadow(a),
        Bench::Frame(a) => frame(a),
        Bench::Accuracy(a) => super::accuracy::run(a),
    }
}

fn shadow(a: ShadowArgs) -> anyhow::Result<()> {
    anyhow::ensure!(a.runs >= 1, "--runs {}: must be at least 1", a.runs);
    let mut scene = super::load_scene(a.scene.as_deref())?;
    if let Some(c) = a.cells {
        anyhow::ensure!(
            (1..=shadow::MAX_CELLS).contains(&c),
            "--cells {c}: must be in 1..={}",
            shadow::MAX_CELLS
        );
        scene.shadow.set_cells(c);
    }
    let hair = super::build_hair(&scene)?;
    let (name, threads, cores) = machine(a.scene.as_deref());
    eprintln!(
        "bench shadow: {name}: {} segments, {} points, {}^3 cells, {} light(s), {threads} threads on {cores} cores, {} runs",
        hair.segment_count(),
        hair.point_count(),
        scene.shadow.cells(),
        scene.lights.len(),
        a.runs
    );
    let mut pipeline = ShadowPipeline::new(&scene)?;
    let t = StageTimes::measure(&mut pipeline, &hair, 5, a.runs, |_| {})?;
    println!("stage           median ms");
    println!("density         {:9.3}", t.density_ms);
    println!("transmittance   {:9.3}", t.transmittance_ms);
    println!("filter          {:9.3}", t.filter_ms);
    println!("total           {:9.3}", t.total_ms());
    eprintln!("bench shadow: {} density samples per run", t.samples);
    if a.json {
        let j = serde_json::json!({
            "scene": name,
            "segments": hair.segment_count(),
            "points": hair.point_count(),
            "cells": scene.shadow.cells(),
            "lights": scene.lights.len(),
            "threads": threads,
            "cores": cores,
            "runs": t.runs,
            "samples": t.samples,
            "density_ms": t.density_ms,
            "transmittance_ms": t.transmittance_ms,
            "filter_ms": t.filter_ms,
            "total_ms": t.total_ms(),
        });
        println!("{j}");
    }
    Ok(())
}

fn frame(a: FrameArgs) -> anyhow::Result<()> {
    anyhow::ensure!(a.runs >= 1, "--runs {}: must be at least 1", a.runs);
    let scene = super::load_scene(a.scene.as_deref())?;
    let hair = super::build_hair(&scene)?;
    let (name, threads, cores) = machine(a.scene.as_deref());
    eprintln!(
        "bench frame: {name}: {} segments, {}x{}, {}^3 cells, {threads} threads on {cores} cores, {} runs",
        hair.segment_count(),
        scene.render.width,
        scene.render.height,
        scene.shadow.cells(),
        a.runs
    );
    let mut renderer = engine::Renderer::new(&scene)?;
    let mut stages: [Vec<f64>; 6] = Default::default();
    for r in 0..3 + a.runs {
        let t0 = std::time::Instant::now();
        let (_, t) = renderer.render(&hair, true)?;
        let whole = t0.elapsed().as_secs_f64() * 1e3;
        if r >= 3 {
            for (v, x) in stages.iter_mut().zip([
                t.density_ms,
                t.transmittance_ms,
                t.filter_ms,
                t.shade_ms,
                t.draw_ms,
                whole,
            ]) {
                v.push(x);
            }
        }
    }
    let m: Vec<f64> = stages
        .iter_mut()
        .map(|v| engine::pipeline::median(v))
        .collect();
    let names = [
        "density",
        "transmittance",
        "filter",
        "shade",
        "draw",
        "frame",
    ];
    println!("stage           median ms");
    for (n, v) in names.iter().zip(&m) {
        println!("{n:<15} {v:9.3}");
    }
    if a.json {
        let j = serde_json::json!({
            "scene": name,
            "segments": hair.segment_count(),
            "width": scene.render.width,
            "height": scene.render.height,
            "cells": scene.shadow.cells(),
            "threads": threads,
            "cores": cores,
            "runs": a.runs,
            "density_ms": m[0],
            "transmittance_ms": m[1],
            "filter_ms": m[2],
            "shade_ms": m[3],
            "draw_ms": m[4],
            "frame_ms": m[5],
        });
        println!("{j}");
    }
    Ok(())
}

/// What a benchmark reports beside its times: the scene's name, the worker
/// threads, and the machine's cores.
pub(crate) fn machine(scene: Option<&std::path::Path>) -> (String, usize, usize) {
    let name = scene.map_or("built-in".to_string(), |p| p.display().to_string());
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    (name, rayon::current_num_threads(), cores)
}
