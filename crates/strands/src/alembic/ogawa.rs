//! The Ogawa container and Alembic's core layer over it: groups and data
//! blocks, objects, properties and their samples, read from bytes already
//! in memory.
//!
//! A fork of ogawa-rs 0.4.0 (Traverse Research, MIT OR Apache-2.0): its
//! layout of the format, rewritten over a byte slice so that every read is
//! checked against the bytes present. The fixes, each marked `Fix:` below:
//! - every size and position a file claims is checked before it is used,
//!   so a lying or truncated file is an error and never a huge allocation
//!   (ogawa-rs allocated what a data block's header claimed);
//! - no `assert!`, `todo!` or `unwrap` on what the file holds;
//! - an array property's sample `i` is data block `2 i` (its dimensions
//!   block `2 i + 1`), as Alembic writes it (ogawa-rs read block `i`, right
//!   for the first sample only);
//! - a property that records neither flag changes from sample 1 (Alembic's
//!   `firstChangedIndex = 1`; ogawa-rs took 0);
//! - nesting and counts are bounded, so a group that contains itself ends.
//!
//! The format, as Alembic's AbcCoreOgawa writes it (all little-endian):
//! - file: `"Ogawa"`, a frozen byte (`0xff` once written whole), a `u16`
//!   version (1), the root group's position `u64`;
//! - group: a `u64` child count and one `u64` a child: a data block when
//!   the top bit is set, else a group; the rest is the position (0: empty);
//! - data block: a `u64` size and that many bytes;
//! - archive (the root group): \[0] Alembic's format version, \[1] the
//!   library's version, \[2] the top object, \[3] the archive's metadata,
//!   \[4] the time samplings, \[5] the indexed metadata;
//! - object (a group): \[0] its properties, \[1..n] its children, \[n] a
//!   data block of the children's headers and 32 bytes of hashes;
//! - compound property (a group): one child a property, then a data block
//!   of their headers;
//! - scalar property (a group): one data block a stored sample, each a
//!   16-byte key and the values; an array property: two a stored sample,
//!   the values (with their key) and the dimensions.

use std::collections::BTreeMap;

use super::AlembicError;

/// The top bit of a child: a data block, not a group.
const DATA_BIT: u64 = 1 << 63;
/// Objects deeper than this are refused: no groom nests so far, and a
/// group that contains itself would otherwise never end.
const MAX_DEPTH: usize = 256;
/// The key before each sample's values.
const KEY_BYTES: usize = 16;
/// The hashes after an object's child headers.
const HASH_BYTES: usize = 32;

/// An Ogawa archive's bytes, every read checked.
#[derive(Clone, Copy)]
pub(super) struct Bytes<'a>(pub(super) &'a [u8]);

impl<'a> Bytes<'a> {
    /// `n` bytes at `at`, or the error naming `what` that runs past the end.
    fn slice(self, at: u64, n: u64, what: &str) -> Result<&'a [u8], AlembicError> {
        let len = self.0.len() as u64;
        match at.checked_add(n) {
            Some(end) if end <= len => Ok(&self.0[at as usize..end as usize]),
            _ => Err(AlembicError::Truncated {
                what: what.to_owned(),
                at,
                len,
            }),
        }
    }

    fn u64_at(self, at: u64, what: &str) -> Result<u64, AlembicError> {
        let b = self.slice(at, 8, what)?;
        Ok(u64::from_le_bytes(b.try_into().expect("8 bytes")))
    }

    /// The children of the group at `pos` (none for position 0).
    fn group(self, pos: u64, what: &str) -> Result<Vec<u64>, AlembicError> {
        if pos == 0 {
            return Ok(Vec::new());
        }
        let count = self.u64_at(pos, what)?;
        // Fix: the count is checked against the bytes that follow before
        // anything is allocated for it.
        let raw = self.slice(pos + 8, count.saturating_mul(8), what)?;
        Ok(raw
            .chunks_exact(8)
            .map(|c| u64::from_le_bytes(c.try_into().expect("8 bytes")))
            .collect())
    }

    /// The bytes of the data block `child` (empty for position 0).
    fn data(self, child: u64, what: &str) -> Result<&'a [u8], AlembicError> {
        if child & DATA_BIT == 0 {
            return Err(malformed(what, "a group where a data block belongs"));
        }
        let pos = child & !DATA_BIT;
        if pos == 0 {
            return Ok(&[]);
        }
        let size = self.u64_at(pos, what)?;
        self.slice(pos + 8, size, what)
    }

    /// The group `child` (an error if it is a data block).
    fn subgroup(self, child: u64, what: &str) -> Result<Vec<u64>, AlembicError> {
        if child & DATA_BIT != 0 {
            return Err(malformed(what, "a data block where a group belongs"));
        }
        self.group(child, what)
    }
}

