//! Alembic grooms read back: the real Sintel groom against its `.hair`
//! copy and against an independent reader (ogawa-rs), the variants the
//! format allows (widths of each scope, indexed, several objects under
//! transforms, animated samples with repeats elided), and refusals.

mod abc_writer;

use std::path::Path;

use abc_writer::{Obj, archive, curves, hair_file, indexed_width, width, xform};
use glam::Vec3;
use strands::{AlembicError, Hair, load, load_bytes, parse_alembic};

fn sintel() -> Hair {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/data/sintel_hair.tfx");
    load(&path, 0).unwrap_or_else(|e| panic!("{e}"))
}

fn flat(h: &Hair) -> Vec<f32> {
    h.points().iter().flat_map(|p| p.to_array()).collect()
}

fn counts(h: &Hair) -> Vec<i32> {
    h.strands().map(|s| s.len() as i32).collect()
}

fn linear(name: &str, h: &Hair, extra: Vec<abc_writer::Prop>) -> Obj {
    curves(name, vec![flat(h)], &counts(h), [1, 0, 0], extra)
}

#[test]
fn the_sintel_groom_as_alembic_reads_back_as_its_hair_copy_bit_for_bit() {
    let groom = sintel();
    let abc = archive(vec![linear("hair", &groom, Vec::new())]);
    let from_abc = load_bytes(Path::new("sintel.abc"), &abc, 0).unwrap();
    let from_hair = load_bytes(Path::new("sintel.hair"), &hair_file(&groom), 0).unwrap();
    assert_eq!(from_abc.offsets(), from_hair.offsets());
    let bits = |h: &Hair| -> Vec<u32> { flat(h).iter().map(|x| x.to_bits()).collect() };
    assert_eq!(bits(&from_abc), bits(&from_hair));
    assert_eq!(from_abc.strand_count(), 228);
    assert_eq!(from_abc.widths(), None, "no width property, no widths");
}

