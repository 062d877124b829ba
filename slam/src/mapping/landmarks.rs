//! Landmarks for bundle adjustment: corners on and around the target's region of interest,
//! initialised from depth, re-observed in every later keyframe where the odometry predicts them.
//!
//! Each landmark keeps the keyframe it was started in (its anchor), its anchor pixel and the
//! surface normal fitted to the anchor's depth around it. At each new keyframe every landmark
//! is projected through the odometry pose; where it lands inside the image, in front of the
//! measured surface (not occluded), seen within `max_view_angle_deg` of the anchor's view and
//! from the front of its surface, it is tracked with KLT **from its anchor image**, starting at
//! the predicted pixel with the window warped by the plane-induced homography (the linear part
//! at the point). Observations are therefore independent (no drift along a chain of
//! keyframe-to-keyframe tracks), sub-pixel, and a landmark re-enters the view when the orbit
//! closes its loop. A match farther than `max_prediction_error_px` from the prediction is
//! rejected (a slip onto another surface). After each new observation the landmark is
//! re-triangulated from its pixels and depths with the odometry poses, which sharpens the next
//! prediction.
//!
//! Without a ROI (a handheld sequence of a whole scene) new corners are spread over the frame by
//! a grid (`whole_frame_grid_cells`), so the adjustment sees the whole view, not its most
//! textured patch.
//!
//! New corners are detected inside the image rectangle that the ROI projects to, away from the
//! landmarks observed in the keyframe, where the depth is valid and smooth around the corner
//! (no silhouettes) and the back-projected point lies inside the ROI (grown by
//! `roi_margin_m`). Landmarks seen by fewer than `min_observations` keyframes are dropped.

use nalgebra::{Isometry3, Matrix2, Matrix3, Point2, Point3, Vector2, Vector3};
use serde::{Deserialize, Serialize};

use super::MappingError;
use super::residuals::triangulate_point;
use crate::PinholeCamera;
use crate::ba::{KeyframeNoise, KeyframeObservation};
use crate::features::{
    CornerConfig, CornerRegion, GuidedPoint, KltConfig, KltPyramid, KltStatus, PixelRect,
    detect_corners, track_points_guided,
};
use crate::image::{DepthImage, GrayImage, MaskImage};
use crate::tsdf::Roi;

