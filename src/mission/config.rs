//! Every tunable of a mission, as one serde struct: `scarp simulate --config mission.toml`
//! reads it (unknown keys are errors naming the key) and `scarp config` prints its defaults.

use serde::{Deserialize, Serialize};

use super::coverage::CoverageConfig;

/// How the mission flies, looks and maps.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MissionConfig {
    /// Search altitude h_s above the highest terrain under the search area, metres. Default 10:
    /// the depth filter draws its points in [3, 18] m (DESIGN defaults), and at γ = 55° the
    /// fine-localization circle sees its target from h/sin γ, so h above the target must stay
    /// under about 14 m wherever the terrain is lowest.
    pub search_height_agl_m: f64,
    /// Inset of the lawn-mower area from the world's edge, metres. Default 10.
    pub search_inset_m: f64,
    /// Camera rate in Search and FineLocalize, Hz. Default 4 (the detector's rate, not the
    /// camera's: the paper's YOLO ran at a few Hz).
    pub search_camera_rate_hz: f64,
    /// Camera rate in Map mode, Hz. Default 20 (DESIGN: 20 Hz camera).
    pub map_camera_rate_hz: f64,
    /// The run stops (status `timeout`) after this much simulated time, seconds. Default 7200.
    pub max_sim_time_s: f64,
    /// The flight ends (`"end_reason": "target_limit"`) once this many targets are finished
    /// (mapped or incomplete), the rest of the search area unflown: a battery or a time slot
    /// spent on the first rocks found. 0 (the default) searches the whole area.
    pub max_targets: usize,
    /// A vehicle closer than this to terrain or a rock counts as a collision, metres.
    /// Default 0.3 (the airframe's radius).
    pub collision_radius_m: f64,
    /// A target whose centre lies horizontally within this of a rock the mission already
    /// handled is a duplicate and is skipped, metres. Default 2 (localization error plus a
    /// rock's radius).
    pub duplicate_radius_m: f64,
    /// A target whose fine-localization circle ends before its point set converges (KL ≤ 0.01
    /// three updates in a row) is mapped anyway when its points are compact (ready for fine
    /// localization): the rings and the coverage test need a compact point set, not a
    /// converged one. Default true; false leaves it `unconverged` and never maps it (the
    /// paper's behaviour), which lost rock 1 of the default world once, its KL hovering just
    /// above the threshold.
    pub map_unconverged_targets: bool,
    /// A converged target is mapped only once its keyframe boxes were seen from this far around
    /// it, degrees (360° less the widest gap between the views' azimuths about C_e); until then
    /// its fine-localization circle goes on. A circle that ends short of it maps the target as
    /// before. Default 330: views all round, a gap of 30° allowed (a keyframe every 1.5 m on the
    /// 7–10 m circle is 9–12° of it). Why: C_e is where the views' rays meet, and the state
    /// estimate's walk over an arc of views moves that point vertically by the walk's change
    /// toward the target times the tangent of the camera's pitch; views all round cancel it.
    /// Session 64 found every miss of the 0.5 m bound in the estimate's frame where the filter
    /// had converged after 204–286° of circle. 0 maps on convergence alone (the paper).
    pub fine_localization_min_view_arc_deg: f64,
    /// Start a target's depth filter afresh when its fine-localization circle begins, so its
    /// centre comes from that circle's views alone. The state estimate drifts by metres over a
    /// flight; a point set that kept the search's views averages the estimate's error over
    /// minutes, and the rings are flown in the frame of the estimate now. Default false: in a
    /// paired campaign (session 16) the restart did not bring the estimate-frame error down,
    /// the shorter stretch of views costing what the consistent estimate gained. Session 37
    /// found that the search's views bias the centre 0.33–0.47 m upward even with an exact
    /// estimator; over default and library-b seeds 36–37 the restart put 12 / 14 centres within
    /// 0.5 m against 10 / 14, but mapped 8 targets against 10. Session 38's pairing on fresh
    /// seeds (default and library-a 38–39) reversed it: 8 / 14 within 0.5 m against 12 / 14,
    /// 7 mapped against 11, |α error| ≤ 2° on 46% against 79%. Over the 28 targets, 20
    /// against 22: it stays off. The search's bias has its own option, which removes it where
    /// the points are born: `[localization] birth_depth_from_image` (also off by default).
    pub restart_filter_for_fine_localization: bool,
    /// Target detectors: which one the perception runs (simulated by default, or an ONNX
    /// model) and their tunables.
    pub detection: DetectionConfig,
    /// The target cylinder from the converged point set.
    pub cylinder: CylinderEstimateConfig,
    /// When mapping is complete.
    pub coverage: CoverageConfig,
    /// Dense mapping of one target.
    pub mapping: MappingConfig,
    /// Paths, trajectories, control and flight.
    pub planning: scarp_planning::PlanningConfig,
    /// Depth and colour noise of the simulated camera.
    pub sensor: scarp_datasets::sensor::SensorConfig,
    /// Box tracking (Algorithm 1).
    pub tracker: crate::tracking::tracker::TrackerConfig,
    /// Depth-filter localization (Algorithms 2–3).
    pub localization: crate::localization::config::LocalizationConfig,
    /// GPS/IMU state-estimator error.
    pub estimator: scarp_datasets::estimator::EstimatorConfig,
    /// Fragility analysis of each mapped rock.
    pub fragility: crate::fragility::FragilityConfig,
    /// The safety layer: rangefinder, clearance monitor, and what a collision does.
    pub safety: super::monitor::SafetyConfig,
}

