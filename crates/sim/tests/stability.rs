//! The dynamics over long runs: rigid links stay rigid, large steps do not
//! explode, bodies keep hair out, and the bytes do not depend on threads or
//! on how the wisps are split.

use glam::{Affine3A, Vec3};
use sim::{Body, ForceField, HairSim, Motion, SimParams};
use strands::{Style, StyleParams, WispModel};

fn guides(style: Style) -> strands::Hair {
    WispModel::generate(&StyleParams::new(style)).guides
}

/// The head sphere under `head`, a little inside the scalp where roots sit.
fn head_body(head: &Affine3A) -> Body {
    Body {
        center: head.transform_point3(Vec3::ZERO),
        radius: 9.8,
    }
}

fn run(sim: &mut HairSim, motion: &Motion, steps: usize, field: Option<&dyn ForceField>) {
    let dt = sim.params().dt;
    sim.reset(&motion.at(0.0, Vec3::ZERO));
    for s in 1..=steps {
        let head = motion.at(s as f32 * dt, Vec3::ZERO);
        sim.step(&head, &[head_body(&head)], field);
    }
}

fn bits(sim: &HairSim) -> Vec<u32> {
    (0..sim.wisp_count())
        .flat_map(|w| sim.wisp(w).pos.clone())
        .flat_map(|p| p.to_array().map(f32::to_bits))
        .collect()
}

#[test]
fn links_stay_within_one_percent_over_a_thousand_dance_steps() {
    for style in [Style::Smooth, Style::Curly] {
        let mut sim = HairSim::new(&guides(style), SimParams::default()).unwrap();
        let dance = Motion::Dance { amplitude: 1.0 };
        let dt = sim.params().dt;
        sim.reset(&dance.at(0.0, Vec3::ZERO));
        for s in 1..=1000 {
            let head = dance.at(s as f32 * dt, Vec3::ZERO);
            sim.step(&head, &[head_body(&head)], None);
            if s % 100 == 0 {
                let stretch = sim.max_stretch();
                assert!(
                    stretch < 0.01,
                    "{style:?} step {s}: a link is off by {stretch}"
                );
            }
        }
    }
}

#[test]
fn four_times_the_time_step_does_not_explode() {
    let g = guides(Style::Smooth);
    let params = SimParams {
        dt: 4.0 * SimParams::default().dt,
        ..SimParams::default()
    };
    let mut sim = HairSim::new(&g, params).unwrap();
    run(&mut sim, &Motion::Dance { amplitude: 1.0 }, 300, None);
    let reach = 10.0 + g.max_strand_length() + 5.0;
    for w in 0..sim.wisp_count() {
        for p in &sim.wisp(w).pos {
            assert!(p.is_finite() && p.length() < reach, "wisp {w} point {p}");
        }
    }
    assert!(sim.max_stretch() < 0.01);
}

#[test]
fn the_same_bytes_on_any_thread_count_and_any_split_of_wisps() {
    let g = guides(Style::Curly);
    let dance = Motion::Dance { amplitude: 1.0 };
    let results: Vec<Vec<u32>> = [1, 3]
        .into_iter()
        .map(|threads| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| {
                    let mut sim = HairSim::new(&g, SimParams::default()).unwrap();
                    run(&mut sim, &dance, 120, None);
                    bits(&sim)
                })
        })
        .collect();
    assert_eq!(results[0], results[1]);
    // Wisps stepped in three shares, as three workers would.
    let mut sim = HairSim::new(&g, SimParams::default()).unwrap();
    let dt = sim.params().dt;
    sim.reset(&dance.at(0.0, Vec3::ZERO));
    let n = sim.wisp_count();
    for s in 1..=120 {
        let head = dance.at(s as f32 * dt, Vec3::ZERO);
        for share in [0..n / 3, n / 3..2 * n / 3, 2 * n / 3..n] {
            sim.step_wisps(share, &head, &[head_body(&head)], None);
        }
    }
    assert_eq!(bits(&sim), results[0]);
}

#[test]
fn hair_at_rest_without_gravity_stays_at_rest_for_a_thousand_steps() {
    let g = guides(Style::Curly);
    let params = SimParams {
        gravity: Vec3::ZERO,
        ..SimParams::default()
    };
    let mut sim = HairSim::new(&g, params).unwrap();
    sim.reset(&Affine3A::IDENTITY);
    for _ in 0..1000 {
        sim.step(&Affine3A::IDENTITY, &[], None);
    }
    let mut now = g.clone();
    sim.write_guides(&mut now);
    // Only float rounding moves it; an unstable shape constraint would
    // oscillate by whole units.
    for (a, b) in now.points().iter().zip(g.points()) {
        assert!(a.distance(*b) < 1e-3, "{a} moved from {b}");
    }
}

