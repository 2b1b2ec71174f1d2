//! `wisplight export`: a frame of a scene as files Blender Cycles renders.

use std::path::PathBuf;

use anyhow::Context;
use engine::Sequence;

#[derive(Debug, clap::Args)]
pub struct Args {
    /// Scene file (TOML); the built-in scene when omitted.
    scene: Option<PathBuf>,
    /// Directory to write the frame into, for Blender: scene.py,
    /// scene.json, strands.bin and head.bin (created if missing; files of
    /// an earlier export there are replaced). Render it with
    /// `blender -b -noaudio --python DIR/scene.py`, which writes
    /// DIR/cycles.exr (`-- --help` for its options).
    #[arg(long, value_name = "DIR")]
    blender: PathBuf,
    /// The frame to export, from 0: the hair as simulated and posed then.
    #[arg(long, default_value_t = 0, value_name = "N",
          value_parser = clap::value_parser!(u64).range(0..=1_000_000))]
    frame: u64,
    /// Cycles samples per pixel the script renders with by default.
    #[arg(long, default_value_t = 128, value_name = "N",
          value_parser = clap::value_parser!(u32).range(1..=65_536))]
    samples: u32,
    #[command(flatten)]
    method: super::MethodArg,
    #[command(flatten)]
    pub threads: super::Threads,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let mut scene = super::load_scene(args.scene.as_deref())?;
    args.method.apply(&mut scene);
    // The directory first: a render that cannot be saved does not start.
    std::fs::create_dir_all(&args.blender)
        .with_context(|| format!("cannot create {}", args.blender.display()))?;
    let mut seq = Sequence::new(&scene).context("cannot set up the scene")?;
    let bar = super::progress_bar(args.frame + 1, "{bar:30} frame {pos}/{len} [{elapsed}]");
    for i in 0..=args.frame {
        seq.next_frame()
            .with_context(|| format!("cannot render frame {i}"))?;
        bar.inc(1);
    }
    bar.finish_and_clear();
    let export = engine::cycles_export(&seq, args.samples).context("cannot export the frame")?;
    let script = crate::cycles::write_export(&args.blender, &export)?;
    super::say!(
        "exported frame {} ({} strands, {} points) to {}; render it with: blender -b -noaudio --python {}",
        args.frame,
        export.strands,
        export.points,
        args.blender.display(),
        script.display()
    );
    Ok(())
}
