use super::*;
use glam::Affine3A;
use raster::{HairLayer, Sums};

#[test]
fn pose_plans_reports_and_jobs_round_trip_exactly() {
    let plan = PosePlan {
        version: 9,
        head: Affine3A::from_rotation_y(0.3) * Affine3A::from_translation(Vec3::X),
        sample: 17,
        drawn_bodies: vec![sim::Body {
            center: Vec3::new(0.0, -16.0, -3.0),
            radius: 6.0,
        }],
        lights: vec![Light::directional(Vec3::new(0.9, -0.35, -0.25)).unwrap()],
        anchor: Vec3::new(0.1, 2.0, -3.0),
    };
    assert_eq!(pose_plan_from_pb(&pose_plan_to_pb(&plan)).unwrap(), plan);
    let report = PoseReport {
        bounds: Bounds {
            min: Vec3::splat(-2.0),
            max: Vec3::new(3.0, 1.0, 2.0),
        },
        extents: vec![
            Extent {
                lo: Vec3::splat(-1.0),
                hi: Vec3::ONE,
            },
            Extent::EMPTY,
        ],
    };
    assert_eq!(report_from_pb(&report_to_pb(&report), 2).unwrap(), report);
    assert!(report_from_pb(&report_to_pb(&report), 1).is_err());
    let camera = Camera::new(Vec3::new(0.0, 8.0, 90.0), Vec3::ZERO, 30.0, 64, 48).unwrap();
    let job = DrawJob {
        version: 3,
        camera,
        look: HairLook {
            fiber_width: 0.1,
            opacity: 0.85,
            depth_ref: 90.0,
            simplify: 0.5,
        },
        shading: Shading::default(),
        lights: vec![
            Light::directional(Vec3::new(0.9, -0.35, -0.25)).unwrap(),
            Light::point(Vec3::new(1.0, 20.0, 3.0), 400.0).unwrap(),
            Light::spot(Vec3::new(-5.0, 20.0, 3.0), Vec3::NEG_Y, 25.0, 4.0, 300.0).unwrap(),
        ],
        shadows: true,
        trilinear: false,
        head: plan.head,
        nearest: 8,
    };
    assert_eq!(job_from_pb(&job_to_pb(&job)).unwrap(), job);
    let mut bad = job_to_pb(&job);
    bad.nearest = raster::MAX_NEAREST as u32 + 1;
    assert!(
        job_from_pb(&bad).is_err(),
        "more nearest fragments than a pixel keeps"
    );
    for simplify in [-1.0, 4.5, f32::NAN] {
        let mut bad = job_to_pb(&job);
        bad.simplify = simplify;
        let e = job_from_pb(&bad).unwrap_err().to_string();
        assert!(e.contains("simplify"), "{e}");
    }
    // A camera with its own up comes back the same.
    let tilted = DrawJob {
        camera: camera.with_up(Vec3::new(0.3, 0.2, 1.0)).unwrap(),
        ..job.clone()
    };
    assert_eq!(job_from_pb(&job_to_pb(&tilted)).unwrap(), tilted);
    let mut bad = job_to_pb(&job);
    bad.camera.truncate(7);
    assert!(job_from_pb(&bad).is_err());
    let mut bad = job_to_pb(&job);
    bad.width = 100_000;
    assert!(job_from_pb(&bad).is_err());
    let mut bad = job_to_pb(&job);
    bad.lights = vec![0.0, 0.0, 0.0, 0.0, 0.0, 2.0, 0.0, 0.0, 0.0, 0.0];
    assert!(job_from_pb(&bad).is_err());
    let mut bad = job_to_pb(&job);
    bad.lights[10] = 7.0;
    assert!(job_from_pb(&bad).is_err(), "a light of no kind");
    let mut bad = job_to_pb(&job);
    bad.lights[29] = -1.0;
    assert!(job_from_pb(&bad).is_err(), "a spot of negative intensity");
    let mut bad = job_to_pb(&job);
    bad.lights[27] = 95.0;
    assert!(job_from_pb(&bad).is_err());
    // The fiber, with multiple scattering and without.
    for multiple in [false, true] {
        let fiber = DrawJob {
            shading: Shading {
                model: ShadingModel::Marschner {
                    optics: raster::FiberOptics::default(),
                    from_color: false,
                    irradiance: 5.0,
                    multiple,
                },
                ..Shading::default()
            },
            ..job.clone()
        };
        let sent = job_to_pb(&fiber);
        assert_eq!(sent.fiber.len(), 9 + usize::from(multiple));
        assert_eq!(job_from_pb(&sent).unwrap(), fiber);
    }
    let mut sent = job_to_pb(&job);
    sent.shading_model = 1;
    for fiber in [vec![1.55; 8], vec![1.55; 11]] {
        sent.fiber = fiber;
        assert!(job_from_pb(&sent).is_err());
    }
    let mut fiber = vec![1.55, 0.5, 0.5, 0.5, 0.3, 0.3, 2.0, 5.0, 0.0];
    sent.fiber = fiber.clone();
    assert!(job_from_pb(&sent).is_ok());
    for tenth in [0.0, 2.0, f32::NAN] {
        fiber.truncate(9);
        fiber.push(tenth);
        sent.fiber = fiber.clone();
        assert!(job_from_pb(&sent).is_err(), "{tenth}");
    }
}