impl Default for MissionConfig {
    fn default() -> Self {
        Self {
            search_height_agl_m: 10.0,
            search_inset_m: 10.0,
            search_camera_rate_hz: 4.0,
            map_camera_rate_hz: 20.0,
            max_sim_time_s: 7200.0,
            max_targets: 0,
            collision_radius_m: 0.3,
            duplicate_radius_m: 2.0,
            map_unconverged_targets: true,
            fine_localization_min_view_arc_deg: 330.0,
            restart_filter_for_fine_localization: false,
            detection: DetectionConfig::default(),
            cylinder: CylinderEstimateConfig::default(),
            coverage: CoverageConfig::default(),
            mapping: MappingConfig::default(),
            planning: scarp_planning::PlanningConfig::default(),
            sensor: scarp_datasets::sensor::SensorConfig::default(),
            tracker: crate::tracking::tracker::TrackerConfig::default(),
            localization: crate::localization::config::LocalizationConfig::default(),
            estimator: scarp_datasets::estimator::EstimatorConfig::default(),
            fragility: crate::fragility::FragilityConfig::default(),
            safety: super::monitor::SafetyConfig::default(),
        }
    }
}

impl MissionConfig {
    /// Parses a mission TOML file's text; `path` names the file in errors.
    ///
    /// # Errors
    /// [`MissionConfigError`] naming the file, the key and the line at fault.
    pub fn from_toml_str(text: &str, path: &str) -> Result<Self, MissionConfigError> {
        let config: Self = toml::from_str(text).map_err(|e| MissionConfigError {
            path: path.to_string(),
            reason: e.to_string(),
        })?;
        config.validate().map_err(|reason| MissionConfigError {
            path: path.to_string(),
            reason,
        })?;
        Ok(config)
    }

