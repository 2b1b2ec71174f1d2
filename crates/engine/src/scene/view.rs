//! `[camera]` and `[render]`: where the picture is taken from and its size.

use super::raw::{RawCamera, RawRender};
use super::{
    DEFAULT_BACKGROUND, DEFAULT_FOV_DEG, DEFAULT_HAIR_ALPHA, DEFAULT_HEIGHT, DEFAULT_NEAREST,
    DEFAULT_WIDTH, Validator,
};
use crate::SceneError;
use glam::Vec3;
use strands::Bounds;

/// Where the camera is; `None` fields are framed around the hair.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraSettings {
    /// Where the default camera looks from (`camera.view`), when no
    /// position is given.
    pub view: CameraView,
    /// The eye (`camera.position`), scene units.
    pub position: Option<Vec3>,
    /// What it looks at (`camera.look_at`), scene units.
    pub look_at: Option<Vec3>,
    /// Vertical field of view (`camera.fov_deg`), degrees.
    pub fov_deg: f32,
    /// The picture's up direction (`camera.up`); +y when not given.
    pub up: Option<Vec3>,
}

/// Where the default camera looks from, towards the hair, slightly above.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum CameraView {
    /// The front (+z), or three quarters for hair seen edge-on from there
    /// (see [`view_direction`]).
    #[default]
    Auto,
    /// The front (+z).
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
    /// Every view's name, as scenes spell it.
    pub const NAMES: [&str; 6] = [
        "auto",
        "front",
        "three-quarter-left",
        "three-quarter-right",
        "left",
        "right",
    ];

    /// The view named `name`, if any.
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

/// `[render]`: the picture's size and look.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RenderSettings {
    /// Width, pixels.
    pub width: u32,
    /// Height, pixels.
    pub height: u32,
    /// Linear RGB.
    pub background: Vec3,
    /// Opacity of a drawn strand where it covers a whole pixel.
    pub hair_alpha: f32,
    /// Fragments of each pixel composited front to back, the rest blended
    /// order-independently (0: all blended).
    pub nearest: u32,
    /// Stochastic simplification, pixels (0: off): strands narrower than
    /// this on screen are drawn as a seeded share of them, each wider
    /// (see `raster::HairLook::simplify`).
    pub simplify: f32,
}

impl Validator<'_> {
    /// An optional point or vector, finite.
    pub(super) fn vec3(
        &self,
        field: &'static str,
        v: Option<[f32; 3]>,
    ) -> Result<Option<Vec3>, SceneError> {
        match v {
            Some(a) if !a.iter().all(|x| x.is_finite()) => {
                Err(self.invalid(field, format!("{a:?}"), "must be finite"))
            }
            v => Ok(v.map(Vec3::from_array)),
        }
    }

    /// `[camera]`: a view or a position, the field of view, the up vector.
    pub(super) fn camera(&self, c: &RawCamera) -> Result<CameraSettings, SceneError> {
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
            position: self.vec3("camera.position", c.position)?,
            look_at: self.vec3("camera.look_at", c.look_at)?,
            fov_deg,
            up: self.vec3("camera.up", c.up)?,
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
        Ok(camera)
    }

    /// `[render]`: the picture's size (within the renderer's limits), its
    /// background and the strands' opacity.
    pub(super) fn render(&self, r: &RawRender) -> Result<RenderSettings, SceneError> {
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
        let nearest = self.int(
            "render.nearest",
            r.nearest,
            DEFAULT_NEAREST,
            0..=raster::MAX_NEAREST as u32,
        )?;
        let simplify = r.simplify.unwrap_or(0.0);
        if !(0.0..=raster::HairLook::MAX_SIMPLIFY).contains(&simplify) {
            return Err(self.invalid(
                "render.simplify",
                simplify,
                format!(
                    "must be in [0, {}] pixels (0: off)",
                    raster::HairLook::MAX_SIMPLIFY
                ),
            ));
        }
        let render = RenderSettings {
            width,
            height,
            background,
            hair_alpha,
            nearest,
            simplify,
        };
        Ok(render)
    }
}

/// Where the default camera looks from, towards the hair, slightly above:
/// as `view` says; for [`crate::CameraView::Auto`] the front (+z), but three
/// quarters (45 degrees to the right) when the hair is less than a third
/// as wide (x) as it is deep (z), where a front view would see it edge-on
/// (a mohawk).
pub fn view_direction(hair: Bounds, view: CameraView) -> Vec3 {
    use CameraView as V;
    let size = hair.size();
    let edge_on = !hair.is_empty() && size.x < size.z / 3.0;
    let h = std::f32::consts::FRAC_1_SQRT_2;
    let (x, z) = match view {
        V::Auto if edge_on => (h, h),
        V::Auto | V::Front => (0.0, 1.0),
        V::ThreeQuarterLeft => (-h, h),
        V::ThreeQuarterRight => (h, h),
        V::Left => (-1.0, 0.0),
        V::Right => (1.0, 0.0),
    };
    Vec3::new(x, 0.15, z).normalize()
}
