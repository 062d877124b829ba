//! What a mission writes: `mission.json` (the interface other tools read), `targets.geojson`
//! and `targets.csv`. Every file is written atomically, so an interrupted run leaves either the
//! old file or the new one.

use std::io::Write;
use std::path::Path;

use super::error::MissionResult;
use nalgebra::Point3;
use scarp_export::atomic::{write_atomically, write_bytes_atomically};
use scarp_export::geojson::{EnuFrame, Geodetic, PointFeature, write_geojson};
use serde::{Deserialize, Serialize};

/// The neck ring of one target in `mission.json`
/// ([`scarp_planning::prelude::NeckRingConfig`]), in the frame the vehicle flies in.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct NeckRingReport {
    /// The neck the map showed when the other rings ended (z, m); `None` where it could not be
    /// read.
    pub neck_z_m: Option<f64>,
    /// The ring's planned height (its lowest, where it follows the terrain; z, m); `None` when
    /// it was not flown.
    pub ring_z_m: Option<f64>,
    /// How far round the axis it was flown (degrees; less than 360 where trimmed).
    pub span_deg: f64,
    /// How it was changed to keep clear of terrain and rocks.
    pub repairs: Vec<scarp_planning::prelude::Repair>,
    /// Why it was not flown.
    pub not_flown: Option<String>,
    /// Frames mapped on it: the ring is mapped only while the odometry tracks every frame
    /// ([`crate::mission::mapping::GuardedStretch`]).
    #[serde(default)]
    pub frames_mapped: usize,
    /// Why its mapping stopped before its end (the first frame the odometry did not track, its
    /// simulated time and reason), and how many keyframes before it were taken out of the map;
    /// `None` where it was mapped to its end or not flown.
    #[serde(default)]
    pub mapping_stopped: Option<String>,
}

