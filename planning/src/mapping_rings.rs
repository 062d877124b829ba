//! Mapping path (paper §IV): horizontal rings around the target's vertical bounding cylinder.
//!
//! Geometry: the camera is pitched down by γ and its vertical scan spans β (slightly less than
//! the vertical field of view, so consecutive scans overlap). From a ring at height z and
//! radius r_e + r_m, the lower scan ray (depression γ + β/2) meets the cylinder surface, r_m
//! away horizontally, at z − r_m·tan(γ + β/2), and the upper ray (depression γ − β/2) at
//! z − r_m·tan(γ − β/2): that is the ring's band on the cylinder. The first ring is placed so
//! that its lower ray just reaches the cylinder bottom; further rings are stacked upward, each
//! band overlapping the previous one by a fraction, until an upper ray reaches the top.
//!
//! Ring direction alternates (DESIGN errata), so the yaw, always toward the axis, turns one way
//! around a ring and back around the next and never winds up.

use std::ops::Range;

use nalgebra::Point3;
use serde::{Deserialize, Serialize};

use crate::camera::CameraConfig;
use crate::clearance::{ClearanceConfig, ClearanceReport, Environment, Repair};
use crate::error::{PlanError, check_positive, check_range};
use crate::geometry::{Path, VerticalCylinder, Waypoint, unwrap_near, yaw_toward};

/// Tunables of the mapping rings.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct MappingRingConfig {
    /// Horizontal standoff r_m between the ring and the cylinder surface (m). Default 1.5
    /// (DESIGN defaults; the seed code's `dist`).
    pub standoff_m: f64,
    /// Vertical scanning angle β (degrees), a little smaller than the camera's vertical field of
    /// view. Default 40 (paper §V).
    pub vertical_scan_deg: f64,
    /// Waypoints a ring (distinct azimuths; the ring is closed by one more waypoint back at the
    /// first azimuth). Default 15 (DESIGN defaults).
    pub waypoints_per_ring: usize,
    /// Fraction of a band that overlaps the band below it. Default 0.1 (ours; β < VFOV already
    /// adds image overlap beyond the bands).
    pub ring_overlap_fraction: f64,
    /// Direction of the first ring seen from above. Default true (counter-clockwise).
    pub first_ring_counter_clockwise: bool,
    /// Refuse cylinders that need more rings than this. Default 20.
    pub max_rings: usize,
    /// How far below the terrain the cylinder's centre may lie before the target is rejected as
    /// underground (m). Default 0.5.
    pub below_terrain_tolerance_m: f64,
}

impl Default for MappingRingConfig {
    fn default() -> Self {
        Self {
            standoff_m: 1.5,
            vertical_scan_deg: 40.0,
            waypoints_per_ring: 15,
            ring_overlap_fraction: 0.1,
            first_ring_counter_clockwise: true,
            max_rings: 20,
            below_terrain_tolerance_m: 0.5,
        }
    }
}

impl MappingRingConfig {
    /// Checks the values, and that both scan rays point below the horizon and above the nadir
    /// for `camera`.
    pub fn validate(&self, camera: &CameraConfig) -> Result<(), PlanError> {
        camera.validate()?;
        check_positive("mapping.standoff_m", self.standoff_m)?;
        check_range(
            "mapping.vertical_scan_deg",
            self.vertical_scan_deg,
            1.0,
            170.0,
        )?;
        check_range(
            "mapping.ring_overlap_fraction",
            self.ring_overlap_fraction,
            0.0,
            0.9,
        )?;
        check_range(
            "mapping.below_terrain_tolerance_m",
            self.below_terrain_tolerance_m,
            0.0,
            1e3,
        )?;
        if self.waypoints_per_ring < 3 {
            return Err(PlanError::InvalidParameter {
                field: "mapping.waypoints_per_ring".into(),
                value: self.waypoints_per_ring as f64,
                reason: "must be at least 3".into(),
            });
        }
        if self.max_rings == 0 {
            return Err(PlanError::InvalidParameter {
                field: "mapping.max_rings".into(),
                value: 0.0,
                reason: "must be at least 1".into(),
            });
        }
        let (lower, upper) = scan_depressions_rad(camera, self);
        if lower >= 89.0f64.to_radians() || upper <= -89.0f64.to_radians() {
            return Err(PlanError::InvalidParameter {
                field: "mapping.vertical_scan_deg".into(),
                value: self.vertical_scan_deg,
                reason: format!(
                    "scan rays at γ ± β/2 = {:.1}°/{:.1}° must stay within ±89° of the horizon",
                    lower.to_degrees(),
                    upper.to_degrees()
                ),
            });
        }
        if upper >= lower {
            return Err(PlanError::InvalidParameter {
                field: "mapping.vertical_scan_deg".into(),
                value: self.vertical_scan_deg,
                reason: "scan band is empty".into(),
            });
        }
        Ok(())
    }
}

