use super::look::{MAX_SHARE_LEVEL, strand_drawn};
use super::*;
use crate::srgb8_to_linear;

#[test]
fn refuses_absurd_sizes() {
    assert!(Canvas::new(0, 10).is_err());
    assert!(Canvas::new(100_000, 10).is_err());
    assert!(Canvas::new(16_000, 16_000).is_err());
    assert!(Canvas::new(64, 48).is_ok());
}

#[test]
fn bands_grow_taller_for_dense_hair_only() {
    // Under a segment a pixel: 16 rows.
    assert_eq!(Canvas::band_rows_for(1280, 720, 100_000), 16);
    // Dense: up to 64 rows of 1280 pixels, at least 8 bands a picture.
    assert_eq!(Canvas::band_rows_for(1280, 720, 3_000_000), 64);
    assert_eq!(Canvas::band_rows_for(640, 360, 3_000_000), 32);
    assert_eq!(Canvas::band_rows_for(3840, 2160, 30_000_000), 16);
    assert_eq!(Canvas::band_rows_for(80, 56, 100_000), 16);
    // Set on an empty canvas, rounded to a multiple of 16 within 16..=64.
    let mut c = Canvas::new(64, 48).unwrap();
    for (asked, got) in [(0, 16), (40, 32), (64, 64), (1000, 64)] {
        c.set_band_rows(asked);
        assert_eq!(c.band_rows(), got, "{asked}");
    }
}

#[test]
fn thread_count_does_not_change_a_single_byte_and_draw_order_only_rounding() {
    let cam = Camera::new(Vec3::new(0.0, 0.0, 10.0), Vec3::ZERO, 40.0, 64, 48).unwrap();
    let mut pts = Vec::new();
    let mut cols = Vec::new();
    for s in 0..40 {
        let f = s as f32 * 0.1;
        pts.extend([
            Vec3::new(-2.0 + f, -1.0, f - 2.0),
            Vec3::new(2.0 - f, 1.5, 1.0 - f),
        ]);
        cols.extend([Vec3::new(f / 4.0, 0.3, 0.9 - f / 5.0); 2]);
    }
    let offsets: Vec<u32> = (0..=40).map(|s| 2 * s).collect();
    let draw = |pts: &[Vec3], cols: &[Vec3]| {
        let mut c = Canvas::new(64, 48).unwrap();
        c.draw_hair(
            &cam,
            pts,
            &offsets,
            cols,
            &HairLook {
                fiber_width: 0.05,
                opacity: 0.6,
                depth_ref: 10.0,
                simplify: 0.0,
            },
            &[],
            0,
        );
        c.resolve(Vec3::splat(0.1)).into_raw()
    };
    let forward = draw(&pts, &cols);
    let on = |threads| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| draw(&pts, &cols))
    };
    assert!(forward == on(1) && forward == on(3), "thread counts");
    // Another order rounds differently, by at most a level.
    let rev_pts: Vec<Vec3> = pts.chunks(2).rev().flatten().copied().collect();
    let rev_cols: Vec<Vec3> = cols.chunks(2).rev().flatten().copied().collect();
    let back = draw(&rev_pts, &rev_cols);
    assert!(forward.iter().zip(&back).all(|(a, b)| a.abs_diff(*b) <= 1));
    assert!(forward.iter().any(|&v| v > 40), "something was drawn");
}

/// Strands in groups drawn on one canvas, and the same groups split
/// across canvases whose layers are composited: the same bytes, for
/// any split and thread count, over a head that hides some of them.
#[test]
fn groups_split_across_canvases_composite_to_the_same_bytes() {
    // Blended alone, and with the 2 and the 8 nearest fragments of each
    // pixel composited front to back.
    for nearest in [0, 2, 8] {
        split_groups_composite_to_the_same_bytes(nearest, 0.0);
    }
    // Simplified (strands about 0.45 pixels wide, a quarter of them drawn
    // at simplify = 2): each canvas draws the same strands of its share.
    split_groups_composite_to_the_same_bytes(4, 2.0);
}

