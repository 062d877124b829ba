//! Lawn-mower (boustrophedon) search over a rectangle or polygon at the search altitude h_s.
//!
//! Lanes run along a heading; the lane spacing is the camera footprint width across the lane
//! (at the principal point's row by default) times (1 − side overlap), shrunk so that a whole
//! number of lanes spans the area. The vehicle faces along each lane, so the forward-pitched
//! camera looks ahead; the yaw turns half a turn one way at one end and back at the next, so it
//! never winds up.

use nalgebra::{Point3, Vector2};
use serde::{Deserialize, Serialize};

use crate::camera::{CameraConfig, Footprint};
use crate::clearance::{ClearanceConfig, ClearanceReport, Environment, Repair};
use crate::error::{PlanError, check_finite, check_range};
use crate::geometry::{Path, Waypoint};

/// Which image row's footprint width sets the lane spacing.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum FootprintRow {
    /// Bottom row (nearest, narrowest): the most conservative.
    Near,
    /// Principal point's row.
    Center,
    /// Top row (farthest, widest).
    Far,
}

/// Tunables of the lawn-mower pattern.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CoverageConfig {
    /// Side overlap between neighbouring lanes' footprints (fraction). Default 0.3 (issue 8).
    pub side_overlap: f64,
    /// Lane heading (degrees from east, counter-clockwise). `None` (default) runs the lanes
    /// along the area's longest edge.
    pub lane_heading_deg: Option<f64>,
    /// Footprint row that sets the spacing. Default `Center`.
    pub footprint_row: FootprintRow,
    /// Extension of each lane beyond the area boundary (m). Default 0.
    pub lane_extension_m: f64,
}

impl Default for CoverageConfig {
    fn default() -> Self {
        Self {
            side_overlap: 0.3,
            lane_heading_deg: None,
            footprint_row: FootprintRow::Center,
            lane_extension_m: 0.0,
        }
    }
}

/// The area to search, in world (x, y) metres.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum SearchArea {
    /// An axis-aligned rectangle.
    Rectangle {
        /// West edge (m).
        min_x_m: f64,
        /// South edge (m).
        min_y_m: f64,
        /// East edge (m).
        max_x_m: f64,
        /// North edge (m).
        max_y_m: f64,
    },
    /// A simple polygon (any orientation, not closed: the last vertex connects to the first).
    Polygon {
        /// Vertices (x, y) in metres.
        vertices_m: Vec<[f64; 2]>,
    },
}

impl SearchArea {
    /// The polygon's vertices, validated: at least 3, finite, non-zero area.
    pub fn vertices(&self) -> Result<Vec<Vector2<f64>>, PlanError> {
        let v: Vec<Vector2<f64>> = match self {
            SearchArea::Rectangle {
                min_x_m,
                min_y_m,
                max_x_m,
                max_y_m,
            } => {
                for (n, x) in [
                    ("min_x_m", min_x_m),
                    ("min_y_m", min_y_m),
                    ("max_x_m", max_x_m),
                    ("max_y_m", max_y_m),
                ] {
                    check_finite(format!("area.{n}"), *x)?;
                }
                if max_x_m <= min_x_m || max_y_m <= min_y_m {
                    return Err(PlanError::InvalidParameter {
                        field: "area".into(),
                        value: (max_x_m - min_x_m).min(max_y_m - min_y_m),
                        reason: "rectangle must have max > min on both axes".into(),
                    });
                }
                vec![
                    Vector2::new(*min_x_m, *min_y_m),
                    Vector2::new(*max_x_m, *min_y_m),
                    Vector2::new(*max_x_m, *max_y_m),
                    Vector2::new(*min_x_m, *max_y_m),
                ]
            }
            SearchArea::Polygon { vertices_m } => {
                if vertices_m.len() < 3 {
                    return Err(PlanError::TooFew {
                        field: "area.vertices_m".into(),
                        got: vertices_m.len(),
                        need: 3,
                    });
                }
                let mut out = Vec::with_capacity(vertices_m.len());
                for (i, p) in vertices_m.iter().enumerate() {
                    check_finite(format!("area.vertices_m[{i}].x"), p[0])?;
                    check_finite(format!("area.vertices_m[{i}].y"), p[1])?;
                    out.push(Vector2::new(p[0], p[1]));
                }
                out
            }
        };
        let area2: f64 = (0..v.len())
            .map(|i| {
                let (a, b) = (v[i], v[(i + 1) % v.len()]);
                a.x * b.y - b.x * a.y
            })
            .sum();
        if area2.abs() < 1e-9 {
            return Err(PlanError::InvalidParameter {
                field: "area".into(),
                value: 0.5 * area2,
                reason: "polygon has zero area".into(),
            });
        }
        Ok(v)
    }
}

