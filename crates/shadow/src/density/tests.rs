use super::*;
use crate::Fiber;
use strands::Hair;

#[test]
fn deposits_in_runs_give_the_cells_of_one_and_stop_when_told() {
    let light = crate::Light::directional(Vec3::new(0.3, -0.9, 0.1)).unwrap();
    let frame = LightFrame::centered(&light, Vec3::ZERO, 8.0, 16).unwrap();
    let mut hair = Hair::new();
    for s in 0..40 {
        let f = s as f32 * 0.13;
        let pts: Vec<Vec3> = (0..1 + s % 6)
            .map(|i| Vec3::new(f - 2.5, 0.4 * i as f32 - 1.0, (f * i as f32).sin()))
            .collect();
        hair.push_strand(&pts).unwrap();
    }
    let fiber = Fiber::new(0.05, 0.7).unwrap();
    let mut whole = DensityMap::new(frame);
    let all = whole.fill(&hair, &fiber);
    let mut runs = DensityMap::new(frame);
    let asked = std::cell::Cell::new(0);
    let go = || {
        asked.set(asked.get() + 1);
        true
    };
    let stats = runs.deposit_runs(&hair, 0..hair.strand_count(), &fiber, 7, go);
    assert_eq!(stats, Some(all));
    assert!(asked.get() > 10, "{} runs", asked.get());
    for col in 0..frame.columns() {
        assert_eq!(whole.meta(col), runs.meta(col), "column {col}");
        assert_eq!(
            whole.column(col, 0..16),
            runs.column(col, 0..16),
            "column {col}"
        );
    }
    // Told to stop after two runs: no answer, and no more runs.
    asked.set(0);
    let go = || {
        asked.set(asked.get() + 1);
        asked.get() <= 2
    };
    assert_eq!(
        runs.deposit_runs(&hair, 0..hair.strand_count(), &fiber, 7, go),
        None
    );
    assert_eq!(asked.get(), 3);
}

#[test]
fn hair_quanta_leave_out_the_bodies_and_only_them() {
    let light = crate::Light::directional(Vec3::new(0.6, -0.7, 0.2)).unwrap();
    let frame = LightFrame::centered(&light, Vec3::ZERO, 8.0, 16).unwrap();
    let mut hair = Hair::new();
    for s in 0..30 {
        let f = s as f32 * 0.21;
        hair.push_strand(&[
            Vec3::new(-3.0, f - 3.0, 0.3 * f),
            Vec3::new(3.0, 2.0 - f, -0.2 * f),
        ])
        .unwrap();
    }
    let fiber = Fiber::new(0.05, 0.7).unwrap();
    let mut hair_only = DensityMap::new(frame);
    hair_only.fill(&hair, &fiber);
    let mut both = hair_only.clone();
    let head = crate::Occluder::sphere(Vec3::new(0.5, 0.0, 0.0), 2.0);
    assert!(both.deposit_body(&head, 30.0) > 0);
    let mut bodies_seen = 0;
    for k in 0..16 {
        for j in 0..16 {
            for i in 0..16 {
                assert_eq!(
                    both.hair_quanta(i, j, k),
                    hair_only.quanta(i, j, k),
                    "{i} {j} {k}"
                );
                bodies_seen += usize::from(both.quanta(i, j, k) != hair_only.quanta(i, j, k));
            }
        }
    }
    assert!(bodies_seen > 10, "the head deposited");
    // Cleared, the map forgets the bodies.
    both.clear();
    both.fill(&hair, &fiber);
    assert_eq!(both.hair_quanta(8, 8, 8), both.quanta(8, 8, 8));
}
use crate::Light;

fn frame(n: u32) -> LightFrame {
    LightFrame::centered(&Light::directional(Vec3::X).unwrap(), Vec3::ZERO, 2.0, n).unwrap()
}

#[test]
fn a_fiber_across_the_light_deposits_alpha_w_length_over_ds_squared() {
    let mut map = DensityMap::new(frame(8));
    let ds = 0.25;
    let mut hair = Hair::new();
    // Along z, a quarter cell off the column centres in y, at slice i = 4: 8 cells long.
    hair.push_strand(&[Vec3::new(0.1, 0.1, -1.0), Vec3::new(0.1, 0.1, 1.0)])
        .unwrap();
    let fiber = Fiber::new(0.01, 0.5).unwrap();
    let stats = map.fill(&hair, &fiber);
    assert_eq!(
        stats,
        FillStats {
            samples: 8,
            out_of_map: 0
        }
    );
    let all = || (0..8).flat_map(|k| (0..8).flat_map(move |j| (0..8).map(move |i| (i, j, k))));
    let total: f64 = all().map(|(i, j, k)| map.cell_depth(i, j, k)).sum();
    // alpha * w * length / ds^2 = 0.005 * 2 / 0.0625
    assert!((total - 0.005 * 2.0 / (ds * ds)).abs() < 1e-5, "{total}");
    // Every deposit lies in the fiber's slice, in 8 columns along it and
    // 2 across it: the fiber is 0.4 cells past a column centre across,
    // so the tent splat weighs the two sides 0.9 and 0.1.
    let c = map.frame().to_cells(Vec3::new(0.1, 0.1, 0.0));
    assert!(all().all(|(i, j, k)| i == c.x as usize || map.quanta(i, j, k) == 0));
    let cols: Vec<f64> = (0..64)
        .filter(|&col| map.span(col).is_some())
        .map(|col| map.cell_depth(c.x as usize, col % 8, col / 8))
        .collect();
    assert_eq!(cols.len(), 16);
    let per_col = total / 8.0;
    assert_eq!(
        cols.iter()
            .filter(|&&d| (d - 0.9 * per_col).abs() < 1e-5)
            .count(),
        8,
        "{cols:?}"
    );
    assert_eq!(
        cols.iter()
            .filter(|&&d| (d - 0.1 * per_col).abs() < 1e-5)
            .count(),
        8,
        "{cols:?}"
    );
}

