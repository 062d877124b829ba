//! Perception: detect → track → filter boxes → localize, at the estimated pose. The one path that
//! the mission (Search and FineLocalize) and `scarp localize` both run, with the same defaults.
//!
//! Only confirmed tracks that a detection updated in this frame feed the depth filter: a
//! sporadic false positive (a one-frame detection) never seeds a target, and KLT-only
//! predictions between detections do not drag the points (on sparse search frames they made
//! the filter converge off the rock). The filter's own hit and miss counters remove what gets
//! through.

use std::time::Instant;

use nalgebra::{Isometry3, Point3};
use rand::SeedableRng;
use rand::rngs::Xoshiro256PlusPlus;
use scarp_datasets::noise::derive_seed;
use scarp_datasets::world::World;
use scarp_slam::image::gray_from_rgb;
use scarp_slam::{PinholeCamera, RgbdFrame};

use super::config::{DetectionConfig, DetectorKind, MissionConfig};
use super::error::{MissionError, MissionResult};
use crate::detection::simulated::{
    RoleMap, SimulatedDetector, SimulatedDetectorConfig, roles_from_world,
};
use crate::detection::{BoundingBox, Detection, Detector};
use crate::localization::catalog::{ObserveReport, TargetCatalog};
use crate::localization::config::LocalizationConfig;
use crate::localization::silhouette::median_depth_in_box;
use crate::localization::target::{Target, TargetStatus as FilterStatus};
use crate::tracking::tracker::{Tracker, TrackerConfig};

/// A localization target as the mission needs it.
#[derive(Debug, Clone)]
pub struct TargetState {
    /// Localization target id.
    pub id: u32,
    /// C_e, world ENU metres: the depth filter's [`Target::located_center`] (the point nearest
    /// its keyframe boxes' central rays, once there are enough).
    pub center: Point3<f64>,
    /// Its point set, world ENU metres.
    pub points: Vec<Point3<f64>>,
    /// The mean of `points`, world ENU metres (the paper's C_e): what the points' spread, and
    /// so the mapping cylinder's radius, is measured about.
    pub points_center: Point3<f64>,
    /// h_p fell below the fine-localization threshold.
    pub ready_for_fine_localization: bool,
    /// KL stayed below the threshold long enough.
    pub converged: bool,
    /// How far around `center` its keyframe boxes were seen from, degrees
    /// ([`Target::view_arc_deg`]).
    pub view_arc_deg: f64,
    /// Horizontal covariance `[σxx, σxy, σyy]`, m².
    pub covariance_xy: [f64; 3],
    /// Spread of the point set along each ENU axis (1σ), metres: how far the filter itself
    /// says `center` may be off.
    pub sigma_m: [f64; 3],
}

/// What perception did with one frame: the wall time of each stage, seconds, and what the depth
/// filter did with its boxes.
#[derive(Debug, Clone, Default)]
pub struct PerceptionStep {
    /// Detection.
    pub detect_s: f64,
    /// Box tracking.
    pub track_s: f64,
    /// Depth filter.
    pub localize_s: f64,
    /// Targets whose points this frame updated (it localized them).
    pub updated: Vec<u32>,
    /// The depth filter's report of the frame (registered, matched, removed, merged targets).
    pub observed: ObserveReport,
}

/// Which boxes reach the depth filter.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BoxSource {
    /// Confirmed tracks of the KLT/Kalman box tracker that a detection updated in this frame
    /// (the default; the mission's).
    UpdatedTracks,
    /// Every confirmed track, predicted boxes included.
    ConfirmedTracks,
    /// Every detection, each as its own track (no tracker).
    Detections,
}

/// Detector, box tracker and depth filter.
pub struct Perception {
    detector: Box<dyn Detector>,
    tracker: Tracker,
    box_source: BoxSource,
    catalog: TargetCatalog,
    rng: Xoshiro256PlusPlus,
    frames: u64,
}

/// The mission's simulated detector with `config`, for the rocks of `roles`, its draws seeded
/// from the run's `seed` as every mission and `scarp localize` seed it.
///
/// # Errors
/// An invalid detector setting.
pub fn mission_detector(
    config: &SimulatedDetectorConfig,
    roles: RoleMap,
    seed: u64,
) -> Result<SimulatedDetector, crate::detection::DetectionError> {
    SimulatedDetector::new(
        SimulatedDetectorConfig {
            seed: derive_seed(seed, 0xde7),
            ..config.clone()
        },
        roles,
    )
}

