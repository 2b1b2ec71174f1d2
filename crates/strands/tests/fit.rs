//! Sphere fits to head meshes, checked against the sphere each was made on.

use glam::Vec3;
use strands::Mesh;

/// A UV sphere of `rings` x `segments` about `c` of radius `r`, with a
/// box of shoulders `w` wide hanging below it.
fn bust(c: Vec3, r: f32, w: f32) -> Mesh {
    let (rings, segments) = (24u32, 32u32);
    let mut pos = vec![c + Vec3::Y * r];
    for i in 1..rings {
        let t = std::f32::consts::PI * i as f32 / rings as f32;
        for j in 0..segments {
            let p = std::f32::consts::TAU * j as f32 / segments as f32;
            pos.push(c + r * Vec3::new(t.sin() * p.cos(), t.cos(), t.sin() * p.sin()));
        }
    }
    pos.push(c - Vec3::Y * r);
    let ring = |i: u32, j: u32| 1 + (i - 1) * segments + j % segments;
    let mut tri = Vec::new();
    for j in 0..segments {
        tri.push([0, ring(1, j + 1), ring(1, j)]);
        for i in 1..rings - 1 {
            tri.push([ring(i, j), ring(i, j + 1), ring(i + 1, j)]);
            tri.push([ring(i + 1, j), ring(i, j + 1), ring(i + 1, j + 1)]);
        }
        tri.push([
            pos.len() as u32 - 1,
            ring(rings - 1, j),
            ring(rings - 1, j + 1),
        ]);
    }
    // Shoulders: a box from 1.5 r to 3 r below the centre.
    let base = pos.len() as u32;
    for k in 0..8u32 {
        let x = if k & 1 == 0 { -w } else { w } / 2.0;
        let y = if k & 2 == 0 { -1.5 * r } else { -3.0 * r };
        let z = if k & 4 == 0 { -r } else { r };
        pos.push(c + Vec3::new(x, y, z));
    }
    for f in [
        [0, 1, 3],
        [0, 3, 2],
        [4, 6, 7],
        [4, 7, 5],
        [0, 4, 5],
        [0, 5, 1],
    ] {
        tri.push(f.map(|i| base + i));
    }
    Mesh::new(pos, tri).unwrap()
}

#[test]
fn the_crown_sphere_of_a_bust_is_its_head() {
    let c = Vec3::new(3.0, 170.0, -2.0);
    let (got, r) = bust(c, 11.0, 45.0).crown_sphere().unwrap();
    assert!(got.distance(c) < 0.2, "centre {got} for {c}");
    assert!((r - 11.0).abs() < 0.2, "radius {r} for 11");
}

#[test]
fn the_crown_sphere_of_the_projects_head_mesh_is_the_sphere_it_was_made_on() {
    // scenes/make_head.py: a sphere of radius 10 at the origin above the
    // middle, a longer jaw, a nose and a neck below.
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../../scenes/head.obj");
    let m = strands::load_obj(std::path::Path::new(path)).unwrap();
    let (c, r) = m.crown_sphere().unwrap();
    assert!(c.length() < 0.3, "centre {c}");
    assert!((r - 10.0).abs() < 0.3, "radius {r}");
}

#[test]
fn a_flat_mesh_falls_back_to_its_bounds_and_a_point_has_no_sphere() {
    let m = Mesh::new(
        vec![
            Vec3::ZERO,
            Vec3::X * 4.0,
            Vec3::new(4.0, 0.0, 2.0),
            Vec3::Z * 2.0,
        ],
        vec![[0, 1, 2], [0, 2, 3]],
    )
    .unwrap();
    assert_eq!(m.crown_sphere(), Some((Vec3::new(2.0, 0.0, 1.0), 1.0)));
    let point = Mesh::new(vec![Vec3::ONE; 3], vec![[0, 1, 2]]).unwrap();
    assert_eq!(point.crown_sphere(), None);
}
