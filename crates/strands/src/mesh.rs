//! Triangle meshes for heads and bodies, and a Wavefront OBJ reader.

use std::path::{Path, PathBuf};

use glam::{Affine3A, Vec3};

use crate::Bounds;

/// The most vertices or triangles a mesh may have (a head needs thousands).
pub const MAX_MESH_ELEMENTS: usize = 1 << 24;

/// A triangle mesh: positions, one unit normal per vertex (area-weighted
/// average of the faces around it, so that a tessellated sphere shades
/// like a sphere) and triangles as index triples, counter-clockwise or not
/// (nothing here depends on winding).
#[derive(Debug, Clone, PartialEq)]
pub struct Mesh {
    positions: Vec<Vec3>,
    normals: Vec<Vec3>,
    triangles: Vec<[u32; 3]>,
}

/// Why a mesh cannot be made or read.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum MeshError {
    #[error("vertex {index} is not finite: {point}")]
    NonFinite { index: usize, point: Vec3 },
    #[error("triangle {triangle} names vertex {index}, but there are {vertices}")]
    BadIndex {
        triangle: usize,
        index: u64,
        vertices: usize,
    },
    #[error("no triangles")]
    Empty,
    #[error("more than {MAX_MESH_ELEMENTS} {what}")]
    TooLarge { what: &'static str },
    #[error("line {line}: {detail}")]
    Obj { line: usize, detail: String },
}

/// Why an OBJ file cannot be loaded.
#[derive(Debug, thiserror::Error)]
pub enum MeshLoadError {
    #[error("cannot read {}: {cause}", path.display())]
    Io {
        path: PathBuf,
        cause: std::io::Error,
    },
    #[error("{}: {cause}", path.display())]
    Format { path: PathBuf, cause: MeshError },
}

impl Mesh {
    /// A mesh of `positions` and `triangles`; refuses non-finite positions,
    /// indices out of range and an empty triangle list.
    pub fn new(positions: Vec<Vec3>, triangles: Vec<[u32; 3]>) -> Result<Mesh, MeshError> {
        if positions.len() > MAX_MESH_ELEMENTS {
            return Err(MeshError::TooLarge { what: "vertices" });
        }
        if triangles.len() > MAX_MESH_ELEMENTS {
            return Err(MeshError::TooLarge { what: "triangles" });
        }
        if let Some((index, &point)) = positions.iter().enumerate().find(|(_, p)| !p.is_finite()) {
            return Err(MeshError::NonFinite { index, point });
        }
        if triangles.is_empty() {
            return Err(MeshError::Empty);
        }
        for (t, tri) in triangles.iter().enumerate() {
            if let Some(&i) = tri.iter().find(|&&i| i as usize >= positions.len()) {
                return Err(MeshError::BadIndex {
                    triangle: t,
                    index: u64::from(i),
                    vertices: positions.len(),
                });
            }
        }
        let normals = vertex_normals(&positions, &triangles);
        Ok(Mesh {
            positions,
            normals,
            triangles,
        })
    }

    pub fn positions(&self) -> &[Vec3] {
        &self.positions
    }

    /// Unit normals, one per vertex.
    pub fn normals(&self) -> &[Vec3] {
        &self.normals
    }

    pub fn triangles(&self) -> &[[u32; 3]] {
        &self.triangles
    }

    /// The triangle's three corners.
    #[inline]
    pub fn corners(&self, t: usize) -> [Vec3; 3] {
        self.triangles[t].map(|i| self.positions[i as usize])
    }

    pub fn bounds(&self) -> Bounds {
        Bounds::of(&self.positions)
    }

    /// The mesh moved by `m`, a rigid motion with uniform scale (normals
    /// are turned by `m` and renormalized, which is exact for such maps).
    pub fn transformed(&self, m: Affine3A) -> Mesh {
        Mesh {
            positions: self
                .positions
                .iter()
                .map(|&p| m.transform_point3(p))
                .collect(),
            normals: self
                .normals
                .iter()
                .map(|&n| m.transform_vector3(n).normalize_or_zero())
                .collect(),
            triangles: self.triangles.clone(),
        }
    }
}

