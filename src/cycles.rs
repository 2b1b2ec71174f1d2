//! Blender Cycles as an independent reference: a frame exported for it
//! ([`engine::cycles_export`]), rendered by a `blender` process, and its
//! linear picture read back.

use std::path::{Path, PathBuf};
use std::process::Command;

use anyhow::{Context, bail};
use glam::Vec3;

/// Writes the export's files into `dir` (created if missing), each whole
/// or not at all. Returns the path of `scene.py`.
pub fn write_export(dir: &Path, export: &engine::CyclesExport) -> anyhow::Result<PathBuf> {
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    for (name, bytes) in &export.files {
        crate::output::write_bytes(&dir.join(name), bytes)
            .with_context(|| format!("cannot export to {}", dir.display()))?;
    }
    Ok(dir.join("scene.py"))
}

/// The `blender` program: `$WISPLIGHT_BLENDER` (when it names a file),
/// else `blender` on PATH.
pub fn blender() -> Option<PathBuf> {
    if let Some(p) = std::env::var_os("WISPLIGHT_BLENDER") {
        return Some(PathBuf::from(p)).filter(|p| p.is_file());
    }
    let path = std::env::var_os("PATH")?;
    std::env::split_paths(&path)
        .map(|d| d.join("blender"))
        .find(|p| p.is_file())
}

/// How one Cycles picture is rendered.
#[derive(Debug, Clone, Copy)]
pub struct CyclesRun {
    /// Nothing casts a shadow.
    pub unshadowed: bool,
    /// Samples per pixel.
    pub samples: u32,
    /// Light bounces; 0 is direct light only.
    pub bounces: u32,
    /// Render threads (0: all).
    pub threads: usize,
}

/// Renders the export in `dir` with Cycles into `out` (OpenEXR, linear);
/// Blender's output goes to `dir/blender.log`. Returns the seconds the
/// render took, as Blender reports them.
pub fn render(blender: &Path, dir: &Path, out: &Path, run: CyclesRun) -> anyhow::Result<f64> {
    let log_path = dir.join("blender.log");
    let log = std::fs::File::create(&log_path)
        .with_context(|| format!("cannot write {}", log_path.display()))?;
    let mut cmd = Command::new(blender);
    cmd.args(["-b", "-noaudio", "--factory-startup", "--python"])
        .arg(dir.join("scene.py"))
        .arg("--")
        .arg("--output")
        .arg(out)
        .args(["--samples", &run.samples.to_string()])
        .args(["--bounces", &run.bounces.to_string()])
        .args(["--threads", &run.threads.to_string()]);
    if run.unshadowed {
        cmd.arg("--unshadowed");
    }
    let status = cmd
        .stdin(std::process::Stdio::null())
        .stdout(log.try_clone()?)
        .stderr(log)
        .status()
        .with_context(|| format!("cannot run {}", blender.display()))?;
    let text = std::fs::read_to_string(&log_path).unwrap_or_default();
    // Blender exits 0 even when the script fails: the script prints its
    // own line once the picture is written.
    if !status.success() || !text.contains("wisplight: wrote") {
        let last: Vec<&str> = text.lines().rev().take(8).collect();
        bail!(
            "blender could not render {} (see {}): {}",
            dir.display(),
            log_path.display(),
            last.into_iter().rev().collect::<Vec<_>>().join(" | ")
        );
    }
    // " Time: 00:16.04 (Saving: 00:00.01)"
    let seconds = text
        .lines()
        .filter_map(|l| l.trim().strip_prefix("Time: "))
        .filter_map(|t| t.split_whitespace().next())
        .filter_map(parse_clock)
        .next_back()
        .unwrap_or(f64::NAN);
    Ok(seconds)
}

/// `MM:SS.ss` or `HH:MM:SS.ss` in seconds.
fn parse_clock(t: &str) -> Option<f64> {
    t.split(':').try_fold(0.0, |acc, part| {
        Some(acc * 60.0 + part.parse::<f64>().ok()?)
    })
}

/// A linear RGB picture read from an OpenEXR file.
pub fn read_exr(path: &Path) -> anyhow::Result<(u32, u32, Vec<Vec3>)> {
    let img = image::ImageReader::open(path)
        .with_context(|| format!("cannot read {}", path.display()))?
        .with_guessed_format()?
        .decode()
        .with_context(|| format!("cannot decode {}", path.display()))?
        .into_rgb32f();
    let (w, h) = img.dimensions();
    let px = img.pixels().map(|p| Vec3::from_array(p.0)).collect();
    Ok((w, h, px))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn blender_clock_times() {
        assert_eq!(parse_clock("00:16.04"), Some(16.04));
        assert_eq!(parse_clock("01:02:03.5"), Some(3723.5));
        assert_eq!(parse_clock("x"), None);
    }
}
