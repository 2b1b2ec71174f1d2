//! Opaque bodies that block light: a head as a sphere or a triangle mesh.

use std::sync::Arc;

use glam::Vec3;
use strands::{Bounds, Mesh};

use crate::LightFrame;

/// An opaque body that blocks light (a head), in world coordinates.
#[derive(Debug, Clone, PartialEq)]
pub enum Occluder {
    /// A sphere.
    Sphere {
        /// Centre, scene units.
        center: Vec3,
        /// Radius, scene units.
        radius: f32,
    },
    /// A triangle mesh, as it stands in this frame. A closed mesh blocks
    /// light along any ray that enters it; an open one along rays that
    /// cross it.
    Mesh(Arc<Mesh>),
}

impl Occluder {
    /// A sphere of `radius` at `center`.
    pub fn sphere(center: Vec3, radius: f32) -> Occluder {
        Occluder::Sphere { center, radius }
    }

    /// The body's axis-aligned bounds, so that maps fitted to the hair hold
    /// the body too.
    pub fn bounds(&self) -> Bounds {
        match self {
            Occluder::Sphere { center, radius } => Bounds {
                min: *center - Vec3::splat(*radius),
                max: *center + Vec3::splat(*radius),
            },
            Occluder::Mesh(m) => m.bounds(),
        }
    }

    /// The corners of [`Self::bounds`].
    pub fn corners(&self) -> [Vec3; 8] {
        let b = self.bounds();
        std::array::from_fn(|i| {
            let pick = |bit: usize, lo: f32, hi: f32| if i & bit == 0 { lo } else { hi };
            Vec3::new(
                pick(1, b.min.x, b.max.x),
                pick(2, b.min.y, b.max.y),
                pick(4, b.min.z, b.max.z),
            )
        })
    }

    /// Where the centre line of each `(j, k)` column of `frame` enters the
    /// body: `(k * n + j, x)` with `x` the slice coordinate (in cells, which
    /// may lie outside `0..n`) of the first crossing, for every column the
    /// line crosses, in ascending column order.
    pub fn entries(&self, frame: &LightFrame) -> Vec<(u32, f32)> {
        let n = frame.n_cells as usize;
        match self {
            Occluder::Sphere { center, radius } if frame.fan.is_some() => {
                // Each column's centre ray from the source against the
                // sphere: |s + t e - c|^2 = r^2, the nearer root.
                let s = frame.fan.map_or(Vec3::ZERO, |f| f.source);
                let mut out = Vec::new();
                for k in 0..n {
                    for j in 0..n {
                        let through =
                            frame.to_world(Vec3::new(0.0, j as f32 + 0.5, k as f32 + 0.5));
                        let e = (through - s).normalize();
                        let m = s - *center;
                        let b = m.dot(e);
                        let h2 = b * b - (m.length_squared() - radius * radius);
                        if h2 >= 0.0 {
                            let t = -b - h2.sqrt();
                            out.push(((k * n + j) as u32, frame.to_cells(s + t.max(0.0) * e).x));
                        }
                    }
                }
                out
            }
            Occluder::Sphere { center, radius } => {
                let c = frame.to_cells(*center);
                let r = radius / frame.ds;
                let mut out = Vec::new();
                for k in 0..n {
                    for j in 0..n {
                        // Squared half chord of the column's centre line.
                        let (dy, dz) = (j as f32 + 0.5 - c.y, k as f32 + 0.5 - c.z);
                        let h2 = r * r - dy * dy - dz * dz;
                        if h2 >= 0.0 {
                            out.push(((k * n + j) as u32, c.x - h2.sqrt()));
                        }
                    }
                }
                out
            }
            Occluder::Mesh(mesh) => {
                let mut first = vec![f32::INFINITY; n * n];
                for t in 0..mesh.triangles().len() {
                    let tri = Projected::new(frame, mesh.corners(t));
                    let Some(tri) = tri else { continue };
                    let [j0, j1, k0, k1] = tri.columns(n);
                    for k in k0..k1 {
                        for j in j0..j1 {
                            let at = (j as f32 + 0.5, k as f32 + 0.5);
                            if let Some(x) = tri.depth_at(at) {
                                let e = &mut first[k * n + j];
                                *e = e.min(x);
                            }
                        }
                    }
                }
                first
                    .iter()
                    .enumerate()
                    .filter(|(_, x)| x.is_finite())
                    .map(|(col, &x)| (col as u32, x))
                    .collect()
            }
        }
    }

