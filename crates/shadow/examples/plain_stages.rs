//! The paper's three shadow stages written plainly, to measure how fast
//! the method itself can run on a machine, apart from what wisplight adds
//! to it:
//!
//! - density: one increment per Catmull-Rom point into the cell holding it
//!   (paper 4.1), into a dense grid of `n^3` counts;
//! - transmittance: a running sum down every column of the dense grid
//!   (paper 4.2), stored as optical depth;
//! - filter: a trilinear lookup of the dense grid at every point, and one
//!   `exp` (paper 4.3).
//!
//! It leaves out what `DensityMap` does besides: no pieces (a segment
//! longer than a cell leaves gaps), no tent splat across columns (combed
//! hair aliases into stripes), no physical units, no per-column spans or
//! fronts (T is not exactly 1 in front of the hair), no count of hair
//! outside the map, and a dense grid that is emptied in full (not timed).
//! Serial without atomics, then with rayon (atomic increments).
//!
//! ```text
//! cargo run --release -p shadow --example plain_stages -- [smooth|curly|dense] [CELLS]
//! ```
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::Instant;

use glam::Vec3;
use rayon::prelude::*;
use shadow::{Fiber, Light, LightFrame, Occluder, ShadowInput};
use strands::{Style, StyleParams, WispModel, resample};

/// Extinction per count, per cell (the paper's free factor `f`).
const F: f32 = 0.01;

fn median(mut t: Vec<f64>) -> f64 {
    t.sort_by(f64::total_cmp);
    t[t.len() / 2]
}

/// The cell holding map coordinates `c`, if inside the map.
#[inline]
fn cell(c: Vec3, n: usize) -> Option<usize> {
    (c.cmpge(Vec3::ZERO).all() && c.cmplt(Vec3::splat(n as f32)).all())
        .then(|| (c.z as usize * n + c.y as usize) * n + c.x as usize)
}

/// Trilinear optical depth of the dense grid `depth` at map coordinates
/// `c`, between cell centres.
#[inline]
fn trilinear(depth: &[f32], n: usize, c: Vec3) -> f32 {
    let c = (c - 0.5).clamp(Vec3::ZERO, Vec3::splat(n as f32 - 1.001));
    let (i, j, k) = (c.x as usize, c.y as usize, c.z as usize);
    let (tx, ty, tz) = (c.x - i as f32, c.y - j as f32, c.z - k as f32);
    let at = |i: usize, j: usize, k: usize| depth[(k * n + j) * n + i];
    let lerp = |a: f32, b: f32, t: f32| a + t * (b - a);
    let plane = |k: usize| {
        lerp(
            lerp(at(i, j, k), at(i + 1, j, k), tx),
            lerp(at(i, j + 1, k), at(i + 1, j + 1, k), tx),
            ty,
        )
    };
    lerp(plane(k), plane(k + 1), tz)
}