/// How the strands of the split tests look.
fn split_look(simplify: f32) -> HairLook {
    HairLook {
        fiber_width: 0.04,
        opacity: 0.7,
        depth_ref: 10.0,
        simplify,
    }
}

/// The head of the split tests.
fn split_head() -> Sphere {
    Sphere {
        center: Vec3::new(0.5, 0.0, -0.5),
        radius: 1.2,
    }
}

fn split_groups_composite_to_the_same_bytes(nearest: usize, simplify: f32) {
    let cam = Camera::new(Vec3::new(0.0, 0.0, 10.0), Vec3::ZERO, 40.0, 80, 56).unwrap();
    let (mut pts, mut cols, mut offsets) = (Vec::new(), Vec::new(), vec![0u32]);
    for s in 0..60 {
        let f = s as f32 * 0.07;
        for k in 0..5 {
            let t = k as f32 / 4.0;
            pts.push(Vec3::new(-2.5 + f + 0.3 * t, 1.8 - 3.6 * t, 1.5 - f * 0.5));
            cols.push(Vec3::new(0.2 + f / 8.0, 0.3 * t, 0.5));
        }
        offsets.push(pts.len() as u32);
    }
    let (look, head) = (split_look(simplify), split_head());
    let groups = [0, 7, 20, 21, 33, 60];
    // Drawn in bands of `band` rows.
    let canvas_in = |strands: std::ops::Range<usize>, band: usize| {
        let mut c = Canvas::new(80, 56).unwrap();
        c.set_band_rows(band as u32);
        c.set_nearest(nearest);
        c.draw_sphere(&cam, &head, |_, _| Vec3::new(0.6, 0.4, 0.3));
        // Group boundaries within `strands`, as strand indices from its start.
        let g: Vec<u32> = groups
            .iter()
            .map(|&b| (b as usize).clamp(strands.start, strands.end))
            .map(|b| (b - strands.start) as u32)
            .collect();
        let (p0, p1) = (
            offsets[strands.start] as usize,
            offsets[strands.end] as usize,
        );
        let off: Vec<u32> = offsets[strands.clone()]
            .iter()
            .chain([&offsets[strands.end]])
            .map(|&o| o - p0 as u32)
            .collect();
        c.draw_hair(
            &cam,
            &pts[p0..p1],
            &off,
            &cols[p0..p1],
            &look,
            &g,
            strands.start as u32,
        );
        c
    };
    let canvas = |strands| canvas_in(strands, 16);
    let bg = Vec3::splat(0.05);
    let whole = canvas(0..60).resolve(bg);
    assert!(whole.pixels().any(|p| p[0] > 60), "something was drawn");
    // Bands of any height draw the same bytes: a pixel's fragments come
    // in strand order whichever band holds it, and a line cut by a band's
    // edge makes the same fragments on either side.
    for band in [32, 48, 64] {
        assert!(
            canvas_in(0..60, band).resolve(bg) == whole,
            "bands of {band} rows"
        );
    }
    for cuts in [
        vec![0, 60],
        vec![0, 21, 60],
        vec![0, 7, 33, 60],
        vec![0, 7, 20, 21, 33, 60],
    ] {
        let layers: Vec<HairLayer> = cuts
            .windows(2)
            .map(|c| canvas(c[0]..c[1]).layer())
            .collect();
        // The compositor has the head alone, and the layers, in any order.
        let mut head_only = Canvas::new(80, 56).unwrap();
        head_only.set_nearest(nearest);
        head_only.draw_sphere(&cam, &head, |_, _| Vec3::new(0.6, 0.4, 0.3));
        let mut rev = layers.clone();
        rev.reverse();
        for ls in [&layers, &rev] {
            let img = rayon::ThreadPoolBuilder::new()
                .num_threads(3)
                .build()
                .unwrap()
                .install(|| head_only.resolve_layers(bg, ls));
            assert!(img == whole, "split at {cuts:?}, {nearest} nearest");
        }
    }
    let all = canvas(0..60).layer();
    assert!(!all.pixels().is_empty());
    assert_eq!(all.fragments() > 0, nearest > 0);
    // The integers themselves add up: split layers sum to the whole's
    // (with nearest fragments kept, a merge moves some into the sums).
    if nearest == 0 {
        split_sums_add_up(&all, &canvas);
    }
    // Stripes of whole bands (the last one short: 56 rows), appended
    // in order, are the whole layer, for any stripe height.
    let whole_canvas = canvas(0..60);
    for step in [16, 32, 48, 56, 64] {
        let mut striped = HairLayer::new(80, 56);
        let mut stripes = 0;
        for y in (0..56).step_by(step) {
            let stripe = whole_canvas.layer_rows(y..(y + step as u32).min(56));
            let rows = y * 80..(y + step as u32).min(56) * 80;
            assert!(stripe.pixels().iter().all(|p| rows.contains(p)));
            stripes += usize::from(!stripe.pixels().is_empty());
            striped.append(stripe);
        }
        assert!(
            stripes > 1 || step > 16,
            "hair in several stripes of {step}"
        );
        assert_eq!(striped, all, "stripes of {step} rows, {nearest} nearest");
    }
    // A band of rows resolved where part of the hair was drawn, with
    // the rest's layers (a cluster worker's band): the whole picture's
    // rows, with the canvas's own hair rasterized there or brought in
    // as its layer of those rows.
    let whole_rgb: &[u8] = &whole;
    let mine = canvas(0..21);
    let rest = [canvas(21..33).layer(), canvas(33..60).layer()];
    for rows in [0..16, 16..48, 48..56, 32..56] {
        let want = &whole_rgb[rows.start as usize * 240..rows.end as usize * 240];
        assert_eq!(mine.resolve_rows(bg, &rest, rows.clone()), want, "{rows:?}");
        let mut all_layers = vec![mine.layer_rows(rows.clone())];
        all_layers.extend(rest.iter().cloned());
        let got = mine.resolve_layer_rows(bg, &all_layers, rows.clone());
        assert_eq!(got, want, "{rows:?}, own hair as a layer");
    }
}

