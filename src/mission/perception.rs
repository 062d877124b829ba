//! Perception during Search and FineLocalize: detect → track → localize, at the estimated pose.
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

/// A target's box in one frame, with the estimated pose it was seen from.
#[derive(Debug, Clone, Copy)]
pub struct Sighting {
    /// The frame's estimated `world_from_camera` (world ENU metres).
    pub world_from_camera: Isometry3<f64>,
    /// The box that matched the target.
    pub bbox: BoundingBox,
    /// Median measured depth over the box's central half, metres.
    pub depth_m: f64,
}

/// The target's centre seen from `sightings`, in the frame of their estimated poses: each box centre's ray is followed to its median depth (a point on the rock's near
/// surface) and then `radius_m` further along the ray, which is exact for a sphere of that
/// radius; the result is the component-wise median over the sightings. `None` without
/// sightings.
///
/// Why: the point set's centre carries the GPS error of the localization, while the map is
/// anchored at the estimate of its first frame, seconds later. With the GPS walk (τ = 30 s)
/// the two differ by up to a metre or more, enough to push the rock out of its region of
/// interest; a box in the first mapped frame sees it in the frame the map will use.
pub fn center_from_sightings(
    camera: &PinholeCamera,
    sightings: &[Sighting],
    radius_m: f64,
) -> Option<Point3<f64>> {
    if sightings.is_empty() {
        return None;
    }
    let centers: Vec<Point3<f64>> = sightings
        .iter()
        .map(|s| {
            let (u, v) = s.bbox.center();
            let on_surface = camera.unproject(&Point2::new(u, v), s.depth_m);
            let along_ray = on_surface.coords.normalize() * radius_m;
            s.world_from_camera * (on_surface + along_ray)
        })
        .collect();
    let median = |axis: usize| {
        let mut v: Vec<f64> = centers.iter().map(|c| c[axis]).collect();
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    Some(Point3::new(median(0), median(1), median(2)))
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

    /// Runs the detector alone on `frame` (no tracking, no depth filter) and returns the
    /// detection whose box centre lies nearest to where `expected` (world ENU, in the frame of
    /// `world_from_camera`) projects, within `gate_px`, as a sighting; `None` when the point is
    /// behind the camera, nothing is near it, or its box has no depth.
    ///
    /// # Errors
    /// A frame without an instance mask.
    pub fn sight_near(
        &mut self,
        frame: &RgbdFrame,
        camera: &PinholeCamera,
        world_from_camera: &Isometry3<f64>,
        expected: &Point3<f64>,
        gate_px: f64,
    ) -> anyhow::Result<Option<Sighting>> {
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
        let nearest = detections
            .iter()
            .map(|d| d.bbox)
            .filter(|b| distance_px(b) <= gate_px)
            .min_by(|a, b| distance_px(a).total_cmp(&distance_px(b)));
        Ok(nearest.and_then(|bbox| {
            median_depth_in_box(&frame.depth_m, &bbox).map(|depth_m| Sighting {
                world_from_camera: *world_from_camera,
                bbox,
                depth_m,
            })
        }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion, Vector3};
    use scarp_slam::image::DepthImage;

    /// A camera at `eye` looking at `target` (z forward, y down in the image).
    fn looking_at(eye: Point3<f64>, target: Point3<f64>) -> Isometry3<f64> {
        let z = (target - eye).normalize();
        let x = z.cross(&Vector3::z()).normalize();
        let y = z.cross(&x);
        let rotation = nalgebra::Rotation3::from_basis_unchecked(&[x, y, z]);
        Isometry3::from_parts(
            Translation3::from(eye.coords),
            UnitQuaternion::from_rotation_matrix(&rotation),
        )
    }

    #[test]
    fn sightings_of_a_sphere_find_its_centre() {
        let camera = PinholeCamera::from_hfov(640, 480, 80.0).unwrap();
        let (center, radius) = (Point3::new(3.0, -2.0, 1.0), 0.7);
        // A stale sighting far off, then eight from around a circle, 55° down.
        let stale = Sighting {
            world_from_camera: looking_at(Point3::new(40.0, 0.0, 9.0), center),
            bbox: BoundingBox::new(10.0, 10.0, 30.0, 30.0).unwrap(),
            depth_m: 5.0,
        };
        let mut sightings = vec![stale];
        for k in 0..8 {
            let a = f64::from(k) * 0.2;
            let eye =
                center + Vector3::new(8.0 * a.cos(), 8.0 * a.sin(), 8.0 * 55f64.to_radians().tan());
            let pose = looking_at(eye, center);
            let in_camera = pose.inverse() * center;
            let pixel = camera.project(&in_camera).unwrap();
            let distance = in_camera.coords.norm();
            sightings.push(Sighting {
                world_from_camera: pose,
                bbox: BoundingBox::new(
                    pixel.x - 20.0,
                    pixel.y - 15.0,
                    pixel.x + 20.0,
                    pixel.y + 15.0,
                )
                .unwrap(),
                // The z-depth of the sphere's near point on the central ray.
                depth_m: in_camera.z * (distance - radius) / distance,
            });
        }
        let found = center_from_sightings(&camera, &sightings[1..], radius).unwrap();
        assert!((found - center).norm() < 1e-9, "{found:?}");
        // The median shrugs off the stale sighting.
        let with_stale = center_from_sightings(&camera, &sightings, radius).unwrap();
        assert!((with_stale - center).norm() < 1e-9, "{with_stale:?}");
        assert!(center_from_sightings(&camera, &[], radius).is_none());
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
