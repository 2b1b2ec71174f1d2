use super::*;
use crate::{Fiber, Light};
use strands::Hair;

#[test]
fn depth_is_zero_in_front_linear_inside_and_constant_behind() {
    let light = Light::directional(Vec3::X).unwrap();
    let frame = LightFrame::centered(&light, Vec3::ZERO, 8.0, 8).unwrap();
    let mut map = DensityMap::new(frame);
    // One cell with depth 1 at slice 3, one with depth 0.5 at slice 5, column (2, 6).
    let q = (1.0 / DEPTH_QUANTUM) as u32;
    map.add_quanta(3, 2, 6, q);
    map.add_quanta(5, 2, 6, q / 2);
    let t = Transmittance::compute(&map);
    let at = |x: f32| t.column_depth(2, 6, x);
    assert_eq!(at(-1.0), 0.0);
    assert_eq!(at(2.999), 0.0);
    assert_eq!(at(3.0), 0.0);
    assert!((at(3.5) - 0.5).abs() < 1e-6);
    assert!((at(4.5) - 1.0).abs() < 1e-6);
    assert!((at(5.5) - 1.25).abs() < 1e-6);
    assert!((at(6.0) - 1.5).abs() < 1e-6);
    assert!((at(100.0) - 1.5).abs() < 1e-6);
    assert_eq!(
        t.column_depth(3, 6, 7.0),
        0.0,
        "a neighbouring column is empty"
    );
}

#[test]
fn the_sweep_rounds_each_cumulative_depth_once_to_the_nearest_step() {
    let light = Light::directional(Vec3::X).unwrap();
    let frame = LightFrame::centered(&light, Vec3::ZERO, 8.0, 8).unwrap();
    let mut map = DensityMap::new(frame);
    // A step is 256 quanta. Cells of 100, 100, 100, 27, 1 quanta:
    // cumulative 100, 200, 300, 327, 328, i.e. 0.39, 0.78, 1.17, 1.28,
    // 1.28 steps (128 quanta is half a step and rounds up).
    for (i, q) in [100, 100, 100, 27, 1].into_iter().enumerate() {
        map.add_quanta(i + 1, 4, 4, q);
    }
    let slab = sweep(&map, 36..37);
    assert_eq!(slab.depth, vec![0, 1, 1, 1, 1]);
    // Rounding each cell on its own would give 0, 0, 0, 0, 0.
    let mut map = DensityMap::new(frame);
    map.add_quanta(2, 4, 4, 128);
    map.add_quanta(3, 4, 4, 127);
    assert_eq!(sweep(&map, 36..37).depth, vec![1, 1]);
    let t = Transmittance::compute(&map);
    assert_eq!(t.column_depth(4, 4, 100.0) as f64, DEPTH_STEP);
}

#[test]
fn slabs_of_any_split_assemble_to_the_same_result() {
    let light = Light::directional(Vec3::new(0.3, -1.0, 0.2)).unwrap();
    let mut hair = Hair::new();
    for s in 0..50 {
        let x = s as f32 * 0.1;
        hair.push_strand(&[
            Vec3::new(x, 1.0, 0.0),
            Vec3::new(x + 0.5, -1.0, 0.3 * x),
            Vec3::new(x, -2.0, 1.0),
        ])
        .unwrap();
    }
    // Many column groups for compute, some starting with empty columns.
    let big = LightFrame::fit(&light, hair.points(), 96).unwrap();
    let mut map = DensityMap::new(big);
    map.fill(&hair, &Fiber::new(0.05, 0.7).unwrap());
    let cuts = [0, 1, 5000, 5001, 9216];
    let slabs = cuts.windows(2).map(|c| sweep(&map, c[0]..c[1]));
    let split = Transmittance::assemble(big, slabs).unwrap();
    assert_eq!(Transmittance::compute(&map), split);
    assert!(map.span(0).is_none() && split.stored_cells() > 1000);
    // Asked before each run of columns; told to stop, it stops.
    let asked = std::cell::Cell::new(0);
    let count = || {
        asked.set(asked.get() + 1);
        true
    };
    assert_eq!(
        sweep_while(&map, 0..9216, count),
        Some(sweep(&map, 0..9216))
    );
    assert_eq!(asked.get(), 9216usize.div_ceil(SWEEP_RUN_COLUMNS));
    asked.set(0);
    let once = || {
        asked.set(asked.get() + 1);
        asked.get() == 1
    };
    assert_eq!(sweep_while(&map, 0..9216, once), None);
    assert_eq!(asked.get(), 2);

    let frame = LightFrame::fit(&light, hair.points(), 16).unwrap();
    let mut map = DensityMap::new(frame);
    map.fill(&hair, &Fiber::new(0.05, 0.7).unwrap());
    let whole = Transmittance::compute(&map);
    let split = Transmittance::assemble(
        frame,
        [
            sweep(&map, 0..7),
            sweep(&map, 7..100),
            sweep(&map, 100..256),
        ],
    )
    .unwrap();
    assert_eq!(whole, split);
    assert!(
        Transmittance::assemble(frame, [sweep(&map, 0..7), sweep(&map, 8..256)]).is_err(),
        "a gap is refused"
    );
    assert!(
        Transmittance::assemble(frame, [sweep(&map, 0..200)]).is_err(),
        "missing columns are refused"
    );
}

