//! A small Alembic (Ogawa) writer for test fixtures, written from
//! Alembic's AbcCoreOgawa sources (AwImpl, OwData, CpwData, ApwImpl,
//! WriteUtil): the same container, headers and sample layout, repeated
//! samples elided as Alembic elides them, metadata indexed as Alembic's
//! `MetaDataMap` indexes it.
#![allow(dead_code, unreachable_pub)]

/// A property to write.
pub enum Prop {
    /// A scalar property: pod code, extent, metadata, one value block a
    /// sample.
    Scalar {
        name: String,
        pod: u32,
        extent: u32,
        meta: String,
        samples: Vec<Vec<u8>>,
        time_sampling: u32,
    },
    /// An array property, the same.
    Array {
        name: String,
        pod: u32,
        extent: u32,
        meta: String,
        samples: Vec<Vec<u8>>,
        time_sampling: u32,
    },
    /// A compound property.
    Compound {
        name: String,
        meta: String,
        props: Vec<Prop>,
    },
}

/// An object to write.
pub struct Obj {
    pub name: String,
    pub meta: String,
    pub props: Vec<Prop>,
    pub children: Vec<Obj>,
}

pub const BOOL: u32 = 0;
pub const U8: u32 = 1;
pub const I32: u32 = 6;
pub const U32: u32 = 5;
pub const F32: u32 = 10;
pub const F64: u32 = 11;

/// The same strands in Cem Yuksel's HAIR format, written by hand from its
/// layout (a 128-byte header, then segments a strand and points): the
/// copy an Alembic groom is compared with.
pub fn hair_file(h: &strands::Hair) -> Vec<u8> {
    let mut b = b"HAIR".to_vec();
    b.extend((h.strand_count() as u32).to_le_bytes());
    b.extend((h.point_count() as u32).to_le_bytes());
    b.extend(3u32.to_le_bytes()); // segments and points
    b.resize(128, 0);
    for s in h.strands() {
        b.extend(((s.len() - 1) as u16).to_le_bytes());
    }
    for p in h.points() {
        for c in p.to_array() {
            b.extend(c.to_le_bytes());
        }
    }
    b
}

pub fn f32s(v: &[f32]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}
pub fn f64s(v: &[f64]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}
pub fn i32s(v: &[i32]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}
pub fn u32s(v: &[u32]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}

/// The curves schema's object: `.geom` holding `.selfBnds`, `P`,
/// `nVertices`, `curveBasisAndType` and any `extra` properties (width).
/// `points` has one entry a sample; `kind` is `[type, wrap, basis]`.
pub fn curves(
    name: &str,
    points: Vec<Vec<f32>>,
    counts: &[i32],
    kind: [u8; 3],
    extra: Vec<Prop>,
) -> Obj {
    let mut props = vec![
        Prop::Scalar {
            name: ".selfBnds".into(),
            pod: F64,
            extent: 6,
            meta: "interpretation=box".into(),
            samples: vec![f64s(&[-1.0, -1.0, -1.0, 1.0, 1.0, 1.0])],
            time_sampling: 0,
        },
        Prop::Array {
            name: "P".into(),
            pod: F32,
            extent: 3,
            meta: "geoScope=vtx;interpretation=point".into(),
            time_sampling: if points.len() > 1 { 1 } else { 0 },
            samples: points.iter().map(|p| f32s(p)).collect(),
        },
        Prop::Array {
            name: "nVertices".into(),
            pod: I32,
            extent: 1,
            meta: String::new(),
            samples: vec![i32s(counts)],
            time_sampling: 0,
        },
        Prop::Scalar {
            name: "curveBasisAndType".into(),
            pod: U8,
            extent: 4,
            meta: String::new(),
            samples: vec![vec![kind[0], kind[1], kind[2], kind[2]]],
            time_sampling: 0,
        },
    ];
    props.extend(extra);
    Obj {
        name: name.into(),
        meta: "schema=AbcGeom_Curve_v2;schemaObjTitle=AbcGeom_Curve_v2:.geom".into(),
        props: vec![Prop::Compound {
            name: ".geom".into(),
            meta: "schema=AbcGeom_Curve_v2;schemaBaseType=AbcGeom_GeomBase_v1".into(),
            props,
        }],
        children: Vec::new(),
    }
}

