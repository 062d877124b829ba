//! Perception: detect → track → filter boxes → localize, at the estimated pose. The one path that
//! the mission (Search and FineLocalize) and `scarp localize` both run, with the same defaults.
//!
//! Only confirmed tracks that a detection updated in this frame feed the depth filter: a
//! sporadic false positive (a one-frame detection) never seeds a target, and KLT-only
//! predictions between detections do not drag the points (on sparse search frames they made
//! the filter converge off the rock). The filter's own hit and miss counters remove what gets
//! through.

use std::time::Instant;

use nalgebra::{Isometry3, Point2, Point3};
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
use crate::localization::box_depth::depth_samples_in_box;
use crate::localization::catalog::{ObserveReport, TargetCatalog};
use crate::localization::config::LocalizationConfig;
use crate::localization::target::TargetStatus as FilterStatus;
use crate::tracking::tracker::{Tracker, TrackerConfig};

/// A localization target as the mission needs it.
#[derive(Debug, Clone)]
pub struct TargetState {
    /// Localization target id.
    pub id: u32,
    /// Centre of its point set C_e, world ENU metres.
    pub center: Point3<f64>,
    /// Its point set, world ENU metres.
    pub points: Vec<Point3<f64>>,
    /// h_p fell below the fine-localization threshold.
    pub ready_for_fine_localization: bool,
    /// KL stayed below the threshold long enough.
    pub converged: bool,
    /// Horizontal covariance `[σxx, σxy, σyy]`, m².
    pub covariance_xy: [f64; 3],
    /// Spread of the point set along each ENU axis (1σ), metres: how far the filter itself
    /// says `center` may be off.
    pub sigma_m: [f64; 3],
}

/// Median measured depth over the central half of a box (sampled on a grid), metres; `None`
/// when no pixel there has a measurement.
///
/// Boxes whose rock lies beyond the depth filter's range are held back: Algorithm 2 draws
/// depths in [3, 18] m, so a rock first seen at 25 m would seed a point set that cannot reach
/// it, and the filter would converge in mid-air. The rock comes into range as the search goes
/// on.
pub fn median_depth_in_box(
    depth_m: &scarp_slam::image::DepthImage,
    bbox: &BoundingBox,
) -> Option<f64> {
    let mut samples = depth_samples_in_box(depth_m, bbox, 0.5, 9);
    scarp_slam::stats::quantile_in_place(&mut samples, 0.5)
}

/// Height above the lowest points in a box (the ground at the rock's foot) from which depth
/// points count as the target, metres: the depth filter's ground band.
const ABOVE_GROUND_M: f64 = crate::localization::free_space::GROUND_BAND_M;

/// Fewest target points [`center_in_box`] accepts.
const MIN_TARGET_POINTS: usize = 30;

/// How far from the surface point at a box's centre [`center_in_box`] looks for the object,
/// per metre of the object's size as the box gives it: a round object's far side lies one
/// diameter away, and 10% covers the detector's box jitter (σ 4 px).
const OBJECT_REACH_PER_SIZE: f64 = 1.1;

/// The reach's margin for small objects, metres.
const OBJECT_REACH_MARGIN_M: f64 = 0.2;

/// The `q`-quantile of `values` (sorted in place; nearest rank); NaN when empty.
fn quantile(values: &mut [f64], q: f64) -> f64 {
    scarp_slam::stats::quantile_in_place(values, q).unwrap_or(f64::NAN)
}

