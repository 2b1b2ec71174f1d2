//! A rendered frame as files Blender Cycles renders: the drawn strands as
//! posed, the head, the camera, the lights, the fiber's width, opacity and
//! optics, and a Python script (`export/scene.py`) that builds the scene
//! in Blender and renders it.
//!
//! The engine makes the files' bytes; writing them is the caller's.
//! Coordinates are converted to Blender's z-up: wisplight's `(x, y, z)` is
//! `(x, -z, y)` there, a rotation, so every picture and shadow is the same.
//!
//! Files (little-endian):
//! - `strands.bin`: `u32` point count of each strand, then `f32 x, y, z` of
//!   every point, strand after strand;
//! - `head.bin` (a scene with a head): `f32 x, y, z` of every vertex, then
//!   `i32` triples of every triangle (a sphere is tessellated), then `f32
//!   x, y, z` of every vertex's unit normal, the one wisplight shades it
//!   with (Cycles takes them as the mesh's own: averaged by its own
//!   weights instead, a closed neck's normals bend towards its bottom and
//!   darken it);
//! - `scene.json`: everything else, read by `scene.py`.
//!
//! What does not carry over: Kajiya-Kay is not a physical model, so a
//! scene shaded with it is exported with the physically based fiber of the
//! same colour; per-strand colours become their mean; the head is a
//! Lambertian surface of its colour.

use glam::Vec3;
use raster::ShadingModel;
use serde::Serialize;
use shadow::Light;

use crate::{DEFAULT_HAIR_COLOR, EngineError, Sequence};

/// The Blender script, the same for every export.
pub const CYCLES_SCRIPT: &str = include_str!("export/scene.py");

/// The format `scene.py` reads (`scene.json`'s `format`).
pub const CYCLES_FORMAT: &str = "wisplight-cycles-2";