#[test]
fn a_fiber_along_the_light_casts_nothing() {
    let mut map = DensityMap::new(frame(8));
    let mut hair = Hair::new();
    hair.push_strand(&[Vec3::new(-0.9, 0.1, 0.1), Vec3::new(0.9, 0.1, 0.1)])
        .unwrap();
    map.fill(&hair, &Fiber::new(0.01, 1.0).unwrap());
    assert!((0..64).all(|c| map.span(c).is_none()));
}

#[test]
fn hair_outside_the_map_is_counted_not_wrapped() {
    let mut map = DensityMap::new(frame(4));
    let mut hair = Hair::new();
    hair.push_strand(&[Vec3::new(0.0, 5.0, -0.5), Vec3::new(0.0, 5.0, 0.5)])
        .unwrap();
    let stats = map.fill(&hair, &Fiber::new(0.1, 1.0).unwrap());
    assert_eq!(stats.samples, 0);
    assert!(stats.out_of_map > 0);
    assert!(
        (0..16).all(|c| map.span(c).is_none()),
        "nothing wrapped into the map"
    );
}

#[test]
fn clear_resets_cells_and_spans() {
    let mut map = DensityMap::new(frame(8));
    let mut hair = Hair::new();
    hair.push_strand(&[Vec3::new(0.1, 0.1, -1.0), Vec3::new(0.1, 0.1, 1.0)])
        .unwrap();
    map.fill(&hair, &Fiber::new(0.01, 0.5).unwrap());
    map.clear();
    assert!((0..64).all(|c| map.span(c).is_none()));
    assert!((0..8).all(|k| map.quanta(4, 4, k) == 0));
}

/// Hair of many strands on a fixed map, some crossing its faces, some
/// far outside it, one along a slice boundary.
fn crossing_hair() -> Hair {
    let mut hair = Hair::new();
    for s in 0..40 {
        let t = s as f32 * 0.37;
        let pts: Vec<Vec3> = (0..30)
            .map(|i| {
                let u = i as f32 / 29.0;
                Vec3::new(
                    1.3 * (t + 5.0 * u).sin(),
                    -1.4 + 2.8 * u,
                    1.2 * (t * 1.7 + 3.0 * u).cos(),
                )
            })
            .collect();
        hair.push_strand(&pts).unwrap();
    }
    hair.push_strand(&[Vec3::new(0.0, -50.0, 3.0), Vec3::new(0.0, 50.0, -3.0)])
        .unwrap();
    hair.push_strand(&[Vec3::new(0.2, 0.0, -0.9), Vec3::new(0.2, 0.0, 0.9)])
        .unwrap();
    hair
}

fn snapshot(map: &DensityMap) -> (Vec<u32>, Vec<ColumnMeta>) {
    let cols = map.frame().columns();
    (map.cells.clone(), (0..cols).map(|c| map.meta(c)).collect())
}

#[test]
fn any_thread_count_and_any_split_of_the_strands_give_the_same_map() {
    let hair = crossing_hair();
    let fiber = Fiber::new(0.01, 0.5).unwrap();
    let fill = |threads: usize, parts: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            let mut map = DensityMap::new(frame(24));
            let strands = hair.strand_count();
            let mut stats = FillStats::default();
            for p in 0..parts {
                let range = p * strands / parts..(p + 1) * strands / parts;
                stats = stats + map.deposit(&hair, range, &fiber);
            }
            (stats, snapshot(&map))
        })
    };
    let (stats, one) = fill(1, 1);
    assert!(stats.samples > 500 && stats.out_of_map > 100, "{stats:?}");
    for (threads, parts) in [(2, 1), (3, 1), (7, 1), (1, 3), (4, 5)] {
        let (s, m) = fill(threads, parts);
        assert_eq!(s, stats, "{threads} threads, {parts} parts");
        assert!(m == one, "{threads} threads, {parts} parts: another map");
    }
}

#[test]
fn a_column_span_holds_all_its_hair_and_its_front_precedes_it() {
    let hair = crossing_hair();
    let mut map = DensityMap::new(frame(24));
    map.fill(&hair, &Fiber::new(0.01, 0.5).unwrap());
    let n = 24;
    let mut occupied = 0;
    for col in 0..n * n {
        let m = map.meta(col);
        for i in 0..n {
            if map.cells[col * n + i] > 0 {
                occupied += 1;
                assert!(!m.is_empty() && (m.lo as usize..=m.hi as usize).contains(&i));
                assert!(m.front < (m.lo + 1) as f32, "{m:?}");
            }
        }
    }
    assert!(occupied > 500);
}

#[test]
fn saturates_instead_of_wrapping() {
    let mut map = DensityMap::new(frame(2));
    map.add_quanta(0, 0, 0, u32::MAX - 1);
    map.add_quanta(0, 0, 0, 5);
    assert_eq!(map.quanta(0, 0, 0), u32::MAX);
}
