//! Map mode for one target: frame-to-model RGBD odometry and TSDF fusion inside the target's
//! cylinder region of interest (plus a margin), the coverage test that ends it, then bundle
//! adjustment, re-integration, the mesh, fragility and export.
//!
//! Frames whose view misses the region of interest are not mapped at all. Keyframes are kept
//! (without their instance masks) for bundle adjustment and re-integration, and every n-th
//! frame between them for re-integration (`mapping.reintegration_frame_stride`); the rest are
//! dropped after fusion.

use std::path::Path;
use std::time::Instant;

use super::error::{Context, MissionError, MissionResult};
use nalgebra::{Isometry3, Point3, Vector3};
use scarp_datasets::world::World;
use scarp_export::atomic::write_bytes_atomically;
use scarp_export::glb::{GlbNode, GlbOptions, write_glb};
use scarp_export::ply::{PlyEncoding, write_mesh, write_point_cloud};
use scarp_export::tum::{StampedPose, write_tum_trajectory};
use scarp_planning::prelude::VerticalCylinder;
use scarp_slam::mapping::{
    BetweenFrame, KeyframeSet, ModelTracker, ModelTrackingConfig, RefineConfig, TrackedFrame,
    refine_keyframes,
};
use scarp_slam::meshing::extract_mesh;
use scarp_slam::tsdf::Roi;
use scarp_slam::tsdf::TsdfConfig;
use scarp_slam::{PinholeCamera, PointCloud, RgbdFrame, TriangleMesh};

use super::catalog::TargetStatus;
use super::config::{CylinderEstimateConfig, MissionConfig};
use super::coverage::CylinderCoverage;
use super::evaluation::nearest_rock;
use super::perception::Perception;
use super::report::{StageTimings, TargetReport};
use crate::evaluation::mesh::{MeshEvalConfig, MeshEvaluation, Visibility, evaluate_mesh_at_taus};
use crate::evaluation::trajectory::{
    Alignment, TrajectoryEvalConfig, evaluate_trajectory, umeyama,
};
use crate::fragility::scan::{
    analyze_closed_scan, close_scan, find_scan_neck, patched_fraction, scan_centroid,
};
use crate::fragility::{ContactSpec, analyze};
use crate::localization::silhouette::center_in_box;

/// A frame kept for bundle adjustment and re-integration.
#[derive(Debug, Clone)]
pub struct StoredFrame {
    /// The frame (without its instance mask).
    pub frame: RgbdFrame,
    /// The pose it was fused at (odometry), world ENU.
    pub world_from_camera_odometry: Isometry3<f64>,
    /// The state estimate at the frame.
    pub world_from_camera_estimate: Isometry3<f64>,
    /// The true pose (ground truth, for evaluation only; `None` for a real or recorded flight).
    pub world_from_camera_truth: Option<Isometry3<f64>>,
    /// Covariance of the odometry motion since the previous keyframe (see
    /// [`scarp_slam::mapping::KeyframeSet::odometry_covariance`]).
    pub odometry_covariance: Option<nalgebra::Matrix6<f64>>,
    /// Frames dropped between the previous keyframe and this one: the odometry link to it
    /// crossed a loss of tracking.
    pub frames_dropped_before: usize,
}

/// The state of mapping one target.
pub struct MappingSession {
    target_id: u32,
    cylinder: VerticalCylinder,
    camera: PinholeCamera,
    tracker: ModelTracker,
    coverage: CylinderCoverage,
    stored: Vec<StoredFrame>,
    /// Frames kept between keyframes for the re-integration.
    between: Vec<BetweenFrame>,
    /// Keep every n-th mapped frame in `between` (0: none).
    between_stride: usize,
    frames_mapped: usize,
    /// Whether the target counts as mapped only once the coverage threshold is reached.
    coverage_required: bool,
    /// The last processed frame's odometry position minus its true position, when it was
    /// tracked (simulation only: what a controller flying on the odometry would be off by).
    navigation_error_m: Option<Vector3<f64>>,
    /// Frames dropped: their odometry failed or disagreed with the state estimate.
    frames_dropped: usize,
    /// Frames dropped since the last keyframe was stored.
    dropped_since_keyframe: usize,
    /// Frames after a gap in view tracked from a search over the estimate's walk.
    reacquisitions: usize,
    /// `frames_mapped` when the map's patched share was last read, and that share (`None`
    /// where the map could not be cut), for [`Self::ends_mapping`].
    patched_check: Option<(usize, Option<f64>)>,
    /// The guarded stretch of the flight, once [`Self::guard_from_here`] started it.
    guard: Option<GuardedStretch>,
}

/// Keyframes (and frames kept between them) from this long before the first frame a guarded
/// stretch lost are taken out of the map with it, seconds. Why: the rotation gate catches a
/// tracked jump, not a slide, and a view leaving what the model shares slides the odometry
/// over the frames before it fails (library-b, seed 62, session 54: the double rock's neck ring
/// lost the map, and the re-acquired guesses 0.40–0.57 m off the estimate took its F@2cm to
/// 0.296). One second is 20 frames at the mission's map rate.
pub const GUARD_ROLLBACK_S: f64 = 1.0;

/// A stretch of a mapping flight whose frames may share too little with the model for the
/// odometry (the neck ring's low views of a map built from above): its frames are mapped while
/// each is tracked, and from the first that is not, none, so that it can add views and never
/// break the map.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct GuardedStretch {
    /// Frames mapped on it (before it stopped).
    pub frames_mapped: usize,
    /// Why and when it stopped mapping; `None` while every frame was tracked.
    pub stop: Option<GuardStop>,
}

/// Where a guarded stretch stopped mapping.
#[derive(Debug, Clone, PartialEq)]
pub struct GuardStop {
    /// The first frame not tracked (its timestamp, simulated seconds).
    pub at_s: f64,
    /// Why it was not tracked.
    pub reason: String,
    /// Keyframes taken out of the map with it ([`GUARD_ROLLBACK_S`]).
    pub keyframes_removed: usize,
}

/// Frames tried to see the target in before its map starts where the localization put it
/// (see [`cylinder_seen_in_frame`]).
pub const RECENTER_ATTEMPTS: usize = 20;

/// Two frames' views of the target ([`cylinder_seen_in_frame`]) agree when their centres are
/// within this of each other, horizontally, metres. In a campaign of seeds 32–34 (session 24),
/// second views fell 0.05–0.28 m from the first on the 11 targets mapped whole, and 0.58–1.87 m
/// on the 4 whose map or α failed (a box on a neighbour or on the background's depth).
pub const RECENTER_AGREEMENT_M: f64 = 0.4;

/// What to do with a frame before the map's first one: see [`Recentering::step`].
#[derive(Debug, Clone, PartialEq)]
pub enum RecenterStep {
    /// Do not map this frame; look again in the next one.
    Wait,
    /// Move the map's cylinder here (`moved_m` horizontally from the localization's), then map
    /// the frame if the moved cylinder is in view.
    Move {
        /// The cylinder where the frame sees the target.
        cylinder: VerticalCylinder,
        /// How far it moved, metres.
        moved_m: f64,
    },
    /// Map the frame with the cylinder as it is.
    Map,
}

/// Moving the map's cylinder onto where the first mapped frames see the target, before the
/// map's frame is anchored (`mapping.recenter_on_first_frame`). A single frame's box can sit on
/// a neighbouring rock or take the background's depth, and a map started around the wrong
/// place cuts its rock off; so a move is made only when two views agree within
/// [`RECENTER_AGREEMENT_M`], and after [`RECENTER_ATTEMPTS`] frames without that the map
/// starts where the localization put the cylinder.
#[derive(Debug, Clone, Default)]
pub struct Recentering {
    attempts: usize,
    /// The last view not yet confirmed by another.
    pending: Option<VerticalCylinder>,
    /// A move was made (or the attempts are spent): map every frame from now on.
    settled: bool,
}

impl Recentering {
    /// Takes one frame's view of the target, `seen` ([`cylinder_seen_in_frame`]'s: where it
    /// sees the target and how far that is from the localization's cylinder, or `None`), and
    /// says what to do with the frame.
    pub fn step(&mut self, seen: Option<(VerticalCylinder, f64)>) -> RecenterStep {
        if self.settled {
            return RecenterStep::Map;
        }
        self.attempts += 1;
        let agrees = |now: &VerticalCylinder| {
            self.pending.is_some_and(|before| {
                (now.center_x_m - before.center_x_m).hypot(now.center_y_m - before.center_y_m)
                    <= RECENTER_AGREEMENT_M
            })
        };
        match seen {
            Some((cylinder, moved_m)) if agrees(&cylinder) => {
                self.settled = true;
                RecenterStep::Move { cylinder, moved_m }
            }
            Some((cylinder, _)) => {
                self.pending = Some(cylinder);
                self.wait_or_map()
            }
            None => self.wait_or_map(),
        }
    }

