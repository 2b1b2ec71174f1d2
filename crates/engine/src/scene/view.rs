//! `[camera]` and `[render]`: where the picture is taken from and its size.

use super::*;

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
        let render = RenderSettings {
            width,
            height,
            background,
            hair_alpha,
        };
        Ok(render)
    }
}