#[test]
fn segments_sent_to_the_band_owner_resolve_to_the_same_bytes() {
    for (nearest, simplify) in [(0, 0.0), (4, 0.0), (8, 0.0), (4, 2.0)] {
        sort_middle_gives_the_same_bytes(nearest, simplify);
    }
}

/// Sort-middle: shares of the groups, each binned on its own canvas,
/// send each band owner their segments of its rows; the owner draws them
/// in the order of the groups over its head and resolves its rows.
fn sort_middle_gives_the_same_bytes(nearest: usize, simplify: f32) {
    let (w, h) = (80u32, 72u32);
    let cam = Camera::new(Vec3::new(0.0, 0.0, 10.0), Vec3::ZERO, 40.0, w, h).unwrap();
    let (mut pts, mut cols, mut offsets) = (Vec::new(), Vec::new(), vec![0u32]);
    for s in 0..60 {
        let f = s as f32 * 0.07;
        for k in 0..7 {
            let t = k as f32 / 6.0;
            // Curls, so that strands leave and re-enter bands.
            let curl = (6.0 * t + f).sin() * 0.4;
            pts.push(Vec3::new(
                -2.5 + f + curl,
                2.4 - 4.8 * t,
                1.5 - f * 0.5 + curl,
            ));
            cols.push(Vec3::new(0.2 + f / 8.0, 0.3 * t, 0.5));
        }
        offsets.push(pts.len() as u32);
    }
    let (look, head) = (split_look(simplify), split_head());
    let groups = [0usize, 7, 20, 21, 33, 60];
    let with_head = |band: u32| {
        let mut c = Canvas::new(w, h).unwrap();
        c.set_band_rows(band);
        c.set_nearest(nearest);
        c.draw_sphere(&cam, &head, |_, _| Vec3::new(0.6, 0.4, 0.3));
        c
    };
    // Groups `gs` of the hair on a canvas of their own.
    let share = |gs: std::ops::Range<usize>, band: u32| {
        let mut c = with_head(band);
        let (s0, s1) = (groups[gs.start], groups[gs.end]);
        let (p0, p1) = (offsets[s0] as usize, offsets[s1] as usize);
        let off: Vec<u32> = offsets[s0..=s1].iter().map(|&o| o - p0 as u32).collect();
        let g: Vec<u32> = groups[gs.start..=gs.end]
            .iter()
            .map(|&b| (b - s0) as u32)
            .collect();
        c.draw_hair(
            &cam,
            &pts[p0..p1],
            &off,
            &cols[p0..p1],
            &look,
            &g,
            s0 as u32,
        );
        c
    };
    let bg = Vec3::splat(0.05);
    let whole = share(0..5, 16).resolve(bg);
    let whole: &[u8] = &whole;
    for (cuts, bands) in [
        (vec![0, 5], [16, 16, 16]),
        (vec![0, 2, 5], [16, 32, 16]),
        (vec![0, 1, 3, 5], [32, 16, 48]),
    ] {
        let shares: Vec<Canvas> = cuts
            .windows(2)
            .zip(bands)
            .map(|(c, band)| share(c[0]..c[1], band))
            .collect();
        // An owner's rows: whole bands of every share's canvas (48 rows
        // divide by 16 and 48; the last band short).
        for rows in [0..48u32, 48..72, 16..32, 32..72] {
            let mut sent: Vec<BandSegments> = shares
                .iter()
                .zip(cuts.windows(2))
                .map(|(c, g)| {
                    let s = c.segments_rows(rows.clone(), g[0] as u32);
                    // As the wire carries them.
                    let mut bytes = Vec::new();
                    s.encode(&mut bytes);
                    assert_eq!(bytes.len(), s.encoded_len());
                    let back = BandSegments::decode(&bytes, h).unwrap();
                    assert_eq!(back, s);
                    back
                })
                .collect();
            assert!(sent.iter().any(|s| s.segment_count() > 0));
            // Arriving in any order, drawn in the order of the groups.
            sent.reverse();
            sent.sort_by_key(|s| s.first_group());
            let mut owner = with_head(16);
            for s in &sent {
                owner.draw_segments(s).unwrap();
            }
            let got = owner.resolve_rows(bg, &[], rows.clone());
            let want =
                &whole[rows.start as usize * 3 * w as usize..rows.end as usize * 3 * w as usize];
            assert!(
                got == want,
                "groups cut at {cuts:?}, rows {rows:?}, {nearest} nearest, simplify {simplify}"
            );
            // A canvas whose bands do not divide the rows refuses them.
            if rows.start % 32 != 0 {
                assert!(with_head(32).draw_segments(&sent[0]).is_err());
            }
        }
        // One owner of two neighbouring row ranges: a segment that
        // reaches both comes with each, and is drawn once in each.
        let mut owner = with_head(16);
        for rows in [48..72u32, 0..48] {
            for (c, g) in shares.iter().zip(cuts.windows(2)) {
                owner
                    .draw_segments(&c.segments_rows(rows.clone(), g[0] as u32))
                    .unwrap();
            }
        }
        assert!(
            owner.resolve_rows(bg, &[], 0..72) == whole,
            "{cuts:?}, two ranges"
        );
    }
}

