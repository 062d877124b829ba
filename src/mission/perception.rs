//! Perception during Search and FineLocalize: detect → track → localize, at the estimated pose.
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

use super::config::MissionConfig;
use crate::detection::simulated::SimulatedDetector;
use crate::detection::{BoundingBox, Detector};
use crate::localization::catalog::TargetCatalog;
use crate::localization::target::TargetStatus as FilterStatus;
use crate::tracking::tracker::Tracker;

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
    let (cx, cy) = bbox.center();
    let (hw, hh) = (0.25 * bbox.width(), 0.25 * bbox.height());
    let mut samples = Vec::with_capacity(81);
    for j in 0..9 {
        for i in 0..9 {
            let u = cx - hw + 2.0 * hw * f64::from(i) / 8.0;
            let v = cy - hh + 2.0 * hh * f64::from(j) / 8.0;
            if u < 0.0 || v < 0.0 {
                continue;
            }
            if let Some(&d) = depth_m.get(u.round() as u32, v.round() as u32)
                && d > 0.0
            {
                samples.push(f64::from(d));
            }
        }
    }
    if samples.is_empty() {
        return None;
    }
    samples.sort_by(f64::total_cmp);
    Some(samples[samples.len() / 2])
}

/// Wall time of each perception stage for one frame, seconds.
#[derive(Debug, Clone, Copy, Default)]
pub struct StageTimes {
    /// Detection.
    pub detect_s: f64,
    /// Box tracking.
    pub track_s: f64,
    /// Depth filter.
    pub localize_s: f64,
}

/// Detector, box tracker and depth filter.
pub struct Perception {
    detector: SimulatedDetector,
    tracker: Tracker,
    catalog: TargetCatalog,
    rng: Xoshiro256PlusPlus,
}

impl Perception {
    /// The simulated detector for `world`'s rocks, a fresh tracker and an empty catalog.
    ///
    /// # Errors
    /// Invalid detector, tracker or localization settings.
    pub fn new(world: &World, config: &MissionConfig, seed: u64) -> anyhow::Result<Self> {
        let mut detector_config = config.detection.simulated.clone();
        detector_config.seed = derive_seed(seed, 0xde7);
        Ok(Self {
            detector: SimulatedDetector::for_world(detector_config, world)?,
            tracker: Tracker::new(config.tracker.clone())?,
            catalog: TargetCatalog::new(config.localization)?,
            rng: Xoshiro256PlusPlus::seed_from_u64(derive_seed(seed, 0x10c)),
        })
    }

    /// Detects, tracks and localizes in one frame seen from `world_from_camera` (estimated).
    ///
    /// # Errors
    /// A frame without an instance mask, or a non-finite pose.
    pub fn process(
        &mut self,
        frame: &RgbdFrame,
        camera: &PinholeCamera,
        world_from_camera: &Isometry3<f64>,
    ) -> anyhow::Result<StageTimes> {
        let clock = Instant::now();
        let detections = self.detector.detect(frame)?;
        let detect_s = clock.elapsed().as_secs_f64();
        let clock = Instant::now();
        let tracks = self.tracker.step(&gray_from_rgb(&frame.rgb), &detections)?;
        let track_s = clock.elapsed().as_secs_f64();
        let clock = Instant::now();
        let max_depth_m = self.catalog.config().max_depth_m;
        let boxes: Vec<(u64, BoundingBox)> = tracks
            .iter()
            .filter(|t| t.confirmed && t.updated)
            .filter(|t| t.bbox.is_inside_image(camera.width, camera.height, 0.0))
            .filter(|t| {
                median_depth_in_box(&frame.depth_m, &t.bbox).is_some_and(|d| d <= max_depth_m)
            })
            .filter(|t| {
                BoundingBox::new(t.bbox.x_min, t.bbox.y_min, t.bbox.x_max, t.bbox.y_max).is_ok()
            })
            .map(|t| (t.id, t.bbox))
            .collect();
        let observed = self
            .catalog
            .observe(camera, world_from_camera, &boxes, &mut self.rng)?;
        tracing::debug!(
            "t = {:.2} s: {} detections, {} tracks, {} boxes to the filter; {:?}",
            frame.timestamp_s,
            detections.len(),
            tracks.len(),
            boxes.len(),
            observed
        );
        Ok(StageTimes {
            detect_s,
            track_s,
            localize_s: clock.elapsed().as_secs_f64(),
        })
    }

    /// Forgets every box track (after the camera looked elsewhere); targets stay.
    ///
    /// # Errors
    /// Never in practice: the tracker settings were valid when the mission started.
    pub fn reset_tracks(&mut self) -> anyhow::Result<()> {
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
}

#[cfg(test)]
mod tests {
    use super::*;
    use scarp_slam::image::DepthImage;

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
