//! OpenEXR output of `render`: the beauty as linear float RGBA (the
//! background left out, so the colour is premultiplied by alpha) and, with
//! `--passes`, the frame's light apart and its depth, as layers of the same
//! file (channels `direct.R`, `direct.G`, ..., `depth.Z`: the names
//! compositors read as layers).
//!
//! The light passes add up to the beauty: `direct + scattered + sky`.
//! - `direct`: the lights' light that reached the hair and head without
//!   meeting a fiber, shadowed, shaded once;
//! - `scattered`: what the fibers pass on to one another of the lights'
//!   light (`[effects] multiple_scattering`; zero without it);
//! - `sky`: light from no source (`[shading] ambient`), all of it: what
//!   the fibers pass on of it and the head sends back of it too;
//! - `shadow` (not part of the sum): the direct light the shadows took,
//!   the direct pass rendered without shadows less the direct pass;
//! - `depth`: the view depth of the nearest surface (scene units), 1e10
//!   where nothing is drawn (as Cycles writes it).
//!
//! The passes are the same frame rendered again with the scene's terms
//! turned off in turn ([`engine::Sequence::set_scene`] and
//! [`engine::Sequence::again`]): each costs about a frame's shadows,
//! shading and drawing.

use anyhow::Context;
use engine::{Scene, Sequence};
use exr::prelude::{AnyChannel, AnyChannels, Encoding, FlatSamples, Image, Layer, SmallVec};
use exr::prelude::{LayerAttributes, WritableImage};
use glam::{Vec3, Vec4};

/// The depth written where nothing is drawn.
const NO_DEPTH: f32 = 1e10;

/// A pass `--passes` may ask for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Pass {
    /// The lights' light, shadowed, shaded once.
    Direct,
    /// What the fibers pass on to one another of the lights' light.
    Scattered,
    /// Light from no source (the ambient term), all of it.
    Sky,
    /// The direct light the shadows took.
    Shadow,
    /// The view depth of the nearest surface.
    Depth,
}

impl Pass {
    fn name(self) -> &'static str {
        match self {
            Pass::Direct => "direct",
            Pass::Scattered => "scattered",
            Pass::Sky => "sky",
            Pass::Shadow => "shadow",
            Pass::Depth => "depth",
        }
    }
}

/// Whether `passes` render the frame again (the light passes; depth comes
/// with the beauty).
pub fn renders_again(passes: &[Pass]) -> bool {
    passes.iter().any(|&p| p != Pass::Depth)
}

