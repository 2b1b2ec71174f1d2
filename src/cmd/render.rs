//! `wisplight render`: a self-shadowed picture of a scene.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Context;
use engine::Renderer;

#[derive(Debug, clap::Args)]
pub struct Args {
    /// Scene file (TOML); the built-in scene (the smooth style on a head)
    /// when omitted.
    scene: Option<PathBuf>,
    /// Output PNG. Written to a temporary file first, then renamed: the
    /// file appears whole or not at all.
    #[arg(short, long, value_name = "OUT.png", default_value = "wisplight.png")]
    output: PathBuf,
    /// Render the same frame without any shadow, for comparison.
    #[arg(long)]
    no_shadow: bool,
    #[command(flatten)]
    method: super::MethodArg,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let start = Instant::now();
    let mut scene = super::load_scene(args.scene.as_deref())?;
    args.method.apply(&mut scene);
    let hair = super::build_hair(&scene)?;
    let mut renderer = Renderer::new(&scene)?;
    let (img, times) = renderer
        .render(&hair, !args.no_shadow)
        .context("cannot render")?;
    raster::write_png_atomic(&img, &args.output).context("cannot save the picture")?;
    eprintln!(
        "wrote {} ({}x{}, {} segments, {}, frame {:.1} ms, {:.0} ms in all)",
        args.output.display(),
        img.width(),
        img.height(),
        hair.segment_count(),
        if args.no_shadow {
            "no shadows"
        } else {
            "self-shadowed"
        },
        times.total_ms(),
        start.elapsed().as_secs_f64() * 1e3
    );
    Ok(())
}