fn malformed(what: &str, why: impl Into<String>) -> AlembicError {
    AlembicError::Malformed {
        what: what.to_owned(),
        why: why.into(),
    }
}

/// Alembic metadata: `key=value` pairs joined by `;`.
#[derive(Debug, Clone, Default, PartialEq)]
pub(super) struct MetaData(BTreeMap<String, String>);

impl MetaData {
    fn parse(text: &[u8]) -> MetaData {
        let text = String::from_utf8_lossy(text);
        MetaData(
            text.split(';')
                .filter_map(|pair| pair.split_once('='))
                .map(|(k, v)| (k.to_owned(), v.to_owned()))
                .collect(),
        )
    }
    /// The value of `key`, if set.
    pub(super) fn get(&self, key: &str) -> Option<&str> {
        self.0.get(key).map(String::as_str)
    }
}

/// A plain old data type, as Alembic numbers them.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Pod {
    Bool,
    U8,
    I8,
    U16,
    I16,
    U32,
    I32,
    U64,
    I64,
    F16,
    F32,
    F64,
    String,
    WString,
}

impl Pod {
    fn from_code(code: u32) -> Option<Pod> {
        use Pod::*;
        [
            Bool, U8, I8, U16, I16, U32, I32, U64, I64, F16, F32, F64, String, WString,
        ]
        .get(code as usize)
        .copied()
    }
    /// Bytes of one value (strings have none fixed).
    pub(super) fn bytes(self) -> usize {
        match self {
            Pod::Bool | Pod::U8 | Pod::I8 => 1,
            Pod::U16 | Pod::I16 | Pod::F16 => 2,
            Pod::U32 | Pod::I32 | Pod::F32 => 4,
            Pod::U64 | Pod::I64 | Pod::F64 => 8,
            Pod::String | Pod::WString => 0,
        }
    }
}

/// What a property is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Kind {
    Compound,
    Scalar,
    Array,
}

/// A property's header: its name, kind, values and samples.
#[derive(Debug, Clone)]
pub(super) struct PropertyHeader {
    pub(super) name: String,
    pub(super) kind: Kind,
    pub(super) pod: Pod,
    pub(super) extent: u8,
    pub(super) meta: MetaData,
    /// The samples written (stored or repeated).
    pub(super) samples: u32,
    first_changed: u32,
    last_changed: u32,
}

impl PropertyHeader {
    /// The stored sample that holds sample `i` (Alembic's
    /// `verifyIndex`): samples before the first change and after the last
    /// are the stored first and last.
    fn stored(&self, i: u32) -> u32 {
        let (first, last) = (self.first_changed, self.last_changed);
        if i < first || (first == 0 && last == 0) {
            0
        } else if i >= last {
            last - first + 1
        } else {
            i - first + 1
        }
    }
}

/// An object of the archive: its path, metadata, properties and children.
pub(super) struct Object {
    /// Its full name, `/` joined.
    pub(super) path: String,
    pub(super) meta: MetaData,
    group: Vec<u64>,
    children: Vec<(String, MetaData)>,
    depth: usize,
}

/// A compound property: its headers and their groups.
pub(super) struct Compound {
    pub(super) headers: Vec<PropertyHeader>,
    group: Vec<u64>,
    /// Where it is, for errors.
    pub(super) path: String,
    depth: usize,
}

/// An open archive.
pub(super) struct Archive<'a> {
    bytes: Bytes<'a>,
    indexed_meta: Vec<MetaData>,
    /// How many time samplings the archive declares (property headers
    /// index them).
    time_samplings: usize,
    top: u64,
}

