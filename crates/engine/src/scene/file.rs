//! Reading a scene file, and saying what a file given as a scene is when
//! it is not one (a mesh, a cache, a picture), before its
//! bytes are read as TOML.

use std::path::Path;

use super::{MAX_SCENE_BYTES, SceneError};

/// What a file given as a scene is, by its extension, when that is
/// surely not a scene: the message that says so and what to do.
fn not_a_scene(path: &Path) -> Option<String> {
    let ext = path.extension()?.to_str()?.to_ascii_lowercase();
    let what = match ext.as_str() {
        "obj" | "stl" | "fbx" | "gltf" | "glb" => {
            "a mesh, not a scene: a head mesh is named in a scene, [head] mesh = \"FILE\" \
             (OBJ or PLY)"
        }
        "wlsim" => "a simulation cache file: give its folder to render --cache",
        "png" | "gif" | "exr" | "jpg" | "jpeg" => "a picture, not a scene (TOML)",
        _ => return None,
    };
    Some(what.to_string())
}

/// The text of the scene file at `path`: refused before it is read when its
/// extension says it is something else, when it is larger than a scene
/// may be, or when it is not text.
pub(super) fn read_text(path: &Path) -> Result<String, SceneError> {
    let parse = |message: String| SceneError::Parse {
        path: path.to_owned(),
        message,
    };
    if let Some(message) = not_a_scene(path) {
        return Err(parse(message));
    }
    let bytes = strands::read_capped(path, MAX_SCENE_BYTES as u64).map_err(|cause| {
        if cause.kind() == std::io::ErrorKind::FileTooLarge {
            parse(format!(
                "{cause}: a scene file is text of at most 16 MiB (strands go in a groom file, \
                 hair.file)"
            ))
        } else {
            SceneError::Io {
                path: path.to_owned(),
                cause,
            }
        }
    })?;
    String::from_utf8(bytes).map_err(|e| {
        parse(format!(
            "not text (byte {} is not UTF-8): a scene is a TOML file; a groom file is rendered \
             by its extension (.hair, .tfx, .data, .bin, .ply, .abc, .usd, .usda, .usdc or .usdz)",
            e.utf8_error().valid_up_to()
        ))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn files_that_are_not_scenes_are_named_by_what_they_are() {
        for (name, says) in [
            ("head.obj", "a mesh"),
            ("frame_000001.wlsim", "simulation cache"),
            ("out.png", "a picture"),
        ] {
            let m = not_a_scene(Path::new(name)).unwrap_or_default();
            assert!(m.contains(says), "{name}: {m}");
        }
        for name in ["scene.toml", "scene", "hair.txt"] {
            assert_eq!(not_a_scene(Path::new(name)), None, "{name}");
        }
    }
}
