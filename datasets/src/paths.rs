//! Camera paths for rendering sequences: an orbit around a target, a lawn-mower sweep, or poses
//! from a TUM file. Every path yields `world_from_camera` poses stamped at a fixed frame rate.

use std::path::Path;

use nalgebra::{Isometry3, Point3, Vector3};
use scarp_export::tum::{StampedPose, read_tum_trajectory};
use scarp_slam::geometry::look_at;

use crate::DatasetError;
use crate::world::World;

/// Frame rate of rendered sequences, Hz.
pub const FRAME_RATE_HZ: f64 = 20.0;

/// Camera pitch below the horizon on survey flights, degrees (the paper's γ).
pub const SURVEY_PITCH_DEG: f64 = 55.0;

fn stamp(poses: Vec<Isometry3<f64>>) -> Vec<StampedPose> {
    poses
        .into_iter()
        .enumerate()
        .map(|(k, world_from_camera)| StampedPose {
            timestamp_s: k as f64 / FRAME_RATE_HZ,
            world_from_camera,
        })
        .collect()
}

/// `frames` poses evenly spread over one full circle of `radius_m` around `centre`, the camera
/// `height_m` above it and looking at it (as the mapping rings do).
///
/// # Errors
/// [`DatasetError::Invalid`] for zero frames or a non-positive radius.
pub fn orbit(
    centre: &Point3<f64>,
    radius_m: f64,
    height_m: f64,
    frames: usize,
) -> Result<Vec<StampedPose>, DatasetError> {
    if frames == 0 || !(radius_m > 0.0) {
        return Err(DatasetError::invalid(
            "orbit",
            "needs at least one frame and a positive radius",
        ));
    }
    let poses = (0..frames)
        .map(|k| {
            let theta = k as f64 / frames as f64 * std::f64::consts::TAU;
            let eye =
                centre + Vector3::new(radius_m * theta.cos(), radius_m * theta.sin(), height_m);
            look_at(&eye, centre, &Vector3::z())
        })
        .collect::<Result<Vec<_>, _>>()?;
    Ok(stamp(poses))
}

/// The default orbit: 4 m around the world's first target, 2 m above its centroid.
///
/// # Errors
/// [`DatasetError::Invalid`] when the world has no target or `frames` is zero.
pub fn default_orbit(world: &World, frames: usize) -> Result<Vec<StampedPose>, DatasetError> {
    let target = world
        .targets()
        .next()
        .ok_or_else(|| DatasetError::invalid("rocks", "the world has no target to orbit"))?;
    orbit(&target.centroid, 4.0, 2.0, frames)
}

/// `frames` poses evenly spaced along a boustrophedon sweep of the whole terrain at
/// `altitude_m` above the terrain's mean height. Lanes run east–west; their spacing keeps 30%
/// side overlap of the ground footprint of a camera with horizontal field of view `hfov_deg`
/// pitched [`SURVEY_PITCH_DEG`] down. The camera faces along the lane.
///
/// # Errors
/// [`DatasetError::Invalid`] for zero frames or a non-positive altitude.
pub fn lawnmower(
    world: &World,
    altitude_m: f64,
    hfov_deg: f64,
    frames: usize,
) -> Result<Vec<StampedPose>, DatasetError> {
    lawnmower_in(
        world,
        world.heightfield.extent(),
        altitude_m,
        hfov_deg,
        frames,
    )
}

/// The terrain's mean height (world z), m: the datum of survey altitudes.
pub fn mean_terrain_height_m(world: &World) -> f64 {
    let heights = &world.heightfield.heights_m;
    heights.iter().sum::<f64>() / heights.len().max(1) as f64
}

/// Like [`lawnmower`], over the rectangle `area` = (x_min, y_min, x_max, y_max) (world x, y,
/// m) instead of the whole terrain; the altitude is still above the terrain's mean height.
///
/// # Errors
/// [`DatasetError::Invalid`] for zero frames, a non-positive altitude or an empty or
/// non-finite area.
pub fn lawnmower_in(
    world: &World,
    area: (f64, f64, f64, f64),
    altitude_m: f64,
    hfov_deg: f64,
    frames: usize,
) -> Result<Vec<StampedPose>, DatasetError> {
    if frames == 0 || !(altitude_m > 0.0) {
        return Err(DatasetError::invalid(
            "lawnmower",
            "needs at least one frame and a positive altitude",
        ));
    }
    let (x0, y0, x1, y1) = area;
    let finite = [x0, y0, x1, y1].iter().all(|v| v.is_finite());
    if !finite || x1 <= x0 || y1 <= y0 {
        return Err(DatasetError::invalid(
            "lawnmower",
            "the area must be a finite, non-empty rectangle",
        ));
    }
    let z = mean_terrain_height_m(world) + altitude_m;
    let pitch = SURVEY_PITCH_DEG.to_radians();
    let slant_m = altitude_m / pitch.sin();
    let footprint_m = 2.0 * slant_m * (hfov_deg.to_radians() / 2.0).tan();
    let spacing_m = 0.7 * footprint_m;
    // The camera looks ahead of the drone by altitude / tan(pitch); keep the view inside.
    let look_ahead_m = altitude_m / pitch.tan();
    let margin = 0.1 * (x1 - x0);
    let ahead = look_ahead_m.min(0.3 * (x1 - x0));
    let lanes = (((y1 - y0 - 2.0 * margin) / spacing_m).ceil() as usize).max(1) + 1;
    let lane_y =
        |k: usize| y0 + margin + (y1 - y0 - 2.0 * margin) * k as f64 / (lanes - 1).max(1) as f64;
    let mut corners = Vec::new();
    for k in 0..lanes {
        // Eastward lanes stop `ahead` short of the east edge, westward ones of the west edge.
        let (a, b) = if k % 2 == 0 {
            (x0 + margin, x1 - margin - ahead)
        } else {
            (x1 - margin, x0 + margin + ahead)
        };
        corners.push(Point3::new(a, lane_y(k), z));
        corners.push(Point3::new(b, lane_y(k), z));
    }
    let lengths: Vec<f64> = corners.windows(2).map(|w| (w[1] - w[0]).norm()).collect();
    let total: f64 = lengths.iter().sum();
    let mut poses = Vec::with_capacity(frames);
    for k in 0..frames {
        let mut s = total * k as f64 / (frames.max(2) - 1) as f64;
        let mut segment = 0;
        while segment + 1 < lengths.len() && s > lengths[segment] {
            s -= lengths[segment];
            segment += 1;
        }
        let (a, b) = (corners[segment], corners[segment + 1]);
        let direction = (b - a).try_normalize(1e-9).unwrap_or_else(Vector3::x);
        let eye = a + direction * s.min(lengths[segment]);
        let heading = Vector3::new(direction.x, direction.y, 0.0)
            .try_normalize(1e-9)
            .unwrap_or_else(Vector3::x);
        let forward = heading * pitch.cos() - Vector3::z() * pitch.sin();
        poses.push(look_at(&eye, &(eye + forward), &Vector3::z())?);
    }
    Ok(stamp(poses))
}

/// Poses read from a TUM trajectory file (its own timestamps are kept).
///
/// # Errors
/// [`DatasetError::Parse`] or [`DatasetError::Io`] naming the file and line.
pub fn from_tum_file(path: &Path) -> Result<Vec<StampedPose>, DatasetError> {
    Ok(read_tum_trajectory(path)?)
}
