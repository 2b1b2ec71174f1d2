//! `wisplight render`: a self-shadowed picture of a scene, or a sequence of
//! frames of its animation.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;
use engine::{FrameStats, Sequence};

use crate::output::AtomicFile;

#[derive(Debug, clap::Args)]
pub struct Args {
    /// Scene file (TOML), or a groom file (.hair, .tfx, .data, .bin, .ply,
    /// Alembic .abc, USD .usd/.usda/.usdc/.usdz; an animated cache plays,
    /// frame k its sample k) to render at the defaults; the built-in scene
    /// (the smooth style, parted, on a dancing head with a face, seen from
    /// three quarters) when omitted.
    scene: Option<PathBuf>,
    /// Output: a PNG (default `wisplight.png`); for several frames a
    /// pattern with `%d` or `%04d` for the frame number (default
    /// `wisplight_%04d.png`; its directory is created); or a `.gif` for one
    /// animated GIF; or `.exr` (one file, or a pattern; from a coordinator
    /// too, which then draws the frames itself) for OpenEXR: linear
    /// float RGBA, alpha the head's and the hair's coverage, the
    /// background left out (colour premultiplied by alpha, to put over any
    /// plate). Every file is written to a temporary file first, then
    /// renamed: it appears whole or not at all.
    #[arg(short, long, value_name = "OUT")]
    output: Option<PathBuf>,
    /// Frames to render at the scene's `animation.fps`: `N` for frames 0
    /// to N-1, `A..B` for A to B-1, `A..=B` for A to B. Frame k is the
    /// same picture whatever range is rendered; without `--cache`, the
    /// frames before A are simulated (not drawn) first.
    #[arg(long, default_value = "1", value_name = "N|A..B",
          value_parser = super::FrameRange::parse)]
    frames: super::FrameRange,
    /// A simulation cache (`wisplight simulate SCENE -o DIR`) of this
    /// scene: the range starts from the wisps the cache holds for its
    /// first frame, with no warm-up, and in one process each later frame
    /// takes its wisps from the cache too. A cache of another scene or
    /// another wisplight is refused.
    #[arg(long, value_name = "DIR")]
    cache: Option<PathBuf>,
    /// Write what every stage of every frame did, as JSON:
    /// {"frames": [{"index": 0, "stages": {"simulate": {"ran": true, "ms": 1.2}, ...}}]}.
    #[arg(long, value_name = "FILE.json")]
    stats: Option<PathBuf>,
    /// Render without any shadow (the scene's `effects.self_shadow` off), for comparison.
    #[arg(long)]
    no_shadow: bool,
    /// With an `.exr` output: also write these passes as layers of each
    /// file. The light passes add up to the beauty (direct + scattered +
    /// sky); shadow is the direct light the shadows took; depth the view
    /// depth of the nearest surface (`depth.Z`). Each light pass renders
    /// the frame again.
    #[arg(long, value_delimiter = ',', value_name = "PASS,...")]
    passes: Vec<super::exr::Pass>,
    #[command(flatten)]
    method: super::MethodArg,
    #[command(flatten)]
    pub threads: super::Threads,
}

/// Where the frames go.
enum Output {
    /// One PNG per frame, named by the pattern.
    Pngs(Pattern),
    /// One OpenEXR per frame, named by the pattern.
    Exrs(Pattern),
    Gif(raster::GifWriter<AtomicFile>, PathBuf),
}

pub fn run(args: Args) -> anyhow::Result<()> {
    run_with(args, None)
}

/// Cluster mode: the workers, and how the coordinator runs them.
#[derive(Debug)]
pub struct Remote {
    pub workers: Vec<String>,
    pub options: cluster::Options,
}