/// One target in `mission.json`. Ground-truth fields are `null` without ground truth.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct TargetReport {
    /// Mission target id (the localization target id).
    pub id: u64,
    /// Status (`mapped`, `incomplete`, …).
    pub status: String,
    /// The target's position, world ENU metres (the frame the vehicle flies in): the volume
    /// centroid of its closed scan once mapped (`center_source` `"scan"`), else the localized
    /// centre C_e (`"localization"`). `targets.csv` and `targets.geojson` give this one.
    pub center: [f64; 3],
    /// Where `center` comes from: `"localization"` (the depth filter's C_e, as
    /// `localized_center`) or `"scan"` (the closed scan's volume centroid).
    #[serde(default = "localization_source")]
    pub center_source: String,
    /// The localized centre C_e the mission planned its flight around, world ENU metres.
    #[serde(default)]
    pub localized_center: [f64; 3],
    /// The spread (1σ along east, north, up; metres) of the depth filter's point set whose
    /// mean is C_e: the filter's own statement of how far C_e may be off.
    #[serde(default)]
    pub localized_sigma_m: Option<[f64; 3]>,
    /// Axis of the bounding cylinder flown around it (x, y), world ENU metres: C_e, or where
    /// the first mapped frame's box saw the target (`mapping.recenter_on_first_frame`), in the
    /// map's frame.
    pub cylinder_center_xy: [f64; 2],
    /// The bounding cylinder's radius, metres.
    pub cylinder_radius_m: f64,
    /// Bottom of the cylinder (world z, m).
    pub cylinder_z_bottom_m: f64,
    /// Top of the cylinder (world z, m).
    pub cylinder_z_top_m: f64,
    /// Mission time the target was first registered, seconds.
    pub found_at_s: f64,
    /// Frames fused into its map.
    pub frames_mapped: usize,
    /// Frames seen while mapping but dropped: their odometry failed or strayed from the state
    /// estimate (`mapping.estimate_gate_sigmas`), and placing them by the estimate would have
    /// shifted the map (for up to `mapping.max_dropped_s` in a row).
    #[serde(default)]
    pub frames_dropped: usize,
    /// Frames after a gap in view (`mapping.reacquisition_min_gap_s`) or after dropped frames
    /// (`mapping.reacquisition_after_drops`) tracked from a search over the state estimate's
    /// walk (`mapping.reacquisition_sigmas`), kept or dropped.
    #[serde(default)]
    pub reacquisitions: usize,
    /// Keyframes in its bundle adjustment.
    pub keyframes: usize,
    /// Links between consecutive keyframes that no landmark of the adjustment spans: the map's
    /// parts on either side are held together by the odometry alone.
    #[serde(default)]
    pub keyframe_links_unspanned: usize,
    /// Of those, the links across dropped frames (a loss of tracking), where a frame tracked
    /// off after the loss splits the map unchecked.
    #[serde(default)]
    pub keyframe_links_unspanned_after_drops: usize,
    /// Whether its point set converged before mapping (false: mapped from a compact but
    /// unconverged point set, see `map_unconverged_targets`).
    pub localization_converged: bool,
    /// Whether the low, level base ring was flown (it is dropped when it cannot be cleared).
    pub base_ring_flown: bool,
    /// How the mapping rings were changed to keep clear of terrain and rocks.
    pub ring_repairs: Vec<scarp_planning::prelude::Repair>,
    /// The neck ring, planned from the map once the other rings were flown (`None` before it
    /// was tried, or when mapping ended otherwise).
    #[serde(default)]
    pub neck_ring: Option<NeckRingReport>,
    /// Fraction of the cylinder's cells seen.
    pub coverage: f64,
    /// Fraction of the cylinder's bottom band seen (the base).
    pub base_coverage: f64,
    /// How far round the cylinder's axis the mapping views reached, degrees: the span of their
    /// unwrapped azimuth ([`super::coverage::CylinderCoverage::sweep_deg`]).
    #[serde(default)]
    pub sweep_deg: f64,
    /// The most unseen side cells of the cylinder that lie together when mapping ended
    /// ([`super::coverage::CylinderCoverage::largest_unseen_region_cells`]): a large one is a
    /// part of the rock no view reached, where the closed scan is guessed.
    #[serde(default)]
    pub largest_unseen_region_cells: usize,
    /// The share of the rock patched over unseen parts and its cut in the map's last reading
    /// before mapping ended ([`super::mapping::MappingSession::ends_mapping`]); `None` where it
    /// was not read (the cells never ended mapping, or the map could not be cut).
    #[serde(default)]
    pub map_patched_fraction: Option<f64>,
    /// The tilt of the rock's support plane from the map's up, degrees, where the rock was
    /// analysed (`fragility.json`'s `support_tilt_deg`; 0 below the tilt it is levelled from):
    /// on a level pedestal, the map frame's tilt from gravity, which α_min takes in full.
    #[serde(default)]
    pub support_tilt_deg: Option<f64>,
    /// Mesh size.
    pub triangles: usize,
    /// Rock height from the mesh, metres.
    pub size_m: Option<f64>,
    /// Smallest rocking angle from the mesh, degrees.
    pub alpha_min_deg: Option<f64>,
    /// Lower end of α_min's 95% interval, degrees (`fragility.json`'s `alpha_min_low_deg`).
    pub alpha_min_low_deg: Option<f64>,
    /// Upper end of α_min's 95% interval, degrees.
    pub alpha_min_high_deg: Option<f64>,
    /// Quasi-static toppling acceleration g·tan(α_min), in g.
    pub toppling_pga_g: Option<f64>,
    /// Why it is not `mapped`, when it is not.
    pub error: Option<String>,
    /// The true rock nearest the centre (ground truth).
    pub gt_rock_id: Option<u32>,
    /// Role of that rock (`target` or `distractor`).
    pub gt_role: Option<String>,
    /// Distance from C_e (`localized_center`) to the true rock's centroid, metres.
    pub localization_error_m: Option<f64>,
    /// The state estimator's mean position error (estimate − truth, ENU metres) over the
    /// frames that updated this target's localization (ground truth).
    #[serde(default)]
    pub estimator_error_at_localization_m: Option<[f64; 3]>,
    /// Distance from C_e to the true centroid moved by that mean error: the localization error
    /// in the frame the vehicle flies in, metres.
    #[serde(default)]
    pub localization_error_estimate_frame_m: Option<f64>,
    /// That error as a vector: C_e less the true centroid moved by the mean error, ENU
    /// metres. Its z tells a centre left above the rock (+) from one sunk into it (−).
    #[serde(default)]
    pub localization_offset_estimate_frame_m: Option<[f64; 3]>,
    /// The state estimator's mean position error (estimate − truth, ENU metres) over the
    /// keyframes of the target's map: the frame its scan, and a `"scan"` centre, are in
    /// (ground truth).
    #[serde(default)]
    pub estimator_error_over_keyframes_m: Option<[f64; 3]>,
    /// Distance from `center` to the true rock's centroid, metres.
    #[serde(default)]
    pub center_error_m: Option<f64>,
    /// Distance from `center` to the true centroid moved by the estimator's mean error over
    /// the frames that placed it (`estimator_error_over_keyframes_m` for a `"scan"` centre,
    /// `estimator_error_at_localization_m` for C_e), metres.
    #[serde(default)]
    pub center_error_estimate_frame_m: Option<f64>,
    /// F-score at τ = 1 cm against the visible ground truth: the mesh within 10 cm of the true
    /// rock's box, its precision against the rock and its pedestal (both true surface), its
    /// recall on the rock's visible surface alone.
    pub fscore_1cm: Option<f64>,
    /// F-score at τ = 2 cm, as [`Self::fscore_1cm`].
    pub fscore_2cm: Option<f64>,
    /// F-score at τ = 2 cm of the tracking volume's mesh: every mapped frame fused at its
    /// odometry pose as it was tracked, the map before BA.
    pub fscore_2cm_before_ba: Option<f64>,
    /// Mean distance from the mesh (within 10 cm of the rock's box) to the nearer of the true
    /// rock and its pedestal, metres.
    pub accuracy_mean_m: Option<f64>,
    /// Mean distance from the visible ground truth to the mesh, metres.
    pub completeness_mean_m: Option<f64>,
    /// Fraction of the true rock's surface visible from the mapping flight.
    pub gt_visible_fraction: Option<f64>,
    /// ATE RMSE of the mapping trajectory before bundle adjustment (odometry), metres.
    pub ate_before_ba_m: Option<f64>,
    /// ATE RMSE after bundle adjustment, metres.
    pub ate_after_ba_m: Option<f64>,
    /// α_min of the true rock on its pedestal, degrees.
    pub alpha_min_gt_deg: Option<f64>,
    /// |α_min − α_min,gt|, degrees.
    pub alpha_error_deg: Option<f64>,
    /// Smallest true clearance while fine-localizing and mapping this target, metres.
    #[serde(default)]
    pub min_clearance_m: Option<f64>,
    /// How far the vehicle's navigation error moved while it flew this target's rings, from
    /// the first mapped frame on, metres (ground truth): how far the rings were carried
    /// across the rock. Flying in the map's frame (`mapping.fly_on_odometry`) keeps it to the
    /// odometry's drift; on the state estimate it is the GPS walk's.
    #[serde(default)]
    pub ring_drift_m: Option<f64>,
    /// Tracked frames whose odometry the map frame's gate refused while this target was
    /// mapped (the odometry was further from the state estimate than the estimator's walk
    /// allows; the vehicle flew on the last plausible offset). Each run of them is a WARN line.
    #[serde(default)]
    pub map_frame_refusals: usize,
}

