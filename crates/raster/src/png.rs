//! PNG output that never leaves a partial file behind.

use std::io::BufWriter;
use std::path::{Path, PathBuf};

use crate::RasterError;

/// Writes `img` as PNG to `path`: first to a temporary file beside it, then
/// renamed into place, so the file appears whole or not at all and an
/// existing file is replaced only by a complete one.
pub fn write_png_atomic(img: &image::RgbImage, path: &Path) -> Result<(), RasterError> {
    write_atomic(path, |out| {
        encode_into(img, out).map_err(|message| RasterError::Encode {
            path: path.to_owned(),
            message,
        })
    })
}

/// `img` encoded as PNG, in memory (to write the same picture to several
/// files without encoding it again).
pub fn encode_png(img: &image::RgbImage) -> Result<Vec<u8>, RasterError> {
    let mut out = Vec::new();
    encode_into(img, &mut out).map_err(|message| RasterError::Encode {
        path: PathBuf::from("<memory>"),
        message,
    })?;
    Ok(out)
}

fn encode_into(img: &image::RgbImage, out: impl std::io::Write) -> Result<(), String> {
    let encoder = image::codecs::png::PngEncoder::new(out);
    image::ImageEncoder::write_image(
        encoder,
        img.as_raw(),
        img.width(),
        img.height(),
        image::ExtendedColorType::Rgb8,
    )
    .map_err(|e| e.to_string())
}

/// Writes `bytes` to `path` whole or not at all (see [`write_atomic`]).
pub fn write_bytes_atomic(path: &Path, bytes: &[u8]) -> Result<(), RasterError> {
    write_atomic(path, |out| {
        std::io::Write::write_all(out, bytes).map_err(|cause| RasterError::Write {
            path: path.to_owned(),
            cause,
        })
    })
}

/// Writes a file through `write`: first to a temporary file beside `path`,
/// synced, then renamed into place. On any error the temporary file is
/// removed and `path` is untouched.
pub fn write_atomic(
    path: &Path,
    write: impl FnOnce(&mut BufWriter<std::fs::File>) -> Result<(), RasterError>,
) -> Result<(), RasterError> {
    let mut file = AtomicFile::create(path)?;
    write(file.writer())?;
    file.commit()
}

/// A file that appears whole or not at all: written to a temporary file
/// beside its path and renamed into place by [`Self::commit`]. Dropped
/// without a commit, it removes the temporary file and leaves the path as
/// it was.
///
/// A symbolic link is followed: the file it points to is replaced, not the
/// link. A path that names something other than a regular file (a device
/// such as `/dev/stdout`, a pipe) is written directly, since it cannot be
/// replaced by renaming; a directory is an error.
#[derive(Debug)]
pub struct AtomicFile {
    path: PathBuf,
    /// The temporary file, or `None` when writing directly.
    tmp: Option<PathBuf>,
    out: Option<BufWriter<std::fs::File>>,
}

impl AtomicFile {
    /// Starts writing `path` (see the type's documentation).
    pub fn create(path: &Path) -> Result<AtomicFile, RasterError> {
        let write_err = |cause| RasterError::Write {
            path: path.to_owned(),
            cause,
        };
        // Where the bytes go: through links to an existing file.
        let target = if path.is_symlink() {
            std::fs::canonicalize(path).unwrap_or_else(|_| path.to_owned())
        } else {
            path.to_owned()
        };
        if let Ok(meta) = std::fs::metadata(&target) {
            if meta.is_dir() {
                return Err(write_err(std::io::Error::new(
                    std::io::ErrorKind::IsADirectory,
                    "is a directory",
                )));
            }
            if !meta.is_file() {
                let file = std::fs::OpenOptions::new()
                    .write(true)
                    .truncate(true)
                    .open(&target)
                    .map_err(write_err)?;
                return Ok(AtomicFile {
                    path: path.to_owned(),
                    tmp: None,
                    out: Some(BufWriter::new(file)),
                });
            }
        }
        let path = target.as_path();
        let dir = path
            .parent()
            .filter(|d| !d.as_os_str().is_empty())
            .unwrap_or(Path::new("."));
        let name = path.file_name().ok_or_else(|| {
            write_err(std::io::Error::new(
                std::io::ErrorKind::InvalidInput,
                "not a file name",
            ))
        })?;
        let tmp = dir.join(format!(
            ".{}.{}.tmp",
            name.to_string_lossy(),
            std::process::id()
        ));
        remove_stale(dir, &name.to_string_lossy());
        let file = std::fs::File::create(&tmp).map_err(write_err)?;
        if let Ok(mut t) = TEMPORARIES.lock() {
            t.push(tmp.clone());
        }
        Ok(AtomicFile {
            path: path.to_owned(),
            tmp: Some(tmp),
            out: Some(BufWriter::new(file)),
        })
    }

