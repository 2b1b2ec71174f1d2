//! AbcGeom's curves schema (`AbcGeom_Curve_v2`, its properties under
//! `.geom`): points, vertex counts, basis and type, widths.

use glam::{DMat4, DVec3};

use super::AlembicError;
use super::ogawa::{Archive, Compound, Kind, Object, Pod, numbers};
use crate::Hair;
use crate::cubic::{Basis, push_curve, strand_widths};

/// One curves object read: its strands in world space, each strand's
/// width when it has widths, and how many samples its points have.
pub(super) struct Curves {
    pub(super) hair: Hair,
    pub(super) widths: Option<Vec<f32>>,
    pub(super) samples: u32,
}

/// Reads the curves object `o` at `sample`, placed by `world`.
pub(super) fn read(
    archive: &Archive,
    o: &Object,
    sample: u32,
    world: DMat4,
    warn: bool,
) -> Result<Curves, AlembicError> {
    let unreadable = |why: String| AlembicError::Unreadable {
        object: o.path.clone(),
        why,
    };
    let top = archive.properties(o)?;
    let geom = match Archive::find(&top, ".geom") {
        Some((i, _)) => archive.sub_compound(&top, i)?,
        None => return Err(unreadable("curves without their .geom properties".into())),
    };
    let (p_index, p) = Archive::find(&geom, "P")
        .ok_or_else(|| unreadable("curves without points (P); nothing to read".into()))?;
    if p.kind != Kind::Array || p.extent != 3 || !matches!(p.pod, Pod::F32 | Pod::F64) {
        return Err(unreadable(format!(
            "P is {:?} of {:?} x{}, not an array of 3 floats",
            p.kind, p.pod, p.extent
        )));
    }
    let samples = p.samples;
    let what = format!("{}.geom.P", o.path);
    let points: Vec<f32> = numbers(archive.sample(&geom, p_index, sample)?, p.pod, &what, |x| {
        x as f32
    })?;
    let counts = counts(archive, &geom, sample, &o.path)?;
    let total: u64 = counts.iter().map(|&c| c as u64).sum();
    if total != points.len() as u64 / 3 {
        return Err(unreadable(format!(
            "nVertices add up to {total} points, but P holds {}",
            points.len() / 3
        )));
    }
    let [kind, wrap, basis] = basis_and_type(archive, &geom, sample, &o.path)?;
    let basis = match kind {
        0 => Some(Basis::from_code(basis).ok_or_else(|| {
            unreadable(format!(
                "cubic curves of basis {} (hermite, power or none), not read; export them linear, Bezier, B-spline or Catmull-Rom",
                basis
            ))
        })?),
        1 => None,
        2 => {
            if warn {
                tracing::warn!(
                "Alembic {}: NURBS curves read as their control polygon",
                    o.path
                );
            }
            None
        }
        k => return Err(unreadable(format!("curve type {k}, not linear, cubic or NURBS"))),
    };
    if wrap == 1 && basis.is_some() {
        return Err(unreadable(
            "periodic (closed) cubic curves, not strands of hair".into(),
        ));
    }
    let widths = widths(archive, &geom, sample, &o.path, &counts, basis)?;
    // Widths are lengths in the object's space: scaled as the transform
    // scales volume, cube root of |det|.
    let width_scale = world.determinant().abs().cbrt() as f32;

    let mut hair = Hair::with_capacity(counts.len(), points.len() / 3);
    let (mut cv, mut along) = (Vec::new(), Vec::new());
    let mut start = 0usize;
    for (s, &n) in counts.iter().enumerate() {
        cv.clear();
        cv.extend((start..start + n).map(|i| {
            let p = DVec3::new(
                f64::from(points[3 * i]),
                f64::from(points[3 * i + 1]),
                f64::from(points[3 * i + 2]),
            );
            world.transform_point3(p)
        }));
        if wrap == 1 && n > 1 {
            cv.push(cv[0]);
        }
        start += n;
        push_curve(&mut hair, &cv, basis, &mut along)
            .map_err(|e| unreadable(format!("curve {s}: {e}")))?;
    }
    let widths = widths.map(|w| w.into_iter().map(|x| x * width_scale).collect());
    Ok(Curves {
        hair,
        widths,
        samples,
    })
}