impl TargetReport {
    /// Records C_e (world ENU metres) as `localized_center`, and as `center` unless a scan
    /// placed the target.
    pub fn set_localized_center(&mut self, center: &Point3<f64>) {
        self.localized_center = center.coords.into();
        if self.center_source != CENTER_FROM_SCAN {
            self.center = self.localized_center;
            self.center_source = CENTER_FROM_LOCALIZATION.into();
        }
    }

    /// Records the closed scan's volume centroid (world ENU metres) as `center`.
    pub fn set_scan_center(&mut self, centroid: &Point3<f64>) {
        self.center = centroid.coords.into();
        self.center_source = CENTER_FROM_SCAN.into();
    }
}

/// `center_source`'s value for a centre from the localization filter.
pub const CENTER_FROM_LOCALIZATION: &str = "localization";
/// `center_source`'s value for a centre from the target's closed scan.
pub const CENTER_FROM_SCAN: &str = "scan";

fn localization_source() -> String {
    CENTER_FROM_LOCALIZATION.into()
}

/// Wall time spent in each stage, seconds.
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize)]
pub struct StageTimings {
    /// Before the first frame: loading the world, writing its ground truth, building the
    /// renderer and planning the search.
    pub setup_s: f64,
    /// Flight dynamics and control.
    pub flight_s: f64,
    /// Path and trajectory planning.
    pub planning_s: f64,
    /// Rendering and sensor noise.
    pub render_s: f64,
    /// Detection.
    pub detect_s: f64,
    /// Box tracking.
    pub track_s: f64,
    /// Depth-filter localization.
    pub localize_s: f64,
    /// Odometry and TSDF fusion during Map mode.
    pub map_s: f64,
    /// Landmarks, bundle adjustment, re-integration and meshing.
    pub ba_mesh_s: f64,
    /// Fragility analysis and target export.
    pub fragility_export_s: f64,
    /// Ground-truth evaluation.
    pub evaluation_s: f64,
}