/// A planned lawn-mower pattern.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CoveragePlan {
    /// Lane ends in flying order, at the search altitude.
    pub path: Path,
    /// Spacing actually used between lanes (m).
    pub lane_spacing_m: f64,
    /// Lane heading (rad from east).
    pub lane_heading_rad: f64,
    /// Number of lanes.
    pub lanes: usize,
    /// Camera footprint at the search altitude over `ground_z_m`.
    pub footprint: Footprint,
    /// Search altitude used (world z, m).
    pub altitude_m: f64,
    /// Repairs made for clearance.
    pub repairs: Vec<Repair>,
    /// Clearance of the final path, when an environment was given.
    pub clearance: Option<ClearanceReport>,
}

/// Plans the lawn-mower over `area` at world height `altitude_m`, sizing the footprint for
/// ground at `ground_z_m`.
///
/// Fails on an invalid area or configuration, or when the altitude is not above the ground.
pub fn plan_lawn_mower(
    area: &SearchArea,
    altitude_m: f64,
    ground_z_m: f64,
    camera: &CameraConfig,
    cfg: &CoverageConfig,
) -> Result<CoveragePlan, PlanError> {
    check_range("coverage.side_overlap", cfg.side_overlap, 0.0, 0.95)?;
    check_range("coverage.lane_extension_m", cfg.lane_extension_m, 0.0, 1e4)?;
    check_finite("altitude_m", altitude_m)?;
    check_finite("ground_z_m", ground_z_m)?;
    let verts = area.vertices()?;
    let footprint = camera.footprint(altitude_m - ground_z_m)?;
    let width = match cfg.footprint_row {
        FootprintRow::Near => footprint.near_width_m,
        FootprintRow::Center => footprint.center_width_m,
        FootprintRow::Far => footprint.far_width_m,
    };
    let nominal = width * (1.0 - cfg.side_overlap);
    let heading = match cfg.lane_heading_deg {
        Some(h) => check_finite("coverage.lane_heading_deg", h)?.to_radians(),
        None => {
            let mut best = (0.0, 0.0);
            for i in 0..verts.len() {
                let e = verts[(i + 1) % verts.len()] - verts[i];
                if e.norm() > best.0 {
                    best = (e.norm(), e.y.atan2(e.x));
                }
            }
            best.1
        }
    };
    // Lane frame: u along the lanes, v across.
    let (c, s) = (heading.cos(), heading.sin());
    let to_lane = |p: &Vector2<f64>| Vector2::new(c * p.x + s * p.y, -s * p.x + c * p.y);
    let from_lane = |q: &Vector2<f64>| Vector2::new(c * q.x - s * q.y, s * q.x + c * q.y);
    let local: Vec<Vector2<f64>> = verts.iter().map(to_lane).collect();
    let v_min = local.iter().map(|q| q.y).fold(f64::INFINITY, f64::min);
    let v_max = local.iter().map(|q| q.y).fold(f64::NEG_INFINITY, f64::max);
    let span = v_max - v_min;
    let lanes = ((span / nominal).ceil() as usize).max(1);
    let spacing = span / lanes as f64;
    let mut wps = Vec::with_capacity(2 * lanes);
    for k in 0..lanes {
        let v = v_min + (k as f64 + 0.5) * spacing;
        // Crossings of the lane line with the polygon edges; fly from the first to the last.
        let mut xs = Vec::new();
        for i in 0..local.len() {
            let (a, b) = (local[i], local[(i + 1) % local.len()]);
            if (a.y <= v && b.y > v) || (b.y <= v && a.y > v) {
                xs.push(a.x + (v - a.y) / (b.y - a.y) * (b.x - a.x));
            }
        }
        if xs.is_empty() {
            continue;
        }
        let lo = xs.iter().cloned().fold(f64::INFINITY, f64::min) - cfg.lane_extension_m;
        let hi = xs.iter().cloned().fold(f64::NEG_INFINITY, f64::max) + cfg.lane_extension_m;
        let forward = wps.len() % 4 == 0;
        let (u0, u1, yaw) = if forward {
            (lo, hi, heading)
        } else {
            (hi, lo, heading + std::f64::consts::PI)
        };
        for u in [u0, u1] {
            let p = from_lane(&Vector2::new(u, v));
            wps.push(Waypoint::new(Point3::new(p.x, p.y, altitude_m), yaw));
        }
    }
    Ok(CoveragePlan {
        lanes: wps.len() / 2,
        path: Path::new(wps),
        lane_spacing_m: spacing,
        lane_heading_rad: heading,
        footprint,
        altitude_m,
        repairs: Vec::new(),
        clearance: None,
    })
}