/// Settings of [`track_landmarks`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LandmarkConfig {
    /// Corner detection at each keyframe. Default: Harris, at most 400 corners at least 8 px
    /// apart (a 640×480 frame of a rock at 4 m yields a few hundred usable corners).
    pub corners: CornerConfig,
    /// KLT from a landmark's anchor keyframe into a later one, started at the predicted pixel
    /// with the predicted window warp. Default: [`KltConfig::default`] with 2 pyramid levels
    /// (the odometry predicts within a pixel or two), a 15 px window (about 15 cm of rock at
    /// 4 m: small enough for the plane model of the warp, large enough for sub-pixel matches)
    /// and brightness compensation (keyframes seconds apart on a real camera differ in
    /// exposure).
    pub klt: KltConfig,
    /// New corners are not started within this distance of a landmark observed in the same
    /// keyframe, pixels. Default 8.
    pub min_track_distance_px: f64,
    /// A landmark needs at least this many keyframes observing it. Default 3.
    pub min_observations: usize,
    /// Reject a KLT match farther than this from the landmark's projection through the odometry
    /// pose, pixels. Default 3 (odometry drifts by millimetres, a pixel is about 1 cm at 4 m;
    /// before a landmark is triangulated its depth-only position is off by a few centimetres).
    pub max_prediction_error_px: f64,
    /// Corners whose back-projected point lies outside the ROI grown by this are ignored,
    /// metres. Default 0.3 ("on and around the target").
    pub roi_margin_m: f64,
    /// A landmark is searched for only in keyframes whose viewing direction to it lies within
    /// this angle of its anchor's, degrees (beyond it the plane-warped anchor window no longer
    /// matches the rock's curved surface). Default 45.
    pub max_view_angle_deg: f64,
    /// A landmark is searched for only where the measured depth at its predicted pixel agrees
    /// with its predicted depth within this fraction (otherwise it is occluded or off the
    /// surface). Default 0.05 (the default sensor's depth σ at 4.5 m is 1%).
    pub max_occlusion_depth_ratio: f64,
    /// Radius of the square window of depths a new corner's surface plane is fitted to,
    /// pixels. Default 8 (17×17 px, about 17 cm at 4.5 m).
    pub normal_radius_px: u32,
    /// A new corner is on a silhouette or depth edge (and not started) when more than a tenth
    /// of that window has no depth or a depth lies farther than this fraction of the corner's
    /// depth from the plane. Default 0.05 (five σ of the default sensor at 4.5 m; a rock
    /// against the terrain behind it jumps by tens of percent).
    pub silhouette_depth_ratio: f64,
    /// A depth is used (for initialisation and as a depth residual) only where the four pixels
    /// around the corner agree within this fraction of their mean. Default 0.05 (a range of four
    /// samples of the default sensor's 1% noise at 4.5 m; 0.02 threw half the depths away).
    pub max_depth_spread_ratio: f64,
    /// Pixel and depth σ used when re-triangulating a landmark between keyframes. Default
    /// 0.5 px, 0.045 m (the default sensor's depth σ at 4.5 m).
    pub triangulation_noise: KeyframeNoise,
    /// Without a ROI, and unless `corners.grid_cells` is set, new corners are spread over this
    /// grid of `[columns, rows]` cells of the frame. Default `[8, 6]` (80 px cells at 640×480,
    /// a share of 9 corners each).
    pub whole_frame_grid_cells: [u32; 2],
    /// Without a ROI, a track is no longer searched for once KLT has failed to find it in this
    /// many keyframes in a row that should have seen it; `None` searches for every track in
    /// every keyframe. Default 25. A handheld camera sweeping a room predicts thousands of old
    /// tracks into each keyframe, most of them ones it already failed to match (occluded,
    /// blurred, drifted beyond `max_prediction_error_px`): on TUM freiburg1_rpy (242 keyframes)
    /// the search took 64 s, and 20 s with 25 misses for the same observations (36 334 and
    /// 36 646; every-frame ATE after BA 45.8 and 46.3 mm, odometry 46.3 mm). Fewer misses are
    /// faster still (10: 12 s; 3: 6 s), but the ATE after BA rose to 47.4 and 50.3 mm, and
    /// 3 dropped 4% of the observations. With a ROI the camera circles its target and returns
    /// to its landmarks, so every track stays.
    pub whole_frame_max_misses: Option<u32>,
}

impl Default for LandmarkConfig {
    fn default() -> Self {
        Self {
            corners: CornerConfig {
                max_corners: 400,
                min_distance_px: 8.0,
                ..CornerConfig::default()
            },
            klt: KltConfig {
                window_px: 15,
                pyramid_levels: 2,
                compensate_brightness: true,
                ..KltConfig::default()
            },
            min_track_distance_px: 8.0,
            min_observations: 3,
            max_prediction_error_px: 3.0,
            roi_margin_m: 0.3,
            max_view_angle_deg: 45.0,
            max_occlusion_depth_ratio: 0.05,
            normal_radius_px: 8,
            silhouette_depth_ratio: 0.05,
            max_depth_spread_ratio: 0.05,
            triangulation_noise: KeyframeNoise {
                pixel_sigma_px: 0.5,
                depth_sigma_m: 0.045,
            },
            whole_frame_grid_cells: [8, 6],
            whole_frame_max_misses: Some(25),
        }
    }
}

/// One keyframe's input to the landmark tracker.
#[derive(Debug, Clone, Copy)]
pub struct LandmarkView<'a> {
    /// Intensity in [0, 1].
    pub gray: &'a GrayImage,
    /// z-depth, metres (0 = none).
    pub depth_m: &'a DepthImage,
    /// The keyframe's pose from odometry.
    pub world_from_camera: &'a Isometry3<f64>,
}

/// Landmarks and their keyframe observations, ready for [`crate::ba::solve`] with a
/// [`crate::ba::KeyframeModel`].
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Landmarks {
    /// World positions (ENU metres), triangulated from the observations' pixels and depths with
    /// the odometry poses.
    pub points: Vec<Vector3<f64>>,
    /// Observations, grouped by landmark in creation order.
    pub observations: Vec<KeyframeObservation>,
}

