//! Reading hair and meshes from files: which parser reads which
//! extension, and errors that name the file.

use std::path::{Path, PathBuf};

use crate::Hair;
use crate::load::{FormatError, parse_ct2hair_bin, parse_hair_format, parse_tfx, parse_usc_data};
use crate::mesh::{Mesh, MeshError, parse_obj};
use crate::ply::{parse_ply_mesh, parse_ply_strands};

/// A file that could not be loaded, with its path.
#[derive(Debug, thiserror::Error)]
pub enum LoadError {
    /// The file cannot be read.
    #[error("cannot read {}: {cause}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// Why.
        cause: std::io::Error,
    },
    /// What the file holds is malformed.
    #[error("{}: {cause}", path.display())]
    Format {
        /// The file.
        path: PathBuf,
        /// What is wrong, and where in the file.
        cause: FormatError,
    },
    #[error(
        "{}: unknown hair file type (expected .hair, .tfx, USC-HairSalon .data, CT2Hair .bin, PLY strands, Alembic .abc or USD .usd, .usda, .usdc, .usdz)",
        path.display()
    )]
    /// An extension no parser reads.
    UnknownExtension {
        /// The file.
        path: PathBuf,
    },
    /// A sample other than the first asked of a format that has one.
    #[error(
        "{}: sample {sample} asked for, but a .{ext} file holds one pose (samples are read from Alembic and USD files)",
        path.display()
    )]
    NotAnimated {
        /// The file.
        path: PathBuf,
        /// Its extension.
        ext: String,
        /// The sample asked for.
        sample: u32,
    },
}

/// Why an OBJ file cannot be loaded.
#[derive(Debug, thiserror::Error)]
pub enum MeshLoadError {
    /// The file cannot be read.
    #[error("cannot read {}: {cause}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// Why.
        cause: std::io::Error,
    },
    /// What the file holds is malformed.
    #[error("{}: {cause}", path.display())]
    Format {
        /// The file.
        path: PathBuf,
        /// What is wrong, and where in the file.
        cause: MeshError,
    },
    /// An extension no parser reads.
    #[error("{}: unknown mesh file type (expected .obj or .ply)", path.display())]
    UnknownExtension {
        /// The file.
        path: PathBuf,
    },
}

/// The largest data file (groom or mesh) read whole: 256 MiB, about 22
/// million points of a binary groom. A longer file, or one that never
/// ends (`/dev/zero`, a FIFO that keeps writing), is refused at the limit.
pub const MAX_FILE_BYTES: u64 = 256 << 20;

/// How long a file that is not a regular file (a FIFO, a device) is
/// given to be opened and read whole: opening a FIFO waits for a writer,
/// and reading it for its data.
pub const SPECIAL_FILE_WAIT: std::time::Duration = std::time::Duration::from_secs(10);

/// Reads `path` whole if it holds at most `cap` bytes. More is an error
/// of kind [`std::io::ErrorKind::FileTooLarge`] once `cap + 1` bytes have
/// been read, so that memory stays bounded whatever the file is (a device
/// or a FIFO has no size to check first); and a FIFO or a device not read
/// whole within [`SPECIAL_FILE_WAIT`] is an error of kind
/// [`std::io::ErrorKind::TimedOut`], so that time stays bounded too.
pub fn read_capped(path: &Path, cap: u64) -> std::io::Result<Vec<u8>> {
    read_capped_within(path, cap, SPECIAL_FILE_WAIT)
}