/// `nVertices`: each curve's control points, none negative.
fn counts(
    archive: &Archive,
    geom: &Compound,
    sample: u32,
    object: &str,
) -> Result<Vec<usize>, AlembicError> {
    let (i, h) = Archive::find(geom, "nVertices").ok_or_else(|| AlembicError::Unreadable {
        object: object.to_owned(),
        why: "curves without nVertices".into(),
    })?;
    let what = format!("{object}.geom.nVertices");
    let raw = numbers(archive.sample(geom, i, sample)?, h.pod, &what, |x| x)?;
    raw.iter()
        .enumerate()
        .map(|(c, &n)| {
            if n >= 0.0 {
                Ok(n as usize)
            } else {
                Err(AlembicError::Unreadable {
                    object: object.to_owned(),
                    why: format!("curve {c} has {n} vertices"),
                })
            }
        })
        .collect()
}

/// `curveBasisAndType`: type (0 cubic, 1 linear, 2 variable order),
/// wrap (0 open, 1 periodic), basis (0 none, 1 Bezier, 2 B-spline,
/// 3 Catmull-Rom, 4 Hermite, 5 power). Linear and open when absent.
fn basis_and_type(
    archive: &Archive,
    geom: &Compound,
    sample: u32,
    object: &str,
) -> Result<[u8; 3], AlembicError> {
    let Some((i, h)) = Archive::find(geom, "curveBasisAndType") else {
        return Ok([1, 0, 0]);
    };
    let b = archive.sample(geom, i, sample)?;
    if h.pod != Pod::U8 || b.len() < 3 {
        return Err(AlembicError::Unreadable {
            object: object.to_owned(),
            why: format!("curveBasisAndType of {} {:?} bytes", b.len(), h.pod),
        });
    }
    Ok([b[0], b[1], b[2]])
}

/// The `width` geometry parameter as one width a strand (the mean of
/// its values), or `None` when the curves have none. Its values may be
/// one for all (`con`), one a curve (`uni`), one a control point (`vtx`)
/// or one a span end (`var`, `fvr`; a control point for linear curves),
/// and indexed (a compound of `.vals` and `.indices`).
fn widths(
    archive: &Archive,
    geom: &Compound,
    sample: u32,
    object: &str,
    counts: &[usize],
    basis: Option<Basis>,
) -> Result<Option<Vec<f32>>, AlembicError> {
    let Some((i, h)) = Archive::find(geom, "width") else {
        return Ok(None);
    };
    let what = format!("{object}.geom.width");
    let values: Vec<f32> = match h.kind {
        Kind::Compound => {
            let c = archive.sub_compound(geom, i)?;
            let (vi, vh) = Archive::find(&c, ".vals").ok_or_else(|| AlembicError::Malformed {
                what: what.clone(),
                why: "an indexed width without .vals".into(),
            })?;
            let vals = numbers(archive.sample(&c, vi, sample)?, vh.pod, &what, |x| x as f32)?;
            match Archive::find(&c, ".indices") {
                Some((ii, ih)) => {
                    let idx = numbers(archive.sample(&c, ii, sample)?, ih.pod, &what, |x| x)?;
                    idx.iter()
                        .map(|&k| {
                            vals.get(k as usize)
                                .copied()
                                .ok_or_else(|| AlembicError::Malformed {
                                    what: what.clone(),
                                    why: format!("index {k} of {} values", vals.len()),
                                })
                        })
                        .collect::<Result<_, _>>()?
                }
                None => vals,
            }
        }
        _ => numbers(archive.sample(geom, i, sample)?, h.pod, &what, |x| x as f32)?,
    };
    strand_widths(&values, counts, basis)
        .map(Some)
        .map_err(|why| AlembicError::Unreadable {
            object: object.to_owned(),
            why,
        })
}