impl Landmarks {
    /// For each link between keyframes `i` and `i + 1` (of `keyframes` in all), how many
    /// landmarks are observed on both sides of it: by keyframe `i` or an earlier one, and by
    /// `i + 1` or a later one. A link no landmark spans holds the map's two parts together by
    /// its odometry prior alone, which bundle adjustment cannot check (session 65: a frame
    /// tracked 0.13 m off after 14 dropped frames split a map in two this way). Observations
    /// of keyframes at or beyond `keyframes` are ignored. Empty for fewer than two keyframes.
    #[must_use]
    pub fn landmarks_spanning_links(&self, keyframes: usize) -> Vec<usize> {
        let links = keyframes.saturating_sub(1);
        let mut first_last = vec![(usize::MAX, 0usize); self.points.len()];
        for o in self.observations.iter().filter(|o| o.camera < keyframes) {
            if let Some((first, last)) = first_last.get_mut(o.point) {
                *first = (*first).min(o.camera);
                *last = (*last).max(o.camera);
            }
        }
        // A landmark seen first at `a` and last at `b` spans links a..b: a difference array.
        let mut starts_minus_ends = vec![0i64; links + 1];
        for &(first, last) in first_last.iter().filter(|(f, l)| f < l) {
            starts_minus_ends[first] += 1;
            starts_minus_ends[last] -= 1;
        }
        starts_minus_ends
            .iter()
            .take(links)
            .scan(0i64, |spanning, d| {
                *spanning += d;
                Some(usize::try_from(*spanning).unwrap_or(0))
            })
            .collect()
    }
}

/// A landmark being tracked: where it started, its surface and its observations so far (their
/// `point` index is assigned when the landmarks are assembled).
struct Track {
    anchor: usize,
    anchor_pixel: Point2<f32>,
    normal_world: Vector3<f64>,
    point_world: Vector3<f64>,
    observations: Vec<KeyframeObservation>,
    /// Keyframes in a row that should have seen the track where KLT did not find it.
    misses: u32,
}