#[test]
fn an_independent_reader_reads_the_fixtures_as_written() {
    // ogawa-rs (upstream, unmodified) reads the writer's archive: the
    // fixtures are Alembic as another implementation understands it.
    let groom = sintel();
    let abc = archive(vec![linear("hair", &groom, Vec::new())]);
    let dir = std::env::temp_dir().join(format!("wisplight-abc-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("sintel.abc");
    std::fs::write(&path, &abc).unwrap();
    let mut reader = ogawa_rs::FileReader::new(std::fs::File::open(&path).unwrap()).unwrap();
    let archive = ogawa_rs::Archive::new(&mut reader).unwrap();
    let top = archive.load_root_object(&mut reader).unwrap();
    assert_eq!(top.child_count(), 1);
    let hair = top
        .load_child(
            0,
            &mut reader,
            &archive.indexed_meta_data,
            &archive.time_samplings,
        )
        .unwrap();
    assert_eq!(hair.header.full_name, "/hair");
    let schema = ogawa_rs::Schema::parse(&hair, &mut reader, &archive).unwrap();
    let ogawa_rs::Schema::Curves(c) = schema else {
        panic!("not read as curves")
    };
    let p = c.load_positions_sample(0, &mut reader).unwrap();
    let n = c.load_n_vertices_sample(0, &mut reader).unwrap();
    assert_eq!(n, counts(&groom));
    let theirs: Vec<f32> = p.iter().flatten().copied().collect();
    assert_eq!(theirs, flat(&groom));
    let _ = std::fs::remove_dir_all(dir);
}

fn two_strands() -> Hair {
    let mut h = Hair::new();
    h.push_strand(&[
        Vec3::ZERO,
        Vec3::new(0.0, 1.0, 0.0),
        Vec3::new(0.0, 2.0, 0.0),
    ])
    .unwrap();
    h.push_strand(&[Vec3::new(1.0, 0.0, 0.0), Vec3::new(1.0, 1.0, 0.5)])
        .unwrap();
    h
}

#[test]
fn widths_of_every_scope_give_each_strand_its_mean_width() {
    let h = two_strands();
    let read = |w| parse_alembic(&archive(vec![linear("c", &h, vec![w])]), 0).unwrap();
    assert_eq!(
        read(width(&[0.01], "con")).widths(),
        Some(&[0.01, 0.01][..])
    );
    assert_eq!(
        read(width(&[0.01, 0.03], "uni")).widths(),
        Some(&[0.01, 0.03][..])
    );
    // Per vertex: the first strand's three (mean 0.02), the second's two.
    let v = read(width(&[0.01, 0.02, 0.03, 0.04, 0.06], "vtx"));
    let w = v.widths().unwrap();
    assert!(
        (w[0] - 0.02).abs() < 1e-7 && (w[1] - 0.05).abs() < 1e-7,
        "{w:?}"
    );
    // Indexed: values 0.1 and 0.3 by index, per vertex.
    let i = read(indexed_width(&[0.1, 0.3], &[0, 0, 1, 1, 1], "vtx"));
    let w = i.widths().unwrap();
    assert!(
        (w[0] - 0.5 / 3.0).abs() < 1e-6 && (w[1] - 0.3).abs() < 1e-7,
        "{w:?}"
    );
    assert_eq!(i.median_width(), Some(w[1]));
    // Three widths fit neither curves nor vertices: refused, named.
    let e = parse_alembic(
        &archive(vec![linear("c", &h, vec![width(&[0.1; 3], "vtx")])]),
        0,
    )
    .unwrap_err();
    assert!(
        e.to_string().starts_with("/c: 3 widths for 2 curves"),
        "{e}"
    );
}

#[test]
fn several_objects_are_placed_by_the_transforms_above_them() {
    let h = two_strands();
    // /a: translate (1, 2, 3). /b: scale (2, 1, 1), then rotate 90 degrees
    // about y (Alembic's op list [rotateY, scale]: the last op applies
    // first), and
    // below it /b/c with inherits off, translate (0, 0, 5) alone.
    let translate = 1 << 4;
    let (scale, rotate_y, matrix) = (0, 5 << 4, 3 << 4);
    let a = xform(
        "a",
        &[translate],
        vec![vec![1.0, 2.0, 3.0]],
        true,
        vec![linear("ca", &h, Vec::new())],
    );
    let c = xform(
        "c",
        &[translate],
        vec![vec![0.0, 0.0, 5.0]],
        false,
        vec![linear("cc", &h, Vec::new())],
    );
    let b = xform(
        "b",
        &[rotate_y, scale],
        vec![vec![90.0, 2.0, 1.0, 1.0]],
        true,
        vec![linear("cb", &h, Vec::new()), c],
    );
    // /m: a matrix op, row-major for row vectors (translation last row).
    let mut m = vec![0.0; 16];
    (m[0], m[5], m[10], m[15]) = (1.0, 1.0, 1.0, 1.0);
    (m[12], m[13], m[14]) = (-4.0, 0.0, 0.0);
    let mx = xform(
        "m",
        &[matrix],
        vec![m],
        true,
        vec![linear("cm", &h, Vec::new())],
    );
    let read = parse_alembic(&archive(vec![a, b, mx]), 0).unwrap();
    assert_eq!(read.strand_count(), 8);
    let pts: Vec<Vec3> = h.points().to_vec();
    let n = pts.len();
    let close = |a: Vec3, b: Vec3| (a - b).length() < 1e-5;
    for (k, &p) in pts.iter().enumerate() {
        // Objects in the order read: /a/ca, /b/cb, /b/c/cc, /m/cm.
        assert!(
            close(read.points()[k], p + Vec3::new(1.0, 2.0, 3.0)),
            "ca {k}"
        );
        // Scale x by 2, then 90 degrees about y: (x, y, z) -> (z, y, -x).
        let s = p * Vec3::new(2.0, 1.0, 1.0);
        assert!(
            close(read.points()[n + k], Vec3::new(s.z, s.y, -s.x)),
            "cb {k}"
        );
        assert!(
            close(read.points()[2 * n + k], p + Vec3::new(0.0, 0.0, 5.0)),
            "cc {k}"
        );
        assert!(
            close(read.points()[3 * n + k], p + Vec3::new(-4.0, 0.0, 0.0)),
            "cm {k}"
        );
    }
}

#[test]
fn a_chosen_sample_of_an_animated_cache_is_read_with_repeats_elided() {
    let h = two_strands();
    let at = |dy: f32| -> Vec<f32> {
        h.points()
            .iter()
            .flat_map(|p| (*p + Vec3::new(0.0, dy, 0.0)).to_array())
            .collect()
    };
    // Samples A A B B C C: Alembic stores A, then B B C from the first
    // change (sample 2) to the last (4), and records both.
    let (a, b, c) = (at(0.0), at(1.0), at(2.0));
    let repeats = vec![
        a.clone(),
        a.clone(),
        b.clone(),
        b.clone(),
        c.clone(),
        c.clone(),
    ];
    let abc = archive(vec![curves(
        "c",
        repeats,
        &counts(&h),
        [1, 0, 0],
        Vec::new(),
    )]);
    for (k, want) in [&a, &a, &b, &b, &c, &c].iter().enumerate() {
        let got = parse_alembic(&abc, k as u32).unwrap();
        assert_eq!(&flat(&got), *want, "sample {k}");
    }
    let e = parse_alembic(&abc, 6).unwrap_err();
    assert_eq!(e, AlembicError::Sample { asked: 6, count: 6 });
    assert!(e.to_string().contains("6 samples (0 to 5)"), "{e}");
    // Every sample different: neither first nor last recorded, the first
    // change is sample 1.
    let all = vec![a.clone(), b.clone(), c.clone()];
    let abc = archive(vec![curves("c", all, &counts(&h), [1, 0, 0], Vec::new())]);
    for (k, want) in [&a, &b, &c].iter().enumerate() {
        assert_eq!(
            &flat(&parse_alembic(&abc, k as u32).unwrap()),
            *want,
            "sample {k}"
        );
    }
    // An animated transform over still curves.
    let moved = xform(
        "x",
        &[1 << 4],
        vec![vec![0.0; 3], vec![0.0, 0.0, 1.0], vec![0.0, 0.0, 2.0]],
        true,
        vec![linear("c", &h, Vec::new())],
    );
    let abc = archive(vec![moved]);
    let z = parse_alembic(&abc, 2).unwrap().points()[0].z;
    assert_eq!(z, 2.0);
    assert_eq!(strands::alembic_samples(&abc), Ok(3));
    // A transform that places no curves (a camera's, say) gives the groom
    // no samples.
    let camera = xform(
        "cam",
        &[1 << 4],
        vec![vec![0.0; 3], vec![1.0, 0.0, 0.0]],
        true,
        Vec::new(),
    );
    let abc = archive(vec![camera, linear("c", &h, Vec::new())]);
    assert_eq!(strands::alembic_samples(&abc), Ok(1));
}

#[test]
fn cubic_curves_are_evaluated_and_nurbs_read_as_their_control_polygon() {
    // One B-spline of 5 control points on a line, 0 to 4 along x: the
    // curve runs from 1 to 3.
    let cv: Vec<f32> = (0..5).flat_map(|i| [i as f32, 0.0, 0.0]).collect();
    let bspline = archive(vec![curves(
        "c",
        vec![cv.clone()],
        &[5],
        [0, 0, 2],
        Vec::new(),
    )]);
    let h = parse_alembic(&bspline, 0).unwrap();
    let xs: Vec<f32> = h.points().iter().map(|p| p.x).collect();
    assert_eq!(xs.first(), Some(&1.0));
    assert!((xs.last().unwrap() - 3.0).abs() < 1e-6, "{xs:?}");
    // NURBS (variable order): the control points as they are.
    let nurbs = archive(vec![curves(
        "n",
        vec![cv.clone()],
        &[5],
        [2, 0, 0],
        Vec::new(),
    )]);
    assert_eq!(flat(&parse_alembic(&nurbs, 0).unwrap()), cv);
    // Hermite: refused, naming the object.
    let hermite = archive(vec![curves("h", vec![cv], &[5], [0, 0, 4], Vec::new())]);
    let e = parse_alembic(&hermite, 0).unwrap_err();
    assert!(
        e.to_string().starts_with("/h: cubic curves of basis 4"),
        "{e}"
    );
}

#[test]
fn what_is_not_curves_is_refused_in_one_line_naming_the_object() {
    let subd = Obj {
        name: "head".into(),
        meta: "schema=AbcGeom_SubD_v1;schemaObjTitle=AbcGeom_SubD_v1:.geom".into(),
        props: Vec::new(),
        children: Vec::new(),
    };
    let e = parse_alembic(&archive(vec![subd]), 0).unwrap_err();
    assert_eq!(
        e.to_string(),
        "holds no curves (it holds /head, a subdivision surface)"
    );
    // Curves without points.
    let mut no_p = curves("c", vec![vec![0.0; 6]], &[2], [1, 0, 0], Vec::new());
    if let abc_writer::Prop::Compound { props, .. } = &mut no_p.props[0] {
        props.retain(|p| !matches!(p, abc_writer::Prop::Array { name, .. } if name == "P"));
    }
    let e = parse_alembic(&archive(vec![no_p]), 0).unwrap_err();
    assert_eq!(
        e.to_string(),
        "/c: curves without points (P); nothing to read"
    );
    // Empty, not Ogawa, HDF5.
    let e = load_bytes(Path::new("groom.abc"), b"", 0).unwrap_err();
    assert!(
        e.to_string()
            .starts_with("groom.abc: Alembic: not an Alembic Ogawa archive (0 bytes"),
        "{e}"
    );
    let e = parse_alembic(b"\x89HDF\r\n\x1a\n........", 0).unwrap_err();
    assert!(e.to_string().contains("HDF5"), "{e}");
}

#[test]
fn every_truncation_and_corruption_is_an_error_not_a_panic_or_a_huge_allocation() {
    let h = two_strands();
    let abc = archive(vec![xform(
        "x",
        &[1 << 4],
        vec![vec![1.0, 0.0, 0.0]],
        true,
        vec![linear("c", &h, vec![indexed_width(&[0.1], &[0; 5], "vtx")])],
    )]);
    assert!(parse_alembic(&abc, 0).is_ok());
    for len in 0..abc.len() {
        assert!(parse_alembic(&abc[..len], 0).is_err(), "truncated to {len}");
    }
    // Each byte set to 0xff in turn: sizes and counts that claim 2^63 and
    // more, positions past the end. Each read ends, with hair or an error.
    for at in 0..abc.len() {
        let mut bad = abc.clone();
        bad[at] = 0xff;
        let _ = parse_alembic(&bad, 0);
        bad[at] = 0x00;
        let _ = parse_alembic(&bad, 0);
    }
    // A group that holds itself ends at the depth bound.
    let mut b = b"Ogawa\xff\x00\x01".to_vec();
    b.extend(16u64.to_le_bytes());
    b.extend(6u64.to_le_bytes());
    for _ in 0..6 {
        b.extend(16u64.to_le_bytes());
    }
    assert!(parse_alembic(&b, 0).is_err());
}

#[test]
fn a_small_file_that_describes_a_huge_tree_is_refused_in_bounded_time() {
    // Each object's group names the same child group twice: 2^60 objects
    // described in a few kilobytes. Written by hand: a chain of groups,
    // each [properties (empty), child, child, headers of two children].
    let mut b = b"Ogawa\xff\x00\x01".to_vec();
    b.extend(0u64.to_le_bytes());
    let data = |b: &mut Vec<u8>, bytes: &[u8]| -> u64 {
        let pos = b.len() as u64;
        b.extend((bytes.len() as u64).to_le_bytes());
        b.extend(bytes);
        pos | 1 << 63
    };
    let group = |b: &mut Vec<u8>, children: &[u64]| -> u64 {
        let pos = b.len() as u64;
        b.extend((children.len() as u64).to_le_bytes());
        for c in children {
            b.extend(c.to_le_bytes());
        }
        pos
    };
    let mut headers = Vec::new();
    for name in [b"a", b"b"] {
        headers.extend(1u32.to_le_bytes());
        headers.extend(name);
        headers.push(0);
    }
    headers.extend([0u8; 32]);
    let headers = data(&mut b, &headers);
    let leaf_headers = data(&mut b, &[0u8; 32]);
    let mut child = group(&mut b, &[0, leaf_headers]);
    for _ in 0..60 {
        child = group(&mut b, &[0, child, child, headers]);
    }
    let version = data(&mut b, &0i32.to_le_bytes());
    let library = data(&mut b, &10709i32.to_le_bytes());
    let empty = 1u64 << 63;
    let root = group(&mut b, &[version, library, child, empty, empty, empty]);
    b[8..16].copy_from_slice(&root.to_le_bytes());
    // Refused once a million objects are walked, not after 2^60.
    let e = parse_alembic(&b, 0).unwrap_err();
    assert!(
        e.to_string().contains("objects in the archive's tree"),
        "{e}"
    );
}