#[test]
fn malformed_segments_are_refused_without_a_panic() {
    let cam = Camera::new(Vec3::new(0.0, 0.0, 10.0), Vec3::ZERO, 40.0, 32, 32).unwrap();
    let mut c = Canvas::new(32, 32).unwrap();
    let pts = [
        Vec3::new(-1.0, -1.0, 0.0),
        Vec3::ZERO,
        Vec3::new(1.0, 1.2, 0.0),
    ];
    let look = HairLook {
        fiber_width: 0.05,
        opacity: 0.6,
        depth_ref: 10.0,
        simplify: 0.0,
    };
    c.draw_hair(&cam, &pts, &[0, 3], &[Vec3::ONE; 3], &look, &[], 4);
    let s = c.segments_rows(0..32, 4);
    assert_eq!(s.segment_count(), 2);
    assert_eq!((s.first_group(), s.last_group()), (Some(4), Some(4)));
    let mut good = Vec::new();
    s.encode(&mut good);
    assert_eq!(BandSegments::decode(&good, 32).unwrap(), s);
    // Every cut short, and a byte more.
    for n in 0..good.len() {
        assert!(BandSegments::decode(&good[..n], 32).is_err(), "{n} bytes");
    }
    let mut long = good.clone();
    long.push(0);
    assert!(BandSegments::decode(&long, 32).is_err());
    // Rows past the picture; a NaN vertex; a look index out of range; a
    // huge claimed count.
    assert!(BandSegments::decode(&good, 16).is_err());
    let vertex0 = 16 + 20 + 8 + 8;
    let mut nan = good.clone();
    nan[vertex0..vertex0 + 4].copy_from_slice(&f32::NAN.to_bits().to_le_bytes());
    let e = BandSegments::decode(&nan, 32).unwrap_err().to_string();
    assert!(e.contains("vertex"), "{e}");
    let mut look = good.clone();
    look[vertex0 - 8..vertex0 - 4].copy_from_slice(&7u32.to_le_bytes());
    assert!(BandSegments::decode(&look, 32).is_err());
    for at in [8, 32, 40, vertex0 - 4] {
        let mut many = good.clone();
        many[at..at + 4].copy_from_slice(&u32::MAX.to_le_bytes());
        assert!(BandSegments::decode(&many, 32).is_err(), "a count at {at}");
    }
}

