//! The opaque layer: the head, a sphere ray-cast or a triangle mesh,
//! depth-tested, under the hair.

use glam::Vec3;
use rayon::prelude::*;

use super::Canvas;

/// Rows of the bands the head's triangles are binned to.
const TRIANGLE_BAND: usize = 16;
use crate::Camera;

/// An opaque sphere: the default head.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sphere {
    /// Centre, scene units.
    pub center: Vec3,
    /// Radius, scene units.
    pub radius: f32,
}

impl Sphere {
    /// Distance along the unit ray `o + t d` to the nearest hit in front.
    pub fn hit(&self, o: Vec3, d: Vec3) -> Option<f32> {
        let oc = o - self.center;
        let b = oc.dot(d);
        let c = oc.length_squared() - self.radius * self.radius;
        let disc = b * b - c;
        if disc < 0.0 {
            return None;
        }
        let s = disc.sqrt();
        [-b - s, -b + s].into_iter().find(|&t| t > 0.0)
    }
}

/// The smallest pixel rectangle `[x0, x1, y0, y1]` holding `a` (if any) and `b`.
fn union(a: Option<[usize; 4]>, b: [usize; 4]) -> [usize; 4] {
    match a {
        Some([a0, a1, b0, b1]) => [a0.min(b[0]), a1.max(b[1]), b0.min(b[2]), b1.max(b[3])],
        None => b,
    }
}

/// A triangle's corners on screen, if all three are in front of the camera.
#[inline]
fn screen_corners(tri: [u32; 3], screen: &[Option<Vec3>]) -> Option<[Vec3; 3]> {
    Some([
        screen[tri[0] as usize]?,
        screen[tri[1] as usize]?,
        screen[tri[2] as usize]?,
    ])
}

impl Canvas {
    /// The pixel rectangle `[x0, x1, y0, y1]` that a sphere can cover: the
    /// projection of its bounding cube, or the whole image when part of
    /// the cube is behind the camera.
    fn sphere_rect(&self, camera: &Camera, sphere: &Sphere) -> [usize; 4] {
        let (w, h) = (self.width as f32, self.height as f32);
        let mut lo = Vec3::splat(f32::INFINITY);
        let mut hi = Vec3::splat(f32::NEG_INFINITY);
        for k in 0..8 {
            let corner = Vec3::new(
                if k & 1 == 0 { -1.0 } else { 1.0 },
                if k & 2 == 0 { -1.0 } else { 1.0 },
                if k & 4 == 0 { -1.0 } else { 1.0 },
            );
            match camera.project(sphere.center + sphere.radius * corner) {
                Some(s) if s.is_finite() => {
                    lo = lo.min(s);
                    hi = hi.max(s);
                }
                _ => return [0, self.width, 0, self.height],
            }
        }
        // Pixel centres x + 0.5 in [lo.x, hi.x], with a pixel to spare.
        let span = |a: f32, b: f32, max: f32| {
            let a = (a - 1.0).clamp(0.0, max) as usize;
            let b = (b + 2.0).clamp(0.0, max) as usize;
            (a, b.max(a))
        };
        let (x0, x1) = span(lo.x, hi.x, w);
        let (y0, y1) = span(lo.y, hi.y, h);
        [x0, x1, y0, y1]
    }

    /// Runs `f(y, depth, colour)` on the rows `y0..y1` of the opaque layer
    /// in parallel, and marks the rectangle `[x0, x1, y0, y1]` drawn.
    fn opaque_rows(&mut self, rect: [usize; 4], f: impl Fn(usize, &mut [f32], &mut [Vec3]) + Sync) {
        let (w, y0, y1) = (self.width, rect[2], rect[3]);
        self.dirty = Some(union(self.dirty, rect));
        let only = &self.opaque_only;
        self.depth[y0 * w..y1 * w]
            .par_chunks_mut(w)
            .zip(self.opaque[y0 * w..y1 * w].par_chunks_mut(w))
            .enumerate()
            .for_each(|(row, (depth, color))| {
                let y = y0 + row;
                if only
                    .as_ref()
                    .is_none_or(|o| o.iter().any(|r| r.contains(&(y as u32))))
                {
                    f(y, depth, color)
                }
            });
    }

    /// Draws the opaque layer in rows `rows` alone from now on (`None`:
    /// every row): a canvas that resolves only those rows needs no more.
    pub fn set_opaque_rows(&mut self, rows: Option<Vec<std::ops::Range<u32>>>) {
        self.opaque_only = rows;
    }

    /// Draws an opaque sphere, one ray per pixel centre; `shade(point,
    /// normal)` gives the linear colour of a visible surface point.
    pub fn draw_sphere(
        &mut self,
        camera: &Camera,
        sphere: &Sphere,
        shade: impl Fn(Vec3, Vec3) -> Vec3 + Sync,
    ) {
        let [x0, x1, y0, y1] = self.sphere_rect(camera, sphere);
        if x0 >= x1 || y0 >= y1 {
            return;
        }
        self.opaque_rows([x0, x1, y0, y1], |y, depth, color| {
            for x in x0..x1 {
                let d = camera.ray(x as f32 + 0.5, y as f32 + 0.5);
                if let Some(t) = sphere.hit(camera.position, d) {
                    let p = camera.position + t * d;
                    // View depth, comparable with the camera's projection.
                    let z = camera.project(p).map_or(f32::INFINITY, |s| s.z);
                    if z < depth[x] {
                        depth[x] = z;
                        color[x] = shade(p, (p - sphere.center) / sphere.radius);
                    }
                }
            }
        });
    }

