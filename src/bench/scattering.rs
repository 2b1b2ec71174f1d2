//! `bench accuracy --cycles DIR --bounces N`: the light fibers pass on to
//! one another (wisplight's multiple scattering) against Cycles' light
//! bounces, measured as three numbers of a picture pair (direct light
//! alone, and with the scattered light):
//!
//! - the **direct share** per block of 8x8 pixels, `F = sum Y(direct) /
//!   sum Y(all)` (`Y` linear luminance; the blocks that show enough, as for
//!   the shadow ratio, [`raster::ShadowRatios`]), compared block by block;
//! - the **gain** of the whole picture, `sum Y(all) / sum Y(direct)`;
//! - the **colour** of the scattered picture, `sum(R) / sum(G)` and
//!   `sum(B) / sum(G)` over its pixels' linear RGB.
//!
//! The background is black, so the sums are the hair's and the head's.
//!
//! The direct-share error mixes two renderers' differences: in the direct
//! light (the shadow, per block) and in the scattered light. Each block's
//! `F = D / (D + S)` is also taken with one of the two swapped for
//! Cycles' (scaled by the ratio of the two direct lights' sums over the
//! blocks, so that units cancel): with Cycles' `S` the error left is the
//! direct light's part, with Cycles' `D` the scattered light's part.

use std::path::Path;

use anyhow::Context;
use engine::{Scene, Sequence, Stage};
use glam::Vec3;
use image::RgbImage;
use shadow::MethodConfig;

use super::cycles_truth::BLOCK;

/// One picture pair's numbers.
#[derive(Debug, Clone)]
pub(super) struct Light {
    /// Per block, the direct share `F`.
    pub(super) share: raster::ShadowRatios,
    /// `sum Y(all) / sum Y(direct)`.
    pub(super) gain: f64,
    /// `sum(R) / sum(G)` and `sum(B) / sum(G)` of the scattered picture.
    pub(super) color: [f64; 2],
}

impl Light {
    /// The numbers of `direct` and `all` (linear RGB, `w x h`).
    pub(super) fn new(direct: &[Vec3], all: &[Vec3], w: usize, h: usize) -> Light {
        let sum = |px: &[Vec3]| {
            px.iter().fold([0.0f64; 3], |s, p| {
                [
                    s[0] + f64::from(p.x),
                    s[1] + f64::from(p.y),
                    s[2] + f64::from(p.z),
                ]
            })
        };
        let (d, a) = (sum(direct), sum(all));
        // Rec. 709 luminance, as the shadow ratios weigh.
        let total = |s: [f64; 3]| 0.2126 * s[0] + 0.7152 * s[1] + 0.0722 * s[2];
        let ratio = |x: f64, y: f64| if y > 0.0 { x / y } else { f64::NAN };
        Light {
            share: raster::ShadowRatios::new(direct, all, w, h, BLOCK),
            gain: ratio(total(a), total(d)),
            color: [ratio(a[0], a[1]), ratio(a[2], a[1])],
        }
    }
}

/// One setting's scattered light against Cycles'.
#[derive(Debug, Clone, Copy)]
pub(super) struct Against {
    /// The direct shares compared block by block.
    pub(super) share: raster::RatioComparison,
    /// The mean `|F - F_cycles|` with Cycles' scattered light in place of
    /// wisplight's (the direct light's part of the error), and with
    /// Cycles' direct light in place of wisplight's (the scattered
    /// light's part).
    pub(super) parts: (f64, f64),
    /// wisplight's gain and colour ratios.
    pub(super) gain: f64,
    pub(super) color: [f64; 2],
    /// The median time of the shade stage with multiple scattering, ms.
    pub(super) shade_ms: f64,
}

impl Against {
    pub(super) fn new(mine: &Light, cycles: &Light, shade_ms: f64) -> Against {
        Against {
            share: raster::RatioComparison::new(&mine.share, &cycles.share),
            parts: error_parts(mine, cycles),
            gain: mine.gain,
            color: mine.color,
            shade_ms,
        }
    }
}

/// The direct-share error of `mine` against `cycles` with Cycles'
/// scattered light, and with Cycles' direct light, in place of
/// wisplight's (see the module's notes), over the blocks both count.
fn error_parts(mine: &Light, cycles: &Light) -> (f64, f64) {
    let blocks: Vec<((f64, f64), (f64, f64))> = mine
        .share
        .ratio
        .iter()
        .zip(&cycles.share.ratio)
        .zip(mine.share.sums.iter().zip(&cycles.share.sums))
        .filter(|((a, b), _)| a.is_some() && b.is_some())
        // Per block, `sum Y(direct)` and the scattered light, `sum Y(all)`
        // less it (none below 0).
        .map(|(_, (&(dw, aw), &(dc, ac)))| ((dw, (aw - dw).max(0.0)), (dc, (ac - dc).max(0.0))))
        .collect();
    let (dw, dc) = blocks
        .iter()
        .fold((0.0, 0.0), |s, (w, c)| (s.0 + w.0, s.1 + c.0));
    if blocks.is_empty() || dw <= 0.0 || dc <= 0.0 {
        return (f64::NAN, f64::NAN);
    }
    // Cycles' light in wisplight's units.
    let k = dw / dc;
    let share = |d: f64, s: f64| if d + s > 0.0 { d / (d + s) } else { 0.0 };
    let n = blocks.len() as f64;
    let (mut of_direct, mut of_scattered) = (0.0, 0.0);
    for ((d_w, s_w), (d_c, s_c)) in blocks {
        let truth = share(d_c, s_c);
        of_direct += (share(d_w, k * s_c) - truth).abs();
        of_scattered += (share(k * d_c, s_w) - truth).abs();
    }
    (of_direct / n, of_scattered / n)
}