    /// The final path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Makes the file readable and writable by its owner alone (mode
    /// 0600 on Unix), before anything is written to it: for keys.
    pub fn private(self) -> Result<AtomicFile, RasterError> {
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            let at = self.tmp.as_deref().unwrap_or(&self.path);
            std::fs::set_permissions(at, std::fs::Permissions::from_mode(0o600)).map_err(
                |cause| RasterError::Write {
                    path: self.path.clone(),
                    cause,
                },
            )?;
        }
        Ok(self)
    }

    /// Where the bytes go, until the commit.
    pub fn writer(&mut self) -> &mut BufWriter<std::fs::File> {
        self.out.as_mut().expect("not yet committed")
    }

    /// Flushes, syncs and renames the file into place.
    pub fn commit(mut self) -> Result<(), RasterError> {
        let write_err = |cause| RasterError::Write {
            path: self.path.clone(),
            cause,
        };
        let out = self.out.take().expect("committed once");
        let file = out.into_inner().map_err(|e| write_err(e.into_error()))?;
        let Some(tmp) = &self.tmp else {
            // Written directly (a device or pipe): flushed is done.
            return Ok(());
        };
        file.sync_all().map_err(write_err)?;
        std::fs::rename(tmp, &self.path).map_err(write_err)
    }
}

impl Drop for AtomicFile {
    fn drop(&mut self) {
        // Not committed, or the commit failed: no partial file stays.
        if let Some(tmp) = &self.tmp {
            if self.out.take().is_some() || tmp.exists() {
                let _ = std::fs::remove_file(tmp);
            }
            if let Ok(mut t) = TEMPORARIES.lock() {
                t.retain(|p| p != tmp);
            }
        }
    }
}

/// The temporary files of this process's outputs not yet in place.
static TEMPORARIES: std::sync::Mutex<Vec<PathBuf>> = std::sync::Mutex::new(Vec::new());

/// Removes the temporary file of every output still being written: for a
/// program about to exit on a signal, which leaves no partial file.
pub fn remove_temporaries() {
    if let Ok(t) = TEMPORARIES.lock() {
        for p in t.iter() {
            let _ = std::fs::remove_file(p);
        }
    }
}

/// Removes the temporary files `.NAME.PID.tmp` in `dir` left by processes
/// that are gone (killed outright while writing `NAME`).
fn remove_stale(dir: &Path, name: &str) {
    // Whether a process lives is read from /proc (Linux); elsewhere
    // nothing is removed.
    if !Path::new("/proc/self").exists() {
        return;
    }
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    let prefix = format!(".{name}.");
    for e in entries.flatten() {
        let file = e.file_name();
        let Some(pid) = file
            .to_str()
            .and_then(|f| f.strip_prefix(&prefix))
            .and_then(|f| f.strip_suffix(".tmp"))
            .and_then(|p| p.parse::<u32>().ok())
        else {
            continue;
        };
        // Another live process's file is its own.
        if pid != std::process::id() && !Path::new(&format!("/proc/{pid}")).exists() {
            let _ = std::fs::remove_file(e.path());
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn writes_a_readable_png_and_leaves_no_temporary_file() {
        let dir = std::env::temp_dir().join(format!("wisplight-png-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("a.png");
        let img =
            image::RgbImage::from_fn(5, 3, |x, y| image::Rgb([x as u8 * 40, y as u8 * 80, 7]));
        write_png_atomic(&img, &path).unwrap();
        let back = image::open(&path).unwrap().to_rgb8();
        assert_eq!(back, img);
        let names: Vec<_> = std::fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names, vec![std::ffi::OsString::from("a.png")]);
        assert!(write_png_atomic(&img, &dir.join("missing-dir/b.png")).is_err());
    }

    #[test]
    fn links_are_followed_devices_written_directly_and_directories_refused() {
        let dir = std::env::temp_dir().join(format!("wisplight-links-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(dir.join("sub")).unwrap();
        let real = dir.join("sub/real.json");
        std::fs::write(&real, b"old").unwrap();
        let link = dir.join("link.json");
        std::os::unix::fs::symlink(&real, &link).unwrap();
        write_bytes_atomic(&link, b"new").unwrap();
        assert!(link.is_symlink(), "the link is kept");
        assert_eq!(std::fs::read(&real).unwrap(), b"new");
        // A pipe (like /dev/stdout) is written into, not replaced.
        let fifo = dir.join("pipe");
        let made = std::process::Command::new("mkfifo").arg(&fifo).status();
        if made.is_ok_and(|s| s.success()) {
            let reader = {
                let fifo = fifo.clone();
                std::thread::spawn(move || std::fs::read(fifo).unwrap())
            };
            write_bytes_atomic(&fifo, b"bytes").unwrap();
            assert_eq!(reader.join().unwrap(), b"bytes");
            let meta = std::fs::symlink_metadata(&fifo).unwrap();
            assert!(!meta.is_file(), "the pipe was replaced by a file");
        }
        let e = write_bytes_atomic(&dir.join("sub"), b"x").unwrap_err();
        assert!(e.to_string().contains("directory"), "{e}");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
