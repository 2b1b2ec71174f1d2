//! Head motion: a rigid transform of the head over time.

use glam::{Affine3A, EulerRot, Quat, Vec3};

use crate::SimError;

/// One key of a keyframed motion: at `time` (seconds) the head is rotated
/// by `rotate_deg` (degrees about x, then y, then z, around its centre) and
/// moved by `translate` (scene units).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Keyframe {
    /// When, seconds.
    pub time: f32,
    /// Movement, scene units.
    pub translate: Vec3,
    /// Rotation about x, then y, then z, degrees.
    pub rotate_deg: Vec3,
}

/// How the head moves.
#[derive(Debug, Clone, PartialEq)]
pub enum Motion {
    /// It does not.
    Still,
    /// Linear in translation and spherical-linear in rotation between keys;
    /// held before the first key and after the last.
    Keyframes(Vec<Keyframe>),
    /// A built-in test sequence like the paper's: the head shakes from side
    /// to side (yaw 40 degrees at 0.5 Hz), nods (12 degrees at 1 Hz), rolls
    /// (6 degrees at 2/3 Hz) and sways sideways (3 units at 1/3 Hz), all
    /// scaled by `amplitude`; at time 0 the head is at rest.
    /// The dance.
    Dance {
        /// 1 for the movement described, 0 for none.
        amplitude: f32,
    },
}

impl Motion {
    /// Checks the keys: finite, at least one, times strictly increasing.
    pub fn validate(&self) -> Result<(), SimError> {
        match self {
            Motion::Still => Ok(()),
            Motion::Dance { amplitude } => {
                if amplitude.is_finite() && *amplitude >= 0.0 {
                    Ok(())
                } else {
                    Err(SimError::Motion(format!(
                        "dance amplitude {amplitude} is not a finite number >= 0"
                    )))
                }
            }
            Motion::Keyframes(keys) => {
                if keys.is_empty() {
                    return Err(SimError::Motion("no keyframes".into()));
                }
                for (i, k) in keys.iter().enumerate() {
                    if !(k.time.is_finite() && k.translate.is_finite() && k.rotate_deg.is_finite())
                    {
                        return Err(SimError::Motion(format!("keyframe {i} is not finite")));
                    }
                    if i > 0 && k.time <= keys[i - 1].time {
                        return Err(SimError::Motion(format!(
                            "keyframe {i} at {} s does not follow keyframe {} at {} s",
                            k.time,
                            i - 1,
                            keys[i - 1].time
                        )));
                    }
                }
                Ok(())
            }
        }
    }

    /// Whether the head never moves.
    pub fn is_still(&self) -> bool {
        match self {
            Motion::Still => true,
            Motion::Dance { amplitude } => *amplitude == 0.0,
            Motion::Keyframes(k) => k
                .windows(2)
                .all(|w| w[0].translate == w[1].translate && w[0].rotate_deg == w[1].rotate_deg),
        }
    }

    /// Seconds after which the motion holds or repeats: every pose it
    /// takes is taken in `0..=span`. Still: 0. The dance: 6 s, the least
    /// common multiple of its periods (2, 1, 1.5 and 3 s). Keyframes: the
    /// last key's time (held after it; before time 0 is never rendered).
    pub fn span(&self) -> f32 {
        match self {
            Motion::Still => 0.0,
            Motion::Dance { .. } => 6.0,
            Motion::Keyframes(keys) => keys.last().map_or(0.0, |k| k.time.max(0.0)),
        }
    }