impl<'a> Archive<'a> {
    /// Reads the header and the archive's tables.
    pub(super) fn open(b: &'a [u8]) -> Result<Archive<'a>, AlembicError> {
        let bytes = Bytes(b);
        if b.len() < 16 || &b[..5] != b"Ogawa" {
            return Err(AlembicError::Magic {
                len: b.len(),
                hdf5: b.starts_with(b"\x89HDF"),
            });
        }
        let root_pos = bytes.u64_at(8, "the archive's root group")?;
        let root = bytes.group(root_pos, "the archive's root group")?;
        if root.len() < 6 || root[2] & DATA_BIT != 0 {
            return Err(malformed(
                "the archive's root group",
                format!("{} children, not the 6 of an Alembic archive", root.len()),
            ));
        }
        let version = bytes.data(root[0], "the archive's version")?;
        if version.len() != 4 || u32::from_le_bytes(version.try_into().expect("4")) != 0 {
            return Err(malformed(
                "the archive's version",
                "not Alembic's Ogawa format version 0",
            ));
        }
        let time_samplings = count_time_samplings(bytes.data(root[4], "the time samplings")?)?;
        let indexed_meta = indexed_meta_data(bytes.data(root[5], "the indexed metadata")?)?;
        Ok(Archive {
            bytes,
            indexed_meta,
            time_samplings,
            top: root[2],
        })
    }

    /// The top object (`/`).
    pub(super) fn top(&self) -> Result<Object, AlembicError> {
        self.object(self.top, String::new(), MetaData::default(), 0)
    }

    fn object(
        &self,
        pos: u64,
        path: String,
        meta: MetaData,
        depth: usize,
    ) -> Result<Object, AlembicError> {
        let what = if path.is_empty() { "/" } else { &path };
        if depth > MAX_DEPTH {
            return Err(malformed(what, format!("nested deeper than {MAX_DEPTH}")));
        }
        let group = self.bytes.subgroup(pos, what)?;
        let mut children = Vec::new();
        if let Some(&last) = group.last()
            && last & DATA_BIT != 0
        {
            children = self.object_headers(self.bytes.data(last, what)?, what)?;
            // Fix: the headers name no more children than the group holds.
            if children.len() + 2 > group.len() {
                return Err(malformed(
                    what,
                    format!(
                        "{} child headers for {} groups",
                        children.len(),
                        group.len().saturating_sub(2)
                    ),
                ));
            }
        }
        Ok(Object {
            path,
            meta,
            group,
            children,
            depth,
        })
    }

    fn object_headers(
        &self,
        b: &[u8],
        what: &str,
    ) -> Result<Vec<(String, MetaData)>, AlembicError> {
        if b.len() <= HASH_BYTES {
            return Ok(Vec::new());
        }
        let mut r = Reader::new(&b[..b.len() - HASH_BYTES], what);
        let mut out = Vec::new();
        while !r.done() {
            let n = r.uint(2)?;
            let name = String::from_utf8_lossy(r.take(n as usize)?).into_owned();
            let index = r.uint(0)?;
            let meta = if index == 0xff {
                let n = r.uint(2)?;
                MetaData::parse(r.take(n as usize)?)
            } else {
                self.meta_at(index, what)?
            };
            out.push((name, meta));
        }
        Ok(out)
    }

    fn meta_at(&self, index: u32, what: &str) -> Result<MetaData, AlembicError> {
        self.indexed_meta
            .get(index as usize)
            .cloned()
            .ok_or_else(|| malformed(what, format!("metadata index {index} of none")))
    }

    /// `o`'s children, in order.
    pub(super) fn children(&self, o: &Object) -> Result<Vec<Object>, AlembicError> {
        o.children
            .iter()
            .enumerate()
            .map(|(i, (name, meta))| {
                self.object(
                    o.group[i + 1],
                    format!("{}/{name}", o.path),
                    meta.clone(),
                    o.depth + 1,
                )
            })
            .collect()
    }

    /// `o`'s properties (its top compound).
    pub(super) fn properties(&self, o: &Object) -> Result<Compound, AlembicError> {
        match o.group.first() {
            Some(&c) if c & DATA_BIT == 0 => self.compound(c, o.path.clone(), o.depth),
            _ => Ok(Compound {
                headers: Vec::new(),
                group: Vec::new(),
                path: o.path.clone(),
                depth: o.depth,
            }),
        }
    }

    fn compound(&self, pos: u64, path: String, depth: usize) -> Result<Compound, AlembicError> {
        if depth > 2 * MAX_DEPTH {
            return Err(malformed(&path, "properties nested too deep"));
        }
        let group = self.bytes.subgroup(pos, &path)?;
        let mut headers = Vec::new();
        if let Some(&last) = group.last()
            && last & DATA_BIT != 0
        {
            headers = self.property_headers(self.bytes.data(last, &path)?, &path)?;
            if headers.len() + 1 > group.len() {
                return Err(malformed(
                    &path,
                    format!(
                        "{} property headers for {} groups",
                        headers.len(),
                        group.len() - 1
                    ),
                ));
            }
        }
        Ok(Compound {
            headers,
            group,
            path,
            depth,
        })
    }

    /// Alembic's `ReadPropertyHeaders`: a packed `u32` of kind, size hint,
    /// pod, flags, extent and metadata index, then counts sized by the hint.
    fn property_headers(&self, b: &[u8], what: &str) -> Result<Vec<PropertyHeader>, AlembicError> {
        let mut r = Reader::new(b, what);
        let mut out = Vec::new();
        while !r.done() {
            let info = r.uint(2)?;
            let kind = match info & 0x3 {
                0 => Kind::Compound,
                1 => Kind::Scalar,
                _ => Kind::Array,
            };
            let hint = (info >> 2) & 0x3;
            let (mut pod, mut extent) = (Pod::U8, 0);
            let (mut samples, mut first_changed, mut last_changed) = (0, 0, 0);
            if kind != Kind::Compound {
                pod = Pod::from_code((info >> 4) & 0xf)
                    .ok_or_else(|| malformed(what, format!("pod type {}", (info >> 4) & 0xf)))?;
                extent = ((info >> 12) & 0xff) as u8;
                samples = r.uint(hint)?;
                if info & 0x200 != 0 {
                    first_changed = r.uint(hint)?;
                    last_changed = r.uint(hint)?;
                } else if info & 0x800 == 0 {
                    // Fix: every sample differs, from the second on.
                    first_changed = 1;
                    last_changed = samples.saturating_sub(1);
                }
                if first_changed > last_changed || last_changed > samples {
                    return Err(malformed(
                        what,
                        format!("samples {first_changed} to {last_changed} changed of {samples}"),
                    ));
                }
                if info & 0x100 != 0 {
                    let ts = r.uint(hint)?;
                    if ts as usize >= self.time_samplings {
                        return Err(malformed(what, format!("time sampling {ts} of none")));
                    }
                }
            }
            let n = r.uint(hint)?;
            let name = String::from_utf8_lossy(r.take(n as usize)?).into_owned();
            let index = (info >> 20) & 0xff;
            let meta = if index == 0xff {
                let n = r.uint(hint)?;
                MetaData::parse(r.take(n as usize)?)
            } else {
                self.meta_at(index, what)?
            };
            out.push(PropertyHeader {
                name,
                kind,
                pod,
                extent,
                meta,
                samples,
                first_changed,
                last_changed,
            });
        }
        Ok(out)
    }

    /// The sub-property named `name` of `c`, with its index.
    pub(super) fn find<'c>(c: &'c Compound, name: &str) -> Option<(usize, &'c PropertyHeader)> {
        c.headers.iter().enumerate().find(|(_, h)| h.name == name)
    }