fn split_sums_add_up(all: &HairLayer, canvas: &dyn Fn(std::ops::Range<usize>) -> Canvas) {
    assert!(all.sums().iter().all(|s| !s.is_zero()));
    let mut added = std::collections::BTreeMap::new();
    for c in [0, 7, 20, 21, 33, 60].windows(2) {
        let l = canvas(c[0]..c[1]).layer();
        for (&p, s) in l.pixels().iter().zip(l.sums()) {
            added.entry(p).or_insert(Sums::ZERO).add(s);
        }
    }
    let whole_sums: std::collections::BTreeMap<u32, Sums> = all
        .pixels()
        .iter()
        .copied()
        .zip(all.sums().iter().copied())
        .collect();
    assert_eq!(added, whole_sums);
}

/// A red strand in front of a green one over black. Drawn alone, each
/// covers the centre pixel with opacity `A_r` (red `A_r`) or `A_g`.
/// Together, composited front to back, the pixel is `A_r` red and
/// `A_g (1 - A_r)` green (the over operator); blended
/// order-independently, the green behind shows through far more.
#[test]
fn the_nearest_fragments_hide_what_is_behind_them() {
    let cam = Camera::new(Vec3::new(0.0, 0.0, 10.0), Vec3::ZERO, 40.0, 32, 32).unwrap();
    let red = [Vec3::new(-2.0, 0.0, 0.1), Vec3::new(2.0, 0.0, 0.1)];
    let green = [Vec3::new(-2.0, 0.0, -0.1), Vec3::new(2.0, 0.0, -0.1)];
    let look = HairLook {
        fiber_width: 0.6,
        opacity: 0.5,
        depth_ref: 10.0,
        simplify: 0.0,
    };
    let centre = |nearest: usize, strands: &[([Vec3; 2], Vec3)]| {
        let mut c = Canvas::new(32, 32).unwrap();
        c.set_nearest(nearest);
        let pts: Vec<Vec3> = strands.iter().flat_map(|s| s.0).collect();
        let cols: Vec<Vec3> = strands.iter().flat_map(|s| [s.1, s.1]).collect();
        let offsets: Vec<u32> = (0..=strands.len() as u32).map(|i| 2 * i).collect();
        c.draw_hair(&cam, &pts, &offsets, &cols, &look, &[], 0);
        let p = c.resolve(Vec3::ZERO).get_pixel(16, 16).0;
        (srgb8_to_linear(p[0]), srgb8_to_linear(p[1]))
    };
    let a_r = centre(4, &[(red, Vec3::X)]).0;
    let a_g = centre(4, &[(green, Vec3::Y)]).1;
    assert!(a_r > 0.3 && a_g > 0.3, "{a_r} {a_g}");
    let both = [(red, Vec3::X), (green, Vec3::Y)];
    let (r, g) = centre(4, &both);
    assert!((r - a_r).abs() < 0.01, "red {r}, alone {a_r}");
    assert!(
        (g - a_g * (1.0 - a_r)).abs() < 0.01,
        "green {g}, want {}",
        a_g * (1.0 - a_r)
    );
    // The same strands the other way round in strand order: the same.
    let (r2, g2) = centre(4, &[(green, Vec3::Y), (red, Vec3::X)]);
    assert!((r2 - r).abs() < 1e-6 && (g2 - g).abs() < 1e-6);
    let (_, g) = centre(0, &both);
    assert!(g > a_g * (1.0 - a_r) + 0.05, "blended green {g}");
}