    /// Whether the cylinder is settled: every frame from now on is mapped as it is.
    pub fn is_settled(&self) -> bool {
        self.settled
    }

    fn wait_or_map(&mut self) -> RecenterStep {
        if self.attempts >= RECENTER_ATTEMPTS {
            self.settled = true;
            RecenterStep::Map
        } else {
            RecenterStep::Wait
        }
    }
}

/// The mapping cylinder's radius around `center` (world, m): the configured quantile of the
/// localization points' horizontal distances from it, clamped to the configured range.
pub fn cylinder_radius_m(
    points: &[Point3<f64>],
    center: &Point3<f64>,
    config: &CylinderEstimateConfig,
) -> f64 {
    let mut radii: Vec<f64> = points
        .iter()
        .map(|p| (p.x - center.x).hypot(p.y - center.y))
        .collect();
    radii.sort_by(f64::total_cmp);
    radii
        .get(((radii.len() as f64 - 1.0) * config.radius_quantile).round() as usize)
        .copied()
        .unwrap_or(config.min_radius_m)
        .clamp(config.min_radius_m, config.max_radius_m)
}

/// The mapping cylinder (paper §III, mapping) on the axis through `center`, of `radius_m`,
/// from `bottom_below_terrain_m` under `ground_m` (world z, m) to `top_over_center_radii`
/// radii above the centre (at least two radii tall).
///
/// # Errors
/// A non-finite or non-positive size.
pub fn cylinder_around(
    center: &Point3<f64>,
    radius_m: f64,
    ground_m: f64,
    config: &CylinderEstimateConfig,
) -> MissionResult<VerticalCylinder> {
    let bottom = ground_m - config.bottom_below_terrain_m;
    let top = (center.z + config.top_over_center_radii * radius_m).max(bottom + 2.0 * radius_m);
    Ok(VerticalCylinder::new(
        center.x, center.y, radius_m, bottom, top,
    )?)
}

/// The cylinder a mission maps `rock` in, built as the mission builds it ([`cylinder_radius_m`],
/// [`cylinder_around`]) but from the truth: the rock's centroid moved by `shift_m` (world
/// metres; zero, or a localization error) for the localized centre, its mesh's vertices for
/// the localized points, and the terrain under that centre for the ground the depth camera
/// measures. For planning studies and tests that fly the mission's rings without a mission.
///
/// # Errors
/// A rock whose size makes no valid cylinder.
pub fn rock_cylinder(
    world: &World,
    rock: &scarp_datasets::world::Rock,
    shift_m: &Vector3<f64>,
    config: &CylinderEstimateConfig,
) -> MissionResult<VerticalCylinder> {
    let points: Vec<Point3<f64>> = rock.mesh.positions.iter().map(|p| p.cast()).collect();
    let radius_m = cylinder_radius_m(&points, &rock.centroid, config);
    let centre = rock.centroid + shift_m;
    let ground_m = world.terrain_height_m(centre.x, centre.y);
    cylinder_around(&centre, radius_m, ground_m, config)
}

/// `old` moved to where the detector sees its target in `frame` (taken at
/// `world_from_camera`): the box nearest the cylinder's middle (within a quarter of the image),
/// whole in the image, gives the centre from the depth inside it ([`center_in_box`]). `None`
/// when no such box is seen or it lies more than `config.max_recenter_m` away. The cylinder is
/// also moved up or down to stand `config.bottom_below_terrain_m` below the ground this frame
/// sees around it ([`ground_height_near`]), unless that ground is not seen or lies more than
/// `config.max_recenter_m` from where the cylinder stood. Returns the moved cylinder and how
/// far it moved horizontally, m.
///
/// Why: the map is anchored at the state estimate of its first frame, seconds after the
/// localization; the GPS walk in between would offset the rock in its region of interest, and
/// its rings. The vertical walk moved the base ring, which the cylinder's bottom places: over
/// library-b seed 50 the estimate's height error went from −0.37 / +0.26 / +0.64 m when the
/// four targets were localized to −0.04 / +0.03 / +0.05 m when their maps began, so the base
/// rings flew 0.6–1.2 m above the contacts (planned 0.3–0.7 m), and the block's ring, planned
/// 0.2 m below its contact, ran into the rock and was dropped.
///
/// # Errors
/// A frame the detector cannot run on.
pub fn cylinder_seen_in_frame(
    perception: &mut Perception,
    frame: &RgbdFrame,
    camera: &PinholeCamera,
    world_from_camera: &Isometry3<f64>,
    old: &VerticalCylinder,
    config: &CylinderEstimateConfig,
) -> MissionResult<Option<(VerticalCylinder, f64)>> {
    let mid = old.axis_point(0.5 * (old.z_bottom_m + old.z_top_m));
    let gate_px = 0.25 * f64::from(camera.width);
    let seen = perception
        .detect_near(frame, camera, world_from_camera, &mid, gate_px)?
        .filter(|b| b.is_inside_image(camera.width, camera.height, 2.0))
        .and_then(|b| center_in_box(camera, &frame.depth_m, world_from_camera, &b))
        .map(|c| (c, (c.x - old.center_x_m).hypot(c.y - old.center_y_m)))
        .filter(|&(_, moved_m)| moved_m <= config.max_recenter_m);
    let Some((seen, moved_m)) = seen else {
        return Ok(None);
    };
    let rise_m = ground_height_near(
        camera,
        &frame.depth_m,
        world_from_camera,
        &seen,
        old.radius_m,
    )
    .map(|ground| ground - config.bottom_below_terrain_m - old.z_bottom_m)
    .filter(|rise| rise.abs() <= config.max_recenter_m)
    .unwrap_or(0.0);
    let cylinder = VerticalCylinder::new(
        seen.x,
        seen.y,
        old.radius_m,
        old.z_bottom_m + rise_m,
        old.z_top_m + rise_m,
    )?;
    Ok(Some((cylinder, moved_m)))
}

/// Median height of the depth points in a ring from `1.5·radius + 0.5` to `1.5·radius + 3`
/// metres (horizontally) around `center`: the ground around a target, seen from
/// `world_from_camera`. `None` with fewer than 50 such points.
pub fn ground_height_near(
    camera: &PinholeCamera,
    depth_m: &scarp_slam::image::DepthImage,
    world_from_camera: &Isometry3<f64>,
    center: &Point3<f64>,
    radius_m: f64,
) -> Option<f64> {
    let (r_in, r_out) = (1.5 * radius_m + 0.5, 1.5 * radius_m + 3.0);
    let mut heights = Vec::new();
    for v in (0..depth_m.height()).step_by(4) {
        for (u, &d) in depth_m.row(v).iter().enumerate().step_by(4) {
            if d <= 0.0 {
                continue;
            }
            let p = world_from_camera
                * camera.unproject(&nalgebra::Point2::new(u as f64, f64::from(v)), f64::from(d));
            let r = (p.x - center.x).hypot(p.y - center.y);
            if r >= r_in && r <= r_out {
                heights.push(p.z);
            }
        }
    }
    if heights.len() < 50 {
        return None;
    }
    heights.sort_by(f64::total_cmp);
    Some(heights[heights.len() / 2])
}

/// The region of interest: the cylinder grown by `margin_m` sideways and by `vertical_margin_m`
/// up and down.
///
/// The map is anchored at the state estimate of its first frame, whose vertical error (the
/// GPS walk) can exceed a metre and differs from the error when the target was localized: a
/// tight vertical range would cut the rock off.
pub fn roi_of(cylinder: &VerticalCylinder, margin_m: f64, vertical_margin_m: f64) -> Roi {
    Roi::Cylinder {
        center_xy: [cylinder.center_x_m, cylinder.center_y_m],
        z_min: cylinder.z_bottom_m - vertical_margin_m,
        z_max: cylinder.z_top_m + vertical_margin_m,
        radius_m: cylinder.radius_m + margin_m,
    }
}

