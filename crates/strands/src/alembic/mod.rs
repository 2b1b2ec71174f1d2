//! Alembic grooms: the AbcGeom curves of an Ogawa archive, placed by the
//! transforms above them, at one sample of an animated cache.
//!
//! Every curves object (`AbcGeom_Curve_v2`) is read: its points `P`,
//! `nVertices`, `curveBasisAndType` and, when present, its `width`
//! geometry parameter (constant, per curve or per vertex, indexed or not).
//! Transforms (`AbcGeom_Xform_v3`) above a curves object place it, each op
//! (scale, translate, rotations, matrix) as Alembic composes them;
//! `.inherits = false` starts afresh. Linear curves are read as they are;
//! cubic ones (Bezier, B-spline, Catmull-Rom) are evaluated into points
//! along them; NURBS curves are read as their control polygon, with a
//! warning. Other geometry (meshes, subdivision surfaces, points,
//! cameras) is passed over with a warning, and an archive of none but
//! such objects is refused naming them.
//!
//! The container and core layer are in `ogawa` (a fork of ogawa-rs, its
//! fixes listed there); this module is the AbcGeom schema on top.

mod curves;
mod ogawa;
mod xform;

use glam::DMat4;

use crate::Hair;
use ogawa::{Archive, Object};

/// The most objects an archive's tree is walked through: an object's
/// group may be named by several parents (Alembic shares what is the
/// same), so a small file can describe an exponential tree.
const MAX_OBJECTS: usize = 1 << 20;
/// The most points read from all curves objects together (about 400 MB
/// of points): more than the largest groom file of another format holds,
/// and shared samples cannot multiply past it.
const MAX_POINTS: usize = 32 << 20;

/// What is wrong in an Alembic archive, naming the object.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum AlembicError {
    /// Not an Ogawa archive.
    #[error("not an Alembic Ogawa archive ({len} bytes, no \"Ogawa\" at the start){}",
        if *hdf5 { "; an HDF5 archive: re-export it as Ogawa" } else { "" })]
    Magic {
        /// The file's bytes.
        len: usize,
        /// It looks like Alembic's older HDF5 container.
        hdf5: bool,
    },
    /// A block that runs past the end of the file.
    #[error("{what}: byte {at} is past the end of the {len}-byte file (truncated?)")]
    Truncated {
        /// What was being read.
        what: String,
        /// Where, bytes.
        at: u64,
        /// The file's bytes.
        len: u64,
    },
    /// Something the format does not allow.
    #[error("{what}: {why}")]
    Malformed {
        /// The object or property.
        what: String,
        /// What is wrong.
        why: String,
    },
    /// A curves object wisplight cannot read.
    #[error("{object}: {why}")]
    Unreadable {
        /// The object's path.
        object: String,
        /// Why.
        why: String,
    },
    /// No curves in the archive.
    #[error("holds no curves{}", if others.is_empty() { String::new() } else { format!(" (it holds {others})") })]
    NoCurves {
        /// The other geometry found, listed.
        others: String,
    },
    /// A sample past the cache's last.
    #[error("sample {asked} asked for, but the archive's curves have {count} sample{} (0 to {})",
        if *count == 1 { "" } else { "s" }, count.saturating_sub(1))]
    Sample {
        /// The sample asked for.
        asked: u32,
        /// The samples the curves have.
        count: u32,
    },
}

/// Reads the curves of the Ogawa archive `b` at sample `sample` (0 the
/// first) into hair, with the strands' widths when every curves object
/// has them.
pub fn parse_alembic(b: &[u8], sample: u32) -> Result<Hair, AlembicError> {
    read(b, sample, true).map(|(hair, _)| hair)
}

/// The samples the archive's curves have (their points' and the
/// transforms above them; 1 for a still groom).
pub fn alembic_samples(b: &[u8]) -> Result<u32, AlembicError> {
    read(b, 0, false).map(|(_, samples)| samples.max(1))
}

/// [`parse_alembic`] and the samples the curves have; `warn`: say what
/// was passed over (once a file, not again at each sample).
pub(crate) fn read(b: &[u8], sample: u32, warn: bool) -> Result<(Hair, u32), AlembicError> {
    let archive = Archive::open(b)?;
    let mut found = Found {
        warn,
        ..Found::default()
    };
    walk(
        &archive,
        &archive.top()?,
        DMat4::IDENTITY,
        sample,
        &mut found,
    )?;
    if found.objects == 0 {
        return Err(AlembicError::NoCurves {
            others: list(&found.others),
        });
    }
    if warn && !found.others.is_empty() {
        tracing::warn!(
            "Alembic: passed over what is not curves: {}",
            list(&found.others)
        );
    }
    if found.samples > 0 && sample >= found.samples {
        return Err(AlembicError::Sample {
            asked: sample,
            count: found.samples,
        });
    }
    let mut hair = found.hair;
    if found.widths_missing == 0 {
        hair.set_widths(found.widths);
    } else if warn && found.widths_missing < found.objects {
        tracing::warn!(
            "Alembic: {} of {} curves objects have no widths; the scene's fiber width applies to all",
            found.widths_missing,
            found.objects
        );
    }
    Ok((hair, found.samples))
}