/// The detector that `config.detector` names: the simulated one (as [`mission_detector`]) or
/// the ONNX model `config.onnx_model`.
///
/// # Errors
/// [`MissionError::Config`] for `onnx` without a model; the detector's own error for invalid
/// settings, an unreadable model or a build without the `onnx` feature.
pub fn configured_detector(
    config: &DetectionConfig,
    roles: RoleMap,
    seed: u64,
) -> MissionResult<Box<dyn Detector>> {
    match config.detector {
        DetectorKind::Simulated => Ok(Box::new(mission_detector(&config.simulated, roles, seed)?)),
        DetectorKind::Onnx => {
            let model = config.onnx_model.as_ref().ok_or_else(|| {
                MissionError::Config(
                    "detection.detector = \"onnx\" needs detection.onnx_model (the model file)"
                        .into(),
                )
            })?;
            Ok(crate::detection::load_onnx_detector(
                model,
                config.onnx.clone(),
            )?)
        }
    }
}

impl Perception {
    /// The detector of `config.detection` (by default the simulated one for `world`'s rocks), a
    /// fresh tracker and an empty catalog, with the mission's settings.
    ///
    /// # Errors
    /// Invalid detector, tracker or localization settings.
    pub fn new(world: &World, config: &MissionConfig, seed: u64) -> MissionResult<Self> {
        Self::with_roles(roles_from_world(world), config, seed)
    }

    /// As [`Self::new`], for the rocks whose roles `roles` gives (a recorded flight's
    /// `boxes.txt`, see [`crate::detection::simulated::roles_from_boxes`]).
    ///
    /// # Errors
    /// Invalid detector, tracker or localization settings.
    pub fn with_roles(roles: RoleMap, config: &MissionConfig, seed: u64) -> MissionResult<Self> {
        Self::with_detector(
            configured_detector(&config.detection, roles, seed)?,
            config.tracker.clone(),
            BoxSource::UpdatedTracks,
            config.localization,
            seed,
        )
    }

    /// Any detector, with the given tracker and depth-filter settings; `seed` seeds the depth
    /// filter's sampling.
    ///
    /// # Errors
    /// Invalid tracker or localization settings.
    pub fn with_detector(
        detector: Box<dyn Detector>,
        tracker: TrackerConfig,
        box_source: BoxSource,
        localization: LocalizationConfig,
        seed: u64,
    ) -> MissionResult<Self> {
        Ok(Self {
            detector,
            tracker: Tracker::new(tracker)?,
            box_source,
            catalog: TargetCatalog::new(localization)?,
            rng: Xoshiro256PlusPlus::seed_from_u64(derive_seed(seed, 0x10c)),
            frames: 0,
        })
    }

    /// The depth filter's targets.
    pub fn catalog(&self) -> &TargetCatalog {
        &self.catalog
    }

    /// Detects, tracks and localizes in one frame seen from `world_from_camera` (estimated).
    ///
    /// # Errors
    /// A frame the detector cannot use (the simulated detector needs an instance mask), or a
    /// non-finite pose.
    pub fn process(
        &mut self,
        frame: &RgbdFrame,
        camera: &PinholeCamera,
        world_from_camera: &Isometry3<f64>,
    ) -> MissionResult<PerceptionStep> {
        let clock = Instant::now();
        let detections = self.detector.detect(frame)?;
        let detect_s = clock.elapsed().as_secs_f64();
        let clock = Instant::now();
        let candidates = match self.box_source {
            BoxSource::Detections => detections_as_tracks(&detections, self.frames),
            source => {
                let tracks = self.tracker.step(&gray_from_rgb(&frame.rgb), &detections)?;
                let updated_only = source == BoxSource::UpdatedTracks;
                tracks
                    .iter()
                    .filter(|t| t.confirmed && (t.updated || !updated_only))
                    .map(|t| (t.id, t.bbox))
                    .collect()
            }
        };
        self.frames += 1;
        let track_s = clock.elapsed().as_secs_f64();
        let clock = Instant::now();
        let boxes = boxes_for_filter(
            &candidates,
            frame,
            camera,
            self.catalog.config().max_depth_m,
        );
        let observed = self.catalog.observe_with_depth(
            camera,
            world_from_camera,
            &boxes,
            Some(&frame.depth_m),
            &mut self.rng,
        )?;
        tracing::debug!(
            "t = {:.2} s: {} detections, {} candidates, {} boxes to the filter; {:?}",
            frame.timestamp_s,
            detections.len(),
            candidates.len(),
            boxes.len(),
            observed
        );
        Ok(PerceptionStep {
            detect_s,
            track_s,
            localize_s: clock.elapsed().as_secs_f64(),
            updated: observed.updated.clone(),
            observed,
        })
    }

