//! The protocol's checks over arbitrary input: any bytes decoded as any
//! message, and messages of arbitrary field values, go through the same
//! validation a worker or coordinator applies. Nothing panics; whatever
//! passes is within bounds.

use super::*;
use crate::pb;
use glam::Vec3;
use proptest::prelude::*;
use prost::Message;
use shadow::{ColumnSlab, DensityMap, Light, LightFrame};

fn frame() -> LightFrame {
    let light = Light::directional(Vec3::new(0.3, -1.0, 0.2)).unwrap();
    LightFrame::centered(&light, Vec3::ZERO, 2.0, 8).unwrap()
}

/// A map of frame `f` with hair in a few columns.
fn occupied_map(f: &LightFrame) -> DensityMap {
    let mut map = DensityMap::new(*f);
    for (i, j, k) in [(0, 0, 0), (3, 0, 0), (7, 5, 2), (2, 7, 7)] {
        map.add_quanta(i, j, k, 1 << 20);
    }
    map
}

/// Every check a received message goes through, on `bytes` decoded as
/// each message type that decodes.
fn check_all(bytes: &[u8]) {
    let f = frame();
    if let Ok(m) = pb::DensityChunk::decode(bytes) {
        if let Ok(fr) = frame_from_pb(m.map.as_ref()) {
            assert!(fr.n_cells >= 1 && fr.ds > 0.0);
        }
        let mut hair = strands::Hair::new();
        if add_strands(&mut hair, &m).is_ok() {
            assert!(hair.points().iter().all(|p| p.is_finite()));
        }
    }
    if let Ok(m) = pb::ColumnChunk::decode(bytes) {
        let mut map = DensityMap::new(f);
        let _ = merge_columns(&mut map, &m);
    }
    if let Ok(m) = pb::SlabChunk::decode(bytes) {
        let map = occupied_map(&f);
        let layout = ColumnSlab::layout(&map, 0..f.columns() as u32);
        let mut reader = SlabReader::new(layout);
        if reader.add(&m).is_ok()
            && let Ok(slab) = reader.finish()
        {
            shadow::Transmittance::check_slab(&f, &slab).unwrap();
        }
    }
    if let Ok(m) = pb::SimulateRequest::decode(bytes) {
        check_step(&m);
    }
    if let Ok(m) = pb::WispChunk::decode(bytes) {
        for per in [1, 3, 96] {
            if let Ok(states) = wisps_from_chunk(&m, per, &(0..134)) {
                assert!(states.iter().all(|(w, s)| *w < 134 && s.pos.len() == per));
            }
        }
        if let Some(r) = &m.report {
            check_report(r);
        }
    }
    if let Ok(m) = pb::PosePlan::decode(bytes)
        && let Ok(p) = pose_plan_from_pb(&m)
    {
        assert!(p.head.is_finite() && p.anchor.is_finite());
        assert!(p.lights.len() <= MAX_LIGHTS);
    }
    if let Ok(m) = pb::PoseReport::decode(bytes) {
        check_report(&m);
    }
    if let Ok(m) = pb::ColumnChunk::decode(bytes)
        && let Ok(bits) = columns_from_pb(&m.columns_read, f.columns())
    {
        assert_eq!(bits.len(), f.columns().div_ceil(64));
    }
    if let Ok(m) = pb::DrawChunk::decode(bytes) {
        if let Some(j) = &m.job
            && let Ok(job) = job_from_pb(j)
        {
            assert!(job.camera.width() >= 1 && job.lights.len() <= MAX_LIGHTS);
        }
        let mut reader = ColumnsReader::new(1);
        if reader.add(&m).is_ok()
            && let Ok(maps) = reader.finish()
        {
            // Whatever was accepted looks up finite, in [0, 1].
            let t = maps[0].transmittance_at(Vec3::ZERO, true);
            assert!((0.0..=1.0).contains(&t), "{t}");
        }
    }
    if let Ok(m) = pb::LayerChunk::decode(bytes) {
        let mut reader = LayerReader::new(m.width.min(64), m.height.min(64));
        if reader.add(&m).is_ok() {
            let layer = reader.finish().unwrap();
            assert!(layer.pixels().len() <= 64 * 64);
        }
        // As a band of finished rows: whatever is accepted fills its rows.
        let (w, h) = (m.width.min(64), m.height.min(64));
        let mut bands = BandReader::new(w, h, vec![0..h.min(16), h.min(16)..h]);
        if bands.add(&m).is_ok() {
            for (rows, rgb) in bands.finish().into_iter().flatten() {
                assert_eq!(rgb.len(), (rows.end - rows.start) as usize * 3 * w as usize);
            }
        }
    }
    if let Ok(m) = pb::DensityChunk::decode(bytes) {
        check_column_plan(&m);
    }
    if let Ok(m) = pb::DrawChunk::decode(bytes)
        && let Some(b) = &m.bands
        && let Ok(bands) = Bands::from_pb(b, 720)
    {
        assert!(bands.plan.own < bands.peers.len() && bands.peers.len() <= MAX_WORKERS);
        assert!(
            bands
                .plan
                .rows_of(bands.plan.own)
                .iter()
                .all(|r| r.end <= 720)
        );
    }
}

