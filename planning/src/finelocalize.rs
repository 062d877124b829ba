//! Fine-localization path (paper §III, Motion Planning): a circle at the search altitude from
//! which the camera, pitched down by γ, looks straight at the centre of the target points, and
//! the next-best-view point on it.
//!
//! The circle C_l is centred above the point-set centre C_e = (x_e, y_e, z_e) at the search
//! altitude h_s, radius (h_s − z_e)/tan γ. The next-best view aligns the optical axis as well as
//! the fixed γ allows with the smallest PCA eigenvector υ (signed so that υ_z ≥ 0): at azimuth
//! atan2(υ_y, υ_x) around C_e. When υ is horizontal (υ_z = 0) the paper takes the point of C_l
//! farthest from the vehicle. The path goes from the current pose to the closest point of C_l,
//! then along the circle (toward the next-best view the short way round) for the configured
//! sweep, with the yaw always toward C_e.

use nalgebra::{Point2, Point3, Vector3};
use serde::{Deserialize, Serialize};

use crate::camera::CameraConfig;
use crate::clearance::{ClearanceConfig, ClearanceReport, Environment, Repair};
use crate::error::{PlanError, check_finite, check_range};
use crate::geometry::{Path, PointSetPca, Waypoint, unwrap_near, wrap_angle};

/// Tunables of the fine-localization path.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FineLocalizeConfig {
    /// Waypoints on the circle. Default 25 (DESIGN defaults; the seed code's N).
    pub waypoints: usize,
    /// Angle swept along the circle (degrees). Default 720 (DESIGN defaults).
    pub sweep_deg: f64,
    /// |υ_z| below this counts as a horizontal eigenvector (the paper's υ_z = 0 case).
    /// Default 0.02 (about 1.1°).
    pub horizontal_tolerance: f64,
    /// ‖(υ_x, υ_y)‖ below this counts as a vertical eigenvector, for which every point of the
    /// circle is equally good and the closest one is taken. Default 1e-3.
    pub vertical_tolerance: f64,
    /// How far below the terrain C_e may lie before the target is rejected (m). Default 0.5.
    pub below_terrain_tolerance_m: f64,
}

impl Default for FineLocalizeConfig {
    fn default() -> Self {
        Self {
            waypoints: 25,
            sweep_deg: 720.0,
            horizontal_tolerance: 0.02,
            vertical_tolerance: 1e-3,
            below_terrain_tolerance_m: 0.5,
        }
    }
}

impl FineLocalizeConfig {
    /// Checks the values.
    pub fn validate(&self) -> Result<(), PlanError> {
        if self.waypoints < 2 {
            return Err(PlanError::InvalidParameter {
                field: "fine_localize.waypoints".into(),
                value: self.waypoints as f64,
                reason: "must be at least 2".into(),
            });
        }
        check_range("fine_localize.sweep_deg", self.sweep_deg, 1.0, 3600.0)?;
        check_range(
            "fine_localize.horizontal_tolerance",
            self.horizontal_tolerance,
            0.0,
            1.0,
        )?;
        check_range(
            "fine_localize.vertical_tolerance",
            self.vertical_tolerance,
            0.0,
            1.0,
        )?;
        check_range(
            "fine_localize.below_terrain_tolerance_m",
            self.below_terrain_tolerance_m,
            0.0,
            1e3,
        )?;
        Ok(())
    }
}

/// Which rule chose the next-best view.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum NbvRule {
    /// υ is tilted: the circle point in the direction of υ's horizontal projection.
    Eigenvector,
    /// υ is horizontal: the circle point farthest from the vehicle.
    Farthest,
    /// υ is vertical: every point is as good; the closest one.
    Closest,
}

/// The fine-localization plan.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FineLocalizePlan {
    /// PCA of the target points.
    pub pca: PointSetPca,
    /// Centre C_l of the circle (world ENU, m); z is the search altitude used.
    pub circle_center_m: Point3<f64>,
    /// Radius of C_l (m).
    pub radius_m: f64,
    /// The next-best-view pose (yaw toward C_e).
    pub next_best_view: Waypoint,
    /// Azimuth of the next-best view around C_l (rad, from east).
    pub nbv_azimuth_rad: f64,
    /// Which rule chose it.
    pub nbv_rule: NbvRule,
    /// Index of the next-best view in `path.waypoints` (its first pass).
    pub nbv_index: usize,
    /// Current pose, closest circle point, then the arc.
    pub path: Path,
    /// Repairs made for clearance.
    pub repairs: Vec<Repair>,
    /// Clearance of the final path, when an environment was given.
    pub clearance: Option<ClearanceReport>,
}

