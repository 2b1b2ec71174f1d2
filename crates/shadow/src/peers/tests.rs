use super::deep_shadow_map::{compress, visibility, visibility_at};
use super::density_clustering::{Bin, cluster_bins};
use super::fragments::Frag;

fn frag(z: f32, len: f32, beta: f32) -> Frag {
    Frag { z, len, beta }
}

#[test]
fn visibility_is_exact_for_ramps_and_compression_stays_within_tolerance() {
    let fs = [
        frag(1.0, 2.0, 0.4),
        frag(2.0, 0.0, 0.3),
        frag(5.0, 1.0, 1.0),
    ];
    let mut exact = Vec::new();
    visibility(&fs, &mut exact);
    // D(3) = 0.4 + 0.3: the step at 2 (a ramp of MIN_SPAN) is passed.
    let at = |x: f32| visibility_at(&exact, x);
    assert_eq!(at(0.5), 1.0);
    assert!((at(2.0) - (-0.2f32).exp()).abs() < 1e-4);
    assert!((at(3.0) - (-0.7f32).exp()).abs() < 1e-4);
    assert!((at(9.0) - (-1.7f32).exp()).abs() < 1e-4);
    for tol in [0.0, 0.01, 0.1] {
        let mut c = Vec::new();
        compress(&exact, tol, &mut c);
        assert!(c.len() <= exact.len());
        for &(z, v) in &exact {
            assert!(
                (visibility_at(&c, z) - v).abs() <= 2.0 * tol + 1e-5,
                "tol {tol} at {z}"
            );
        }
        assert!(c.windows(2).all(|w| w[1].1 <= w[0].1 && w[1].0 >= w[0].0));
    }
}

#[test]
fn clusters_of_one_depth_become_a_step() {
    let fs = [frag(3.0, 0.0, 0.5), frag(3.0, 0.0, 0.25)];
    let mut bins = [Bin::EMPTY; 4];
    cluster_bins(&fs, &mut bins);
    let d = |x: f32| bins.iter().map(|b| b.depth(x)).sum::<f32>();
    assert_eq!(d(2.9), 0.0);
    assert_eq!(d(3.0), 0.0);
    assert_eq!(d(3.01), 0.75);
    assert!(bins.iter().all(|b| b.lo <= b.hi || b.b == 0.0));
}

#[test]
fn two_separate_bundles_give_two_bins_with_their_own_depth() {
    // Uniform bundles over [0, 2] and [10, 12], weight 1 each.
    let fs: Vec<Frag> = (0..20)
        .map(|i| frag(0.1 * i as f32, 0.0, 0.05))
        .chain((0..20).map(|i| frag(10.0 + 0.1 * i as f32, 0.0, 0.05)))
        .collect();
    let mut bins = [Bin::EMPTY; 4];
    cluster_bins(&fs, &mut bins);
    let d = |x: f32| bins.iter().map(|b| b.depth(x)).sum::<f32>();
    assert!(d(-0.5) == 0.0 && (d(5.0) - 1.0).abs() < 1e-5, "{bins:?}");
    assert!((d(13.0) - 2.0).abs() < 1e-5);
    // Half way through the first bundle, about half its depth.
    assert!((d(0.95) - 0.5).abs() < 0.1, "{}", d(0.95));
}