#[test]
fn the_linear_picture_is_the_encoded_one_before_encoding_with_coverage_as_alpha() {
    let cam = Camera::new(Vec3::new(0.0, 0.0, 10.0), Vec3::ZERO, 40.0, 32, 32).unwrap();
    let a = [Vec3::new(-2.0, 0.0, 0.1), Vec3::new(2.0, 0.0, 0.1)];
    let b = [Vec3::new(-2.0, 0.0, -0.1), Vec3::new(2.0, 0.0, -0.1)];
    let look = HairLook {
        fiber_width: 0.6,
        opacity: 0.5,
        depth_ref: 10.0,
        simplify: 0.0,
    };
    let bg = Vec3::new(0.0, 0.0, 0.05);
    // A strand brighter than 1 in red, one in green behind it.
    let bright = Vec3::new(3.0, 0.5, 0.0);
    let draw = |strands: &[([Vec3; 2], Vec3)]| {
        let mut c = Canvas::new(32, 32).unwrap();
        c.set_nearest(4);
        let pts: Vec<Vec3> = strands.iter().flat_map(|s| s.0).collect();
        let cols: Vec<Vec3> = strands.iter().flat_map(|s| [s.1, s.1]).collect();
        let offsets: Vec<u32> = (0..=strands.len() as u32).map(|i| 2 * i).collect();
        c.draw_hair(&cam, &pts, &offsets, &cols, &look, &[], 0);
        let (lin, depth) = c.resolve_linear_and_depth(bg);
        (c.resolve(bg), lin, depth)
    };
    let (img, lin, depth) = draw(&[(a, bright), (b, Vec3::Y)]);
    // The nearest surface: the strand in front (9.9 from the camera), the
    // one behind alone (10.1); nothing on the background.
    let centre = 16 * 32 + 16;
    assert!((depth[centre] - 9.9).abs() < 0.01, "{}", depth[centre]);
    assert!((draw(&[(b, Vec3::Y)]).2[centre] - 10.1).abs() < 0.01);
    assert_eq!(depth[0], f32::INFINITY);
    assert_eq!(lin.len(), 32 * 32);
    // Encoded, the linear picture is the picture.
    for (p, l) in img.pixels().zip(&lin) {
        assert_eq!(p.0, crate::to_srgb8(l.truncate()), "{l}");
    }
    // The background: its colour, no coverage.
    assert_eq!(lin[0], bg.extend(0.0));
    // The first strand alone at the centre: its opacity there as alpha,
    // and its colour over the background by that alpha, not clamped.
    let (_, alone, _) = draw(&[(a, bright)]);
    let c = alone[16 * 32 + 16];
    assert!(c.w > 0.3 && c.w < 1.0, "{c}");
    let want = bright * c.w + bg * (1.0 - c.w);
    assert!(
        (c.truncate() - want).abs().max_element() < 1e-5,
        "{c} vs {want}"
    );
    assert!(c.x > 1.0, "{c}");
    // Both: what lets light through multiplies.
    let (_, other, _) = draw(&[(b, Vec3::Y)]);
    let both = lin[16 * 32 + 16].w;
    let want = 1.0 - (1.0 - c.w) * (1.0 - other[16 * 32 + 16].w);
    assert!((both - want).abs() < 1e-5, "{both} vs {want}");
}