    /// The compound sub-property `i` of `c`.
    pub(super) fn sub_compound(&self, c: &Compound, i: usize) -> Result<Compound, AlembicError> {
        let h = &c.headers[i];
        let path = format!("{}.{}", c.path, h.name);
        if h.kind != Kind::Compound {
            return Err(malformed(&path, "not a compound property"));
        }
        self.compound(c.group[i], path, c.depth + 1)
    }

    /// The raw values of sample `sample` of the scalar or array
    /// sub-property `i` of `c` (clamped to its last sample, as Alembic's
    /// sample selector does), without the key.
    pub(super) fn sample(
        &self,
        c: &Compound,
        i: usize,
        sample: u32,
    ) -> Result<&'a [u8], AlembicError> {
        let h = &c.headers[i];
        let what = format!("{}.{}", c.path, h.name);
        if h.samples == 0 {
            return Err(malformed(&what, "no samples"));
        }
        let stored = h.stored(sample.min(h.samples - 1)) as usize;
        let group = self.bytes.subgroup(c.group[i], &what)?;
        // Fix: an array's sample is every other block (values, dimensions).
        let block = match h.kind {
            Kind::Array => 2 * stored,
            _ => stored,
        };
        let child = *group.get(block).ok_or_else(|| {
            malformed(
                &what,
                format!("sample {stored} stored, of {} blocks", group.len()),
            )
        })?;
        let data = self.bytes.data(child, &what)?;
        if data.is_empty() {
            return Ok(data);
        }
        if data.len() < KEY_BYTES {
            return Err(malformed(&what, "a sample shorter than its key"));
        }
        Ok(&data[KEY_BYTES..])
    }
}