/// The centre of the object in `bbox`, from the depth points inside the box, in the frame of
/// `world_from_camera` (world ENU metres).
///
/// The object's points are those near the box's central depth and above the ground at its
/// foot:
/// - the median depth of the box's central half ([`median_depth_in_box`]), on the ray through
///   the box's centre, gives a point on the object's surface;
/// - the box's larger side at that depth gives the object's size; points farther than
///   1.1 × that size + 0.2 m horizontally from the surface point are background;
/// - of the rest, those more than 0.25 m above their lowest 5% (the ground at the foot) are
///   the object.
///
/// Its centre is then [`center_of_silhouette`]. `None` without depth at the box's centre, or
/// with fewer than 30 object points.
///
/// Why the size limit: the box holds whatever lies behind the object too. Seen from low, the
/// terrain rising behind a rock stands higher than its foot, and counted as object it widened
/// the silhouette by metres. Rendered from 3.5 m out and 0.6 m up at 12 azimuths, the default,
/// library-a and library-b targets' centres came out up to 7.7 m off (on 9 of 11 targets, over
/// 1.5 m somewhere); the rock's own pixels (the instance mask) give at most 0.74 m, and this
/// rule at most 0.76 m (`mission::mapping`'s `the_centre_seen_from_low_is_the_rocks`).
///
/// Why it exists: the point set's centre carries the GPS error of the localization, while the
/// map is anchored at the estimate of its first frame, seconds later. With the GPS walk
/// (τ = 30 s) the two differ by up to a metre or more, enough to push the rock out of its
/// region of interest; a box in the first mapped frame sees it in the frame the map will use.
/// Its silhouette's extent does not depend on how steeply the camera looks down at it.
pub fn center_in_box(
    camera: &PinholeCamera,
    depth_m: &scarp_slam::image::DepthImage,
    world_from_camera: &Isometry3<f64>,
    bbox: &BoundingBox,
) -> Option<Point3<f64>> {
    let central_depth_m = median_depth_in_box(depth_m, bbox)?;
    let (u, v) = bbox.center();
    let surface = world_from_camera * camera.unproject(&Point2::new(u, v), central_depth_m);
    let size_m = (bbox.width() / camera.fx).max(bbox.height() / camera.fy.abs()) * central_depth_m;
    let reach_m = OBJECT_REACH_PER_SIZE * size_m + OBJECT_REACH_MARGIN_M;
    let near: Vec<Point3<f64>> = points_in_box(camera, depth_m, world_from_camera, bbox)
        .into_iter()
        .filter(|p| (p.xy() - surface.xy()).norm() <= reach_m)
        .collect();
    if near.len() < MIN_TARGET_POINTS {
        return None;
    }
    let ground_z = quantile(&mut near.iter().map(|p| p.z).collect::<Vec<_>>(), 0.05);
    let object: Vec<Point3<f64>> = near
        .into_iter()
        .filter(|p| p.z > ground_z + ABOVE_GROUND_M)
        .collect();
    center_of_silhouette(&world_from_camera.translation.vector.into(), &object)
}

/// The depth points of the pixels inside `bbox` (clamped to the image), in the frame of
/// `world_from_camera`, row by row.
pub fn points_in_box(
    camera: &PinholeCamera,
    depth_m: &scarp_slam::image::DepthImage,
    world_from_camera: &Isometry3<f64>,
    bbox: &BoundingBox,
) -> Vec<Point3<f64>> {
    let clamp = |v: f64, n: u32| v.round().clamp(0.0, f64::from(n) - 1.0) as u32;
    let (u0, u1) = (
        clamp(bbox.x_min, depth_m.width()),
        clamp(bbox.x_max, depth_m.width()),
    );
    let (v0, v1) = (
        clamp(bbox.y_min, depth_m.height()),
        clamp(bbox.y_max, depth_m.height()),
    );
    let mut points = Vec::new();
    for v in v0..=v1 {
        for u in u0..=u1 {
            if let Some(&d) = depth_m.get(u, v)
                && d > 0.0
            {
                let p = camera.unproject(&Point2::new(f64::from(u), f64::from(v)), f64::from(d));
                points.push(world_from_camera * p);
            }
        }
    }
    points
}

