use super::*;

use std::time::Duration;

use glam::Vec3;
use shadow::{Fiber, Light};
use strands::{Style, StyleParams, WispModel};

fn hair() -> strands::Hair {
    let mut p = StyleParams::new(Style::Curly);
    p.strands_per_wisp = 3;
    WispModel::generate(&p).interpolate()
}

#[test]
fn text_pieces_cut_at_characters_and_join_to_the_text() {
    let text = "aé€😀".repeat(50);
    for max in [1, 4, 5, 7, 64, 1000] {
        let pieces: Vec<&str> = text_pieces(&text, max).collect();
        assert_eq!(pieces.concat(), text);
        assert!(
            pieces
                .iter()
                .all(|p| p.len() <= max.max(4) && !p.is_empty())
        );
    }
    assert_eq!(text_pieces("", 8).collect::<Vec<_>>(), vec![""]);
}

#[test]
fn packed_values_round_trip_and_runs_shrink_zeros() {
    let values: Vec<u32> = (0..5000u32)
        .map(|i| match i % 7 {
            0..=3 => 0,
            4 => u32::MAX,
            5 => i * 977,
            _ => 1,
        })
        .chain([0; 300])
        .collect();
    let packed = pack(&values);
    let mut back = vec![42];
    unpack_runs(&packed, values.len(), &mut back).unwrap();
    assert_eq!(back[0], 42, "appends after what is there");
    assert_eq!(&back[1..], &values[..]);
    // 300 trailing zeros are one two-byte token.
    assert_eq!(pack(&[0; 300]), vec![0xd9, 0x04]);
    assert_eq!(pack(&[5, 0, 0]), vec![10, 5]);
    assert!(pack(&[]).is_empty());
}

#[test]
fn malformed_packings_are_refused_without_allocating_what_they_claim() {
    let mut out = Vec::new();
    // Too few, too many, a run past the end, an empty run.
    assert!(unpack_runs(&pack(&[1, 2]), 3, &mut out).is_err());
    assert!(unpack_runs(&pack(&[1, 2, 3]), 2, &mut out).is_err());
    assert!(unpack_runs(&[0xff, 0xff, 0xff, 0xff, 0x0f], 10, &mut out).is_err());
    assert!(unpack_runs(&[1], 10, &mut out).is_err());
    // Cut short, past 64 bits, past 32 bits.
    assert!(unpack_runs(&[0x80], 1, &mut out).is_err());
    assert!(unpack_runs(&[0xff; 11], 1, &mut out).is_err());
    assert!(unpack_runs(&[0x80, 0x80, 0x80, 0x80, 0x40], 1, &mut out).is_err());
    // A claimed count of a billion from three bytes reserves little.
    let mut small = Vec::new();
    assert!(unpack_runs(&[2, 2, 2], 1_000_000_000, &mut small).is_err());
    assert!(small.capacity() < 1000);
}

/// A map of 8 a side with a few occupied columns, one of them
/// saturating its cells.
fn swept_map() -> DensityMap {
    let light = shadow::Light::directional(Vec3::X).unwrap();
    let frame = LightFrame::centered(&light, Vec3::ZERO, 8.0, 8).unwrap();
    let mut map = DensityMap::new(frame);
    map.add_quanta(2, 1, 0, 1000);
    map.add_quanta(5, 1, 0, 77);
    map.add_quanta(0, 6, 0, 3 << 20);
    for i in 0..8 {
        map.add_quanta(i, 3, 2, u32::MAX);
    }
    map
}

fn read(layout: ColumnSlab, chunks: &[pb::SlabChunk]) -> Result<ColumnSlab, Malformed> {
    let mut r = SlabReader::new(layout);
    for c in chunks {
        r.add(c)?;
    }
    r.finish()
}

#[test]
fn slabs_round_trip_exactly_into_the_senders_spans() {
    let map = swept_map();
    for cols in [0..64, 0..7, 7..64, 20..20] {
        let slab = shadow::sweep(&map, cols.clone());
        let back = read(ColumnSlab::layout(&map, cols), &slab_chunks(&slab)).unwrap();
        assert_eq!(back, slab);
    }
    // The saturated column: 8 cells of 2^32 - 1 quanta reach 2^27
    // steps; 3 * 2^20 quanta are 3 * 2^12 steps.
    let slab = shadow::sweep(&map, 0..64);
    let saturated = ((8 * u64::from(u32::MAX) + 128) >> 8) as u32;
    assert_eq!(slab.depth.last(), Some(&saturated));
    assert!(slab.depth.contains(&(3 << 12)));
}

