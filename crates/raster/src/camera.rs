//! A pinhole camera with a vertical field of view.

use glam::Vec3;

use crate::RasterError;

/// Perspective camera: `position` looking at `look_at`, `up` roughly up,
/// `fov_deg` the vertical field of view in degrees, for an image of
/// `width x height` pixels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Camera {
    /// The eye, scene units.
    pub position: Vec3,
    /// Right, up and forward unit axes of the view.
    right: Vec3,
    up: Vec3,
    forward: Vec3,
    /// Focal length in pixels: `height / (2 tan(fov / 2))`.
    focal: f32,
    width: u32,
    height: u32,
    /// What it was made from, to make it again elsewhere.
    look_at: Vec3,
    fov_deg: f32,
    /// The up direction asked for ([`Self::with_up`]; +y by default).
    up_hint: Vec3,
}

/// Points closer to the camera than this (scene units) are not drawn.
pub(crate) const NEAR: f32 = 1e-3;

impl Camera {
    /// A camera at `position` looking at `look_at` (+y up, or +z when
    /// looking straight up or down), `fov_deg` the vertical field of view,
    /// for `width x height` pixels; refuses non-finite or coincident
    /// points and a field of view outside (0.1, 179) degrees.
    pub fn new(
        position: Vec3,
        look_at: Vec3,
        fov_deg: f32,
        width: u32,
        height: u32,
    ) -> Result<Camera, RasterError> {
        let forward = look_at - position;
        if !(position.is_finite() && look_at.is_finite()) || forward.length() < 1e-6 {
            return Err(RasterError::Camera(format!(
                "position {position} and look_at {look_at} must be finite and apart"
            )));
        }
        if !(fov_deg > 0.1 && fov_deg < 179.0) {
            return Err(RasterError::Camera(format!(
                "fov_deg {fov_deg}: must be in (0.1, 179)"
            )));
        }
        // Up is +y unless the camera looks straight up or down.
        let f = forward.normalize();
        let up = if f.cross(Vec3::Y).length() < 1e-4 {
            Vec3::Z
        } else {
            Vec3::Y
        };
        let right = f.cross(up).normalize();
        let up = right.cross(f);
        let focal = height as f32 / (2.0 * (0.5 * fov_deg.to_radians()).tan());
        Ok(Camera {
            position,
            right,
            up,
            forward: f,
            focal,
            width,
            height,
            look_at,
            fov_deg,
            up_hint: Vec3::Y,
        })
    }

    /// The same camera with `up` (any length) as the picture's up: the
    /// view's up axis is the part of `up` square to the view direction.
    /// Refuses an `up` that is not finite, is zero or lies along the view.
    pub fn with_up(self, up: Vec3) -> Result<Camera, RasterError> {
        let f = self.forward;
        let u = up.normalize_or_zero();
        if !u.is_finite() || u == Vec3::ZERO || f.cross(u).length() < 1e-4 {
            return Err(RasterError::Camera(format!(
                "up {up}: must be finite, not zero, and not along the view direction {f}"
            )));
        }
        let right = f.cross(u).normalize();
        Ok(Camera {
            right,
            up: right.cross(f),
            up_hint: up,
            ..self
        })
    }

    /// The up direction the camera was made with (+y unless
    /// [`Self::with_up`] said otherwise).
    pub fn up_hint(&self) -> Vec3 {
        self.up_hint
    }

    /// The point it looks at, as given to [`Self::new`].
    pub fn look_at(&self) -> Vec3 {
        self.look_at
    }

    /// The vertical field of view in degrees, as given to [`Self::new`].
    pub fn fov_deg(&self) -> f32 {
        self.fov_deg
    }

    /// The view depth `z` of `p` that [`Self::project`] gives, or `None`
    /// behind the camera (nearer than its near distance, or NaN).
    #[inline]
    pub fn depth(&self, p: Vec3) -> Option<f32> {
        let z = (p - self.position).dot(self.forward);
        if z.is_nan() || z < NEAR {
            return None;
        }
        Some(z)
    }

