//! Landmarks for bundle adjustment: corners tracked with pyramidal KLT from keyframe to
//! keyframe, on and around the target's region of interest, initialised from depth.
//!
//! At each keyframe the live tracks are followed from the previous keyframe with KLT (forward–
//! backward checked), then checked against the odometry: a track whose pixel lies farther than
//! `max_prediction_error_px` from its landmark's projection through the odometry pose is ended
//! (a KLT slip onto another surface). New corners are detected inside the image rectangle that
//! the ROI projects to, away from live tracks, where the depth is valid and the back-projected
//! point lies inside the ROI (grown by `roi_margin_m`). Landmarks seen by fewer than
//! `min_observations` keyframes are dropped.

use nalgebra::{Isometry3, Point2, Point3, Vector2, Vector3};
use serde::{Deserialize, Serialize};

use super::MappingError;
use crate::PinholeCamera;
use crate::ba::KeyframeObservation;
use crate::features::{
    CornerConfig, CornerRegion, KltConfig, KltPyramid, KltStatus, PixelRect, detect_corners,
    track_points,
};
use crate::image::{DepthImage, GrayImage};
use crate::tsdf::Roi;

/// Settings of [`track_landmarks`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LandmarkConfig {
    /// Corner detection at each keyframe. Default: Harris, at most 400 corners at least 8 px
    /// apart (a 640×480 frame of a rock at 4 m yields a few hundred usable corners).
    pub corners: CornerConfig,
    /// KLT between keyframes. Default [`KltConfig::default`] (25 px window, 4 levels, 15
    /// iterations, forward–backward 0.5 px).
    pub klt: KltConfig,
    /// New corners are not started within this distance of a live track, pixels. Default 8.
    pub min_track_distance_px: f64,
    /// A landmark needs at least this many keyframes observing it. Default 3.
    pub min_observations: usize,
    /// End a track whose KLT position is farther than this from the landmark projected through
    /// the odometry pose, pixels. Default 4 (odometry drifts by millimetres, a pixel is about
    /// 1 cm at 4 m).
    pub max_prediction_error_px: f64,
    /// Corners whose back-projected point lies outside the ROI grown by this are ignored,
    /// metres. Default 0.3 ("on and around the target").
    pub roi_margin_m: f64,
    /// Follow the tracks alive at the last keyframe into the first one and merge them with the
    /// tracks started there (an orbit that closes its loop). Default true.
    pub close_loop: bool,
    /// Loop merging joins tracks that land within this distance, pixels. Default 1.5.
    pub loop_merge_px: f64,
    /// New corners need valid depths within this many pixels around them, all within twice
    /// `max_depth_spread_ratio` of the corner's own (no silhouettes). Default 4.
    pub silhouette_radius_px: u32,
    /// A depth is used (for initialisation and as a depth residual) only where the four pixels
    /// around the corner agree within this fraction of their mean. Default 0.02.
    pub max_depth_spread_ratio: f64,
}