    /// Makes target `id`'s depth filter start afresh from the next box paired with it (see
    /// [`TargetCatalog::restart_on_next_box`]); false for an unknown id.
    pub fn restart_target(&mut self, id: u32) -> bool {
        self.catalog.restart_on_next_box(id)
    }

    /// Forgets every box track (after the camera looked elsewhere); targets stay.
    ///
    /// # Errors
    /// Never in practice: the tracker settings were valid when the mission started.
    pub fn reset_tracks(&mut self) -> MissionResult<()> {
        self.tracker = Tracker::new(self.tracker.config().clone())?;
        Ok(())
    }

    fn state_of(&self, target: &Target) -> TargetState {
        let c = target.covariance();
        let center = target.located_center(self.catalog.config().center_from_depth_views);
        TargetState {
            id: target.id(),
            center,
            view_arc_deg: target.view_arc_deg(&center),
            points: target.points().to_vec(),
            points_center: target.center(),
            ready_for_fine_localization: target.status() != FilterStatus::Tracking,
            converged: target.status() == FilterStatus::Converged,
            covariance_xy: [c[(0, 0)], c[(0, 1)], c[(1, 1)]],
            sigma_m: [0, 1, 2].map(|i| c[(i, i)].max(0.0).sqrt()),
        }
    }

    /// Every confirmed target.
    pub fn target_states(&self) -> Vec<TargetState> {
        let cfg = self.catalog.config();
        self.catalog
            .targets()
            .iter()
            .filter(|t| t.is_confirmed(cfg))
            .map(|t| self.state_of(t))
            .collect()
    }

    /// One target, if it still exists.
    pub fn target_state(&self, id: u32) -> Option<TargetState> {
        self.catalog.target(id).map(|t| self.state_of(t))
    }

    /// Runs the detector alone on `frame` (no tracking, no depth filter) and returns the box
    /// whose centre lies nearest to where `expected` (world ENU, in the frame of
    /// `world_from_camera`) projects, within `gate_px`; `None` when the point is behind the
    /// camera or nothing is near it.
    ///
    /// # Errors
    /// A frame without an instance mask.
    pub fn detect_near(
        &mut self,
        frame: &RgbdFrame,
        camera: &PinholeCamera,
        world_from_camera: &Isometry3<f64>,
        expected: &Point3<f64>,
        gate_px: f64,
    ) -> MissionResult<Option<BoundingBox>> {
        let in_camera = world_from_camera.inverse() * expected;
        if in_camera.z <= 0.0 {
            return Ok(None);
        }
        let Some(pixel) = camera.project(&in_camera) else {
            return Ok(None);
        };
        let detections = self.detector.detect(frame)?;
        let distance_px = |b: &BoundingBox| {
            let (u, v) = b.center();
            (u - pixel.x).hypot(v - pixel.y)
        };
        Ok(detections
            .iter()
            .map(|d| d.bbox)
            .filter(|b| distance_px(b) <= gate_px)
            .min_by(|a, b| distance_px(a).total_cmp(&distance_px(b))))
    }
}

/// Each detection as its own track: ids `frame · 2²⁰ + k` never repeat, so no box inherits a
/// target through its track id.
fn detections_as_tracks(detections: &[Detection], frame: u64) -> Vec<(u64, BoundingBox)> {
    detections
        .iter()
        .enumerate()
        .map(|(k, d)| ((frame << 20) + k as u64, d.bbox))
        .collect()
}