    /// Pixel coordinates `(x, y)` (x right, y down, pixel centres at
    /// half-integers) and view depth `z > 0` of `p`, or `None` behind the
    /// camera.
    #[inline]
    pub fn project(&self, p: Vec3) -> Option<Vec3> {
        let z = self.depth(p)?;
        let q = p - self.position;
        let x = 0.5 * self.width as f32 + self.focal * q.dot(self.right) / z;
        let y = 0.5 * self.height as f32 - self.focal * q.dot(self.up) / z;
        Some(Vec3::new(x, y, z))
    }

    /// The world-space ray direction (unit) through pixel coordinates `(x, y)`.
    pub fn ray(&self, x: f32, y: f32) -> Vec3 {
        let (dx, dy) = (
            (x - 0.5 * self.width as f32) / self.focal,
            -(y - 0.5 * self.height as f32) / self.focal,
        );
        (self.forward + dx * self.right + dy * self.up).normalize()
    }

    /// Pixels per scene unit at unit view depth.
    pub fn focal(&self) -> f32 {
        self.focal
    }

    /// The view's unit axes: right, up (in the picture) and forward
    /// (into it), a right-handed frame `right x up = -forward`.
    pub fn axes(&self) -> (Vec3, Vec3, Vec3) {
        (self.right, self.up, self.forward)
    }

    /// Image width, pixels.
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Image height, pixels.
    pub fn height(&self) -> u32 {
        self.height
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn projects_the_look_at_point_to_the_centre_and_rays_invert_projection() {
        let c = Camera::new(
            Vec3::new(1.0, 2.0, 30.0),
            Vec3::new(0.0, -1.0, 0.0),
            40.0,
            320,
            200,
        )
        .unwrap();
        let p = c.project(Vec3::new(0.0, -1.0, 0.0)).unwrap();
        assert!((p.x - 160.0).abs() < 1e-3 && (p.y - 100.0).abs() < 1e-3);
        let q = Vec3::new(3.0, 4.0, -2.0);
        let s = c.project(q).unwrap();
        let back = c.position + c.ray(s.x, s.y) * (q - c.position).length();
        assert!(back.distance(q) < 1e-3, "{back} vs {q}");
        assert!(
            c.project(Vec3::new(0.0, 0.0, 100.0)).is_none(),
            "behind the camera"
        );
    }

    #[test]
    fn refuses_degenerate_cameras() {
        // Up along +x: a point to +x of the target is above the centre,
        // one to +y is to the left.
        let c = Camera::new(Vec3::new(0.0, 0.0, 10.0), Vec3::ZERO, 40.0, 100, 100)
            .unwrap()
            .with_up(Vec3::new(2.0, 0.0, 0.0))
            .unwrap();
        let above = c.project(Vec3::X).unwrap();
        let left = c.project(Vec3::Y).unwrap();
        assert!((above.x - 50.0).abs() < 1e-3 && above.y < 40.0, "{above}");
        assert!(left.x < 40.0 && (left.y - 50.0).abs() < 1e-3, "{left}");
        assert_eq!(c.up_hint(), Vec3::new(2.0, 0.0, 0.0));
        for bad in [Vec3::ZERO, Vec3::Z, Vec3::NAN] {
            assert!(c.with_up(bad).is_err(), "{bad}");
        }
        assert!(Camera::new(Vec3::ZERO, Vec3::ZERO, 40.0, 10, 10).is_err());
        assert!(Camera::new(Vec3::ZERO, Vec3::X, 0.0, 10, 10).is_err());
        assert!(Camera::new(Vec3::ZERO, Vec3::X, f32::NAN, 10, 10).is_err());
        assert!(
            Camera::new(Vec3::ZERO, Vec3::Y, 40.0, 10, 10).is_ok(),
            "looking straight up"
        );
    }
}