#[test]
fn lookups_anywhere_around_the_map_read_the_nearest_edge_column_or_nothing() {
    // Hair in every column of a 4^3 map, so that every edge column is
    // occupied; then points from 10 cells before to 10 cells past the
    // map on every axis.
    let light = Light::directional(Vec3::X).unwrap();
    let frame = LightFrame::centered(&light, Vec3::ZERO, 4.0, 4).unwrap();
    let mut map = DensityMap::new(frame);
    let q = (0.25 / DEPTH_QUANTUM) as u32;
    for k in 0..4 {
        for j in 0..4 {
            map.add_quanta(1, j, k, q);
        }
    }
    let t = Transmittance::compute(&map);
    let total = t.column_depth(0, 0, 100.0);
    assert!((total - 0.25).abs() < 1e-6);
    for x in -10..=14 {
        for y in -10..=14 {
            for z in -10..=14 {
                let c = Vec3::new(x as f32, y as f32, z as f32) + 0.25;
                let p = frame.to_world(c);
                for trilinear in [true, false] {
                    let d = t.optical_depth(p, trilinear);
                    assert!(
                        d.is_finite() && (0.0..=total + 1e-6).contains(&d),
                        "D = {d} at cell coordinates {c}, filter {trilinear}"
                    );
                    let inside_across = (0.0..4.0).contains(&c.y) && (0.0..4.0).contains(&c.z);
                    if c.x <= 1.0 {
                        // In front of all hair: nothing at all.
                        assert_eq!(d, 0.0, "in front at {c}");
                    } else if c.x >= 2.0 && inside_across && !trilinear {
                        // Behind the hair, within the map's columns.
                        assert!((d - total).abs() < 1e-6, "behind at {c}: {d}");
                    }
                    // A drawn point reads half a cell nearer the light.
                    let drawn = -t.transmittance_at_drawn(p, trilinear).ln();
                    if c.x >= 2.0 + LIT_EDGE_OFFSET && inside_across && !trilinear {
                        assert!(
                            (drawn - total).abs() < 1e-5,
                            "drawn, behind at {c}: {drawn}"
                        );
                    }
                    if c.x <= 1.0 + LIT_EDGE_OFFSET {
                        assert_eq!(drawn, 0.0, "drawn, in front at {c}");
                    }
                    if !(-2.5..6.5).contains(&c.y) || !(-2.5..6.5).contains(&c.z) {
                        // Clamped two cells beyond the map: no column there.
                        assert_eq!(d, 0.0, "far to the side at {c}");
                    }
                }
            }
        }
    }
}

#[test]
fn the_columns_a_lookup_reads_are_all_it_needs() {
    let light = Light::directional(Vec3::new(0.7, -0.5, 0.2)).unwrap();
    let mut hair = Hair::new();
    for s in 0..40 {
        let f = s as f32 * 0.1;
        hair.push_strand(&[
            Vec3::new(f.sin(), 1.0 + f * 0.2, f.cos()),
            Vec3::new(f.sin() * 1.5, -1.0, f.cos() * 0.5 - 0.3),
            Vec3::new(f * 0.3, -2.0, 0.4),
        ])
        .unwrap();
    }
    let frame = LightFrame::fit(&light, hair.points(), 24).unwrap();
    let mut map = DensityMap::new(frame);
    map.deposit(
        &hair,
        0..hair.strand_count(),
        &Fiber::new(0.05, 0.6).unwrap(),
    );
    let whole = Transmittance::compute(&map);
    let slab = sweep(&map, 0..frame.columns() as u32);
    // Points of the first few strands, and some outside the map.
    let part = &hair.points()[..15];
    let outside = [Vec3::splat(50.0), Vec3::new(-40.0, 3.0, 0.0)];
    for trilinear in [true, false] {
        let mut pts = part.to_vec();
        pts.extend(outside);
        let need = columns_read(&frame, &pts, trilinear);
        let kept = slab.keep(&need);
        assert!(kept.depth.len() < slab.depth.len(), "only some columns");
        let sparse = Transmittance::assemble(frame, [kept]).unwrap();
        for &p in &pts {
            assert_eq!(
                sparse.optical_depth(p, trilinear).to_bits(),
                whole.optical_depth(p, trilinear).to_bits(),
                "{p} filter {trilinear}"
            );
        }
    }
}