fn main() {
    let style = std::env::args().nth(1).unwrap_or_else(|| "smooth".into());
    let cells = std::env::args()
        .nth(2)
        .map_or(128, |c| c.parse().expect("CELLS: a number of cells"));
    let params = match style.as_str() {
        "smooth" => StyleParams::new(Style::Smooth),
        "curly" => StyleParams::new(Style::Curly),
        // The size of scenes/dense.toml: about 1.1M segments.
        "dense" => StyleParams {
            strands_per_wisp: 280,
            ..StyleParams::new(Style::Smooth)
        },
        other => panic!("unknown style {other:?}: smooth, curly or dense"),
    };
    // The hair as `wisplight` draws it: the style's strands, Catmull-Rom
    // resampled with one point between each two.
    let hair = resample(&WispModel::generate(&params).interpolate(), 2);
    let light = Light::directional(Vec3::new(0.9, -0.35, -0.25)).expect("a light");
    let fiber = Fiber::new(0.01, 0.5).expect("a fiber");
    let head = [Occluder::sphere(Vec3::ZERO, 10.0)];
    let frame: LightFrame = ShadowInput {
        light: &light,
        hair: &hair,
        fiber: &fiber,
        occluders: &head,
        extent: None,
    }
    .fit(cells)
    .expect("a map");
    let n = frame.n_cells as usize;
    let pts = hair.points();
    let mut depth = vec![0.0f32; n * n * n];
    let mut out = vec![0.0f32; pts.len()];
    let runs = 30;

    // Serial, plain integers.
    let mut grid = vec![0u32; n * n * n];
    let mut serial = [vec![], vec![], vec![]];
    for _ in 0..runs {
        grid.fill(0);
        let t0 = Instant::now();
        for &p in pts {
            if let Some(c) = cell(frame.to_cells(p), n) {
                grid[c] += 1;
            }
        }
        let t1 = Instant::now();
        for (d, g) in depth.chunks_mut(n).zip(grid.chunks(n)) {
            let mut sum = 0.0;
            for (d, &g) in d.iter_mut().zip(g) {
                sum += F * g as f32;
                *d = sum;
            }
        }
        let t2 = Instant::now();
        for (o, &p) in out.iter_mut().zip(pts) {
            *o = (-trilinear(&depth, n, frame.to_cells(p))).exp();
        }
        let t3 = Instant::now();
        for (s, (a, b)) in serial.iter_mut().zip([(t0, t1), (t1, t2), (t2, t3)]) {
            s.push((b - a).as_secs_f64() * 1e3);
        }
    }
    let serial_sum: f64 = out.iter().map(|&t| f64::from(t)).sum();

    // Parallel: atomic increments, columns and points split over threads.
    let counts: Vec<AtomicU32> = (0..n * n * n).map(|_| AtomicU32::new(0)).collect();
    let mut parallel = [vec![], vec![], vec![]];
    for _ in 0..runs {
        counts
            .par_chunks(n * n)
            .for_each(|c| c.iter().for_each(|c| c.store(0, Ordering::Relaxed)));
        let t0 = Instant::now();
        pts.par_chunks(8192).for_each(|ps| {
            for &p in ps {
                if let Some(c) = cell(frame.to_cells(p), n) {
                    counts[c].fetch_add(1, Ordering::Relaxed);
                }
            }
        });
        let t1 = Instant::now();
        depth
            .par_chunks_mut(n)
            .zip(counts.par_chunks(n))
            .for_each(|(d, c)| {
                let mut sum = 0.0;
                for (d, c) in d.iter_mut().zip(c) {
                    sum += F * c.load(Ordering::Relaxed) as f32;
                    *d = sum;
                }
            });
        let t2 = Instant::now();
        out.par_chunks_mut(4096)
            .zip(pts.par_chunks(4096))
            .for_each(|(o, ps)| {
                for (o, &p) in o.iter_mut().zip(ps) {
                    *o = (-trilinear(&depth, n, frame.to_cells(p))).exp();
                }
            });
        let t3 = Instant::now();
        for (s, (a, b)) in parallel.iter_mut().zip([(t0, t1), (t1, t2), (t2, t3)]) {
            s.push((b - a).as_secs_f64() * 1e3);
        }
    }
    let parallel_sum: f64 = out.iter().map(|&t| f64::from(t)).sum();
    assert!(
        (serial_sum - parallel_sum).abs() <= 1e-6 * serial_sum,
        "the serial and parallel stages disagree"
    );

    println!(
        "plain stages, {style}: {} points, {n}^3 cells, medians of {runs} runs",
        pts.len()
    );
    for (name, t) in [("1 thread", serial), ("rayon", parallel)] {
        let [d, s, f] = t.map(median);
        println!(
            "  {name:>8} ({} threads): density {d:.2} ms, transmittance {s:.2} ms, \
             filter {f:.2} ms, total {:.2} ms",
            if name == "rayon" {
                rayon::current_num_threads()
            } else {
                1
            },
            d + s + f
        );
    }
}
