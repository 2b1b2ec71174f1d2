//! Scene files: TOML with documented defaults; unknown keys are refused.
//!
//! ```toml
//! [hair]
//! style = "smooth"          # or "curly"; or file = "groom.tfx" (.hair, .tfx, .data, .bin, .ply, .abc, .usd, .usda, .usdc or .usdz, relative to the scene);
//! sample = 0                # files: the sample of an animated Alembic or USD groom (0 the first)
//!                           # or strands = [[[x, y, z], ...], ...] written out in the scene
//! seed = 1                  # procedural styles
//! strands_per_wisp = 25     # procedural styles: 134 wisps of this many drawn strands
//! parting = false           # procedural styles: a middle parting, front hair swept off the face, a fringe
//! color = [0.16, 0.075, 0.03] # procedural styles: linear RGB, each strand within 20 % (default dark brown; curly auburn)
//! subdivide = 2             # Catmull-Rom pieces per input segment
//! followers = 15            # files: follow strands grown per file strand (default 15 for .tfx, 0 for .hair)
//! follow_radius = 0.4       # files: root disc radius of follow strands, scene units (x the groom's unit)
//! tip_spread = 1.5          # files: follow offset at the tip / at the root
//! scale = 1.0               # files and strands: p' = translate + R_z R_y R_x (scale p)
//! rotate_deg = [0, 0, 0]    # files and strands: degrees about x, then y, then z
//! translate = [0, 0, 0]     # files and strands: scene units
//!
//! [fiber]
//! width = 0.1               # effective width w of one drawn strand, scene units; for a groom
//!                           # from a file, x its unit: 10 for one 100 to 1000 across (mm), 0.01 (m) ...
//! opacity = 0.5             # alpha in [0, 1]
//!
//! [light]                   # or several [[light]] tables
//! direction = [0.9, -0.35, -0.25]  # the direction light travels (from the left, above, front)
//!
//! [shadow]
//! method = "density-map"
//! cells = 128               # map cells a side, 1..=512
//! filter = true             # trilinear filtering of transmittance
//!
//! [camera]                  # view = "auto" (front; three quarters for hair seen edge-on), "front",
//!                           # "three-quarter-left", "three-quarter-right", "left", "right";
//!                           # or position, look_at; fov_deg = 30, up
//! [head]                    # visible, center, radius, color; mesh = "head.obj" or .ply, mesh_scale, mesh_offset
//!                           # (a mesh alone: center and radius fitted to its crown)
//! [effects]                 # dynamics, self_collision, body_collision, self_shadow, specular, head_shadow,
//!                           # multiple_scattering (off; with model = "marschner" and self_shadow),
//!                           # head_bounce (with multiple_scattering: the head's reflected light)
//! [animation]               # motion = "still" | "dance" | "keyframes" ([[animation.key]]), fps = 30
//! [dynamics]                # time_step, gravity, damping, stiffness, iterations, settle
//! [collision]               # density, repulsion, max_acceleration (self-collisions)
//! [[body]]                  # center, radius, follows_head (collision spheres)
//! ```
//!
//! docs/scene.md lists every key with its default and unit.

mod file;
mod hair;
mod lights;
mod motion;
mod raw;
mod shading;
mod shadow_settings;
mod toml_error;
mod view;

use hair::{Grown, groom_fiber_width};
use raw::*;
use toml_error::{field_at, one_line};

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use glam::Vec3;
use shadow::{Fiber, Light, MethodConfig};
use strands::{FollowParams, Hair, StyleParams};

pub use motion::{Animation, BodySettings, Collision, Dynamics, Effects};
pub use view::{CameraSettings, CameraView, RenderSettings, view_direction};

/// A scene that could not be read, naming the file and the field.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    /// The scene file cannot be read.
    #[error("cannot read scene {}: {cause}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// Why.
        cause: std::io::Error,
    },
    /// The text is not TOML, or has a key wisplight does not know.
    #[error("{}: {message}", path.display())]
    Parse {
        /// The file.
        path: PathBuf,
        /// The parser's message, with the line.
        message: String,
    },
    /// A value out of range.
    #[error("{}: {field} = {value}: {reason}", path.display())]
    Invalid {
        /// The file.
        path: PathBuf,
        /// The key, as `table.key`.
        field: &'static str,
        /// Its value.
        value: String,
        /// The range it must be in.
        reason: String,
    },
}