/// Depression angles (below the horizon, radians) of the lower and upper scan rays,
/// γ + β/2 and γ − β/2.
pub fn scan_depressions_rad(camera: &CameraConfig, cfg: &MappingRingConfig) -> (f64, f64) {
    let g = camera.pitch_down_rad();
    let hb = 0.5 * cfg.vertical_scan_deg.to_radians();
    (g + hb, g - hb)
}

/// One horizontal ring.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Ring {
    /// World x of the centre (on the cylinder axis, m).
    pub center_x_m: f64,
    /// World y of the centre (m).
    pub center_y_m: f64,
    /// Height (world z, m).
    pub z_m: f64,
    /// Radius r_e + r_m (after repairs, possibly wider) (m).
    pub radius_m: f64,
    /// Direction seen from above.
    pub counter_clockwise: bool,
    /// Lowest height on the cylinder surface covered by the scan band (m).
    pub band_bottom_m: f64,
    /// Highest height on the cylinder surface covered by the scan band (m).
    pub band_top_m: f64,
}

impl Ring {
    fn with_band(mut self, cylinder: &VerticalCylinder, lower: f64, upper: f64) -> Self {
        let s = self.radius_m - cylinder.radius_m;
        self.band_bottom_m = self.z_m - s * lower.tan();
        self.band_top_m = self.z_m - s * upper.tan();
        self
    }

    /// Point of the ring at azimuth `azimuth_rad` (from east, counter-clockwise).
    pub fn point_at(&self, azimuth_rad: f64) -> Point3<f64> {
        Point3::new(
            self.center_x_m + self.radius_m * azimuth_rad.cos(),
            self.center_y_m + self.radius_m * azimuth_rad.sin(),
            self.z_m,
        )
    }
}

/// The planned rings and the path that flies them.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RingPlan {
    /// The target's cylinder.
    pub cylinder: VerticalCylinder,
    /// Rings in flying order (bottom up).
    pub rings: Vec<Ring>,
    /// The path: the start pose, the approach, then each ring (closed) in turn.
    pub path: Path,
    /// For each ring, the range of `path.waypoints` that lies on it.
    pub ring_waypoints: Vec<Range<usize>>,
    /// Azimuth (from the axis, rad) where every ring starts and ends.
    pub start_azimuth_rad: f64,
    /// Repairs made for clearance.
    pub repairs: Vec<Repair>,
    /// Clearance of the final path, when an environment was given.
    pub clearance: Option<ClearanceReport>,
}

impl RingPlan {
    /// Scan bands (bottom, top) of the rings on the cylinder surface, in ring order (m).
    pub fn vertical_coverage(&self) -> Vec<(f64, f64)> {
        self.rings
            .iter()
            .map(|r| (r.band_bottom_m, r.band_top_m))
            .collect()
    }

