//! Output files that appear whole or not at all: pictures, GIFs, tables,
//! stats and keys are written to a temporary file beside their path
//! (tempfile's `NamedTempFile`), synced, and renamed into place by its
//! `persist`. An existing file is only ever replaced by a complete one.
//!
//! What tempfile leaves to its caller is done here: a run stopped by
//! SIGINT or SIGTERM removes its temporaries before exiting
//! ([`remove_temporaries`]), and one killed outright has its temporary
//! removed by the next run writing the same file (the process id is in the
//! name, `.NAME.PID.RANDOM.tmp`, and `/proc` says whether it lives).

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::Mutex;

use anyhow::Context;
use tempfile::NamedTempFile;

/// A file being written (see the module's documentation). Dropped without
/// [`Self::commit`], it removes its temporary file and leaves the path as
/// it was.
///
/// A symbolic link is followed: the file it points to is replaced, not the
/// link. A path naming something other than a regular file (a device such
/// as `/dev/stdout`, a pipe) is written directly, since it cannot be
/// replaced by renaming; a directory is an error.
#[derive(Debug)]
pub struct AtomicFile {
    /// The path as given, for messages.
    path: PathBuf,
    /// Where the bytes land: the link's target for a link.
    target: PathBuf,
    /// `None` once committed.
    out: Option<Out>,
}

#[derive(Debug)]
enum Out {
    Temporary(BufWriter<NamedTempFile>),
    Direct(BufWriter<File>),
}

impl AtomicFile {
    /// Starts writing `path`, readable as the umask allows (0644 with the
    /// usual 022).
    pub fn create(path: &Path) -> anyhow::Result<AtomicFile> {
        AtomicFile::with_mode(path, 0o666)
    }

    /// Starts writing `path` readable and writable by its owner alone
    /// (0600) from its first byte: for keys.
    pub fn private(path: &Path) -> anyhow::Result<AtomicFile> {
        AtomicFile::with_mode(path, 0o600)
    }

    fn with_mode(path: &Path, mode: u32) -> anyhow::Result<AtomicFile> {
        let cannot = || format!("cannot write {}", path.display());
        // Where the bytes go: through links to an existing file.
        let target = if path.is_symlink() {
            std::fs::canonicalize(path).unwrap_or_else(|_| path.to_owned())
        } else {
            path.to_owned()
        };
        if let Ok(meta) = std::fs::metadata(&target) {
            if meta.is_dir() {
                anyhow::bail!("{}: is a directory", cannot());
            }
            if meta.is_file() && meta.permissions().readonly() {
                anyhow::bail!(
                    "{}: the file is read-only, so it is not replaced (make it writable, or \
                     write elsewhere)",
                    cannot()
                );
            }
            if !meta.is_file() {
                let file = std::fs::OpenOptions::new()
                    .write(true)
                    .truncate(true)
                    .open(&target)
                    .with_context(cannot)?;
                return Ok(AtomicFile {
                    path: path.to_owned(),
                    target,
                    out: Some(Out::Direct(BufWriter::new(file))),
                });
            }
        }
        let dir = target
            .parent()
            .filter(|d| !d.as_os_str().is_empty())
            .unwrap_or(Path::new("."));
        let name = target
            .file_name()
            .with_context(|| format!("{}: not a file name", cannot()))?
            .to_string_lossy()
            .into_owned();
        remove_stale(dir, &name);
        let prefix = format!(".{name}.{}.", std::process::id());
        let mut builder = tempfile::Builder::new();
        builder.prefix(&prefix).suffix(".tmp");
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            builder.permissions(std::fs::Permissions::from_mode(mode));
        }
        #[cfg(not(unix))]
        let _ = mode;
        // tempfile names its random temporary in the error; the user's
        // path, in the context, is the one that means something.
        let tmp = builder
            .tempfile_in(dir)
            .map_err(os_error)
            .with_context(cannot)?;
        if let Ok(mut t) = TEMPORARIES.lock() {
            t.push(tmp.path().to_owned());
        }
        Ok(AtomicFile {
            path: path.to_owned(),
            target,
            out: Some(Out::Temporary(BufWriter::new(tmp))),
        })
    }

    /// Flushes, syncs and renames the file into place.
    pub fn commit(mut self) -> anyhow::Result<()> {
        let cannot = || format!("cannot write {}", self.path.display());
        match self.out.take().expect("committed once") {
            Out::Direct(out) => out
                .into_inner()
                .map(drop)
                .map_err(|e| e.into_error())
                .with_context(cannot),
            Out::Temporary(out) => {
                let at = out.get_ref().path().to_owned();
                let done = out
                    .into_inner()
                    .map_err(|e| e.into_error())
                    .and_then(|tmp| {
                        tmp.as_file().sync_all()?;
                        tmp.persist(&self.target).map(drop).map_err(|e| e.error)
                    });
                // In place, or removed by tempfile on the way out.
                forget(&at);
                done.with_context(cannot)
            }
        }
    }

    /// Where the bytes go, until the commit.
    fn writer(&mut self) -> &mut dyn Write {
        match self.out.as_mut().expect("not yet committed") {
            Out::Temporary(w) => w,
            Out::Direct(w) => w,
        }
    }
}