#[test]
fn malformed_layers_are_refused() {
    let s = Sums::ZERO;
    assert!(HairLayer::from_parts(4, 4, vec![1, 3], vec![s, s]).is_ok());
    assert!(HairLayer::from_parts(4, 4, vec![3, 1], vec![s, s]).is_err());
    assert!(HairLayer::from_parts(4, 4, vec![1, 1], vec![s, s]).is_err());
    assert!(HairLayer::from_parts(4, 4, vec![16], vec![s]).is_err());
    assert!(HairLayer::from_parts(4, 4, vec![1], vec![]).is_err());
}

#[test]
fn a_mesh_covers_its_projected_area_without_cracks_and_the_nearer_face_wins() {
    // Orthographic enough: a far camera with a narrow field of view.
    let cam = Camera::new(Vec3::new(0.0, 0.0, 400.0), Vec3::ZERO, 2.0, 96, 96).unwrap();
    let px = cam.focal() / 400.0; // pixels per unit at the plane z = 0
    // A square of side 8 px made of a fan of 4 triangles around its centre
    // (shared edges), and behind it a larger square of another colour.
    let h = 4.0 / px;
    let front = [
        Vec3::new(0.0, 0.0, 0.0),
        Vec3::new(-h, -h, 0.0),
        Vec3::new(h, -h, 0.0),
        Vec3::new(h, h, 0.0),
        Vec3::new(-h, h, 0.0),
    ];
    let back = [
        Vec3::new(-3.0 * h, -3.0 * h, -1.0),
        Vec3::new(3.0 * h, -3.0 * h, -1.0),
        Vec3::new(3.0 * h, 3.0 * h, -1.0),
        Vec3::new(-3.0 * h, 3.0 * h, -1.0),
    ];
    let positions: Vec<Vec3> = back.iter().chain(&front).copied().collect();
    let normals = vec![Vec3::Z; positions.len()];
    let tris = [
        [0, 1, 2],
        [0, 2, 3],
        [4, 5, 6],
        [4, 6, 7],
        [4, 7, 8],
        [4, 8, 5],
    ];
    let draw = || {
        let mut c = Canvas::new(96, 96).unwrap();
        // Colour by depth: the front square white, the back one grey.
        c.draw_mesh(&cam, &positions, &normals, &tris, |p, n| {
            assert!((n - Vec3::Z).length() < 1e-5);
            Vec3::splat(if p.z > -0.5 { 1.0 } else { 0.2 })
        });
        c.resolve(Vec3::ZERO)
    };
    let img = draw();
    let count = |v: u8| img.pixels().filter(|p| p[0] == v).count();
    assert_eq!(count(255), 64, "an 8x8 px square, no crack and no overlap");
    assert_eq!(count(to_srgb8(Vec3::splat(0.2))[0]), 24 * 24 - 64);
    let one = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap()
        .install(draw);
    assert!(one == img, "thread counts");
}

/// A quad facing the camera shades the same whichever way it is wound
/// (its vertex normals pointing at the camera or away): the shading
/// normal is on the side the camera sees. (The head mesh's neck was wound
/// inwards and came out unlit where Blender Cycles lit it.)
#[test]
fn a_mesh_part_wound_inwards_is_shaded_from_the_side_the_camera_sees() {
    let cam = Camera::new(Vec3::new(0.0, 0.0, 10.0), Vec3::ZERO, 40.0, 16, 16).unwrap();
    let p = vec![
        Vec3::new(-2.0, -2.0, 0.0),
        Vec3::new(2.0, -2.0, 0.0),
        Vec3::new(2.0, 2.0, 0.0),
        Vec3::new(-2.0, 2.0, 0.0),
    ];
    let to_light = Vec3::new(0.3, 0.2, 1.0).normalize();
    let lit = |normal: Vec3, tris: &[[u32; 3]]| {
        let mut c = Canvas::new(16, 16).unwrap();
        c.draw_mesh(&cam, &p, &[normal; 4], tris, |_, n| {
            Vec3::splat(n.dot(to_light).max(0.0))
        });
        c.resolve(Vec3::ZERO).get_pixel(8, 8).0
    };
    let outwards = lit(Vec3::Z, &[[0, 1, 2], [0, 2, 3]]);
    let inwards = lit(Vec3::NEG_Z, &[[0, 2, 1], [0, 3, 2]]);
    assert!(outwards[0] > 200, "{outwards:?}");
    assert_eq!(outwards, inwards);
}