/// Where the hair comes from.
#[derive(Debug, Clone, PartialEq)]
pub enum HairSource {
    /// A generated style.
    Style(StyleParams),
    /// A groom file.
    File {
        /// The file, relative to the scene's.
        path: PathBuf,
        /// The sample of an animated Alembic or USD file read for every
        /// frame (`hair.sample`, 0 the first); `None`: frame `k` reads
        /// sample `k` (the last past the last), the first of a still file.
        sample: Option<u32>,
        /// Follow strands grown around its strands, when asked.
        follow: Option<FollowParams>,
        /// Where the groom goes in the scene (`hair.scale`,
        /// `hair.rotate_deg`, `hair.translate`), before follow strands grow.
        place: Placement,
    },
    /// Strands written out in the scene (`hair.strands`): small test
    /// cases and bug reports that need no other file.
    Inline(Hair),
}

/// How a groom read from a file (or written out in the scene) is placed
/// in the scene: scaled by `scale` about the origin, then turned by
/// `rotate_deg` (degrees about x, then y, then z, fixed axes), then moved
/// by `translate` (scene units):
///
/// ```text
/// p' = translate + R_z R_y R_x (scale p)
/// ```
///
/// For a groom in millimetres, `scale = 0.1` gives centimetres, the
/// built-in styles' unit; for one whose up axis is +z, `rotate_deg =
/// [-90, 0, 0]` stands it up along +y.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Placement {
    /// Uniform scale.
    pub scale: f32,
    /// Rotation about x, then y, then z, degrees.
    pub rotate_deg: Vec3,
    /// Movement after scaling and rotating, scene units.
    pub translate: Vec3,
}

impl Placement {
    /// Where the file puts it.
    pub const IDENTITY: Placement = Placement {
        scale: 1.0,
        rotate_deg: Vec3::ZERO,
        translate: Vec3::ZERO,
    };

    /// The transform `p -> p'` above.
    pub fn affine(&self) -> glam::Affine3A {
        let r = self.rotate_deg * (std::f32::consts::PI / 180.0);
        let rotation = glam::Quat::from_euler(glam::EulerRot::ZYX, r.z, r.y, r.x);
        glam::Affine3A::from_scale_rotation_translation(
            Vec3::splat(self.scale),
            rotation,
            self.translate,
        )
    }

    /// Places every point of `hair` (nothing to do for the identity).
    pub fn apply(&self, hair: &mut Hair) {
        if *self != Placement::IDENTITY {
            let a = self.affine();
            hair.points_mut()
                .iter_mut()
                .for_each(|p| *p = a.transform_point3(*p));
        }
    }
}

/// At most this many points written out in `hair.strands`.
pub(crate) const MAX_INLINE_POINTS: usize = 100_000;

/// The largest scene text (16 MiB): checked before it is parsed.
pub(crate) const MAX_SCENE_BYTES: usize = 16 << 20;

/// The most lights a scene may have: each fills and sweeps a map of its own.
pub(crate) const MAX_LIGHTS: usize = 16;

/// The most bodies a scene may have: each is tested at every guide point
/// of every time step.
pub(crate) const MAX_BODIES: usize = 256;

/// The most density-map cells of all the lights' maps together (about
/// 1 GB of quanta): 512^3 for two lights, 256^3 for sixteen.
pub(crate) const MAX_MAP_CELLS: u64 = 1 << 28;

/// The most keyframes of a keyframed motion.
pub(crate) const MAX_KEYFRAMES: usize = 10_000;

/// The shadow method and its settings (see [`MethodConfig`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShadowSettings {
    /// The method.
    pub method: MethodConfig,
}

impl ShadowSettings {
    /// The method's resolution: cells (or light-view pixels) a side.
    pub fn cells(&self) -> u32 {
        self.method.resolution()
    }

    /// Sets the method's resolution (the reference has none).
    pub fn set_cells(&mut self, n: u32) {
        self.method.set_resolution(n);
    }