/// Counts the archive's time samplings: each a `u32` of the most samples,
/// an `f64` of time a cycle, a `u32` count and that many `f64` times.
fn count_time_samplings(b: &[u8]) -> Result<usize, AlembicError> {
    let mut r = Reader::new(b, "the time samplings");
    let mut n = 0;
    while !r.done() {
        r.take(12)?;
        let times = r.uint(2)? as usize;
        r.take(times.saturating_mul(8))?;
        n += 1;
    }
    Ok(n)
}

/// The indexed metadata: index 0 is empty, then one `u8`-sized string each.
fn indexed_meta_data(b: &[u8]) -> Result<Vec<MetaData>, AlembicError> {
    let mut r = Reader::new(b, "the indexed metadata");
    let mut out = vec![MetaData::default()];
    while !r.done() {
        let n = r.uint(0)?;
        out.push(MetaData::parse(r.take(n as usize)?));
    }
    Ok(out)
}

/// Reads packed header fields, each checked against the bytes left.
struct Reader<'b> {
    b: &'b [u8],
    at: usize,
    what: &'b str,
}

impl<'b> Reader<'b> {
    fn new(b: &'b [u8], what: &'b str) -> Self {
        Reader { b, at: 0, what }
    }
    fn done(&self) -> bool {
        self.at >= self.b.len()
    }
    fn take(&mut self, n: usize) -> Result<&'b [u8], AlembicError> {
        match self.at.checked_add(n) {
            Some(end) if end <= self.b.len() => {
                let s = &self.b[self.at..end];
                self.at = end;
                Ok(s)
            }
            _ => Err(malformed(
                self.what,
                format!(
                    "a header field of {n} bytes runs past the {}-byte block",
                    self.b.len()
                ),
            )),
        }
    }
    /// A `u32` stored in 1, 2 or 4 bytes (size hint 0, 1 or 2).
    fn uint(&mut self, hint: u32) -> Result<u32, AlembicError> {
        Ok(match hint {
            0 => u32::from(self.take(1)?[0]),
            1 => u32::from(u16::from_le_bytes(self.take(2)?.try_into().expect("2"))),
            2 => u32::from_le_bytes(self.take(4)?.try_into().expect("4")),
            _ => return Err(malformed(self.what, "size hint 3")),
        })
    }
}

/// Values of `pod`, each through `f64` into `T` (no `Vec<f64>` between:
/// a groom's points are read straight into `f32`).
pub(super) fn numbers<T>(
    b: &[u8],
    pod: Pod,
    what: &str,
    into: impl Fn(f64) -> T,
) -> Result<Vec<T>, AlembicError> {
    let n = pod.bytes();
    if n == 0 || pod == Pod::F16 || !b.len().is_multiple_of(n) {
        return Err(malformed(
            what,
            format!("{} bytes of {pod:?}, not numbers read here", b.len()),
        ));
    }
    Ok(b.chunks_exact(n)
        .map(|c| {
            into(match pod {
                Pod::Bool | Pod::U8 => f64::from(c[0]),
                Pod::I8 => f64::from(c[0] as i8),
                Pod::U16 => f64::from(u16::from_le_bytes([c[0], c[1]])),
                Pod::I16 => f64::from(i16::from_le_bytes([c[0], c[1]])),
                Pod::U32 => f64::from(u32::from_le_bytes(c.try_into().expect("4"))),
                Pod::I32 => f64::from(i32::from_le_bytes(c.try_into().expect("4"))),
                Pod::F32 => f64::from(f32::from_le_bytes(c.try_into().expect("4"))),
                Pod::U64 => u64::from_le_bytes(c.try_into().expect("8")) as f64,
                Pod::I64 => i64::from_le_bytes(c.try_into().expect("8")) as f64,
                _ => f64::from_le_bytes(c.try_into().expect("8")),
            })
        })
        .collect())
}