    /// Whether the ray from `p` towards the light (against `dir`, the
    /// direction light travels) passes through the body. Tests every
    /// triangle of a mesh: for many queries, [`OccluderView`] is faster.
    pub fn blocks(&self, p: Vec3, dir: Vec3) -> bool {
        match self {
            Occluder::Sphere { center, radius } => sphere_blocks(*center, *radius, p, dir),
            Occluder::Mesh(mesh) => (0..mesh.triangles().len()).any(|t| {
                let [a, b, c] = mesh.corners(t);
                ray_hits_triangle(p, -dir, a, b, c)
            }),
        }
    }
}

/// Whether a sphere blocks the ray from `p` against `dir`: `|p - t dir - c|^2 = r^2` for some `t > 0`.
fn sphere_blocks(center: Vec3, radius: f32, p: Vec3, dir: Vec3) -> bool {
    let m = p - center;
    let b = m.dot(dir);
    let c = m.length_squared() - radius * radius;
    if c <= 0.0 {
        // Inside the sphere: in its shadow, except on its lit surface
        // itself, which the caller offsets from.
        return true;
    }
    // Roots of t^2 - 2 b t + c = 0 are positive when b > 0.
    b > 0.0 && b * b >= c
}

/// Moeller-Trumbore: does the ray `o + t d`, `t > 0`, cross triangle `abc`?
fn ray_hits_triangle(o: Vec3, d: Vec3, a: Vec3, b: Vec3, c: Vec3) -> bool {
    ray_triangle(o, d, a, b, c).is_some()
}

/// Where the ray `o + t d` crosses triangle `abc` (Moeller and Trumbore
/// 1997), from either side: `t > 0` and the barycentrics `(u, v)` of `b`
/// and `c`.
pub fn ray_triangle(o: Vec3, d: Vec3, a: Vec3, b: Vec3, c: Vec3) -> Option<(f32, f32, f32)> {
    let (e1, e2) = (b - a, c - a);
    let p = d.cross(e2);
    let det = e1.dot(p);
    if det.abs() < 1e-12 {
        return None;
    }
    let inv = 1.0 / det;
    let s = o - a;
    let u = s.dot(p) * inv;
    let q = s.cross(e1);
    let v = d.dot(q) * inv;
    let t = e2.dot(q) * inv;
    (u >= 0.0 && v >= 0.0 && u + v <= 1.0 && t > 0.0).then_some((t, u, v))
}

/// A triangle in map coordinates (cells), for questions along the light
/// (the map's first axis): which columns it covers and at what depth.
#[derive(Debug, Clone, Copy)]
struct Projected {
    a: Vec3,
    b: Vec3,
    c: Vec3,
    /// Twice the signed area of the triangle's shadow across the light.
    area2: f32,
}

impl Projected {
    /// `None` when the triangle is edge-on to the light: its neighbours
    /// cover what it would.
    fn new(frame: &LightFrame, [a, b, c]: [Vec3; 3]) -> Option<Projected> {
        let (a, b, c) = (frame.to_cells(a), frame.to_cells(b), frame.to_cells(c));
        let area2 = (b.y - a.y) * (c.z - a.z) - (b.z - a.z) * (c.y - a.y);
        (area2.abs() > 1e-9).then_some(Projected { a, b, c, area2 })
    }

    /// Columns `j0..j1` x `k0..k1` whose centres may lie in the shadow.
    fn columns(&self, n: usize) -> [usize; 4] {
        let lo = self.a.min(self.b).min(self.c);
        let hi = self.a.max(self.b).max(self.c);
        // Centres j + 0.5 in [lo, hi]: j from ceil(lo - 0.5) to floor(hi - 0.5).
        let first = |v: f32| (v - 0.5).ceil().clamp(0.0, n as f32) as usize;
        let end = |v: f32| ((v - 0.5).floor() + 1.0).clamp(0.0, n as f32) as usize;
        [first(lo.y), end(hi.y), first(lo.z), end(hi.z)]
    }