    /// Switches to method `name` with its default settings, keeping the
    /// resolution and the filter switch. `None` for an unknown name.
    pub fn switch_to(&self, name: &str) -> Option<ShadowSettings> {
        let mut m = MethodConfig::with_defaults(name, self.cells())?;
        m.set_trilinear(self.method.trilinear());
        Some(ShadowSettings { method: m })
    }
}

/// The head: an opaque sphere, or a triangle mesh, that receives the
/// hair's shadow and blocks light for the hair behind it (with
/// `effects.head_shadow`). Hair collides with the sphere (with
/// `effects.body_collision`), mesh or not. It moves with the scene's
/// motion, turning about its centre.
#[derive(Debug, Clone, PartialEq)]
pub struct HeadSettings {
    /// The sphere's centre, scene units.
    pub center: Vec3,
    /// The sphere's radius, scene units.
    pub radius: f32,
    /// Linear RGB.
    pub color: Vec3,
    /// Drawn and casting shadow instead of the sphere.
    pub mesh: Option<HeadMesh>,
}

/// A head mesh: an OBJ file whose vertex `v` stands at `offset + scale * v`
/// (scene units) before the head moves.
#[derive(Debug, Clone, PartialEq)]
pub struct HeadMesh {
    /// The OBJ or PLY file, relative to the scene's.
    pub path: PathBuf,
    /// Scale of its vertices.
    pub scale: f32,
    /// Where its origin goes, scene units.
    pub offset: Vec3,
}

/// What a scene was made from: its TOML text, the path it came from
/// (relative paths in it are relative to that), and the bytes of the data
/// files it names once they are read (see [`Scene::read_data_files`]):
/// everything another process needs to make the same scene.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct SceneSource {
    /// The TOML text.
    pub text: Arc<str>,
    /// Where it was read from (empty for the built-in scene).
    pub path: PathBuf,
    /// Data files by the path the scene names them by.
    pub files: BTreeMap<PathBuf, Arc<[u8]>>,
}

/// A validated scene.
#[derive(Debug, Clone, PartialEq)]
pub struct Scene {
    /// What it was made from.
    pub source: SceneSource,
    /// `[hair]`: where the hair comes from.
    pub hair: HairSource,
    /// Drawn segments per control segment (Catmull-Rom).
    pub subdivide: u32,
    /// Width and opacity of every fiber.
    pub fiber: Fiber,
    /// `[light]` or `[[lights]]`.
    pub lights: Vec<Light>,
    /// `[shadow]`: the method and its settings.
    pub shadow: ShadowSettings,
    /// `[camera]`.
    pub camera: CameraSettings,
    /// `[render]`: image size, background, hair look.
    pub render: RenderSettings,
    /// `[head]`, when the scene has one.
    pub head: Option<HeadSettings>,
    /// `[shading]`.
    pub shading: raster::Shading,
    /// `[effects]`: which stages run.
    pub effects: Effects,
    /// `[animation]`.
    pub animation: Animation,
    /// `[dynamics]`.
    pub dynamics: Dynamics,
    /// `[collision]`.
    pub collision: Collision,
    /// `[[body]]`: spheres hair collides with.
    pub bodies: Vec<BodySettings>,
}

/// Defaults, documented in the module comment and docs/scene.md.
pub(crate) const DEFAULT_LIGHT_DIRECTION: [f32; 3] = [0.9, -0.35, -0.25];
/// A spot light's cone and soft edge, degrees.
pub(crate) const DEFAULT_CONE_DEG: f32 = 30.0;
pub(crate) const DEFAULT_FALLOFF_DEG: f32 = 5.0;
/// The styles' fiber width (the paper's look), scene units (cm).
pub(crate) const DEFAULT_FIBER_WIDTH: f32 = 0.1;
pub(crate) const DEFAULT_FOLLOW_RADIUS: f32 = 0.4;
pub(crate) const DEFAULT_FIBER_OPACITY: f32 = 0.5;
pub(crate) const DEFAULT_CELLS: u32 = 128;
pub(crate) const DEFAULT_SUBDIVIDE: u32 = 2;
pub(crate) const DEFAULT_TFX_FOLLOWERS: u32 = 15;
pub(crate) const DEFAULT_WIDTH: u32 = 1280;
pub(crate) const DEFAULT_HEIGHT: u32 = 720;
pub(crate) const DEFAULT_FOV_DEG: f32 = 30.0;
pub(crate) const DEFAULT_BACKGROUND: [f32; 3] = [0.02, 0.025, 0.035];
pub(crate) const DEFAULT_HAIR_ALPHA: f32 = 0.85;
/// Fragments a pixel composites front to back (see `raster::Canvas::set_nearest`).
pub(crate) const DEFAULT_NEAREST: u32 = 4;
pub(crate) const DEFAULT_HEAD_COLOR: [f32; 3] = [0.55, 0.38, 0.3];

