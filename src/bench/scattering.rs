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
            gain: mine.gain,
            color: mine.color,
            shade_ms,
        }
    }
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
        "{:<19} {:<78} {:>9} {:>9} {:>9} {:>8} {:>8} {:>8} {:>8}",
        "method", "parameters", "ms", "shade_ms", "F_error", "F", "gain", "r/g", "b/g"
    );
    for r in rows {
        let s = &r.against;
        println!(
            "{:<19} {:<78} {:>9.2} {:>9.2} {:>9.4} {:>8.4} {:>8.4} {:>8.4} {:>8.4}",
            r.method,
            r.parameters,
            r.shadow_ms,
            s.shade_ms,
            s.share.mean_abs,
            s.share.mean,
            s.gain,
            s.color[0],
            s.color[1]
        );
    }
    println!(
        "{:<19} {:<78} {:>9.0} {:>9} {:>9} {:>8.4} {:>8.4} {:>8.4} {:>8.4}",
        "cycles",
        format!("samples={samples} bounces={bounces}"),
        1e3 * seconds,
        "-",
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
}
