//! The simulation cache's format: the state of every wisp after one
//! frame's steps, one file a frame (`frame_000100.wlsim`), so that any
//! range of frames renders alone, on any machine, with the bytes of a run
//! that rendered every frame ([`crate::Sequence::resume_at`]). This module
//! encodes and decodes; the caller writes each file whole or not at all.
//!
//! A file, little-endian throughout:
//!
//! | bytes | what |
//! |---|---|
//! | 8 | magic `WLSIMCAC` |
//! | 4 | format, 1 |
//! | 2 + n | the writing wisplight's version, its length then its UTF-8 |
//! | 8 | the scene's hash ([`scene_hash`]) |
//! | 8 | the frame |
//! | 4 | wisps |
//! | 4 | points per wisp (its three guides') |
//! | 4 | CRC-32 of what follows |
//! | wisps x 2 x points x 12 | each wisp's points now, then one step ago, as x, y, z `f32` |

use std::hash::Hasher;

use glam::Vec3;
use sim::WispState;

use crate::Scene;

/// The first bytes of a cache file.
const MAGIC: &[u8; 8] = b"WLSIMCAC";
/// The layout above.
const FORMAT: u32 = 1;
/// The writing program's version: a cache from another is refused (its
/// steps may differ).
const VERSION: &str = env!("CARGO_PKG_VERSION");

/// A cache file that cannot be used, and why.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum CacheError {
    /// Not a cache file, or cut short, or its bytes changed.
    #[error("not a whole wisplight simulation cache file: {0}")]
    Corrupt(String),
    /// Written by another version or format.
    #[error("written by wisplight {found}, not this {VERSION}: simulate again")]
    Version {
        /// The writer's version (and format).
        found: String,
    },
    /// Written for another scene.
    #[error(
        "written for another scene (hash {found:016x}, this scene's {expected:016x}; \
         flags such as --no-shadow and --method count): simulate this scene again"
    )]
    Scene {
        /// The file's scene hash.
        found: u64,
        /// This scene's.
        expected: u64,
    },
    /// Holds another frame than its name says.
    #[error("holds frame {found}, not frame {expected}")]
    Frame {
        /// The frame it holds.
        found: u64,
        /// The frame asked for.
        expected: u64,
    },
    /// Holds another number of wisps or points.
    #[error("holds {found}, the scene has {expected}")]
    Shape {
        /// What it holds.
        found: String,
        /// What the scene has.
        expected: String,
    },
}

/// A hash of everything in `scene` that the simulation's steps depend on:
/// all of it but the camera, the shading and where the scene was read
/// from (the text's comments and layout do not count; the groom files it
/// names do, byte for byte). FNV-1a, 64 bits, over the settings as written
/// by `Debug` and the files' bytes: the same on every machine.
pub fn scene_hash(scene: &Scene) -> u64 {
    let mut h = fnv::FnvHasher::default();
    let settings = format!(
        "{:?}{:?}",
        (
            &scene.hair,
            scene.subdivide,
            &scene.fiber,
            &scene.lights,
            &scene.shadow,
            &scene.render,
            &scene.head,
            &scene.effects,
        ),
        (
            &scene.animation.motion,
            scene.animation.fps,
            &scene.dynamics,
            &scene.collision,
            &scene.bodies,
        )
    );
    h.write(settings.as_bytes());
    for (path, bytes) in &scene.source.files {
        h.write(path.to_string_lossy().as_bytes());
        h.write_u64(bytes.len() as u64);
        h.write(bytes);
    }
    h.finish()
}

/// The file name of frame `frame` in a cache folder.
pub fn file_name(frame: u64) -> String {
    format!("frame_{frame:06}.wlsim")
}

/// Frame `frame`'s file: `states` (each wisp's, all of one size) of a
/// scene with hash `scene`.
pub fn encode(scene: u64, frame: u64, states: &[WispState]) -> Vec<u8> {
    let per = states.first().map_or(0, |s| s.pos.len());
    let mut payload = Vec::with_capacity(states.len() * per * 24);
    for s in states {
        debug_assert!(s.pos.len() == per && s.prev.len() == per);
        for p in s.pos.iter().chain(&s.prev) {
            for c in p.to_array() {
                payload.extend_from_slice(&c.to_le_bytes());
            }
        }
    }
    let mut out = Vec::with_capacity(payload.len() + 64);
    out.extend_from_slice(MAGIC);
    out.extend_from_slice(&FORMAT.to_le_bytes());
    out.extend_from_slice(&(VERSION.len() as u16).to_le_bytes());
    out.extend_from_slice(VERSION.as_bytes());
    out.extend_from_slice(&scene.to_le_bytes());
    out.extend_from_slice(&frame.to_le_bytes());
    out.extend_from_slice(&(states.len() as u32).to_le_bytes());
    out.extend_from_slice(&(per as u32).to_le_bytes());
    out.extend_from_slice(&crc32fast::hash(&payload).to_le_bytes());
    out.extend_from_slice(&payload);
    out
}

/// Reads `n` bytes at a time from a file's bytes.
struct Reader<'a>(&'a [u8]);