#[test]
fn the_dance_moves_hair_relative_to_the_head_and_the_head_keeps_it_out() {
    let g = guides(Style::Smooth);
    let mut sim = HairSim::new(&g, SimParams::default()).unwrap();
    let dance = Motion::Dance { amplitude: 1.0 };
    run(&mut sim, &dance, 90, None);
    let head = dance.at(90.0 * sim.params().dt, Vec3::ZERO);
    let mut now = g.clone();
    sim.write_guides(&mut now);
    // Tips lag behind the head: not rigidly attached.
    let lag = now
        .strands()
        .zip(g.strands())
        .map(|(a, b)| a[a.len() - 1].distance(head.transform_point3(b[b.len() - 1])))
        .fold(0.0f32, f32::max);
    assert!(lag > 1.0, "tips follow the head rigidly (lag {lag})");
    let centre = head.transform_point3(Vec3::ZERO);
    let inside = now
        .strands()
        .flat_map(|s| s[2..].iter())
        .map(|p| 9.8 - p.distance(centre))
        .fold(0.0f32, f32::max);
    assert!(inside < 0.5, "hair {inside} units inside the head");
}

/// A field that pushes everything away from the head's centre, hard.
struct Push;
impl ForceField for Push {
    fn acceleration(&self, p: Vec3) -> Vec3 {
        p.normalize_or_zero() * 5000.0
    }
}

#[test]
fn a_force_field_moves_hair_and_lengths_hold() {
    let g = guides(Style::Smooth);
    let mut free = HairSim::new(&g, SimParams::default()).unwrap();
    let mut pushed = free.clone();
    run(&mut free, &Motion::Still, 60, None);
    run(&mut pushed, &Motion::Still, 60, Some(&Push));
    let spread = |s: &HairSim| {
        (0..s.wisp_count())
            .flat_map(|w| s.wisp(w).pos.clone())
            .map(|p| p.length())
            .sum::<f32>()
    };
    assert!(spread(&pushed) > spread(&free) * 1.01);
    assert!(pushed.max_stretch() < 0.01);
}

#[test]
fn bad_inputs_are_refused() {
    let g = guides(Style::Smooth);
    let bad = SimParams {
        dt: 0.0,
        ..SimParams::default()
    };
    assert!(HairSim::new(&g, bad).is_err());
    let mut two = strands::Hair::new();
    two.push_strand(&[Vec3::ZERO, Vec3::X, Vec3::Y]).unwrap();
    assert!(
        HairSim::new(&two, SimParams::default()).is_err(),
        "one guide is not a wisp"
    );
}

/// A field with absurd pushes: 1e30 units/s^2 one way, then the other.
struct Absurd;
impl ForceField for Absurd {
    fn acceleration(&self, p: Vec3) -> Vec3 {
        if p.x > 0.0 {
            Vec3::new(-1e30, 1e30, 0.0)
        } else {
            Vec3::new(1e30, 0.0, -1e30)
        }
    }
}

#[test]
fn stiff_links_at_the_largest_time_step_and_absurd_forces_stay_finite() {
    let g = guides(Style::Curly);
    let reach = 10.0 + g.max_strand_length() + 1.0;
    // The largest step a scene accepts (0.1 s, six times the default),
    // the stiffest style, the most iterations, strong gravity, no damping.
    let params = SimParams {
        dt: 0.1,
        gravity: Vec3::new(0.0, -1e5, 0.0),
        damping: 0.0,
        stiffness: 1.0,
        iterations: 64,
    };
    for field in [None, Some(&Absurd as &dyn ForceField)] {
        let mut sim = HairSim::new(&g, params).unwrap();
        run(&mut sim, &Motion::Dance { amplitude: 1.0 }, 100, field);
        for w in 0..sim.wisp_count() {
            for p in &sim.wisp(w).pos {
                assert!(p.is_finite() && p.length() < reach, "wisp {w} point {p}");
            }
        }
        assert!(
            sim.max_stretch() < 0.01,
            "a link is off by {}",
            sim.max_stretch()
        );
    }
}