/// A switch of the mission mode.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ModeChange {
    /// Mission time, seconds.
    pub time_s: f64,
    /// The new mode: `search`, `fine_localize`, `map`, `done`.
    pub mode: String,
    /// The target concerned, if any.
    pub target: Option<u64>,
}

/// `mission.json`.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct MissionReport {
    /// The run was stopped (Ctrl-C) before the search finished.
    pub interrupted: bool,
    /// Why the run ended: `complete`, `interrupted`, `timeout`, `crashed`, `target_limit`
    /// (`max_targets` finished) or an error message.
    pub end_reason: String,
    /// The world (`default` or a file).
    pub world: String,
    /// The seed of every random draw.
    pub seed: u64,
    /// Simulated time, seconds.
    pub sim_time_s: f64,
    /// Wall-clock time, seconds.
    pub wall_time_s: f64,
    /// sim_time_s / wall_time_s.
    pub real_time_factor: f64,
    /// Camera steps at which the true vehicle was closer than the collision radius to terrain,
    /// a rock or a pedestal (`safety_events` groups them).
    pub collisions: usize,
    /// Smallest clearance of the true vehicle to terrain and rocks, metres.
    pub min_clearance_m: Option<f64>,
    /// Smallest true clearance per mode (`search`, `fine_localize`, `map`), metres.
    #[serde(default)]
    pub min_clearance_by_mode_m: std::collections::BTreeMap<String, f64>,
    /// Collisions and the safety monitor's interventions as events: when, in which mode,
    /// where, against what, how deep.
    #[serde(default)]
    pub safety_events: Vec<super::safety::SafetyEvent>,
    /// Times the safety monitor sensed a surface inside its safety radius and climbed.
    #[serde(default)]
    pub safety_interventions: usize,
    /// Frames taken in Search, FineLocalize and Map modes.
    pub frames_search: usize,
    /// Frames taken while flying fine-localization circles.
    pub frames_fine_localize: usize,
    /// Frames taken in Map mode.
    pub frames_map: usize,
    /// Targets registered by the localization filter.
    pub targets_found: usize,
    /// Targets mapped.
    pub targets_mapped: usize,
    /// Every target with its status and metrics.
    pub targets: Vec<TargetReport>,
    /// Targets mapped whose nearest true rock is a distractor (ground truth).
    pub distractors_mapped: usize,
    /// Ids of true targets never mapped (ground truth).
    pub targets_missed: Vec<u32>,
    /// Wall time per stage.
    pub timings: StageTimings,
    /// The mode log.
    pub modes: Vec<ModeChange>,
}