/// What the walk has gathered.
#[derive(Default)]
struct Found {
    hair: Hair,
    /// Each strand's width, of the curves objects that have widths.
    widths: Vec<f32>,
    widths_missing: usize,
    /// Curves objects read.
    objects: usize,
    /// Objects walked through.
    visited: usize,
    /// Say what is read only approximately (once a file).
    warn: bool,
    /// The most samples of any curves' points or transform.
    samples: u32,
    /// Geometry passed over: path and kind.
    others: Vec<(String, &'static str)>,
}

fn list(others: &[(String, &'static str)]) -> String {
    let mut s: Vec<String> = others
        .iter()
        .take(4)
        .map(|(path, kind)| format!("{path}, {kind}"))
        .collect();
    if others.len() > 4 {
        s.push(format!("and {} more", others.len() - 4));
    }
    s.join("; ")
}

/// The AbcGeom schema an object follows: its metadata's, or its first
/// property compound's.
fn schema(archive: &Archive, o: &Object) -> Result<Option<String>, AlembicError> {
    if let Some(s) = o.meta.get("schema") {
        return Ok(Some(s.to_owned()));
    }
    let props = archive.properties(o)?;
    Ok(props
        .headers
        .first()
        .and_then(|h| h.meta.get("schema"))
        .map(str::to_owned))
}

/// Reads `o` and what is below it, `parent` its parent's world transform.
fn walk(
    archive: &Archive,
    o: &Object,
    parent: DMat4,
    sample: u32,
    found: &mut Found,
) -> Result<(), AlembicError> {
    found.visited += 1;
    if found.visited > MAX_OBJECTS {
        return Err(AlembicError::Malformed {
            what: o.path.clone(),
            why: format!("more than {MAX_OBJECTS} objects in the archive's tree"),
        });
    }
    let mut world = parent;
    // A transform's samples count when it places curves.
    let mut xform_samples = 0;
    match schema(archive, o)?.as_deref() {
        Some("AbcGeom_Xform_v3") => {
            let x = xform::read(archive, o, sample)?;
            xform_samples = x.samples;
            world = if x.inherits {
                parent * x.local
            } else {
                x.local
            };
        }
        Some("AbcGeom_Curve_v2") => {
            let c = curves::read(archive, o, sample, parent, found.warn)?;
            if found.hair.point_count() + c.hair.point_count() > MAX_POINTS {
                return Err(AlembicError::Unreadable {
                    object: o.path.clone(),
                    why: format!("the curves read so far pass {MAX_POINTS} points, the most read"),
                });
            }
            found.samples = found.samples.max(c.samples);
            found.objects += 1;
            match c.widths {
                Some(w) => found.widths.extend(w),
                None => found.widths_missing += 1,
            }
            for strand in c.hair.strands() {
                found
                    .hair
                    .push_strand(strand)
                    .map_err(|e| AlembicError::Unreadable {
                        object: o.path.clone(),
                        why: e.to_string(),
                    })?;
            }
        }
        Some(other) => {
            if let Some(kind) = kind_of(other) {
                found.others.push((o.path.clone(), kind));
            }
        }
        None => {}
    }
    let curves_before = found.objects;
    for child in archive.children(o)? {
        walk(archive, &child, world, sample, found)?;
    }
    if found.objects > curves_before {
        found.samples = found.samples.max(xform_samples);
    }
    Ok(())
}

/// A plain name for a geometry schema that is not curves.
fn kind_of(schema: &str) -> Option<&'static str> {
    Some(match schema {
        "AbcGeom_PolyMesh_v1" => "a polygon mesh",
        "AbcGeom_SubD_v1" => "a subdivision surface",
        "AbcGeom_NuPatch_v2" => "a NURBS patch",
        "AbcGeom_Points_v1" => "points",
        "AbcGeom_Camera_v1" => "a camera",
        "AbcGeom_Light_v1" => "a light",
        "AbcGeom_FaceSet_v1" => return None,
        _ => "an object of another schema",
    })
}