/// The built-in scene: the smooth style with a middle parting and a fringe
/// on a head with a face ([`BUILT_IN_HEAD`]), dancing, seen from three
/// quarters on the lit side; every other key at its default.
pub(crate) const BUILT_IN_SCENE: &str = "[hair]\nstyle = \"smooth\"\nparting = true\n\n\
[head]\nmesh = \"head.obj\"\n\n\
[animation]\nmotion = \"dance\"\n\n\
[camera]\nview = \"three-quarter-left\"\n";

/// The built-in scene's head mesh, `head.obj` in it: `scenes/head.obj`,
/// made by `scenes/make_head.py` (the styles' sphere of radius 10 above the
/// middle, a jaw, a nose and a neck below).
pub(crate) const BUILT_IN_HEAD: &[u8] = include_bytes!("../../../scenes/head.obj");

impl Default for Scene {
    /// The built-in scene (`BUILT_IN_SCENE`), its head mesh held in its
    /// files: nothing to read from disk.
    fn default() -> Scene {
        let files = BTreeMap::from([(PathBuf::from("head.obj"), Arc::from(BUILT_IN_HEAD))]);
        Scene::parse(BUILT_IN_SCENE, Path::new("<built-in>"), files)
            .expect("the built-in scene is valid")
    }
}

impl Scene {
    /// Reads and validates a scene file; relative paths inside it are
    /// relative to the file.
    pub fn load(path: &Path) -> Result<Scene, SceneError> {
        if strands::is_groom_path(path) {
            return Scene::for_groom(path);
        }
        let text = file::read_text(path)?;
        Scene::from_toml_str(&text, path)
    }

    /// The scene of one groom file at its defaults: `[hair] file = PATH`
    /// and nothing else (the camera framed on the hair, the file's own
    /// defaults for followers and width; no head unless the scene gives
    /// one). A scene file is needed only for more.
    pub fn for_groom(path: &Path) -> Result<Scene, SceneError> {
        let name = path.file_name().ok_or_else(|| SceneError::Parse {
            path: path.to_owned(),
            message: "not a file name".into(),
        })?;
        let text = format!(
            "[hair]\nfile = {}\n",
            toml::Value::String(name.to_string_lossy().into_owned())
        );
        Scene::from_toml_str(&text, path)
    }

    /// Parses scene text; `path` names it in errors and anchors relative paths.
    pub fn from_toml_str(text: &str, path: &Path) -> Result<Scene, SceneError> {
        Scene::parse(text, path, BTreeMap::new())
    }

    /// [`Self::from_toml_str`] with the data files already read (what a
    /// head mesh given alone is fitted from; the others' are read from
    /// disk).
    fn parse(
        text: &str,
        path: &Path,
        files: BTreeMap<PathBuf, Arc<[u8]>>,
    ) -> Result<Scene, SceneError> {
        if text.len() > MAX_SCENE_BYTES {
            return Err(SceneError::Parse {
                path: path.to_owned(),
                message: format!("a scene of {} bytes: at most {MAX_SCENE_BYTES}", text.len()),
            });
        }
        let raw: RawScene = toml::from_str(text).map_err(|e| SceneError::Parse {
            path: path.to_owned(),
            message: match e
                .span()
                .and_then(|s| Some((field_at(text, s.start)?, s.start)))
            {
                Some((field, at)) => {
                    let before = &text[..at.min(text.len())];
                    let line = before.matches('\n').count() + 1;
                    let column = before.len() - before.rfind('\n').map_or(0, |i| i + 1) + 1;
                    format!(
                        "{field}: {} (line {line}, column {column})",
                        one_line(e.message())
                    )
                }
                None => one_line(&e.to_string()),
            },
        })?;
        let mut scene = Validator {
            path,
            files: &files,
        }
        .scene(raw)?;
        scene.source = SceneSource {
            text: text.into(),
            path: path.to_owned(),
            files,
        };
        Ok(scene)
    }