    /// Draws an opaque triangle mesh (`positions`, unit vertex `normals`,
    /// `triangles` as index triples) with the depth test; `shade(point,
    /// normal)` gives the linear colour of a visible surface point, the
    /// normal interpolated perspective-correctly from the vertices'.
    ///
    /// Triangles are binned to bands of rows, and each row tests its
    /// band's triangles in index order at every pixel centre: edges are
    /// inclusive (no cracks between triangles) and the first triangle
    /// wins a tie, so the result does not depend on the thread count. A
    /// triangle with a corner behind the camera is not drawn. Panics when
    /// an index names no vertex.
    pub fn draw_mesh(
        &mut self,
        camera: &Camera,
        positions: &[Vec3],
        normals: &[Vec3],
        triangles: &[[u32; 3]],
        shade: impl Fn(Vec3, Vec3) -> Vec3 + Sync,
    ) {
        assert_eq!(positions.len(), normals.len());
        assert!(
            triangles
                .iter()
                .flatten()
                .all(|&i| (i as usize) < positions.len()),
            "triangle indices name vertices"
        );
        let (w, h) = (self.width, self.height);
        let screen: Vec<Option<Vec3>> = positions
            .par_iter()
            .map(|&p| camera.project(p).filter(|s| s.is_finite()))
            .collect();
        // Triangles facing either way, with their pixel rows and columns.
        let mut rect: Option<[usize; 4]> = None;
        let bands = h.div_ceil(TRIANGLE_BAND);
        let mut bins: Vec<Vec<u32>> = vec![Vec::new(); bands];
        for (t, tri) in triangles.iter().enumerate() {
            let Some([a, b, c]) = screen_corners(*tri, &screen) else {
                continue;
            };
            let lo = a.min(b).min(c);
            let hi = a.max(b).max(c);
            // Pixel centres x + 0.5 in [lo, hi].
            let first = |v: f32, max: usize| (v - 0.5).ceil().clamp(0.0, max as f32) as usize;
            let end =
                |v: f32, max: usize| ((v - 0.5).floor() + 1.0).clamp(0.0, max as f32) as usize;
            let (x0, x1, y0, y1) = (first(lo.x, w), end(hi.x, w), first(lo.y, h), end(hi.y, h));
            if x0 >= x1 || y0 >= y1 {
                continue;
            }
            rect = Some(union(rect, [x0, x1, y0, y1]));
            for bin in &mut bins[y0 / TRIANGLE_BAND..=(y1 - 1) / TRIANGLE_BAND] {
                bin.push(t as u32);
            }
        }
        let Some([x0, x1, y0, y1]) = rect else {
            return;
        };
        self.opaque_rows([x0, x1, y0, y1], |y, depth, color| {
            let py = y as f32 + 0.5;
            // Per pixel of the row: the nearest surface so far, as its
            // triangle and perspective-correct barycentric weights.
            let mut best: Vec<(f32, u32, [f32; 3])> =
                vec![(f32::INFINITY, u32::MAX, [0.0; 3]); x1 - x0];
            for &t in &bins[y / TRIANGLE_BAND] {
                let tri = triangles[t as usize];
                let Some([a, b, c]) = screen_corners(tri, &screen) else {
                    continue;
                };
                let area = (b.x - a.x) * (c.y - a.y) - (b.y - a.y) * (c.x - a.x);
                if area.abs() < 1e-12 {
                    continue;
                }
                let inv = 1.0 / area;
                // Columns where the row's centre line crosses the triangle.
                let (lo, hi) = (a.min(b).min(c), a.max(b).max(c));
                if py < lo.y || py > hi.y {
                    continue;
                }
                let xa = ((lo.x - 0.5).ceil().max(x0 as f32) as usize).max(x0);
                let xb = (((hi.x - 0.5).floor() + 1.0).clamp(0.0, x1 as f32) as usize).min(x1);
                for x in xa..xb {
                    let px = x as f32 + 0.5;
                    // Screen-space barycentric weights of the pixel centre.
                    let l1 = ((px - a.x) * (c.y - a.y) - (py - a.y) * (c.x - a.x)) * inv;
                    let l2 = ((b.x - a.x) * (py - a.y) - (b.y - a.y) * (px - a.x)) * inv;
                    let l0 = 1.0 - l1 - l2;
                    const EDGE: f32 = -1e-6;
                    if l0 < EDGE || l1 < EDGE || l2 < EDGE {
                        continue;
                    }
                    // Perspective-correct: weights over view depth.
                    let (q0, q1, q2) = (l0 / a.z, l1 / b.z, l2 / c.z);
                    let sum = q0 + q1 + q2;
                    let z = 1.0 / sum;
                    let slot = &mut best[x - x0];
                    if z < slot.0 {
                        *slot = (z, t, [q0 * z, q1 * z, q2 * z]);
                    }
                }
            }
            for (x, &(z, t, wt)) in (x0..x1).zip(&best) {
                if t != u32::MAX && z < depth[x] {
                    let [i, j, k] = triangles[t as usize].map(|v| v as usize);
                    let p = wt[0] * positions[i] + wt[1] * positions[j] + wt[2] * positions[k];
                    let n = (wt[0] * normals[i] + wt[1] * normals[j] + wt[2] * normals[k])
                        .normalize_or_zero();
                    // Two-sided: the shading normal on the side the camera
                    // sees (the triangle's own normal turned to the eye),
                    // so a part wound the other way round is not shaded as
                    // its inside.
                    let g = (positions[j] - positions[i]).cross(positions[k] - positions[i]);
                    let g = if g.dot(camera.position - p) < 0.0 {
                        -g
                    } else {
                        g
                    };
                    let n = if n.dot(g) < 0.0 { -n } else { n };
                    depth[x] = z;
                    color[x] = shade(p, n);
                }
            }
        });
    }
}