#[test]
fn column_bitmaps_round_trip_and_refuse_columns_past_the_map() {
    let mut bits = vec![0u64; 3];
    bits[0] = 1 | 1 << 40;
    bits[2] = 1 << 3;
    let packed = columns_to_pb(&bits);
    assert_eq!(columns_from_pb(&packed, 150).unwrap(), bits);
    // Column 131 is past a map of 130 columns.
    assert!(columns_from_pb(&packed, 130).is_err());
}

#[test]
fn partial_pictures_round_trip_across_chunks_and_malformed_ones_are_refused() {
    let n = PIXELS_PER_CHUNK + 10;
    let pixels: Vec<u32> = (0..n as u32).map(|i| 3 * i + 1).collect();
    let sums: Vec<Sums> = (0..n as i64)
        .map(|i| Sums {
            rgbw: [i, 2 * i, 3 * i + 1, 1 << 40],
            absorb: i as u64 * 7,
        })
        .collect();
    let layer = HairLayer::from_parts(1000, 1000, pixels, sums).unwrap();
    let times = engine::DrawTimes {
        filter_ms: 1.0,
        shade_ms: 2.0,
        raster_ms: 3.0,
        wait_ms: 7.0,
        composite_ms: 8.0,
    };
    let chunks = layer_chunks(&layer, &times);
    assert_eq!(chunks.len(), 2);
    let mut r = LayerReader::new(1000, 1000);
    for c in &chunks {
        r.add(c).unwrap();
    }
    assert_eq!(r.times, times);
    assert_eq!(r.finish().unwrap(), layer);
    // Another size, a pixel past the picture, bytes left over.
    assert!(LayerReader::new(10, 10).add(&chunks[0]).is_err());
    let mut c = chunks[1].clone();
    c.pixels.push(0x7f);
    let mut r = LayerReader::new(1000, 1000);
    r.add(&chunks[0]).unwrap();
    assert!(r.add(&c).is_err());
    let small = HairLayer::from_parts(4, 4, vec![15], vec![Sums::ZERO]).unwrap();
    let c = layer_chunks(&small, &times).remove(0);
    assert!(LayerReader::new(4, 4).add(&c).is_ok());
    let mut wide = c.clone();
    wide.pixels = vec![16];
    assert!(LayerReader::new(4, 4).add(&wide).is_err());
}

#[test]
fn nearest_fragments_round_trip_and_bad_ones_are_refused() {
    use raster::Fragment;
    let n = PIXELS_PER_CHUNK + 10;
    let pixels: Vec<u32> = (0..n as u32).map(|i| 2 * i).collect();
    let sums = vec![Sums::ZERO; n];
    // 0 to 3 fragments a pixel, nearest first.
    let counts: Vec<u8> = (0..n).map(|i| (i % 4) as u8).collect();
    let fronts: Vec<Fragment> = counts
        .iter()
        .enumerate()
        .flat_map(|(i, &c)| {
            (0..c).map(move |k| Fragment {
                z: 10.0 + k as f32 + i as f32 * 1e-3,
                color: Vec3::new(0.1, 0.2, 0.3 * k as f32),
                alpha: 0.25,
                weight: 2.0,
            })
        })
        .collect();
    let layer =
        HairLayer::from_parts_with_fronts(1000, 1000, pixels, sums, &counts, fronts).unwrap();
    let chunks = layer_chunks(&layer, &engine::DrawTimes::default());
    assert_eq!(chunks.len(), 2);
    let mut r = LayerReader::new(1000, 1000);
    for c in &chunks {
        r.add(c).unwrap();
    }
    let back = r.finish().unwrap();
    assert_eq!(back, layer);
    assert_eq!(back.front(3).len(), 3);
    // Malformed: too many at a pixel, cut short, out of order, NaN.
    let read = |c: &pb::LayerChunk| {
        let mut r = LayerReader::new(1000, 1000);
        r.add(c).and_then(|()| r.finish().map(|_| ()))
    };
    let mut c = chunks[0].clone();
    c.fronts[0] = 17;
    assert!(read(&c).is_err());
    let mut c = chunks[0].clone();
    c.fronts.pop();
    assert!(read(&c).is_err());
    // Pixel 3's first two fragments swapped: depths 10.003 and 11.003.
    let mut c = chunks[0].clone();
    let at = 1 + (1 + 24) + (1 + 2 * 24) + 1;
    let (a, b) = c.fronts[at..at + 48].split_at_mut(24);
    a.swap_with_slice(b);
    assert!(read(&c).is_err(), "fragments out of order");
    let mut c = chunks[0].clone();
    c.fronts[at..at + 4].copy_from_slice(&f32::NAN.to_le_bytes());
    assert!(read(&c).is_err(), "a NaN depth");
}