    /// Checks the mission's own values (nested stages check theirs when they are built).
    ///
    /// # Errors
    /// A message naming the key and the allowed range.
    pub fn validate(&self) -> Result<(), String> {
        let positive = [
            ("search_height_agl_m", self.search_height_agl_m),
            ("search_camera_rate_hz", self.search_camera_rate_hz),
            ("map_camera_rate_hz", self.map_camera_rate_hz),
            ("max_sim_time_s", self.max_sim_time_s),
            ("collision_radius_m", self.collision_radius_m),
            ("duplicate_radius_m", self.duplicate_radius_m),
            ("cylinder.min_radius_m", self.cylinder.min_radius_m),
            ("cylinder.max_recenter_m", self.cylinder.max_recenter_m),
            ("mapping.voxel_size_m", self.mapping.voxel_size_m),
            ("mapping.max_depth_m", self.mapping.max_depth_m),
        ];
        for (key, value) in positive {
            if !(value.is_finite() && value > 0.0) {
                return Err(format!("`{key}` = {value}: must be a positive number"));
            }
        }
        self.safety.validate()?;
        for (key, value) in [
            (
                "mapping.estimate_gate_sigmas",
                self.mapping.estimate_gate_sigmas,
            ),
            (
                "mapping.estimate_gate_min_deg",
                self.mapping.estimate_gate_min_deg,
            ),
            ("mapping.max_dropped_s", self.mapping.max_dropped_s),
            (
                "mapping.reacquisition_min_gap_s",
                self.mapping.reacquisition_min_gap_s,
            ),
            (
                "mapping.reacquisition_sigmas",
                self.mapping.reacquisition_sigmas,
            ),
        ] {
            if !(value.is_finite() && value >= 0.0) {
                return Err(format!("`{key}` = {value}: must be a number ≥ 0"));
            }
        }
        if !(self.search_inset_m.is_finite() && self.search_inset_m >= 0.0) {
            return Err(format!(
                "`search_inset_m` = {}: must be ≥ 0",
                self.search_inset_m
            ));
        }
        if !(self.cylinder.max_radius_m >= self.cylinder.min_radius_m) {
            return Err("`cylinder.max_radius_m` must be ≥ `cylinder.min_radius_m`".into());
        }
        if !(self.coverage.threshold > 0.0 && self.coverage.threshold <= 1.0) {
            return Err(format!(
                "`coverage.threshold` = {}: must lie in (0, 1]",
                self.coverage.threshold
            ));
        }
        if !(0.0..=360.0).contains(&self.fine_localization_min_view_arc_deg) {
            return Err(format!(
                "`fine_localization_min_view_arc_deg` = {}: must lie in [0, 360]",
                self.fine_localization_min_view_arc_deg
            ));
        }
        if !(0.0..=3600.0).contains(&self.coverage.min_sweep_deg) {
            return Err(format!(
                "`coverage.min_sweep_deg` = {}: must lie in [0, 3600]",
                self.coverage.min_sweep_deg
            ));
        }
        if !(0.0..=1.0).contains(&self.coverage.max_patched_fraction) {
            return Err(format!(
                "`coverage.max_patched_fraction` = {}: must lie in [0, 1]",
                self.coverage.max_patched_fraction
            ));
        }
        Ok(())
    }
}

/// A mission configuration file that does not parse or holds a bad value.
#[derive(Debug, thiserror::Error)]
#[error("mission config {path}: {reason}")]
pub struct MissionConfigError {
    /// The file.
    pub path: String,
    /// What is wrong, with the key and line.
    pub reason: String,
}

/// Which detector the mission's perception runs.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum DetectorKind {
    /// The modelled detector: boxes from the rendered instance masks, with the jitter, misses
    /// and false positives of [`crate::detection::SimulatedDetectorConfig`]. The default.
    #[default]
    Simulated,
    /// A YOLO v5/v8 ONNX export (`onnx_model`), run with tract; needs the `onnx` cargo feature.
    Onnx,
}

/// The detectors' tunables, and which one the mission runs.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DetectionConfig {
    /// The detector of the mission's perception. Default `simulated`.
    pub detector: DetectorKind,
    /// The ONNX model file for `detector = "onnx"` (a path relative to the working directory).
    pub onnx_model: Option<std::path::PathBuf>,
    /// The modelled detector of synthetic sequences (its seed is derived from the mission's).
    pub simulated: crate::detection::SimulatedDetectorConfig,
    /// The ONNX YOLO detector (cargo feature `onnx`).
    pub onnx: crate::detection::OnnxDetectorConfig,
}

/// How the target's bounding cylinder (paper §III, mapping) comes from its converged points.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CylinderEstimateConfig {
    /// Quantile of the points' horizontal distance from C_e taken as the radius r_e: the paper
    /// bounds every point, but a few stray points would inflate the rings. Default 0.9.
    pub radius_quantile: f64,
    /// Smallest radius, metres. Default 0.6.
    pub min_radius_m: f64,
    /// Largest radius, metres. Default 2.5.
    pub max_radius_m: f64,
    /// Height of the cylinder's top above C_e, as a multiple of the radius. Default 1.2.
    pub top_over_center_radii: f64,
    /// The bottom sits this far below the terrain under C_e, metres (the pedestal's foot).
    /// Default 0.2.
    pub bottom_below_terrain_m: f64,
    /// A move of the cylinder onto the first mapped frame's box
    /// (`mapping.recenter_on_first_frame`) larger than this (horizontal, metres) is not
    /// trusted: the cylinder stays where the localization put it. Default 3.
    pub max_recenter_m: f64,
}

impl Default for CylinderEstimateConfig {
    fn default() -> Self {
        Self {
            radius_quantile: 0.9,
            min_radius_m: 0.6,
            max_radius_m: 2.5,
            top_over_center_radii: 1.2,
            bottom_below_terrain_m: 0.2,
            max_recenter_m: 3.0,
        }
    }
}

