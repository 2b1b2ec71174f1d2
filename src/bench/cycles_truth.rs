//! Blender Cycles' picture of a scene's first frame as the truth `bench
//! accuracy --cycles` compares with: the frame exported, rendered with
//! and without shadows (or reused), read back, and the shadow ratios of
//! its blocks.

use std::path::Path;

use anyhow::Context;
use engine::{Scene, Sequence};
use image::RgbImage;

/// Pixels a side of the blocks whose shadow ratio is compared with
/// Cycles'.
pub(super) const BLOCK: usize = 8;
/// With `--cycles DIR`: the exact reference's picture and the picture
/// without shadows that the ratios come from (direct light, 8-bit sRGB),
/// to set beside Cycles' `cycles.exr` and `cycles-unshadowed.exr`.
pub(super) const REFERENCE_PNG: &str = "wisplight-reference.png";
pub(super) const UNSHADOWED_PNG: &str = "wisplight-unshadowed.png";
/// Cycles' `cycles.exr` and `cycles-unshadowed.exr` as 8-bit sRGB.
pub(super) const CYCLES_PNG: &str = "cycles.png";
pub(super) const CYCLES_UNSHADOWED_PNG: &str = "cycles-unshadowed.png";

/// The scene as both renderers are compared: direct light only (no
/// ambient term, no multiple scattering) over a black background. Against
/// Cycles (`physical`), hair shaded with Kajiya-Kay is shaded with the
/// physically based fiber of its colour instead, the fiber Cycles is
/// given: Kajiya-Kay weighs lit and shadowed fibers otherwise (a block's
/// ratio is a weighted mean of its fibers' transmittance), which left
/// the exact reference 0.02 further from Cycles on the smooth style.
pub(super) fn direct_light(scene: &Scene, physical: bool) -> Scene {
    let mut s = scene.clone();
    s.shading.ambient = 0.0;
    s.effects.multiple_scattering = false;
    s.render.background = glam::Vec3::ZERO;
    if physical && s.shading.model == raster::ShadingModel::KajiyaKay {
        s.shading.model = raster::ShadingModel::Marschner {
            optics: raster::FiberOptics::default(),
            from_color: true,
            irradiance: 1.0,
            multiple: false,
        };
    }
    s
}

/// An 8-bit sRGB picture in linear RGB.
pub(super) fn linear(img: &RgbImage) -> Vec<glam::Vec3> {
    let lut: Vec<f32> = (0..=255u8).map(raster::srgb8_to_linear).collect();
    img.pixels()
        .map(|p| {
            glam::Vec3::new(
                lut[p.0[0] as usize],
                lut[p.0[1] as usize],
                lut[p.0[2] as usize],
            )
        })
        .collect()
}

/// Shadow ratios side by side, a block a 4x4 square, grey from black (0)
/// to white (1); red where a block does not count.
pub(super) fn ratio_picture(all: &[&raster::ShadowRatios]) -> RgbImage {
    const PX: u32 = 4;
    let (cols, rows) = (all[0].cols as u32, all[0].rows as u32);
    let gap = 2;
    let w = all.len() as u32 * (cols * PX + gap);
    let mut img = RgbImage::new(w, rows * PX);
    for (i, r) in all.iter().enumerate() {
        for (b, v) in r.ratio.iter().enumerate() {
            let (bx, by) = (b as u32 % cols, b as u32 / cols);
            let px = match v {
                Some(v) => {
                    let g = raster::to_srgb8(glam::Vec3::splat(v.clamp(0.0, 1.0)))[0];
                    image::Rgb([g, g, g])
                }
                None => image::Rgb([60, 0, 0]),
            };
            for dy in 0..PX {
                for dx in 0..PX {
                    let x = i as u32 * (cols * PX + gap) + bx * PX + dx;
                    img.put_pixel(x, by * PX + dy, px);
                }
            }
        }
    }
    img
}