#[test]
fn a_picture_sent_in_stripes_reads_back_as_the_whole() {
    let width = 1000;
    let n = 2 * PIXELS_PER_CHUNK + 100;
    // Dense in the first stripe (two chunks), sparse below.
    let pixels: Vec<u32> = (0..n as u32)
        .map(|i| {
            if i < 20_000 {
                i
            } else {
                20_000 + 70 * (i - 20_000)
            }
        })
        .collect();
    let sums: Vec<Sums> = (0..n as i64)
        .map(|i| Sums {
            rgbw: [i, 5 * i, 1, i << 30],
            absorb: i as u64,
        })
        .collect();
    let whole = HairLayer::from_parts(width, 1000, pixels.clone(), sums.clone()).unwrap();
    // The pixels whose rows `keep` says, as a layer.
    let layer_of = |keep: &dyn Fn(u32) -> bool| {
        let kept: Vec<usize> = (0..n).filter(|&i| keep(pixels[i] / width)).collect();
        HairLayer::from_parts(
            width,
            1000,
            kept.iter().map(|&i| pixels[i]).collect(),
            kept.iter().map(|&i| sums[i]).collect(),
        )
        .unwrap()
    };
    // Rows 200..300 have no hair: one stripe is empty.
    let drawn = |row: u32| !(200..300).contains(&row);
    // Stripes of 100 rows (100,000 pixels).
    let stripe = |rows: std::ops::Range<u32>| layer_of(&|row| rows.contains(&row) && drawn(row));
    let expect = layer_of(&drawn);
    assert!(expect.pixels().len() < whole.pixels().len());
    let times = engine::DrawTimes {
        filter_ms: 4.0,
        shade_ms: 5.0,
        raster_ms: 6.0,
        ..Default::default()
    };
    let mut enc = StripeEncoder::new();
    let mut chunks = Vec::new();
    for y in (0..1000).step_by(100) {
        chunks.extend(enc.chunks(&stripe(y..y + 100)));
    }
    chunks.push(enc.last(width, 1000, &times));
    assert_eq!(
        chunks.len(),
        11,
        "2 chunks, 8 stripes of one, 1 empty, the last"
    );
    let mut r = LayerReader::new(width, 1000);
    for c in &chunks {
        r.add(c).unwrap();
    }
    assert_eq!(r.times, times);
    assert_eq!(r.finish().unwrap(), expect);
}

#[test]
fn swept_columns_a_worker_reads_round_trip_into_the_same_transmittance() {
    let light = Light::directional(Vec3::new(0.3, -1.0, 0.2)).unwrap();
    let frame = LightFrame::centered(&light, Vec3::ZERO, 4.0, 12).unwrap();
    let mut map = shadow::DensityMap::new(frame);
    let mut hair = strands::Hair::new();
    for s in 0..12 {
        let x = -1.5 + 0.25 * s as f32;
        hair.push_strand(&[Vec3::new(x, 1.5, -1.0), Vec3::new(x * 0.5, -1.5, 1.0)])
            .unwrap();
    }
    map.deposit(&hair, 0..12, &shadow::Fiber::new(0.05, 0.6).unwrap());
    let whole = shadow::Transmittance::compute(&map);
    let cols = frame.columns() as u32;
    let slabs = [
        shadow::sweep(&map, 0..cols / 2),
        shadow::sweep(&map, cols / 2..cols),
    ];
    let read = shadow::columns_read(&frame, hair.points(), true);
    for keep in [None, Some(&read[..])] {
        let mut r = ColumnsReader::new(1);
        for c in draw_columns(0, &frame, &slabs, keep) {
            r.add(&c).unwrap();
        }
        let t = r.finish().unwrap().remove(0);
        for &p in hair.points() {
            assert_eq!(
                t.optical_depth(p, true).to_bits(),
                whole.optical_depth(p, true).to_bits()
            );
        }
    }
    // A column twice, and a light's columns before its frame, are refused.
    let mut chunks = draw_columns(0, &frame, &slabs, None);
    chunks[0].column_steps[1] = 0;
    let mut r = ColumnsReader::new(1);
    assert!(chunks.iter().try_for_each(|c| r.add(c)).is_err());
    let mut chunks = draw_columns(0, &frame, &slabs, None);
    chunks[0].map = None;
    assert!(ColumnsReader::new(1).add(&chunks[0]).is_err());
}