    /// The parts of [z_bottom, z_top] that no band covers (m). Empty when covered.
    pub fn coverage_gaps(&self) -> Vec<(f64, f64)> {
        let mut bands = self.vertical_coverage();
        bands.sort_by(|a, b| a.0.total_cmp(&b.0));
        let mut gaps = Vec::new();
        let mut covered_to = self.cylinder.z_bottom_m;
        // Rounding in the band formulas must not show up as a gap.
        let tol = 1e-9 * (1.0 + self.cylinder.z_top_m.abs());
        for (lo, hi) in bands {
            if lo > covered_to + tol && covered_to < self.cylinder.z_top_m {
                gaps.push((covered_to, lo.min(self.cylinder.z_top_m)));
            }
            covered_to = covered_to.max(hi);
        }
        if covered_to + tol < self.cylinder.z_top_m {
            gaps.push((covered_to, self.cylinder.z_top_m));
        }
        gaps
    }
}

/// Ring heights for `cylinder` (world z, m), bottom up, before any repair.
///
/// Fails on an invalid configuration or cylinder, or if more than `cfg.max_rings` are needed.
pub fn ring_heights(
    cylinder: &VerticalCylinder,
    camera: &CameraConfig,
    cfg: &MappingRingConfig,
) -> Result<Vec<f64>, PlanError> {
    cfg.validate(camera)?;
    cylinder.validate()?;
    let (lower, upper) = scan_depressions_rad(camera, cfg);
    let s = cfg.standoff_m;
    let band = s * (lower.tan() - upper.tan());
    let step = band * (1.0 - cfg.ring_overlap_fraction);
    let z_first = cylinder.z_bottom_m + s * lower.tan();
    let top_of_first = z_first - s * upper.tan();
    let extra = ((cylinder.z_top_m - top_of_first) / step).ceil().max(0.0) as usize;
    let n = 1 + extra;
    if n > cfg.max_rings {
        return Err(PlanError::InvalidParameter {
            field: "cylinder.z_top_m".into(),
            value: cylinder.z_top_m,
            reason: format!(
                "needs {n} rings, more than mapping.max_rings = {}",
                cfg.max_rings
            ),
        });
    }
    Ok((0..n).map(|k| z_first + k as f64 * step).collect())
}

/// Plans the rings around `cylinder`, starting from the vehicle pose `start` (the first
/// waypoint of the path). Rings start at the azimuth nearest the start.
///
/// Fails on NaN input, a zero or negative radius, an invalid configuration, or too many rings.
pub fn plan_mapping_rings(
    cylinder: &VerticalCylinder,
    start: &Waypoint,
    camera: &CameraConfig,
    cfg: &MappingRingConfig,
) -> Result<RingPlan, PlanError> {
    start.validate("start")?;
    let heights = ring_heights(cylinder, camera, cfg)?;
    let (lower, upper) = scan_depressions_rad(camera, cfg);
    let axis = cylinder.axis_point(start.position_m.z);
    let start_azimuth = if (start.position_m.xy() - axis.xy()).norm() > 1e-6 {
        yaw_toward(&axis, &start.position_m)
    } else {
        start.yaw_rad
    };
    let rings = heights
        .iter()
        .enumerate()
        .map(|(k, &z)| {
            Ring {
                center_x_m: cylinder.center_x_m,
                center_y_m: cylinder.center_y_m,
                z_m: z,
                radius_m: cylinder.radius_m + cfg.standoff_m,
                counter_clockwise: cfg.first_ring_counter_clockwise == (k % 2 == 0),
                band_bottom_m: 0.0,
                band_top_m: 0.0,
            }
            .with_band(cylinder, lower, upper)
        })
        .collect();
    Ok(assemble(
        cylinder,
        start,
        rings,
        start_azimuth,
        cfg.waypoints_per_ring,
        Vec::new(),
        None,
    ))
}