#[test]
fn the_hair_depth_about_a_body_leaves_the_body_out() {
    // A uniform layer of hair, optical depth 0.4 a cell, in which a body
    // enters a central column part way through a cell.
    let light = Light::directional(Vec3::X).unwrap();
    let frame = LightFrame::centered(&light, Vec3::ZERO, 8.0, 16).unwrap();
    let mut map = DensityMap::new(frame);
    let q = (0.4 / DEPTH_QUANTUM) as u32;
    for i in 2..14 {
        for j in 0..16 {
            for k in 0..16 {
                map.add_quanta(i, j, k, q);
            }
        }
    }
    map.deposit_body(&crate::Occluder::sphere(Vec3::ZERO, 1.3), OPAQUE_DEPTH);
    let t = Transmittance::compute(&map);
    // A column's centre line, near the sphere's axis.
    let p0 = Vec3::new(-6.0, 0.25, 0.25);
    let c = map.frame().to_cells(p0);
    assert!((c.y.fract() - 0.5).abs() < 1e-4 && (c.z.fract() - 0.5).abs() < 1e-4);
    let step = map.frame().ds;
    let at = |x: f32| p0 + Vec3::X * (x * step);
    for trilinear in [false, true] {
        // The map itself holds the body: the depth jumps by 30 through it.
        let through = t.optical_depth(at(20.0), trilinear);
        assert!((through - (12.0 * 0.4 + 30.0)).abs() < 0.01, "{through}");
        // Cell by cell along the line: the layer's 0.4 everywhere, the
        // cell the body enters too (its 30 out, its hair kept).
        let mut sum = 0.0;
        for i in 0..20 {
            let d = t.hair_depth_between(at(i as f32), at(i as f32 + 1.0), trilinear);
            // (Depths are stored in steps of 2^-12: DEPTH_STEP.)
            assert!((0.0..=0.4 + 1e-3).contains(&d), "cell {i}: {d}");
            sum += d;
        }
        assert!((sum - 12.0 * 0.4).abs() < 0.01, "{sum}");
    }
}

#[test]
fn hair_lying_on_a_body_shadows_the_surface_beneath_it() {
    // A sphere lit along +X with a layer of hair lying on its lit side:
    // optical depth 0.6, all of it in the cell each column enters the
    // sphere in (thinner than the distance a surface's lookup goes off
    // the surface, 1.5 cells along the normal).
    let light = Light::directional(Vec3::X).unwrap();
    let frame = LightFrame::centered(&light, Vec3::ZERO, 8.0, 16).unwrap();
    let mut map = DensityMap::new(frame);
    let (r, ds) = (2.0f32, frame.ds);
    let q = (0.6 / DEPTH_QUANTUM) as u32;
    for j in 0..16usize {
        for k in 0..16usize {
            let centre = frame.to_world(Vec3::new(0.0, j as f32 + 0.5, k as f32 + 0.5));
            let (y, z) = (centre.y, centre.z);
            let h2 = r * r - y * y - z * z;
            if h2 > 0.0 {
                let front = Vec3::new(-h2.sqrt(), y, z);
                map.add_quanta(frame.to_cells(front).x as usize, j, k, q);
            }
        }
    }
    map.deposit_body(&crate::Occluder::sphere(Vec3::ZERO, r), OPAQUE_DEPTH);
    let t = Transmittance::compute(&map);
    // Where a surface point's lookup goes: off along its normal, and a
    // little towards the light.
    let off = |p: Vec3| p + (p.normalize() * 1.5 - Vec3::X * 0.5) * ds;
    // A column's centre line near the axis, where it meets the lit side.
    let (y, z) = (0.25, 0.25);
    let lit = Vec3::new(-(r * r - y * y - z * z).sqrt(), y, z);
    for trilinear in [false, true] {
        let d = t.surface_depth(lit, off(lit), trilinear);
        assert!(
            (d - 0.6).abs() < 0.01,
            "under the layer: {d} (trilinear {trilinear})"
        );
        // Read off the surface alone, the layer lies behind the lookup.
        let above = t.transmittance_at_drawn(off(lit), trilinear);
        assert!(above > 0.95, "{above}");
        // The far side stays in the body's own shadow.
        let dark = Vec3::new(-lit.x, y, z);
        let d = t.surface_depth(dark, off(dark), trilinear);
        assert!(d >= OPAQUE_DEPTH - 0.01, "behind the body: {d}");
    }
}