impl Write for AtomicFile {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.writer().write(buf)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.writer().flush()
    }
}

impl Drop for AtomicFile {
    fn drop(&mut self) {
        // Not committed: tempfile removes the file itself.
        if let Some(Out::Temporary(w)) = &self.out {
            forget(w.get_ref().path());
        }
    }
}

/// tempfile's error without the path of the temporary it appends
/// (`... at path "..."`), which it keeps private with the OS's error code.
fn os_error(e: std::io::Error) -> std::io::Error {
    let text = e.to_string();
    match text.rsplit_once(" at path \"") {
        Some((reason, _)) => std::io::Error::new(e.kind(), reason.to_owned()),
        None => e,
    }
}

/// Writes `bytes` to `path` whole or not at all.
pub fn write_bytes(path: &Path, bytes: &[u8]) -> anyhow::Result<()> {
    let mut file = AtomicFile::create(path)?;
    file.write_all(bytes)
        .with_context(|| format!("cannot write {}", path.display()))?;
    file.commit()
}

/// Writes `img` as a PNG to `path` whole or not at all.
pub fn write_png(path: &Path, img: &image::RgbImage) -> anyhow::Result<()> {
    let bytes =
        raster::encode_png(img).with_context(|| format!("cannot write {}", path.display()))?;
    write_bytes(path, &bytes)
}

/// The temporary files of this process's outputs not yet in place.
static TEMPORARIES: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

fn forget(tmp: &Path) {
    if let Ok(mut t) = TEMPORARIES.lock() {
        t.retain(|p| p != tmp);
    }
}

/// Removes the temporary file of every output still being written: for a
/// program about to exit on a signal, which runs no destructor.
pub fn remove_temporaries() {
    remove_temporaries_where(|_| true);
}

fn remove_temporaries_where(which: impl Fn(&Path) -> bool) {
    if let Ok(t) = TEMPORARIES.lock() {
        for p in t.iter().filter(|p| which(p)) {
            let _ = std::fs::remove_file(p);
        }
    }
}

