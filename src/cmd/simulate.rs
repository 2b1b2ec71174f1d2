//! `wisplight simulate`: the wisps' state after each frame's steps, one
//! file a frame, so that a farm renders any chunk of frames alone
//! (`render --cache DIR --frames A..B`).

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;
use engine::{Sequence, cache};

use super::FrameRange;

#[derive(Debug, clap::Args)]
pub struct Args {
    /// Scene file (TOML); the built-in scene when omitted. Its hair must
    /// be simulated (a style with `effects.dynamics` on).
    scene: Option<PathBuf>,
    /// The cache folder (created when missing): one file a frame,
    /// `frame_000000.wlsim`, each written whole or not at all.
    #[arg(short, long, value_name = "DIR")]
    output: PathBuf,
    /// Frames to simulate and write: `N` for 0 to N-1, `A..B` for A to
    /// B-1, `A..=B` for A to B (the frames before A are simulated, not
    /// written).
    #[arg(long, default_value = "1", value_name = "N|A..B",
          value_parser = FrameRange::parse)]
    frames: FrameRange,
    /// Simulate the scene as `render --no-shadow` renders it (the
    /// self-collision map then is a map of its own): a cache is made for
    /// the scene, and the flags, its render gives.
    #[arg(long)]
    no_shadow: bool,
    #[command(flatten)]
    method: super::MethodArg,
    #[command(flatten)]
    pub threads: super::Threads,
}

/// A simulation cache folder for one scene.
#[derive(Debug)]
pub struct CacheDir {
    dir: PathBuf,
    /// [`cache::scene_hash`] of the scene.
    hash: u64,
    wisps: usize,
    per: usize,
}

impl CacheDir {
    /// The cache in `dir` of the scene `seq` renders. `None` when the
    /// scene's hair is not simulated.
    pub fn new(dir: &Path, seq: &Sequence) -> Option<CacheDir> {
        let states = seq.wisp_states()?;
        Some(CacheDir {
            dir: dir.to_path_buf(),
            hash: cache::scene_hash(seq.scene()),
            wisps: states.len(),
            per: states.first().map_or(0, |s| s.pos.len()),
        })
    }

    /// Frame `frame`'s file.
    pub fn path(&self, frame: u64) -> PathBuf {
        self.dir.join(cache::file_name(frame))
    }

    /// Whether frame `frame` is in the cache (a file by its name).
    pub fn has(&self, frame: u64) -> bool {
        self.path(frame).is_file()
    }

    /// Frame `frame`'s wisps, checked whole; the error names the file.
    pub fn read(&self, frame: u64) -> anyhow::Result<Vec<sim::WispState>> {
        let path = self.path(frame);
        let cannot = || format!("{}: cannot use this cache file", path.display());
        // The file's size follows from the scene: a larger one is not read
        // whole, but its header may say why it is larger (another scene).
        let cap = (self.wisps * self.per * 24 + 4096) as u64;
        let bytes = match strands::read_capped(&path, cap) {
            Ok(b) => b,
            Err(e) => {
                if let Some(head) = file_head(&path)
                    && let Err(
                        why @ (cache::CacheError::Version { .. }
                        | cache::CacheError::Scene { .. }
                        | cache::CacheError::Frame { .. }
                        | cache::CacheError::Shape { .. }),
                    ) = cache::decode(&head, self.hash, frame, self.wisps, self.per)
                {
                    return Err(anyhow::Error::new(why).context(cannot()));
                }
                return Err(anyhow::Error::new(e).context(format!(
                    "cannot read the simulation cache's frame {frame}, {} (`wisplight \
                     simulate` writes it)",
                    path.display()
                )));
            }
        };
        cache::decode(&bytes, self.hash, frame, self.wisps, self.per).with_context(cannot)
    }

    /// Writes frame `frame`'s wisps, whole or not at all.
    fn write(&self, frame: u64, states: &[sim::WispState]) -> anyhow::Result<u64> {
        let bytes = cache::encode(self.hash, frame, states);
        crate::output::write_bytes(&self.path(frame), &bytes)
            .context("cannot write the simulation cache")?;
        Ok(bytes.len() as u64)
    }
}

/// The first 4 KiB of the regular file at `path`, if it is one.
fn file_head(path: &Path) -> Option<Vec<u8>> {
    use std::io::Read;
    let file = std::fs::File::open(path).ok()?;
    if !file.metadata().ok()?.is_file() {
        return None;
    }
    let mut head = Vec::with_capacity(4096);
    file.take(4096).read_to_end(&mut head).ok()?;
    Some(head)
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let start = Instant::now();
    let mut scene = super::load_scene(args.scene.as_deref())?;
    args.method.apply(&mut scene);
    if args.no_shadow {
        scene.effects.self_shadow = false;
    }
    let mut seq = Sequence::new(&scene).context("cannot set up the scene")?;
    let Some(dir) = CacheDir::new(&args.output, &seq) else {
        return Err(super::usage(
            "the scene's hair is not simulated (a groom file, or effects.dynamics off): \
             each of its frames follows from the scene alone, and `render --frames A..B` \
             renders any range without a cache",
        ));
    };
    std::fs::create_dir_all(&args.output)
        .with_context(|| format!("-o {}: cannot create the folder", args.output.display()))?;
    let range = args.frames;
    let bar = super::progress_bar(range.end, "{bar:30} frame {pos}/{len} [{elapsed} < {eta}]");
    let (mut bytes, mut sim_ms) = (0u64, Vec::with_capacity(range.end.min(100_000) as usize));
    for frame in 0..range.end {
        let t = Instant::now();
        seq.skip_frame()
            .with_context(|| format!("cannot simulate frame {frame}"))?;
        sim_ms.push(t.elapsed().as_secs_f64() * 1e3);
        if frame >= range.start {
            let states = seq.wisp_states().expect("simulated hair has wisps");
            bytes = dir.write(frame, &states)?;
        }
        bar.inc(1);
    }
    bar.finish_and_clear();
    super::say!(
        "wrote {} .. {} ({} frames of {} wisps, {:.1} KiB a frame, median frame {:.1} ms \
         simulated, {:.0} ms in all)",
        dir.path(range.start).display(),
        dir.path(range.end - 1).display(),
        range.count(),
        dir.wisps,
        bytes as f64 / 1024.0,
        super::median(&mut sim_ms),
        start.elapsed().as_secs_f64() * 1e3
    );
    Ok(())
}