/// Whether any of the cylinder's axis points (bottom, middle, top) and rim points at mid height
/// projects inside the image at `world_from_camera`, in front of the camera and within
/// `max_depth_m`.
pub fn sees_cylinder(
    camera: &PinholeCamera,
    world_from_camera: &Isometry3<f64>,
    cylinder: &VerticalCylinder,
    max_depth_m: f64,
) -> bool {
    let camera_from_world = world_from_camera.inverse();
    let mid = 0.5 * (cylinder.z_bottom_m + cylinder.z_top_m);
    let mut probes = vec![
        cylinder.axis_point(cylinder.z_bottom_m),
        cylinder.axis_point(mid),
        cylinder.axis_point(cylinder.z_top_m),
    ];
    for k in 0..8 {
        let a = f64::from(k) / 8.0 * std::f64::consts::TAU;
        probes.push(
            cylinder.axis_point(mid) + Vector3::new(a.cos(), a.sin(), 0.0) * cylinder.radius_m,
        );
    }
    probes.iter().any(|p| {
        let q = camera_from_world * p;
        q.z > 0.0
            && q.z <= max_depth_m
            && camera
                .project(&q)
                .is_some_and(|px| camera.in_bounds(&px, 0.0))
    })
}

impl MappingSession {
    /// An empty map of target `target_id` inside `cylinder` (grown by the configured margin).
    ///
    /// # Errors
    /// Invalid TSDF, odometry or camera settings.
    pub fn new(
        target_id: u32,
        cylinder: &VerticalCylinder,
        camera: &PinholeCamera,
        config: &MissionConfig,
    ) -> MissionResult<Self> {
        let m = &config.mapping;
        let roi = roi_of(cylinder, m.roi_margin_m, m.roi_vertical_margin_m);
        let tsdf = TsdfConfig {
            voxel_size_m: m.voxel_size_m as f32,
            max_depth_m: m.max_depth_m as f32,
            depth_sample: m.depth_sample,
            roi: Some(roi),
            ..TsdfConfig::default()
        };
        let tracking = ModelTrackingConfig {
            tsdf,
            odometry: m.odometry.clone(),
            keyframes: m.keyframes,
            estimate_rotation_gate: m.estimate_rotation_gate(&config.estimator),
            reacquisition: m.reacquisition_search(&config.estimator),
            max_dropped_frames: (m.max_dropped_s * config.map_camera_rate_hz).round() as usize,
            ..ModelTrackingConfig::default()
        };
        Ok(Self {
            target_id,
            cylinder: *cylinder,
            camera: *camera,
            tracker: ModelTracker::new(*camera, tracking)?,
            coverage: CylinderCoverage::new(cylinder, config.coverage),
            stored: Vec::new(),
            between: Vec::new(),
            between_stride: m.reintegration_frame_stride,
            frames_mapped: 0,
            coverage_required: true,
            navigation_error_m: None,
            frames_dropped: 0,
            dropped_since_keyframe: 0,
            reacquisitions: 0,
            patched_check: None,
            guard: None,
        })
    }

    /// The same session, whose target counts as mapped once analysed, whatever its coverage.
    ///
    /// Why: the live mission requires the coverage threshold, which is also what ends its
    /// mapping flight; processing a recording offline cannot fly more, and its 1 mm depth PNGs
    /// can move a coverage right at the threshold by a cell. The coverage stays in the row.
    pub fn without_coverage_requirement(mut self) -> Self {
        self.coverage_required = false;
        self
    }

    /// The target being mapped.
    pub fn target_id(&self) -> u32 {
        self.target_id
    }

    /// The cylinder the map covers (map frame, which is the state estimate's frame at the
    /// first mapped frame).
    pub fn cylinder(&self) -> &VerticalCylinder {
        &self.cylinder
    }

    /// Whether no frame has been mapped yet: the map frame is not anchored, and the cylinder
    /// can still move ([`Self::recenter`]).
    pub fn is_empty(&self) -> bool {
        self.frames_mapped == 0
    }

    /// Whether a frame seen from `world_from_camera` would be mapped.
    pub fn would_map(&self, world_from_camera: &Isometry3<f64>) -> bool {
        let max_depth = f64::from(self.tracker.volume().config().max_depth_m);
        sees_cylinder(&self.camera, world_from_camera, &self.cylinder, max_depth)
    }

    /// Moves the cylinder (its region of interest and coverage) before the first frame is
    /// mapped.
    ///
    /// # Errors
    /// A map that already holds frames (its frame is anchored), or invalid settings.
    pub fn recenter(
        &mut self,
        cylinder: &VerticalCylinder,
        config: &MissionConfig,
    ) -> MissionResult<()> {
        if !self.is_empty() {
            return Err(MissionError::invalid(format!(
                "target {}: the map already holds frames; its cylinder cannot move",
                self.target_id
            )));
        }
        let coverage_required = self.coverage_required;
        *self = Self::new(self.target_id, cylinder, &self.camera, config)?;
        self.coverage_required = coverage_required;
        Ok(())
    }

    /// How far the odometry's position of the frame last given to [`Self::process`] is from
    /// the truth (metres, world ENU): the navigation error of a vehicle flying on the map's
    /// odometry. `None` when that frame was not tracked (out of the region of interest,
    /// dropped, or placed by the state estimate after an odometry failure) or its truth is
    /// unknown.
    pub fn navigation_error_m(&self) -> Option<Vector3<f64>> {
        self.navigation_error_m
    }

    /// Coverage of the cylinder so far.
    pub fn coverage(&self) -> &CylinderCoverage {
        &self.coverage
    }

    /// Whether mapping may stop flying: the coverage's cells would end it
    /// ([`CylinderCoverage::ends_mapping`]) and the rock in the map so far is patched over no
    /// more than `coverage.max_patched_fraction` of its closed surface. The share is read
    /// (the tracking volume meshed, cut and closed) at most every
    /// `coverage.patched_check_every_frames` mapped frames, and only once the cells are done;
    /// with the rule off (1) it is read once, for the report. A map that cannot be cut yet (no
    /// neck, nothing above it) does not hold the flight: the analysis will say why.
    pub fn ends_mapping(&mut self, config: &MissionConfig) -> bool {
        let coverage = &config.coverage;
        if !self.coverage.ends_mapping() {
            return false;
        }
        let due = self.patched_check.is_none_or(|(at, _)| {
            self.frames_mapped >= at + coverage.patched_check_every_frames.max(1)
        });
        if due {
            let mesh = extract_mesh(self.tracker.volume(), &config.mapping.meshing());
            let share = patched_fraction(&mesh, &config.fragility.scan).ok();
            tracing::debug!(
                "target {}: {} frames mapped, the map's rock patched over {}",
                self.target_id,
                self.frames_mapped,
                share.map_or("? (not cut)".to_string(), |s| format!("{:.0}%", 100.0 * s))
            );
            self.patched_check = Some((self.frames_mapped, share));
        }
        coverage.max_patched_fraction >= 1.0
            || self
                .patched_check
                .and_then(|(_, share)| share)
                .is_none_or(|share| share <= coverage.max_patched_fraction)
    }

    /// The neck of the rock in the map so far ([`find_scan_neck`]), world z in the frame the
    /// vehicle flies in (m), for the neck ring.
    ///
    /// # Errors
    /// A message when the map is empty or shows no neck (a rock sitting on the ground).
    pub fn neck_height_m(&self, config: &MissionConfig) -> Result<f64, String> {
        if self.is_empty() {
            return Err("nothing mapped".into());
        }
        let mesh = extract_mesh(self.tracker.volume(), &config.mapping.meshing());
        find_scan_neck(&mesh, &config.fragility.scan).map_err(|e| format!("the map's neck: {e}"))
    }

    /// The rock's patched share at the last reading by [`Self::ends_mapping`] (`None` before
    /// one, or where the map could not be cut).
    pub fn last_patched_fraction(&self) -> Option<f64> {
        self.patched_check.and_then(|(_, share)| share)
    }

    /// From the next frame on, maps only while every frame is tracked (see [`GuardedStretch`]):
    /// the first frame the odometry fails, distrusts or has to re-acquire stops the mapping
    /// for good and takes the keyframes of the [`GUARD_ROLLBACK_S`] before it out of the map.
    pub fn guard_from_here(&mut self) {
        self.guard = Some(GuardedStretch::default());
    }

    /// The guarded stretch, once [`Self::guard_from_here`] started one.
    pub fn guarded_stretch(&self) -> Option<&GuardedStretch> {
        self.guard.as_ref()
    }

    /// Stops the guarded stretch at the frame at `at_s`: takes out the keyframes and the frames
    /// between them from [`GUARD_ROLLBACK_S`] before it.
    fn stop_guarded_stretch(&mut self, at_s: f64, reason: String) {
        let cutoff_s = at_s - GUARD_ROLLBACK_S;
        let before = self.stored.len();
        // Keyframes before the guarded stretch stay: it started after them.
        self.stored.retain(|f| f.frame.timestamp_s < cutoff_s);
        self.between.retain(|f| f.frame.timestamp_s < cutoff_s);
        let keyframes_removed = before - self.stored.len();
        tracing::warn!(
            "target {}: the guarded stretch stops mapping at {at_s:.2} s ({reason}); {} \
             keyframes of the {GUARD_ROLLBACK_S} s before it taken out",
            self.target_id,
            keyframes_removed
        );
        if let Some(guard) = self.guard.as_mut() {
            guard.stop = Some(GuardStop {
                at_s,
                reason,
                keyframes_removed,
            });
        }
    }

