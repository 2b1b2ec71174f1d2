//! AbcGeom's transform schema (`AbcGeom_Xform_v3`, its properties under
//! `.xform`): a stack of ops whose values are one list of channels.

use glam::{DMat4, DVec3};

use super::AlembicError;
use super::ogawa::{Archive, Kind, Object, Pod, numbers};

/// A transform read at one sample.
pub(super) struct Xform {
    /// Local to parent, column vectors (`p_parent = local * p`).
    pub(super) local: DMat4,
    /// Whether the parent's transform applies too.
    pub(super) inherits: bool,
    /// How many samples its values have.
    pub(super) samples: u32,
}

/// Reads the transform `o` at `sample`.
///
/// `.ops` is one byte an op, its type in the high four bits (0 scale,
/// 1 translate, 2 rotate about an axis, 3 matrix, 4 to 6 rotate about x,
/// y, z; angles in degrees); `.vals` holds every op's channels in order
/// (3, 3, 4, 16, 1, 1, 1). Alembic composes the ops with row vectors as
/// `M = m_{n-1} ... m_1 m_0` and `p' = p M`: the last op applies first.
/// With column vectors that is `M = M_0 M_1 ... M_{n-1}`, each `M_i` the
/// transpose; a matrix op's 16 values, row-major for row vectors, are
/// column-major for column vectors as they stand.
pub(super) fn read(archive: &Archive, o: &Object, sample: u32) -> Result<Xform, AlembicError> {
    let bad = |why: String| AlembicError::Malformed {
        what: format!("{}.xform", o.path),
        why,
    };
    let top = archive.properties(o)?;
    let Some((xi, _)) = Archive::find(&top, ".xform") else {
        return Ok(Xform {
            local: DMat4::IDENTITY,
            inherits: true,
            samples: 0,
        });
    };
    let x = archive.sub_compound(&top, xi)?;
    let inherits = match Archive::find(&x, ".inherits") {
        Some((i, h)) if h.samples > 0 => archive.sample(&x, i, sample)?.first() != Some(&0),
        _ => true,
    };
    let ops: Vec<u8> = match Archive::find(&x, ".ops") {
        Some((i, h)) if h.samples > 0 => archive.sample(&x, i, 0)?.to_vec(),
        _ => Vec::new(),
    };
    let (vals, samples) = match Archive::find(&x, ".vals") {
        Some((i, h)) if h.samples > 0 => {
            if h.pod != Pod::F64 || h.kind == Kind::Compound {
                return Err(bad(format!(".vals of {:?}, not doubles", h.pod)));
            }
            let what = format!("{}.xform.vals", o.path);
            (
                numbers(archive.sample(&x, i, sample)?, h.pod, &what, |v| v)?,
                h.samples,
            )
        }
        _ => (Vec::new(), 0),
    };
    let mut local = DMat4::IDENTITY;
    let mut at = 0;
    for (k, &op) in ops.iter().enumerate() {
        let n = match op >> 4 {
            0 | 1 => 3,
            2 => 4,
            3 => 16,
            4..=6 => 1,
            t => {
                return Err(bad(format!(
                    "op {k} of type {t}, not one of Alembic's 0 to 6"
                )));
            }
        };
        let c = vals.get(at..at + n).ok_or_else(|| {
            bad(format!(
                "{} ops need more than the {} values of .vals",
                ops.len(),
                vals.len()
            ))
        })?;
        at += n;
        let v = || DVec3::new(c[0], c[1], c[2]);
        let m = match op >> 4 {
            0 => DMat4::from_scale(v()),
            1 => DMat4::from_translation(v()),
            2 => match v().try_normalize() {
                Some(axis) => DMat4::from_axis_angle(axis, c[3].to_radians()),
                None => DMat4::IDENTITY,
            },
            3 => DMat4::from_cols_array(c.try_into().expect("16 values")),
            4 => DMat4::from_rotation_x(c[0].to_radians()),
            5 => DMat4::from_rotation_y(c[0].to_radians()),
            _ => DMat4::from_rotation_z(c[0].to_radians()),
        };
        local *= m;
    }
    if !local.is_finite() {
        return Err(bad("a transform that is not finite".into()));
    }
    Ok(Xform {
        local,
        inherits,
        samples,
    })
}