/// A column plan that is accepted cuts the map whole, in ranges that
/// never fall, and every worker's swept columns that are accepted lie in
/// its range.
fn check_column_plan(m: &pb::DensityChunk) {
    let f = frame();
    let Some(p) = &m.columns else { return };
    let Ok(plan) = ColumnPlan::from_pb(p, f.columns()) else {
        return;
    };
    assert!(plan.own < plan.workers() && plan.workers() <= MAX_WORKERS);
    let ranges: Vec<_> = (0..plan.workers()).map(|i| plan.range(i)).collect();
    assert_eq!(ranges.first().map(|r| r.start), Some(0));
    assert_eq!(ranges.last().map(|r| r.end), Some(f.columns()));
    assert!(ranges.windows(2).all(|w| w[0].end == w[1].start));
    // Every worker's columns swept from a full map, each in its range.
    let map = occupied_map(&f);
    let owners: Vec<Vec<pb::DrawChunk>> = ranges
        .iter()
        .map(|r| swept_chunks(&f, &shadow::sweep(&map, r.start as u32..r.end as u32)))
        .collect();
    let t = assemble_swept(f, &plan, &owners).unwrap();
    assert_eq!(t.frame(), &f);
    // The first worker's columns given as the last's are refused, unless
    // both hold the same columns (or none).
    if plan.workers() > 1 && ranges[0] != ranges[plan.workers() - 1] {
        let mut swapped = owners.clone();
        swapped.swap(0, plan.workers() - 1);
        let occupied = |r: &std::ops::Range<usize>| r.clone().any(|c| !map.meta(c).is_empty());
        if occupied(&ranges[0]) || occupied(&ranges[plan.workers() - 1]) {
            assert!(assemble_swept(f, &plan, &swapped).is_err());
        }
    }
}

fn check_report(r: &pb::PoseReport) {
    for lights in [0, 1, 2] {
        if let Ok(rep) = report_from_pb(r, lights) {
            assert_eq!(rep.extents.len(), lights);
            assert!(rep.bounds.is_empty() || rep.bounds.min.cmple(rep.bounds.max).all());
        }
    }
}

fn check_step(m: &pb::SimulateRequest) {
    if let Ok(heads) = affines_from_floats(&m.heads) {
        assert!(heads.iter().all(|h| h.is_finite()));
    }
    if let Ok(bodies) = bodies_from_floats(&m.bodies) {
        assert!(bodies.iter().all(|b| b.radius >= 0.0));
    }
    for len in [0, 1, 100] {
        if let Ok(a) = accel_from_pb(&m.accel_skip, &m.accel, len) {
            assert_eq!(a.len(), len);
            assert!(a.iter().all(|v| v.is_finite()));
        }
    }
}

/// Floats that are often special.
fn float() -> impl Strategy<Value = f32> {
    prop_oneof![
        Just(f32::NAN),
        Just(f32::INFINITY),
        Just(-0.0f32),
        Just(f32::MAX),
        -10.0f32..10.0,
    ]
}