    /// The head's transform at time `t` (seconds), rotating about `pivot`
    /// (the head's centre at rest).
    pub fn at(&self, t: f32, pivot: Vec3) -> Affine3A {
        let (translate, rotation) = match self {
            Motion::Still => (Vec3::ZERO, Quat::IDENTITY),
            Motion::Dance { amplitude } => {
                let tau = std::f32::consts::TAU;
                let a = *amplitude;
                let yaw = a * 40f32.to_radians() * (tau * t / 2.0).sin();
                let pitch = a * 12f32.to_radians() * (tau * t).sin();
                let roll = a * 6f32.to_radians() * (tau * t / 1.5).sin();
                let sway = Vec3::new(a * 3.0 * (tau * t / 3.0).sin(), 0.0, 0.0);
                (sway, Quat::from_euler(EulerRot::YXZ, yaw, pitch, roll))
            }
            Motion::Keyframes(keys) => {
                let pose = |k: &Keyframe| {
                    let r = k.rotate_deg * (std::f32::consts::PI / 180.0);
                    (k.translate, Quat::from_euler(EulerRot::XYZ, r.x, r.y, r.z))
                };
                let i = keys.partition_point(|k| k.time <= t);
                if i == 0 {
                    pose(&keys[0])
                } else if i == keys.len() {
                    pose(&keys[i - 1])
                } else {
                    let (a, b) = (&keys[i - 1], &keys[i]);
                    let s = (t - a.time) / (b.time - a.time);
                    let (ta, ra) = pose(a);
                    let (tb, rb) = pose(b);
                    (ta.lerp(tb, s), ra.slerp(rb, s))
                }
            }
        };
        Affine3A::from_translation(pivot + translate)
            * Affine3A::from_quat(rotation)
            * Affine3A::from_translation(-pivot)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keyframes_interpolate_and_hold_at_the_ends() {
        let m = Motion::Keyframes(vec![
            Keyframe {
                time: 0.0,
                translate: Vec3::ZERO,
                rotate_deg: Vec3::ZERO,
            },
            Keyframe {
                time: 2.0,
                translate: Vec3::new(4.0, 0.0, 0.0),
                rotate_deg: Vec3::new(0.0, 90.0, 0.0),
            },
        ]);
        m.validate().unwrap();
        let p = Vec3::new(0.0, 0.0, 1.0);
        assert!(
            m.at(-1.0, Vec3::ZERO)
                .transform_point3(p)
                .abs_diff_eq(p, 1e-6)
        );
        let mid = m.at(1.0, Vec3::ZERO).transform_point3(p);
        // Half way: moved by 2, turned 45 degrees about y.
        let h = std::f32::consts::FRAC_1_SQRT_2;
        assert!(mid.abs_diff_eq(Vec3::new(2.0 + h, 0.0, h), 1e-5), "{mid}");
        let end = m.at(5.0, Vec3::ZERO).transform_point3(p);
        assert!(end.abs_diff_eq(Vec3::new(5.0, 0.0, 0.0), 1e-5), "{end}");
    }

    #[test]
    fn bad_keys_are_refused() {
        let k = |time| Keyframe {
            time,
            translate: Vec3::ZERO,
            rotate_deg: Vec3::ZERO,
        };
        assert!(Motion::Keyframes(vec![]).validate().is_err());
        assert!(Motion::Keyframes(vec![k(1.0), k(1.0)]).validate().is_err());
        assert!(Motion::Keyframes(vec![k(f32::NAN)]).validate().is_err());
        assert!(Motion::Dance { amplitude: -1.0 }.validate().is_err());
    }

    #[test]
    fn the_dance_rotates_about_the_pivot() {
        let pivot = Vec3::new(1.0, 2.0, 3.0);
        let m = Motion::Dance { amplitude: 1.0 };
        let x = m.at(0.37, pivot);
        // The pivot moves only by the sway.
        let moved = x.transform_point3(pivot) - pivot;
        assert!(moved.y.abs() < 1e-5 && moved.z.abs() < 1e-5, "{moved}");
        assert!(Motion::Dance { amplitude: 0.0 }.is_still());
        assert_eq!(m.at(0.0, pivot), Affine3A::IDENTITY, "at rest at time 0");
        assert!(!m.is_still());
    }

    #[test]
    fn the_dance_repeats_after_its_span() {
        let pivot = Vec3::new(0.0, 2.0, 0.0);
        let m = Motion::Dance { amplitude: 1.0 };
        let span = m.span();
        for t in [0.1f32, 0.77, 1.9, 4.4] {
            let (a, b) = (m.at(t, pivot), m.at(t + span, pivot));
            assert!(a.abs_diff_eq(b, 1e-4), "{t}: {a:?} != {b:?}");
        }
        // Not before: half the span is not a period (the sway's is 3 s,
        // the shake's 2 s).
        assert!(
            !m.at(0.5, pivot)
                .abs_diff_eq(m.at(0.5 + span / 4.0, pivot), 1e-3)
        );
    }
}
