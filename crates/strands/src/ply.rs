//! PLY strand sets, as hairutil and CT2Hair write them: a `vertex` element
//! with `x`, `y`, `z`, and which vertices make a strand said either by a
//! `strand` element with a per-strand count (`nsegs`: segments, hairutil's;
//! or `nverts`, `num_vertices`, `vertex_count`: vertices), or by a strand
//! index on every vertex (`strand`, `strand_id`, `strand_index`: each run
//! of equal indices is one strand). ASCII and binary, either byte order;
//! any other elements and properties are read past.
//!
//! Written here rather than with a PLY crate: the one on crates.io keeps
//! every vertex as a map of its properties (hundreds of bytes a point) and
//! sizes its buffers from the header's counts, where every count here is
//! checked against the bytes that are left before anything is allocated.

use glam::Vec3;

use crate::{FormatError, Hair, MAX_MESH_ELEMENTS, Mesh, MeshError};

/// The most header bytes read before `end_header` must have come.
const MAX_HEADER_BYTES: usize = 1 << 20;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn named(s: &str) -> Option<Scalar> {
        Some(match s {
            "char" | "int8" => Scalar::I8,
            "uchar" | "uint8" => Scalar::U8,
            "short" | "int16" => Scalar::I16,
            "ushort" | "uint16" => Scalar::U16,
            "int" | "int32" => Scalar::I32,
            "uint" | "uint32" => Scalar::U32,
            "float" | "float32" => Scalar::F32,
            "double" | "float64" => Scalar::F64,
            _ => return None,
        })
    }

    fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }
}

#[derive(Debug)]
enum Property {
    Scalar(Scalar, String),
    /// The type of the item count, of the items, and the name.
    List(Scalar, Scalar, String),
}

#[derive(Debug)]
struct Element {
    name: String,
    count: u64,
    props: Vec<Property>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Encoding {
    Ascii,
    Little,
    Big,
}

fn bad(msg: impl Into<String>) -> FormatError {
    FormatError::Ply(msg.into())
}

/// Per-strand vertex counts, by property name: how many vertices a count
/// of that name means.
fn strand_count_of(name: &str) -> Option<u64> {
    match name {
        "nsegs" => Some(1),
        "nverts" | "num_vertices" | "vertex_count" => Some(0),
        _ => None,
    }
}

fn is_strand_index(name: &str) -> bool {
    matches!(name, "strand" | "strand_id" | "strand_index")
}

/// The header: the encoding, the elements, and where the data starts.
fn header(b: &[u8]) -> Result<(Encoding, Vec<Element>, usize), FormatError> {
    let head = &b[..b.len().min(MAX_HEADER_BYTES)];
    let mut lines = Vec::new();
    let mut start = 0;
    let mut body = None;
    for (i, &c) in head.iter().enumerate() {
        if c == b'\n' {
            let line = &head[start..i];
            let line = line.strip_suffix(b"\r").unwrap_or(line);
            let text = std::str::from_utf8(line)
                .map_err(|_| bad(format!("header line {} is not text", lines.len() + 1)))?;
            start = i + 1;
            if text.trim() == "end_header" {
                body = Some(start);
                break;
            }
            lines.push(text.to_string());
        }
    }
    let body = body.ok_or_else(|| {
        bad(format!(
            "no end_header line within the first {} bytes",
            head.len()
        ))
    })?;
    if lines.first().map(|l| l.trim()) != Some("ply") {
        return Err(bad("the file does not start with a \"ply\" line"));
    }
    let mut encoding = None;
    let mut elements: Vec<Element> = Vec::new();
    for (n, line) in lines.iter().enumerate().skip(1) {
        let at = |msg: String| bad(format!("header line {}: {msg}", n + 1));
        let words: Vec<&str> = line.split_ascii_whitespace().collect();
        match words.as_slice() {
            [] | ["comment", ..] | ["obj_info", ..] => {}
            ["format", f, _version] => {
                encoding = Some(match *f {
                    "ascii" => Encoding::Ascii,
                    "binary_little_endian" => Encoding::Little,
                    "binary_big_endian" => Encoding::Big,
                    other => return Err(at(format!("unknown format {other:?}"))),
                });
            }
            ["element", name, count] => {
                let count = count
                    .parse::<u64>()
                    .map_err(|_| at(format!("element {name}: count {count:?}")))?;
                if elements.len() >= 64 {
                    return Err(at("more than 64 elements".into()));
                }
                elements.push(Element {
                    name: name.to_string(),
                    count,
                    props: Vec::new(),
                });
            }
            ["property", "list", c, t, name] => {
                let e = elements
                    .last_mut()
                    .ok_or_else(|| at("a property before any element".into()))?;
                let (Some(c), Some(t)) = (Scalar::named(c), Scalar::named(t)) else {
                    return Err(at(format!("list property {name}: unknown types {c} {t}")));
                };
                if matches!(c, Scalar::F32 | Scalar::F64) {
                    return Err(at(format!("list property {name}: a count of type {c:?}")));
                }
                e.props.push(Property::List(c, t, name.to_string()));
            }
            ["property", t, name] => {
                let e = elements
                    .last_mut()
                    .ok_or_else(|| at("a property before any element".into()))?;
                let t = Scalar::named(t)
                    .ok_or_else(|| at(format!("property {name}: unknown type {t}")))?;
                e.props.push(Property::Scalar(t, name.to_string()));
            }
            _ => return Err(at(format!("not a PLY header line: {line:?}"))),
        }
        if elements.last().is_some_and(|e| e.props.len() > 256) {
            return Err(at("more than 256 properties in one element".into()));
        }
    }
    let encoding = encoding.ok_or_else(|| bad("the header has no format line"))?;
    Ok((encoding, elements, body))
}

/// Reads values from the data after the header.
struct Reader<'a> {
    b: &'a [u8],
    at: usize,
    encoding: Encoding,
    /// ASCII: the line of the token read last.
    line: u64,
}