/// Azimuth (rad) of the next-best view around the circle centre and the rule that chose it.
///
/// `pca` gives υ; `vehicle_xy` and `center_xy` are world (x, y) of the vehicle and of C_l.
pub fn next_best_view_azimuth(
    pca: &PointSetPca,
    vehicle_xy: &Point2<f64>,
    center_xy: &Point2<f64>,
    cfg: &FineLocalizeConfig,
) -> (f64, NbvRule) {
    let u = pca.smallest_axis();
    let h = (u.x * u.x + u.y * u.y).sqrt();
    let away = vehicle_xy - center_xy;
    let closest = if away.norm() > 1e-9 {
        away.y.atan2(away.x)
    } else {
        0.0
    };
    if u.z.abs() <= cfg.horizontal_tolerance {
        (
            wrap_angle(closest + std::f64::consts::PI),
            NbvRule::Farthest,
        )
    } else if h <= cfg.vertical_tolerance {
        (closest, NbvRule::Closest)
    } else {
        (u.y.atan2(u.x), NbvRule::Eigenvector)
    }
}

/// The optical axis (world, unit) of a camera at azimuth `azimuth_rad` on the circle looking at
/// the centre with depression `pitch_down_rad`.
pub fn view_direction(azimuth_rad: f64, pitch_down_rad: f64) -> Vector3<f64> {
    Vector3::new(
        -pitch_down_rad.cos() * azimuth_rad.cos(),
        -pitch_down_rad.cos() * azimuth_rad.sin(),
        -pitch_down_rad.sin(),
    )
}

/// Plans the fine-localization path for target `points` from the vehicle pose `current`, at
/// search altitude `search_altitude_m` (world z).
///
/// Fails on fewer than 3 or non-finite points, a non-finite pose or altitude, an altitude not
/// above C_e, or an invalid configuration.
pub fn plan_fine_localization(
    points: &[Point3<f64>],
    current: &Waypoint,
    search_altitude_m: f64,
    camera: &CameraConfig,
    cfg: &FineLocalizeConfig,
) -> Result<FineLocalizePlan, PlanError> {
    cfg.validate()?;
    camera.validate()?;
    current.validate("current")?;
    check_finite("search_altitude_m", search_altitude_m)?;
    let pca = PointSetPca::from_points(points)?;
    let ce = pca.centroid_m;
    if search_altitude_m <= ce.z {
        return Err(PlanError::AltitudeBelowTarget {
            search_altitude_m,
            target_z_m: ce.z,
        });
    }
    let g = camera.pitch_down_rad();
    let radius = (search_altitude_m - ce.z) / g.tan();
    let center = Point3::new(ce.x, ce.y, search_altitude_m);
    let (nbv_az, rule) = next_best_view_azimuth(&pca, &current.position_m.xy(), &center.xy(), cfg);
    let away = current.position_m.xy() - center.xy();
    let closest_az = if away.norm() > 1e-9 {
        away.y.atan2(away.x)
    } else {
        current.yaw_rad
    };
    let delta = wrap_angle(nbv_az - closest_az);
    // Toward the next-best view the short way round; counter-clockwise on a tie.
    let sign = if delta >= 0.0 { 1.0 } else { -1.0 };
    let at = |az: f64| {
        Point3::new(
            center.x + radius * az.cos(),
            center.y + radius * az.sin(),
            center.z,
        )
    };
    let sweep = cfg.sweep_deg.to_radians();
    let n = cfg.waypoints;
    // Arc parameters (unsigned angle travelled from the closest point).
    let mut params: Vec<f64> = (0..n).map(|k| sweep * k as f64 / (n - 1) as f64).collect();
    let nbv_param = delta.abs();
    let nbv_pos = match params.iter().position(|&p| (p - nbv_param).abs() < 1e-6) {
        Some(i) => i,
        None => {
            let i = params.partition_point(|&p| p < nbv_param);
            params.insert(i, nbv_param);
            i
        }
    };
    let mut wps = vec![*current];
    let first_yaw = unwrap_near(closest_az + std::f64::consts::PI, current.yaw_rad);
    let offset = usize::from(
        (at(closest_az) - current.position_m).norm() >= 1e-6
            || (first_yaw - current.yaw_rad).abs() >= 1e-9,
    );
    if offset == 0 {
        wps.clear();
    }
    for &p in &params {
        let az = closest_az + sign * p;
        wps.push(Waypoint::new(at(az), first_yaw + sign * p));
    }
    let nbv_index = nbv_pos + usize::from(offset == 1);
    let next_best_view = wps[nbv_index];
    Ok(FineLocalizePlan {
        pca,
        circle_center_m: center,
        radius_m: radius,
        next_best_view,
        nbv_azimuth_rad: nbv_az,
        nbv_rule: rule,
        nbv_index,
        path: Path::new(wps),
        repairs: Vec::new(),
        clearance: None,
    })
}

