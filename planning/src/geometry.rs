//! Shared geometric types: waypoints, paths, angles, the target's point-set statistics and its
//! vertical bounding cylinder. All positions are world ENU metres (x east, y north, z up).

use nalgebra::{Point3, Vector3};
use scarp_slam::geometry::{eigenpairs_ascending, mean_and_scatter};
use serde::{Deserialize, Serialize};

use crate::error::{PlanError, check_finite, check_point, check_positive};

/// One keypoint of a path: where the vehicle (body origin) should pass and where it should point.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Waypoint {
    /// Position of the body origin in the world frame (ENU, metres).
    pub position_m: Point3<f64>,
    /// Heading: the angle of the body x axis from world east, counter-clockwise seen from above
    /// (radians). Paths keep it unwrapped (continuous, not reduced to (-π, π]) so that the yaw
    /// trajectory never takes a detour.
    pub yaw_rad: f64,
}

impl Waypoint {
    /// Creates a waypoint at `position_m` with heading `yaw_rad`.
    pub fn new(position_m: Point3<f64>, yaw_rad: f64) -> Self {
        Self {
            position_m,
            yaw_rad,
        }
    }

    /// Checks that position and yaw are finite; `field` names the waypoint in the error.
    pub fn validate(&self, field: &str) -> Result<(), PlanError> {
        check_point(format!("{field}.position_m"), &self.position_m)?;
        check_finite(format!("{field}.yaw_rad"), self.yaw_rad)?;
        Ok(())
    }
}

/// An ordered list of waypoints (a geometric path, no timing).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Path {
    /// The keypoints, in flying order.
    pub waypoints: Vec<Waypoint>,
}

impl Path {
    /// Wraps a list of waypoints.
    pub fn new(waypoints: Vec<Waypoint>) -> Self {
        Self { waypoints }
    }

    /// Total length of the straight segments between waypoints (metres).
    pub fn length_m(&self) -> f64 {
        self.waypoints
            .windows(2)
            .map(|w| (w[1].position_m - w[0].position_m).norm())
            .sum()
    }

    /// Checks every waypoint for NaN or infinite values.
    pub fn validate(&self) -> Result<(), PlanError> {
        for (i, w) in self.waypoints.iter().enumerate() {
            w.validate(&format!("waypoints[{i}]"))?;
        }
        Ok(())
    }
}

/// Wraps an angle to (-π, π].
pub fn wrap_angle(angle_rad: f64) -> f64 {
    let two_pi = std::f64::consts::TAU;
    let mut a = angle_rad.rem_euclid(two_pi);
    if a > std::f64::consts::PI {
        a -= two_pi;
    }
    a
}

/// Returns the representative of `angle_rad` (mod 2π) that is closest to `reference_rad`.
pub fn unwrap_near(angle_rad: f64, reference_rad: f64) -> f64 {
    reference_rad + wrap_angle(angle_rad - reference_rad)
}

/// Yaw (radians) of a body at `from` whose x axis points horizontally toward `to`.
///
/// Returns 0 when the two points are vertically aligned.
pub fn yaw_toward(from: &Point3<f64>, to: &Point3<f64>) -> f64 {
    let d = to - from;
    if d.x.abs() < 1e-12 && d.y.abs() < 1e-12 {
        0.0
    } else {
        d.y.atan2(d.x)
    }
}

/// Principal component analysis of a point set (the paper's ellipsoid of the target points).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PointSetPca {
    /// Centroid C_e of the points (world ENU, metres).
    pub centroid_m: Point3<f64>,
    /// Eigenvalues of the covariance (m²), ascending.
    pub eigenvalues_m2: [f64; 3],
    /// Unit eigenvectors matching `eigenvalues_m2`, forming a right-handed frame
    /// (`axes[0] × axes[1] = axes[2]`). `axes[0]` is the smallest eigenvector υ, signed so that
    /// υ_z ≥ 0.
    pub axes: [Vector3<f64>; 3],
}

impl PointSetPca {
    /// Computes the PCA of `points`.
    ///
    /// Fails if fewer than 3 points are given or any coordinate is not finite.
    pub fn from_points(points: &[Point3<f64>]) -> Result<Self, PlanError> {
        if points.len() < 3 {
            return Err(PlanError::TooFew {
                field: "points".into(),
                got: points.len(),
                need: 3,
            });
        }
        for (i, p) in points.iter().enumerate() {
            check_point(format!("points[{i}]"), p)?;
        }
        let (centroid_m, scatter) = mean_and_scatter(points);
        let pairs = eigenpairs_ascending(&(scatter / points.len() as f64));
        let mut axes = pairs.map(|(_, vector)| vector.normalize());
        if axes[0].z < 0.0 {
            axes[0] = -axes[0];
        }
        // Make the frame right-handed (DESIGN errata: never negate an axis arbitrarily).
        axes[2] = axes[0].cross(&axes[1]);
        Ok(Self {
            centroid_m,
            eigenvalues_m2: pairs.map(|(value, _)| value.max(0.0)),
            axes,
        })
    }

