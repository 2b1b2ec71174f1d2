//! Scene files: TOML with documented defaults; unknown keys are refused.
//!
//! ```toml
//! [hair]
//! style = "smooth"          # or "curly"; or file = "groom.tfx" (.hair, .tfx, .data, .bin or .ply, relative to the scene);
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
//!                           # multiple_scattering (off; with model = "marschner" and self_shadow)
//! [animation]               # motion = "still" | "dance" | "keyframes" ([[animation.key]]), fps = 30
//! [dynamics]                # time_step, gravity, damping, stiffness, iterations, settle
//! [collision]               # density, repulsion, max_acceleration (self-collisions)
//! [[body]]                  # center, radius, follows_head (collision spheres)
//! ```
//!
//! docs/scene.md lists every key with its default and unit.

mod motion;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use glam::Vec3;
use serde::Deserialize;
use shadow::{Beyond, Fiber, Light, MethodConfig, OpacityMode};
use strands::{FollowParams, Hair, Style, StyleParams};

pub use motion::{
    Animation, BodySettings, Collision, DEFAULT_COLLISION_DENSITY, DEFAULT_FPS,
    DEFAULT_MAX_ACCELERATION, DEFAULT_REPULSION, DEFAULT_SETTLE_S, Dynamics, Effects,
};

