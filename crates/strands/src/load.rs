//! Strand file parsers: Cem Yuksel's HAIR format, TressFX 4 `.tfx`,
//! USC-HairSalon `.data` and CT2Hair `.bin` (PLY in `ply`; by extension in `files`).
//!
//! The parsers work on bytes already read, and check every count a header
//! claims against the bytes actually present *before* allocating anything
//! sized by it: a lying header gets an error, not a 10^12-element allocation.

use glam::Vec3;

use crate::hair::{Hair, HairError};

/// A file's first bytes as text, escaped where not printable ASCII.
fn magic_text(b: &[u8]) -> String {
    b.iter()
        .flat_map(|&c| std::ascii::escape_default(c))
        .map(char::from)
        .collect()
}

/// What a file's first bytes suggest it is, as a note for an error.
fn format_guess(b: &[u8; 4]) -> &'static str {
    match b {
        [b'p', b'l', b'y', _] => " (a PLY file?)",
        [b'O', b'g', b'a', b'w'] => " (an Alembic Ogawa archive?)",
        [0x89, b'H', b'D', b'F'] => " (an Alembic HDF5 archive?)",
        [0x1f, 0x8b, _, _] => " (a gzip-compressed file?)",
        [0x89, b'P', b'N', b'G'] => " (a PNG picture?)",
        [b'v' | b'#' | b'o' | b'g', b' ', _, _] => " (an OBJ text file?)",
        _ if b
            .iter()
            .all(|c| c.is_ascii_graphic() || c.is_ascii_whitespace()) =>
        {
            " (a text file?)"
        }
        _ => "",
    }
}