/// Stochastic simplification draws a share of thin strands, each wider:
/// a region of many strands keeps its brightness, strands at least as
/// wide as the threshold are drawn as before, and the share is the one
/// asked for.
#[test]
fn simplified_thin_strands_cover_as_all_of_them_would() {
    let cam = Camera::new(Vec3::new(0.0, 0.0, 10.0), Vec3::ZERO, 40.0, 96, 64).unwrap();
    // 800 slanted strands across the view, 0.02 wide: about 0.26 pixels.
    let (mut pts, mut cols) = (Vec::new(), Vec::new());
    let mut seed = 7u32;
    let mut next = || {
        seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        (seed >> 8) as f32 / (1u32 << 24) as f32
    };
    for _ in 0..800 {
        let (x, z, tint) = (-2.4 + 4.8 * next(), next() - 0.5, next());
        pts.extend([Vec3::new(x, 1.5, z), Vec3::new(x + 0.4, -1.5, z)]);
        cols.extend([Vec3::new(0.8, 0.5 + 0.3 * tint, 0.2); 2]);
    }
    let offsets: Vec<u32> = (0..=800).map(|s| 2 * s).collect();
    let draw = |simplify: f32, width: f32| {
        let mut c = Canvas::new(96, 64).unwrap();
        let look = HairLook {
            fiber_width: width,
            opacity: 0.9,
            depth_ref: 10.0,
            simplify,
        };
        c.draw_hair(&cam, &pts, &offsets, &cols, &look, &[], 0);
        c.resolve(Vec3::ZERO)
    };
    // The mean linear red of the middle, where strands cross every pixel.
    let mean = |img: &image::RgbImage| {
        let mut sum = 0.0;
        for y in 16..48 {
            for x in 24..72 {
                sum += srgb8_to_linear(img.get_pixel(x, y)[0]);
            }
        }
        sum / (32.0 * 48.0)
    };
    let all = draw(0.0, 0.02);
    let m = mean(&all);
    assert!(m > 0.2, "the strands cover the middle: {m}");
    // Every 2nd, 4th and 8th strand drawn (0.26 px against 0.6, 1.2 and
    // 2.4): within 3 % of all of them, and not the same picture.
    for simplify in [0.6, 1.2, 2.4] {
        let some = draw(simplify, 0.02);
        let ms = mean(&some);
        assert!(
            (ms / m - 1.0).abs() < 0.03,
            "simplify {simplify}: mean {ms} against {m}"
        );
        assert!(some != all, "simplify {simplify} drew every strand");
    }
    // Strands wider than the threshold: every one drawn, as they were.
    assert!(draw(0.2, 0.02) == all, "simplify below the strands' width");
    // A strand said to be left out draws nothing on its own (so its
    // colours need no shading); about three in four are, at 1.2 pixels.
    let look = HairLook {
        fiber_width: 0.02,
        opacity: 0.9,
        depth_ref: 10.0,
        simplify: 1.2,
    };
    let mut left_out = 0;
    for s in 0..800u32 {
        let pts = &pts[2 * s as usize..2 * s as usize + 2];
        if look.may_draw_strand(&cam, pts, s) {
            continue;
        }
        left_out += 1;
        let mut c = Canvas::new(96, 64).unwrap();
        c.draw_hair(&cam, pts, &[0, 2], &[Vec3::ONE; 2], &look, &[], s);
        assert!(c.layer().pixels().is_empty(), "strand {s} was drawn");
    }
    assert!((500..700).contains(&left_out), "{left_out} of 800 left out");
    // The shares: about 2^-level of many strands, nested.
    for level in 1..=MAX_SHARE_LEVEL {
        let n = (0..40_000).filter(|&s| strand_drawn(s, level)).count();
        let want = 40_000.0 / f64::from(1u32 << level);
        assert!((n as f64 / want - 1.0).abs() < 0.05, "level {level}: {n}");
        assert!((0..2000).all(|s| !strand_drawn(s, level) || strand_drawn(s, level - 1)));
    }
}
