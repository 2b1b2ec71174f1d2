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
        "{}: unknown hair file type (expected .hair, .tfx, USC-HairSalon .data, CT2Hair .bin or PLY strands; convert Alembic curves to one of them, e.g. with hairutil)",
        path.display()
    )]
    /// An extension no parser reads.
    UnknownExtension {
        /// The file.
        path: PathBuf,
    },
    /// Alembic archives are not read: the Rust readers of Ogawa archives
    /// (ogawa-rs 0.4) are unfinished and trust the sizes a file claims.
    #[error(
        "{}: Alembic archives are not read; convert the curves to PLY strands first, e.g. `hairutil convert -i {} -o ply` (github.com/kenshi84/hairutil), and name the .ply",
        path.display(),
        path.display()
    )]
    Alembic {
        /// The archive.
        path: PathBuf,
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

/// Loads `.hair`, `.tfx`, `.data`, `.bin` or `.ply` by extension.
pub fn load(path: &Path) -> Result<Hair, LoadError> {
    load_with(path, |p| std::fs::read(p).map(std::borrow::Cow::Owned))
}

/// Loads `.hair`, `.tfx`, `.data`, `.bin` or `.ply` by extension, its bytes from `read` (called
/// once the extension is known: an unknown one is refused first).
pub fn load_with<'a>(
    path: &Path,
    read: impl FnOnce(&Path) -> std::io::Result<std::borrow::Cow<'a, [u8]>>,
) -> Result<Hair, LoadError> {
    parser(path)?;
    let bytes = read(path).map_err(|cause| LoadError::Io {
        path: path.to_owned(),
        cause,
    })?;
    load_bytes(path, &bytes)
}

/// Parses the bytes of the file `path` (`.hair`, `.tfx`, `.data`, `.bin` or `.ply` by extension;
/// the path names the file in errors).
pub fn load_bytes(path: &Path, bytes: &[u8]) -> Result<Hair, LoadError> {
    parser(path)?(bytes).map_err(|cause| LoadError::Format {
        path: path.to_owned(),
        cause,
    })
}

type Parser = fn(&[u8]) -> Result<Hair, FormatError>;

/// The parser for `path`'s extension.
fn parser(path: &Path) -> Result<Parser, LoadError> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    match ext.as_deref() {
        Some("hair") => Ok(parse_hair_format),
        Some("tfx") => Ok(parse_tfx),
        Some("data") => Ok(parse_usc_data),
        Some("bin") => Ok(parse_ct2hair_bin),
        Some("ply") => Ok(parse_ply_strands),
        Some("abc") => Err(LoadError::Alembic {
            path: path.to_owned(),
        }),
        _ => Err(LoadError::UnknownExtension {
            path: path.to_owned(),
        }),
    }
}

/// Reads a mesh from Wavefront OBJ or PLY, by the file's extension.
pub fn load_mesh(path: &Path) -> Result<Mesh, MeshLoadError> {
    mesh_parser(path)?;
    let bytes = std::fs::read(path).map_err(|cause| MeshLoadError::Io {
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
    let bytes = std::fs::read(path).map_err(|cause| MeshLoadError::Io {
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
mod tests {
    use super::*;

    #[test]
    fn unknown_extension_and_missing_file_name_the_path() {
        let e = load(Path::new("groom.obj")).unwrap_err();
        assert!(e.to_string().contains("groom.obj"), "{e}");
        // An Alembic archive is refused before it is read, with a way out.
        let e = load(Path::new("/nonexistent/groom.abc")).unwrap_err();
        assert!(
            matches!(e, LoadError::Alembic { .. })
                && e.to_string()
                    .contains("hairutil convert -i /nonexistent/groom.abc -o ply"),
            "{e}"
        );
        let e = load(Path::new("/nonexistent/x.hair")).unwrap_err();
        assert!(
            e.to_string().starts_with("cannot read /nonexistent/x.hair"),
            "{e}"
        );
    }
}