/// One setting's row of the table.
#[derive(Debug, Clone)]
pub(super) struct Measured {
    pub(super) method: &'static str,
    pub(super) parameters: String,
    /// The three shadow stages' median time, ms.
    pub(super) shadow_ms: f64,
    pub(super) against: Against,
}

/// Prints the settings' scattered light beside Cycles' (`samples`
/// samples, `bounces` bounces, rendered in `seconds`).
pub(super) fn print_table(
    rows: &[Measured],
    cycles: &Light,
    seconds: f64,
    samples: u32,
    bounces: u32,
) {
    println!();
    println!(
        "multiple scattering against Cycles with {bounces} bounces (direct share F per 8x8 block, gain = all / direct, colour of all):"
    );
    println!(
        "{:<19} {:<78} {:>9} {:>9} {:>9} {:>9} {:>9} {:>8} {:>8} {:>8} {:>8}",
        "method",
        "parameters",
        "ms",
        "shade_ms",
        "F_error",
        "of_direct",
        "of_scat",
        "F",
        "gain",
        "r/g",
        "b/g"
    );
    for r in rows {
        let s = &r.against;
        println!(
            "{:<19} {:<78} {:>9.2} {:>9.2} {:>9.4} {:>9.4} {:>9.4} {:>8.4} {:>8.4} {:>8.4} {:>8.4}",
            r.method,
            r.parameters,
            r.shadow_ms,
            s.shade_ms,
            s.share.mean_abs,
            s.parts.0,
            s.parts.1,
            s.share.mean,
            s.gain,
            s.color[0],
            s.color[1]
        );
    }
    println!(
        "{:<19} {:<78} {:>9.0} {:>9} {:>9} {:>9} {:>9} {:>8.4} {:>8.4} {:>8.4} {:>8.4}",
        "cycles",
        format!("samples={samples} bounces={bounces}"),
        1e3 * seconds,
        "-",
        "0",
        "0",
        "0",
        cycles.share.mean(),
        cycles.gain,
        cycles.color[0],
        cycles.color[1]
    );
}

/// The scene's first frame with `config` and multiple scattering,
/// rendered `runs` times: the median time of its shade stage, and the
/// last picture in linear RGB, unclamped (light hair with its scattered
/// light is brighter than an 8-bit picture holds).
pub(super) fn measure(
    scene: &Scene,
    config: MethodConfig,
    runs: usize,
) -> anyhow::Result<(f64, Vec<Vec3>)> {
    let mut s = scene.clone();
    s.shadow.method = config;
    s.effects.self_shadow = true;
    s.effects.multiple_scattering = true;
    s.animation.motion = sim::Motion::Still;
    let mut seq = Sequence::new(&s)?;
    let mut times = Vec::with_capacity(runs);
    for _ in 0..runs {
        let (_, stats) = seq
            .again()
            .with_context(|| format!("cannot render with {}", config.name()))?;
        times.push(stats.stage(Stage::Shade).ms);
    }
    let px = seq
        .renderer()
        .linear_picture()
        .context("no picture drawn")?;
    Ok((
        crate::cmd::median(&mut times),
        px.iter().map(|p| p.truncate()).collect(),
    ))
}

/// Cycles' picture of the frame exported in `dir` with `bounces` light
/// bounces (`cycles-bounces{N}.exr`), rendered unless `dir` holds it for
/// the same export (`fresh` false), and the seconds it took.
pub(super) fn cycles_bounced(
    blender: &Path,
    dir: &Path,
    samples: u32,
    bounces: u32,
    fresh: bool,
    size: (u32, u32),
) -> anyhow::Result<(Vec<Vec3>, f64)> {
    let out = dir.join(format!("cycles-bounces{bounces}.exr"));
    let stamp = dir.join(format!("cycles-bounces{bounces}-time.json"));
    let kept = (!fresh && out.is_file())
        .then(|| std::fs::read(&stamp).ok())
        .flatten()
        .and_then(|b| serde_json::from_slice::<f64>(&b).ok());
    let seconds = match kept {
        Some(t) => t,
        None => {
            eprintln!(
                "rendering {} in Cycles ({samples} samples, {bounces} bounces)...",
                out.display()
            );
            let t = crate::cycles::render(
                blender,
                dir,
                &out,
                crate::cycles::CyclesRun {
                    unshadowed: false,
                    samples,
                    bounces,
                    threads: rayon::current_num_threads(),
                },
            )?;
            crate::output::write_bytes(&stamp, format!("{t}\n").as_bytes())?;
            t
        }
    };
    let (w, h, px) = crate::cycles::read_exr(&out)?;
    if (w, h) != size {
        anyhow::bail!(
            "{} is {w}x{h}, not the scene's {}x{}",
            out.display(),
            size.0,
            size.1
        );
    }
    // To look at beside wisplight's without an OpenEXR viewer.
    let png = dir.join(format!("cycles-bounces{bounces}.png"));
    write_png(&png, &px, w as usize, h as usize)?;
    Ok((px, seconds))
}