impl Reader<'_> {
    fn left(&self) -> u64 {
        (self.b.len() - self.at) as u64
    }

    fn value(&mut self, t: Scalar, what: &dyn Fn() -> String) -> Result<f64, FormatError> {
        if self.encoding == Encoding::Ascii {
            return self.token(t, what);
        }
        let n = t.size();
        if self.b.len() - self.at < n {
            return Err(bad(format!(
                "byte {}: the file ends inside {}",
                self.at,
                what()
            )));
        }
        let mut raw = [0u8; 8];
        raw[..n].copy_from_slice(&self.b[self.at..self.at + n]);
        if self.encoding == Encoding::Big {
            raw[..n].reverse();
        }
        self.at += n;
        // Little-endian now, whatever the file's order.
        let four: [u8; 4] = raw[..4].try_into().expect("4 bytes");
        Ok(match t {
            Scalar::I8 => f64::from(raw[0] as i8),
            Scalar::U8 => f64::from(raw[0]),
            Scalar::I16 => f64::from(i16::from_le_bytes([raw[0], raw[1]])),
            Scalar::U16 => f64::from(u16::from_le_bytes([raw[0], raw[1]])),
            Scalar::I32 => f64::from(i32::from_le_bytes(four)),
            Scalar::U32 => f64::from(u32::from_le_bytes(four)),
            Scalar::F32 => f64::from(f32::from_le_bytes(four)),
            Scalar::F64 => f64::from_le_bytes(raw),
        })
    }

    fn token(&mut self, t: Scalar, what: &dyn Fn() -> String) -> Result<f64, FormatError> {
        while self.at < self.b.len() && self.b[self.at].is_ascii_whitespace() {
            if self.b[self.at] == b'\n' {
                self.line += 1;
            }
            self.at += 1;
        }
        let start = self.at;
        while self.at < self.b.len() && !self.b[self.at].is_ascii_whitespace() {
            self.at += 1;
        }
        if start == self.at {
            return Err(bad(format!(
                "line {}: the file ends inside {}",
                self.line,
                what()
            )));
        }
        let text = std::str::from_utf8(&self.b[start..self.at]).unwrap_or("");
        let v = if matches!(t, Scalar::F32 | Scalar::F64) {
            text.parse::<f64>().ok()
        } else {
            text.parse::<i64>().ok().map(|v| v as f64)
        };
        v.ok_or_else(|| {
            bad(format!(
                "line {}: {text:?} is not a number of type {t:?}, in {}",
                self.line,
                what()
            ))
        })
    }
}