#[test]
fn slab_chunks_out_of_place_or_overflowing_are_refused() {
    let map = swept_map();
    let layout = || ColumnSlab::layout(&map, 0..64);
    let chunks = slab_chunks(&shadow::sweep(&map, 0..64));
    assert_eq!(chunks.len(), 1);
    let mut c = chunks[0].clone();
    c.first_column = 1;
    assert!(read(layout(), &[c]).is_err(), "a gap before the chunk");
    // Columns 0..10 hold fewer depths than the chunk carries.
    let mut c = chunks[0].clone();
    c.end_column = 10;
    assert!(read(layout(), &[c]).is_err(), "depths left over");
    let mut c = chunks[0].clone();
    c.end_column = 65;
    assert!(read(layout(), &[c]).is_err(), "past the slab");
    // Two halves are fine; one half is not the whole slab.
    let slab = shadow::sweep(&map, 0..64);
    let halves: Vec<_> = [0..20, 20..64]
        .into_iter()
        .flat_map(|r| slab_chunks(&shadow::sweep(&map, r)))
        .collect();
    assert_eq!(read(layout(), &halves).unwrap(), slab);
    let e = read(layout(), &halves[..1]).unwrap_err().to_string();
    assert!(e.contains("slab ends at column 20, expected 64"), "{e}");
    // Growth past 32 bits within a column.
    let big = pb::SlabChunk {
        first_column: 0,
        end_column: 64,
        depth_steps: {
            let n = layout().cells();
            let mut v = vec![1u32; n];
            v[n - 1] = u32::MAX;
            pack(&v)
        },
    };
    let e = read(layout(), &[big]).unwrap_err().to_string();
    assert!(e.contains("past 2^32"), "{e}");
}

#[test]
fn columns_summed_and_swept_by_their_owners_give_the_local_transmittance_bit_for_bit() {
    // Three workers' partial maps, as each deposits its third of the
    // strands; each owner sums the others' density of its columns over
    // the wire format, adds the head, sweeps, and every worker assembles
    // all owners' swept columns.
    let hair = hair();
    let fiber = Fiber::new(0.1, 0.5).unwrap();
    let light = Light::directional(Vec3::new(0.9, -0.35, -0.25)).unwrap();
    let frame = LightFrame::fit(&light, hair.points(), 64).unwrap();
    let head = shadow::Occluder::sphere(Vec3::new(0.0, 3.0, 0.0), 4.0);
    let n = hair.strand_count();
    let thirds = [0..n / 3, n / 3..2 * n / 3, 2 * n / 3..n];
    let partial: Vec<DensityMap> = thirds
        .iter()
        .map(|r| {
            let mut m = DensityMap::new(frame);
            m.deposit(&hair, r.clone(), &fiber);
            m
        })
        .collect();
    let mut whole = DensityMap::new(frame);
    whole.deposit(&hair, 0..n, &fiber);
    assert!(
        whole.deposit_body(&head, shadow::OPAQUE_DEPTH) > 100,
        "the head is in the map"
    );
    let want = shadow::Transmittance::compute(&whole);
    // Uneven cuts, one of them empty.
    let cuts = vec![0, 700, 700, frame.columns() as u32];
    let peers: Vec<(String, String)> = (0..3)
        .map(|i| (format!("w{i}:1"), format!("s{i}")))
        .collect();
    let plan = |own| ColumnPlan {
        round: 1,
        cuts: cuts.clone(),
        own,
        peers: peers.clone(),
        wait: Duration::from_secs(1),
        tls_domain: None,
        head: None,
    };
    let owners: Vec<Vec<pb::DrawChunk>> = (0..3)
        .map(|own| {
            let p = plan(own);
            let mine = p.range(own);
            let mut m = partial[own].clone();
            for (b, other) in partial.iter().enumerate() {
                if b != own {
                    for c in column_chunks(other, mine.clone()) {
                        let d = decode_columns(&frame, &c).unwrap();
                        assert!(d.within(mine.clone()));
                        add_columns(&mut m, &d);
                    }
                }
            }
            m.deposit_body(&head, shadow::OPAQUE_DEPTH);
            let slab = shadow::sweep(&m, mine.start as u32..mine.end as u32);
            swept_chunks(&frame, &slab)
        })
        .collect();
    let got = assemble_swept(frame, &plan(0), &owners).unwrap();
    let mut checked = 0;
    for p in hair.points().iter().step_by(7) {
        for filter in [false, true] {
            assert_eq!(
                want.optical_depth(*p, filter).to_bits(),
                got.optical_depth(*p, filter).to_bits(),
                "{p} filtered {filter}"
            );
            checked += 1;
        }
    }
    assert!(checked > 100);
    // An owner's columns handed in as another's are refused.
    let mut swapped = owners.clone();
    swapped.swap(0, 2);
    assert!(assemble_swept(frame, &plan(0), &swapped).is_err());
    // A plan that does not cut the map whole is refused.
    let mut bad = plan(0).to_pb();
    bad.cuts[3] -= 1;
    let e = ColumnPlan::from_pb(&bad, frame.columns()).unwrap_err();
    assert!(e.to_string().contains("cuts"), "{e}");
    bad.cuts = vec![0, 900, 800, frame.columns() as u32];
    assert!(ColumnPlan::from_pb(&bad, frame.columns()).is_err());
    let mut bad = plan(0).to_pb();
    bad.own = 3;
    assert!(ColumnPlan::from_pb(&bad, frame.columns()).is_err());
    assert_eq!(
        ColumnPlan::from_pb(&plan(1).to_pb(), frame.columns()).unwrap(),
        plan(1)
    );
}