    /// The triangle's slice coordinate at `(y, z)` across the light, if its
    /// shadow holds that point (edges included, so that a closed mesh has
    /// no cracks between triangles).
    fn depth_at(&self, (y, z): (f32, f32)) -> Option<f32> {
        let (a, b, c) = (self.a, self.b, self.c);
        let wb = ((y - a.y) * (c.z - a.z) - (z - a.z) * (c.y - a.y)) / self.area2;
        let wc = ((b.y - a.y) * (z - a.z) - (b.z - a.z) * (y - a.y)) / self.area2;
        let wa = 1.0 - wb - wc;
        const EDGE: f32 = -1e-6;
        (wa >= EDGE && wb >= EDGE && wc >= EDGE).then_some(wa * a.x + wb * b.x + wc * c.x)
    }
}

/// Bodies prepared for many "is this point in their shadow" questions
/// along one light: a mesh's triangles binned by the map columns their
/// shadow overlaps, so that a query tests only the triangles of its column.
#[derive(Debug, Clone)]
pub struct OccluderView {
    frame: LightFrame,
    spheres: Vec<(Vec3, f32)>,
    triangles: Vec<Projected>,
    /// Per column, the triangles whose shadow overlaps it: `bins[start[c]..start[c + 1]]`.
    start: Vec<u32>,
    bins: Vec<u32>,
}

impl OccluderView {
    /// `occluders` prepared for queries along the columns of `frame`.
    pub fn new(frame: LightFrame, occluders: &[Occluder]) -> OccluderView {
        let n = frame.n_cells as usize;
        let mut spheres = Vec::new();
        let mut triangles = Vec::new();
        for o in occluders {
            match o {
                Occluder::Sphere { center, radius } => spheres.push((*center, *radius)),
                Occluder::Mesh(m) => triangles.extend(
                    (0..m.triangles().len()).filter_map(|t| Projected::new(&frame, m.corners(t))),
                ),
            }
        }
        // Columns whose square (not only centre) the shadow's bounds overlap.
        let cover = |t: &Projected| {
            let lo = t.a.min(t.b).min(t.c);
            let hi = t.a.max(t.b).max(t.c);
            let cell = |v: f32| v.clamp(0.0, n as f32 - 1.0) as usize;
            let inside = hi.y >= 0.0 && hi.z >= 0.0 && lo.y < n as f32 && lo.z < n as f32;
            inside.then(|| [cell(lo.y), cell(hi.y), cell(lo.z), cell(hi.z)])
        };
        let mut start = vec![0u32; n * n + 1];
        for t in &triangles {
            if let Some([j0, j1, k0, k1]) = cover(t) {
                for k in k0..=k1 {
                    for j in j0..=j1 {
                        start[k * n + j + 1] += 1;
                    }
                }
            }
        }
        for c in 0..n * n {
            start[c + 1] += start[c];
        }
        let mut fill = start.clone();
        let mut bins = vec![0u32; start[n * n] as usize];
        for (i, t) in triangles.iter().enumerate() {
            if let Some([j0, j1, k0, k1]) = cover(t) {
                for k in k0..=k1 {
                    for j in j0..=j1 {
                        let f = &mut fill[k * n + j];
                        bins[*f as usize] = i as u32;
                        *f += 1;
                    }
                }
            }
        }
        OccluderView {
            frame,
            spheres,
            triangles,
            start,
            bins,
        }
    }