impl MissionReport {
    /// Writes `mission.json`, `targets.geojson` and `targets.csv` into `dir`.
    ///
    /// # Errors
    /// File-system errors naming the file.
    pub fn write(&self, dir: &Path, origin: Geodetic) -> MissionResult<()> {
        let json = serde_json::to_string_pretty(self)?;
        write_bytes_atomically(dir.join("mission.json"), json.as_bytes())?;
        let features: Vec<PointFeature> = self
            .targets
            .iter()
            .map(|t| PointFeature {
                position_enu_m: Point3::from(t.center),
                properties: serde_json::json!({
                    "id": t.id,
                    "status": t.status,
                    "center_source": t.center_source,
                    "size_m": t.size_m,
                    "alpha_min_deg": t.alpha_min_deg,
                    "alpha_min_low_deg": t.alpha_min_low_deg,
                    "alpha_min_high_deg": t.alpha_min_high_deg,
                    "toppling_pga_g": t.toppling_pga_g,
                }),
            })
            .collect();
        let frame = EnuFrame::new(origin)?;
        write_geojson(dir.join("targets.geojson"), &frame, &features)?;
        write_atomically(dir.join("targets.csv"), |w| {
            writeln!(
                w,
                "id,status,center_source,x_m,y_m,z_m,lat_deg,lon_deg,alt_m,size_m,alpha_min_deg,alpha_min_low_deg,alpha_min_high_deg,toppling_pga_g"
            )?;
            let opt = |v: Option<f64>| v.map_or(String::new(), |v| format!("{v:.4}"));
            for t in &self.targets {
                let g = frame.enu_to_geodetic(&Point3::from(t.center));
                writeln!(
                    w,
                    "{},{},{},{:.3},{:.3},{:.3},{:.8},{:.8},{:.3},{},{},{},{},{}",
                    t.id,
                    t.status,
                    t.center_source,
                    t.center[0],
                    t.center[1],
                    t.center[2],
                    g.lat_deg,
                    g.lon_deg,
                    g.alt_m,
                    opt(t.size_m),
                    opt(t.alpha_min_deg),
                    opt(t.alpha_min_low_deg),
                    opt(t.alpha_min_high_deg),
                    opt(t.toppling_pga_g)
                )?;
            }
            Ok(())
        })?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mission::catalog::TargetStatus;

    #[test]
    fn writes_json_geojson_and_csv_that_read_back() {
        let dir = tempfile::tempdir().unwrap();
        let report = MissionReport {
            interrupted: true,
            targets: vec![{
                let mut t = TargetReport {
                    id: 3,
                    status: TargetStatus::Mapped.as_str().into(),
                    alpha_min_deg: Some(12.5),
                    ..TargetReport::default()
                };
                t.set_localized_center(&Point3::new(10.4, -5.3, 2.6));
                t.set_scan_center(&Point3::new(10.0, -5.0, 2.0));
                t
            }],
            ..MissionReport::default()
        };
        let origin = Geodetic {
            lat_deg: 33.6,
            lon_deg: -116.5,
            alt_m: 1200.0,
        };
        report.write(dir.path(), origin).unwrap();
        let json: serde_json::Value =
            serde_json::from_slice(&std::fs::read(dir.path().join("mission.json")).unwrap())
                .unwrap();
        assert_eq!(json["interrupted"], true);
        assert_eq!(json["targets"][0]["status"], "mapped");
        assert_eq!(json["targets"][0]["localized_center"][2], 2.6);
        // A later scan does not give the centre back to the filter.
        let mut t = report.targets[0].clone();
        t.set_localized_center(&Point3::new(0.0, 0.0, 0.0));
        assert_eq!(
            (t.center, t.center_source.as_str()),
            ([10.0, -5.0, 2.0], "scan")
        );
        let geo: serde_json::Value =
            serde_json::from_slice(&std::fs::read(dir.path().join("targets.geojson")).unwrap())
                .unwrap();
        let coords = &geo["features"][0]["geometry"]["coordinates"];
        assert!((coords[1].as_f64().unwrap() - 33.6).abs() < 1e-3);
        assert_eq!(geo["features"][0]["properties"]["alpha_min_deg"], 12.5);
        let csv = std::fs::read_to_string(dir.path().join("targets.csv")).unwrap();
        assert_eq!(csv.lines().count(), 2);
        assert!(
            csv.lines()
                .nth(1)
                .unwrap()
                .starts_with("3,mapped,scan,10.000,-5.000")
        );
    }
}