/// The boxes that reach the depth filter: inside the image, with a valid shape, and whose rock
/// lies within the filter's range (`max_depth_m`, by the median depth of the box's centre; see
/// [`median_depth_in_box`]).
///
/// Boxes whose rock lies beyond that range are held back: Algorithm 2 draws depths in
/// [3, 18] m, so a rock first seen at 25 m would seed a point set that cannot reach it, and the
/// filter would converge in mid-air. The rock comes into range as the search goes on.
pub fn boxes_for_filter(
    candidates: &[(u64, BoundingBox)],
    frame: &RgbdFrame,
    camera: &PinholeCamera,
    max_depth_m: f64,
) -> Vec<(u64, BoundingBox)> {
    candidates
        .iter()
        .filter(|(_, b)| b.is_inside_image(camera.width, camera.height, 0.0))
        .filter(|(_, b)| median_depth_in_box(&frame.depth_m, b).is_some_and(|d| d <= max_depth_m))
        .filter(|(_, b)| BoundingBox::new(b.x_min, b.y_min, b.x_max, b.y_max).is_ok())
        .copied()
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_detector_is_chosen_by_config() {
        let config: MissionConfig =
            toml::from_str("[detection]\ndetector = \"simulated\"").unwrap();
        assert!(configured_detector(&config.detection, RoleMap::default(), 1).is_ok());
        // An ONNX detector without its model is a config error naming the key.
        let config: MissionConfig = toml::from_str("[detection]\ndetector = \"onnx\"").unwrap();
        let error = configured_detector(&config.detection, RoleMap::default(), 1)
            .err()
            .unwrap()
            .to_string();
        assert!(error.contains("detection.onnx_model"), "{error}");
        // A model that does not exist: the feature's absence, or the unreadable file, is named.
        let config: MissionConfig = toml::from_str(
            "[detection]\ndetector = \"onnx\"\nonnx_model = \"/nonexistent/yolo.onnx\"",
        )
        .unwrap();
        let error = configured_detector(&config.detection, RoleMap::default(), 1)
            .err()
            .unwrap()
            .to_string();
        assert!(error.contains("/nonexistent/yolo.onnx"), "{error}");
        assert!(toml::from_str::<MissionConfig>("[detection]\ndetector = \"yolo\"").is_err());
    }

    /// The claim of `LocalizationConfig::center_from_depth_views`: from 25 views around the
    /// fine-localization circle (10 m up, 55° down), with the sensor's depth noise, the median
    /// of the object centres in the detector's boxes lies within 0.2 m of every target's
    /// centroid in three worlds.
    #[test]
    fn the_boxes_around_the_fine_circle_place_every_target() {
        use crate::localization::silhouette::center_in_box;
        use nalgebra::Vector3;
        use scarp_datasets::world::RockRole;
        let camera = PinholeCamera::from_hfov(640, 480, 80.0).unwrap();
        let sensor = scarp_datasets::sensor::SensorConfig::default();
        for name in ["default", "library-a", "library-b"] {
            let world = World::builtin(name).unwrap();
            let mut perception = Perception::new(&world, &MissionConfig::default(), 3).unwrap();
            let renderer = scarp_datasets::render::Renderer::new(&world);
            for rock in world.rocks.iter().filter(|r| r.role == RockRole::Target) {
                let centroid = rock.centroid;
                let (mut xs, mut ys) = (Vec::new(), Vec::new());
                for k in 0..25u32 {
                    let azimuth = f64::from(k) * std::f64::consts::TAU / 25.0;
                    let out_m = 10.0 / 55f64.to_radians().tan();
                    let eye =
                        centroid + Vector3::new(out_m * azimuth.cos(), out_m * azimuth.sin(), 10.0);
                    let pose =
                        scarp_slam::geometry::look_at(&eye, &centroid, &Vector3::z()).unwrap();
                    let rendered = renderer.render(&camera, &pose).unwrap();
                    let seed = u64::from(k) + 100 * u64::from(rock.id);
                    let depth = sensor.corrupt_depth(&rendered.depth_m, camera.fx, seed);
                    let frame =
                        RgbdFrame::new(0.0, rendered.rgb, depth, Some(rendered.instance)).unwrap();
                    if let Some(c) = perception
                        .detect_near(&frame, &camera, &pose, &centroid, 160.0)
                        .unwrap()
                        .and_then(|b| center_in_box(&camera, &frame.depth_m, &pose, &b))
                    {
                        xs.push(c.x);
                        ys.push(c.y);
                    }
                }
                assert!(
                    xs.len() >= 20,
                    "{name} rock {}: {} views",
                    rock.id,
                    xs.len()
                );
                let median = |v: &mut Vec<f64>| {
                    scarp_slam::stats::quantile_in_place(v, 0.5).unwrap_or(f64::NAN)
                };
                let (x, y) = (median(&mut xs), median(&mut ys));
                let off_m = (x - centroid.x).hypot(y - centroid.y);
                assert!(off_m <= 0.2, "{name} rock {}: {off_m:.2} m off", rock.id);
            }
        }
    }
}
