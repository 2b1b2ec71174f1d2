//! Triangle meshes for heads and bodies, and readers of Wavefront OBJ and
//! (in `ply.rs`) PLY.

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
    /// A vertex with a coordinate that is NaN or infinite.
    #[error("vertex {index} is not finite: {point}")]
    NonFinite {
        /// The vertex.
        index: usize,
        /// Its coordinates.
        point: Vec3,
    },
    /// A triangle naming a vertex that does not exist.
    #[error("triangle {triangle} names vertex {index}, but there are {vertices}")]
    BadIndex {
        /// The triangle.
        triangle: usize,
        /// The vertex it names.
        index: u64,
        /// The vertices there are.
        vertices: usize,
    },
    /// No triangles.
    #[error("no triangles")]
    Empty,
    /// More vertices or faces than `MAX_MESH_ELEMENTS`.
    #[error("more than {MAX_MESH_ELEMENTS} {what}")]
    TooLarge {
        /// Which.
        what: &'static str,
    },
    /// A malformed OBJ line.
    #[error("line {line}: {detail}")]
    Obj {
        /// The line, from 1.
        line: usize,
        /// What is wrong with it.
        detail: String,
    },
    /// A malformed PLY file.
    #[error("PLY: {0}")]
    Ply(String),
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

    /// The vertices, scene units.
    pub fn positions(&self) -> &[Vec3] {
        &self.positions
    }

    /// Unit normals, one per vertex.
    pub fn normals(&self) -> &[Vec3] {
        &self.normals
    }

    /// The triangles, as vertex indices.
    pub fn triangles(&self) -> &[[u32; 3]] {
        &self.triangles
    }

    /// The triangle's three corners.
    #[inline]
    pub fn corners(&self, t: usize) -> [Vec3; 3] {
        self.triangles[t].map(|i| self.positions[i as usize])
    }

    /// The box around every vertex.
    pub fn bounds(&self) -> Bounds {
        Bounds::of(&self.positions)
    }

    /// A sphere for hair to collide with, fitted to the crown of a head
    /// mesh whose up is +y: its centre and radius.
    ///
    /// Kasa's algebraic least-squares fit, `|p|^2 = 2 c . p + k` over the
    /// chosen vertices `p`, linear in the centre `c` and `k`, with
    /// `r^2 = k + |c|^2`: first through the vertices in the top
    /// `CROWN_SHARE` of the mesh's height, then twice through those above
    /// the last fit's centre (the cranium's upper half, whatever hangs
    /// below: a jaw, a neck, shoulders). The radius is then the median
    /// distance of those vertices from the centre. A crown too flat or too
    /// sparse to fit falls back to the bounds' centre and half their
    /// smallest side (their largest, for a flat mesh); `None` for a mesh
    /// of one point.
    pub fn crown_sphere(&self) -> Option<(Vec3, f32)> {
        let b = self.bounds();
        let size = b.size();
        let smallest = [size.x, size.y, size.z]
            .into_iter()
            .filter(|&v| v > 0.0)
            .reduce(f32::min)?;
        let fallback = Some((b.center(), 0.5 * smallest));
        let top = b.max.y;
        let mut pick: Vec<Vec3> = self
            .positions
            .iter()
            .copied()
            .filter(|p| p.y >= top - CROWN_SHARE * b.size().y)
            .collect();
        let mut fit = None;
        for _ in 0..3 {
            let Some((c, _)) = sphere_fit(&pick) else {
                break;
            };
            fit = Some(c);
            let upper: Vec<Vec3> = self
                .positions
                .iter()
                .copied()
                .filter(|p| p.y >= c.y)
                .collect();
            if upper.len() < 10 {
                break;
            }
            pick = upper;
        }
        let Some(c) = fit else {
            return fallback;
        };
        let mut d: Vec<f32> = pick.iter().map(|p| p.distance(c)).collect();
        d.sort_by(f32::total_cmp);
        let r = d[d.len() / 2];
        if c.is_finite() && r.is_finite() && r > 0.0 {
            Some((c, r))
        } else {
            fallback
        }
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

/// The share of a head mesh's height, from the top, that the first fit of
/// [`Mesh::crown_sphere`] goes through.
pub(crate) const CROWN_SHARE: f32 = 0.15;

/// Kasa's least-squares sphere through `points` (see
/// [`Mesh::crown_sphere`]): centre and radius, or `None` for fewer than 10
/// points or points too close to a plane to place a centre.
fn sphere_fit(points: &[Vec3]) -> Option<(Vec3, f32)> {
    if points.len() < 10 {
        return None;
    }
    // About the mean, in f64: the normal equations of rows
    // [2x 2y 2z 1] x = |p|^2.
    let n = points.len() as f64;
    let mean = points.iter().map(|p| p.as_dvec3()).sum::<glam::DVec3>() / n;
    let mut ata = glam::DMat4::ZERO;
    let mut atb = glam::DVec4::ZERO;
    let mut scale = 0.0f64;
    for p in points {
        let q = p.as_dvec3() - mean;
        scale = scale.max(q.length());
        let row = glam::DVec4::new(2.0 * q.x, 2.0 * q.y, 2.0 * q.z, 1.0);
        let rhs = q.length_squared();
        for i in 0..4 {
            *ata.col_mut(i) += row * row[i];
        }
        atb += row * rhs;
    }
    if scale <= 0.0 {
        return None;
    }
    // Conditioned on the points' spread: a flat cap gives a singular
    // system (relative determinant ~0).
    let det = ata.determinant() / (n.powi(4) * scale.powi(6));
    if det.is_nan() || det.abs() <= 1e-9 {
        return None;
    }
    let x = ata.inverse() * atb;
    let c = x.truncate();
    let r2 = x.w + c.length_squared();
    if r2.is_nan() || r2 <= 0.0 {
        return None;
    }
    Some(((c + mean).as_vec3(), r2.sqrt() as f32))
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

/// Parses OBJ text (see [`load_obj`](crate::load_obj)).
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