impl Default for LandmarkConfig {
    fn default() -> Self {
        Self {
            corners: CornerConfig {
                max_corners: 400,
                min_distance_px: 8.0,
                ..CornerConfig::default()
            },
            klt: KltConfig::default(),
            min_track_distance_px: 8.0,
            min_observations: 3,
            max_prediction_error_px: 4.0,
            roi_margin_m: 0.3,
            close_loop: true,
            silhouette_radius_px: 4,
            loop_merge_px: 1.5,
            max_depth_spread_ratio: 0.02,
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
    /// World positions (ENU metres), initialised from the first observation's depth and the
    /// odometry pose.
    pub points: Vec<Vector3<f64>>,
    /// Observations, grouped by landmark in creation order.
    pub observations: Vec<KeyframeObservation>,
}

/// A live track: its landmark's first back-projection and its observations so far.
struct Track {
    point_world: Vector3<f64>,
    position: Point2<f32>,
    observations: Vec<(usize, Vector2<f64>, Option<f64>)>,
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
    let mut finished: Vec<Track> = Vec::new();
    let mut live: Vec<Track> = Vec::new();
    let mut previous: Option<KltPyramid> = None;
    for (k, view) in views.iter().enumerate() {
        let pyramid = KltPyramid::new(view.gray, config.klt.pyramid_levels);
        let camera_from_world = view.world_from_camera.inverse();
        if let Some(prev) = &previous {
            let points: Vec<Point2<f32>> = live.iter().map(|t| t.position).collect();
            let tracked = track_points(prev, &pyramid, &points, &config.klt)?;
            let mut kept = Vec::with_capacity(live.len());
            for (mut track, result) in live.drain(..).zip(tracked) {
                let predicted =
                    camera.project(&(camera_from_world * Point3::from(track.point_world)));
                let pixel =
                    Vector2::new(f64::from(result.position.x), f64::from(result.position.y));
                let agrees = predicted
                    .is_some_and(|p| (p.coords - pixel).norm() <= config.max_prediction_error_px);
                if result.status == KltStatus::Tracked && agrees {
                    track.position = result.position;
                    let depth = depth_at(view.depth_m, &pixel, config.max_depth_spread_ratio);
                    track.observations.push((k, pixel, depth));
                    kept.push(track);
                } else {
                    finished.push(track);
                }
            }
            live = kept;
        }
        let started = start_tracks(camera, view, k, roi, &live, config)?;
        live.extend(started);
        previous = Some(pyramid);
    }
    if config.close_loop
        && views.len() > 2
        && let Some(last) = &previous
    {
        close_loop(camera, views, last, &mut live, &mut finished, config)?;
    }
    finished.append(&mut live);
    let mut landmarks = Landmarks::default();
    for track in finished {
        if track.observations.len() < config.min_observations {
            continue;
        }
        let point = landmarks.points.len();
        landmarks.points.push(track.point_world);
        for (camera_index, pixel, depth_m) in track.observations {
            landmarks.observations.push(KeyframeObservation {
                camera: camera_index,
                point,
                pixel,
                depth_m,
            });
        }
    }
    Ok(landmarks)
}

/// Follows the live tracks from the last keyframe into the first; a track that lands within
/// `loop_merge_px` of a track started in the first keyframe takes over that track's
/// observations (one landmark seen at both ends of the loop).
fn close_loop(
    camera: &PinholeCamera,
    views: &[LandmarkView<'_>],
    last: &KltPyramid,
    live: &mut [Track],
    finished: &mut [Track],
    config: &LandmarkConfig,
) -> Result<(), MappingError> {
    let first = KltPyramid::new(views[0].gray, config.klt.pyramid_levels);
    let points: Vec<Point2<f32>> = live.iter().map(|t| t.position).collect();
    let tracked = track_points(last, &first, &points, &config.klt)?;
    let camera_from_world = views[0].world_from_camera.inverse();
    let merge_d2 = (config.loop_merge_px * config.loop_merge_px) as f32;
    for (track, result) in live.iter_mut().zip(tracked) {
        if result.status != KltStatus::Tracked || track.observations.iter().any(|o| o.0 == 0) {
            continue;
        }
        let pixel = Vector2::new(f64::from(result.position.x), f64::from(result.position.y));
        let predicted = camera.project(&(camera_from_world * Point3::from(track.point_world)));
        if !predicted.is_some_and(|p| (p.coords - pixel).norm() <= config.max_prediction_error_px) {
            continue;
        }
        // The nearest unmerged track started in keyframe 0.
        let nearest = finished
            .iter_mut()
            .filter(|t| t.observations.first().is_some_and(|o| o.0 == 0))
            .map(|t| {
                let p = t.observations[0].1;
                let d2 = (p.x as f32 - result.position.x).powi(2)
                    + (p.y as f32 - result.position.y).powi(2);
                (d2, t)
            })
            .filter(|(d2, _)| *d2 <= merge_d2)
            .min_by(|a, b| a.0.total_cmp(&b.0));
        if let Some((_, start)) = nearest {
            track.observations.append(&mut start.observations);
        }
    }
    Ok(())
}

/// Detects corners in keyframe `k` and starts a track for each usable one (the corner detector's
/// minimum distance keeps new corners apart; `existing` keeps them off live tracks).
fn start_tracks(
    camera: &PinholeCamera,
    view: &LandmarkView<'_>,
    k: usize,
    roi: Option<&Roi>,
    existing: &[Track],
    config: &LandmarkConfig,
) -> Result<Vec<Track>, MappingError> {
    let mut out = Vec::new();
    let region = match roi {
        Some(roi) => match roi_rect(camera, view.world_from_camera, roi, config.roi_margin_m) {
            Some(rect) => CornerRegion::Rect(rect),
            None => return Ok(out),
        },
        None => CornerRegion::Whole,
    };
    let corners = detect_corners(view.gray, &config.corners, &region)?;
    let taken: Vec<Point2<f32>> = existing.iter().map(|t| t.position).collect();
    let min_d2 = (config.min_track_distance_px * config.min_track_distance_px) as f32;
    for corner in corners {
        let p = corner.position;
        if taken
            .iter()
            .any(|q| (q.x - p.x).powi(2) + (q.y - p.y).powi(2) < min_d2)
        {
            continue;
        }
        let pixel = Vector2::new(f64::from(p.x), f64::from(p.y));
        let Some(depth) = depth_at(view.depth_m, &pixel, config.max_depth_spread_ratio) else {
            continue;
        };
        // Corners on silhouettes (T-junctions of two surfaces) move with the view: keep only
        // corners on a surface that is continuous around them.
        if !depth_is_smooth(
            view.depth_m,
            &pixel,
            config.silhouette_radius_px,
            config.max_depth_spread_ratio * 2.0,
        ) {
            continue;
        }
        let world = view.world_from_camera * camera.unproject(&Point2::from(pixel), depth);
        if let Some(roi) = roi
            && !inside_grown(roi, &world, config.roi_margin_m)
        {
            continue;
        }
        out.push(Track {
            point_world: world.coords,
            position: p,
            observations: vec![(k, pixel, Some(depth))],
        });
    }
    Ok(out)
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
        ("loop_merge_px", config.loop_merge_px),
        ("max_depth_spread_ratio", config.max_depth_spread_ratio),
    ] {
        if !(value.is_finite() && value >= 0.0) {
            return bad(field, "must be finite and non-negative");
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

/// Whether every depth within `radius_px` (a square window) of `pixel` is valid and within
/// `max_spread_ratio` of the centre pixel's depth.
fn depth_is_smooth(
    depth_m: &DepthImage,
    pixel: &Vector2<f64>,
    radius_px: u32,
    max_spread_ratio: f64,
) -> bool {
    let (u, v) = (pixel.x.round() as i64, pixel.y.round() as i64);
    let r = i64::from(radius_px);
    let Some(&centre) = u32::try_from(u)
        .ok()
        .zip(u32::try_from(v).ok())
        .and_then(|(u, v)| depth_m.get(u, v))
    else {
        return false;
    };
    let centre = f64::from(centre);
    for dv in -r..=r {
        for du in -r..=r {
            let (x, y) = (u + du, v + dv);
            let Some(&d) = u32::try_from(x)
                .ok()
                .zip(u32::try_from(y).ok())
                .and_then(|(x, y)| depth_m.get(x, y))
            else {
                return false;
            };
            if !(d > 0.0 && (f64::from(d) - centre).abs() <= max_spread_ratio * centre) {
                return false;
            }
        }
    }
    true
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
    let (lo, hi) = roi_bounds(roi);
    let camera_from_world = world_from_camera.inverse();
    let (mut u0, mut v0, mut u1, mut v1) = (
        f64::INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::NEG_INFINITY,
    );
    let mut behind = 0;
    for corner in 0..8 {
        let pick = |a: usize| {
            if corner >> a & 1 == 1 {
                hi[a] + margin_m
            } else {
                lo[a] - margin_m
            }
        };
        let p = camera_from_world * Point3::new(pick(0), pick(1), pick(2));
        match camera.project(&p) {
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

/// Axis-aligned bounds of a ROI, metres.
fn roi_bounds(roi: &Roi) -> ([f64; 3], [f64; 3]) {
    match *roi {
        Roi::Box { min, max } => (min, max),
        Roi::Cylinder {
            center_xy,
            z_min,
            z_max,
            radius_m,
        } => (
            [center_xy[0] - radius_m, center_xy[1] - radius_m, z_min],
            [center_xy[0] + radius_m, center_xy[1] + radius_m, z_max],
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::look_at;

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