    /// The data files the scene names: the groom file and the head mesh.
    pub fn data_paths(&self) -> Vec<&Path> {
        let hair = match &self.hair {
            HairSource::File { path, .. } => Some(path.as_path()),
            _ => None,
        };
        let mesh = self
            .head
            .as_ref()
            .and_then(|h| h.mesh.as_ref())
            .map(|m| m.path.as_path());
        hair.into_iter().chain(mesh).collect()
    }

    /// Reads every data file the scene names into [`Scene::source`], so
    /// that the scene can be made again elsewhere without them.
    pub fn read_data_files(&mut self) -> Result<(), SceneError> {
        let paths: Vec<PathBuf> = self.data_paths().into_iter().map(Path::to_owned).collect();
        for p in paths {
            if self.source.files.contains_key(&p) {
                continue;
            }
            let bytes = strands::read_capped(&p, strands::MAX_FILE_BYTES).map_err(|cause| {
                SceneError::Io {
                    path: p.clone(),
                    cause,
                }
            })?;
            self.source.files.insert(p, bytes.into());
        }
        Ok(())
    }

    /// The bytes of data file `path`: those read into the scene's source,
    /// else the file's.
    pub fn data_file(&self, path: &Path) -> std::io::Result<std::borrow::Cow<'_, [u8]>> {
        match self.source.files.get(path) {
            Some(b) => Ok(std::borrow::Cow::Borrowed(b)),
            None => {
                strands::read_capped(path, strands::MAX_FILE_BYTES).map(std::borrow::Cow::Owned)
            }
        }
    }

    /// The scene `source` describes, with its data files as read there.
    pub fn from_source(source: &SceneSource) -> Result<Scene, SceneError> {
        Scene::parse(&source.text, &source.path, source.files.clone())
    }
}

struct Validator<'a> {
    path: &'a Path,
    /// Data files already read, by the path the scene names them by.
    files: &'a BTreeMap<PathBuf, Arc<[u8]>>,
}

