//! One module per subcommand.

pub mod cluster;
pub mod export;
pub mod exr;
pub mod probe;
pub mod render;
pub mod simulate;
pub mod view;

use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};

use anyhow::Context;
use engine::Scene;

/// `--threads`, on the commands that run parallel stages.
#[derive(Debug, Clone, Copy, Default, clap::Args)]
pub struct Threads {
    /// Worker threads for the parallel stages (default: one per core).
    /// Results are the same bytes for any count.
    #[arg(long, value_name = "N",
          value_parser = clap::value_parser!(u16).range(1..=1024))]
    pub threads: Option<u16>,
}

/// `-v` and `-q`, on both programs' every command.
#[derive(Debug, Clone, Copy, clap::Args)]
pub struct Log {
    /// More log detail on stderr (-v info, -vv debug).
    #[arg(short, long, global = true, action = clap::ArgAction::Count)]
    pub verbose: u8,
    /// Only errors on stderr.
    #[arg(short, long, global = true, conflicts_with = "verbose")]
    pub quiet: bool,
}

static QUIET: AtomicBool = AtomicBool::new(false);

/// `-q`: only errors on stderr, the summary lines of a run too.
pub fn set_quiet(quiet: bool) {
    QUIET.store(quiet, Ordering::Relaxed);
}

/// A summary line on stderr, unless `-q` asked for errors only.
macro_rules! say {
    ($($arg:tt)*) => {
        if !$crate::cmd::quiet() {
            eprintln!($($arg)*);
        }
    };
}
pub(crate) use say;

pub fn quiet() -> bool {
    QUIET.load(Ordering::Relaxed)
}

/// A mistake in the command line itself (an option's value, or options
/// that do not go together): exit status 2, like clap's own usage errors.
#[derive(Debug)]
pub struct Usage(pub String);

impl std::fmt::Display for Usage {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for Usage {}

/// A [`Usage`] error.
pub fn usage(message: impl Into<String>) -> anyhow::Error {
    Usage(message.into()).into()
}

/// Loads a scene file, or the built-in scene when none is given.
pub fn load_scene(path: Option<&Path>) -> anyhow::Result<Scene> {
    match path {
        Some(p) => Scene::load(p).map_err(|e| match e {
            // "cannot read scene X: ..." says it all.
            engine::SceneError::Io { .. } => e.into(),
            _ => anyhow::Error::new(e).context("invalid scene"),
        }),
        None => Ok(Scene::default()),
    }
}

/// A progress bar of `len` steps drawn with `template` on a terminal;
/// hidden (nothing printed) when stderr is not one.
pub fn progress_bar(len: u64, template: &str) -> indicatif::ProgressBar {
    if !std::io::IsTerminal::is_terminal(&std::io::stderr()) {
        return indicatif::ProgressBar::hidden();
    }
    let bar = indicatif::ProgressBar::new(len);
    bar.set_style(indicatif::ProgressStyle::with_template(template).expect("a valid template"));
    bar
}

/// A spinner on a terminal, from one second on, naming the stage the
/// frame runs ([`engine::running_stage`]) until dropped: a single long
/// frame (the production groom's first, about 10 s) says what it does.
#[derive(Debug)]
pub struct StageSpinner {
    stop: Option<std::sync::mpsc::Sender<()>>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl StageSpinner {
    /// Starts it (nothing at all when stderr is not a terminal).
    pub fn start() -> StageSpinner {
        if !std::io::IsTerminal::is_terminal(&std::io::stderr()) || quiet() {
            return StageSpinner {
                stop: None,
                thread: None,
            };
        }
        let (stop, stopped) = std::sync::mpsc::channel::<()>();
        let thread = std::thread::spawn(move || {
            use std::sync::mpsc::RecvTimeoutError::Timeout;
            if stopped.recv_timeout(std::time::Duration::from_secs(1)) != Err(Timeout) {
                return;
            }
            let bar = indicatif::ProgressBar::new_spinner();
            bar.set_style(
                indicatif::ProgressStyle::with_template("{spinner} {msg} [{elapsed}]")
                    .expect("a valid template"),
            );
            // Between two stages, the last one's name stays.
            let mut shown = "setting up";
            while stopped.recv_timeout(std::time::Duration::from_millis(100)) == Err(Timeout) {
                if let Some(s) = engine::running_stage() {
                    shown = s.name();
                }
                bar.set_message(shown);
                bar.tick();
            }
            bar.finish_and_clear();
        });
        StageSpinner {
            stop: Some(stop),
            thread: Some(thread),
        }
    }
}

impl Drop for StageSpinner {
    fn drop(&mut self) {
        drop(self.stop.take());
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// Builds the scene's hair, with the scene file named in any error.
pub fn build_hair(scene: &Scene) -> anyhow::Result<strands::Hair> {
    engine::build_hair(scene).context("cannot build the hair")
}

/// `--method NAME`: the scene's shadow method replaced by another, at its
/// default settings (the scene's resolution and filter switch kept).
#[derive(Debug, Clone, clap::Args)]
pub struct MethodArg {
    /// Shadow method, overriding the scene's `[shadow] method`.
    #[arg(long, value_name = "NAME",
          value_parser = clap::builder::PossibleValuesParser::new(shadow::MethodConfig::NAMES))]
    method: Option<String>,
}

impl MethodArg {
    pub fn apply(&self, scene: &mut Scene) {
        if let Some(name) = &self.method
            && let Some(s) = scene.shadow.switch_to(name)
        {
            scene.shadow = s;
        }
    }
}

/// `--frames`: `N` for frames 0 to N-1, `A..B` for frames A to B-1, or
/// `A..=B` for frames A to B.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FrameRange {
    /// The first frame.
    pub start: u64,
    /// One past the last.
    pub end: u64,
}

/// The most frames one run renders, and the last frame's index.
pub const MAX_FRAMES: u64 = 1_000_000;

impl FrameRange {
    /// How many frames.
    pub fn count(&self) -> u64 {
        self.end - self.start
    }