/// The name of a property.
fn name_of(p: &Property) -> &str {
    match p {
        Property::Scalar(_, n) | Property::List(_, _, n) => n,
    }
}

/// Reads element `e`'s items, calling `item(index, values, list)` for
/// each with every scalar property's value (a list's slot holds its
/// length) and the items of the list property at `list_at`, when given.
/// The item count is checked against the bytes left before any is read,
/// and each list's length before its items.
fn read_items(
    r: &mut Reader,
    e: &Element,
    list_at: Option<usize>,
    mut item: impl FnMut(u64, &[f64], &[f64]) -> Result<(), FormatError>,
) -> Result<(), FormatError> {
    // Every item takes a byte at least (binary: its fixed part).
    let fixed: u64 = e
        .props
        .iter()
        .map(|p| match p {
            Property::Scalar(t, _) => t.size() as u64,
            Property::List(c, _, _) => c.size() as u64,
        })
        .sum::<u64>()
        .max(1);
    let per_item = if r.encoding == Encoding::Ascii {
        e.props.len().max(1) as u64
    } else {
        fixed
    };
    if e.count.saturating_mul(per_item) > r.left() {
        return Err(bad(format!(
            "element {} claims {} items, needing {} bytes at least, but {} remain",
            e.name,
            e.count,
            e.count.saturating_mul(per_item),
            r.left()
        )));
    }
    let mut vals = vec![0.0f64; e.props.len()];
    let mut list = Vec::new();
    for i in 0..e.count {
        for (k, p) in e.props.iter().enumerate() {
            let what = || format!("{} {i}, property {}", e.name, name_of(p));
            match p {
                Property::Scalar(t, _) => vals[k] = r.value(*t, &what)?,
                Property::List(c, t, _) => {
                    let len = r.value(*c, &what)?;
                    if !(0.0..=r.left() as f64).contains(&len) {
                        return Err(bad(format!("{}: a list of {len} items", what())));
                    }
                    vals[k] = len;
                    let keep = list_at == Some(k);
                    if keep {
                        list.clear();
                    }
                    for _ in 0..len as u64 {
                        let v = r.value(*t, &what)?;
                        if keep {
                            list.push(v);
                        }
                    }
                }
            }
        }
        item(i, &vals, &list)?;
    }
    Ok(())
}

/// The header read and a reader at the data after it.
fn open(b: &[u8]) -> Result<(Vec<Element>, Reader<'_>), FormatError> {
    let (encoding, elements, body) = header(b)?;
    let lines_in_header = b[..body].iter().filter(|&&c| c == b'\n').count() as u64;
    let r = Reader {
        b,
        at: body,
        encoding,
        line: lines_in_header + 1,
    };
    Ok((elements, r))
}

/// Binary data must end with the last element.
fn check_end(r: &Reader) -> Result<(), FormatError> {
    if r.encoding != Encoding::Ascii && r.at != r.b.len() {
        return Err(bad(format!(
            "byte {}: {} bytes left over after the last element",
            r.at,
            r.b.len() - r.at
        )));
    }
    Ok(())
}

/// The index of the scalar property named `want`.
fn scalar_at(e: &Element, want: impl Fn(&str) -> bool) -> Option<usize> {
    e.props
        .iter()
        .position(|p| matches!(p, Property::Scalar(_, n) if want(n)))
}

/// The `x`, `y`, `z` properties of a vertex element.
fn xyz_of(e: &Element) -> Result<[usize; 3], FormatError> {
    match (
        scalar_at(e, |n| n == "x"),
        scalar_at(e, |n| n == "y"),
        scalar_at(e, |n| n == "z"),
    ) {
        (Some(x), Some(y), Some(z)) => Ok([x, y, z]),
        _ => Err(bad("the vertex element has no x, y and z")),
    }
}