/// [`read_capped`], a FIFO or a device given `wait`. Such a file is read
/// on a thread of its own (the file's kind is checked first, which does
/// not wait); past `wait` that thread is left to end when the file does
/// (its writer comes, or goes) while the caller gets the error.
pub fn read_capped_within(
    path: &Path,
    cap: u64,
    wait: std::time::Duration,
) -> std::io::Result<Vec<u8>> {
    let meta = std::fs::metadata(path)?;
    if meta.is_dir() {
        return Err(std::io::Error::new(
            std::io::ErrorKind::IsADirectory,
            "a directory, not a file",
        ));
    }
    if meta.is_file() {
        return read_open(path, cap);
    }
    let (tx, rx) = std::sync::mpsc::channel();
    let owned = path.to_owned();
    std::thread::Builder::new()
        .name("read-special-file".into())
        .spawn(move || {
            let _ = tx.send(read_open(&owned, cap));
        })?;
    rx.recv_timeout(wait).unwrap_or_else(|_| {
        Err(std::io::Error::new(
            std::io::ErrorKind::TimedOut,
            format!(
                "not read whole within {} s: not a regular file, but a FIFO with no writer, or \
                 a FIFO or a device that stays silent",
                wait.as_secs_f64()
            ),
        ))
    })
}

/// Opens and reads `path` whole, at most `cap` bytes.
fn read_open(path: &Path, cap: u64) -> std::io::Result<Vec<u8>> {
    use std::io::Read;
    let file = std::fs::File::open(path)?;
    let meta = file.metadata()?;
    if meta.is_file() && meta.len() > cap {
        return Err(too_large(meta.len(), cap));
    }
    let mut bytes = Vec::with_capacity(if meta.is_file() {
        meta.len() as usize
    } else {
        0
    });
    file.take(cap + 1).read_to_end(&mut bytes)?;
    if bytes.len() as u64 > cap {
        return Err(std::io::Error::new(
            std::io::ErrorKind::FileTooLarge,
            format!("more than {cap} bytes, the limit, and still going (a device or a FIFO?)"),
        ));
    }
    Ok(bytes)
}

fn too_large(len: u64, cap: u64) -> std::io::Error {
    std::io::Error::new(
        std::io::ErrorKind::FileTooLarge,
        format!("{len} bytes, more than the limit of {cap}"),
    )
}

/// Loads a groom by its extension (`.hair`, `.tfx`, `.data`, `.bin`,
/// `.ply`, `.abc`, `.usd`, `.usda`, `.usdc`, `.usdz`; at most
/// [`MAX_FILE_BYTES`]), at `sample` of an animated Alembic or USD file (0
/// the first; others have only 0).
pub fn load(path: &Path, sample: u32) -> Result<Hair, LoadError> {
    load_with(path, sample, |p| {
        read_capped(p, MAX_FILE_BYTES).map(std::borrow::Cow::Owned)
    })
}

/// Whether `path` names a groom file by its extension (one [`load`]
/// reads).
pub fn is_groom_path(path: &Path) -> bool {
    format(path).is_ok()
}

/// Whether `path` names a groom format that holds samples (Alembic, USD).
pub fn is_animated_groom_path(path: &Path) -> bool {
    matches!(format(path), Ok(Format::Alembic | Format::Usd(_)))
}

/// [`load`], the bytes from `read` (called once the extension is known:
/// an unknown one is refused first).
pub fn load_with<'a>(
    path: &Path,
    sample: u32,
    read: impl FnOnce(&Path) -> std::io::Result<std::borrow::Cow<'a, [u8]>>,
) -> Result<Hair, LoadError> {
    load_with_samples(path, sample, read).map(|(hair, _)| hair)
}

/// [`load_with`], and the samples the file holds (see [`groom_samples`]).
pub fn load_with_samples<'a>(
    path: &Path,
    sample: u32,
    read: impl FnOnce(&Path) -> std::io::Result<std::borrow::Cow<'a, [u8]>>,
) -> Result<(Hair, u32), LoadError> {
    format(path)?;
    let bytes = read(path).map_err(|cause| LoadError::Io {
        path: path.to_owned(),
        cause,
    })?;
    read_groom(path, &bytes, sample, true)
}

/// Parses the bytes of the groom file `path` by its extension, at
/// `sample` (see [`load`]; the path names the file in errors).
pub fn load_bytes(path: &Path, bytes: &[u8], sample: u32) -> Result<Hair, LoadError> {
    read_groom(path, bytes, sample, true).map(|(hair, _)| hair)
}

