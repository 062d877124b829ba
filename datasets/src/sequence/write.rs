//! Rendering a camera path through a world into a sequence directory.

use std::path::Path;

use rayon::prelude::*;
use scarp_export::atomic::write_bytes_atomically;
use scarp_export::tum::{StampedPose, format_timestamp, write_tum_trajectory};
use scarp_slam::PinholeCamera;
use serde::Serialize;

use super::camera_file::CameraFile;
use super::images::{write_depth_png, write_mask_png, write_rgb_png};
use super::lists::{BoxRecord, boxes_from_mask, format_boxes};
use crate::DatasetError;
use crate::estimator::EstimatorConfig;
use crate::noise::derive_seed;
use crate::render::Renderer;
use crate::sensor::SensorConfig;
use crate::world::World;

/// How to render a sequence.
#[derive(Debug, Clone)]
pub struct RenderSettings {
    /// The camera.
    pub camera: PinholeCamera,
    /// Apply sensor noise and state-estimator error. Without it, images are clean and
    /// `estimate.txt` equals `groundtruth.txt`.
    pub noise: bool,
    /// Depth and colour noise.
    pub sensor: SensorConfig,
    /// State-estimator error.
    pub estimator: EstimatorConfig,
    /// Seed of every random draw.
    pub seed: u64,
    /// Depth PNG units per metre (5000 as TUM; 1000 reaches 65 m).
    pub depth_scale: f64,
}

/// What [`write_sequence`] produced.
#[derive(Debug, Clone, Serialize)]
pub struct SequenceSummary {
    /// Frames written.
    pub frames: usize,
    /// Box records written to `boxes.txt`.
    pub boxes: usize,
    /// Wall time, seconds.
    pub seconds: f64,
}

/// The file name of the frame taken at `timestamp_s` in `rgb/`, `depth/` and `mask/`.
pub fn frame_name(timestamp_s: f64) -> String {
    format!("{timestamp_s:.6}.png")
}

/// Writes `rgb.txt` and `depth.txt` listing the frames at `timestamps_s` (named by
/// [`frame_name`]), atomically. Written last, they make a sequence directory complete.
///
/// # Errors
/// I/O errors naming the file.
pub fn write_image_lists(dir: &Path, timestamps_s: &[f64]) -> Result<(), DatasetError> {
    for (list, sub) in [("rgb.txt", "rgb"), ("depth.txt", "depth")] {
        let mut text = format!("# {sub} images: timestamp path\n");
        for &t in timestamps_s {
            text.push_str(&format!(
                "{} {sub}/{}\n",
                format_timestamp(t),
                frame_name(t)
            ));
        }
        write_bytes_atomically(dir.join(list), text.as_bytes())?;
    }
    Ok(())
}

/// Renders `poses` (true `world_from_camera`) through `world` into `dir` in the TUM RGB-D layout
/// (see the [module docs](super)). Frames are rendered in parallel; every frame draws its noise
/// from its own seed, so the output is the same for any thread count. The list files are written
/// last, so an interrupted run never looks complete. `progress` is called once per finished
/// frame.
///
/// # Errors
/// [`DatasetError::Invalid`] for an empty path; I/O and rendering errors naming the file.
pub fn write_sequence(
    dir: &Path,
    world: &World,
    poses: &[StampedPose],
    settings: &RenderSettings,
    progress: &(dyn Fn() + Sync),
) -> Result<SequenceSummary, DatasetError> {
    let start = std::time::Instant::now();
    if poses.is_empty() {
        return Err(DatasetError::invalid("path", "has no poses"));
    }
    for sub in ["rgb", "depth", "mask"] {
        std::fs::create_dir_all(dir.join(sub)).map_err(|e| DatasetError::io(&dir.join(sub), e))?;
    }
    let depth_sigma_at_1m_m = if settings.noise {
        settings.sensor.depth_sigma_m(1.0, settings.camera.fx)
    } else {
        0.0
    };
    CameraFile {
        depth_sigma_at_1m_m: Some(depth_sigma_at_1m_m),
        ..CameraFile::new(&settings.camera, settings.depth_scale)
    }
    .write(&dir.join("camera.toml"))?;
    let estimate = if settings.noise {
        settings
            .estimator
            .estimate(poses, derive_seed(settings.seed, 0xe57))
    } else {
        poses.to_vec()
    };
    write_tum_trajectory(
        &dir.join("groundtruth.txt"),
        poses,
        "true world_from_camera (ENU metres)",
    )?;
    write_tum_trajectory(
        &dir.join("estimate.txt"),
        &estimate,
        "state-estimator world_from_camera (ENU metres)",
    )?;
    let renderer = Renderer::new(world);
    let role_of = |id: u32| world.rock(id).map(|r| r.role);
    let boxes: Vec<Vec<BoxRecord>> = poses
        .par_iter()
        .enumerate()
        .map(|(index, pose)| {
            let mut out = renderer.render(&settings.camera, &pose.world_from_camera)?;
            if settings.noise {
                let seed = derive_seed(settings.seed, index as u64);
                out.depth_m = settings
                    .sensor
                    .corrupt_depth(&out.depth_m, settings.camera.fx, seed);
                out.rgb = settings.sensor.corrupt_rgb(&out.rgb, seed);
            }
            let name = frame_name(pose.timestamp_s);
            write_rgb_png(&dir.join("rgb").join(&name), &out.rgb)?;
            write_depth_png(
                &dir.join("depth").join(&name),
                &out.depth_m,
                settings.depth_scale,
            )?;
            write_mask_png(&dir.join("mask").join(&name), &out.instance)?;
            progress();
            Ok(boxes_from_mask(&out.instance, pose.timestamp_s, role_of))
        })
        .collect::<Result<_, DatasetError>>()?;
    let boxes: Vec<BoxRecord> = boxes.concat();
    write_bytes_atomically(dir.join("boxes.txt"), format_boxes(&boxes).as_bytes())?;
    let timestamps: Vec<f64> = poses.iter().map(|p| p.timestamp_s).collect();
    write_image_lists(dir, &timestamps)?;
    Ok(SequenceSummary {
        frames: poses.len(),
        boxes: boxes.len(),
        seconds: start.elapsed().as_secs_f64(),
    })
}