/// Tracks corners through `views` (keyframes in order) and turns tracks into landmarks.
///
/// # Errors
/// [`MappingError::Features`] for invalid corner/KLT settings or images of different sizes;
/// [`MappingError::InvalidConfig`] for invalid landmark settings.
pub fn track_landmarks(
    camera: &PinholeCamera,
    views: &[LandmarkView<'_>],
    roi: Option<&Roi>,
    config: &LandmarkConfig,
) -> Result<Landmarks, MappingError> {
    validate(config)?;
    let poses: Vec<Isometry3<f64>> = views.iter().map(|v| *v.world_from_camera).collect();
    let mut pyramids: Vec<KltPyramid> = Vec::with_capacity(views.len());
    let mut tracks: Vec<Track> = Vec::new();
    let max_misses = config.whole_frame_max_misses.filter(|_| roi.is_none());
    for (k, view) in views.iter().enumerate() {
        let pyramid = KltPyramid::new(view.gray, config.klt.pyramid_levels);
        // Tracks are created keyframe by keyframe, so their anchors never decrease and one
        // KLT call serves each anchor.
        let candidates: Vec<(usize, usize, GuidedPoint)> = tracks
            .iter()
            .enumerate()
            .filter(|(_, track)| max_misses.is_none_or(|m| track.misses < m))
            .filter_map(|(i, track)| {
                Some((i, track.anchor, predict(camera, views, track, k, config)?))
            })
            .collect();
        let mut observed: Vec<Point2<f32>> = Vec::new();
        for group in candidates.chunk_by(|a, b| a.1 == b.1) {
            let anchor = group[0].1;
            let points: Vec<GuidedPoint> = group.iter().map(|c| c.2).collect();
            let results = track_points_guided(&pyramids[anchor], &pyramid, &points, &config.klt)?;
            for (&(i, _, guided), result) in group.iter().zip(results) {
                let miss = (result.position - guided.predicted).norm();
                let track = &mut tracks[i];
                if result.status != KltStatus::Tracked
                    || !(f64::from(miss) <= config.max_prediction_error_px)
                {
                    track.misses += 1;
                    continue;
                }
                track.misses = 0;
                let pixel =
                    Vector2::new(f64::from(result.position.x), f64::from(result.position.y));
                track.observations.push(KeyframeObservation {
                    camera: k,
                    point: 0,
                    pixel,
                    depth_m: depth_at(view.depth_m, &pixel, config.max_depth_spread_ratio),
                });
                retriangulate(camera, &poses, track, &config.triangulation_noise);
                observed.push(result.position);
            }
        }
        tracks.extend(start_tracks(camera, view, k, roi, &observed, config)?);
        pyramids.push(pyramid);
    }
    let mut landmarks = Landmarks::default();
    for track in tracks {
        if track.observations.len() < config.min_observations {
            continue;
        }
        let point = landmarks.points.len();
        landmarks.points.push(track.point_world);
        landmarks.observations.extend(
            track
                .observations
                .into_iter()
                .map(|o| KeyframeObservation { point, ..o }),
        );
    }
    Ok(landmarks)
}

/// Where `track` should appear in keyframe `k` and how its anchor window deforms there, or
/// `None` when it should not be searched for (behind the camera, outside the image, occluded,
/// seen from too far off its anchor's view or from behind its surface).
fn predict(
    camera: &PinholeCamera,
    views: &[LandmarkView<'_>],
    track: &Track,
    k: usize,
    config: &LandmarkConfig,
) -> Option<GuidedPoint> {
    let pose = views[k].world_from_camera;
    let anchor_pose = views[track.anchor].world_from_camera;
    let point = Point3::from(track.point_world);
    let in_camera = pose.inverse_transform_point(&point);
    let predicted = camera.project(&in_camera)?;
    let margin = f64::from(config.klt.window_px / 2 + 2);
    if !camera.in_bounds(&predicted, margin) {
        return None;
    }
    let measured = depth_at(
        views[k].depth_m,
        &predicted.coords,
        config.max_depth_spread_ratio,
    )?;
    if (measured - in_camera.z).abs() > config.max_occlusion_depth_ratio * in_camera.z {
        return None;
    }
    let to_current = pose.translation.vector - track.point_world;
    let to_anchor = anchor_pose.translation.vector - track.point_world;
    let cos_view = to_current.dot(&to_anchor) / (to_current.norm() * to_anchor.norm());
    if !(cos_view >= config.max_view_angle_deg.to_radians().cos())
        || track.normal_world.dot(&to_current) <= 0.0
    {
        return None;
    }
    let linear = plane_warp(
        camera,
        anchor_pose,
        pose,
        &track.anchor_pixel,
        &track.point_world,
        &track.normal_world,
    )?;
    Some(GuidedPoint {
        position: track.anchor_pixel,
        predicted: Point2::new(predicted.x as f32, predicted.y as f32),
        next_from_prev_linear: linear,
    })
}

/// The Jacobian at `anchor_pixel` of the map from the anchor image to the current image induced
/// by the plane through `point_world` with normal `normal_world` (central differences of one
/// pixel); `None` when a ray misses the plane or a point falls behind a camera.
fn plane_warp(
    camera: &PinholeCamera,
    world_from_anchor: &Isometry3<f64>,
    world_from_current: &Isometry3<f64>,
    anchor_pixel: &Point2<f32>,
    point_world: &Vector3<f64>,
    normal_world: &Vector3<f64>,
) -> Option<Matrix2<f32>> {
    let centre = world_from_anchor.translation.vector;
    let through = |du: f64, dv: f64| -> Option<Vector2<f64>> {
        let pixel = Point2::new(
            f64::from(anchor_pixel.x) + du,
            f64::from(anchor_pixel.y) + dv,
        );
        let ray = world_from_anchor.rotation * camera.unproject(&pixel, 1.0).coords;
        let along = normal_world.dot(&ray);
        if along.abs() < 1e-6 {
            return None;
        }
        let s = normal_world.dot(&(point_world - centre)) / along;
        if !(s > 0.0) {
            return None;
        }
        let on_plane = Point3::from(centre + ray * s);
        Some(
            camera
                .project(&world_from_current.inverse_transform_point(&on_plane))?
                .coords,
        )
    };
    let du = (through(1.0, 0.0)? - through(-1.0, 0.0)?) * 0.5;
    let dv = (through(0.0, 1.0)? - through(0.0, -1.0)?) * 0.5;
    let linear = Matrix2::new(du.x as f32, dv.x as f32, du.y as f32, dv.y as f32);
    linear.iter().all(|v| v.is_finite()).then_some(linear)
}

/// Re-triangulates a track from its pixels and depths with the odometry poses; keeps the old
/// position when that fails.
fn retriangulate(
    camera: &PinholeCamera,
    world_from_camera: &[Isometry3<f64>],
    track: &mut Track,
    noise: &KeyframeNoise,
) {
    if let Some(point) = triangulate_point(
        camera,
        world_from_camera,
        &track.observations,
        Some(noise),
        &track.point_world,
        5,
    ) {
        track.point_world = point;
    }
}

/// Detects corners in keyframe `k` and starts a track for each usable one (the corner detector's
/// minimum distance keeps new corners apart; `observed` keeps them off landmarks seen here).
fn start_tracks(
    camera: &PinholeCamera,
    view: &LandmarkView<'_>,
    k: usize,
    roi: Option<&Roi>,
    observed: &[Point2<f32>],
    config: &LandmarkConfig,
) -> Result<Vec<Track>, MappingError> {
    let mut out = Vec::new();
    if let Some(roi) = roi
        && roi_rect(camera, view.world_from_camera, roi, config.roi_margin_m).is_none()
    {
        return Ok(out);
    }
    let mask = usable_mask(camera, view, roi, config.roi_margin_m);
    let region = CornerRegion::Mask { mask: &mask, id: 1 };
    let corner_config = match (roi, config.corners.grid_cells) {
        (None, None) => &CornerConfig {
            grid_cells: Some(config.whole_frame_grid_cells),
            ..config.corners.clone()
        },
        _ => &config.corners,
    };
    let corners = detect_corners(view.gray, corner_config, &region)?;
    let min_d2 = (config.min_track_distance_px * config.min_track_distance_px) as f32;
    for corner in corners {
        let p = corner.position;
        if observed
            .iter()
            .any(|q| (q.x - p.x).powi(2) + (q.y - p.y).powi(2) < min_d2)
        {
            continue;
        }
        let pixel = Vector2::new(f64::from(p.x), f64::from(p.y));
        let Some(depth) = depth_at(view.depth_m, &pixel, config.max_depth_spread_ratio) else {
            continue;
        };
        let in_camera = camera.unproject(&Point2::from(pixel), depth);
        let world = view.world_from_camera * in_camera;
        if let Some(roi) = roi
            && !inside_grown(roi, &world, config.roi_margin_m)
        {
            continue;
        }
        // Corners on silhouettes (T-junctions of two surfaces) move with the view: keep only
        // corners on a surface that is continuous around them; its normal predicts the warp.
        let Some(normal_camera) = surface_normal(camera, view.depth_m, &pixel, depth, config)
        else {
            continue;
        };
        out.push(Track {
            anchor: k,
            anchor_pixel: p,
            normal_world: view.world_from_camera.rotation * normal_camera,
            point_world: world.coords,
            observations: vec![KeyframeObservation {
                camera: k,
                point: 0,
                pixel,
                depth_m: Some(depth),
            }],
            misses: 0,
        });
    }
    Ok(out)
}

/// A mask of the pixels where new corners may start: 1 where the depth is valid and (with a
/// ROI) the back-projected point lies inside the ROI grown by `margin_m`, 0 elsewhere.
fn usable_mask(
    camera: &PinholeCamera,
    view: &LandmarkView<'_>,
    roi: Option<&Roi>,
    margin_m: f64,
) -> MaskImage {
    let (w, h) = (view.depth_m.width(), view.depth_m.height());
    let mut mask = MaskImage::filled(w, h, 0);
    for v in 0..h {
        for u in 0..w {
            let Some(&d) = view.depth_m.get(u, v) else {
                continue;
            };
            if !(d > 0.0 && d.is_finite()) {
                continue;
            }
            let inside = roi.is_none_or(|roi| {
                let p = camera.unproject(&Point2::new(f64::from(u), f64::from(v)), f64::from(d));
                inside_grown(roi, &(view.world_from_camera * p), margin_m)
            });
            if inside && let Some(m) = mask.get_mut(u, v) {
                *m = 1;
            }
        }
    }
    mask
}

/// The unit normal (camera coordinates, facing the camera) of the plane fitted to the depths
/// within `normal_radius_px` of `pixel` (whose depth is `centre_depth_m`), or `None` on a
/// silhouette or depth edge: more than a tenth of the window without depth, or a depth farther
/// than `silhouette_depth_ratio` of the centre depth from the plane.
fn surface_normal(
    camera: &PinholeCamera,
    depth_m: &DepthImage,
    pixel: &Vector2<f64>,
    centre_depth_m: f64,
    config: &LandmarkConfig,
) -> Option<Vector3<f64>> {
    let r = i64::from(config.normal_radius_px);
    let (u0, v0) = (pixel.x.round() as i64, pixel.y.round() as i64);
    let window = ((2 * r + 1) * (2 * r + 1)) as usize;
    let mut points = Vec::with_capacity(window);
    for v in v0 - r..=v0 + r {
        for u in u0 - r..=u0 + r {
            let d = u32::try_from(u)
                .ok()
                .zip(u32::try_from(v).ok())
                .and_then(|(u, v)| depth_m.get(u, v))
                .map_or(0.0, |&d| f64::from(d));
            if d > 0.0 && d.is_finite() {
                points.push(camera.unproject(&Point2::new(u as f64, v as f64), d).coords);
            }
        }
    }
    if points.len() * 10 < window * 9 || points.len() < 3 {
        return None;
    }
    let mean = points.iter().sum::<Vector3<f64>>() / points.len() as f64;
    let covariance = points
        .iter()
        .map(|p| (p - mean) * (p - mean).transpose())
        .sum::<Matrix3<f64>>();
    let eigen = covariance.symmetric_eigen();
    let normal = eigen
        .eigenvectors
        .column(eigen.eigenvalues.imin())
        .into_owned();
    let limit = config.silhouette_depth_ratio * centre_depth_m;
    if !points
        .iter()
        .all(|p| (p - mean).dot(&normal).abs() <= limit)
    {
        return None;
    }
    let normal = if normal.dot(&mean) > 0.0 {
        -normal
    } else {
        normal
    };
    normal.iter().all(|v| v.is_finite()).then_some(normal)
}

fn validate(config: &LandmarkConfig) -> Result<(), MappingError> {
    let bad = |field, reason| Err(MappingError::InvalidConfig { field, reason });
    if config.min_observations < 2 {
        return bad("min_observations", "must be at least 2");
    }
    for (field, value) in [
        ("min_track_distance_px", config.min_track_distance_px),
        ("max_prediction_error_px", config.max_prediction_error_px),
        ("roi_margin_m", config.roi_margin_m),
        (
            "max_occlusion_depth_ratio",
            config.max_occlusion_depth_ratio,
        ),
        ("silhouette_depth_ratio", config.silhouette_depth_ratio),
        ("max_depth_spread_ratio", config.max_depth_spread_ratio),
    ] {
        if !(value.is_finite() && value >= 0.0) {
            return bad(field, "must be finite and non-negative");
        }
    }
    if config.whole_frame_grid_cells.contains(&0) {
        return bad(
            "whole_frame_grid_cells",
            "needs at least one column and one row",
        );
    }
    if config.whole_frame_max_misses == Some(0) {
        return bad(
            "whole_frame_max_misses",
            "must be at least 1 (or absent, to search for every track)",
        );
    }
    if !(config.max_view_angle_deg > 0.0 && config.max_view_angle_deg <= 90.0) {
        return bad("max_view_angle_deg", "must be in (0, 90]");
    }
    for (field, value) in [
        (
            "triangulation_noise.pixel_sigma_px",
            config.triangulation_noise.pixel_sigma_px,
        ),
        (
            "triangulation_noise.depth_sigma_m",
            config.triangulation_noise.depth_sigma_m,
        ),
    ] {
        if !(value.is_finite() && value > 0.0) {
            return bad(field, "must be positive and finite");
        }
    }
    Ok(())
}

/// The depth at a sub-pixel position: the bilinear mean of the four pixels around it when all
/// four are valid and agree within `max_spread_ratio` of their mean; `None` otherwise (no depth,
/// a depth edge).
pub fn depth_at(depth_m: &DepthImage, pixel: &Vector2<f64>, max_spread_ratio: f64) -> Option<f64> {
    if !(pixel.x.is_finite() && pixel.y.is_finite()) || pixel.x < 0.0 || pixel.y < 0.0 {
        return None;
    }
    let (u0, v0) = (pixel.x.floor(), pixel.y.floor());
    let (fu, fv) = (pixel.x - u0, pixel.y - v0);
    let (u0, v0) = (u0 as u32, v0 as u32);
    let mut values = [0.0f64; 4];
    for (i, (du, dv)) in [(0, 0), (1, 0), (0, 1), (1, 1)].into_iter().enumerate() {
        let d = f64::from(*depth_m.get(u0 + du, v0 + dv)?);
        if !(d > 0.0 && d.is_finite()) {
            return None;
        }
        values[i] = d;
    }
    let mean = values.iter().sum::<f64>() / 4.0;
    let (lo, hi) = values.iter().fold((f64::INFINITY, 0.0f64), |(lo, hi), &d| {
        (lo.min(d), hi.max(d))
    });
    if hi - lo > max_spread_ratio * mean {
        return None;
    }
    let top = values[0] * (1.0 - fu) + values[1] * fu;
    let bottom = values[2] * (1.0 - fu) + values[3] * fu;
    Some(top * (1.0 - fv) + bottom * fv)
}

/// Whether `p` lies inside `roi` grown by `margin_m` on every side.
fn inside_grown(roi: &Roi, p: &Point3<f64>, margin_m: f64) -> bool {
    match *roi {
        Roi::Box { min, max } => {
            (0..3).all(|a| p[a] >= min[a] - margin_m && p[a] <= max[a] + margin_m)
        }
        Roi::Cylinder {
            center_xy,
            z_min,
            z_max,
            radius_m,
        } => {
            let (dx, dy) = (p.x - center_xy[0], p.y - center_xy[1]);
            (dx * dx + dy * dy).sqrt() <= radius_m + margin_m
                && p.z >= z_min - margin_m
                && p.z <= z_max + margin_m
        }
    }
}

/// The image rectangle that the ROI's bounding box (grown by `margin_m`) projects to, clipped to
/// the image; `None` when it is behind the camera or outside the image. A box corner behind the
/// camera makes the whole image the rectangle.
pub fn roi_rect(
    camera: &PinholeCamera,
    world_from_camera: &Isometry3<f64>,
    roi: &Roi,
    margin_m: f64,
) -> Option<PixelRect> {
    let camera_from_world = world_from_camera.inverse();
    let (mut u0, mut v0, mut u1, mut v1) = (
        f64::INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::NEG_INFINITY,
    );
    let mut behind = 0;
    for corner in roi.corners(margin_m) {
        match camera.project(&(camera_from_world * corner)) {
            Some(px) => {
                u0 = u0.min(px.x);
                v0 = v0.min(px.y);
                u1 = u1.max(px.x);
                v1 = v1.max(px.y);
            }
            None => behind += 1,
        }
    }
    let (w, h) = (f64::from(camera.width), f64::from(camera.height));
    if behind == 8 {
        return None;
    }
    if behind > 0 {
        return PixelRect::from_continuous(0.0, 0.0, w - 1.0, h - 1.0, camera.width, camera.height);
    }
    PixelRect::from_continuous(u0, v0, u1, v1, camera.width, camera.height)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::look_at;

    fn observation(point: usize, camera: usize) -> KeyframeObservation {
        KeyframeObservation {
            camera,
            point,
            pixel: Vector2::zeros(),
            depth_m: None,
        }
    }

    #[test]
    fn a_link_no_landmark_spans_counts_zero() {
        // Landmark 0 spans keyframes 0–2, landmark 1 keyframes 3–4 (observed out of order),
        // landmark 2 only keyframe 2: nothing links keyframes 2 and 3.
        let landmarks = Landmarks {
            points: vec![Vector3::zeros(); 3],
            observations: vec![
                observation(0, 0),
                observation(0, 2),
                observation(1, 4),
                observation(1, 3),
                observation(2, 2),
            ],
        };
        assert_eq!(landmarks.landmarks_spanning_links(5), vec![1, 1, 0, 1]);
        // Keyframes beyond the count are ignored: landmark 1 is then seen once.
        assert_eq!(landmarks.landmarks_spanning_links(4), vec![1, 1, 0]);
        assert!(landmarks.landmarks_spanning_links(1).is_empty());
        assert!(Landmarks::default().landmarks_spanning_links(0).is_empty());
        assert_eq!(Landmarks::default().landmarks_spanning_links(3), vec![0, 0]);
    }

    proptest::proptest! {
        #[test]
        fn spanning_counts_match_a_direct_count(
            seen in proptest::collection::vec(
                proptest::collection::vec(0usize..8, 1..5), 0..12),
            keyframes in 0usize..9,
        ) {
            let landmarks = Landmarks {
                points: vec![Vector3::zeros(); seen.len()],
                observations: seen
                    .iter()
                    .enumerate()
                    .flat_map(|(p, cameras)| cameras.iter().map(move |&c| observation(p, c)))
                    .collect(),
            };
            let direct: Vec<usize> = (0..keyframes.saturating_sub(1))
                .map(|link| {
                    seen.iter()
                        .filter(|cameras| {
                            cameras.iter().any(|&c| c <= link)
                                && cameras.iter().any(|&c| c > link && c < keyframes)
                        })
                        .count()
                })
                .collect();
            proptest::prop_assert_eq!(landmarks.landmarks_spanning_links(keyframes), direct);
        }
    }

    #[test]
    fn depth_at_interpolates_and_rejects_edges() {
        let mut depth = DepthImage::filled(4, 4, 2.0);
        *depth.get_mut(1, 1).unwrap() = 2.02;
        let d = depth_at(&depth, &Vector2::new(0.5, 0.5), 0.02).unwrap();
        assert!((d - 2.005).abs() < 1e-6, "{d}");
        *depth.get_mut(2, 2).unwrap() = 3.0;
        assert_eq!(depth_at(&depth, &Vector2::new(1.5, 1.5), 0.02), None);
        assert_eq!(depth_at(&depth, &Vector2::new(3.5, 0.0), 0.02), None);
        assert_eq!(depth_at(&depth, &Vector2::new(f64::NAN, 0.0), 0.02), None);
    }

    #[test]
    fn roi_rect_covers_the_projected_region() {
        let camera = PinholeCamera::from_hfov(640, 480, 80.0).unwrap();
        let world_from_camera = look_at(
            &Point3::new(4.0, 0.0, 2.0),
            &Point3::origin(),
            &Vector3::z(),
        )
        .unwrap();
        let roi = Roi::Cylinder {
            center_xy: [0.0, 0.0],
            z_min: -0.5,
            z_max: 0.5,
            radius_m: 0.5,
        };
        let rect = roi_rect(&camera, &world_from_camera, &roi, 0.0).unwrap();
        // The centre projects to the principal point, inside the rectangle, which is smaller
        // than the image.
        assert!(rect.u_min < 320 && rect.u_max > 320 && rect.v_min < 240 && rect.v_max > 240);
        assert!(rect.u_max - rect.u_min < 400);
        assert!(inside_grown(&roi, &Point3::new(0.6, 0.0, 0.0), 0.2));
        assert!(!inside_grown(&roi, &Point3::new(0.6, 0.0, 0.0), 0.0));
        let behind = look_at(
            &Point3::new(4.0, 0.0, 2.0),
            &Point3::new(8.0, 0.0, 2.0),
            &Vector3::z(),
        )
        .unwrap();
        assert_eq!(roi_rect(&camera, &behind, &roi, 0.0), None);
    }

    /// A static camera sees a textured wall, then three blank frames (nothing for KLT to lock
    /// onto), then the wall again. Searching every track, the last keyframe re-observes the
    /// first one's corners; with tracks retired after two misses it does not look for them.
    #[test]
    fn tracks_missed_in_a_row_are_retired_without_a_roi() {
        let camera = PinholeCamera::from_hfov(160, 120, 70.0).unwrap();
        let textured = GrayImage::from_vec(
            160,
            120,
            (0..160 * 120u32)
                .map(|i| {
                    let (u, v) = (i % 160, i / 160);
                    // A smooth pattern with corners everywhere: products of sines.
                    let x = f64::from(u) * 0.45;
                    let y = f64::from(v) * 0.38;
                    (0.5 + 0.25 * (x.sin() * y.cos()) + 0.2 * ((x * 0.31 + y * 0.7).sin())) as f32
                })
                .collect(),
        )
        .unwrap();
        let blank = GrayImage::filled(160, 120, 0.5);
        let depth = DepthImage::filled(160, 120, 2.0);
        let pose = Isometry3::identity();
        let images = [&textured, &blank, &blank, &blank, &textured];
        let views: Vec<LandmarkView<'_>> = images
            .iter()
            .map(|gray| LandmarkView {
                gray,
                depth_m: &depth,
                world_from_camera: &pose,
            })
            .collect();
        let reobserved = |max_misses: Option<u32>| {
            let config = LandmarkConfig {
                min_observations: 2,
                whole_frame_max_misses: max_misses,
                ..LandmarkConfig::default()
            };
            let landmarks = track_landmarks(&camera, &views, None, &config).unwrap();
            landmarks
                .observations
                .iter()
                .filter(|o| o.camera == 4)
                .count()
        };
        let every_track = reobserved(None);
        assert!(every_track > 20, "{every_track} re-observations");
        assert_eq!(reobserved(Some(2)), 0);
        assert_eq!(reobserved(Some(4)), every_track);
        let bad = LandmarkConfig {
            whole_frame_max_misses: Some(0),
            ..LandmarkConfig::default()
        };
        assert!(validate(&bad).is_err());
    }

    #[test]
    fn bad_settings_are_rejected() {
        let config = LandmarkConfig {
            min_observations: 1,
            ..LandmarkConfig::default()
        };
        assert!(matches!(
            validate(&config),
            Err(MappingError::InvalidConfig {
                field: "min_observations",
                ..
            })
        ));
    }
}