/// Dense mapping of one target inside its region of interest.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MappingConfig {
    /// TSDF voxel edge, metres. Default 0.01 (issue 3's fragility-grade 1 cm).
    pub voxel_size_m: f64,
    /// Depth beyond this is not fused, metres. Default 5.
    pub max_depth_m: f64,
    /// How the TSDF reads a voxel's depth: `"bilinear"` (default) or `"nearest"` (17–22% faster
    /// integration on session 60's sequences); see [`scarp_slam::tsdf::DepthSample`].
    pub depth_sample: scarp_slam::tsdf::DepthSample,
    /// The region of interest is the target's cylinder grown by this, metres. Default 1.0:
    /// the cylinder's error in the map frame (its box in the first mapped frame with
    /// `recenter_on_first_frame`, else the localization error plus the GPS walk since) must
    /// not cut the rock off.
    pub roi_margin_m: f64,
    /// ... and by this up and down, metres. Default 2.0: the map is anchored at the GPS
    /// estimate of its first frame, whose vertical error can exceed a metre.
    pub roi_vertical_margin_m: f64,
    /// Just before the first frame is mapped, move the cylinder (and its region of interest)
    /// to where the detector sees the target in that frame, within `cylinder.max_recenter_m`.
    /// Default true: the GPS walk over the transit from the localization circle to the rings
    /// offsets the rock in its map frame by 0.5–1.4 m, which cut one side off a rock of the
    /// default world.
    pub recenter_on_first_frame: bool,
    /// Drop mesh components smaller than this many triangles. Default 500.
    pub min_component_triangles: usize,
    /// Landmarks, bundle adjustment, re-integration and meshing of the keyframes (its TSDF
    /// settings are replaced by the mapping volume's). Default
    /// [`scarp_slam::mapping::RefineConfig::default`]. `estimate_noise = true` lowers the
    /// keyframe ATE after BA (campaign seeds 32–34: median 1.39 → 1.19 mm), but it stays off
    /// until the fragility analysis stops refusing meshes over sub-millimetre changes: with it,
    /// one campaign target and the small test world's were refused (too few base directions;
    /// one non-manifold edge).
    pub refine: scarp_slam::mapping::RefineConfig,
    /// RGBD odometry.
    pub odometry: scarp_slam::odometry::OdometryConfig,
    /// Keyframe selection for bundle adjustment.
    pub keyframes: scarp_slam::keyframes::KeyframeConfig,
    /// Besides the keyframes, every n-th mapped frame is kept and re-integrated after bundle
    /// adjustment at its odometry pose moved by its keyframe's correction; 0 re-integrates the
    /// keyframes only. Default 2. On the default world's mapping trajectories fused with true
    /// poses, the keyframes alone (about every 11th frame) left holes in rock 3's lower half
    /// that moved its α_min by 3.2°; every 5th frame by 1.6°, every 3rd by 0.1°. Memory: about
    /// 2 MB a kept frame, freed when the target is finished.
    pub reintegration_frame_stride: usize,
    /// While mapping, the controller flies in the map's frame (the odometry, anchored at the
    /// state estimate when mapping began) instead of on the GPS/IMU estimate, so the rings
    /// stay put around the rock while the GPS walk wanders (see [`super::navigation`]).
    /// Default true. It was false until session 32: an odometry failure on the base ring had
    /// steered the vehicle to 0.9 m of a rock (2026-11-22, before the tracker's estimate gate
    /// and the safety monitor); flying on the estimate instead carried holdout-c seed 47's
    /// rings 1.8 m across a rock and into it. The odometry's offset from the estimate is now
    /// gated by the estimator's walk.
    pub fly_on_odometry: bool,
    /// A mapped frame whose tracked rotation since the previous frame strays from the state
    /// estimator's by more than `estimate_gate_min_deg` plus this many σ of the estimator's
    /// attitude walk over the time between them (`[estimator]`'s attitude σ and correlation
    /// time) is dropped: not fused, not a keyframe. 0 turns the gate off. Default 4: on the
    /// default world's seed 36 (with 300° localization), the 1677 frames tracked right
    /// (within 0.01° of the truth) strayed from the estimate by at most 1.03° (median 0.17°),
    /// and one that did not (5.5° off, 0.22 m) became a keyframe that carried its error into
    /// the rest of the map (ATE 8.2 cm, F@2cm 0.41).
    pub estimate_gate_sigmas: f64,
    /// The gate's floor, degrees (the odometry's own error and the estimator's noise at once).
    /// Default 0.5.
    pub estimate_gate_min_deg: f64,
    /// Mapped frames whose odometry failed or strayed from the estimate are dropped for up to
    /// this long in a row, seconds (at `map_camera_rate_hz`); the next is placed by the
    /// estimate's motion and re-anchors the keyframes. Default 1.0: on the default world's
    /// seed 35 (300° localization, 1.5 m exit), the vehicle's attitude swung by 30° and back
    /// within 0.4 s on the base ring, the odometry failed for 0.6 s, and a 0.6 s limit placed
    /// the next frame by the estimate, 12 cm off, which then carried into the map.
    pub max_dropped_s: f64,
    /// The first mapped frame this long after the previous one kept, seconds, is tracked from
    /// a grid of guesses spanning the state estimate's walk over the gap (`[estimator]`'s
    /// position σ, correlation time and white noise), not from one. Default 1.0.
    pub reacquisition_min_gap_s: f64,
    /// ... spanning this many σ of the walk (the horizontal radius and vertical half height of
    /// the search); 0 turns the search off. Default 3. Why: the odometry corrects a guess by at
    /// most `odometry.max_correction_m` (0.5 m), and the GPS walks by a metre in 14 s. On
    /// holdout-c seed 48 a frame re-acquired that way converged 1.3 m beside the truth at an
    /// inlier ratio of 0.30, and the keyframe taken there shifted the rest of the map.
    pub reacquisition_sigmas: f64,
    /// The first mapped frame kept after frames were dropped (`max_dropped_s`) is searched
    /// for the same way (`reacquisition_min_gap_s`), however short the run. Default true.
    /// Why: over a run of dropped frames the estimate's motion is off by its white noise and
    /// its walk at once; on the default
    /// world's seed 62 (session 65) a 0.9 s run ended on a frame tracked from that one guess,
    /// 0.4 m out, which converged 0.13 m beside the truth at an inlier ratio of 0.34 and split
    /// the map in two (F@2cm 0.34, α +6.7° outside its interval).
    pub reacquisition_after_drops: bool,
}