/// A linear picture of `w x h` pixels as 8-bit sRGB PNG, encoded as
/// wisplight encodes its own.
pub(super) fn write_png(path: &Path, px: &[Vec3], w: usize, h: usize) -> anyhow::Result<()> {
    let bytes = px.iter().flat_map(|&c| raster::to_srgb8(c)).collect();
    let img = RgbImage::from_raw(w as u32, h as u32, bytes).context("one RGB pixel each")?;
    crate::output::write_png(path, &img)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gain_and_colour_come_from_the_pictures_sums() {
        // 8x8 pixels: direct light grey 0.1; scattered adds (0.2, 0.1, 0.0)
        // on the left half only.
        let direct = vec![Vec3::splat(0.1); 64];
        let all: Vec<Vec3> = (0..64)
            .map(|i| {
                if i % 8 < 4 {
                    Vec3::new(0.3, 0.2, 0.1)
                } else {
                    Vec3::splat(0.1)
                }
            })
            .collect();
        let l = Light::new(&direct, &all, 8, 8);
        // Luminance sums: direct 64 * 0.1 = 6.4; all 32 * Y(0.3, 0.2, 0.1)
        // + 32 * 0.1, Y(0.3, 0.2, 0.1) = 0.06378 + 0.14304 + 0.00722.
        let y_all = 32.0 * 0.21404 + 3.2;
        assert!((l.gain - y_all / 6.4).abs() < 1e-5, "{}", l.gain);
        // R: 32 * 0.3 + 32 * 0.1 = 12.8; G: 32 * 0.2 + 3.2 = 9.6; B: 6.4.
        assert!((l.color[0] - 12.8 / 9.6).abs() < 1e-6, "{:?}", l.color);
        assert!((l.color[1] - 6.4 / 9.6).abs() < 1e-6, "{:?}", l.color);
        // One block: its direct share is the inverse of the gain.
        let f = l.share.ratio[0].unwrap();
        assert!((f64::from(f) - 6.4 / y_all).abs() < 1e-5, "{f}");
    }

    #[test]
    fn the_error_splits_into_the_direct_lights_part_and_the_scattered_lights() {
        // Four 8x8 blocks, 16 x 16 pixels, each block one grey level.
        let px = |v: [f32; 4]| -> Vec<Vec3> {
            (0..256)
                .map(|i| Vec3::splat(v[(i / 16 / 8) * 2 + (i % 16) / 8]))
                .collect()
        };
        // Cycles: direct 1, 2, 3, 4 and scattered 1 in every block.
        let cd = [1.0, 2.0, 3.0, 4.0];
        let cycles = Light::new(&px(cd), &px(cd.map(|d| d + 1.0)), 16, 16);
        // The same direct light, the scattered light twice Cycles': all of
        // the error is the scattered light's.
        let twice = Light::new(&px(cd), &px(cd.map(|d| d + 2.0)), 16, 16);
        let a = Against::new(&twice, &cycles, 0.0);
        assert!(a.share.mean_abs > 0.05, "{a:?}");
        assert!(a.parts.0 < 1e-9, "{a:?}");
        assert!((a.parts.1 - a.share.mean_abs).abs() < 1e-6, "{a:?}");
        // The same scattered light, the direct light off block by block
        // (its sum the same: the units stay): all of it is the direct
        // light's.
        let wd = [2.0, 1.0, 4.0, 3.0];
        let moved = Light::new(&px(wd), &px(wd.map(|d| d + 1.0)), 16, 16);
        let b = Against::new(&moved, &cycles, 0.0);
        assert!(b.share.mean_abs > 0.05, "{b:?}");
        assert!(b.parts.1 < 1e-9, "{b:?}");
        assert!((b.parts.0 - b.share.mean_abs).abs() < 1e-6, "{b:?}");
        // Direct: 1/2 vs 2/3 and so on; worked out by hand for block 0:
        // F = 2 / 3 against Cycles' 1 / 2.
        let f0 = f64::from(moved.share.ratio[0].unwrap());
        assert!((f0 - 2.0 / 3.0).abs() < 1e-6, "{f0}");
    }
}