/// Cycles' shadow ratios of the scene's first frame, and the seconds its
/// two renders took.
pub(super) struct Truth {
    pub(super) ratios: raster::ShadowRatios,
    pub(super) seconds: (f64, f64),
    /// Cycles' shadowed picture (direct light), linear.
    pub(super) lit: Vec<glam::Vec3>,
    /// Whether the frame was exported anew (pictures of an older export
    /// are stale).
    pub(super) fresh: bool,
}

/// Exports the scene's first frame at rest into `dir`, renders it in
/// Cycles with and without shadows (unless `dir` holds those pictures of
/// the same frame at the same samples already) and reads them back.
pub(super) fn cycles_truth(
    scene: &Scene,
    blender: &Path,
    dir: &Path,
    samples: u32,
) -> anyhow::Result<Truth> {
    let mut s = scene.clone();
    s.animation.motion = sim::Motion::Still;
    s.effects.self_shadow = true;
    let mut seq = Sequence::new(&s)?;
    seq.again().context("cannot render the frame to export")?;
    let export = engine::cycles_export(&seq, samples)?;
    let json = &export
        .files
        .iter()
        .find(|f| f.0 == "scene.json")
        .expect("an export has scene.json")
        .1;
    let shadowed = dir.join("cycles.exr");
    let unshadowed = dir.join("cycles-unshadowed.exr");
    let stamp = dir.join("cycles-times.json");
    let same = std::fs::read(dir.join("scene.json")).is_ok_and(|old| &old == json)
        && std::fs::read(dir.join("scene.py")).is_ok_and(|p| p == engine::CYCLES_SCRIPT.as_bytes());
    let kept: Option<(f64, f64)> = same
        .then(|| std::fs::read(&stamp).ok())
        .flatten()
        .and_then(|b| serde_json::from_slice::<Vec<f64>>(&b).ok())
        .filter(|t| t.len() == 2 && shadowed.is_file() && unshadowed.is_file())
        .map(|t| (t[0], t[1]));
    let seconds = match kept {
        Some(t) => {
            eprintln!(
                "reusing Cycles' pictures of this frame in {}",
                dir.display()
            );
            t
        }
        None => {
            crate::cycles::write_export(dir, &export)?;
            let run = |unshadowed: bool, out: &Path| {
                eprintln!(
                    "rendering {} in Cycles ({samples} samples{})...",
                    out.display(),
                    if unshadowed { ", no shadows" } else { "" }
                );
                crate::cycles::render(
                    blender,
                    dir,
                    out,
                    crate::cycles::CyclesRun {
                        unshadowed,
                        samples,
                        bounces: 0,
                        threads: rayon::current_num_threads(),
                    },
                )
            };
            let t = (run(false, &shadowed)?, run(true, &unshadowed)?);
            crate::output::write_bytes(&stamp, format!("[{}, {}]\n", t.0, t.1).as_bytes())?;
            t
        }
    };
    let (w, h, lit) = crate::cycles::read_exr(&shadowed)?;
    let (w2, h2, unlit) = crate::cycles::read_exr(&unshadowed)?;
    let (cw, ch) = (s.render.width, s.render.height);
    if (w, h) != (cw, ch) || (w2, h2) != (cw, ch) {
        anyhow::bail!(
            "Cycles' pictures in {} are {w}x{h} and {w2}x{h2}, not the scene's {cw}x{ch}",
            dir.display()
        );
    }
    // Cycles' pictures as 8-bit sRGB too, encoded as wisplight's are, to
    // look at beside wisplight's without an OpenEXR viewer.
    for (name, px) in [(CYCLES_PNG, &lit), (CYCLES_UNSHADOWED_PNG, &unlit)] {
        let bytes = px.iter().flat_map(|&c| raster::to_srgb8(c)).collect();
        let img = RgbImage::from_raw(w, h, bytes).expect("one RGB pixel each");
        crate::output::write_png(&dir.join(name), &img)?;
    }
    Ok(Truth {
        ratios: raster::ShadowRatios::new(&lit, &unlit, w as usize, h as usize, BLOCK),
        seconds,
        lit,
        fresh: kept.is_none(),
    })
}