/// The samples of the groom file `path` of `bytes`: an animated Alembic
/// or USD file's (its curves' points and transforms), 1 for others.
pub fn groom_samples(path: &Path, bytes: &[u8]) -> Result<u32, LoadError> {
    read_groom(path, bytes, 0, false).map(|(_, samples)| samples)
}

/// [`load_bytes`] of a file read before at another sample: what it passes
/// over or reads only approximately is not said again.
pub fn load_bytes_again(path: &Path, bytes: &[u8], sample: u32) -> Result<Hair, LoadError> {
    read_groom(path, bytes, sample, false).map(|(hair, _)| hair)
}

/// The groom `path` of `bytes` at `sample`, and the samples the file holds
/// (1 for a format of one pose); `warn`: say what is passed over or read
/// only approximately.
fn read_groom(
    path: &Path,
    bytes: &[u8],
    sample: u32,
    warn: bool,
) -> Result<(Hair, u32), LoadError> {
    let format_error = |cause| LoadError::Format {
        path: path.to_owned(),
        cause,
    };
    let (hair, samples) = match format(path)? {
        Format::Still(_, ext) if sample != 0 => {
            return Err(LoadError::NotAnimated {
                path: path.to_owned(),
                ext: ext.to_owned(),
                sample,
            });
        }
        Format::Still(parse, _) => (parse(bytes).map_err(format_error)?, 1),
        Format::Alembic => {
            crate::alembic::read(bytes, sample, warn).map_err(|e| format_error(e.into()))?
        }
        Format::Usd(ext) => {
            crate::usd::read(bytes, ext, sample, warn).map_err(|e| format_error(e.into()))?
        }
    };
    Ok((hair, samples.max(1)))
}

/// How a groom file's bytes are read.
enum Format {
    /// One pose, by this parser; the extension.
    Still(fn(&[u8]) -> Result<Hair, FormatError>, &'static str),
    /// An Alembic Ogawa archive.
    Alembic,
    /// A USD layer or package, by its extension.
    Usd(&'static str),
}

/// The format of `path`, by its extension.
fn format(path: &Path) -> Result<Format, LoadError> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    Ok(match ext.as_deref() {
        Some("hair") => Format::Still(parse_hair_format, "hair"),
        Some("tfx") => Format::Still(parse_tfx, "tfx"),
        Some("data") => Format::Still(parse_usc_data, "data"),
        Some("bin") => Format::Still(parse_ct2hair_bin, "bin"),
        Some("ply") => Format::Still(parse_ply_strands, "ply"),
        Some("abc") => Format::Alembic,
        Some("usd") => Format::Usd("usd"),
        Some("usda") => Format::Usd("usda"),
        Some("usdc") => Format::Usd("usdc"),
        Some("usdz") => Format::Usd("usdz"),
        _ => {
            return Err(LoadError::UnknownExtension {
                path: path.to_owned(),
            });
        }
    })
}

/// Reads a mesh from Wavefront OBJ or PLY, by the file's extension.
pub fn load_mesh(path: &Path) -> Result<Mesh, MeshLoadError> {
    mesh_parser(path)?;
    let bytes = read_capped(path, MAX_FILE_BYTES).map_err(|cause| MeshLoadError::Io {
        path: path.to_owned(),
        cause,
    })?;
    load_mesh_bytes(path, &bytes)
}

/// Parses the bytes of the mesh file `path` (`.obj` or `.ply` by
/// extension; the path names the file in errors).
pub fn load_mesh_bytes(path: &Path, bytes: &[u8]) -> Result<Mesh, MeshLoadError> {
    mesh_parser(path)?(bytes).map_err(|cause| MeshLoadError::Format {
        path: path.to_owned(),
        cause,
    })
}

type MeshParser = fn(&[u8]) -> Result<Mesh, MeshError>;

/// The mesh parser for `path`'s extension.
pub fn mesh_parser(path: &Path) -> Result<MeshParser, MeshLoadError> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    match ext.as_deref() {
        Some("obj") => Ok(parse_obj),
        Some("ply") => Ok(parse_ply_mesh),
        _ => Err(MeshLoadError::UnknownExtension {
            path: path.to_owned(),
        }),
    }
}