fn point(vals: &[f64], [x, y, z]: [usize; 3]) -> Vec3 {
    Vec3::new(vals[x] as f32, vals[y] as f32, vals[z] as f32)
}

/// Parses a PLY strand set (see the module docs).
pub fn parse_ply_strands(b: &[u8]) -> Result<Hair, FormatError> {
    let (elements, mut r) = open(b)?;
    let mut points: Option<Vec<Vec3>> = None;
    let mut index: Option<Vec<f64>> = None;
    let mut counts: Option<Vec<u64>> = None;
    for e in &elements {
        let n = e.count.min(r.left()) as usize;
        if e.name == "vertex" {
            let xyz = xyz_of(e)?;
            let strand_at = scalar_at(e, is_strand_index);
            let mut pts = Vec::with_capacity(n);
            let mut idx = Vec::with_capacity(if strand_at.is_some() { n } else { 0 });
            read_items(&mut r, e, None, |_, vals, _| {
                pts.push(point(vals, xyz));
                if let Some(s) = strand_at {
                    idx.push(vals[s]);
                }
                Ok(())
            })?;
            points = Some(pts);
            index = strand_at.map(|_| idx);
            continue;
        }
        let count_at = (e.name == "strand")
            .then(|| {
                e.props.iter().enumerate().find_map(|(i, p)| match p {
                    Property::Scalar(_, n) => strand_count_of(n).map(|extra| (i, extra)),
                    _ => None,
                })
            })
            .flatten();
        let mut cnt = Vec::with_capacity(if count_at.is_some() { n } else { 0 });
        read_items(&mut r, e, None, |item, vals, _| {
            if let Some((c, extra)) = count_at {
                let v = vals[c];
                if !(v >= 0.0 && v.fract() == 0.0) {
                    return Err(bad(format!("strand {item}: a vertex count of {v}")));
                }
                cnt.push(v as u64 + extra);
            }
            Ok(())
        })?;
        if count_at.is_some() {
            counts = Some(cnt);
        }
    }
    check_end(&r)?;
    let points = points.ok_or_else(|| bad("no vertex element"))?;
    let mut hair = Hair::with_capacity(0, points.len());
    match (counts, index) {
        (Some(counts), _) => {
            let sum = counts.iter().try_fold(0u64, |a, &c| a.checked_add(c));
            if sum != Some(points.len() as u64) {
                return Err(bad(format!(
                    "the strands' counts add up to {} vertices, but the file has {}",
                    sum.map_or_else(|| "more than 2^64".to_string(), |s| s.to_string()),
                    points.len()
                )));
            }
            let mut at = 0usize;
            for c in counts {
                hair.push_strand(&points[at..at + c as usize])?;
                at += c as usize;
            }
        }
        (None, Some(index)) => {
            let mut start = 0;
            for i in 1..=points.len() {
                if i == points.len() || index[i] != index[start] {
                    hair.push_strand(&points[start..i])?;
                    start = i;
                }
            }
        }
        (None, None) => {
            return Err(bad(
                "which vertices make a strand is not said: no strand element with nsegs \
                 (or nverts) and no strand index on the vertices",
            ));
        }
    }
    Ok(hair)
}

