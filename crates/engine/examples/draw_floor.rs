//! Drawing hair written plainly, a yardstick for the `draw` stage of
//! `wisplight bench frame`: a scene's segments (the smooth style by
//! default), framed from the front as the renderer frames hair (its head
//! aside), drawn as Wu lines (two fragments a step, as the renderer draws
//! them), binned by chunks of strands in parallel and added into an RGBA
//! float sum per pixel in bands of 16 rows that stay in a core's cache,
//! then encoded to 8 bits through a table.
//!
//! It leaves out what the renderer does besides: no depth test against the
//! head, no colour per vertex, no depth weights, no transparency product,
//! no head, no clipping of far segments. It is straightforward code, not
//! the fastest possible: it measures what drawing these fragments costs on
//! a machine with the least work per fragment, not a proven lower bound.
//!
//! ```text
//! cargo run --release -p engine --example draw_floor [SCENE.toml]
//! ```
use std::time::Instant;

use engine::{Scene, build_hair};
use glam::{Vec3, Vec4};
use raster::Camera;
use rayon::prelude::*;

/// Rows per band.
const BAND: usize = 16;

fn median(mut t: Vec<f64>) -> f64 {
    t.sort_by(f64::total_cmp);
    t[t.len() / 2]
}

/// Adds the fragments of `segs` in rows `y0..y0 + rows` to `acc`.
fn draw(segs: &[(Vec3, Vec3)], acc: &mut [Vec4], w: usize, y0: usize, rows: usize) {
    let color = Vec4::new(0.3, 0.2, 0.1, 1.0);
    let (y0, y1) = (y0 as i32, (y0 + rows) as i32);
    for &(a, b) in segs {
        let d = b - a;
        let steep = d.y.abs() > d.x.abs();
        let (ua, va, du, dv) = if steep {
            (a.y, a.x, d.y, d.x)
        } else {
            (a.x, a.y, d.x, d.y)
        };
        if du == 0.0 {
            continue;
        }
        let (u0, u1) = if du > 0.0 {
            (ua, ua + du)
        } else {
            (ua + du, ua)
        };
        let m = dv / du;
        let cov = 0.5 * (1.0 + m * m).sqrt();
        // Pixel centres along the major axis, within the band or the row.
        let (lo, hi) = if steep {
            (y0 as f32, y1 as f32)
        } else {
            (0.0, w as f32)
        };
        let first = (u0 - 0.5).max(lo - 1.0) as i32 + 1;
        let last = (u1 - 0.5).min(hi) as i32 + 1;
        for k in first..last {
            let v = va + (k as f32 + 0.5 - ua) * m - 0.5;
            if v < 0.0 {
                continue;
            }
            let r = v as i32;
            let f = v - r as f32;
            for (r, share) in [(r, 1.0 - f), (r + 1, f)] {
                let (x, y) = if steep { (r, k) } else { (k, r) };
                if x < w as i32 && y >= y0 && y < y1 {
                    acc[(y - y0) as usize * w + x as usize] += color * (cov * share);
                }
            }
        }
    }
}

/// Encodes a band's sums to 8-bit pixels, emptying the sums.
fn resolve(acc: &mut [Vec4], img: &mut [u8], lut: &[u8]) {
    for (a, px) in acc.iter_mut().zip(img.chunks_exact_mut(3)) {
        let c = if a.w > 0.0 {
            a.truncate() * a.w.recip()
        } else {
            Vec3::ZERO
        };
        for (p, v) in px.iter_mut().zip(c.to_array()) {
            *p = lut[(v.clamp(0.0, 1.0) * 4096.0) as i32 as usize];
        }
        *a = Vec4::ZERO;
    }
}

fn main() {
    let path = std::env::args()
        .nth(1)
        .unwrap_or_else(|| "scenes/smooth.toml".into());
    let scene = Scene::load(std::path::Path::new(&path)).expect("a scene");
    let hair = build_hair(&scene).expect("hair");
    let (w, h) = (scene.render.width as usize, scene.render.height as usize);
    // Framed as the renderer frames a scene without a camera position,
    // from the hair's bounds alone.
    let b = hair.bounds();
    let size = b.size().max_element();
    let fov = scene.camera.fov_deg;
    let dist = 0.5 * size / (0.5 * fov.to_radians()).tan() + 0.5 * size;
    let eye = b.center() + Vec3::new(0.0, 0.15, 1.0).normalize() * dist;
    let camera = Camera::new(eye, b.center(), fov, w as u32, h as u32).expect("a camera");
    let lut: Vec<u8> = (0..=4096)
        .map(|i| ((i as f32 / 4096.0).powf(1.0 / 2.2) * 255.0 + 0.5) as u8)
        .collect();
    let mut img = vec![0u8; w * h * 3];
    let mut times = [vec![], vec![]];
    let mut fragments = 0.0;
    for (threads, times) in [1, 2].into_iter().zip(&mut times) {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("a thread pool");
        for _ in 0..20 {
            let t0 = Instant::now();
            pool.install(|| {
                let pts: Vec<Option<Vec3>> = hair
                    .points()
                    .par_iter()
                    .map(|&p| camera.project(p))
                    .collect();
                // Segments binned to bands, by chunks of 256 strands in
                // parallel.
                let offsets = hair.offsets();
                let chunks: Vec<Vec<Vec<(Vec3, Vec3)>>> = offsets[..offsets.len() - 1]
                    .par_chunks(256)
                    .enumerate()
                    .map(|(c, starts)| {
                        let mut bins = vec![Vec::new(); h.div_ceil(BAND)];
                        for (s, &start) in starts.iter().enumerate() {
                            let end = offsets[c * 256 + s + 1] as usize;
                            for i in start as usize..end.saturating_sub(1) {
                                let (Some(a), Some(b)) = (pts[i], pts[i + 1]) else {
                                    continue;
                                };
                                let lo = (a.y.min(b.y) - 2.0).clamp(0.0, h as f32 - 1.0) as usize;
                                let hi = (a.y.max(b.y) + 2.0).clamp(0.0, h as f32 - 1.0) as usize;
                                for bin in &mut bins[lo / BAND..=hi / BAND] {
                                    bin.push((a, b));
                                }
                            }
                        }
                        bins
                    })
                    .collect();
                img.par_chunks_mut(BAND * w * 3).enumerate().for_each_init(
                    || vec![Vec4::ZERO; BAND * w],
                    |acc, (band, img)| {
                        let rows = img.len() / (3 * w);
                        for bins in &chunks {
                            draw(&bins[band], acc, w, band * BAND, rows);
                        }
                        resolve(&mut acc[..rows * w], img, &lut);
                    },
                );
                fragments = chunks
                    .iter()
                    .flatten()
                    .flatten()
                    .map(|(a, b)| 2.0 * f64::from((b.x - a.x).abs().max((b.y - a.y).abs())))
                    .sum::<f64>();
            });
            times.push(t0.elapsed().as_secs_f64() * 1e3);
        }
    }
    let lit = img.iter().filter(|&&b| b > 0).count();
    println!(
        "draw floor, {path}: {} segments, about {fragments:.0} fragments, {w}x{h}: \
         1 thread {:.2} ms, 2 threads {:.2} ms (median of 20; {lit} lit channels)",
        hair.segment_count(),
        median(times[0].clone()),
        median(times[1].clone()),
    );
}