/// The files of one exported frame: name and bytes.
#[derive(Debug, Clone)]
pub struct CyclesExport {
    /// `scene.py`, `scene.json`, `strands.bin` and, with a head,
    /// `head.bin`.
    pub files: Vec<(&'static str, Vec<u8>)>,
    /// Strands and points written.
    pub strands: usize,
    /// Drawn points written.
    pub points: usize,
}

/// wisplight's y-up coordinates in Blender's z-up ones.
fn z_up(v: Vec3) -> [f32; 3] {
    [v.x, -v.z, v.y]
}

#[derive(Serialize)]
struct SceneJson {
    format: &'static str,
    frame: u64,
    width: u32,
    height: u32,
    samples: u32,
    background: [f32; 3],
    /// The sky's radiance from every direction (`[shading] ambient` of
    /// the physically based fiber); 0 for none, and for Kajiya-Kay.
    sky: f32,
    camera: CameraJson,
    lights: Vec<LightJson>,
    hair: HairJson,
    head: Option<HeadJson>,
}

#[derive(Serialize)]
struct CameraJson {
    position: [f32; 3],
    right: [f32; 3],
    up: [f32; 3],
    forward: [f32; 3],
    fov_deg: f32,
    clip_start: f32,
    clip_end: f32,
}

#[derive(Serialize)]
#[serde(tag = "kind", rename_all = "lowercase")]
enum LightJson {
    Directional {
        direction: [f32; 3],
        irradiance: f32,
    },
    Point {
        position: [f32; 3],
        intensity: f32,
    },
    Spot {
        position: [f32; 3],
        direction: [f32; 3],
        cone_deg: f32,
        falloff_deg: f32,
        intensity: f32,
    },
}

#[derive(Serialize)]
struct HairJson {
    file: &'static str,
    strands: usize,
    points: usize,
    /// Fiber width, scene units.
    width: f32,
    /// What a fiber stops of the light that reaches it, for shadows.
    shadow_opacity: f32,
    /// And for the camera, where a fiber covers a whole pixel.
    camera_opacity: f32,
    fiber: FiberJson,
}

#[derive(Serialize)]
struct FiberJson {
    sigma_a: [f32; 3],
    beta_m: f32,
    beta_n: f32,
    alpha_deg: f32,
    eta: f32,
}

#[derive(Serialize)]
struct HeadJson {
    file: &'static str,
    vertices: usize,
    triangles: usize,
    color: [f32; 3],
}

/// Exports the frame `seq` rendered last (in this process), for `samples`
/// Cycles samples per pixel. Fails when no frame was drawn here yet.
pub fn cycles_export(seq: &Sequence, samples: u32) -> Result<CyclesExport, EngineError> {
    let scene = seq.scene();
    let camera = *seq.renderer().camera().ok_or_else(|| {
        EngineError::executor("no frame was drawn in this process yet: nothing to export")
    })?;
    let hair = seq.hair();
    let frame = seq.next_index().saturating_sub(1);

    // Strands: counts, then points.
    let mut strands = Vec::with_capacity(4 * hair.strand_count() + 12 * hair.point_count());
    for s in hair.strands() {
        strands.extend_from_slice(&(s.len() as u32).to_le_bytes());
    }
    for &p in hair.points() {
        for c in z_up(p) {
            strands.extend_from_slice(&c.to_le_bytes());
        }
    }

    // The fiber: the scene's optics, or for Kajiya-Kay (or colours per
    // strand) the physically based fiber of the hair's (mean) colour.
    let color = hair.colors().map_or(DEFAULT_HAIR_COLOR, |c| {
        c.iter().copied().sum::<Vec3>() / c.len().max(1) as f32
    });
    let (optics, irradiance) = match scene.shading.model {
        ShadingModel::Marschner {
            optics,
            from_color,
            irradiance,
            ..
        } => {
            let mut o = optics;
            if from_color {
                o.sigma_a = raster::sigma_a_from_color(color, o.beta_n);
            }
            (o, irradiance)
        }
        ShadingModel::KajiyaKay => {
            let mut o = raster::FiberOptics::default();
            o.sigma_a = raster::sigma_a_from_color(color, o.beta_n);
            (o, 1.0)
        }
    };

    let lights = scene
        .lights
        .iter()
        .map(|l| match *l {
            Light::Directional { direction } => LightJson::Directional {
                direction: z_up(direction),
                irradiance,
            },
            Light::Point {
                position,
                intensity,
            } => LightJson::Point {
                position: z_up(position),
                intensity: intensity * irradiance,
            },
            Light::Spot {
                position,
                direction,
                cone_deg,
                falloff_deg,
                intensity,
            } => LightJson::Spot {
                position: z_up(position),
                direction: z_up(direction),
                cone_deg,
                falloff_deg,
                intensity: intensity * irradiance,
            },
        })
        .collect();

    let mut files = Vec::new();
    let head = match seq.renderer().shadows().head() {
        None => None,
        Some(h) => {
            let (positions, triangles, normals) = match h.mesh() {
                Some(m) => (
                    m.positions().to_vec(),
                    m.triangles().to_vec(),
                    m.normals().to_vec(),
                ),
                None => {
                    let (p, t) = uv_sphere(h.center(), h.settings().radius, 96, 48);
                    let n = p
                        .iter()
                        .map(|&x| (x - h.center()).normalize_or(Vec3::Y))
                        .collect();
                    (p, t, n)
                }
            };
            let mut bytes = Vec::with_capacity(12 * (2 * positions.len() + triangles.len()));
            for &p in &positions {
                for c in z_up(p) {
                    bytes.extend_from_slice(&c.to_le_bytes());
                }
            }
            for t in &triangles {
                for &i in t {
                    bytes.extend_from_slice(&(i as i32).to_le_bytes());
                }
            }
            for &n in &normals {
                for c in z_up(n) {
                    bytes.extend_from_slice(&c.to_le_bytes());
                }
            }
            files.push(("head.bin", bytes));
            Some(HeadJson {
                file: "head.bin",
                vertices: positions.len(),
                triangles: triangles.len(),
                color: h.settings().color.to_array(),
            })
        }
    };

    let (right, up, forward) = camera.axes();
    let extent = hair.bounds().union(
        seq.renderer()
            .shadows()
            .head()
            .map_or(strands::Bounds::empty(), |h| h.bounds()),
    );
    let far = (extent.center() - camera.position).length() + extent.size().length();
    let json = SceneJson {
        format: CYCLES_FORMAT,
        frame,
        width: camera.width(),
        height: camera.height(),
        samples,
        background: scene.render.background.to_array(),
        // Kajiya-Kay's ambient term is no light: none goes with it.
        sky: match scene.shading.model {
            raster::ShadingModel::Marschner { .. } => scene.shading.ambient,
            raster::ShadingModel::KajiyaKay => 0.0,
        },
        camera: CameraJson {
            position: z_up(camera.position),
            right: z_up(right),
            up: z_up(up),
            forward: z_up(forward),
            fov_deg: camera.fov_deg(),
            clip_start: 1e-3,
            clip_end: 2.0 * far.max(1.0),
        },
        lights,
        hair: HairJson {
            file: "strands.bin",
            strands: hair.strand_count(),
            points: hair.point_count(),
            width: scene.fiber.width(),
            shadow_opacity: scene.fiber.opacity(),
            camera_opacity: scene.render.hair_alpha,
            fiber: FiberJson {
                sigma_a: optics.sigma_a.to_array(),
                beta_m: optics.beta_m,
                beta_n: optics.beta_n,
                alpha_deg: optics.alpha_deg,
                eta: optics.eta,
            },
        },
        head,
    };
    let mut text = serde_json::to_string_pretty(&json).expect("plain data serializes");
    text.push('\n');
    files.push(("scene.json", text.into_bytes()));
    files.push(("strands.bin", strands));
    files.push(("scene.py", CYCLES_SCRIPT.as_bytes().to_vec()));
    Ok(CyclesExport {
        files,
        strands: hair.strand_count(),
        points: hair.point_count(),
    })
}

/// A sphere as `rings` bands of `segments` quads (each two triangles, the
/// poles' fans one).
fn uv_sphere(center: Vec3, radius: f32, segments: u32, rings: u32) -> (Vec<Vec3>, Vec<[u32; 3]>) {
    let mut v = vec![center + Vec3::Y * radius];
    for r in 1..rings {
        let theta = std::f32::consts::PI * r as f32 / rings as f32;
        for s in 0..segments {
            let phi = std::f32::consts::TAU * s as f32 / segments as f32;
            v.push(
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
    let south = v.len() as u32;
    v.push(center - Vec3::Y * radius);
    let at = |r: u32, s: u32| 1 + (r - 1) * segments + s % segments;
    let mut t = Vec::new();
    for s in 0..segments {
        t.push([0, at(1, s + 1), at(1, s)]);
        t.push([south, at(rings - 1, s), at(rings - 1, s + 1)]);
    }
    for r in 1..rings - 1 {
        for s in 0..segments {
            t.push([at(r, s), at(r, s + 1), at(r + 1, s + 1)]);
            t.push([at(r, s), at(r + 1, s + 1), at(r + 1, s)]);
        }
    }
    (v, t)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_sphere_is_closed_and_on_its_radius() {
        let (v, t) = uv_sphere(Vec3::new(1.0, 2.0, 3.0), 2.0, 12, 6);
        assert!(
            v.iter()
                .all(|p| ((*p - Vec3::new(1.0, 2.0, 3.0)).length() - 2.0).abs() < 1e-5)
        );
        // A closed surface: every edge is shared by exactly two triangles.
        let mut edges = std::collections::HashMap::new();
        for tri in &t {
            for e in 0..3 {
                let (a, b) = (tri[e], tri[(e + 1) % 3]);
                *edges.entry((a.min(b), a.max(b))).or_insert(0) += 1;
            }
        }
        assert!(edges.values().all(|&n| n == 2));
        // Euler: V - E + F = 2.
        assert_eq!(v.len() as i64 - edges.len() as i64 + t.len() as i64, 2);
    }

    #[test]
    fn z_up_is_a_rotation() {
        let a = Vec3::new(0.3, -1.2, 2.0);
        let b = Vec3::new(-0.7, 0.4, 0.9);
        let (ra, rb) = (Vec3::from(z_up(a)), Vec3::from(z_up(b)));
        assert!((ra.dot(rb) - a.dot(b)).abs() < 1e-6);
        assert!((Vec3::from(z_up(a.cross(b))) - ra.cross(rb)).length() < 1e-6);
        assert_eq!(z_up(Vec3::Y), [0.0, 0.0, 1.0]);
    }
}