/// Parses a PLY triangle mesh (a head): a `vertex` element with `x`, `y`,
/// `z` and a `face` element with a `vertex_indices` (or `vertex_index`)
/// list, ASCII or binary; polygons are split into fans, other elements and
/// properties are read past.
pub fn parse_ply_mesh(b: &[u8]) -> Result<Mesh, MeshError> {
    let ply = |e: FormatError| match e {
        FormatError::Ply(m) => MeshError::Ply(m),
        other => MeshError::Ply(other.to_string()),
    };
    let (elements, mut r) = open(b).map_err(ply)?;
    let mut positions: Option<Vec<Vec3>> = None;
    let mut triangles: Option<Vec<[u32; 3]>> = None;
    for e in &elements {
        let n = e.count.min(r.left()) as usize;
        if e.name == "vertex" {
            let xyz = xyz_of(e).map_err(ply)?;
            if n > MAX_MESH_ELEMENTS {
                return Err(MeshError::TooLarge { what: "vertices" });
            }
            let mut pts = Vec::with_capacity(n);
            read_items(&mut r, e, None, |_, vals, _| {
                pts.push(point(vals, xyz));
                Ok(())
            })
            .map_err(ply)?;
            positions = Some(pts);
            continue;
        }
        let list_at = (e.name == "face")
            .then(|| {
                e.props.iter().position(|p| {
                    matches!(p, Property::List(_, _, n) if n == "vertex_indices" || n == "vertex_index")
                })
            })
            .flatten();
        if e.name == "face" && list_at.is_none() {
            return Err(MeshError::Ply(
                "the face element has no vertex_indices list".into(),
            ));
        }
        let mut tris = Vec::with_capacity(n.min(MAX_MESH_ELEMENTS));
        let mut too_many = false;
        read_items(&mut r, e, list_at, |face, _, list| {
            if list_at.is_none() {
                return Ok(());
            }
            if list.len() < 3 {
                return Err(bad(format!(
                    "face {face} has {} corners, fewer than 3",
                    list.len()
                )));
            }
            let corner = |v: f64| {
                if v >= 0.0 && v.fract() == 0.0 && v <= f64::from(u32::MAX) {
                    Ok(v as u32)
                } else {
                    Err(bad(format!("face {face}: vertex index {v}")))
                }
            };
            // A fan around the first corner.
            let first = corner(list[0])?;
            for w in list[1..].windows(2) {
                if tris.len() >= MAX_MESH_ELEMENTS {
                    too_many = true;
                    return Err(bad("too many triangles"));
                }
                tris.push([first, corner(w[0])?, corner(w[1])?]);
            }
            Ok(())
        })
        .map_err(|e| {
            if too_many {
                MeshError::TooLarge { what: "triangles" }
            } else {
                ply(e)
            }
        })?;
        if list_at.is_some() {
            triangles = Some(tris);
        }
    }
    check_end(&r).map_err(ply)?;
    let positions = positions.ok_or_else(|| MeshError::Ply("no vertex element".into()))?;
    let triangles = triangles.ok_or_else(|| MeshError::Ply("no face element".into()))?;
    Mesh::new(positions, triangles)
}

#[cfg(test)]
mod tests {
    use super::*;

    const ASCII: &str = "ply\nformat ascii 1.0\ncomment two strands\nelement vertex 5\n\
        property float x\nproperty float y\nproperty float z\nproperty uchar red\n\
        element strand 2\nproperty ushort nsegs\nend_header\n\
        0 0 0 9\n0 -1 0 9\n0 -2 0 9\n1 0 0 9\n1 -1 0 9\n2\n1\n";

    fn binary(big: bool) -> Vec<u8> {
        let order = if big { "big" } else { "little" };
        let mut b = format!(
            "ply\r\nformat binary_{order}_endian 1.0\r\nelement vertex 5\r\n\
             property float x\r\nproperty float y\r\nproperty float z\r\n\
             property int strand_id\r\nelement edge 1\r\nproperty list uchar int vertex_index\r\n\
             end_header\r\n"
        )
        .into_bytes();
        let pts = [
            [0.0f32, 0.0, 0.0],
            [0.0, -1.0, 0.0],
            [0.0, -2.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, -1.0, 0.0],
        ];
        for (i, p) in pts.iter().enumerate() {
            for v in p {
                b.extend(if big {
                    v.to_be_bytes()
                } else {
                    v.to_le_bytes()
                });
            }
            let s = i32::from(i >= 3) + 7;
            b.extend(if big {
                s.to_be_bytes()
            } else {
                s.to_le_bytes()
            });
        }
        b.push(2);
        for v in [0i32, 1] {
            b.extend(if big {
                v.to_be_bytes()
            } else {
                v.to_le_bytes()
            });
        }
        b
    }