/// A transform object: `ops` one byte each (type << 4), `vals` one list
/// of channels a sample, with `children` below it.
pub fn xform(
    name: &str,
    ops: &[u8],
    vals: Vec<Vec<f64>>,
    inherits: bool,
    children: Vec<Obj>,
) -> Obj {
    let channels = vals[0].len() as u32;
    let mut props = vec![
        Prop::Scalar {
            name: ".inherits".into(),
            pod: BOOL,
            extent: 1,
            meta: String::new(),
            samples: vec![vec![u8::from(inherits)]],
            time_sampling: 0,
        },
        Prop::Scalar {
            name: ".ops".into(),
            pod: U8,
            extent: ops.len() as u32,
            meta: String::new(),
            samples: vec![ops.to_vec()],
            time_sampling: 0,
        },
        Prop::Scalar {
            name: ".vals".into(),
            pod: F64,
            extent: channels,
            meta: String::new(),
            time_sampling: if vals.len() > 1 { 1 } else { 0 },
            samples: vals.iter().map(|v| f64s(v)).collect(),
        },
    ];
    props.push(Prop::Scalar {
        name: "isNotConstantIdentity".into(),
        pod: BOOL,
        extent: 1,
        meta: String::new(),
        samples: vec![vec![1]],
        time_sampling: 0,
    });
    Obj {
        name: name.into(),
        meta: "schema=AbcGeom_Xform_v3;schemaObjTitle=AbcGeom_Xform_v3:.xform".into(),
        props: vec![Prop::Compound {
            name: ".xform".into(),
            meta: "schema=AbcGeom_Xform_v3".into(),
            props,
        }],
        children,
    }
}

/// A width geometry parameter, not indexed.
pub fn width(values: &[f32], scope: &str) -> Prop {
    Prop::Array {
        name: "width".into(),
        pod: F32,
        extent: 1,
        meta: format!("geoScope={scope};isGeomParam=true;podExtent=1;podName=float32_t"),
        samples: vec![f32s(values)],
        time_sampling: 0,
    }
}

/// A width geometry parameter, indexed: `.vals` and `.indices`.
pub fn indexed_width(values: &[f32], indices: &[u32], scope: &str) -> Prop {
    Prop::Compound {
        name: "width".into(),
        meta: format!("geoScope={scope};isGeomParam=true;podExtent=1;podName=float32_t"),
        props: vec![
            Prop::Array {
                name: ".indices".into(),
                pod: U32,
                extent: 1,
                meta: String::new(),
                samples: vec![u32s(indices)],
                time_sampling: 0,
            },
            Prop::Array {
                name: ".vals".into(),
                pod: F32,
                extent: 1,
                meta: String::new(),
                samples: vec![f32s(values)],
                time_sampling: 0,
            },
        ],
    }
}

/// Writes the archive of the top object's `children`; time sampling 1 is
/// uniform at 24 a second (for animated properties).
pub fn archive(children: Vec<Obj>) -> Vec<u8> {
    let mut w = Writer {
        out: b"Ogawa\xff\x00\x01".to_vec(),
        meta_map: Vec::new(),
        max_samples: [0, 0],
    };
    w.out.extend(0u64.to_le_bytes());
    let version = w.data(&0i32.to_le_bytes());
    let library = w.data(&10709i32.to_le_bytes());
    let top = Obj {
        name: "ABC".into(),
        meta: String::new(),
        props: Vec::new(),
        children,
    };
    let top = w.object(&top);
    let meta = w.data(b"_ai_AlembicVersion=wisplight test writer;_ai_Application=tests");
    let mut ts = Vec::new();
    for (i, (tpc, times)) in [(1.0f64, [0.0f64]), (1.0 / 24.0, [0.0])].iter().enumerate() {
        ts.extend(w.max_samples[i].to_le_bytes());
        ts.extend(tpc.to_le_bytes());
        ts.extend((times.len() as u32).to_le_bytes());
        for t in times {
            ts.extend(t.to_le_bytes());
        }
    }
    let ts = w.data(&ts);
    let mut indexed = Vec::new();
    for m in &w.meta_map {
        indexed.push(m.len() as u8);
        indexed.extend(m.as_bytes());
    }
    let indexed = w.data(&indexed);
    let root = w.group(&[version, library, top, meta, ts, indexed]);
    w.out[8..16].copy_from_slice(&root.to_le_bytes());
    w.out
}

struct Writer {
    out: Vec<u8>,
    /// Alembic's MetaDataMap: strings under 256 bytes get an index from
    /// 1 (0 is the empty string), up to 254 of them; 0xff means inline.
    meta_map: Vec<String>,
    max_samples: [u32; 2],
}

const DATA_BIT: u64 = 1 << 63;