impl<'a> Reader<'a> {
    fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8], CacheError> {
        if self.0.len() < n {
            return Err(CacheError::Corrupt(format!("cut short in its {what}")));
        }
        let (head, rest) = self.0.split_at(n);
        self.0 = rest;
        Ok(head)
    }

    fn u16(&mut self, what: &str) -> Result<u16, CacheError> {
        Ok(u16::from_le_bytes(
            self.take(2, what)?.try_into().expect("2 bytes"),
        ))
    }

    fn u32(&mut self, what: &str) -> Result<u32, CacheError> {
        Ok(u32::from_le_bytes(
            self.take(4, what)?.try_into().expect("4 bytes"),
        ))
    }

    fn u64(&mut self, what: &str) -> Result<u64, CacheError> {
        Ok(u64::from_le_bytes(
            self.take(8, what)?.try_into().expect("8 bytes"),
        ))
    }
}

/// Frame `frame`'s wisp states from its file's `bytes`, checked against a
/// scene with hash `scene` of `wisps` wisps of `per` points each (before
/// anything is allocated): the magic, the version, the scene, the frame,
/// the shape, the checksum, the length and finite points.
pub fn decode(
    bytes: &[u8],
    scene: u64,
    frame: u64,
    wisps: usize,
    per: usize,
) -> Result<Vec<WispState>, CacheError> {
    let mut r = Reader(bytes);
    if r.0.len() < MAGIC.len() || &r.0[..MAGIC.len()] != MAGIC {
        return Err(CacheError::Corrupt(
            "it does not begin as a cache file does".into(),
        ));
    }
    r.take(MAGIC.len(), "magic")?;
    let format = r.u32("header")?;
    let len = r.u16("header")? as usize;
    let version = String::from_utf8_lossy(r.take(len, "header")?).into_owned();
    if format != FORMAT || version != VERSION {
        return Err(CacheError::Version {
            found: format!("{version} (format {format})"),
        });
    }
    let found = r.u64("header")?;
    if found != scene {
        return Err(CacheError::Scene {
            found,
            expected: scene,
        });
    }
    let found = r.u64("header")?;
    if found != frame {
        return Err(CacheError::Frame {
            found,
            expected: frame,
        });
    }
    let (n, p) = (r.u32("header")? as usize, r.u32("header")? as usize);
    if (n, p) != (wisps, per) {
        return Err(CacheError::Shape {
            found: format!("{n} wisps of {p} points"),
            expected: format!("{wisps} wisps of {per} points"),
        });
    }
    let crc = r.u32("header")?;
    let size = wisps * per * 24;
    if r.0.len() != size {
        return Err(CacheError::Corrupt(format!(
            "{} bytes of points where {wisps} wisps of {per} points take {size}",
            r.0.len()
        )));
    }
    if crc32fast::hash(r.0) != crc {
        return Err(CacheError::Corrupt("its checksum does not match".into()));
    }
    let mut points = r.0.chunks_exact(12).map(|c| {
        let f = |i: usize| f32::from_le_bytes(c[i..i + 4].try_into().expect("4 bytes"));
        Vec3::new(f(0), f(4), f(8))
    });
    let mut states = Vec::with_capacity(wisps);
    for w in 0..wisps {
        let pos: Vec<Vec3> = points.by_ref().take(per).collect();
        let prev: Vec<Vec3> = points.by_ref().take(per).collect();
        if !pos.iter().chain(&prev).all(|p| p.is_finite()) {
            return Err(CacheError::Corrupt(format!("wisp {w} is not finite")));
        }
        states.push(WispState { pos, prev });
    }
    Ok(states)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn states() -> Vec<WispState> {
        (0..3)
            .map(|w| WispState {
                pos: (0..6)
                    .map(|i| Vec3::splat((w * 10 + i) as f32 + 0.25))
                    .collect(),
                prev: (0..6)
                    .map(|i| Vec3::new(-(i as f32), w as f32, 1e-7))
                    .collect(),
            })
            .collect()
    }

    #[test]
    fn a_frame_reads_back_as_written() {
        let s = states();
        let bytes = encode(7, 42, &s);
        assert_eq!(decode(&bytes, 7, 42, 3, 6).unwrap(), s);
    }

    #[test]
    fn every_kind_of_wrong_file_is_named() {
        let bytes = encode(7, 42, &states());
        let err =
            |b: &[u8], scene, frame, wisps, per| decode(b, scene, frame, wisps, per).unwrap_err();
        assert!(matches!(
            err(&bytes, 8, 42, 3, 6),
            CacheError::Scene {
                found: 7,
                expected: 8
            }
        ));
        assert!(matches!(
            err(&bytes, 7, 41, 3, 6),
            CacheError::Frame {
                found: 42,
                expected: 41
            }
        ));
        assert!(matches!(err(&bytes, 7, 42, 4, 6), CacheError::Shape { .. }));
        assert!(matches!(
            err(b"PNG....", 7, 42, 3, 6),
            CacheError::Corrupt(_)
        ));
        // Cut anywhere: in the header or in the points.
        for cut in [3, 12, 20, 40, bytes.len() - 1] {
            assert!(
                matches!(err(&bytes[..cut], 7, 42, 3, 6), CacheError::Corrupt(_)),
                "{cut}"
            );
        }
        // A flipped bit in the points.
        let mut flipped = bytes.clone();
        *flipped.last_mut().unwrap() ^= 1;
        assert!(matches!(err(&flipped, 7, 42, 3, 6), CacheError::Corrupt(_)));
        // Another version.
        let mut other = bytes.clone();
        other[14] ^= 0x20;
        assert!(matches!(
            err(&other, 7, 42, 3, 6),
            CacheError::Version { .. }
        ));
    }
}