/// A scene that could not be read, naming the file and the field.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    #[error("cannot read scene {}: {cause}", path.display())]
    Io {
        path: PathBuf,
        cause: std::io::Error,
    },
    #[error("{}: {message}", path.display())]
    Parse { path: PathBuf, message: String },
    #[error("{}: {field} = {value}: {reason}", path.display())]
    Invalid {
        path: PathBuf,
        field: &'static str,
        value: String,
        reason: String,
    },
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawScene {
    #[serde(default)]
    hair: RawHair,
    #[serde(default)]
    fiber: RawFiber,
    #[serde(default)]
    light: Option<OneOrMany<RawLight>>,
    #[serde(default)]
    shadow: RawShadow,
    #[serde(default)]
    camera: RawCamera,
    #[serde(default)]
    render: RawRender,
    #[serde(default)]
    head: RawHead,
    #[serde(default)]
    shading: RawShading,
    #[serde(default)]
    effects: motion::RawEffects,
    #[serde(default)]
    animation: motion::RawAnimation,
    #[serde(default)]
    dynamics: motion::RawDynamics,
    #[serde(default)]
    collision: motion::RawCollision,
    #[serde(default)]
    body: Option<Vec<motion::RawBody>>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawCamera {
    view: Option<String>,
    position: Option<[f32; 3]>,
    look_at: Option<[f32; 3]>,
    fov_deg: Option<f32>,
    up: Option<[f32; 3]>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawRender {
    width: Option<i64>,
    height: Option<i64>,
    background: Option<[f32; 3]>,
    hair_alpha: Option<f32>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawHead {
    visible: Option<bool>,
    center: Option<[f32; 3]>,
    radius: Option<f32>,
    color: Option<[f32; 3]>,
    mesh: Option<PathBuf>,
    mesh_scale: Option<f32>,
    mesh_offset: Option<[f32; 3]>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawShading {
    ambient: Option<f32>,
    diffuse: Option<f32>,
    specular: Option<f32>,
    shininess: Option<f32>,
    model: Option<String>,
    eumelanin: Option<f32>,
    pheomelanin: Option<f32>,
    sigma_a: Option<[f32; 3]>,
    eta: Option<f32>,
    beta_m: Option<f32>,
    beta_n: Option<f32>,
    alpha_deg: Option<f32>,
    irradiance: Option<f32>,
}

/// One table (`[light]`) or an array of them (`[[light]]`), told apart
/// by what TOML holds, so that an error inside either names its key (an
/// untagged enum would only say that neither matched).
#[derive(Debug)]
enum OneOrMany<T> {
    One(T),
    Many(Vec<T>),
}

impl<'de, T: Deserialize<'de>> Deserialize<'de> for OneOrMany<T> {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        use serde::de::value::{MapAccessDeserializer, SeqAccessDeserializer};
        struct Either<T>(std::marker::PhantomData<T>);
        impl<'de, T: Deserialize<'de>> serde::de::Visitor<'de> for Either<T> {
            type Value = OneOrMany<T>;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("a table or an array of tables")
            }
            fn visit_map<A: serde::de::MapAccess<'de>>(
                self,
                a: A,
            ) -> Result<Self::Value, A::Error> {
                T::deserialize(MapAccessDeserializer::new(a)).map(OneOrMany::One)
            }
            fn visit_seq<A: serde::de::SeqAccess<'de>>(
                self,
                a: A,
            ) -> Result<Self::Value, A::Error> {
                Vec::<T>::deserialize(SeqAccessDeserializer::new(a)).map(OneOrMany::Many)
            }
        }
        d.deserialize_any(Either(std::marker::PhantomData))
    }
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawHair {
    style: Option<String>,
    file: Option<PathBuf>,
    strands: Option<Vec<Vec<[f32; 3]>>>,
    seed: Option<u64>,
    strands_per_wisp: Option<i64>,
    parting: Option<bool>,
    color: Option<[f32; 3]>,
    subdivide: Option<i64>,
    followers: Option<i64>,
    follow_radius: Option<f32>,
    tip_spread: Option<f32>,
    scale: Option<f32>,
    rotate_deg: Option<[f32; 3]>,
    translate: Option<[f32; 3]>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawFiber {
    width: Option<f32>,
    opacity: Option<f32>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawLight {
    direction: Option<[f32; 3]>,
    position: Option<[f32; 3]>,
    cone_deg: Option<f32>,
    falloff_deg: Option<f32>,
    intensity: Option<f32>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawShadow {
    method: Option<String>,
    cells: Option<i64>,
    filter: Option<bool>,
    slices: Option<i64>,
    mode: Option<String>,
    kappa: Option<f32>,
    offset: Option<f32>,
    layers: Option<i64>,
    layer_cells: Option<f32>,
    beyond: Option<String>,
    clusters: Option<i64>,
    tolerance: Option<f32>,
    footprint: Option<f32>,
    rays: Option<i64>,
}

/// Where the hair comes from.
#[derive(Debug, Clone, PartialEq)]
pub enum HairSource {
    Style(StyleParams),
    File {
        path: PathBuf,
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
    pub scale: f32,
    pub rotate_deg: Vec3,
    pub translate: Vec3,
}

impl Placement {
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
pub const MAX_INLINE_POINTS: usize = 100_000;

/// The largest scene text (16 MiB): checked before it is parsed.
pub const MAX_SCENE_BYTES: usize = 16 << 20;

/// The most lights a scene may have: each fills and sweeps a map of its own.
pub const MAX_LIGHTS: usize = 16;

/// The most bodies a scene may have: each is tested at every guide point
/// of every time step.
pub const MAX_BODIES: usize = 256;

/// The most density-map cells of all the lights' maps together (about
/// 1 GB of quanta): 512^3 for two lights, 256^3 for sixteen.
pub const MAX_MAP_CELLS: u64 = 1 << 28;

/// The most keyframes of a keyframed motion.
pub const MAX_KEYFRAMES: usize = 10_000;

/// The shadow method and its settings (see [`MethodConfig`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShadowSettings {
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
        m.set_filter(self.method.filter());
        Some(ShadowSettings { method: m })
    }
}

/// Where the camera is; `None` fields are framed around the hair.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraSettings {
    /// Where the default camera looks from (`camera.view`), when no
    /// position is given.
    pub view: CameraView,
    pub position: Option<Vec3>,
    pub look_at: Option<Vec3>,
    pub fov_deg: f32,
    /// The picture's up direction (`camera.up`); +y when not given.
    pub up: Option<Vec3>,
}

/// Where the default camera looks from, towards the hair, slightly above.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum CameraView {
    /// The front (+z), or three quarters for hair seen edge-on from there
    /// (see [`crate::render::view_direction`]).
    #[default]
    Auto,
    Front,
    /// 45 degrees to the left of the front (-x, +z).
    ThreeQuarterLeft,
    /// 45 degrees to the right of the front (+x, +z).
    ThreeQuarterRight,
    /// The left side (-x).
    Left,
    /// The right side (+x).
    Right,
}

impl CameraView {
    pub const NAMES: [&str; 6] = [
        "auto",
        "front",
        "three-quarter-left",
        "three-quarter-right",
        "left",
        "right",
    ];

    pub fn from_name(name: &str) -> Option<CameraView> {
        Some(match name {
            "auto" => CameraView::Auto,
            "front" => CameraView::Front,
            "three-quarter-left" => CameraView::ThreeQuarterLeft,
            "three-quarter-right" => CameraView::ThreeQuarterRight,
            "left" => CameraView::Left,
            "right" => CameraView::Right,
            _ => return None,
        })
    }
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RenderSettings {
    pub width: u32,
    pub height: u32,
    /// Linear RGB.
    pub background: Vec3,
    /// Opacity of a drawn strand where it covers a whole pixel.
    pub hair_alpha: f32,
}

/// The head: an opaque sphere, or a triangle mesh, that receives the
/// hair's shadow and blocks light for the hair behind it (with
/// `effects.head_shadow`). Hair collides with the sphere (with
/// `effects.body_collision`), mesh or not. It moves with the scene's
/// motion, turning about its centre.
#[derive(Debug, Clone, PartialEq)]
pub struct HeadSettings {
    pub center: Vec3,
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
    pub path: PathBuf,
    pub scale: f32,
    pub offset: Vec3,
}

/// What a scene was made from: its TOML text, the path it came from
/// (relative paths in it are relative to that), and the bytes of the data
/// files it names once they are read (see [`Scene::read_data_files`]):
/// everything another process needs to make the same scene.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct SceneSource {
    pub text: Arc<str>,
    pub path: PathBuf,
    /// Data files by the path the scene names them by.
    pub files: BTreeMap<PathBuf, Arc<[u8]>>,
}

/// A validated scene.
#[derive(Debug, Clone, PartialEq)]
pub struct Scene {
    /// What it was made from.
    pub source: SceneSource,
    pub hair: HairSource,
    pub subdivide: u32,
    pub fiber: Fiber,
    pub lights: Vec<Light>,
    pub shadow: ShadowSettings,
    pub camera: CameraSettings,
    pub render: RenderSettings,
    pub head: Option<HeadSettings>,
    pub shading: raster::Shading,
    pub effects: Effects,
    pub animation: Animation,
    pub dynamics: Dynamics,
    pub collision: Collision,
    pub bodies: Vec<BodySettings>,
}

/// Defaults, documented in the module comment and docs/scene.md.
pub const DEFAULT_LIGHT_DIRECTION: [f32; 3] = [0.9, -0.35, -0.25];
/// A spot light's cone and soft edge, degrees.
pub const DEFAULT_CONE_DEG: f32 = 30.0;
pub const DEFAULT_FALLOFF_DEG: f32 = 5.0;
pub const DEFAULT_FIBER_WIDTH: f32 = 0.1;
pub const DEFAULT_FOLLOW_RADIUS: f32 = 0.4;
pub const DEFAULT_FIBER_OPACITY: f32 = 0.5;
pub const DEFAULT_CELLS: u32 = 128;
pub const DEFAULT_SUBDIVIDE: u32 = 2;
pub const DEFAULT_TFX_FOLLOWERS: u32 = 15;
pub const DEFAULT_WIDTH: u32 = 1280;
pub const DEFAULT_HEIGHT: u32 = 720;
pub const DEFAULT_FOV_DEG: f32 = 30.0;
pub const DEFAULT_BACKGROUND: [f32; 3] = [0.02, 0.025, 0.035];
pub const DEFAULT_HAIR_ALPHA: f32 = 0.85;
pub const DEFAULT_HEAD_COLOR: [f32; 3] = [0.55, 0.38, 0.3];

/// The built-in scene: the smooth style with a middle parting and a fringe
/// on a head with a face ([`BUILT_IN_HEAD`]), dancing, seen from three
/// quarters on the lit side; every other key at its default.
pub const BUILT_IN_SCENE: &str = "[hair]\nstyle = \"smooth\"\nparting = true\n\n\
[head]\nmesh = \"head.obj\"\n\n\
[animation]\nmotion = \"dance\"\n\n\
[camera]\nview = \"three-quarter-left\"\n";

/// The built-in scene's head mesh, `head.obj` in it: `scenes/head.obj`,
/// made by `scenes/make_head.py` (the styles' sphere of radius 10 above the
/// middle, a jaw, a nose and a neck below).
pub const BUILT_IN_HEAD: &[u8] = include_bytes!("../../../scenes/head.obj");

impl Default for Scene {
    /// The built-in scene ([`BUILT_IN_SCENE`]), its head mesh held in its
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
        let io = |cause| SceneError::Io {
            path: path.to_owned(),
            cause,
        };
        // The size first: a huge file is refused before it is read.
        let size = std::fs::metadata(path).map_err(io)?.len();
        if size > MAX_SCENE_BYTES as u64 {
            return Err(SceneError::Parse {
                path: path.to_owned(),
                message: format!(
                    "a scene file of {size} bytes: at most {MAX_SCENE_BYTES} (put strands in a \
                     groom file, hair.file)"
                ),
            });
        }
        let text = std::fs::read_to_string(path).map_err(io)?;
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
            message: one_line(&e.to_string()),
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
            let bytes = std::fs::read(&p).map_err(|cause| SceneError::Io {
                path: p.clone(),
                cause,
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
            None => std::fs::read(path).map(std::borrow::Cow::Owned),
        }
    }

    /// The scene `source` describes, with its data files as read there.
    pub fn from_source(source: &SceneSource) -> Result<Scene, SceneError> {
        Scene::parse(&source.text, &source.path, source.files.clone())
    }
}

/// toml's messages span several lines with a source excerpt; keep them to one.
fn one_line(message: &str) -> String {
    let mut parts = message.lines().map(str::trim).filter(|l| {
        !l.is_empty()
            && !l.starts_with('|')
            && !l.chars().next().is_some_and(|c| c.is_ascii_digit())
    });
    let head = parts
        .next()
        .unwrap_or("invalid TOML")
        .trim_end_matches(':')
        .to_string();
    let rest: Vec<&str> = parts.collect();
    if rest.is_empty() {
        head
    } else {
        format!("{head}: {}", rest.join("; "))
    }
}

struct Validator<'a> {
    path: &'a Path,
    /// Data files already read, by the path the scene names them by.
    files: &'a BTreeMap<PathBuf, Arc<[u8]>>,
}