impl Writer {
    fn data(&mut self, bytes: &[u8]) -> u64 {
        if bytes.is_empty() {
            return DATA_BIT;
        }
        let pos = self.out.len() as u64;
        self.out.extend((bytes.len() as u64).to_le_bytes());
        self.out.extend(bytes);
        pos | DATA_BIT
    }
    fn group(&mut self, children: &[u64]) -> u64 {
        if children.is_empty() {
            return 0;
        }
        let pos = self.out.len() as u64;
        self.out.extend((children.len() as u64).to_le_bytes());
        for c in children {
            self.out.extend(c.to_le_bytes());
        }
        pos
    }
    fn meta_index(&mut self, meta: &str) -> u32 {
        if meta.is_empty() {
            return 0;
        }
        if meta.len() < 256 {
            if let Some(i) = self.meta_map.iter().position(|m| m == meta) {
                return i as u32 + 1;
            }
            if self.meta_map.len() < 254 {
                self.meta_map.push(meta.to_owned());
                return self.meta_map.len() as u32;
            }
        }
        0xff
    }
    /// An object's group: its properties, its children, their headers and
    /// 32 bytes of hashes.
    fn object(&mut self, o: &Obj) -> u64 {
        let props = self.compound(&o.props);
        let mut children = vec![props];
        let mut headers = Vec::new();
        for c in &o.children {
            children.push(self.object(c));
            headers.extend((c.name.len() as u32).to_le_bytes());
            headers.extend(c.name.as_bytes());
            let index = self.meta_index(&c.meta);
            headers.push(index as u8);
            if index == 0xff {
                headers.extend((c.meta.len() as u32).to_le_bytes());
                headers.extend(c.meta.as_bytes());
            }
        }
        headers.extend([0u8; 32]);
        let h = self.data(&headers);
        children.push(h);
        self.group(&children)
    }
    /// A compound's group: one child a property, then their headers.
    fn compound(&mut self, props: &[Prop]) -> u64 {
        let mut children = Vec::new();
        let mut headers = Vec::new();
        for p in props {
            match p {
                Prop::Compound { name, meta, props } => {
                    children.push(self.compound(props));
                    self.header(&mut headers, 0, name, meta, None);
                }
                Prop::Scalar {
                    name,
                    pod,
                    extent,
                    meta,
                    samples,
                    time_sampling,
                }
                | Prop::Array {
                    name,
                    pod,
                    extent,
                    meta,
                    samples,
                    time_sampling,
                } => {
                    let array = matches!(p, Prop::Array { .. });
                    // Alembic writes sample 0 and every sample from the
                    // first change to the last, elides the rest.
                    let changed: Vec<usize> = (1..samples.len())
                        .filter(|&i| samples[i] != samples[i - 1])
                        .collect();
                    let (first, last) = match (changed.first(), changed.last()) {
                        (Some(&f), Some(&l)) => (f, l),
                        _ => (0, 0),
                    };
                    let mut stored = vec![&samples[0]];
                    if first > 0 {
                        stored.extend(&samples[first..=last]);
                    }
                    let mut blocks = Vec::new();
                    for s in stored {
                        let mut b = vec![0x5au8; 16];
                        b.extend(s);
                        blocks.push(self.data(&b));
                        if array {
                            blocks.push(DATA_BIT);
                        }
                    }
                    children.push(self.group(&blocks));
                    let ts = *time_sampling as usize;
                    self.max_samples[ts] = self.max_samples[ts].max(samples.len() as u32);
                    let kind = if array { 2 } else { 1 };
                    let info = (
                        kind,
                        *pod,
                        *extent,
                        samples.len() as u32,
                        first as u32,
                        last as u32,
                        *time_sampling,
                    );
                    self.header(&mut headers, kind, name, meta, Some(info));
                }
            }
        }
        let h = self.data(&headers);
        children.push(h);
        self.group(&children)
    }
    /// Alembic's `WritePropertyInfo`.
    #[allow(clippy::type_complexity)]
    fn header(
        &mut self,
        out: &mut Vec<u8>,
        kind: u32,
        name: &str,
        meta: &str,
        info: Option<(u32, u32, u32, u32, u32, u32, u32)>,
    ) {
        let index = self.meta_index(meta);
        let mut max = meta.len().max(name.len()) as u32;
        if let Some((_, _, _, n, _, _, ts)) = info {
            max = max.max(n).max(ts);
        }
        let hint = if max > 255 && max < 65536 {
            1
        } else if max >= 65536 {
            2
        } else {
            0
        };
        let push = |out: &mut Vec<u8>, v: u32, hint: u32| match hint {
            0 => out.push(v as u8),
            1 => out.extend((v as u16).to_le_bytes()),
            _ => out.extend(v.to_le_bytes()),
        };
        let mut word = (hint << 2) | (index << 20);
        match info {
            None => push(out, word, 2),
            Some((kind, pod, extent, n, first, last, ts)) => {
                word |= kind | (pod << 4) | (extent << 12);
                if ts != 0 {
                    word |= 0x100;
                }
                let needs_first_last = !(first == 0 && last == 0) && (first != 1 || last != n - 1);
                if first == 0 && last == 0 {
                    word |= 0x800;
                } else if needs_first_last {
                    word |= 0x200;
                }
                push(out, word, 2);
                push(out, n, hint);
                if needs_first_last {
                    push(out, first, hint);
                    push(out, last, hint);
                }
                if ts != 0 {
                    push(out, ts, hint);
                }
            }
        }
        let _ = kind;
        push(out, name.len() as u32, hint);
        out.extend(name.as_bytes());
        if index == 0xff {
            push(out, meta.len() as u32, hint);
            out.extend(meta.as_bytes());
        }
    }
}
