//! The physical fiber: the two numbers that turn hair length into extinction.

use crate::ShadowError;

/// A hair fiber's optical size.
///
/// A fiber of width `w` (scene units) and opacity `alpha` (the fraction of
/// light it stops where it covers) crossing a light beam at angle `theta`
/// casts a shadow strip `w` wide over a length `dl sin(theta)` across the
/// beam, so a length `dl` of fiber inside a volume `V` adds extinction
///
/// ```text
/// kappa = alpha * w * dl * sin(theta) / V        (per scene unit)
/// ```
///
/// This replaces the paper's free scale factor `f` (section 4.2): the same
/// hair looks equally dark at any map resolution, and a slab of parallel
/// fibers, `n` per unit area across them, follows Beer-Lambert
/// `T(x) = exp(-n * w * alpha * sin(theta) * x)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Fiber {
    width: f32,
    opacity: f32,
}

impl Fiber {
    /// A fiber of `width` scene units (finite, > 0) and `opacity` in [0, 1].
    pub fn new(width: f32, opacity: f32) -> Result<Fiber, ShadowError> {
        if !(width.is_finite() && width > 0.0) {
            return Err(ShadowError::FiberWidth(width));
        }
        if !(0.0..=1.0).contains(&opacity) {
            return Err(ShadowError::FiberOpacity(opacity));
        }
        Ok(Fiber { width, opacity })
    }

    /// Fiber width `w`, in scene units.
    pub fn width(&self) -> f32 {
        self.width
    }

    /// Fiber opacity `alpha`, in [0, 1].
    pub fn opacity(&self) -> f32 {
        self.opacity
    }

    /// `alpha * w`: extinction cross-section per unit fiber length, in scene units.
    pub fn cross_section(&self) -> f32 {
        self.width * self.opacity
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn refuses_nan_negative_and_out_of_range() {
        assert!(Fiber::new(f32::NAN, 0.5).is_err());
        assert!(Fiber::new(-1.0, 0.5).is_err());
        assert!(Fiber::new(f32::INFINITY, 0.5).is_err());
        assert!(Fiber::new(0.1, 1.5).is_err());
        assert!(Fiber::new(0.1, f32::NAN).is_err());
        assert_eq!(Fiber::new(0.1, 0.5).unwrap().cross_section(), 0.05);
        // A fiber of no width stops no light: not a fiber.
        assert!(Fiber::new(0.0, 0.5).is_err());
        assert!(Fiber::new(1e-6, 0.0).is_ok());
    }
}