    #[test]
    fn ascii_counts_and_binary_indices_give_the_same_strands() {
        let a = parse_ply_strands(ASCII.as_bytes()).unwrap();
        assert_eq!(a.offsets(), &[0, 3, 5]);
        assert_eq!(
            a.strand(1),
            &[Vec3::new(1.0, 0.0, 0.0), Vec3::new(1.0, -1.0, 0.0)]
        );
        for big in [false, true] {
            let h = parse_ply_strands(&binary(big)).unwrap();
            assert_eq!(
                (h.points(), h.offsets()),
                (a.points(), a.offsets()),
                "big {big}"
            );
        }
    }

    #[test]
    fn broken_files_name_what_is_wrong() {
        let err = |b: &[u8]| parse_ply_strands(b).unwrap_err().to_string();
        assert!(err(b"ply\nformat ascii 1.0\n").contains("end_header"));
        assert!(err(ASCII.replace("nsegs", "width").as_bytes()).contains("which vertices"));
        assert!(err(ASCII.replace("\n2\n1\n", "\n2\n2\n").as_bytes()).contains("add up to 6"));
        assert!(err(ASCII.replace("1 -1 0 9", "1 -1 x 9").as_bytes()).contains("\"x\""));
        assert!(err(ASCII.replace("vertex 5", "vertex 4000000000").as_bytes()).contains("claims"));
        let mut cut = binary(false);
        cut.truncate(cut.len() - 3);
        assert!(err(&cut).contains("ends inside edge 0"));
        let mut long = binary(true);
        long.push(0);
        assert!(err(&long).contains("left over"));
    }

    /// A unit square of two quads' worth: four corners, one quad face and
    /// one triangle face, with an extra element and property between.
    const SQUARE: &str = "ply\nformat ascii 1.0\nelement vertex 5\nproperty float x\n\
        property float y\nproperty float z\nproperty float nx\nelement face 2\n\
        property uchar flags\nproperty list uchar int vertex_indices\nend_header\n\
        0 0 0 1\n1 0 0 1\n1 1 0 1\n0 1 0 1\n2 2 0 1\n7 4 0 1 2 3\n0 3 1 4 2\n";

    #[test]
    fn a_ply_mesh_is_the_same_mesh_as_its_obj() {
        let m = parse_ply_mesh(SQUARE.as_bytes()).unwrap();
        let obj =
            crate::parse_obj(b"v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 2 2 0\nf 1 2 3 4\nf 2 5 3\n")
                .unwrap();
        assert_eq!(m, obj);
        assert_eq!(m.triangles(), &[[0, 1, 2], [0, 2, 3], [1, 4, 2]]);
        // The same in binary, big-endian, with short indices.
        let mut b = b"ply\nformat binary_big_endian 1.0\nelement vertex 5\nproperty float x\n\
            property float y\nproperty float z\nelement face 2\n\
            property list uchar ushort vertex_index\nend_header\n"
            .to_vec();
        for p in m.positions() {
            for v in p.to_array() {
                b.extend(v.to_be_bytes());
            }
        }
        for face in [&[0u16, 1, 2, 3][..], &[1, 4, 2]] {
            b.push(face.len() as u8);
            for i in face {
                b.extend(i.to_be_bytes());
            }
        }
        assert_eq!(parse_ply_mesh(&b).unwrap(), obj);
    }

    #[test]
    fn broken_meshes_name_what_is_wrong() {
        let err = |t: &str| parse_ply_mesh(t.as_bytes()).unwrap_err().to_string();
        assert!(err(&SQUARE.replace("1 2 3\n", "1 2 9\n")).contains("vertex 9"));
        assert!(err(&SQUARE.replace("0 3 1 4 2", "0 2 1 4")).contains("fewer than 3"));
        assert!(err(&SQUARE.replace("0 3 1 4 2", "0 3 1 -4 2")).contains("index -4"));
        assert!(err(&SQUARE.replace("vertex_indices", "corners")).contains("no vertex_indices"));
        assert!(err(&SQUARE.replace("face 2", "face 2000000000")).contains("claims"));
        let no_faces = "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n\
            property float y\nproperty float z\nend_header\n0 0 0\n";
        assert!(err(no_faces).contains("no face element"));
    }
}