    /// The smallest eigenvector υ, with υ_z ≥ 0.
    pub fn smallest_axis(&self) -> Vector3<f64> {
        self.axes[0]
    }
}

/// A vertical cylinder in the world frame: the bounding volume of a target (paper §IV).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct VerticalCylinder {
    /// World x of the axis (metres).
    pub center_x_m: f64,
    /// World y of the axis (metres).
    pub center_y_m: f64,
    /// Radius r_e (metres).
    pub radius_m: f64,
    /// World z of the bottom face Z_n (metres).
    pub z_bottom_m: f64,
    /// World z of the top face Z_m (metres).
    pub z_top_m: f64,
}

impl VerticalCylinder {
    /// Creates a cylinder, checking that all values are finite, the radius is > 0 and the top is
    /// above the bottom.
    pub fn new(
        center_x_m: f64,
        center_y_m: f64,
        radius_m: f64,
        z_bottom_m: f64,
        z_top_m: f64,
    ) -> Result<Self, PlanError> {
        let c = Self {
            center_x_m,
            center_y_m,
            radius_m,
            z_bottom_m,
            z_top_m,
        };
        c.validate()?;
        Ok(c)
    }

    /// Checks the invariants listed in [`VerticalCylinder::new`].
    pub fn validate(&self) -> Result<(), PlanError> {
        check_finite("cylinder.center_x_m", self.center_x_m)?;
        check_finite("cylinder.center_y_m", self.center_y_m)?;
        check_positive("cylinder.radius_m", self.radius_m)?;
        check_finite("cylinder.z_bottom_m", self.z_bottom_m)?;
        check_finite("cylinder.z_top_m", self.z_top_m)?;
        if self.z_top_m <= self.z_bottom_m {
            return Err(PlanError::InvalidParameter {
                field: "cylinder.z_top_m".into(),
                value: self.z_top_m,
                reason: format!("must be above z_bottom_m = {}", self.z_bottom_m),
            });
        }
        Ok(())
    }

    /// The paper's fit: the axis passes through the centroid C_e of the points, the top is the
    /// highest point, the bottom the lowest, and the radius is the smallest that holds every
    /// point.
    ///
    /// Fails on fewer than 3 points, non-finite points, a zero radius (all points on one
    /// vertical line) or zero height.
    pub fn bounding(points: &[Point3<f64>]) -> Result<Self, PlanError> {
        let pca = PointSetPca::from_points(points)?;
        let c = pca.centroid_m;
        let radius = points
            .iter()
            .map(|p| ((p.x - c.x).powi(2) + (p.y - c.y).powi(2)).sqrt())
            .fold(0.0_f64, f64::max);
        let z_bottom = points.iter().map(|p| p.z).fold(f64::INFINITY, f64::min);
        let z_top = points.iter().map(|p| p.z).fold(f64::NEG_INFINITY, f64::max);
        Self::new(c.x, c.y, radius, z_bottom, z_top)
    }

    /// Height of the cylinder (metres).
    pub fn height_m(&self) -> f64 {
        self.z_top_m - self.z_bottom_m
    }

    /// A point on the axis at height `z_m`.
    pub fn axis_point(&self, z_m: f64) -> Point3<f64> {
        Point3::new(self.center_x_m, self.center_y_m, z_m)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wrap_and_unwrap() {
        use std::f64::consts::PI;
        assert!((wrap_angle(3.0 * PI) - PI).abs() < 1e-12);
        assert!((wrap_angle(-PI) - PI).abs() < 1e-12);
        assert!((unwrap_near(0.1, 4.0 * PI) - (4.0 * PI + 0.1)).abs() < 1e-12);
    }

    #[test]
    fn pca_axes_right_handed_and_up() {
        let pts: Vec<Point3<f64>> = (0..200)
            .map(|i| {
                let t = i as f64 * 0.37;
                Point3::new(
                    3.0 * t.sin(),
                    1.0 * (1.3 * t).cos(),
                    0.2 * (2.1 * t).sin() - 0.5,
                )
            })
            .collect();
        let pca = PointSetPca::from_points(&pts).unwrap();
        assert!(pca.axes[0].z >= 0.0);
        let det = nalgebra::Matrix3::from_columns(&pca.axes).determinant();
        assert!((det - 1.0).abs() < 1e-9);
        assert!(pca.eigenvalues_m2[0] <= pca.eigenvalues_m2[1]);
        assert!(pca.eigenvalues_m2[1] <= pca.eigenvalues_m2[2]);
    }

    #[test]
    fn cylinder_rejects_zero_radius() {
        let err = VerticalCylinder::new(0.0, 0.0, 0.0, 0.0, 2.0).unwrap_err();
        assert!(
            matches!(err, PlanError::InvalidParameter { ref field, .. } if field == "cylinder.radius_m")
        );
        let pts = vec![
            Point3::new(1.0, 1.0, 0.0),
            Point3::new(1.0, 1.0, 1.0),
            Point3::new(1.0, 1.0, 2.0),
        ];
        assert!(VerticalCylinder::bounding(&pts).is_err());
    }
}