/// What is wrong inside a hair file.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum FormatError {
    /// The file ends inside its header.
    #[error("file is {len} bytes, shorter than the {need}-byte header")]
    TruncatedHeader {
        /// The file's bytes.
        len: usize,
        /// The header's bytes.
        need: usize,
    },
    #[error(
        "wrong magic \"{}\"{}, expected \"HAIR\"",
        magic_text(found),
        format_guess(found)
    )]
    /// The first bytes are not the format's magic.
    BadMagic {
        /// The bytes found.
        found: [u8; 4],
    },
    #[error(
        "header claims {count} {what}, needing {need} bytes, but only {have} bytes follow the header"
    )]
    /// The header claims more than the file holds.
    Truncated {
        /// What it counts.
        what: &'static str,
        /// How many it claims.
        count: u64,
        /// The bytes they need.
        need: u64,
        /// The bytes present.
        have: u64,
    },
    /// The strands' point counts do not add up to the header's.
    #[error("segment counts add up to {sum} points, but the header says {points}")]
    CountMismatch {
        /// Their sum.
        sum: u64,
        /// The header's count.
        points: u64,
    },
    /// An array that starts outside the file.
    #[error("{what} array starts at byte {offset}, outside the {len}-byte file")]
    BadOffset {
        /// Which array.
        what: &'static str,
        /// Where it starts, bytes.
        offset: u64,
        /// The file's bytes.
        len: u64,
    },
    /// Points claimed but no point array flagged.
    #[error("header claims {points} points but sets no point array flag")]
    NoPointArray {
        /// The points claimed.
        points: u64,
    },
    /// The points do not make hair (a non-finite coordinate).
    #[error(transparent)]
    Hair(#[from] HairError),
    /// A colour that is NaN or infinite.
    #[error("colour of point {point} is not finite")]
    NonFiniteColor {
        /// The point it belongs to.
        point: usize,
    },
    /// A TressFX version other than 4.
    #[error("unsupported TressFX version {0} (expected 4)")]
    TfxVersion(f32),
    /// Strands of no vertices.
    #[error("header claims {strands} strands of no vertices")]
    EmptyStrands {
        /// The strands claimed.
        strands: u64,
    },
    /// A negative count.
    #[error("byte {offset}: a negative {what} count, {count}")]
    NegativeCount {
        /// What it counts.
        what: &'static str,
        /// The count.
        count: i64,
        /// Where it is, bytes.
        offset: u64,
    },
    #[error(
        "byte {offset}: strand {strand} claims {count} vertices, needing {need} bytes, but only {have} remain"
    )]
    /// A strand whose vertices run past the end of the file.
    StrandTruncated {
        /// The strand.
        strand: u64,
        /// Its vertices.
        count: u64,
        /// Where it starts, bytes.
        offset: u64,
        /// The bytes they need.
        need: u64,
        /// The bytes left.
        have: u64,
    },
    /// Bytes left over after the last strand.
    #[error("byte {offset}: {left} bytes left over after the last of {strands} strands")]
    TrailingBytes {
        /// Where they start.
        offset: u64,
        /// How many.
        left: u64,
        /// The strands read.
        strands: u64,
    },
    /// A malformed PLY file.
    #[error("PLY: {0}")]
    Ply(String),
    /// An Alembic archive wisplight cannot read.
    #[error("Alembic: {0}")]
    Alembic(#[from] crate::AlembicError),
    /// A USD file wisplight cannot read.
    #[error("USD: {0}")]
    Usd(#[from] crate::UsdError),
}

fn u32_at(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes(b[at..at + 4].try_into().expect("4 bytes"))
}

fn f32_at(b: &[u8], at: usize) -> f32 {
    f32::from_le_bytes(b[at..at + 4].try_into().expect("4 bytes"))
}

fn vec3_at(b: &[u8], at: usize) -> Vec3 {
    Vec3::new(f32_at(b, at), f32_at(b, at + 4), f32_at(b, at + 8))
}

const HAIR_HEADER: usize = 128;
const HAS_SEGMENTS: u32 = 1;
const HAS_POINTS: u32 = 2;
const HAS_THICKNESS: u32 = 4;
const HAS_TRANSPARENCY: u32 = 8;
const HAS_COLORS: u32 = 16;

/// Parses Cem Yuksel's HAIR format.
///
/// Header (128 bytes, little-endian): `"HAIR"`, strand count, point count,
/// array flags (1 segments, 2 points, 4 thickness, 8 transparency, 16
/// colours), default segment count, default thickness, default
/// transparency, default colour (3 f32), 88 bytes of text. Then the arrays
/// present, in flag order: u16 segments per strand, f32 xyz per point, f32
/// thickness per point, f32 transparency per point, f32 rgb per point.
///
/// Each strand's colour is its root point's colour (or the default colour).
/// Thickness and transparency are read past: fiber width and opacity come
/// from the scene, in physical units.
pub fn parse_hair_format(b: &[u8]) -> Result<Hair, FormatError> {
    if b.len() < HAIR_HEADER {
        return Err(FormatError::TruncatedHeader {
            len: b.len(),
            need: HAIR_HEADER,
        });
    }
    let magic: [u8; 4] = b[0..4].try_into().expect("4 bytes");
    if &magic != b"HAIR" {
        return Err(FormatError::BadMagic { found: magic });
    }
    let strands = u64::from(u32_at(b, 4));
    let points = u64::from(u32_at(b, 8));
    let flags = u32_at(b, 12);
    let default_segments = u64::from(u32_at(b, 16));
    let default_color = vec3_at(b, 36);
    let have = (b.len() - HAIR_HEADER) as u64;

    // Sizes of each array from the header's counts, in u64 so that no count
    // can overflow; compared with the file length before any allocation.
    let seg_bytes = if flags & HAS_SEGMENTS != 0 {
        strands * 2
    } else {
        0
    };
    let per_point = [
        (HAS_POINTS, 12u64),
        (HAS_THICKNESS, 4),
        (HAS_TRANSPARENCY, 4),
        (HAS_COLORS, 12),
    ];
    let point_bytes: u64 = per_point
        .iter()
        .filter(|(f, _)| flags & f != 0)
        .map(|(_, s)| s * points)
        .sum();
    let need = seg_bytes + point_bytes;
    if need > have {
        let what = if seg_bytes > have {
            "strands"
        } else {
            "points"
        };
        let count = if seg_bytes > have { strands } else { points };
        return Err(FormatError::Truncated {
            what,
            count,
            need,
            have,
        });
    }
    if flags & HAS_POINTS == 0 && points != 0 {
        return Err(FormatError::NoPointArray { points });
    }

    // Points per strand, checked to add up before building anything.
    let seg_at = HAIR_HEADER;
    let strand_len = |s: usize| -> u64 {
        if flags & HAS_SEGMENTS != 0 {
            u64::from(u16::from_le_bytes([
                b[seg_at + 2 * s],
                b[seg_at + 2 * s + 1],
            ])) + 1
        } else {
            default_segments + 1
        }
    };
    let sum: u64 = if flags & HAS_SEGMENTS != 0 {
        (0..strands as usize).map(strand_len).sum()
    } else {
        strands.saturating_mul(default_segments + 1)
    };
    if sum != points {
        return Err(FormatError::CountMismatch { sum, points });
    }

    let pos_at = HAIR_HEADER + seg_bytes as usize;
    let mut array_at = pos_at
        + if flags & HAS_POINTS != 0 {
            12 * points as usize
        } else {
            0
        };
    for flag in [HAS_THICKNESS, HAS_TRANSPARENCY] {
        if flags & flag != 0 {
            array_at += 4 * points as usize;
        }
    }
    let color_at = (flags & HAS_COLORS != 0).then_some(array_at);

    let mut hair = Hair::with_capacity(strands as usize, points as usize);
    let mut colors = Vec::with_capacity(strands as usize);
    let mut strand_pts = Vec::new();
    let mut first = 0usize;
    for s in 0..strands as usize {
        let n = strand_len(s) as usize;
        strand_pts.clear();
        strand_pts.extend((first..first + n).map(|p| vec3_at(b, pos_at + 12 * p)));
        hair.push_strand(&strand_pts)?;
        let color = match color_at {
            Some(at) => {
                let c = vec3_at(b, at + 12 * first);
                if !c.is_finite() {
                    return Err(FormatError::NonFiniteColor { point: first });
                }
                c
            }
            None => default_color,
        };
        colors.push(color);
        first += n;
    }
    if color_at.is_some() {
        hair.set_colors(colors);
    }
    Ok(hair)
}

const TFX_HEADER: usize = 160;

/// Parses a TressFX 4 `.tfx` file.
///
/// Header (160 bytes, little-endian): f32 version, u32 strand count, u32
/// vertices per strand, u32 byte offset of the positions, four more u32
/// offsets (strand UV, vertex UV, thickness, colour) and 128 reserved bytes.
/// Positions are f32 xyzw per vertex, `w` the inverse mass (0 pins the root).
pub fn parse_tfx(b: &[u8]) -> Result<Hair, FormatError> {
    if b.len() < TFX_HEADER {
        return Err(FormatError::TruncatedHeader {
            len: b.len(),
            need: TFX_HEADER,
        });
    }
    let version = f32_at(b, 0);
    if version != 4.0 {
        return Err(FormatError::TfxVersion(version));
    }
    let strands = u64::from(u32_at(b, 4));
    let per_strand = u64::from(u32_at(b, 8));
    let offset = u64::from(u32_at(b, 12));
    let len = b.len() as u64;
    if offset < TFX_HEADER as u64 || offset > len {
        return Err(FormatError::BadOffset {
            what: "position",
            offset,
            len,
        });
    }
    // Strands of no vertices take no bytes: without this check a header
    // could claim 4 billion of them.
    if per_strand == 0 && strands > 0 {
        return Err(FormatError::EmptyStrands { strands });
    }
    // u32 * u32 fits u64; times 16 may not: saturate, the length check refuses it.
    let points = strands * per_strand;
    let need = points.saturating_mul(16);
    let have = len - offset;
    if need > have {
        return Err(FormatError::Truncated {
            what: "vertices",
            count: points,
            need,
            have,
        });
    }
    if strands == 0 {
        // No strands: whatever the vertex count per strand claims, nothing
        // is read (nor allocated for it).
        return Ok(Hair::new());
    }
    let mut hair = Hair::with_capacity(strands as usize, points as usize);
    let mut strand_pts = Vec::with_capacity(per_strand as usize);
    for s in 0..strands as usize {
        strand_pts.clear();
        let base = offset as usize + 16 * s * per_strand as usize;
        strand_pts.extend((0..per_strand as usize).map(|v| vec3_at(b, base + 16 * v)));
        hair.push_strand(&strand_pts)?;
    }
    Ok(hair)
}

/// Parses a USC-HairSalon `.data` file (the format of the USC-HairSalon
/// dataset and of the tools that read it, hairutil among them).
///
/// Little-endian: an i32 strand count, then per strand an i32 vertex count
/// and that many f32 xyz. Strands of one vertex (a root with no hair, as
/// the dataset has) are kept: they draw nothing and deposit nothing. Every
/// count is checked against the bytes left before anything is allocated
/// for it, and bytes after the last strand are refused.
pub fn parse_usc_data(b: &[u8]) -> Result<Hair, FormatError> {
    parse_counted(b, 12)
}

/// Parses a CT2Hair `.bin` file (the strands CT2Hair reconstructs from CT
/// scans; hairutil reads and writes them).
///
/// Little-endian, as `.data` but with seven f32 per vertex: x, y, z and
/// four values wisplight does not use. The same checks as
/// [`parse_usc_data`].
pub fn parse_ct2hair_bin(b: &[u8]) -> Result<Hair, FormatError> {
    parse_counted(b, 28)
}

/// An i32 strand count, then per strand an i32 vertex count and that many
/// vertices of `stride` bytes, each starting with f32 x, y, z.
fn parse_counted(b: &[u8], stride: u64) -> Result<Hair, FormatError> {
    let len = b.len() as u64;
    if b.len() < 4 {
        return Err(FormatError::TruncatedHeader {
            len: b.len(),
            need: 4,
        });
    }
    let count = |at: usize, what: &'static str| -> Result<u64, FormatError> {
        let c = i32::from_le_bytes(b[at..at + 4].try_into().expect("4 bytes"));
        u64::try_from(c).map_err(|_| FormatError::NegativeCount {
            what,
            count: i64::from(c),
            offset: at as u64,
        })
    };
    let strands = count(0, "strand")?;
    // Each strand takes 4 bytes at least.
    let have = len - 4;
    if strands * 4 > have {
        return Err(FormatError::Truncated {
            what: "strands",
            count: strands,
            need: strands * 4,
            have,
        });
    }
    // No more points than the bytes can hold.
    let mut hair = Hair::with_capacity(strands as usize, (have / stride) as usize);
    let mut pts = Vec::new();
    let mut at = 4usize;
    for s in 0..strands {
        if b.len() - at < 4 {
            return Err(FormatError::StrandTruncated {
                strand: s,
                count: 0,
                offset: at as u64,
                need: 4,
                have: (b.len() - at) as u64,
            });
        }
        let n = count(at, "vertex")?;
        let (need, have) = (n * stride, (b.len() - at - 4) as u64);
        if need > have {
            return Err(FormatError::StrandTruncated {
                strand: s,
                count: n,
                offset: at as u64,
                need,
                have,
            });
        }
        at += 4;
        pts.clear();
        pts.extend((0..n as usize).map(|v| vec3_at(b, at + stride as usize * v)));
        hair.push_strand(&pts)?;
        at += need as usize;
    }
    if at != b.len() {
        return Err(FormatError::TrailingBytes {
            offset: at as u64,
            left: (b.len() - at) as u64,
            strands,
        });
    }
    Ok(hair)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Writes a USC-HairSalon file by the format's description.
    fn usc_file(strands: &[&[[f32; 3]]]) -> Vec<u8> {
        let mut b = (strands.len() as i32).to_le_bytes().to_vec();
        for s in strands {
            b.extend_from_slice(&(s.len() as i32).to_le_bytes());
            for p in *s {
                for c in p {
                    b.extend_from_slice(&c.to_le_bytes());
                }
            }
        }
        b
    }

    #[test]
    fn reads_usc_data_with_root_only_strands_and_refuses_what_does_not_fit() {
        let a: &[[f32; 3]] = &[[0.0, 1.0, 2.0], [0.5, -1.0, 2.0], [1.0, -3.0, 2.5]];
        let root: &[[f32; 3]] = &[[9.0, 9.0, 9.0]];
        let f = usc_file(&[a, root, &a[..2]]);
        let h = parse_usc_data(&f).unwrap();
        assert_eq!((h.strand_count(), h.point_count()), (3, 6));
        assert_eq!(h.offsets(), &[0, 3, 4, 6]);
        assert_eq!(h.points()[1], Vec3::new(0.5, -1.0, 2.0));
        assert_eq!(h.points()[3], Vec3::new(9.0, 9.0, 9.0));
        assert_eq!(parse_usc_data(&usc_file(&[])).unwrap().strand_count(), 0);
        // Cut inside the last strand's vertices: names strand 2 and its byte.
        let cut = &f[..f.len() - 1];
        assert_eq!(
            parse_usc_data(cut),
            Err(FormatError::StrandTruncated {
                strand: 2,
                count: 2,
                offset: 4 + (4 + 36) + (4 + 12),
                need: 24,
                have: 23,
            })
        );
        // A count of 2^31 - 1 strands in 16 bytes, a negative vertex count,
        // a byte too many, too short for a count.
        let mut lying = usc_file(&[root]);
        lying[..4].copy_from_slice(&i32::MAX.to_le_bytes());
        assert!(matches!(
            parse_usc_data(&lying),
            Err(FormatError::Truncated { .. })
        ));
        let mut negative = usc_file(&[root]);
        negative[4..8].copy_from_slice(&(-3i32).to_le_bytes());
        assert_eq!(
            parse_usc_data(&negative),
            Err(FormatError::NegativeCount {
                what: "vertex",
                count: -3,
                offset: 4
            })
        );
        let mut extra = f.clone();
        extra.push(0);
        assert!(matches!(
            parse_usc_data(&extra),
            Err(FormatError::TrailingBytes {
                left: 1,
                strands: 3,
                ..
            })
        ));
        assert!(matches!(
            parse_usc_data(&[1, 0]),
            Err(FormatError::TruncatedHeader { .. })
        ));
        let mut nan = usc_file(&[a]);
        nan[8..12].copy_from_slice(&f32::NAN.to_le_bytes());
        assert!(matches!(parse_usc_data(&nan), Err(FormatError::Hair(_))));
    }

    /// Writes a HAIR file by the format's description (independent of the parser).
    fn hair_file(
        segments: Option<&[u16]>,
        points: &[[f32; 3]],
        colors: Option<&[[f32; 3]]>,
        strands: u32,
        default_seg: u32,
    ) -> Vec<u8> {
        let mut b = Vec::new();
        b.extend_from_slice(b"HAIR");
        b.extend_from_slice(&strands.to_le_bytes());
        b.extend_from_slice(&(points.len() as u32).to_le_bytes());
        let flags =
            2 | if segments.is_some() { 1 } else { 0 } | if colors.is_some() { 16 } else { 0 };
        b.extend_from_slice(&(flags as u32).to_le_bytes());
        b.extend_from_slice(&default_seg.to_le_bytes());
        for f in [0.1f32, 1.0, 0.5, 0.25, 0.125] {
            b.extend_from_slice(&f.to_le_bytes());
        }
        b.resize(128, 0);
        for s in segments.unwrap_or(&[]) {
            b.extend_from_slice(&s.to_le_bytes());
        }
        for p in points.iter().flatten() {
            b.extend_from_slice(&p.to_le_bytes());
        }
        for c in colors.unwrap_or(&[]).iter().flatten() {
            b.extend_from_slice(&c.to_le_bytes());
        }
        b
    }

    const PTS: [[f32; 3]; 5] = [
        [0.0, 0.0, 0.0],
        [0.0, -1.0, 0.0],
        [0.0, -2.0, 0.0],
        [1.0, 0.0, 0.0],
        [1.0, -1.0, 0.0],
    ];

    #[test]
    fn reads_segments_points_and_root_colours() {
        let cols = [
            [1.0, 0.0, 0.0],
            [0.0; 3],
            [0.0; 3],
            [0.0, 1.0, 0.0],
            [0.0; 3],
        ];
        let h = parse_hair_format(&hair_file(Some(&[2, 1]), &PTS, Some(&cols), 2, 0)).unwrap();
        assert_eq!(h.strand_count(), 2);
        assert_eq!(h.strand(0).len(), 3);
        assert_eq!(h.strand(1), &[Vec3::X, Vec3::new(1.0, -1.0, 0.0)]);
        assert_eq!(h.colors().unwrap(), &[Vec3::X, Vec3::Y]);
    }

    #[test]
    fn default_segment_count_applies_without_segment_array() {
        let pts = &PTS[..4];
        let h = parse_hair_format(&hair_file(None, pts, None, 2, 1)).unwrap();
        assert_eq!(h.strand_count(), 2);
        assert_eq!(h.segment_count(), 2);
        assert!(h.colors().is_none());
    }

    #[test]
    fn refuses_wrong_magic_truncation_and_bad_counts() {
        let mut f = hair_file(Some(&[2, 1]), &PTS, None, 2, 0);
        f[0] = b'X';
        assert!(matches!(
            parse_hair_format(&f),
            Err(FormatError::BadMagic { .. })
        ));
        // Shown as text, with a guess at what the file is.
        f[..4].copy_from_slice(b"ply\n");
        let e = parse_hair_format(&f).unwrap_err().to_string();
        assert_eq!(e, "wrong magic \"ply\\n\" (a PLY file?), expected \"HAIR\"");
        f[..4].copy_from_slice(&[0, 0, 0x80, 0x40]);
        let e = parse_hair_format(&f).unwrap_err().to_string();
        assert_eq!(e, "wrong magic \"\\x00\\x00\\x80@\", expected \"HAIR\"");

        let f = hair_file(Some(&[2, 1]), &PTS, None, 2, 0);
        assert!(matches!(
            parse_hair_format(&f[..100]),
            Err(FormatError::TruncatedHeader { .. })
        ));
        assert!(matches!(
            parse_hair_format(&f[..f.len() - 1]),
            Err(FormatError::Truncated { .. })
        ));

        let f = hair_file(Some(&[2, 2]), &PTS, None, 2, 0);
        assert_eq!(
            parse_hair_format(&f),
            Err(FormatError::CountMismatch { sum: 6, points: 5 })
        );
    }

    #[test]
    fn a_lying_header_is_refused_before_allocating() {
        let mut f = hair_file(Some(&[2, 1]), &PTS, None, 2, 0);
        f[4..8].copy_from_slice(&u32::MAX.to_le_bytes());
        f[8..12].copy_from_slice(&u32::MAX.to_le_bytes());
        assert!(matches!(
            parse_hair_format(&f),
            Err(FormatError::Truncated { .. })
        ));
        // Without a segment array, strands * (default + 1) may overflow u32 arithmetic.
        let mut f = hair_file(None, &PTS[..4], None, 2, 1);
        f[4..8].copy_from_slice(&u32::MAX.to_le_bytes());
        f[16..20].copy_from_slice(&u32::MAX.to_le_bytes());
        assert!(matches!(
            parse_hair_format(&f),
            Err(FormatError::CountMismatch { .. })
        ));
    }

    #[test]
    fn refuses_non_finite_coordinates() {
        let mut pts = PTS;
        pts[4][1] = f32::INFINITY;
        let err = parse_hair_format(&hair_file(Some(&[2, 1]), &pts, None, 2, 0)).unwrap_err();
        assert_eq!(
            err.to_string(),
            "strand 1, point 1: coordinate (1, inf, 0) is not finite"
        );
    }

    fn tfx_file(strands: u32, per: u32, pts: &[[f32; 4]]) -> Vec<u8> {
        let mut b = Vec::new();
        b.extend_from_slice(&4.0f32.to_le_bytes());
        b.extend_from_slice(&strands.to_le_bytes());
        b.extend_from_slice(&per.to_le_bytes());
        b.extend_from_slice(&160u32.to_le_bytes());
        b.resize(160, 0);
        for p in pts.iter().flatten() {
            b.extend_from_slice(&p.to_le_bytes());
        }
        b
    }

    #[test]
    fn reads_tfx_and_refuses_truncation() {
        let pts = [
            [0.0, 0.0, 0.0, 0.0],
            [0.0, -1.0, 0.0, 1.0],
            [2.0, 0.0, 0.0, 0.0],
            [2.0, -1.0, 0.0, 1.0],
        ];
        let h = parse_tfx(&tfx_file(2, 2, &pts)).unwrap();
        assert_eq!(h.strand_count(), 2);
        assert_eq!(h.strand(1)[0], Vec3::new(2.0, 0.0, 0.0));
        let f = tfx_file(2, 2, &pts);
        assert!(matches!(
            parse_tfx(&f[..f.len() - 4]),
            Err(FormatError::Truncated { .. })
        ));
        assert!(matches!(
            parse_tfx(&tfx_file(u32::MAX, u32::MAX, &pts)),
            Err(FormatError::Truncated { .. })
        ));
        let mut f = tfx_file(2, 2, &pts);
        f[0..4].copy_from_slice(&3.0f32.to_le_bytes());
        assert_eq!(parse_tfx(&f), Err(FormatError::TfxVersion(3.0)));
    }
}
