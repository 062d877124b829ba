//! Helpers for rigid transforms and quaternions.

use nalgebra::{Isometry3, Point3, Quaternion, Rotation3, Translation3, UnitQuaternion, Vector3};

use crate::SlamError;

/// The unit quaternion of TUM's `qx qy qz qw` order, normalised.
///
/// # Errors
/// [`SlamError::NotFinite`] for NaN or infinite components, and [`SlamError::Degenerate`] for a
/// quaternion whose norm is below 1e-9 (it encodes no rotation).
pub fn quaternion_from_xyzw(
    qx: f64,
    qy: f64,
    qz: f64,
    qw: f64,
) -> Result<UnitQuaternion<f64>, SlamError> {
    let q = Quaternion::new(qw, qx, qy, qz);
    if !q.coords.iter().all(|c| c.is_finite()) {
        return Err(SlamError::NotFinite {
            what: "quaternion".into(),
        });
    }
    // The norm of components near f64::MAX overflows to infinity, and dividing by it would
    // give a zero "unit" quaternion: such a quaternion is scaled by its largest component
    // first (only then, so that every other one normalises bit for bit as before).
    let q = if q.norm().is_finite() {
        q
    } else {
        q / q.coords.amax()
    };
    UnitQuaternion::try_new(q, 1e-9)
        .ok_or_else(|| SlamError::Degenerate("quaternion with zero norm".into()))
}

/// `transform` with its quaternion renormalised to unit length. Chained products of
/// transforms drift off unit length by rounding, and the drift grows with every product; call
/// this on a pose composed once per frame. Frames and units are those of `transform`.
pub fn renormalized(transform: &Isometry3<f64>) -> Isometry3<f64> {
    Isometry3::from_parts(
        transform.translation,
        UnitQuaternion::new_normalize(*transform.rotation.quaternion()),
    )
}

/// The transform of a TUM trajectory line `tx ty tz qx qy qz qw` (metres, Hamilton quaternion).
/// TUM lines give `world_from_camera`.
///
/// # Errors
/// As [`quaternion_from_xyzw`], and [`SlamError::NotFinite`] for a non-finite translation.
pub fn isometry_from_tum(values: &[f64; 7]) -> Result<Isometry3<f64>, SlamError> {
    let [tx, ty, tz, qx, qy, qz, qw] = *values;
    if ![tx, ty, tz].iter().all(|c| c.is_finite()) {
        return Err(SlamError::NotFinite {
            what: "translation".into(),
        });
    }
    let rotation = quaternion_from_xyzw(qx, qy, qz, qw)?;
    Ok(Isometry3::from_parts(
        Translation3::new(tx, ty, tz),
        rotation,
    ))
}

/// The TUM values `tx ty tz qx qy qz qw` of a transform. The quaternion is returned with
/// qw ≥ 0 so that identical rotations give identical text.
pub fn tum_from_isometry(transform: &Isometry3<f64>) -> [f64; 7] {
    let t = transform.translation.vector;
    let mut q = *transform.rotation.quaternion();
    if q.w < 0.0 {
        q = -q;
    }
    [t.x, t.y, t.z, q.i, q.j, q.k, q.w]
}

/// Checks that every component of a transform is finite.
///
/// # Errors
/// [`SlamError::NotFinite`] naming `what`.
pub fn check_finite_isometry(transform: &Isometry3<f64>, what: &str) -> Result<(), SlamError> {
    let finite = transform.translation.vector.iter().all(|c| c.is_finite())
        && transform.rotation.coords.iter().all(|c| c.is_finite());
    if finite {
        Ok(())
    } else {
        Err(SlamError::NotFinite { what: what.into() })
    }
}

/// `world_from_camera` for an OpenCV camera at `eye` looking at `target`, with image "up" as
/// close to `world_up` as possible (camera y points away from `world_up`).
///
/// # Errors
/// [`SlamError::Degenerate`] when the eye is on the target or the view direction is parallel to
/// `world_up`; [`SlamError::NotFinite`] for non-finite input.
pub fn look_at(
    eye: &Point3<f64>,
    target: &Point3<f64>,
    world_up: &Vector3<f64>,
) -> Result<Isometry3<f64>, SlamError> {
    if !(eye
        .coords
        .iter()
        .chain(target.coords.iter())
        .chain(world_up.iter()))
    .all(|c| c.is_finite())
    {
        return Err(SlamError::NotFinite {
            what: "look_at input".into(),
        });
    }
    let forward = target - eye;
    let forward_norm = forward.norm();
    if forward_norm < 1e-12 {
        return Err(SlamError::Degenerate("look_at: eye equals target".into()));
    }
    let z = forward / forward_norm;
    let right = z.cross(world_up);
    let right_norm = right.norm();
    if right_norm < 1e-9 {
        return Err(SlamError::Degenerate(
            "look_at: view direction parallel to up".into(),
        ));
    }
    let x = right / right_norm;
    let y = z.cross(&x);
    let rotation = Rotation3::from_matrix_unchecked(nalgebra::Matrix3::from_columns(&[x, y, z]));
    Ok(Isometry3::from_parts(
        Translation3::from(eye.coords),
        UnitQuaternion::from_rotation_matrix(&rotation),
    ))
}

