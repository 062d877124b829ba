//! Keyframe selection for depth-filter updates: a target is updated only after the camera has
//! moved or turned enough since its last update, so that nearly identical views do not collapse
//! the point set (DESIGN.md: 1.5 m or 30°, angles wrapped).

use nalgebra::Isometry3;

/// The angle between two camera orientations, degrees in [0, 180]: the angle of the relative
/// rotation, so headings of 350° and 10° are 20° apart.
pub fn rotation_between_deg(a: &Isometry3<f64>, b: &Isometry3<f64>) -> f64 {
    (a.rotation.inverse() * b.rotation).angle().to_degrees()
}

/// Whether `current` is a keyframe with respect to `last`: the camera centre moved more than
/// `translation_m` or the orientation turned more than `rotation_deg`.
pub fn is_keyframe(
    last: &Isometry3<f64>,
    current: &Isometry3<f64>,
    translation_m: f64,
    rotation_deg: f64,
) -> bool {
    let moved_m = (current.translation.vector - last.translation.vector).norm();
    moved_m > translation_m || rotation_between_deg(last, current) > rotation_deg
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion, Vector3};

    fn yawed(deg: f64, x: f64) -> Isometry3<f64> {
        Isometry3::from_parts(
            Translation3::new(x, 0.0, 0.0),
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), deg.to_radians()),
        )
    }

    #[test]
    fn angles_wrap() {
        assert!((rotation_between_deg(&yawed(350.0, 0.0), &yawed(10.0, 0.0)) - 20.0).abs() < 1e-9);
        assert!(!is_keyframe(
            &yawed(350.0, 0.0),
            &yawed(10.0, 0.0),
            1.5,
            30.0
        ));
        assert!(is_keyframe(
            &yawed(340.0, 0.0),
            &yawed(15.0, 0.0),
            1.5,
            30.0
        ));
        assert!(is_keyframe(
            &yawed(-179.0, 0.0),
            &yawed(150.0, 0.0),
            1.5,
            30.0
        ));
    }

    #[test]
    fn translation_counts() {
        assert!(!is_keyframe(&yawed(0.0, 0.0), &yawed(0.0, 1.4), 1.5, 30.0));
        assert!(is_keyframe(&yawed(0.0, 0.0), &yawed(0.0, 1.6), 1.5, 30.0));
    }
}
