//! The scene's hair: generated from its style or loaded from its groom,
//! with follow strands when asked, resampled into drawn points, and its
//! size checked before anything is built.

use strands::{Hair, WispModel, grow_followers, resample};

use crate::{EngineError, HairSource, Scene};

/// The most drawn segments one scene may ask for (about 1.6 GB of points):
/// beyond this a typo in `strands_per_wisp` or `followers` is more likely
/// than a real groom.
pub const MAX_SEGMENTS: u64 = 100_000_000;

/// Builds the hair a scene describes: generated or loaded, with follow
/// strands when asked, then Catmull-Rom resampled into drawn points.
pub fn build_hair(scene: &Scene) -> Result<Hair, EngineError> {
    build_hair_at(scene, None).map(|(hair, _)| hair)
}

/// [`build_hair`] at `sample` of an animated groom file (`None`: the
/// scene's `hair.sample`, or the first; a sample given is a file read
/// before, its warnings not said again), and the samples its groom file
/// holds (1 for other hair).
pub(crate) fn build_hair_at(scene: &Scene, at: Option<u32>) -> Result<(Hair, u32), EngineError> {
    let mut samples = 1;
    let control = match &scene.hair {
        HairSource::Style(p) => {
            let segs = u64::from(p.wisps)
                * u64::from(p.strands_per_wisp)
                * 31
                * u64::from(scene.subdivide);
            check_size(segs)?;
            WispModel::generate(p).interpolate()
        }
        HairSource::File {
            path,
            sample,
            follow,
            place,
        } => {
            let mut guides = match at {
                Some(s) => load_groom_again(scene, path, s)?,
                None => {
                    let (guides, n) = load_groom(scene, path, sample.unwrap_or(0))?;
                    samples = n;
                    guides
                }
            };
            place.apply(&mut guides);
            match follow {
                Some(f) => {
                    check_size(
                        guides.segment_count() as u64
                            * (u64::from(f.followers) + 1)
                            * u64::from(scene.subdivide),
                    )?;
                    grow_followers(&guides, f)
                }
                None => guides,
            }
        }
        HairSource::Inline(hair) => hair.clone(),
    };
    check_size(control.segment_count() as u64 * u64::from(scene.subdivide))?;
    Ok((resample(&control, scene.subdivide), samples))
}

/// The groom `path` of `scene`'s `hair.file`, at `sample`, and the
/// samples the file holds; an error names both.
fn load_groom(
    scene: &Scene,
    path: &std::path::Path,
    sample: u32,
) -> Result<(Hair, u32), EngineError> {
    strands::load_with_samples(path, sample, |p| scene.data_file(p)).map_err(|error| {
        EngineError::Load {
            scene: scene.source.path.clone(),
            error,
        }
    })
}

/// [`load_groom`] of a file read before, at another sample.
fn load_groom_again(
    scene: &Scene,
    path: &std::path::Path,
    sample: u32,
) -> Result<Hair, EngineError> {
    let bytes = scene
        .data_file(path)
        .map_err(|cause| strands::LoadError::Io {
            path: path.to_owned(),
            cause,
        });
    bytes
        .and_then(|b| strands::load_bytes_again(path, &b, sample))
        .map_err(|error| EngineError::Load {
            scene: scene.source.path.clone(),
            error,
        })
}

/// The drawn segments [`build_hair`] makes of a scene's hair, counted
/// without making them (a loaded groom is loaded, not resampled). Checked
/// against [`MAX_SEGMENTS`].
pub fn drawn_segments(scene: &Scene) -> Result<u64, EngineError> {
    let sub = u64::from(scene.subdivide);
    let segs = match &scene.hair {
        HairSource::Style(p) => u64::from(p.wisps) * u64::from(p.strands_per_wisp) * 31 * sub,
        HairSource::File {
            path,
            sample,
            follow,
            ..
        } => {
            // Placing the groom changes no count.
            let (guides, _) = load_groom(scene, path, sample.unwrap_or(0))?;
            let per = follow.as_ref().map_or(1, |f| u64::from(f.followers) + 1);
            guides.segment_count() as u64 * per * sub
        }
        HairSource::Inline(hair) => hair.segment_count() as u64 * sub,
    };
    check_size(segs)?;
    Ok(segs)
}

fn check_size(segments: u64) -> Result<(), EngineError> {
    if segments > MAX_SEGMENTS {
        return Err(EngineError::TooLarge {
            what: format!("{segments} drawn segments"),
            bytes: segments * 16,
            limit: MAX_SEGMENTS * 16,
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn absurd_sizes_are_refused_before_building() {
        let mut scene = Scene::default();
        if let HairSource::Style(p) = &mut scene.hair {
            p.strands_per_wisp = 2000;
        }
        scene.subdivide = 64;
        assert!(matches!(
            build_hair(&scene),
            Err(EngineError::TooLarge { .. })
        ));
    }
}