    /// Maps one frame when its view meets the region of interest: tracks it against the model,
    /// fuses it, updates the coverage and keeps it if it is a keyframe. The true pose, where
    /// known (simulation), is kept for the evaluation only. On a guarded stretch that stopped,
    /// frames are not mapped.
    ///
    /// # Errors
    /// A frame that does not match the camera or a non-finite estimate.
    pub fn process(
        &mut self,
        mut frame: RgbdFrame,
        world_from_camera_estimate: &Isometry3<f64>,
        world_from_camera_truth: Option<&Isometry3<f64>>,
    ) -> MissionResult<()> {
        self.navigation_error_m = None;
        if self.guard.as_ref().is_some_and(|g| g.stop.is_some())
            || !self.would_map(world_from_camera_estimate)
        {
            return Ok(());
        }
        frame.instance_mask = None;
        let tracked = self.tracker.process(&frame, world_from_camera_estimate)?;
        // The way to a stretch mostly leaves the target out of view, so its first frame is
        // often a re-acquisition (library-b seed 60, session 55: a neck ring stopped on its
        // first frame, re-acquired on the estimate itself). One the odometry trusts opens it;
        // any later one means the view left the model part way, and stops it.
        let opening = self.guard.as_ref().is_some_and(|g| g.frames_mapped == 0);
        let reacquired_mid_stretch = tracked.reacquisition.is_some() && !opening;
        if self.guard.is_some() && (tracked.dropped || tracked.fell_back || reacquired_mid_stretch)
        {
            let reason = match (tracked.distrust_reason(), &tracked.reacquisition) {
                (Some(why), _) => why,
                (None, Some(r)) => format!(
                    "re-acquired after {:.1} s out of view, {:.2} m from the estimate",
                    r.gap_s,
                    r.offset_m.norm()
                ),
                (None, None) => "placed by the estimate".into(),
            };
            self.stop_guarded_stretch(frame.timestamp_s, reason);
            if tracked.dropped {
                self.frames_dropped += 1;
            }
            return Ok(());
        }
        if let Some(guard) = self.guard.as_mut() {
            guard.frames_mapped += 1;
        }
        if let Some(r) = &tracked.reacquisition {
            self.reacquisitions += 1;
            tracing::info!(
                "target {}: frame at {:.2} s, {:.1} s after the last one kept, searched over {} \
                 guesses: {}; kept the guess {:.2} m from the estimate's ({:+.2}, {:+.2}, {:+.2})",
                self.target_id,
                frame.timestamp_s,
                r.gap_s,
                r.starts,
                match (tracked.distrust_reason(), tracked.dropped) {
                    (None, _) => "re-acquired".to_string(),
                    (Some(why), true) => format!("dropped, {why}"),
                    (Some(why), false) => format!("placed by the estimate, {why}"),
                },
                r.offset_m.norm(),
                r.offset_m.x,
                r.offset_m.y,
                r.offset_m.z
            );
        }
        if tracked.dropped {
            self.frames_dropped += 1;
            self.dropped_since_keyframe += 1;
            tracing::debug!(
                "target {}: frame at {:.2} s dropped: {}",
                self.target_id,
                frame.timestamp_s,
                tracked.distrust_reason().unwrap_or_default()
            );
            return Ok(());
        }
        trace_tracked_frame(
            self.target_id,
            frame.timestamp_s,
            &tracked,
            world_from_camera_estimate,
            world_from_camera_truth,
        );
        self.navigation_error_m = world_from_camera_truth
            .filter(|_| !tracked.fell_back)
            .map(|truth| tracked.world_from_camera.translation.vector - truth.translation.vector);
        self.coverage
            .observe(&self.camera, &tracked.world_from_camera);
        if tracked.keyframe.is_some() {
            self.stored.push(StoredFrame {
                frame,
                world_from_camera_odometry: tracked.world_from_camera,
                world_from_camera_estimate: *world_from_camera_estimate,
                world_from_camera_truth: world_from_camera_truth.copied(),
                odometry_covariance: tracked.keyframe_covariance,
                frames_dropped_before: std::mem::take(&mut self.dropped_since_keyframe),
            });
        } else if !tracked.fell_back
            && self.between_stride > 0
            && self.frames_mapped.is_multiple_of(self.between_stride)
            && !self.stored.is_empty()
        {
            self.between.push(BetweenFrame {
                keyframe: self.stored.len() - 1,
                frame,
                world_from_camera_odometry: tracked.world_from_camera,
            });
        }
        self.frames_mapped += 1;
        Ok(())
    }
}

/// One TRACE line per tracked frame (`RUST_LOG=scarp::mission::mapping=trace`): how the
/// odometry converged and, in simulation, how far the odometry and the state estimate are from
/// the truth (world ENU, metres), to find where a map's odometry slid. The errors are formatted
/// only when TRACE is on (`tracing` evaluates an event's arguments after its level check).
fn trace_tracked_frame(
    target_id: u32,
    timestamp_s: f64,
    tracked: &TrackedFrame,
    world_from_camera_estimate: &Isometry3<f64>,
    world_from_camera_truth: Option<&Isometry3<f64>>,
) {
    let error = |pose: &Isometry3<f64>| {
        world_from_camera_truth.map_or_else(String::new, |truth| {
            let e = pose.translation.vector - truth.translation.vector;
            format!("({:+.3}, {:+.3}, {:+.3})", e.x, e.y, e.z)
        })
    };
    let (inlier_ratio, correspondences, iterations) =
        tracked.odometry.as_ref().map_or((f64::NAN, 0, 0), |o| {
            (o.inlier_ratio, o.correspondences, o.iterations)
        });
    tracing::trace!(
        "target {target_id}: frame {} at {timestamp_s:.2} s: keyframe {:?}, fell back {}, \
         inliers {inlier_ratio:.3} of {correspondences}, {iterations} iterations; \
         odometry − truth {}, estimate − truth {}",
        tracked.index,
        tracked.keyframe,
        tracked.fell_back,
        error(&tracked.world_from_camera),
        error(world_from_camera_estimate),
    );
}

/// Records in `report` the keyframe links no landmark spans (`spanning[i]` landmarks span the
/// link from keyframe `i` to `i + 1`, stamped `timestamps_s`), and those among them that
/// crossed dropped frames (`dropped_before[i + 1]`), each with a WARN line: there the map's two
/// parts are held together by one odometry result after a loss of tracking, which nothing in
/// the adjustment checks.
fn report_unspanned_links(
    report: &mut TargetReport,
    spanning: &[usize],
    dropped_before: &[usize],
    timestamps_s: &[f64],
) {
    let unspanned: Vec<usize> = (0..spanning.len()).filter(|&i| spanning[i] == 0).collect();
    report.keyframe_links_unspanned = unspanned.len();
    report.keyframe_links_unspanned_after_drops = 0;
    for &i in &unspanned {
        let dropped = dropped_before.get(i + 1).copied().unwrap_or(0);
        if dropped == 0 {
            continue;
        }
        report.keyframe_links_unspanned_after_drops += 1;
        tracing::warn!(
            "target {}: keyframes at {:.2} s and {:.2} s are joined across {dropped} dropped \
             frames by the odometry alone: no landmark spans them",
            report.id,
            timestamps_s.get(i).copied().unwrap_or(f64::NAN),
            timestamps_s.get(i + 1).copied().unwrap_or(f64::NAN),
        );
    }
}