/// `render`, or with `remote` the same frames with the density map filled
/// and swept by cluster workers (the coordinator).
pub fn run_with(args: Args, mut remote: Option<Remote>) -> anyhow::Result<()> {
    let start = Instant::now();
    // A single frame says what it does once it takes a second; frames
    // have their progress bar.
    let spinner = (args.frames.count() == 1).then(super::StageSpinner::start);
    let mut scene = super::load_scene(args.scene.as_deref())?;
    args.method.apply(&mut scene);
    if args.no_shadow {
        scene.effects.self_shadow = false;
    }
    let range = args.frames;
    let n = range.count();
    let out_path = args.output.clone().unwrap_or_else(|| {
        PathBuf::from(if n == 1 {
            "wisplight.png"
        } else {
            "wisplight_%04d.png"
        })
    });
    // The output's folder before the render, the same way for every kind
    // of output: made when missing and tried for writing, so that a
    // render does not fail at its end.
    let mut output = if is_gif(&out_path) {
        ready_folder(&out_path)?;
        let w = raster::GifWriter::new(
            AtomicFile::create(&out_path)?,
            scene.render.width,
            scene.render.height,
            scene.animation.fps,
        )
        .context("cannot start the GIF")?;
        Output::Gif(w, out_path.clone())
    } else {
        let pattern = Pattern::parse(&out_path)?;
        let ext = |x: &str| {
            out_path
                .extension()
                .is_some_and(|e| e.eq_ignore_ascii_case(x))
        };
        let exr = ext("exr");
        if !ext("png") && !exr {
            return Err(super::usage(format!(
                "-o {}: the output must be a .png or .exr (or a .gif)",
                out_path.display()
            )));
        }
        // OpenEXR is the linear picture, before it is made 8-bit sRGB: the
        // coordinator draws it (the paper's scheme), where the workers
        // would finish their bands as 8-bit. The workers still simulate,
        // fill and sweep; the bytes are those of one process.
        if let Some(r) = remote.as_mut().filter(|_| exr) {
            if matches!(
                r.options.draw,
                cluster::DrawAt::SortLast | cluster::DrawAt::SortMiddle
            ) {
                return Err(super::usage(format!(
                    "-o {}: --draw {}: OpenEXR frames are drawn on the coordinator, where the \
                     linear picture is (the workers finish theirs as 8-bit sRGB): leave --draw \
                     out, or write .png",
                    out_path.display(),
                    r.options.draw.name()
                )));
            }
            r.options.draw = cluster::DrawAt::Coordinator;
        }
        if n > 1 && !pattern.numbered() {
            let e = if exr { "exr" } else { "png" };
            return Err(super::usage(format!(
                "-o {}: {n} frames need a numbered name, like out/frame_%04d.{e} (or a .gif)",
                out_path.display()
            )));
        }
        if !exr && !args.passes.is_empty() {
            return Err(super::usage(format!(
                "-o {}: --passes are layers of an OpenEXR file: write .exr",
                out_path.display()
            )));
        }
        ready_folder(&out_path)?;
        if exr {
            Output::Exrs(pattern)
        } else {
            Output::Pngs(pattern)
        }
    };

    let mut seq = Sequence::new(&scene).context("cannot set up the scene")?;
    // The range's first wisps from the cache, before any executor takes
    // them.
    let cache = match &args.cache {
        None => None,
        Some(dir) => {
            let Some(c) = super::simulate::CacheDir::new(dir, &seq) else {
                return Err(super::usage(format!(
                    "--cache {}: the scene's hair is not simulated; render any range without a cache",
                    dir.display()
                )));
            };
            let states = c.read(range.start)?;
            seq.resume_at(range.start, states)
                .context("cannot start from the cache")?;
            Some(c)
        }
    };
    let mut traffic = None;
    let mut timing = None;
    let mut workers = 0;
    if let Some(r) = remote {
        let executor = cluster::RemoteExecutor::connect(&r.workers, &scene, &r.options)
            .context("cannot start the cluster")?;
        if !matches!(scene.shadow.method, shadow::MethodConfig::DensityMap { .. })
            && scene.effects.self_shadow
        {
            tracing::warn!(
                method = scene.shadow.method.name(),
                "only the density map runs on workers; this method and the drawing run on the coordinator"
            );
        }
        workers = executor.worker_count();
        traffic = Some(executor.traffic());
        timing = Some(executor.timing());
        seq.set_executor(Box::new(executor))
            .context("cannot start the cluster")?;
    }
    if cache.is_none() && range.start > 0 {
        // The frames before the range: their motion alone.
        let bar = super::progress_bar(
            range.start,
            "{bar:30} simulating frame {pos}/{len} before the range [{elapsed} < {eta}]",
        );
        for frame in 0..range.start {
            seq.skip_frame()
                .with_context(|| format!("cannot simulate frame {frame}"))?;
            bar.inc(1);
        }
        bar.finish_and_clear();
    }
    // A progress bar on a terminal for more than one frame.
    let bar = if n > 1 {
        super::progress_bar(n, "{bar:30} frame {pos}/{len} [{elapsed} < {eta}]")
    } else {
        indicatif::ProgressBar::hidden()
    };
    let mut all = Vec::with_capacity(n.min(100_000) as usize);
    // The last frame's PNG bytes: a frame that drew nothing new is the same
    // picture, written again without encoding it again.
    let mut png: Option<Vec<u8>> = None;
    // Bytes on the wire of each frame (cluster mode).
    let mut wire: Vec<cluster::Traffic> = Vec::new();
    let mut counted = cluster::Traffic::default();
    // Frames to come let the next frame's stages run beside this one's
    // drawing; OpenEXR light passes render each frame again with other
    // settings, which needs the hair where the frame left it.
    let again = matches!(output, Output::Exrs(_)) && super::exr::renders_again(&args.passes);
    seq.expect_frames(if again { 1 } else { n });
    // Each frame's wall time: with the next frame's stages running beside
    // this one's drawing, the stages' own times add up to more.
    let mut frame_ms = Vec::with_capacity(n.min(100_000) as usize);
    // In one process, every frame of the cache is read from it (nothing
    // is simulated); on a cluster, whose workers hold the wisps, the
    // frames after the first step on from it.
    let from_cache = |frame: u64| {
        cache
            .as_ref()
            .filter(|c| workers == 0 && frame > range.start && c.has(frame))
    };
    for frame in range.start..range.end {
        if let Some(c) = from_cache(frame) {
            seq.resume_at(frame, c.read(frame)?)
                .context("cannot take the frame from the cache")?;
        }
        let t = std::time::Instant::now();
        let (img, stats) = seq.next_frame().context("cannot render")?;
        frame_ms.push(t.elapsed().as_secs_f64() * 1e3);
        if let Some(t) = traffic.as_ref().and_then(|t| t.lock().ok().map(|t| *t)) {
            wire.push(t.since(&counted));
            counted = t;
        }
        match &mut output {
            Output::Pngs(p) => {
                let path = p.path(stats.index);
                let bytes = match png.take() {
                    Some(b) if !stats.stage(engine::Stage::Draw).ran => b,
                    _ => raster::encode_png(img).context("cannot encode the picture")?,
                };
                crate::output::write_bytes(&path, &bytes).context("cannot save the picture")?;
                png = Some(bytes);
            }
            Output::Exrs(p) => {
                let bytes = super::exr::frame(&mut seq, &scene, &args.passes)?;
                crate::output::write_bytes(&p.path(stats.index), &bytes)
                    .context("cannot save the picture")?;
            }
            Output::Gif(w, _) => w.add(img).context("cannot add a frame to the GIF")?,
        }
        tracing::debug!(
            frame = stats.index,
            ms = stats.total_ms(),
            steps = stats.steps,
            "frame done"
        );
        if all.is_empty() {
            describe(&seq, &scene);
        }
        all.push(stats);
        bar.inc(1);
    }
    bar.finish_and_clear();
    drop(spinner);
    let written = match output {
        Output::Gif(w, path) => {
            w.finish()
                .context("cannot save the GIF")?
                .commit()
                .context("cannot save the GIF")?;
            path.display().to_string()
        }
        Output::Pngs(p) | Output::Exrs(p) if n == 1 => p.path(range.start).display().to_string(),
        Output::Pngs(p) | Output::Exrs(p) => format!(
            "{} .. {}",
            p.path(range.start).display(),
            p.path(range.end - 1).display()
        ),
    };
    if let Some(path) = &args.stats {
        write_stats(path, &all)?;
    }

    if let Some(first) = wire.first() {
        let lost = timing
            .as_ref()
            .and_then(|t| t.lock().ok().map(|t| t.workers_lost))
            .unwrap_or(0);
        let lost = if lost > 0 {
            format!(" ({lost} lost on the way)")
        } else {
            String::new()
        };
        super::say!(
            "{workers} workers{lost}, bytes on the wire: frame 0 {}",
            first.summary()
        );
        // The median later frame, by total bytes.
        let mut later: Vec<_> = wire[1..].to_vec();
        later.sort_by_key(cluster::Traffic::total);
        if let Some(m) = later.get(later.len() / 2) {
            super::say!("  median later frame {}", m.summary());
        }
    }
    let hair = seq.hair();
    super::say!(
        "wrote {written} ({n} frame{}, {}x{}, {} segments, {}, median frame {:.1} ms, {:.0} ms in all)",
        if n == 1 { "" } else { "s" },
        scene.render.width,
        scene.render.height,
        hair.segment_count(),
        if scene.effects.self_shadow {
            "self-shadowed"
        } else {
            "no shadows"
        },
        super::median(&mut frame_ms),
        start.elapsed().as_secs_f64() * 1e3
    );
    Ok(())
}