impl MappingConfig {
    /// How a target's map is meshed: the refinement's meshing with small components dropped
    /// ([`Self::min_component_triangles`]). The tracking volume's mesh read in flight and the
    /// refined map's mesh are cut alike.
    pub fn meshing(&self) -> scarp_slam::meshing::MeshingConfig {
        scarp_slam::meshing::MeshingConfig {
            min_component_triangles: self.min_component_triangles,
            ..self.refine.meshing
        }
    }

    /// The tracker's gate against the state estimate (`None` when `estimate_gate_sigmas` is
    /// 0), scaled to `estimator`'s attitude walk.
    pub fn estimate_rotation_gate(
        &self,
        estimator: &scarp_datasets::estimator::EstimatorConfig,
    ) -> Option<scarp_slam::mapping::EstimateRotationGate> {
        (self.estimate_gate_sigmas > 0.0).then(|| scarp_slam::mapping::EstimateRotationGate {
            min_deg: self.estimate_gate_min_deg,
            deg_per_sqrt_s: self.estimate_gate_sigmas * estimator.attitude_walk_deg_per_sqrt_s(),
        })
    }

    /// The tracker's search for a frame after a gap in view (`None` when
    /// `reacquisition_sigmas` is 0), scaled to `estimator`'s position walk.
    pub fn reacquisition_search(
        &self,
        estimator: &scarp_datasets::estimator::EstimatorConfig,
    ) -> Option<scarp_slam::mapping::ReacquisitionSearch> {
        (self.reacquisition_sigmas > 0.0).then(|| scarp_slam::mapping::ReacquisitionSearch {
            min_gap_s: self.reacquisition_min_gap_s,
            after_dropped_frames: self.reacquisition_after_drops,
            sigmas: self.reacquisition_sigmas,
            ..scarp_slam::mapping::ReacquisitionSearch::for_walk(
                estimator.horizontal_sigma_m,
                estimator.vertical_sigma_m,
                estimator.position_correlation_s,
                estimator.horizontal_white_m.max(estimator.vertical_white_m),
            )
        })
    }
}