    /// Parses `N`, `A..B` or `A..=B` (clap's value parser).
    pub fn parse(s: &str) -> Result<FrameRange, String> {
        let num = |t: &str| {
            t.trim()
                .parse::<u64>()
                .map_err(|_| format!("{t:?} is not a frame number"))
        };
        let (start, end) = if let Some((a, b)) = s.split_once("..=") {
            (num(a)?, num(b)?.saturating_add(1))
        } else if let Some((a, b)) = s.split_once("..") {
            (num(a)?, num(b)?)
        } else {
            (0, num(s)?)
        };
        if end <= start {
            return Err(format!(
                "{s}: no frames (give N, A..B for A to B-1, or A..=B)"
            ));
        }
        if end - start > MAX_FRAMES || end > 100 * MAX_FRAMES {
            return Err(format!(
                "{s}: at most {MAX_FRAMES} frames a run, none past frame {}",
                100 * MAX_FRAMES - 1
            ));
        }
        Ok(FrameRange { start, end })
    }
}

impl std::fmt::Display for FrameRange {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}..{}", self.start, self.end)
    }
}

/// The median of `v` (the mean of the middle two for even lengths).
pub fn median(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    let m = v.len() / 2;
    if v.len() % 2 == 1 {
        v[m]
    } else {
        0.5 * (v[m - 1] + v[m])
    }
}

/// `wisplight bench ARGS`: runs `wisplight-bench ARGS` (beside this
/// program, or on `PATH`) with `-q`/`-v` passed on, and ends with its exit
/// code.
pub fn run_bench(log: Log, args: Vec<std::ffi::OsString>) -> anyhow::Result<()> {
    const NAME: &str = "wisplight-bench";
    let beside = std::env::current_exe()
        .ok()
        .map(|p| p.with_file_name(NAME))
        .filter(|p| p.is_file());
    let program = beside.map_or_else(|| std::ffi::OsString::from(NAME), |p| p.into_os_string());
    let mut command = std::process::Command::new(&program);
    if log.quiet {
        command.arg("-q");
    }
    for _ in 0..log.verbose {
        command.arg("-v");
    }
    command.args(&args);
    match command.status() {
        Ok(status) => match status.code() {
            Some(0) => Ok(()),
            // Its own message is printed; its code is this one's.
            Some(code) => std::process::exit(code),
            None => Err(anyhow::anyhow!("{NAME} was stopped by a signal")),
        },
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Err(usage(format!(
            "`wisplight bench` runs {NAME}, found neither beside {} nor on PATH: \
             `cargo install --path . --locked` installs both programs, `cargo build --release` \
             builds both into target/release",
            std::env::current_exe()
                .map_or_else(|_| "wisplight".into(), |p| p.display().to_string())
        ))),
        Err(e) => Err(anyhow::Error::new(e).context(format!("cannot run {NAME}"))),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frame_ranges_parse_as_documented() {
        let r = |a, b| Ok(FrameRange { start: a, end: b });
        assert_eq!(FrameRange::parse("30"), r(0, 30));
        assert_eq!(FrameRange::parse("100..120"), r(100, 120));
        assert_eq!(FrameRange::parse("100..=120"), r(100, 121));
        assert_eq!(FrameRange::parse("7..=7"), r(7, 8));
        for bad in [
            "0",
            "5..5",
            "9..3",
            "a..3",
            "..3",
            "1..",
            "-1",
            "2000000",
            "1..2000000",
        ] {
            assert!(FrameRange::parse(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn median_of_odd_and_even() {
        assert_eq!(median(&mut [3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(&mut [4.0, 1.0, 3.0, 2.0]), 2.5);
        assert!(median(&mut []).is_nan());
    }
}