/// Area-weighted vertex normals: the sum of the (unnormalized) cross
/// products of the triangles around a vertex, oriented consistently
/// outwards for a closed mesh of consistent winding. A vertex whose faces
/// cancel out (or that no face uses) gets the direction from the mesh's
/// centroid, which is outwards for star-shaped heads.
fn vertex_normals(positions: &[Vec3], triangles: &[[u32; 3]]) -> Vec<Vec3> {
    let mut sum = vec![Vec3::ZERO; positions.len()];
    for t in triangles {
        let [a, b, c] = t.map(|i| positions[i as usize]);
        let n = (b - a).cross(c - a);
        for &i in t {
            sum[i as usize] += n;
        }
    }
    let centroid = positions.iter().copied().sum::<Vec3>() / positions.len().max(1) as f32;
    // Winding decides the sign of the sums: turn them all outwards if most
    // point inwards (a mesh wound clockwise).
    let outward: f64 = sum
        .iter()
        .zip(positions)
        .map(|(n, p)| f64::from(n.dot(*p - centroid)))
        .sum();
    let sign = if outward < 0.0 { -1.0 } else { 1.0 };
    sum.iter()
        .zip(positions)
        .map(|(&n, &p)| {
            let n = (sign * n).normalize_or_zero();
            if n == Vec3::ZERO {
                (p - centroid).normalize_or(Vec3::Y)
            } else {
                n
            }
        })
        .collect()
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

/// Parses OBJ text (see [`load_obj`]).
pub fn parse_obj(bytes: &[u8]) -> Result<Mesh, MeshError> {
    let text = std::str::from_utf8(bytes).map_err(|e| MeshError::Obj {
        line: bytes[..e.valid_up_to()]
            .iter()
            .filter(|&&b| b == b'\n')
            .count()
            + 1,
        detail: "not UTF-8 text".into(),
    })?;
    let mut positions: Vec<Vec3> = Vec::new();
    let mut triangles: Vec<[u32; 3]> = Vec::new();
    let mut face: Vec<u32> = Vec::new();
    for (l, raw) in text.lines().enumerate() {
        let line = l + 1;
        let err = |detail: String| MeshError::Obj { line, detail };
        let content = raw.split('#').next().unwrap_or("");
        let mut words = content.split_whitespace();
        match words.next() {
            Some("v") => {
                let mut c = [0.0f32; 3];
                for (axis, c) in c.iter_mut().enumerate() {
                    let w = words
                        .next()
                        .ok_or_else(|| err(format!("vertex has {axis} coordinates, needs 3")))?;
                    *c = w
                        .parse()
                        .map_err(|_| err(format!("vertex coordinate {w:?} is not a number")))?;
                    if !c.is_finite() {
                        return Err(err(format!("vertex coordinate {w:?} is not finite")));
                    }
                }
                // A fourth (w) coordinate or vertex colours may follow.
                if positions.len() == MAX_MESH_ELEMENTS {
                    return Err(MeshError::TooLarge { what: "vertices" });
                }
                positions.push(Vec3::from_array(c));
            }
            Some("f") => {
                face.clear();
                for w in words {
                    let first = w.split('/').next().unwrap_or("");
                    let i: i64 = first
                        .parse()
                        .map_err(|_| err(format!("face index {w:?} is not an integer")))?;
                    let count = positions.len() as i64;
                    // 1-based, or negative: relative to the vertices so far.
                    let index = if i > 0 { i - 1 } else { count + i };
                    if i == 0 || index < 0 || index >= count {
                        return Err(err(format!(
                            "face index {i} names no vertex ({count} so far)"
                        )));
                    }
                    face.push(index as u32);
                }
                if face.len() < 3 {
                    return Err(err(format!("face has {} vertices, needs 3", face.len())));
                }
                for t in 1..face.len() - 1 {
                    if triangles.len() == MAX_MESH_ELEMENTS {
                        return Err(MeshError::TooLarge { what: "triangles" });
                    }
                    triangles.push([face[0], face[t], face[t + 1]]);
                }
            }
            // Comments, normals, texture coordinates, groups, materials,
            // smoothing groups, lines and points.
            _ => {}
        }
    }
    Mesh::new(positions, triangles)
}

#[cfg(test)]
mod tests {
    use super::*;

    const SQUARE: &str =
        "# a unit square\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvn 0 0 1\nf 1//1 2//1 3//1 4//1\n";

    #[test]
    fn reads_polygons_as_fans_and_every_index_form() {
        let m = parse_obj(SQUARE.as_bytes()).unwrap();
        assert_eq!(m.triangles(), &[[0, 1, 2], [0, 2, 3]]);
        let rel = parse_obj(b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf -3/1 -2/2/2 -1\n").unwrap();
        assert_eq!(rel.triangles(), &[[0, 1, 2]]);
        // Counter-clockwise seen from +z: normals along +z.
        for n in m.normals() {
            assert!((*n - Vec3::Z).length() < 1e-6, "{n}");
        }
    }

    #[test]
    fn names_the_line_of_what_is_wrong() {
        let bad = |text: &str| parse_obj(text.as_bytes()).unwrap_err().to_string();
        assert_eq!(
            bad("v 0 0 0\nv 1 x 0\n"),
            "line 2: vertex coordinate \"x\" is not a number"
        );
        assert_eq!(bad("v 0 0\n"), "line 1: vertex has 2 coordinates, needs 3");
        assert_eq!(
            bad("v 0 0 nan\n"),
            "line 1: vertex coordinate \"nan\" is not finite"
        );
        assert_eq!(
            bad("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n"),
            "line 4: face index 4 names no vertex (3 so far)"
        );
        assert_eq!(
            bad("v 0 0 0\nv 1 0 0\nf 1 2\n"),
            "line 3: face has 2 vertices, needs 3"
        );
        assert_eq!(
            bad("v 0 0 0\nf 0 1 1\n"),
            "line 2: face index 0 names no vertex (1 so far)"
        );
        assert_eq!(bad("v 0 0 0\n"), "no triangles");
        assert_eq!(
            parse_obj(b"v 0 0 0\n\xff\xfe").unwrap_err().to_string(),
            "line 2: not UTF-8 text"
        );
    }

    #[test]
    fn a_clockwise_sphere_still_has_outward_normals() {
        // An octahedron, wound clockwise seen from outside.
        let p = vec![Vec3::X, -Vec3::X, Vec3::Y, -Vec3::Y, Vec3::Z, -Vec3::Z];
        let ccw = [
            [0, 2, 4],
            [2, 1, 4],
            [1, 3, 4],
            [3, 0, 4],
            [2, 0, 5],
            [1, 2, 5],
            [3, 1, 5],
            [0, 3, 5],
        ];
        for tris in [
            ccw.to_vec(),
            ccw.iter().map(|t| [t[0], t[2], t[1]]).collect(),
        ] {
            let m = Mesh::new(p.clone(), tris).unwrap();
            for (n, q) in m.normals().iter().zip(m.positions()) {
                assert!((*n - *q).length() < 1e-6, "{n} at {q}");
            }
        }
    }

    #[test]
    fn transformed_moves_points_and_turns_normals() {
        let m = parse_obj(SQUARE.as_bytes()).unwrap();
        let t = Affine3A::from_scale_rotation_translation(
            Vec3::splat(2.0),
            glam::Quat::from_rotation_x(std::f32::consts::FRAC_PI_2),
            Vec3::new(5.0, 0.0, 0.0),
        );
        let moved = m.transformed(t);
        assert!((moved.positions()[2] - Vec3::new(7.0, 0.0, 2.0)).length() < 1e-5);
        assert!((moved.normals()[0] - -Vec3::Y).length() < 1e-5);
        assert_eq!(moved.bounds().max.x, 7.0);
    }
}