/// Removes the temporary files `.NAME.PID.*.tmp` in `dir` left by
/// processes that are gone (killed outright while writing `NAME`).
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
            .and_then(|f| f.split('.').next())
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

    fn scratch(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("wisplight-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    fn names(dir: &Path) -> Vec<String> {
        let mut n: Vec<String> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        n.sort();
        n
    }

    #[test]
    fn a_file_appears_whole_at_commit_and_nothing_stays_otherwise() {
        let dir = scratch("atomic");
        let path = dir.join("a.json");
        std::fs::write(&path, b"old").unwrap();
        let mut f = AtomicFile::create(&path).unwrap();
        f.write_all(b"new and longer").unwrap();
        f.flush().unwrap();
        assert_eq!(
            std::fs::read(&path).unwrap(),
            b"old",
            "untouched until commit"
        );
        assert_eq!(names(&dir).len(), 2, "a temporary beside it");
        f.commit().unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), b"new and longer");
        assert_eq!(names(&dir), ["a.json"]);
        // Dropped unfinished: the old file stays, the temporary goes.
        let mut f = AtomicFile::create(&path).unwrap();
        f.write_all(b"partial").unwrap();
        drop(f);
        assert_eq!(std::fs::read(&path).unwrap(), b"new and longer");
        assert_eq!(names(&dir), ["a.json"]);
        let e = write_bytes(&dir.join("missing-dir/b.png"), b"x").unwrap_err();
        let e = format!("{e:#}");
        assert!(e.contains("missing-dir/b.png: No such file"), "{e}");
        assert!(!e.contains(".tmp"), "{e}");
        let listed = TEMPORARIES.lock().unwrap().clone();
        assert!(!listed.iter().any(|p| p.starts_with(&dir)), "{listed:?}");
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn files_get_the_umasks_mode_and_keys_their_owners_alone() {
        use std::os::unix::fs::PermissionsExt;
        let dir = scratch("modes");
        let mode = |p: &Path| std::fs::metadata(p).unwrap().permissions().mode() & 0o777;
        write_bytes(&dir.join("a.png"), b"x").unwrap();
        // What a plain File::create gives under this process's umask.
        std::fs::write(dir.join("plain"), b"x").unwrap();
        assert_eq!(mode(&dir.join("a.png")), mode(&dir.join("plain")));
        let mut key = AtomicFile::private(&dir.join("a.key")).unwrap();
        key.write_all(b"secret").unwrap();
        key.commit().unwrap();
        assert_eq!(mode(&dir.join("a.key")), 0o600);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_signal_removes_what_is_being_written_and_a_dead_processs_temporary_goes() {
        let dir = scratch("stale");
        let path = dir.join("c.png");
        // A temporary of a process that no longer exists (pid_max is at
        // most 2^22), and one of a live process (this one's parent).
        let parent = std::os::unix::process::parent_id();
        std::fs::write(dir.join(".c.png.4194999.AbCdEf.tmp"), b"x").unwrap();
        std::fs::write(dir.join(format!(".c.png.{parent}.AbCdEf.tmp")), b"x").unwrap();
        std::fs::write(dir.join(".other.png.4194999.AbCdEf.tmp"), b"x").unwrap();
        let f = AtomicFile::create(&path).unwrap();
        let n = names(&dir);
        assert!(
            !n.contains(&".c.png.4194999.AbCdEf.tmp".to_string()),
            "{n:?}"
        );
        assert!(n.contains(&format!(".c.png.{parent}.AbCdEf.tmp")), "{n:?}");
        assert!(
            n.contains(&".other.png.4194999.AbCdEf.tmp".to_string()),
            "{n:?}"
        );
        let own = format!(".c.png.{}.", std::process::id());
        assert!(n.iter().any(|x| x.starts_with(&own)), "{n:?}");
        // What remove_temporaries does, to this test's files alone (the
        // other tests write theirs at the same time).
        remove_temporaries_where(|p| p.starts_with(&dir));
        assert!(!names(&dir).iter().any(|x| x.starts_with(&own)));
        drop(f);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn links_are_followed_devices_written_directly_and_directories_refused() {
        let dir = scratch("links");
        std::fs::create_dir_all(dir.join("sub")).unwrap();
        let real = dir.join("sub/real.json");
        std::fs::write(&real, b"old").unwrap();
        let link = dir.join("link.json");
        std::os::unix::fs::symlink(&real, &link).unwrap();
        write_bytes(&link, b"new").unwrap();
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
            write_bytes(&fifo, b"bytes").unwrap();
            assert_eq!(reader.join().unwrap(), b"bytes");
            let meta = std::fs::symlink_metadata(&fifo).unwrap();
            assert!(!meta.is_file(), "the pipe was replaced by a file");
        }
        let e = write_bytes(&dir.join("sub"), b"x").unwrap_err();
        assert!(format!("{e:#}").contains("directory"), "{e:#}");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