/// Like [`plan_fine_localization`], then makes the path keep `ccfg.min_clearance_m` from `env`
/// by raising the search altitude (which also widens the circle) in steps of
/// `ccfg.repair_step_m`, up to `ccfg.max_raise_m`.
///
/// Fails with [`PlanError::TargetBelowTerrain`] when C_e is underground, or
/// [`PlanError::Clearance`] when no raise clears the path.
pub fn plan_fine_localization_clear(
    points: &[Point3<f64>],
    current: &Waypoint,
    search_altitude_m: f64,
    camera: &CameraConfig,
    cfg: &FineLocalizeConfig,
    env: &Environment,
    ccfg: &ClearanceConfig,
) -> Result<FineLocalizePlan, PlanError> {
    ccfg.validate()?;
    let pca = PointSetPca::from_points(points)?;
    env.ensure_above_terrain(&pca.centroid_m, cfg.below_terrain_tolerance_m)?;
    let steps = (ccfg.max_raise_m / ccfg.repair_step_m).floor() as usize;
    let mut first_report = None;
    for s in 0..=steps {
        let raise = s as f64 * ccfg.repair_step_m;
        let mut plan =
            plan_fine_localization(points, current, search_altitude_m + raise, camera, cfg)?;
        // The whole path, including the leg from the current pose to the circle.
        let report = env.check_path(&plan.path, ccfg);
        if report.is_clear() {
            if s > 0 {
                plan.repairs.push(Repair::RaisedPath { raise_m: raise });
            }
            plan.clearance = Some(report);
            return Ok(plan);
        }
        first_report.get_or_insert(report);
    }
    // At least one iteration ran, so a report exists.
    let report = first_report.unwrap_or_else(|| env.check_path(&Path::default(), ccfg));
    Err(report.to_error(format!(
        "raising the search altitude by up to {} m did not clear the circle",
        ccfg.max_raise_m
    )))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn blob(axis_small: Vector3<f64>) -> Vec<Point3<f64>> {
        // Points spread widely in the plane ⟂ axis_small, thinly along it.
        let a = axis_small.normalize();
        let b = a.cross(&Vector3::new(0.3, -0.2, 0.9)).normalize();
        let c = a.cross(&b);
        let mut pts = Vec::new();
        for i in 0..20 {
            for j in 0..20 {
                for k in [-1.0, 1.0] {
                    let u = (i as f64 - 9.5) * 0.2;
                    let v = (j as f64 - 9.5) * 0.1;
                    pts.push(Point3::new(3.0, 4.0, 1.0) + b * u + c * v + a * (0.05 * k));
                }
            }
        }
        pts
    }

    #[test]
    fn circle_radius_and_yaw_toward_center() {
        let pts = blob(Vector3::new(0.3, 0.2, 1.0));
        let cur = Waypoint::new(Point3::new(30.0, 4.0, 20.0), 0.0);
        let plan = plan_fine_localization(
            &pts,
            &cur,
            20.0,
            &CameraConfig::default(),
            &FineLocalizeConfig::default(),
        )
        .unwrap();
        let r = (20.0 - plan.pca.centroid_m.z) / 55f64.to_radians().tan();
        assert!((plan.radius_m - r).abs() < 1e-9);
        for w in &plan.path.waypoints[1..] {
            let d = plan.pca.centroid_m - w.position_m;
            assert!((wrap_angle(d.y.atan2(d.x) - w.yaw_rad)).abs() < 1e-9);
            assert!(((w.position_m.xy() - plan.circle_center_m.xy()).norm() - r).abs() < 1e-9);
        }
        // 720° sweep: the arc ends where it started.
        let arc = &plan.path.waypoints[1..];
        assert!((arc[0].position_m - arc[arc.len() - 1].position_m).norm() < 1e-9);
    }

    #[test]
    fn horizontal_eigenvector_takes_farthest_point() {
        let pts = blob(Vector3::new(1.0, 0.0, 0.0));
        let cur = Waypoint::new(Point3::new(3.0, -20.0, 20.0), 0.0);
        let plan = plan_fine_localization(
            &pts,
            &cur,
            20.0,
            &CameraConfig::default(),
            &FineLocalizeConfig::default(),
        )
        .unwrap();
        assert_eq!(plan.nbv_rule, NbvRule::Farthest);
        assert!((wrap_angle(plan.nbv_azimuth_rad - std::f64::consts::FRAC_PI_2)).abs() < 1e-3);
    }

    #[test]
    fn altitude_below_target_is_an_error() {
        let pts = blob(Vector3::new(0.0, 0.0, 1.0));
        let cur = Waypoint::new(Point3::new(0.0, 0.0, 0.5), 0.0);
        let err = plan_fine_localization(
            &pts,
            &cur,
            0.5,
            &CameraConfig::default(),
            &FineLocalizeConfig::default(),
        )
        .unwrap_err();
        assert!(
            matches!(err, PlanError::AltitudeBelowTarget { .. }),
            "{err}"
        );
    }
}