/// Reads a Wavefront OBJ file: `v x y z` vertices and `f` faces (indices
/// `i`, `i/t`, `i//n` or `i/t/n`, 1-based or negative relative ones;
/// polygons are split into fans). Normals, texture coordinates, groups and
/// materials are ignored: normals are recomputed from the faces.
pub fn load_obj(path: &Path) -> Result<Mesh, MeshLoadError> {
    let bytes = read_capped(path, MAX_FILE_BYTES).map_err(|cause| MeshLoadError::Io {
        path: path.to_owned(),
        cause,
    })?;
    load_obj_bytes(path, &bytes)
}

/// Parses the bytes of the OBJ file `path` (which names it in errors).
pub fn load_obj_bytes(path: &Path, bytes: &[u8]) -> Result<Mesh, MeshLoadError> {
    parse_obj(bytes).map_err(|cause| MeshLoadError::Format {
        path: path.to_owned(),
        cause,
    })
}

#[cfg(test)]
mod special_file_tests {
    use super::*;
    use std::time::{Duration, Instant};

    fn fifo(name: &str) -> PathBuf {
        let dir =
            std::env::temp_dir().join(format!("wisplight-fifo-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("f");
        let made = std::process::Command::new("mkfifo")
            .arg(&path)
            .status()
            .unwrap();
        assert!(made.success());
        path
    }

    #[test]
    fn a_fifo_with_no_writer_or_a_silent_one_is_refused_in_time() {
        let wait = Duration::from_millis(300);
        // No writer: opening it would wait for ever.
        let lonely = fifo("lonely");
        let t = Instant::now();
        let e = read_capped_within(&lonely, 1 << 20, wait).unwrap_err();
        assert_eq!(e.kind(), std::io::ErrorKind::TimedOut, "{e}");
        assert!(e.to_string().contains("a FIFO with no writer"), "{e}");
        assert!(t.elapsed() < Duration::from_secs(5));
        // A writer that says a little and then holds it open, silent.
        let silent = fifo("silent");
        let path = silent.clone();
        let (hold, held) = std::sync::mpsc::channel::<()>();
        let writer = std::thread::spawn(move || {
            use std::io::Write;
            let mut f = std::fs::OpenOptions::new().write(true).open(path).unwrap();
            f.write_all(b"# a start\n").unwrap();
            let _ = held.recv_timeout(Duration::from_secs(10));
        });
        let e = read_capped_within(&silent, 1 << 20, wait).unwrap_err();
        assert_eq!(e.kind(), std::io::ErrorKind::TimedOut, "{e}");
        drop(hold);
        writer.join().unwrap();
        // A FIFO whose writer says it all and goes is read whole.
        let said = fifo("said");
        let path = said.clone();
        let writer = std::thread::spawn(move || std::fs::write(path, b"all of it").unwrap());
        assert_eq!(
            read_capped_within(&said, 1 << 20, Duration::from_secs(5)).unwrap(),
            b"all of it"
        );
        writer.join().unwrap();
        // The lonely FIFO's reader is still waiting for a writer: let it end.
        let _ = std::fs::OpenOptions::new().write(true).open(&lonely);
        for p in [lonely, silent, said] {
            let _ = std::fs::remove_dir_all(p.parent().unwrap());
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unknown_extension_and_missing_file_name_the_path() {
        let e = load(Path::new("groom.obj"), 0).unwrap_err();
        assert!(e.to_string().contains("groom.obj"), "{e}");
        let e = load(Path::new("/nonexistent/x.hair"), 0).unwrap_err();
        assert!(
            e.to_string().starts_with("cannot read /nonexistent/x.hair"),
            "{e}"
        );
        // A sample of a format of one pose is refused, naming the format.
        let e = load_bytes(Path::new("x.hair"), b"", 3).unwrap_err();
        assert!(
            e.to_string().contains("sample 3") && e.to_string().contains(".hair file"),
            "{e}"
        );
    }
}