#[test]
fn finished_bands_round_trip_as_runs_and_malformed_ones_are_refused() {
    let one = std::slice::from_ref(&(16..48));
    let (w, h) = (100u32, 64u32);
    let bg = [7u8, 8, 9];
    // Rows 16..48: background but for a few runs, one across a row end.
    let mut rgb: Vec<u8> = bg.repeat((w * 32) as usize);
    for px in [0usize, 1, 2, 99, 100, 101, 1234, 3199] {
        rgb[3 * px..3 * px + 3].copy_from_slice(&[px as u8, 1, 2]);
    }
    let chunks = band_chunks(w, h, 16, &rgb, bg);
    assert_eq!(chunks.len(), 1);
    assert!(
        chunks[0].rgb.len() == 8 * 3,
        "only the pixels that are not background travel"
    );
    let times = engine::DrawTimes {
        wait_ms: 2.0,
        composite_ms: 3.0,
        ..Default::default()
    };
    let mut last = StripeEncoder::new().last(w, h, &times);
    last.stripes_sent = 77;
    let read = |chunks: &[pb::LayerChunk], bands: &[std::ops::Range<u32>]| {
        let mut r = BandReader::new(w, h, bands.to_vec());
        for c in chunks {
            r.add(c)?;
        }
        r.add(&last)?;
        assert_eq!((r.times, r.stripes_sent), (times, 77));
        r.finish()
    };
    let got = read(&chunks, one).unwrap();
    assert_eq!(got, vec![(16..48, rgb.clone())]);
    // Two bands, each whole: another band's rows, rows missing, a run
    // past the chunk and colours left over are refused.
    let two = [
        band_chunks(w, h, 0, &rgb[..(3 * w * 16) as usize], bg),
        chunks.clone(),
    ]
    .concat();
    assert!(read(&two, &[0..16, 32..64]).is_err());
    assert!(read(&chunks, &[16..48, 48..64]).is_err());
    let mut long = chunks[0].clone();
    long.spans.extend([0x80, 0x19, 1]);
    assert!(read(&[long], one).is_err());
    let mut spare = chunks[0].clone();
    spare.rgb.push(0);
    assert!(read(&[spare], one).is_err());
    let mut partial = chunks[0].clone();
    partial.count = 1;
    assert!(read(&[partial], one).is_err());
}

#[test]
fn band_plans_deal_whole_bands_and_absurd_ones_are_refused() {
    let plan = engine::BandPlan::dealt(720, 48, 3, 1);
    assert_eq!(plan.bands(), 15);
    assert_eq!(plan.rows_of(1)[..2], [48..96, 192..240]);
    assert!(plan.owns_row(50) && !plan.owns_row(47) && !plan.owns_row(720));
    // Canvas bands that cut these whole: 48 rows, or 16.
    assert_eq!(plan.band_rows_within(64), 48);
    assert_eq!(plan.band_rows_within(32), 16);
    assert_eq!(plan.band_rows_within(16), 16);
    let bands = Bands {
        round: 4,
        plan: plan.clone(),
        peers: (0..3)
            .map(|i| (format!("10.0.0.{i}:7000"), format!("s{i}")))
            .collect(),
        wait: std::time::Duration::from_secs(3),
        tls_domain: Some("workers".into()),
    };
    assert_eq!(Bands::from_pb(&bands.to_pb(), 720).unwrap(), bands);
    // Another height, a cut off the canvas bands, one worker, no session.
    assert!(Bands::from_pb(&bands.to_pb(), 700).is_err());
    let mut b = bands.to_pb();
    b.cuts[1] = 40;
    assert!(Bands::from_pb(&b, 720).is_err());
    let mut b = bands.to_pb();
    b.peers.truncate(1);
    b.sessions.truncate(1);
    b.own = 0;
    assert!(Bands::from_pb(&b, 720).is_err());
    let mut b = bands.to_pb();
    b.sessions[2].clear();
    assert!(Bands::from_pb(&b, 720).is_err());
    let mut b = bands.to_pb();
    b.own = 3;
    assert!(Bands::from_pb(&b, 720).is_err());
}