/// The centre of an object whose visible surface is `object`, seen from `eye`: across the
/// horizontal viewing direction, the middle of its extent (1st to 99th percentile, against
/// depth noise); along it, the nearest point plus half that extent (a round cross-section);
/// its height, the median. `None` with fewer than 30 points.
pub fn center_of_silhouette(eye: &Point3<f64>, object: &[Point3<f64>]) -> Option<Point3<f64>> {
    if object.len() < MIN_TARGET_POINTS {
        return None;
    }
    let median_of = |f: &dyn Fn(&Point3<f64>) -> f64| {
        quantile(&mut object.iter().map(f).collect::<Vec<_>>(), 0.5)
    };
    let toward = nalgebra::Vector2::new(median_of(&|p| p.x) - eye.x, median_of(&|p| p.y) - eye.y);
    if toward.norm() < 1e-6 {
        return None;
    }
    let forward = toward.normalize();
    let across = nalgebra::Vector2::new(-forward.y, forward.x);
    let along_of = |p: &Point3<f64>| forward.dot(&(p.xy() - eye.xy()));
    let across_of = |p: &Point3<f64>| across.dot(&(p.xy() - eye.xy()));
    let mut across_m: Vec<f64> = object.iter().map(across_of).collect();
    let (left, right) = (quantile(&mut across_m, 0.01), quantile(&mut across_m, 0.99));
    let nearest = quantile(&mut object.iter().map(along_of).collect::<Vec<_>>(), 0.01);
    let half_width = 0.5 * (right - left);
    let center_xy =
        eye.xy().coords + forward * (nearest + half_width) + across * (0.5 * (left + right));
    Some(Point3::new(center_xy.x, center_xy.y, median_of(&|p| p.z)))
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

    fn state_of(target: &crate::localization::target::Target) -> TargetState {
        let c = target.covariance();
        TargetState {
            id: target.id(),
            center: target.center(),
            points: target.points().to_vec(),
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
            .map(Self::state_of)
            .collect()
    }

    /// One target, if it still exists.
    pub fn target_state(&self, id: u32) -> Option<TargetState> {
        self.catalog.target(id).map(Self::state_of)
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
    use crate::localization::test_scenes::sphere_on_ground;
    use nalgebra::Vector3;
    use scarp_slam::geometry::look_at;
    use scarp_slam::image::DepthImage;

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

    #[test]
    fn a_sphere_on_the_ground_is_found_from_above_and_from_the_side() {
        let camera = PinholeCamera::from_hfov(320, 240, 80.0).unwrap();
        let (center, radius) = (Point3::new(3.0, -2.0, 0.7), 0.7);
        for (elevation_deg, azimuth) in [(55.0f64, 0.3f64), (20.0, 2.0), (40.0, -1.2)] {
            let e = elevation_deg.to_radians();
            let eye = center
                + Vector3::new(azimuth.cos() * e.cos(), azimuth.sin() * e.cos(), e.sin()) * 5.0;
            let pose = look_at(&eye, &center, &Vector3::z()).unwrap();
            let depth = sphere_on_ground(&camera, &pose, &center, radius);
            let px = camera.project(&(pose.inverse() * center)).unwrap();
            let r_px = radius / 5.0 * camera.fx * 1.2;
            let bbox =
                BoundingBox::new(px.x - r_px, px.y - r_px, px.x + r_px, px.y + r_px).unwrap();
            let found = center_in_box(&camera, &depth, &pose, &bbox).unwrap();
            let horizontal = (found.xy() - center.xy()).norm();
            assert!(
                horizontal < 0.1,
                "{elevation_deg}°: {found:?} is {horizontal} m off"
            );
        }
        // A box on bare ground holds no object.
        let pose = look_at(
            &Point3::new(20.0, 0.0, 5.0),
            &Point3::new(25.0, 0.0, 0.0),
            &Vector3::z(),
        )
        .unwrap();
        let depth = sphere_on_ground(&camera, &pose, &center, radius);
        let bbox = BoundingBox::new(140.0, 100.0, 180.0, 140.0).unwrap();
        assert!(center_in_box(&camera, &depth, &pose, &bbox).is_none());
    }

    #[test]
    fn median_depth_reads_the_box_centre() {
        let mut depth = DepthImage::filled(100, 80, 0.0);
        for v in 20..60 {
            for u in 30..70 {
                if let Some(d) = depth.get_mut(u, v) {
                    *d = 12.0;
                }
            }
        }
        let inside = BoundingBox::new(30.0, 20.0, 70.0, 60.0).unwrap();
        assert_eq!(median_depth_in_box(&depth, &inside), Some(12.0));
        let empty = BoundingBox::new(0.0, 0.0, 20.0, 15.0).unwrap();
        assert_eq!(median_depth_in_box(&depth, &empty), None);
    }
}