    /// Whether the ray from `p` (world coordinates) towards the light
    /// passes through a body.
    pub fn blocks(&self, p: Vec3) -> bool {
        // Towards the source along p's own ray, for a light with one.
        let dir = match &self.frame.fan {
            None => self.frame.axes[0],
            Some(f) => (p - f.source).normalize_or(self.frame.axes[0]),
        };
        if self
            .spheres
            .iter()
            .any(|&(c, r)| sphere_blocks(c, r, p, dir))
        {
            return true;
        }
        if self.triangles.is_empty() {
            return false;
        }
        let n = self.frame.n_cells as usize;
        let q = self.frame.to_cells(p);
        if !(q.y >= 0.0 && q.z >= 0.0 && q.y < n as f32 && q.z < n as f32) {
            return false;
        }
        let col = q.z as usize * n + q.y as usize;
        self.bins[self.start[col] as usize..self.start[col + 1] as usize]
            .iter()
            .any(|&t| {
                self.triangles[t as usize]
                    .depth_at((q.y, q.z))
                    .is_some_and(|x| x < q.x)
            })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Light;

    /// A UV sphere of `rings` x `segments`, closed at the poles.
    fn uv_sphere(center: Vec3, radius: f32, rings: u32, segments: u32) -> Mesh {
        let mut p = vec![center + radius * Vec3::Y, center - radius * Vec3::Y];
        for r in 1..rings {
            let theta = std::f32::consts::PI * r as f32 / rings as f32;
            for s in 0..segments {
                let phi = std::f32::consts::TAU * s as f32 / segments as f32;
                p.push(
                    center
                        + radius
                            * Vec3::new(
                                theta.sin() * phi.cos(),
                                theta.cos(),
                                theta.sin() * phi.sin(),
                            ),
                );
            }
        }
        let at = |r: u32, s: u32| 2 + (r - 1) * segments + s % segments;
        let mut t = Vec::new();
        for s in 0..segments {
            t.push([0, at(1, s + 1), at(1, s)]);
            t.push([1, at(rings - 1, s), at(rings - 1, s + 1)]);
            for r in 1..rings - 1 {
                t.push([at(r, s), at(r, s + 1), at(r + 1, s)]);
                t.push([at(r, s + 1), at(r + 1, s + 1), at(r + 1, s)]);
            }
        }
        Mesh::new(p, t).unwrap()
    }

    #[test]
    fn a_sphere_blocks_rays_towards_the_light_only() {
        let o = Occluder::sphere(Vec3::ZERO, 1.0);
        let down = Vec3::NEG_Y;
        assert!(
            o.blocks(Vec3::new(0.0, -3.0, 0.0), down),
            "below, in shadow"
        );
        assert!(!o.blocks(Vec3::new(0.0, 3.0, 0.0), down), "above, lit");
        assert!(!o.blocks(Vec3::new(1.5, -3.0, 0.0), down), "beside");
        assert!(o.blocks(Vec3::new(0.99, -3.0, 0.0), down));
    }

    #[test]
    fn a_tessellated_sphere_enters_columns_where_the_sphere_does() {
        let light = Light::directional(Vec3::new(0.3, -1.0, 0.2)).unwrap();
        let (c, r) = (Vec3::new(1.0, 2.0, 3.0), 5.0);
        let frame = LightFrame::centered(&light, c, 14.0, 32).unwrap();
        let sphere = Occluder::sphere(c, r).entries(&frame);
        let mesh = Occluder::Mesh(Arc::new(uv_sphere(c, r, 64, 128))).entries(&frame);
        // The mesh is inscribed: it may miss a column at the rim, never add one.
        let ds = frame.ds;
        let mut matched = 0;
        for &(col, x) in &mesh {
            let s = sphere
                .iter()
                .find(|e| e.0 == col)
                .expect("inside the sphere's shadow");
            // Within the chord of a facet: r (1 - cos(pi / 64)) plus slope at the rim.
            if s.1 - x < 0.05 * r / ds {
                matched += 1;
            }
            assert!(
                x >= s.1 - 1e-3,
                "an inscribed mesh is entered behind the sphere"
            );
        }
        assert!(
            mesh.len() + 8 >= sphere.len(),
            "{} of {}",
            mesh.len(),
            sphere.len()
        );
        assert!(
            matched * 10 >= mesh.len() * 9,
            "{matched} of {}",
            mesh.len()
        );
    }

    #[test]
    fn a_mesh_view_blocks_exactly_what_its_triangles_block() {
        let light = Light::directional(Vec3::new(0.2, -1.0, 0.1)).unwrap();
        let mesh = Arc::new(uv_sphere(Vec3::ZERO, 2.0, 12, 24));
        let o = [Occluder::Mesh(mesh)];
        let frame = LightFrame::centered(&light, Vec3::ZERO, 10.0, 16).unwrap();
        let view = OccluderView::new(frame, &o);
        let mut rng = strands::Rng::new(7);
        let mut blocked = 0;
        for _ in 0..2000 {
            let p = Vec3::new(
                rng.range(-4.0, 4.0),
                rng.range(-4.0, 4.0),
                rng.range(-4.0, 4.0),
            );
            let brute = o[0].blocks(p, light.direction());
            assert_eq!(view.blocks(p), brute, "at {p}");
            blocked += usize::from(brute);
        }
        assert!(blocked > 100, "{blocked}");
        // Downstream of the centre along the light: in shadow; upstream: lit.
        assert!(view.blocks(3.0 * light.direction()));
        assert!(!view.blocks(-3.0 * light.direction()));
    }
}