impl Validator<'_> {
    /// The collision sphere of a head mesh given without one: fitted to
    /// its crown ([`strands::Mesh::crown_sphere`]), as the mesh is placed.
    fn fitted_sphere(&self, m: &HeadMesh) -> Result<(Vec3, f32), SceneError> {
        let fail = |reason: String| self.invalid("head.mesh", m.path.display(), reason);
        let parse = strands::mesh_parser(&m.path).map_err(|e| fail(e.to_string()))?;
        let bytes = match self.files.get(&m.path) {
            Some(b) => std::borrow::Cow::Borrowed(&b[..]),
            None => std::borrow::Cow::Owned(
                strands::read_capped(&m.path, strands::MAX_FILE_BYTES)
                    .map_err(|e| fail(format!("cannot read it: {e}")))?,
            ),
        };
        let mesh = parse(&bytes).map_err(|e| fail(e.to_string()))?;
        let (c, r) = mesh.crown_sphere().ok_or_else(|| {
            fail(
                "a single point: no collision sphere fits it (give head.center and head.radius)"
                    .into(),
            )
        })?;
        Ok((m.offset + m.scale * c, m.scale * r))
    }

    fn invalid(
        &self,
        field: &'static str,
        value: impl std::fmt::Display,
        reason: impl Into<String>,
    ) -> SceneError {
        SceneError::Invalid {
            path: self.path.to_owned(),
            field,
            value: value.to_string(),
            reason: reason.into(),
        }
    }

    fn int(
        &self,
        field: &'static str,
        v: Option<i64>,
        default: u32,
        range: std::ops::RangeInclusive<u32>,
    ) -> Result<u32, SceneError> {
        let Some(v) = v else { return Ok(default) };
        u32::try_from(v)
            .ok()
            .filter(|v| range.contains(v))
            .ok_or_else(|| {
                self.invalid(
                    field,
                    v,
                    format!(
                        "must be a whole number in {}..={}",
                        range.start(),
                        range.end()
                    ),
                )
            })
    }

    /// A file named in the scene: relative paths are relative to the
    /// scene file's folder.
    fn relative(&self, file: &Path) -> PathBuf {
        match self.path.parent() {
            Some(dir) if file.is_relative() => dir.join(file),
            _ => file.to_owned(),
        }
    }

    fn positive(
        &self,
        field: &'static str,
        v: Option<f32>,
        default: f32,
    ) -> Result<f32, SceneError> {
        let v = v.unwrap_or(default);
        if v.is_finite() && v >= 0.0 {
            Ok(v)
        } else {
            Err(self.invalid(field, v, "must be a finite number > 0"))
        }
    }

    /// An error for the first of `fields` that the scene set, saying `why`.
    fn refuse_set(&self, fields: &[(&'static str, bool)], why: &str) -> Result<(), SceneError> {
        match fields.iter().find(|(_, set)| *set) {
            Some((field, _)) => Err(self.invalid(field, "(set)", why)),
            None => Ok(()),
        }
    }

    fn scene(&self, raw: RawScene) -> Result<Scene, SceneError> {
        let Grown {
            hair,
            subdivide,
            scale_width,
            scale_follow,
        } = self.hair(&raw.hair, raw.fiber.width.is_none())?;

        let width = raw.fiber.width.unwrap_or(DEFAULT_FIBER_WIDTH);
        let opacity = raw.fiber.opacity.unwrap_or(DEFAULT_FIBER_OPACITY);
        let fiber = Fiber::new(width, opacity).map_err(|e| match e {
            shadow::ShadowError::FiberWidth(v) => {
                self.invalid("fiber.width", v, "must be a finite number > 0")
            }
            _ => self.invalid("fiber.opacity", opacity, "must be in [0, 1]"),
        })?;

        let raw_lights = match raw.light {
            None => vec![RawLight {
                direction: Some(DEFAULT_LIGHT_DIRECTION),
                position: None,
                cone_deg: None,
                falloff_deg: None,
                intensity: None,
            }],
            Some(OneOrMany::One(l)) => vec![l],
            Some(OneOrMany::Many(ls)) => ls,
        };
        if raw_lights.is_empty() {
            return Err(self.invalid("light", "[]", "needs at least one light"));
        }
        if raw_lights.len() > MAX_LIGHTS {
            return Err(self.invalid(
                "light",
                format!("({} tables)", raw_lights.len()),
                format!("at most {MAX_LIGHTS} lights"),
            ));
        }
        let head_center = Vec3::from_array(raw.head.center.unwrap_or([0.0; 3]));
        let lights = raw_lights
            .iter()
            .map(|l| self.light(l, head_center))
            .collect::<Result<Vec<_>, _>>()?;

        let shadow = self.shadow(raw.shadow)?;
        let cells = u64::from(shadow.cells());
        if cells.pow(3) * lights.len() as u64 > MAX_MAP_CELLS {
            return Err(self.invalid(
                "shadow.cells",
                cells,
                format!(
                    "{} lights of {cells}^3 cells pass the {MAX_MAP_CELLS} map cells a scene \
                     may have: fewer cells or fewer lights",
                    lights.len()
                ),
            ));
        }
        let camera = self.camera(&raw.camera)?;
        let render = self.render(&raw.render)?;

        let hd = raw.head;
        let style_head = match &hair {
            HairSource::Style(p) => Some((p.head_center, p.head_radius)),
            HairSource::File { .. } | HairSource::Inline(_) => None,
        };
        let visible = hd.visible.unwrap_or(
            style_head.is_some() || hd.center.is_some() || hd.radius.is_some() || hd.mesh.is_some(),
        );
        let mut fit_head = false;
        let head = if visible {
            let mesh = match &hd.mesh {
                Some(file) => {
                    let scale = hd.mesh_scale.unwrap_or(1.0);
                    if !(scale.is_finite() && scale > 0.0) {
                        return Err(self.invalid(
                            "head.mesh_scale",
                            scale,
                            "must be a finite number > 0",
                        ));
                    }
                    Some(HeadMesh {
                        path: self.relative(file),
                        scale,
                        offset: self
                            .vec3("head.mesh_offset", hd.mesh_offset)?
                            .unwrap_or(Vec3::ZERO),
                    })
                }
                None => {
                    self.refuse_set(
                        &[
                            ("head.mesh_scale", hd.mesh_scale.is_some()),
                            ("head.mesh_offset", hd.mesh_offset.is_some()),
                        ],
                        "needs head.mesh",
                    )?;
                    None
                }
            };
            let center = self
                .vec3("head.center", hd.center)?
                .or(style_head.map(|h| h.0));
            let radius = hd.radius.or(style_head.map(|h| h.1));
            let (center, radius) = match (center, radius, &mesh) {
                (Some(c), Some(r), _) => (c, r),
                // A head mesh alone: the collision sphere fitted to it
                // once the rest is valid.
                (None, None, Some(_)) => {
                    fit_head = true;
                    (Vec3::ZERO, 1.0)
                }
                _ => {
                    return Err(self.invalid(
                        "head",
                        "(incomplete)",
                        "a head for hair from a file needs head.center and head.radius, or \
                         head.mesh alone",
                    ));
                }
            };
            if !(radius.is_finite() && radius > 0.0) {
                return Err(self.invalid("head.radius", radius, "must be a finite number > 0"));
            }
            Some(HeadSettings {
                center,
                radius,
                color: self.color("head.color", hd.color, DEFAULT_HEAD_COLOR)?,
                mesh,
            })
        } else {
            None
        };

        let d = raster::Shading::default();
        let sh = raw.shading;
        let shading = raster::Shading {
            ambient: self.positive("shading.ambient", sh.ambient, d.ambient)?,
            diffuse: self.positive("shading.diffuse", sh.diffuse, d.diffuse)?,
            specular: self.positive("shading.specular", sh.specular, d.specular)?,
            shininess: self.positive("shading.shininess", sh.shininess, d.shininess)?,
            specular_color: d.specular_color,
            model: self.shading_model(&sh)?,
        };
        let from_file = !matches!(hair, HairSource::Style(_));
        let animation = self.animation(raw.animation)?;
        let dynamics = self.dynamics(raw.dynamics)?;
        self.steps_in_bounds(&animation, &dynamics)?;
        let mut scene = Scene {
            source: SceneSource::default(),
            hair,
            subdivide,
            fiber,
            lights,
            shadow,
            camera,
            render,
            head,
            shading,
            effects: self.effects(raw.effects, from_file)?,
            animation,
            dynamics,
            collision: self.collision(raw.collision)?,
            bodies: self.bodies(raw.body)?,
        };
        if scene.effects.multiple_scattering {
            let why = if !matches!(scene.shading.model, raster::ShadingModel::Marschner { .. }) {
                Some("needs shading.model = \"marschner\" (Kajiya-Kay has no fiber to scatter)")
            } else if !scene.effects.self_shadow {
                Some("needs effects.self_shadow: it scatters the light the shadow takes")
            } else {
                None
            };
            if let Some(why) = why {
                return Err(self.invalid("effects.multiple_scattering", true, why));
            }
        }
        // What needs the data files read, now that the text is valid.
        if let HairSource::File {
            path,
            sample,
            follow,
            place,
        } = &mut scene.hair
            && (scale_width || scale_follow)
        {
            let (unit, files_strands, file_width) =
                self.groom_unit(path, sample.unwrap_or(0), place)?;
            if scale_follow && let Some(f) = follow {
                f.radius = DEFAULT_FOLLOW_RADIUS * unit;
            }
            if scale_width {
                let per = follow.as_ref().map_or(1, |f| u64::from(f.followers) + 1);
                // The file's own widths (Alembic, USD), placed, else one
                // from the groom's unit and strands.
                let width = match file_width {
                    Some(w) => w * place.scale,
                    None => groom_fiber_width(unit, files_strands.saturating_mul(per)),
                };
                scene.fiber = Fiber::new(width, scene.fiber.opacity()).map_err(|_| {
                    self.invalid("fiber.width", width, "must be a finite number > 0")
                })?;
            }
        }
        if let Some(h) = scene.head.as_mut().filter(|_| fit_head) {
            let m = h.mesh.as_ref().expect("fitted heads have a mesh");
            (h.center, h.radius) = self.fitted_sphere(m)?;
        }
        Ok(scene)
    }
}

#[cfg(test)]
mod tests;