/// Writes the keyframes' trajectories (TUM, `world_from_camera`, stamped with `timestamps_s`):
/// `keyframes_odometry.txt`, `keyframes_ba.txt` (both in the map frame) and, with ground truth,
/// `keyframes_groundtruth.txt`, so that the mapping flight can be inspected with the TUM tools.
fn write_keyframe_trajectories(
    dir: &Path,
    timestamps_s: &[f64],
    truth: Option<&[StampedPose]>,
    odometry: &[Isometry3<f64>],
    refined: &[Isometry3<f64>],
) -> MissionResult<()> {
    let stamped = |poses: &[Isometry3<f64>]| -> Vec<StampedPose> {
        timestamps_s
            .iter()
            .zip(poses)
            .map(|(&timestamp_s, p)| StampedPose {
                timestamp_s,
                world_from_camera: *p,
            })
            .collect()
    };
    let truth = truth.map(|t| {
        (
            "keyframes_groundtruth.txt",
            t.to_vec(),
            "keyframe true world_from_camera (world frame)",
        )
    });
    for (name, poses, comment) in [
        (
            "keyframes_odometry.txt",
            stamped(odometry),
            "keyframe world_from_camera from RGBD odometry (map frame)",
        ),
        (
            "keyframes_ba.txt",
            stamped(refined),
            "keyframe world_from_camera after bundle adjustment (map frame)",
        ),
    ]
    .into_iter()
    .chain(truth)
    {
        let path = dir.join(name);
        write_tum_trajectory(&path, &poses, comment)
            .with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(())
}

/// ATE RMSE (SE(3)-aligned) of `poses` against `truth` (same length and timestamps).
fn ate_rmse(truth: &[StampedPose], poses: &[Isometry3<f64>]) -> Option<f64> {
    let estimate: Vec<StampedPose> = truth
        .iter()
        .zip(poses)
        .map(|(t, p)| StampedPose {
            timestamp_s: t.timestamp_s,
            world_from_camera: *p,
        })
        .collect();
    let config = TrajectoryEvalConfig {
        alignment: Alignment::Se3,
        ..TrajectoryEvalConfig::default()
    };
    evaluate_trajectory(truth, &estimate, &config)
        .ok()
        .map(|m| m.ate_rmse_m)
}

/// The rigid transform that best maps the mapping trajectory's camera centres onto the true
/// ones (Umeyama, no scale): the map frame's offset from the world, the GPS error at mapping.
/// `None` when the camera centres are too few or degenerate for an alignment.
pub fn map_to_world(truth: &[StampedPose], poses: &[Isometry3<f64>]) -> Option<Isometry3<f64>> {
    let source: Vec<Vector3<f64>> = poses.iter().map(|p| p.translation.vector).collect();
    let target: Vec<Vector3<f64>> = truth
        .iter()
        .map(|t| t.world_from_camera.translation.vector)
        .collect();
    let s = umeyama(&source, &target, false).ok()?;
    Some(Isometry3::from_parts(
        s.translation.into(),
        nalgebra::UnitQuaternion::from_rotation_matrix(&s.rotation),
    ))
}

/// The mission status of a target from [`finish_target`]'s outcome: mapped, or incomplete
/// (a failure is kept in `report.error`).
pub fn mapped_status(outcome: MissionResult<bool>, report: &mut TargetReport) -> TargetStatus {
    match outcome {
        Ok(true) => TargetStatus::Mapped,
        Ok(false) => TargetStatus::Incomplete,
        Err(e) => {
            report.error = Some(format!("{e:#}"));
            TargetStatus::Incomplete
        }
    }
}

/// The mean of `estimate`'s camera positions less `truth`'s, pose by pose, metres; `None`
/// when they are empty or differ in length.
fn mean_position_error_m(
    estimate: &[Isometry3<f64>],
    truth: &[StampedPose],
) -> Option<Vector3<f64>> {
    (!estimate.is_empty() && estimate.len() == truth.len()).then(|| {
        estimate
            .iter()
            .zip(truth)
            .map(|(e, t)| e.translation.vector - t.world_from_camera.translation.vector)
            .sum::<Vector3<f64>>()
            / estimate.len() as f64
    })
}

/// Finishes a target: bundle adjustment of the stored frames, re-integration, mesh, fragility,
/// files in `dir` (`mesh.ply`, `mesh.glb`, `points.ply`, `fragility.json`, view PNGs) and, with
/// ground truth (`world`, and every keyframe's true pose), the scores in `report`. Without a
/// world, the view PNGs are lit by the built-in default world's sun. Returns whether the
/// target counts as mapped (coverage reached, unless the session does not require it, see
/// [`MappingSession::without_coverage_requirement`]; and fragility analysed).
///
/// # Errors
/// Only writing errors; a failed analysis is recorded in `report.error`.
pub fn finish_target(
    session: MappingSession,
    points: &[Point3<f64>],
    world: Option<&World>,
    config: &MissionConfig,
    dir: &Path,
    report: &mut TargetReport,
    timings: &mut StageTimings,
) -> MissionResult<bool> {
    let clock = Instant::now();
    report.frames_mapped = session.frames_mapped;
    report.frames_dropped = session.frames_dropped;
    report.reacquisitions = session.reacquisitions;
    report.coverage = session.coverage.fraction();
    report.base_coverage = session.coverage.bottom_fraction();
    report.sweep_deg = session.coverage.sweep_deg();
    report.largest_unseen_region_cells = session.coverage.largest_unseen_region_cells();
    report.map_patched_fraction = session.last_patched_fraction();
    report.keyframes = session.stored.len();
    let shortfall = session.coverage.shortfall();
    let stored = session.stored;
    if stored.len() < 3 {
        report.error = Some(format!("only {} frames were mapped", stored.len()));
        return Ok(false);
    }
    // The frames move into the keyframe set; the truth stays beside it for the evaluation.
    let timestamps_s: Vec<f64> = stored.iter().map(|f| f.frame.timestamp_s).collect();
    let dropped_before: Vec<usize> = stored.iter().map(|f| f.frames_dropped_before).collect();
    let truth: Option<Vec<StampedPose>> = stored
        .iter()
        .map(|f| {
            f.world_from_camera_truth
                .map(|world_from_camera| StampedPose {
                    timestamp_s: f.frame.timestamp_s,
                    world_from_camera,
                })
        })
        .collect();
    let mut keyframes = KeyframeSet {
        between_frames: session.between,
        ..KeyframeSet::default()
    };
    for f in stored {
        keyframes
            .world_from_camera_odometry
            .push(f.world_from_camera_odometry);
        keyframes
            .world_from_camera_estimate
            .push(f.world_from_camera_estimate);
        keyframes.odometry_covariance.push(f.odometry_covariance);
        keyframes.frames.push(f.frame);
    }
    let odometry_poses = &keyframes.world_from_camera_odometry;
    let refine = RefineConfig {
        tsdf: session.tracker.volume().config().clone(),
        meshing: config.mapping.meshing(),
        mesh_before: false,
        ..config.mapping.refine.clone()
    };
    // The F-score before BA (with a world to score against) is the tracking volume's: every
    // mapped frame fused at its odometry pose as it was tracked, the map without the adjustment.
    // Fusing the keyframes again at their odometry poses for it took as long as the re-fusion
    // after BA (5.4 s against 5.2 s a target on the small test world) and measured nearly the
    // same map.
    let started = Instant::now();
    let mesh_before = world
        .is_some()
        .then(|| extract_mesh(session.tracker.volume(), &refine.meshing));
    let mesh_before_s = started.elapsed().as_secs_f64();
    let refined = refine_keyframes(&session.camera, &keyframes, &refine)?;
    tracing::info!(
        "target {}: refined in {:.1} s (landmarks {:.1}, BA {:.1}, re-fusion {:.1}, mesh {:.1}, \
         tracking volume's mesh {mesh_before_s:.1})",
        report.id,
        clock.elapsed().as_secs_f64(),
        refined.landmarks_ms * 1e-3,
        refined.ba_ms * 1e-3,
        refined.reintegrate_ms * 1e-3,
        refined.mesh_ms * 1e-3,
    );
    report_unspanned_links(
        report,
        &refined.tracks.landmarks_spanning_links(timestamps_s.len()),
        &dropped_before,
        &timestamps_s,
    );
    let mesh = refined.mesh;
    let refined = refined.world_from_camera;
    report.triangles = mesh.faces.len();
    timings.ba_mesh_s += clock.elapsed().as_secs_f64();

    let clock = Instant::now();
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    // The scan is open (ROI cut, unseen parts): cut the rock off above its support, extrapolate
    // its contact from the basal profile, close it and analyse it.
    let closed = close_scan(&mesh, &config.fragility.scan);
    // The closed rock's volume centroid places the target to centimetres where the box filter
    // places it to decimetres, in the map's frame (the estimate's over the keyframes); where
    // closing refused the contact, the same cut and patches without it.
    let centroid = match &closed {
        Ok(closed) => closed
            .mesh
            .volume_properties()
            .ok()
            .map(|v| closed.support_from_scan.inverse() * v.centroid),
        Err(_) => scan_centroid(&mesh, &config.fragility.scan).ok(),
    };
    if let Some(centroid) = centroid {
        report.set_scan_center(&centroid);
    }
    report.estimator_error_over_keyframes_m = truth
        .as_deref()
        .and_then(|t| mean_position_error_m(&keyframes.world_from_camera_estimate, t))
        .map(Into::into);
    let fragility = closed.and_then(|closed| analyze_closed_scan(&closed, &config.fragility));
    let coverage_required = session.coverage_required;
    let mut mapped = shortfall.is_none() || !coverage_required;
    match &fragility {
        Ok(analysis) => {
            let r = &analysis.report;
            report.alpha_min_deg = Some(r.alpha_min_deg);
            report.alpha_min_low_deg = Some(r.alpha_min_low_deg);
            report.alpha_min_high_deg = Some(r.alpha_min_high_deg);
            report.support_tilt_deg = Some(r.support_tilt_deg);
            report.toppling_pga_g = Some(r.toppling_pga_g);
            report.size_m = Some(r.rock_height_m);
            let json = serde_json::to_string_pretty(r)?;
            write_bytes_atomically(dir.join("fragility.json"), json.as_bytes())?;
        }
        Err(e) => {
            report.error = Some(format!("fragility: {e}"));
            mapped = false;
        }
    }
    if let Some(shortfall) = shortfall.filter(|_| coverage_required)
        && report.error.is_none()
    {
        report.error = Some(format!("coverage: {shortfall}"));
    }
    write_mesh(dir.join("mesh.ply"), &mesh, PlyEncoding::BinaryLittleEndian)?;
    write_keyframe_trajectories(
        dir,
        &timestamps_s,
        truth.as_deref(),
        odometry_poses,
        &refined,
    )?;
    let mut extras = serde_json::json!({"target_id": report.id, "status": if mapped {"mapped"} else {"incomplete"}});
    if let Some(a) = report.alpha_min_deg {
        extras["alpha_min_deg"] = a.into();
        extras["alpha_min_low_deg"] = report.alpha_min_low_deg.into();
        extras["alpha_min_high_deg"] = report.alpha_min_high_deg.into();
        extras["toppling_pga_g"] = report.toppling_pga_g.into();
    }
    write_glb(
        dir.join("mesh.glb"),
        &[GlbNode {
            name: format!("target_{}", report.id),
            mesh: &mesh,
            extras,
        }],
        &GlbOptions::default(),
    )?;
    let cloud = PointCloud::from_positions(points.iter().map(|p| p.cast::<f32>()).collect());
    write_point_cloud(
        dir.join("points.ply"),
        &cloud,
        PlyEncoding::BinaryLittleEndian,
    )?;
    if !mesh.faces.is_empty() {
        let view_mesh = fragility
            .as_ref()
            .map_or_else(|_| mesh.clone(), |a| a.closed_rock());
        match world {
            Some(world) => super::html::write_mesh_views(world, &view_mesh, dir)?,
            None => super::html::write_mesh_views(&World::builtin_default()?, &view_mesh, dir)?,
        };
    }
    timings.fragility_export_s += clock.elapsed().as_secs_f64();

    let clock = Instant::now();
    if let Some(world) = world {
        score_against_ground_truth(
            world,
            config,
            truth.as_deref(),
            odometry_poses,
            &refined,
            &mesh,
            mesh_before.as_ref(),
            report,
            &session.camera,
        );
    }
    timings.evaluation_s += clock.elapsed().as_secs_f64();
    Ok(mapped)
}

/// F-scores at 1 and 2 cm (and accuracy, completeness, visible fraction at 1 cm) of `mesh`,
/// built at `poses` in the map frame, against `rock`, after the SE(3) alignment of `poses` to
/// the truth and counting only the ground truth visible from the mapping flight.
fn score_mesh(
    world: &World,
    rock: &scarp_datasets::world::Rock,
    truth: &[StampedPose],
    poses: &[Isometry3<f64>],
    mesh: &TriangleMesh,
    camera: &PinholeCamera,
) -> Option<[MeshEvaluation; 2]> {
    let world_from_map = map_to_world(truth, poses)?;
    let mut aligned = mesh.clone();
    aligned.transform(&world_from_map);
    // Visibility from at most 60 of the mapping flight's true poses: enough to tell the base
    // and the contact from what a camera saw.
    let step = truth.len().div_ceil(60).max(1);
    let visibility = Visibility {
        world,
        camera: *camera,
        world_from_camera: truth
            .iter()
            .step_by(step)
            .map(|t| t.world_from_camera)
            .collect(),
        tolerance_m: 0.01,
    };
    let config = MeshEvalConfig {
        crop_to_gt_m: Some(0.1),
        ..MeshEvalConfig::default()
    };
    // The pedestal is true surface too: mapped inside the crop box, it is no error of the rock's.
    let scores = evaluate_mesh_at_taus(
        &aligned,
        &rock.mesh,
        rock.pedestal.as_ref(),
        &config,
        Some(&visibility),
        &[0.01, 0.02],
    )
    .ok()?;
    scores.try_into().ok()
}

/// Fills the ground-truth fields of `report` (nothing when no true rock is near): the true α_min
/// and, with the true poses `truth`, the ATEs and the mesh scores.
#[allow(clippy::too_many_arguments)]
fn score_against_ground_truth(
    world: &World,
    config: &MissionConfig,
    truth: Option<&[StampedPose]>,
    odometry_poses: &[Isometry3<f64>],
    refined: &[Isometry3<f64>],
    mesh: &TriangleMesh,
    mesh_before: Option<&TriangleMesh>,
    report: &mut TargetReport,
    camera: &PinholeCamera,
) {
    let Some((rock, _)) = nearest_rock(world, &Point3::from(report.center)) else {
        return;
    };
    if let Some(pedestal) = &rock.pedestal
        && let Ok(gt) = analyze(
            &rock.mesh,
            ContactSpec::Pedestal(pedestal),
            &config.fragility,
        )
    {
        report.alpha_min_gt_deg = Some(gt.alpha_min_deg);
        report.alpha_error_deg = report.alpha_min_deg.map(|a| (a - gt.alpha_min_deg).abs());
    }
    // The trajectory and mesh scores need the true poses (a recorded flight keeps them apart).
    let Some(truth) = truth else {
        return;
    };
    report.ate_before_ba_m = ate_rmse(truth, odometry_poses);
    report.ate_after_ba_m = ate_rmse(truth, refined);
    if let Some([at_1cm, at_2cm]) = score_mesh(world, rock, truth, refined, mesh, camera) {
        report.fscore_1cm = Some(at_1cm.fscore);
        report.fscore_2cm = Some(at_2cm.fscore);
        report.accuracy_mean_m = Some(at_1cm.accuracy_mean_m);
        report.completeness_mean_m = Some(at_1cm.completeness_mean_m);
        report.gt_visible_fraction = Some(at_1cm.gt_visible_fraction);
    }
    if let Some(before) = mesh_before
        && let Some([_, at_2cm]) = score_mesh(world, rock, truth, odometry_poses, before, camera)
    {
        report.fscore_2cm_before_ba = Some(at_2cm.fscore);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_map_cylinder_moves_only_where_two_views_agree() {
        let at = |x: f64, y: f64| {
            let cylinder = VerticalCylinder::new(x, y, 0.8, -0.2, 2.0).unwrap();
            Some((cylinder, x.hypot(y)))
        };
        // A jump to a neighbour, then the rock twice: the move waits for the two alike.
        let mut r = Recentering::default();
        assert_eq!(r.step(at(2.5, 0.0)), RecenterStep::Wait);
        assert_eq!(r.step(at(0.6, 0.1)), RecenterStep::Wait);
        assert_eq!(r.step(None), RecenterStep::Wait);
        match r.step(at(0.7, 0.2)) {
            RecenterStep::Move { cylinder, moved_m } => {
                assert_eq!((cylinder.center_x_m, cylinder.center_y_m), (0.7, 0.2));
                assert!((moved_m - 0.7f64.hypot(0.2)).abs() < 1e-12);
            }
            other => panic!("{other:?}"),
        }
        assert!(r.is_settled());
        assert_eq!(r.step(at(3.0, 0.0)), RecenterStep::Map);
        // Views that never agree leave the cylinder where the localization put it.
        let mut r = Recentering::default();
        let steps: Vec<RecenterStep> = (0..RECENTER_ATTEMPTS)
            .map(|k| r.step(at(if k % 2 == 0 { 1.0 } else { -1.0 }, 0.0)))
            .collect();
        assert!(
            steps[..RECENTER_ATTEMPTS - 1]
                .iter()
                .all(|s| *s == RecenterStep::Wait)
        );
        assert_eq!(steps[RECENTER_ATTEMPTS - 1], RecenterStep::Map);
        assert_eq!(r.step(at(1.0, 0.0)), RecenterStep::Map);
    }

    /// The first mapped frame moves the cylinder by the state estimate's error at that frame,
    /// up and down as well as across: its bottom follows the ground that frame sees, so the
    /// base ring it places stays at its height above the ground whatever the GPS walked since
    /// the localization.
    #[test]
    fn the_first_mapped_frame_moves_the_cylinder_up_and_across() {
        let world = World::builtin_default().unwrap();
        let config = MissionConfig::default();
        let rock = world.rocks.iter().find(|r| r.id == 3).unwrap();
        let truth = rock_cylinder(&world, rock, &Vector3::zeros(), &config.cylinder).unwrap();
        let camera = PinholeCamera::from_hfov(320, 240, 87.0).unwrap();
        let centre = rock.centroid;
        let eye = centre + Vector3::new(-4.5, 1.5, 3.5);
        let world_from_camera =
            scarp_slam::geometry::look_at(&eye, &centre, &Vector3::z()).unwrap();
        let rendered = scarp_datasets::render::Renderer::new(&world)
            .render(&camera, &world_from_camera)
            .unwrap();
        let frame =
            RgbdFrame::new(0.0, rendered.rgb, rendered.depth_m, Some(rendered.instance)).unwrap();
        let mut perception = Perception::new(&world, &config, 3).unwrap();
        let mut seen_from = |world_from_camera: &Isometry3<f64>| {
            cylinder_seen_in_frame(
                &mut perception,
                &frame,
                &camera,
                world_from_camera,
                &truth,
                &config.cylinder,
            )
            .unwrap()
            .expect("the rock is in view")
            .0
        };
        // Seen from the true pose, the cylinder stays where the truth's ground puts it.
        let still = seen_from(&world_from_camera);
        let rise_m = still.z_bottom_m - truth.z_bottom_m;
        assert!(rise_m.abs() < 0.1, "rose {rise_m:.3} m");
        // The estimate is off by the GPS walk: the cylinder moves with it, up as well.
        let walk = Vector3::new(0.4, -0.3, 0.7);
        let estimate = Isometry3::from_parts(
            (walk + world_from_camera.translation.vector).into(),
            world_from_camera.rotation,
        );
        let moved = seen_from(&estimate);
        let moved_by = Vector3::new(
            moved.center_x_m - still.center_x_m,
            moved.center_y_m - still.center_y_m,
            moved.z_bottom_m - still.z_bottom_m,
        );
        assert!((moved_by - walk).norm() < 1e-6, "{moved_by:?}");
        assert!((moved.height_m() - truth.height_m()).abs() < 1e-9);
        // Where the cylinder is behind the camera, nothing moves.
        let away = Isometry3::from_parts(
            estimate.translation,
            nalgebra::UnitQuaternion::from_axis_angle(&Vector3::z_axis(), std::f64::consts::PI)
                * estimate.rotation,
        );
        assert!(
            cylinder_seen_in_frame(
                &mut perception,
                &frame,
                &camera,
                &away,
                &truth,
                &config.cylinder
            )
            .unwrap()
            .is_none()
        );
    }

    /// `center_in_box` from low views, where the terrain rising behind a rock fills the top of
    /// its box: the centre is as close to the truth as the rock's own pixels (its instance
    /// mask) put it, on every target of three worlds from twelve azimuths. Before the object
    /// was limited to the box's size around its central depth, it came out up to 7.7 m off.
    #[test]
    fn the_centre_seen_from_low_is_the_rocks() {
        use crate::localization::silhouette::{center_in_box, center_of_silhouette, points_in_box};
        use scarp_datasets::world::RockRole;
        let camera = PinholeCamera::from_hfov(640, 480, 87.0).unwrap();
        let mut worst_m: f64 = 0.0;
        for name in ["default", "library-a", "library-b"] {
            let world = World::builtin(name).unwrap();
            let mut perception = Perception::new(&world, &MissionConfig::default(), 3).unwrap();
            let renderer = scarp_datasets::render::Renderer::new(&world);
            for rock in world.rocks.iter().filter(|r| r.role == RockRole::Target) {
                let centre = rock.centroid;
                for (out_m, up_m, k) in (0..12).flat_map(|k| [(3.5, 0.6, k), (6.0, 1.5, k)]) {
                    let azimuth = f64::from(k) * std::f64::consts::PI / 6.0;
                    let eye =
                        centre + Vector3::new(out_m * azimuth.cos(), out_m * azimuth.sin(), up_m);
                    let pose = scarp_slam::geometry::look_at(&eye, &centre, &Vector3::z()).unwrap();
                    let rendered = renderer.render(&camera, &pose).unwrap();
                    let mut rock_only = rendered.depth_m.clone();
                    for (d, id) in rock_only
                        .as_mut_slice()
                        .iter_mut()
                        .zip(rendered.instance.as_slice())
                    {
                        if *id != rock.id as u16 {
                            *d = 0.0;
                        }
                    }
                    let frame = RgbdFrame::new(
                        0.0,
                        rendered.rgb,
                        rendered.depth_m,
                        Some(rendered.instance),
                    )
                    .unwrap();
                    let bbox = perception
                        .detect_near(&frame, &camera, &pose, &centre, 160.0)
                        .unwrap()
                        .filter(|b| b.is_inside_image(camera.width, camera.height, 2.0))
                        .expect("the rock is detected");
                    let off_m = |c: Option<Point3<f64>>| (c.unwrap().xy() - centre.xy()).norm();
                    let seen_m = off_m(center_in_box(&camera, &frame.depth_m, &pose, &bbox));
                    let own_m = off_m(center_of_silhouette(
                        &eye,
                        &points_in_box(&camera, &rock_only, &pose, &bbox),
                    ));
                    assert!(
                        seen_m <= own_m + 0.25 && seen_m <= 1.0,
                        "{name} rock {} from {out_m} m out, {up_m} m up, azimuth {k}/12: \
                         {seen_m:.2} m off (its own pixels: {own_m:.2} m)",
                        rock.id
                    );
                    worst_m = worst_m.max(seen_m);
                }
            }
        }
        eprintln!("worst centre error {worst_m:.2} m");
    }

    #[test]
    fn only_unspanned_links_across_dropped_frames_count_as_after_drops() {
        let mut report = TargetReport {
            keyframe_links_unspanned_after_drops: 7,
            ..TargetReport::default()
        };
        // Links 0..4; 1 and 3 are unspanned; keyframe 2 follows 5 drops, keyframe 4 none,
        // keyframe 1 follows 2 drops but its link is spanned.
        report_unspanned_links(
            &mut report,
            &[4, 0, 9, 0],
            &[0, 2, 5, 0, 0],
            &[0.0, 1.0, 2.0, 3.0, 4.0],
        );
        assert_eq!(report.keyframe_links_unspanned, 2);
        assert_eq!(report.keyframe_links_unspanned_after_drops, 1);
        report_unspanned_links(&mut report, &[], &[0], &[0.0]);
        assert_eq!(report.keyframe_links_unspanned, 0);
        assert_eq!(report.keyframe_links_unspanned_after_drops, 0);
    }

    #[test]
    fn the_mapping_table_chooses_how_the_tsdf_samples_depth() {
        let world = World::builtin_default().unwrap();
        let rock = world.targets().next().unwrap();
        let camera = PinholeCamera::from_hfov(160, 120, 87.0).unwrap();
        let sample_of = |config: &MissionConfig| {
            let cylinder =
                rock_cylinder(&world, rock, &Vector3::zeros(), &config.cylinder).unwrap();
            let session = MappingSession::new(1, &cylinder, &camera, config).unwrap();
            session.tracker.volume().config().depth_sample
        };
        assert_eq!(
            sample_of(&MissionConfig::default()),
            scarp_slam::tsdf::DepthSample::Bilinear
        );
        let nearest: MissionConfig =
            toml::from_str("[mapping]\ndepth_sample = \"nearest\"").unwrap();
        assert_eq!(sample_of(&nearest), scarp_slam::tsdf::DepthSample::Nearest);
        assert!(toml::from_str::<MissionConfig>("[mapping]\ndepth_sample = \"cubic\"").is_err());
    }

    /// A mapping session of the default world's first rock, and views round it: step `step`
    /// of a circle 1.5 m outside its cylinder, 3° and 0.1 s apart, taken `delay_s` later, with
    /// the estimate yawed by `yaw_error_deg`.
    fn circling_first_rock(
        world: &World,
    ) -> (
        MappingSession,
        impl FnMut(&mut MappingSession, u32, f64, f64),
    ) {
        let rock = world.targets().next().unwrap();
        let mut config = MissionConfig::default();
        // These tests are about the guarded stretch, and need its frames tracked. The small
        // camera's 3° steps drop a frame now and then; searching after each (the default)
        // keeps the map closer (10 mm against 17–22 mm by step 29) but had the stretch's first
        // frame diverge, where one guess and a re-acquisition after a 1 s run tracked it.
        config.mapping.reacquisition_after_drops = false;
        let camera = PinholeCamera::from_hfov(160, 120, 87.0).unwrap();
        let cylinder = rock_cylinder(world, rock, &Vector3::zeros(), &config.cylinder).unwrap();
        let session = MappingSession::new(1, &cylinder, &camera, &config).unwrap();
        let centre = rock.centroid;
        let renderer = scarp_datasets::render::Renderer::new(world);
        let view = move |session: &mut MappingSession, step: u32, yaw_error_deg: f64, delay_s| {
            let azimuth = (f64::from(step) * 3.0).to_radians();
            let out_m = cylinder.radius_m + 1.5;
            let eye = centre + Vector3::new(out_m * azimuth.cos(), out_m * azimuth.sin(), 1.0);
            let pose = scarp_slam::geometry::look_at(&eye, &centre, &Vector3::z()).unwrap();
            let rendered = renderer.render(&camera, &pose).unwrap();
            let t_s = f64::from(step) * 0.1 + delay_s;
            let frame = RgbdFrame::new(t_s, rendered.rgb, rendered.depth_m, None).unwrap();
            let yaw =
                nalgebra::UnitQuaternion::from_euler_angles(0.0, 0.0, yaw_error_deg.to_radians());
            let estimate = Isometry3::from_parts(pose.translation, yaw * pose.rotation);
            session.process(frame, &estimate, Some(&pose)).unwrap();
        };
        (session, view)
    }

    /// A guarded stretch opened after 2 s without a view of the rock (its first frame a
    /// re-acquisition, which opens it) and stopped by a frame the rotation gate distrusts.
    #[test]
    fn a_guarded_stretch_stops_at_the_first_frame_lost_and_takes_its_last_second_out() {
        let world = World::builtin_default().unwrap();
        let (mut session, mut view_at) = circling_first_rock(&world);
        let mut view = |session: &mut MappingSession, step: u32, yaw_error_deg: f64| {
            view_at(
                session,
                step,
                yaw_error_deg,
                if step >= 30 { 2.0 } else { 0.0 },
            );
        };
        for step in 0..30 {
            view(&mut session, step, 0.0);
        }
        let before_guard = session.stored.len();
        let reacquired_before = session.reacquisitions;
        session.guard_from_here();
        for step in 30..45 {
            view(&mut session, step, 0.0);
        }
        // Its first frame was re-acquired, and opened it.
        assert_eq!(session.reacquisitions, reacquired_before + 1);
        let guard = session.guarded_stretch().unwrap().clone();
        assert_eq!((guard.frames_mapped, guard.stop), (15, None));
        let in_last_second = session
            .stored
            .iter()
            .filter(|f| f.frame.timestamp_s >= 5.5 - 1e-9)
            .count();
        assert!(
            in_last_second > 0 && session.stored.len() > before_guard,
            "the guarded frames made keyframes, some in its last second: {} of {}",
            in_last_second,
            session.stored.len()
        );
        // The state estimate turns 10° in 0.1 s where the views do not: the frame is distrusted.
        view(&mut session, 45, 10.0);
        let stop = session.guarded_stretch().unwrap().stop.clone().unwrap();
        assert_eq!(stop.at_s, 6.5);
        assert_eq!(stop.keyframes_removed, in_last_second, "{}", stop.reason);
        assert!(!stop.reason.is_empty());
        assert!(session.stored.iter().all(|f| f.frame.timestamp_s < 5.5));
        assert!(session.between.iter().all(|f| f.frame.timestamp_s < 5.5));
        let kept = session.stored.len();
        for step in 46..60 {
            view(&mut session, step, 0.0);
        }
        assert_eq!(
            session.stored.len(),
            kept,
            "nothing is mapped after the stop"
        );
        assert_eq!(session.guarded_stretch().unwrap().frames_mapped, 15);
    }

    /// A re-acquisition part way along a guarded stretch (the view left the model) stops it.
    #[test]
    fn a_re_acquisition_part_way_stops_a_guarded_stretch() {
        let world = World::builtin_default().unwrap();
        let (mut session, mut view) = circling_first_rock(&world);
        for step in 0..30 {
            view(&mut session, step, 0.0, 0.0);
        }
        session.guard_from_here();
        for step in 30..40 {
            view(&mut session, step, 0.0, 0.0);
        }
        view(&mut session, 40, 0.0, 2.0);
        let stop = session.guarded_stretch().unwrap().stop.clone().unwrap();
        assert_eq!(stop.at_s, 6.0, "{}", stop.reason);
        assert!(stop.reason.contains("re-acquired"), "{}", stop.reason);
        assert_eq!(session.guarded_stretch().unwrap().frames_mapped, 10);
    }

    /// The cells of a loose coverage end mapping after a few frames; the rock's patched share
    /// keeps it flying while the map holds one side of the rock only, and lets it end once the
    /// ring has gone round.
    #[test]
    fn mapping_flies_on_while_the_rock_in_the_map_is_mostly_unseen() {
        let world = World::builtin_default().unwrap();
        let rock = world.targets().next().unwrap();
        let mut config = MissionConfig::default();
        config.coverage.threshold = 0.05;
        config.coverage.max_unseen_region_cells = 0;
        config.coverage.top_cells = 0;
        config.coverage.patched_check_every_frames = 1;
        config.coverage.max_patched_fraction = 0.3;
        let camera = PinholeCamera::from_hfov(160, 120, 87.0).unwrap();
        let cylinder = rock_cylinder(&world, rock, &Vector3::zeros(), &config.cylinder).unwrap();
        let mut session = MappingSession::new(1, &cylinder, &camera, &config).unwrap();
        let renderer = scarp_datasets::render::Renderer::new(&world);
        let centre = rock.centroid;
        let view = |session: &mut MappingSession, deg: f64| {
            let azimuth = deg.to_radians();
            let out_m = cylinder.radius_m + 1.5;
            let eye = centre + Vector3::new(out_m * azimuth.cos(), out_m * azimuth.sin(), 1.0);
            let pose = scarp_slam::geometry::look_at(&eye, &centre, &Vector3::z()).unwrap();
            let rendered = renderer.render(&camera, &pose).unwrap();
            let frame = RgbdFrame::new(deg / 10.0, rendered.rgb, rendered.depth_m, None).unwrap();
            session.process(frame, &pose, Some(&pose)).unwrap();
        };
        for step in 0..=12 {
            view(&mut session, f64::from(step) * 5.0);
        }
        assert!(
            session.coverage().ends_mapping(),
            "the loose cells are done: {} frames mapped, {:?}",
            session.frames_mapped,
            session.coverage().shortfall()
        );
        let mut one_side = config.clone();
        assert!(!session.ends_mapping(&one_side));
        let share = session.last_patched_fraction().unwrap();
        assert!(share > 0.3, "{share}");
        one_side.coverage.max_patched_fraction = 1.0;
        assert!(session.ends_mapping(&one_side), "the rule turned off");
        for step in 13..=72 {
            view(&mut session, f64::from(step) * 5.0);
        }
        assert!(session.ends_mapping(&config));
        let share = session.last_patched_fraction().unwrap();
        assert!(share <= 0.3, "{share}");
    }

    #[test]
    fn an_empty_map_moves_its_region_and_a_started_one_refuses() {
        let config = MissionConfig::default();
        let camera = PinholeCamera::from_hfov(64, 48, 80.0).unwrap();
        let cylinder = VerticalCylinder::new(0.0, 0.0, 1.0, 0.0, 2.0).unwrap();
        let mut session = MappingSession::new(7, &cylinder, &camera, &config).unwrap();
        let moved = VerticalCylinder::new(0.5, -0.3, 1.0, 0.0, 2.0).unwrap();
        session.recenter(&moved, &config).unwrap();
        assert_eq!(session.cylinder(), &moved);
        assert_eq!(session.target_id(), 7);
        let m = &config.mapping;
        assert_eq!(
            session.tracker.volume().config().roi,
            Some(roi_of(&moved, m.roi_margin_m, m.roi_vertical_margin_m))
        );
        // Once a frame is mapped the map frame is anchored around the cylinder.
        session.frames_mapped = 1;
        assert!(!session.is_empty());
        let err = session.recenter(&cylinder, &config).unwrap_err();
        assert!(err.to_string().contains("already holds frames"), "{err}");
        assert_eq!(session.cylinder(), &moved);
    }
}