impl Default for MappingConfig {
    fn default() -> Self {
        Self {
            voxel_size_m: 0.01,
            max_depth_m: 5.0,
            depth_sample: scarp_slam::tsdf::DepthSample::Bilinear,
            roi_margin_m: 1.0,
            roi_vertical_margin_m: 2.0,
            recenter_on_first_frame: true,
            min_component_triangles: 500,
            refine: scarp_slam::mapping::RefineConfig::default(),
            odometry: scarp_slam::odometry::OdometryConfig::default(),
            keyframes: scarp_slam::keyframes::KeyframeConfig::default(),
            reintegration_frame_stride: 2,
            fly_on_odometry: true,
            estimate_gate_sigmas: 4.0,
            estimate_gate_min_deg: 0.5,
            max_dropped_s: 1.0,
            reacquisition_min_gap_s: 1.0,
            reacquisition_after_drops: true,
            reacquisition_sigmas: 3.0,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    /// The campaign documents' configurations still load, so their commands still run.
    #[test]
    fn the_campaign_tools_configs_load() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("docs/campaigns/tools");
        let mut loaded = 0;
        for entry in std::fs::read_dir(&dir).unwrap() {
            let path = entry.unwrap().path();
            if path.extension().is_some_and(|e| e == "toml") {
                let text = std::fs::read_to_string(&path).unwrap();
                let config = MissionConfig::from_toml_str(&text, &path.display().to_string())
                    .unwrap_or_else(|e| panic!("{e}"));
                let neck = config.planning.mapping.neck_ring;
                let is_neck_aim = path.ends_with("neck_aim.toml");
                assert_eq!(neck.aim_on_approach, is_neck_aim, "{}", path.display());
                loaded += 1;
            }
        }
        assert!(loaded >= 6, "{loaded} configs in {}", dir.display());
    }

    #[test]
    fn defaults_round_trip_through_toml() {
        let text = toml::to_string_pretty(&MissionConfig::default()).unwrap();
        let back = MissionConfig::from_toml_str(&text, "mission.toml").unwrap();
        assert_eq!(back, MissionConfig::default());
    }

    #[test]
    fn unknown_keys_and_bad_values_are_named() {
        let err = MissionConfig::from_toml_str("search_hieght_agl_m = 3\n", "m.toml")
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("m.toml") && err.contains("search_hieght_agl_m"),
            "{err}"
        );
        let err = MissionConfig::from_toml_str("map_camera_rate_hz = -1\n", "m.toml")
            .unwrap_err()
            .to_string();
        assert!(err.contains("map_camera_rate_hz"), "{err}");
        let err =
            MissionConfig::from_toml_str("fine_localization_min_view_arc_deg = 400\n", "m.toml")
                .unwrap_err()
                .to_string();
        assert!(err.contains("fine_localization_min_view_arc_deg"), "{err}");
        let err = MissionConfig::from_toml_str("[coverage]\nthreshold = 2.0\n", "m.toml")
            .unwrap_err()
            .to_string();
        assert!(err.contains("coverage.threshold"), "{err}");
        let err = MissionConfig::from_toml_str("[mapping]\nmax_dropped_s = -1.0\n", "m.toml")
            .unwrap_err()
            .to_string();
        assert!(err.contains("mapping.max_dropped_s"), "{err}");
    }

    /// Every table of the configuration, however deep (`[planning.min_snap]`, …), refuses a key
    /// it does not know, naming it: a misspelt key must never be silently ignored.
    #[test]
    fn every_table_denies_unknown_keys() {
        fn table_paths(table: &toml::Table, prefix: &[String], out: &mut Vec<Vec<String>>) {
            out.push(prefix.to_vec());
            for (key, value) in table {
                if let toml::Value::Table(sub) = value {
                    let mut path = prefix.to_vec();
                    path.push(key.clone());
                    table_paths(sub, &path, out);
                }
            }
        }
        let defaults: toml::Table =
            toml::from_str(&toml::to_string_pretty(&MissionConfig::default()).unwrap()).unwrap();
        let mut paths = Vec::new();
        table_paths(&defaults, &[], &mut paths);
        assert!(paths.len() > 10, "{paths:?}");
        for path in paths {
            let mut config = defaults.clone();
            let mut table = &mut config;
            for key in &path {
                table = table.get_mut(key).unwrap().as_table_mut().unwrap();
            }
            table.insert("misspelt_key_zq".into(), toml::Value::Integer(1));
            let text = toml::to_string(&config).unwrap();
            let err = MissionConfig::from_toml_str(&text, "m.toml")
                .err()
                .unwrap_or_else(|| panic!("[{}] accepted an unknown key", path.join(".")));
            assert!(err.to_string().contains("misspelt_key_zq"), "{err}");
        }
    }
}