/// The last frame of `seq` (rendered with `scene`) as an OpenEXR file's
/// bytes, with `passes`. The sequence is left rendering with `scene`.
pub fn frame(seq: &mut Sequence, scene: &Scene, passes: &[Pass]) -> anyhow::Result<Vec<u8>> {
    let (w, h) = (scene.render.width as usize, scene.render.height as usize);
    let asked = |p: Pass| passes.contains(&p);
    // The beauty, and its depth in the same pass when asked.
    let (beauty, depth) = if asked(Pass::Depth) {
        let (beauty, depth) = seq
            .renderer()
            .linear_picture_and_depth(Vec3::ZERO)
            .context("no picture was drawn in this process")?;
        (beauty, Some(depth))
    } else {
        (linear(seq)?, None)
    };
    let mut channels: Vec<AnyChannel<FlatSamples>> = Vec::new();
    rgba(&mut channels, "", &beauty, true);
    if let Some(depth) = depth {
        let z = depth
            .iter()
            .map(|&z| if z.is_finite() { z } else { NO_DEPTH })
            .collect();
        channels.push(AnyChannel::new("depth.Z", FlatSamples::F32(z)));
    }
    let light = [Pass::Direct, Pass::Scattered, Pass::Sky, Pass::Shadow];
    if light.iter().any(|&p| asked(p)) {
        // The direct light alone: no scattering, no sky.
        let mut direct_scene = scene.clone();
        direct_scene.effects.multiple_scattering = false;
        direct_scene.shading.ambient = 0.0;
        // A pass of the scene itself is the beauty: not rendered again.
        let mut render = |s: &Scene| -> anyhow::Result<Vec<Vec4>> {
            if s == scene {
                Ok(beauty.clone())
            } else {
                again(seq, s)
            }
        };
        let direct = render(&direct_scene)?;
        // The sky's share: the beauty less the same frame without it
        // (which, without multiple scattering, is the direct light).
        let sky = if scene.shading.ambient > 0.0 && (asked(Pass::Sky) || asked(Pass::Scattered)) {
            let mut s = scene.clone();
            s.shading.ambient = 0.0;
            let rendered;
            let without: &[Vec4] = if s == direct_scene {
                &direct
            } else {
                rendered = render(&s)?;
                &rendered
            };
            beauty.iter().zip(without).map(|(a, b)| *a - *b).collect()
        } else {
            vec![Vec4::ZERO; w * h]
        };
        // Scattered: the rest of the beauty, so that the passes add up.
        let scattered: Vec<Vec4> = if scene.effects.multiple_scattering && asked(Pass::Scattered) {
            beauty
                .iter()
                .zip(&direct)
                .zip(&sky)
                .map(|((b, d), s)| *b - *d - *s)
                .collect()
        } else {
            vec![Vec4::ZERO; w * h]
        };
        if asked(Pass::Shadow) {
            let mut s = direct_scene.clone();
            s.effects.self_shadow = false;
            let lit = render(&s)?;
            let took: Vec<Vec4> = lit.iter().zip(&direct).map(|(l, d)| *l - *d).collect();
            rgba(&mut channels, Pass::Shadow.name(), &took, false);
        }
        for (p, px) in [
            (Pass::Direct, &direct),
            (Pass::Scattered, &scattered),
            (Pass::Sky, &sky),
        ] {
            if asked(p) {
                rgba(&mut channels, p.name(), px, false);
            }
        }
        // Back to the scene for the frames to come.
        if seq.scene() != scene {
            seq.set_scene(scene)
                .context("cannot render the next frame")?;
        }
    }
    let layer = Layer::new(
        (w, h),
        LayerAttributes::default(),
        Encoding::FAST_LOSSLESS,
        AnyChannels::sort(SmallVec::from_vec(channels)),
    );
    let mut out = std::io::Cursor::new(Vec::new());
    Image::from_layer(layer)
        .write()
        .to_buffered(&mut out)
        .context("cannot encode the OpenEXR picture")?;
    Ok(out.into_inner())
}

/// The channels `NAME.R`, `NAME.G`, `NAME.B` (and `NAME.A` with `alpha`)
/// of `px`; `R`, `G`, ... for the unnamed beauty.
fn rgba(channels: &mut Vec<AnyChannel<FlatSamples>>, name: &str, px: &[Vec4], alpha: bool) {
    let prefix = if name.is_empty() {
        String::new()
    } else {
        format!("{name}.")
    };
    let names = if alpha {
        &["R", "G", "B", "A"][..]
    } else {
        &["R", "G", "B"][..]
    };
    for (k, c) in names.iter().enumerate() {
        let samples = px.iter().map(|p| p[k]).collect();
        channels.push(AnyChannel::new(
            format!("{prefix}{c}").as_str(),
            FlatSamples::F32(samples),
        ));
    }
}

/// The last picture drawn, linear, over nothing.
fn linear(seq: &Sequence) -> anyhow::Result<Vec<Vec4>> {
    seq.renderer()
        .linear_picture_over(Vec3::ZERO)
        .context("no picture was drawn in this process")
}

/// The last frame rendered again with `scene`'s shading and effects.
fn again(seq: &mut Sequence, scene: &Scene) -> anyhow::Result<Vec<Vec4>> {
    seq.set_scene(scene).context("cannot render a pass")?;
    seq.again().context("cannot render a pass")?;
    linear(seq)
}