/// With `-v`: what the run renders, once its first frame framed the
/// camera and fitted the maps: the groom, the strand width, the head, each
/// light's map, the camera.
fn describe(seq: &Sequence, scene: &engine::Scene) {
    let hair = seq.hair();
    let b = hair.bounds();
    let size = b.size();
    tracing::info!(
        strands = hair.strand_count(),
        points = hair.point_count(),
        segments = hair.segment_count(),
        "hair: bounds [{:.3}, {:.3}, {:.3}] .. [{:.3}, {:.3}, {:.3}], {:.3} x {:.3} x {:.3} scene units",
        b.min.x,
        b.min.y,
        b.min.z,
        b.max.x,
        b.max.y,
        b.max.z,
        size.x,
        size.y,
        size.z
    );
    tracing::info!(
        "fiber: width {:.4} scene units, opacity {:.2}",
        scene.fiber.width(),
        scene.fiber.opacity()
    );
    if let Some(h) = &scene.head {
        let mesh = h.mesh.as_ref().map_or(String::new(), |m| {
            format!(", drawn as {}", m.path.display())
        });
        tracing::info!(
            "head: collision sphere at [{:.3}, {:.3}, {:.3}], radius {:.3}{mesh}",
            h.center.x,
            h.center.y,
            h.center.z,
            h.radius
        );
    }
    let shadows = seq.renderer().shadows();
    for l in 0..shadows.light_count() {
        if let Some(f) = shadows.frame(l) {
            tracing::info!(
                light = l,
                "map: {n}^3 cells of {:.4} scene units ({:.3} a side), light along [{:.3}, {:.3}, {:.3}]",
                f.ds,
                f.ds * f.n_cells as f32,
                f.axes[0].x,
                f.axes[0].y,
                f.axes[0].z,
                n = f.n_cells
            );
        }
    }
    if let Some(c) = seq.renderer().camera() {
        let (p, a) = (c.position, c.look_at());
        tracing::info!(
            "camera: at [{:.3}, {:.3}, {:.3}] looking at [{:.3}, {:.3}, {:.3}], {:.1} degrees vertical field of view, {}x{}",
            p.x,
            p.y,
            p.z,
            a.x,
            a.y,
            a.z,
            c.fov_deg(),
            c.width(),
            c.height()
        );
    }
}