impl Validator<'_> {
    /// The length unit the groom at `path`, placed by `place`, appears to
    /// be measured in, relative to the centimetres the length defaults
    /// (fiber width, follow radius) assume: with `L` the largest side of
    /// its bounds,
    ///
    /// ```text
    /// unit = 10^floor(log10(L / 10))
    /// ```
    ///
    /// 1 for a groom 10 to 100 units across (centimetres: a head is about
    /// 16 to 20 across, long hair under 100), 10 for 100 to 1000
    /// (millimetres), 0.01 for 0.1 to 1 (metres); at most 10^4 either way,
    /// 1 for an empty groom. Reads the groom (from the scene's files when
    /// held there).
    fn groom_unit(&self, path: &Path, place: &Placement) -> Result<f32, SceneError> {
        let fail = |reason: String| self.invalid("hair.file", path.display(), reason);
        let hair = match self.files.get(path) {
            Some(b) => strands::load_bytes(path, b),
            None => strands::load(path),
        }
        .map_err(|e| fail(e.to_string()))?;
        let b = hair.bounds();
        if b.is_empty() {
            return Ok(1.0);
        }
        let side = (b.size() * place.scale).max_element();
        if side.is_nan() || side <= 0.0 {
            return Ok(1.0);
        }
        let e = (side / 10.0).log10().floor().clamp(-4.0, 4.0);
        Ok(10f32.powf(e))
    }

    /// The collision sphere of a head mesh given without one: fitted to
    /// its crown ([`strands::Mesh::crown_sphere`]), as the mesh is placed.
    fn fitted_sphere(&self, m: &HeadMesh) -> Result<(Vec3, f32), SceneError> {
        let fail = |reason: String| self.invalid("head.mesh", m.path.display(), reason);
        let parse = strands::mesh_parser(&m.path).map_err(|e| fail(e.to_string()))?;
        let bytes = match self.files.get(&m.path) {
            Some(b) => std::borrow::Cow::Borrowed(&b[..]),
            None => std::borrow::Cow::Owned(
                std::fs::read(&m.path).map_err(|e| fail(format!("cannot read it: {e}")))?,
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

    /// The `[shadow]` table: the method, then the settings it takes; a
    /// setting of another method is refused by name.
    fn shadow(&self, s: RawShadow) -> Result<ShadowSettings, SceneError> {
        let name = s.method.as_deref().unwrap_or("density-map");
        let cells = self.int(
            "shadow.cells",
            s.cells,
            DEFAULT_CELLS,
            1..=shadow::MAX_CELLS,
        )?;
        let mut m = MethodConfig::with_defaults(name, cells).ok_or_else(|| {
            self.invalid(
                "shadow.method",
                format!("{name:?}"),
                format!("known methods: {}", MethodConfig::NAMES.join(", ")),
            )
        })?;
        if let Some(f) = s.filter {
            if matches!(m, MethodConfig::Reference { .. }) {
                return Err(self.invalid("shadow.filter", f, "the reference does not filter"));
            }
            m.set_filter(f);
        }
        if s.cells.is_some() && matches!(m, MethodConfig::Reference { .. }) {
            return Err(self.invalid(
                "shadow.cells",
                cells,
                "the reference has no cells; set shadow.footprint",
            ));
        }
        let not_for = |field: &'static str, value: String, owner: &str| {
            self.invalid(
                field,
                value,
                format!("applies to method {owner:?} only, not {name:?}"),
            )
        };
        let count = |field: &'static str, v: i64| {
            u32::try_from(v).map_err(|_| self.invalid(field, v, "must be a whole number >= 0"))
        };
        macro_rules! set {
            ($field:literal, $raw:expr, $owner:literal, $pat:pat => $assign:expr) => {
                if let Some(v) = $raw {
                    match &mut m {
                        $pat => $assign(v)?,
                        _ => return Err(not_for($field, format!("{v:?}"), $owner)),
                    }
                }
            };
        }
        set!("shadow.slices", s.slices, "opacity-shadow-map",
            MethodConfig::OpacityShadowMap { slices, .. } => |v| count("shadow.slices", v).map(|v| *slices = v));
        set!("shadow.mode", s.mode.clone(), "opacity-shadow-map",
        MethodConfig::OpacityShadowMap { mode, .. } => |v: String| match v.as_str() {
            "linear" => { *mode = OpacityMode::Linear; Ok(()) }
            "exponential" => {
                if !matches!(mode, OpacityMode::Exponential { .. }) {
                    *mode = OpacityMode::Exponential { kappa: 1.0 };
                }
                Ok(())
            }
            _ => Err(self.invalid("shadow.mode", format!("{v:?}"), "must be \"linear\" or \"exponential\"")),
        });
        set!("shadow.kappa", s.kappa, "opacity-shadow-map",
        MethodConfig::OpacityShadowMap { mode, .. } => |v: f32| match mode {
            OpacityMode::Exponential { kappa } => { *kappa = v; Ok(()) }
            OpacityMode::Linear => Err(self.invalid("shadow.kappa", v, "applies to mode \"exponential\" only")),
        });
        set!("shadow.offset", s.offset, "opacity-shadow-map",
            MethodConfig::OpacityShadowMap { offset, .. } => |v| { *offset = v; Ok::<(), SceneError>(()) });
        set!("shadow.layers", s.layers, "deep-opacity-map",
            MethodConfig::DeepOpacityMap { layers, .. } => |v| count("shadow.layers", v).map(|v| *layers = v));
        set!("shadow.layer_cells", s.layer_cells, "deep-opacity-map",
            MethodConfig::DeepOpacityMap { layer_cells, .. } => |v| { *layer_cells = v; Ok::<(), SceneError>(()) });
        set!("shadow.beyond", s.beyond.clone(), "deep-opacity-map",
        MethodConfig::DeepOpacityMap { beyond, .. } => |v: String| match Beyond::from_name(&v) {
            Some(b) => { *beyond = b; Ok(()) }
            None => Err(self.invalid("shadow.beyond", format!("{v:?}"), format!("known: {}", Beyond::NAMES.join(", ")))),
        });
        set!("shadow.clusters", s.clusters, "density-clustering",
            MethodConfig::DensityClustering { clusters, .. } => |v| count("shadow.clusters", v).map(|v| *clusters = v));
        set!("shadow.tolerance", s.tolerance, "deep-shadow-map",
            MethodConfig::DeepShadowMap { tolerance, .. } => |v| { *tolerance = v; Ok::<(), SceneError>(()) });
        set!("shadow.footprint", s.footprint, "reference",
            MethodConfig::Reference { footprint, .. } => |v| { *footprint = Some(v); Ok::<(), SceneError>(()) });
        set!("shadow.rays", s.rays, "reference",
            MethodConfig::Reference { rays, .. } => |v| count("shadow.rays", v).map(|v| *rays = v));
        m.validate().map_err(|e| match e {
            shadow::ShadowError::Setting { name, value, why } => {
                self.invalid(setting_field(name), value, why)
            }
            other => self.invalid("shadow", name, other.to_string()),
        })?;
        Ok(ShadowSettings { method: m })
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

    /// One `[[light]]`: directional (`direction`), point (`position`) or
    /// spot (`position`, `direction`, `cone_deg`, `falloff_deg`); a light
    /// with a source has an `intensity` (default: irradiance 1 at
    /// `head_center`, `intensity = r^2`).
    fn light(&self, l: &RawLight, head_center: Vec3) -> Result<Light, SceneError> {
        let finite = |field: &'static str, v: [f32; 3]| {
            if v.iter().all(|x| x.is_finite()) {
                Ok(Vec3::from_array(v))
            } else {
                Err(self.invalid(field, format!("{v:?}"), "must be finite"))
            }
        };
        let Some(position) = l.position else {
            for (field, set) in [
                ("light.cone_deg", l.cone_deg.is_some()),
                ("light.falloff_deg", l.falloff_deg.is_some()),
                ("light.intensity", l.intensity.is_some()),
            ] {
                if set {
                    return Err(self.invalid(
                        field,
                        "(set)",
                        "applies to point and spot lights (with light.position)",
                    ));
                }
            }
            let d = l.direction.ok_or_else(|| {
                self.invalid(
                    "light",
                    "(no direction or position)",
                    "give direction (a directional light) or position (a point or spot light)",
                )
            })?;
            return Light::directional(Vec3::from_array(d)).map_err(|_| {
                self.invalid(
                    "light.direction",
                    format!("{d:?}"),
                    "must be finite and not zero",
                )
            });
        };
        let position = finite("light.position", position)?;
        let intensity = match l.intensity {
            Some(i) if !(i.is_finite() && i > 0.0 && i <= 1e12) => {
                return Err(self.invalid("light.intensity", i, "must be in (0, 1e12]"));
            }
            Some(i) => i,
            None => (head_center - position).length_squared().max(1e-6),
        };
        let Some(direction) = l.direction else {
            for (field, set) in [
                ("light.cone_deg", l.cone_deg.is_some()),
                ("light.falloff_deg", l.falloff_deg.is_some()),
            ] {
                if set {
                    return Err(self.invalid(
                        field,
                        "(set)",
                        "applies to spot lights (a position and a direction)",
                    ));
                }
            }
            return Light::point(position, intensity)
                .map_err(|e| self.invalid("light.position", format!("{position}"), e.to_string()));
        };
        let direction = finite("light.direction", direction)?;
        let cone = l.cone_deg.unwrap_or(DEFAULT_CONE_DEG);
        if !(cone > 0.0 && cone < 90.0) {
            return Err(self.invalid("light.cone_deg", cone, "must be in (0, 90) degrees"));
        }
        let falloff = l.falloff_deg.unwrap_or(DEFAULT_FALLOFF_DEG.min(cone));
        if !(falloff >= 0.0 && falloff <= cone) {
            return Err(self.invalid("light.falloff_deg", falloff, "must be in [0, cone_deg]"));
        }
        Light::spot(position, direction, cone, falloff, intensity).map_err(|_| {
            self.invalid(
                "light.direction",
                format!("{direction}"),
                "must be finite and not zero",
            )
        })
    }

    fn color(
        &self,
        field: &'static str,
        v: Option<[f32; 3]>,
        default: [f32; 3],
    ) -> Result<Vec3, SceneError> {
        let c = v.unwrap_or(default);
        if c.iter().all(|x| x.is_finite() && (0.0..=1.0).contains(x)) {
            Ok(Vec3::from_array(c))
        } else {
            Err(self.invalid(
                field,
                format!("{c:?}"),
                "each component must be in [0, 1] (linear RGB)",
            ))
        }
    }

    /// `[shading] model` and the fiber's settings: Kajiya-Kay (the
    /// default), or `"marschner"`, a physically based fiber whose
    /// absorption comes from `sigma_a`, from melanin concentrations, or
    /// (neither given) from each strand's colour.
    fn shading_model(&self, sh: &RawShading) -> Result<raster::ShadingModel, SceneError> {
        let fiber_keys = [
            ("shading.eumelanin", sh.eumelanin.is_some()),
            ("shading.pheomelanin", sh.pheomelanin.is_some()),
            ("shading.sigma_a", sh.sigma_a.is_some()),
            ("shading.eta", sh.eta.is_some()),
            ("shading.beta_m", sh.beta_m.is_some()),
            ("shading.beta_n", sh.beta_n.is_some()),
            ("shading.alpha_deg", sh.alpha_deg.is_some()),
            ("shading.irradiance", sh.irradiance.is_some()),
        ];
        match sh.model.as_deref().unwrap_or("kajiya-kay") {
            "kajiya-kay" => {
                self.refuse_set(&fiber_keys, "is a setting of model = \"marschner\"")?;
                Ok(raster::ShadingModel::KajiyaKay)
            }
            "marschner" => {
                let d = raster::FiberOptics::default();
                let in_range = |field: &'static str,
                                v: Option<f32>,
                                default: f32,
                                lo: f32,
                                hi: f32,
                                open_lo: bool| {
                    let v = v.unwrap_or(default);
                    let ok = v.is_finite() && v <= hi && if open_lo { v > lo } else { v >= lo };
                    if ok {
                        Ok(v)
                    } else {
                        let bracket = if open_lo { "(" } else { "[" };
                        Err(self.invalid(
                            field,
                            v,
                            format!("must be a number in {bracket}{lo}, {hi}]"),
                        ))
                    }
                };
                let beta_n = in_range("shading.beta_n", sh.beta_n, d.beta_n, 0.0, 1.0, true)?;
                let melanin = sh.eumelanin.is_some() || sh.pheomelanin.is_some();
                if melanin && sh.sigma_a.is_some() {
                    return Err(self.invalid(
                        "shading.sigma_a",
                        "(set)",
                        "give sigma_a or melanin concentrations (eumelanin, pheomelanin), not both",
                    ));
                }
                let sigma_a = match sh.sigma_a {
                    Some(s) if s.iter().all(|x| x.is_finite() && (0.0..=100.0).contains(x)) => {
                        Vec3::from_array(s)
                    }
                    Some(s) => {
                        return Err(self.invalid(
                            "shading.sigma_a",
                            format!("{s:?}"),
                            "each component must be in [0, 100] (per unit of the fiber's diameter)",
                        ));
                    }
                    None => raster::sigma_a_from_melanin(
                        in_range("shading.eumelanin", sh.eumelanin, 0.0, 0.0, 50.0, false)?,
                        in_range("shading.pheomelanin", sh.pheomelanin, 0.0, 0.0, 50.0, false)?,
                    ),
                };
                let optics = raster::FiberOptics {
                    eta: in_range("shading.eta", sh.eta, d.eta, 1.0, 3.0, true)?,
                    sigma_a,
                    beta_m: in_range("shading.beta_m", sh.beta_m, d.beta_m, 0.0, 1.0, true)?,
                    beta_n,
                    alpha_deg: in_range(
                        "shading.alpha_deg",
                        sh.alpha_deg,
                        d.alpha_deg,
                        -20.0,
                        20.0,
                        false,
                    )?,
                };
                Ok(raster::ShadingModel::Marschner {
                    optics,
                    multiple: false,
                    from_color: !melanin && sh.sigma_a.is_none(),
                    irradiance: in_range(
                        "shading.irradiance",
                        sh.irradiance,
                        5.0,
                        0.0,
                        1000.0,
                        false,
                    )?,
                })
            }
            other => Err(self.invalid(
                "shading.model",
                other,
                "must be \"kajiya-kay\" or \"marschner\"",
            )),
        }
    }

    /// An error for the first of `fields` that the scene set, saying `why`.
    fn refuse_set(&self, fields: &[(&'static str, bool)], why: &str) -> Result<(), SceneError> {
        match fields.iter().find(|(_, set)| *set) {
            Some((field, _)) => Err(self.invalid(field, "(set)", why)),
            None => Ok(()),
        }
    }

    /// `hair.scale`, `hair.rotate_deg`, `hair.translate`: finite, the
    /// scale in (0, 1e6], the offset within 1e9 scene units.
    fn placement(&self, h: &RawHair) -> Result<Placement, SceneError> {
        let scale = h.scale.unwrap_or(1.0);
        if !(scale > 0.0 && scale <= 1e6) {
            return Err(self.invalid("hair.scale", scale, "must be a number in (0, 1e6]"));
        }
        let three = |field: &'static str, v: Option<[f32; 3]>, max: f32| match v {
            Some(a) if !a.iter().all(|x| x.is_finite() && x.abs() <= max) => Err(self.invalid(
                field,
                format!("{a:?}"),
                format!("each component must be finite, within {max:e}"),
            )),
            v => Ok(Vec3::from_array(v.unwrap_or([0.0; 3]))),
        };
        Ok(Placement {
            scale,
            rotate_deg: three("hair.rotate_deg", h.rotate_deg, 1e6)?,
            translate: three("hair.translate", h.translate, 1e9)?,
        })
    }

    /// `hair.strands`: every coordinate finite, at most
    /// [`MAX_INLINE_POINTS`] points. Strands of one point or none are kept
    /// (they draw and shadow nothing).
    fn inline_strands(&self, strands: &[Vec<[f32; 3]>]) -> Result<Hair, SceneError> {
        let points: usize = strands.iter().map(Vec::len).sum();
        if points > MAX_INLINE_POINTS {
            return Err(self.invalid(
                "hair.strands",
                format!("({points} points)"),
                format!("at most {MAX_INLINE_POINTS} points; use hair.file for larger hair"),
            ));
        }
        let mut hair = Hair::new();
        let mut buf = Vec::new();
        for (s, st) in strands.iter().enumerate() {
            buf.clear();
            buf.extend(st.iter().map(|&p| Vec3::from_array(p)));
            if let Some(i) = buf.iter().position(|p| !p.is_finite()) {
                return Err(self.invalid(
                    "hair.strands",
                    format!("{:?}", st[i]),
                    format!("strand {s}, point {i}: coordinates must be finite"),
                ));
            }
            hair.push_strand(&buf).map_err(|e| {
                self.invalid("hair.strands", format!("(strand {s})"), e.to_string())
            })?;
        }
        Ok(hair)
    }

    fn scene(&self, raw: RawScene) -> Result<Scene, SceneError> {
        let h = raw.hair;
        let subdivide = self.int("hair.subdivide", h.subdivide, DEFAULT_SUBDIVIDE, 1..=64)?;
        let seed = h.seed.unwrap_or(1);
        let given = [h.style.is_some(), h.file.is_some(), h.strands.is_some()];
        if given.iter().filter(|&&g| g).count() > 1 {
            return Err(self.invalid(
                "hair",
                "(style, file, strands)",
                "give one of hair.style, hair.file and hair.strands",
            ));
        }
        // Keys of follow strands, which only hair from files grows.
        let follow_keys = [
            ("hair.followers", h.followers.is_some()),
            ("hair.follow_radius", h.follow_radius.is_some()),
            ("hair.tip_spread", h.tip_spread.is_some()),
        ];
        let place = self.placement(&h)?;
        // Length defaults in centimetres that follow a groom file's unit
        // (set once the rest is valid): the fiber width, the follow radius.
        let mut scale_width = false;
        let mut scale_follow = false;
        let hair = match (&h.strands, &h.file) {
            (Some(strands), _) => {
                self.refuse_set(&follow_keys, "does not apply to hair.strands")?;
                self.refuse_set(
                    &[("hair.seed", h.seed.is_some())],
                    "does not apply to hair.strands",
                )?;
                let mut hair = self.inline_strands(strands)?;
                place.apply(&mut hair);
                HairSource::Inline(hair)
            }
            (None, Some(file)) => {
                let path = self.relative(file);
                let tfx = path
                    .extension()
                    .is_some_and(|e| e.eq_ignore_ascii_case("tfx"));
                let followers = self.int(
                    "hair.followers",
                    h.followers,
                    if tfx { DEFAULT_TFX_FOLLOWERS } else { 0 },
                    0..=1000,
                )?;
                scale_width = raw.fiber.width.is_none();
                scale_follow = followers > 0 && h.follow_radius.is_none();
                let radius =
                    self.positive("hair.follow_radius", h.follow_radius, DEFAULT_FOLLOW_RADIUS)?;
                let tip_spread = self.positive("hair.tip_spread", h.tip_spread, 1.5)?;
                let follow = (followers > 0).then_some(FollowParams {
                    followers,
                    radius,
                    tip_spread,
                    seed,
                });
                HairSource::File {
                    path,
                    follow,
                    place,
                }
            }
            (None, None) => {
                self.refuse_set(
                    &[
                        ("hair.scale", h.scale.is_some()),
                        ("hair.rotate_deg", h.rotate_deg.is_some()),
                        ("hair.translate", h.translate.is_some()),
                    ],
                    "places a groom from hair.file or hair.strands; a style grows on the head",
                )?;
                let name = h.style.as_deref().unwrap_or("smooth");
                let style = Style::from_name(name).ok_or_else(|| {
                    self.invalid(
                        "hair.style",
                        format!("{name:?}"),
                        "expected \"smooth\" or \"curly\"",
                    )
                })?;
                self.refuse_set(&follow_keys, "applies to hair.file only")?;
                let mut p = StyleParams::new(style);
                p.seed = seed;
                p.strands_per_wisp = self.int(
                    "hair.strands_per_wisp",
                    h.strands_per_wisp,
                    p.strands_per_wisp,
                    1..=2000,
                )?;
                p.parting = h.parting.unwrap_or(false);
                if h.color.is_some() {
                    p.color = Some(self.color("hair.color", h.color, [0.0; 3])?);
                }
                HairSource::Style(p)
            }
        };
        if !matches!(hair, HairSource::Style(_)) {
            self.refuse_set(
                &[
                    ("hair.strands_per_wisp", h.strands_per_wisp.is_some()),
                    ("hair.parting", h.parting.is_some()),
                    ("hair.color", h.color.is_some()),
                ],
                "applies to hair.style only",
            )?;
        }

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
        let c = raw.camera;
        let vec3 = |field: &'static str, v: Option<[f32; 3]>| -> Result<Option<Vec3>, SceneError> {
            match v {
                Some(a) if !a.iter().all(|x| x.is_finite()) => {
                    Err(self.invalid(field, format!("{a:?}"), "must be finite"))
                }
                v => Ok(v.map(Vec3::from_array)),
            }
        };
        let fov_deg = c.fov_deg.unwrap_or(DEFAULT_FOV_DEG);
        if !(fov_deg > 0.1 && fov_deg < 179.0) {
            return Err(self.invalid("camera.fov_deg", fov_deg, "must be in (0.1, 179) degrees"));
        }
        let view = match c.view.as_deref() {
            None => CameraView::Auto,
            Some(v) => CameraView::from_name(v).ok_or_else(|| {
                self.invalid(
                    "camera.view",
                    format!("{v:?}"),
                    format!("expected one of {}", CameraView::NAMES.join(", ")),
                )
            })?,
        };
        if view != CameraView::Auto && c.position.is_some() {
            return Err(self.invalid(
                "camera.view",
                format!("{:?}", c.view.as_deref().unwrap_or_default()),
                "says where a camera without camera.position looks from; give one of them",
            ));
        }
        let camera = CameraSettings {
            view,
            position: vec3("camera.position", c.position)?,
            look_at: vec3("camera.look_at", c.look_at)?,
            fov_deg,
            up: vec3("camera.up", c.up)?,
        };
        if camera.up.is_some_and(|u| u.length() < 1e-6) {
            return Err(self.invalid(
                "camera.up",
                format!("{:?}", c.up.unwrap_or_default()),
                "must not be zero",
            ));
        }
        if let (Some(p), Some(l)) = (camera.position, camera.look_at)
            && p.distance(l) < 1e-6
        {
            return Err(self.invalid("camera.look_at", l, "must differ from camera.position"));
        }

        let r = raw.render;
        let width = self.int(
            "render.width",
            r.width,
            DEFAULT_WIDTH,
            1..=raster::canvas_max_side(),
        )?;
        let height = self.int(
            "render.height",
            r.height,
            DEFAULT_HEIGHT,
            1..=raster::canvas_max_side(),
        )?;
        if u64::from(width) * u64::from(height) > raster::MAX_PIXELS {
            return Err(self.invalid(
                "render.width",
                width,
                format!(
                    "{width}x{height} is more than {} pixels",
                    raster::MAX_PIXELS
                ),
            ));
        }
        let background = self.color("render.background", r.background, DEFAULT_BACKGROUND)?;
        let hair_alpha = r.hair_alpha.unwrap_or(DEFAULT_HAIR_ALPHA);
        if !(0.0..=1.0).contains(&hair_alpha) {
            return Err(self.invalid("render.hair_alpha", hair_alpha, "must be in [0, 1]"));
        }
        let render = RenderSettings {
            width,
            height,
            background,
            hair_alpha,
        };

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
                        offset: vec3("head.mesh_offset", hd.mesh_offset)?.unwrap_or(Vec3::ZERO),
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
            let center = vec3("head.center", hd.center)?.or(style_head.map(|h| h.0));
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
            follow,
            place,
        } = &mut scene.hair
            && (scale_width || scale_follow)
        {
            let unit = self.groom_unit(path, place)?;
            if scale_follow && let Some(f) = follow {
                f.radius = DEFAULT_FOLLOW_RADIUS * unit;
            }
            if scale_width {
                scene.fiber = Fiber::new(DEFAULT_FIBER_WIDTH * unit, scene.fiber.opacity())
                    .map_err(|_| {
                        self.invalid(
                            "fiber.width",
                            DEFAULT_FIBER_WIDTH * unit,
                            "must be a finite number > 0",
                        )
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

/// The scene field of a method setting.
fn setting_field(name: &str) -> &'static str {
    match name {
        "slices" => "shadow.slices",
        "kappa" => "shadow.kappa",
        "offset" => "shadow.offset",
        "layers" => "shadow.layers",
        "layer_cells" => "shadow.layer_cells",
        "clusters" => "shadow.clusters",
        "tolerance" => "shadow.tolerance",
        "footprint" => "shadow.footprint",
        "rays" => "shadow.rays",
        _ => "shadow",
    }
}

#[cfg(test)]
mod tests;