/// Like [`plan_lawn_mower`], then raises the whole pattern in steps of `ccfg.repair_step_m`
/// (up to `ccfg.max_raise_m`) until it keeps `ccfg.min_clearance_m` from `env`. The footprint
/// is sized over the highest terrain node under the area's bounding box.
///
/// Fails with [`PlanError::Clearance`] when no raise clears the pattern.
pub fn plan_lawn_mower_clear(
    area: &SearchArea,
    altitude_m: f64,
    camera: &CameraConfig,
    cfg: &CoverageConfig,
    env: &Environment,
    ccfg: &ClearanceConfig,
) -> Result<CoveragePlan, PlanError> {
    ccfg.validate()?;
    let verts = area.vertices()?;
    let ground = match env.terrain() {
        Some(t) => {
            let (x0, x1) = verts
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |a, v| {
                    (a.0.min(v.x), a.1.max(v.x))
                });
            let (y0, y1) = verts
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |a, v| {
                    (a.0.min(v.y), a.1.max(v.y))
                });
            let mut hmax = f64::NEG_INFINITY;
            for j in 0..t.ny {
                for i in 0..t.nx {
                    let x = t.origin_x_m + i as f64 * t.spacing_m;
                    let y = t.origin_y_m + j as f64 * t.spacing_m;
                    if x >= x0 - t.spacing_m
                        && x <= x1 + t.spacing_m
                        && y >= y0 - t.spacing_m
                        && y <= y1 + t.spacing_m
                    {
                        hmax = hmax.max(t.node(i, j));
                    }
                }
            }
            if hmax.is_finite() {
                hmax
            } else {
                t.height_range_m().1
            }
        }
        None => altitude_m - 1.0,
    };
    if altitude_m <= ground {
        return Err(PlanError::InvalidParameter {
            field: "altitude_m".into(),
            value: altitude_m,
            reason: format!("must be above the highest terrain under the area, {ground:.2} m"),
        });
    }
    let steps = (ccfg.max_raise_m / ccfg.repair_step_m).floor() as usize;
    let mut first_err = None;
    for s in 0..=steps {
        let raise = s as f64 * ccfg.repair_step_m;
        let mut plan = plan_lawn_mower(area, altitude_m + raise, ground, camera, cfg)?;
        let report = env.check_path(&plan.path, ccfg);
        if report.is_clear() {
            if s > 0 {
                plan.repairs.push(Repair::RaisedPath { raise_m: raise });
            }
            plan.clearance = Some(report);
            return Ok(plan);
        }
        first_err.get_or_insert_with(|| {
            report.to_error(format!(
                "raising the pattern by up to {} m did not clear it",
                ccfg.max_raise_m
            ))
        });
    }
    Err(first_err.unwrap_or_else(|| PlanError::InvalidParameter {
        field: "clearance.max_raise_m".into(),
        value: ccfg.max_raise_m,
        reason: "no attempt was made".into(),
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rectangle_lanes_cover_with_overlap() {
        let area = SearchArea::Rectangle {
            min_x_m: 0.0,
            min_y_m: 0.0,
            max_x_m: 200.0,
            max_y_m: 100.0,
        };
        let cam = CameraConfig::default();
        let plan = plan_lawn_mower(&area, 30.0, 0.0, &cam, &CoverageConfig::default()).unwrap();
        let w = plan.footprint.center_width_m;
        assert!(plan.lane_spacing_m <= 0.7 * w + 1e-9);
        assert_eq!(plan.path.waypoints.len(), 2 * plan.lanes);
        assert!((plan.lane_heading_rad).abs() < 1e-12);
        // Lanes alternate direction and yaw flips by π.
        let y0 = plan.path.waypoints[0].yaw_rad;
        let y2 = plan.path.waypoints[2].yaw_rad;
        assert!((y2 - y0 - std::f64::consts::PI).abs() < 1e-12);
        // First and last lanes are within half a spacing of the edges.
        assert!((plan.path.waypoints[0].position_m.y - 0.5 * plan.lane_spacing_m).abs() < 1e-9);
    }

    #[test]
    fn polygon_and_bad_polygons() {
        let tri = SearchArea::Polygon {
            vertices_m: vec![[0.0, 0.0], [100.0, 0.0], [0.0, 100.0]],
        };
        let plan = plan_lawn_mower(
            &tri,
            40.0,
            0.0,
            &CameraConfig::default(),
            &CoverageConfig::default(),
        )
        .unwrap();
        assert!(plan.lanes >= 2);
        let bad = SearchArea::Polygon {
            vertices_m: vec![[0.0, 0.0], [1.0, 1.0], [2.0, 2.0]],
        };
        assert!(
            plan_lawn_mower(
                &bad,
                40.0,
                0.0,
                &CameraConfig::default(),
                &CoverageConfig::default()
            )
            .is_err()
        );
        let nan = SearchArea::Polygon {
            vertices_m: vec![[0.0, 0.0], [f64::NAN, 1.0], [2.0, 0.0]],
        };
        assert!(matches!(
            plan_lawn_mower(
                &nan,
                40.0,
                0.0,
                &CameraConfig::default(),
                &CoverageConfig::default()
            ),
            Err(PlanError::NonFinite { .. })
        ));
    }
}