fn is_gif(p: &Path) -> bool {
    p.extension().is_some_and(|e| e.eq_ignore_ascii_case("gif"))
}

/// Writes `{"frames": [...]}`, each frame's record as
/// [`FrameStats`] serializes it.
fn write_stats(path: &Path, frames: &[FrameStats]) -> anyhow::Result<()> {
    let doc = serde_json::json!({ "frames": frames });
    let bytes = serde_json::to_vec_pretty(&doc).context("cannot encode the stats")?;
    crate::output::write_bytes(path, &bytes).context("cannot save the stats")
}

/// An output name with an optional printf-style frame number: `%d`, or
/// `%0Nd` for N digits with leading zeros (`%%` is a literal `%`).
#[derive(Debug, Clone, PartialEq)]
struct Pattern {
    before: String,
    /// Digits, when numbered.
    width: Option<usize>,
    after: String,
}

impl Pattern {
    fn parse(path: &Path) -> anyhow::Result<Pattern> {
        let s = path
            .to_str()
            .ok_or_else(|| super::usage(format!("-o {}: not valid UTF-8", path.display())))?;
        let bad = |why: &str| super::usage(format!("-o {s}: {why}"));
        let mut before = String::new();
        let mut after = String::new();
        let mut width = None;
        let mut chars = s.chars().peekable();
        while let Some(c) = chars.next() {
            let out = if width.is_some() {
                &mut after
            } else {
                &mut before
            };
            if c != '%' {
                out.push(c);
                continue;
            }
            if chars.peek() == Some(&'%') {
                chars.next();
                out.push('%');
                continue;
            }
            let mut digits = String::new();
            while let Some(&d) = chars.peek().filter(|d| d.is_ascii_digit()) {
                digits.push(d);
                chars.next();
            }
            if chars.next() != Some('d') {
                return Err(bad("a % must start %d or %04d (or be written %%)"));
            }
            if width.is_some() {
                return Err(bad("only one frame number (%d) is allowed"));
            }
            let w = if digits.is_empty() {
                0
            } else {
                digits
                    .parse::<usize>()
                    .ok()
                    .filter(|&w| w <= 12)
                    .ok_or_else(|| bad("at most 12 digits"))?
            };
            width = Some(w);
        }
        Ok(Pattern {
            before,
            width,
            after,
        })
    }