fn assemble(
    cylinder: &VerticalCylinder,
    start: &Waypoint,
    rings: Vec<Ring>,
    start_azimuth: f64,
    n: usize,
    repairs: Vec<Repair>,
    approach_via: Option<Waypoint>,
) -> RingPlan {
    let mut wps = vec![*start];
    if let Some(v) = approach_via {
        wps.push(v);
    }
    let mut yaw = wps[wps.len() - 1].yaw_rad;
    let mut ranges = Vec::with_capacity(rings.len());
    for (k, ring) in rings.iter().enumerate() {
        let first = ring.point_at(start_azimuth);
        let toward_axis = yaw_toward(&first, &cylinder.axis_point(first.z));
        if k == 0 {
            yaw = unwrap_near(toward_axis, yaw);
        }
        let sign = if ring.counter_clockwise { 1.0 } else { -1.0 };
        let begin = wps.len();
        for j in 0..=n {
            let da = sign * std::f64::consts::TAU * j as f64 / n as f64;
            let p = ring.point_at(start_azimuth + da);
            let w = Waypoint::new(p, yaw + da);
            // Skip a duplicate of the previous waypoint (e.g. the start already on the ring).
            if let Some(last) = wps.last()
                && (last.position_m - w.position_m).norm() < 1e-6
                && (last.yaw_rad - w.yaw_rad).abs() < 1e-9
            {
                continue;
            }
            wps.push(w);
        }
        yaw += sign * std::f64::consts::TAU;
        ranges.push(begin..wps.len());
    }
    RingPlan {
        cylinder: *cylinder,
        rings,
        path: Path::new(wps),
        ring_waypoints: ranges,
        start_azimuth_rad: start_azimuth,
        repairs,
        clearance: None,
    }
}

/// Samples a full ring every `spacing_m` of arc and returns its clearance report.
fn ring_clearance(ring: &Ring, env: &Environment, ccfg: &ClearanceConfig) -> ClearanceReport {
    let n = ((std::f64::consts::TAU * ring.radius_m / ccfg.path_sample_spacing_m).ceil() as usize)
        .max(8);
    let pts: Vec<Point3<f64>> = (0..n)
        .map(|k| ring.point_at(std::f64::consts::TAU * k as f64 / n as f64))
        .collect();
    env.check_points(pts.iter(), ccfg)
}