proptest! {
    #![proptest_config(ProptestConfig {
        cases: 512,
        // The same cases on every run (CI gates on them); set
        // PROPTEST_RNG_SEED to explore others.
        rng_seed: match ProptestConfig::default().rng_seed {
            proptest::test_runner::RngSeed::Random => proptest::test_runner::RngSeed::Fixed(0x5eed),
            chosen => chosen,
        },
        ..ProptestConfig::default()
    })]

    #[test]
    fn any_bytes_as_any_message(bytes in proptest::collection::vec(any::<u8>(), 0..512)) {
        check_all(&bytes);
    }

    #[test]
    fn valid_messages_with_bytes_flipped(
        flips in proptest::collection::vec((any::<usize>(), any::<u8>()), 1..8),
        cut in any::<usize>(),
    ) {
        // A real Density chunk, column chunk and slab chunk, damaged.
        let f = frame();
        let mut hair = strands::Hair::new();
        hair.push_strand(&[Vec3::ZERO, Vec3::new(0.1, 0.2, 0.0), Vec3::new(0.2, 0.5, 0.1)]).unwrap();
        let deposit = density_chunks(1, 0, &f, &hair, 0..1).remove(0);
        let mut map = DensityMap::new(f);
        map.deposit(&hair, 0..1, &shadow::Fiber::new(0.1, 0.5).unwrap());
        let columns = column_chunks(&map, 0..f.columns()).remove(0);
        let full = 0..f.columns() as u32;
        let swept = shadow::sweep(&occupied_map(&f), full);
        let slab = slab_chunks(&swept).remove(0);
        let draw = draw_columns(0, &f, &[swept], None).remove(0);
        let mut layer_canvas = raster::Canvas::new(8, 8).unwrap();
        let cam = raster::Camera::new(Vec3::new(0.0, 0.0, 5.0), Vec3::ZERO, 40.0, 8, 8).unwrap();
        let look = raster::HairLook { fiber_width: 0.1, opacity: 0.8, depth_ref: 5.0, simplify: 0.0 };
        let pts = [Vec3::new(-1.0, -1.0, 0.0), Vec3::new(1.0, 1.0, 0.0)];
        layer_canvas.draw_hair(&cam, &pts, &[0, 2], &[Vec3::ONE; 2], &look, &[], 0);
        let layer = layer_chunks(&layer_canvas.layer(), &engine::DrawTimes::default()).remove(0);
        let rows = layer_canvas.resolve(Vec3::ZERO);
        let band = band_chunks(8, 8, 0, &rows, [0, 0, 0]).remove(0);
        let plan = Bands {
            round: 3,
            plan: engine::BandPlan::dealt(720, 48, 2, 1),
            peers: vec![("10.0.0.1:1".into(), "ab".into()), ("10.0.0.2:1".into(), "cd".into())],
            wait: std::time::Duration::from_secs(1),
            tls_domain: None,
        };
        let banded = pb::DrawChunk { bands: Some(plan.to_pb()), ..Default::default() };
        let column_plan = ColumnPlan {
            round: 4,
            cuts: ColumnPlan::cuts(f.columns(), 3, |c| c as u64 % 5),
            own: 2,
            peers: vec![
                ("10.0.0.1:1".into(), "ab".into()),
                ("10.0.0.2:1".into(), "cd".into()),
                ("10.0.0.3:1".into(), "ef".into()),
            ],
            wait: std::time::Duration::from_secs(1),
            tls_domain: None,
            head: Some(glam::Affine3A::from_translation(Vec3::X)),
        };
        let planned = pb::DensityChunk { columns: Some(column_plan.to_pb()), ..deposit.clone() };
        let messages = [
            planned.encode_to_vec(),
            band.encode_to_vec(),
            banded.encode_to_vec(),
            deposit.encode_to_vec(),
            columns.encode_to_vec(),
            slab.encode_to_vec(),
            draw.encode_to_vec(),
            layer.encode_to_vec(),
        ];
        for msg in messages {
            let mut b = msg;
            for &(at, x) in &flips {
                if !b.is_empty() {
                    let i = at % b.len();
                    b[i] ^= x;
                }
            }
            b.truncate(cut % (b.len() + 1));
            check_all(&b);
        }
    }

    #[test]
    fn step_requests_of_arbitrary_values(
        heads in proptest::collection::vec(float(), 0..40),
        bodies in proptest::collection::vec(float(), 0..20),
        skip in proptest::collection::vec(any::<u32>(), 0..8),
        accel in proptest::collection::vec(float(), 0..30),
    ) {
        check_step(&pb::SimulateRequest {
            heads,
            bodies,
            accel_skip: skip,
            accel,
            has_accel: true,
            ..Default::default()
        });
    }
}