    fn numbered(&self) -> bool {
        self.width.is_some()
    }

    fn path(&self, index: u64) -> PathBuf {
        match self.width {
            Some(w) => format!("{}{index:0w$}{}", self.before, self.after).into(),
            None => format!("{}{}", self.before, self.after).into(),
        }
    }
}

/// Makes the folder `out` goes in when it is missing, and checks that a
/// file can be written there (a temporary one, removed at once).
fn ready_folder(out: &Path) -> anyhow::Result<()> {
    let dir = out
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    // A read-only output is not replaced: said before the render, not
    // after it.
    if std::fs::metadata(out).is_ok_and(|m| m.is_file() && m.permissions().readonly()) {
        anyhow::bail!(
            "-o {}: the file is read-only, so it is not replaced (make it writable, or write \
             elsewhere)",
            out.display()
        );
    }
    // A file where a folder of the path should be: said as such, not as
    // the system's "File exists".
    if let Some(file) = dir.ancestors().find(|a| a.is_file()) {
        anyhow::bail!(
            "-o {}: cannot create the folder {}: {} is a file, not a folder",
            out.display(),
            dir.display(),
            file.display()
        );
    }
    std::fs::create_dir_all(dir).with_context(|| {
        format!(
            "-o {}: cannot create the folder {}",
            out.display(),
            dir.display()
        )
    })?;
    tempfile::Builder::new()
        .prefix(".wisplight-check.")
        .tempfile_in(dir)
        .with_context(|| {
            format!(
                "-o {}: cannot write in the folder {}",
                out.display(),
                dir.display()
            )
        })?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frame_patterns_expand_like_printf() {
        let p = Pattern::parse(Path::new("out/frame_%04d.png")).unwrap();
        assert_eq!(p.path(7), PathBuf::from("out/frame_0007.png"));
        assert_eq!(p.path(12345), PathBuf::from("out/frame_12345.png"));
        let p = Pattern::parse(Path::new("f%d-100%%.png")).unwrap();
        assert_eq!(p.path(3), PathBuf::from("f3-100%.png"));
        let p = Pattern::parse(Path::new("plain.png")).unwrap();
        assert!(!p.numbered());
        assert_eq!(p.path(9), PathBuf::from("plain.png"));
        for bad in ["a%s.png", "a%d%d.png", "a%.png", "a%099999999999999d.png"] {
            assert!(Pattern::parse(Path::new(bad)).is_err(), "{bad}");
        }
    }
}