/// Like [`plan_mapping_rings`], then makes the plan keep `ccfg.min_clearance_m` from `env`.
///
/// A ring that comes too close is first slid up and out along its lower scan ray in steps of
/// `ccfg.repair_step_m` (which keeps its band's bottom, so coverage is kept), then, if that
/// fails, raised in place. A blocked approach from the start is replaced by a path that first
/// flies level at the higher of the start and first-ring heights. Fails with
/// [`PlanError::TargetBelowTerrain`] if the cylinder's centre is underground, and with
/// [`PlanError::Clearance`] if no repair within `ccfg.max_raise_m` works.
pub fn plan_mapping_rings_clear(
    cylinder: &VerticalCylinder,
    start: &Waypoint,
    camera: &CameraConfig,
    cfg: &MappingRingConfig,
    env: &Environment,
    ccfg: &ClearanceConfig,
) -> Result<RingPlan, PlanError> {
    ccfg.validate()?;
    cylinder.validate()?;
    env.ensure_above_terrain(
        &cylinder.axis_point(0.5 * (cylinder.z_bottom_m + cylinder.z_top_m)),
        cfg.below_terrain_tolerance_m,
    )?;
    let plan = plan_mapping_rings(cylinder, start, camera, cfg)?;
    let (lower, upper) = scan_depressions_rad(camera, cfg);
    let mut repairs = Vec::new();
    let mut rings = plan.rings.clone();
    let steps = (ccfg.max_raise_m / ccfg.repair_step_m).floor() as usize;
    for (k, ring) in rings.iter_mut().enumerate() {
        let report = ring_clearance(ring, env, ccfg);
        if report.is_clear() {
            continue;
        }
        let mut fixed = None;
        // Slide along the lower ray: raise Δ, widen Δ / tan(lower).
        for s in 1..=steps {
            let raise = s as f64 * ccfg.repair_step_m;
            let widen = raise / lower.tan();
            let cand = Ring {
                z_m: ring.z_m + raise,
                radius_m: ring.radius_m + widen,
                ..*ring
            }
            .with_band(cylinder, lower, upper);
            if ring_clearance(&cand, env, ccfg).is_clear() {
                fixed = Some((
                    cand,
                    Repair::SlidRing {
                        ring: k,
                        raise_m: raise,
                        widen_m: widen,
                    },
                ));
                break;
            }
        }
        if fixed.is_none() {
            for s in 1..=steps {
                let raise = s as f64 * ccfg.repair_step_m;
                let cand = Ring {
                    z_m: ring.z_m + raise,
                    ..*ring
                }
                .with_band(cylinder, lower, upper);
                if ring_clearance(&cand, env, ccfg).is_clear() {
                    fixed = Some((
                        cand,
                        Repair::RaisedRing {
                            ring: k,
                            raise_m: raise,
                        },
                    ));
                    break;
                }
            }
        }
        match fixed {
            Some((cand, rep)) => {
                *ring = cand;
                repairs.push(rep);
            }
            None => {
                return Err(report.to_error(format!(
                    "ring {k} at z = {:.2} m: neither sliding out nor raising by up to {} m clears it",
                    ring.z_m, ccfg.max_raise_m
                )));
            }
        }
    }
    let n = cfg.waypoints_per_ring;
    let mut out = assemble(
        cylinder,
        start,
        rings.clone(),
        plan.start_azimuth_rad,
        n,
        repairs.clone(),
        None,
    );
    let mut report = env.check_path(&out.path, ccfg);
    if !report.is_clear() {
        // Approach level at the higher altitude, then straight down or up to the first ring.
        let first = rings[0].point_at(plan.start_azimuth_rad);
        let z = start.position_m.z.max(first.z);
        let via_pos = if start.position_m.z >= first.z {
            Point3::new(first.x, first.y, z)
        } else {
            Point3::new(start.position_m.x, start.position_m.y, z)
        };
        if (via_pos - start.position_m).norm() > 1e-6 && (via_pos - first).norm() > 1e-6 {
            let via = Waypoint::new(via_pos, start.yaw_rad);
            let alt = assemble(
                cylinder,
                start,
                rings,
                plan.start_azimuth_rad,
                n,
                repairs,
                Some(via),
            );
            let alt_report = env.check_path(&alt.path, ccfg);
            if alt_report.is_clear() {
                out = alt;
                report = alt_report;
            }
        }
    }
    report.ensure_clear("the approach or a ring transition is blocked")?;
    out.clearance = Some(report);
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn two_metre_rock_gets_one_ring_and_full_coverage() {
        let cyl = VerticalCylinder::new(0.0, 0.0, 1.0, 0.0, 2.0).unwrap();
        let start = Waypoint::new(Point3::new(10.0, 0.0, 6.0), 0.0);
        let plan = plan_mapping_rings(
            &cyl,
            &start,
            &CameraConfig::default(),
            &MappingRingConfig::default(),
        )
        .unwrap();
        assert!(!plan.rings.is_empty());
        assert!(
            plan.coverage_gaps().is_empty(),
            "{:?}",
            plan.coverage_gaps()
        );
        assert!((plan.rings[0].band_bottom_m - 0.0).abs() < 1e-12);
    }

    #[test]
    fn tall_pillar_alternates_and_yaw_unwinds_back() {
        let cyl = VerticalCylinder::new(5.0, -3.0, 2.0, 10.0, 25.0).unwrap();
        let start = Waypoint::new(Point3::new(5.0, -20.0, 30.0), 1.0);
        let plan = plan_mapping_rings(
            &cyl,
            &start,
            &CameraConfig::default(),
            &MappingRingConfig::default(),
        )
        .unwrap();
        assert!(plan.rings.len() >= 3);
        for w in plan.rings.windows(2) {
            assert_ne!(w[0].counter_clockwise, w[1].counter_clockwise);
            assert!(w[1].band_bottom_m <= w[0].band_top_m);
        }
        // Past the start pose, the yaw sweeps one turn and comes back: never more than 2π.
        let yaws: Vec<f64> = plan.path.waypoints[1..].iter().map(|w| w.yaw_rad).collect();
        let span = yaws.iter().cloned().fold(f64::NEG_INFINITY, f64::max)
            - yaws.iter().cloned().fold(f64::INFINITY, f64::min);
        assert!(span <= std::f64::consts::TAU + 1e-9, "yaw span {span}");
        for r in &plan.ring_waypoints {
            assert_eq!(r.len(), 16);
        }
    }
}