/// The angle of a rotation in degrees, in [0, 180].
pub fn rotation_angle_deg(rotation: &UnitQuaternion<f64>) -> f64 {
    rotation.angle().to_degrees()
}

/// Yaw, pitch and roll (radians) of a rotation in the aerospace Z-Y-X order:
/// `rotation = Rz(yaw) · Ry(pitch) · Rx(roll)`.
pub fn yaw_pitch_roll_from_rotation(rotation: &UnitQuaternion<f64>) -> (f64, f64, f64) {
    let (roll, pitch, yaw) = rotation.euler_angles();
    (yaw, pitch, roll)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn look_at_points_z_at_target_and_y_down() {
        let w = look_at(
            &Point3::new(0.0, -4.0, 2.0),
            &Point3::origin(),
            &Vector3::z(),
        )
        .unwrap();
        let target_in_camera = w.inverse() * Point3::origin();
        assert!(target_in_camera.x.abs() < 1e-12 && target_in_camera.y.abs() < 1e-12);
        assert!((target_in_camera.z - 20f64.sqrt()).abs() < 1e-12);
        // Camera y (image down) has a negative world z component.
        let y_world = w.rotation * Vector3::y();
        assert!(y_world.z < 0.0);
        // Right-handed: x × y = z.
        let x_world = w.rotation * Vector3::x();
        let z_world = w.rotation * Vector3::z();
        assert!((x_world.cross(&y_world) - z_world).norm() < 1e-12);
    }

    #[test]
    fn look_at_rejects_degenerate() {
        let p = Point3::new(1.0, 2.0, 3.0);
        assert!(look_at(&p, &p, &Vector3::z()).is_err());
        assert!(look_at(&p, &Point3::new(1.0, 2.0, 0.0), &Vector3::z()).is_err());
        assert!(look_at(&Point3::new(f64::NAN, 0.0, 0.0), &p, &Vector3::z()).is_err());
    }

    #[test]
    fn quaternion_rejects_nan_and_zero() {
        assert!(quaternion_from_xyzw(f64::NAN, 0.0, 0.0, 1.0).is_err());
        assert!(quaternion_from_xyzw(0.0, 0.0, 0.0, 0.0).is_err());
        assert!(quaternion_from_xyzw(0.0, 0.0, 1e-10, 0.0).is_err());
        // Components whose squares overflow still give the rotation they encode.
        let huge = quaternion_from_xyzw(0.0, 0.0, 1e300, 1e300).unwrap();
        let quarter_turn =
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), std::f64::consts::FRAC_PI_2);
        assert!(huge.angle_to(&quarter_turn) < 1e-12, "{huge}");
        let q = quaternion_from_xyzw(0.0, 0.0, 0.0, 2.0).unwrap();
        assert!((q.w - 1.0).abs() < 1e-15);
    }

    proptest! {
        #[test]
        fn tum_round_trip(tx in -100.0f64..100.0, ty in -100.0f64..100.0, tz in -100.0f64..100.0,
                          ax in -3.0f64..3.0, ay in -3.0f64..3.0, az in -3.0f64..3.0) {
            let iso = Isometry3::new(Vector3::new(tx, ty, tz), Vector3::new(ax, ay, az));
            let back = isometry_from_tum(&tum_from_isometry(&iso)).unwrap();
            prop_assert!((back.translation.vector - iso.translation.vector).norm() < 1e-12);
            prop_assert!(back.rotation.angle_to(&iso.rotation) < 1e-9);
        }

        #[test]
        fn yaw_pitch_roll_recompose(yaw in -3.1f64..3.1, pitch in -1.5f64..1.5, roll in -3.1f64..3.1) {
            let q = UnitQuaternion::from_euler_angles(roll, pitch, yaw);
            let (y, p, r) = yaw_pitch_roll_from_rotation(&q);
            let back = UnitQuaternion::from_euler_angles(r, p, y);
            prop_assert!(back.angle_to(&q) < 1e-9);
        }
    }
}
