//! `scarp simulate --record DIR`: the flight as the drone sensed it, in the TUM RGB-D layout
//! that `scarp process`, `scarp map` and `scarp localize` read.
//!
//! What a real flight brings home, and only that, at the top level:
//! - `rgb/`, `depth/` (z-depth PNG, `camera.toml`'s `depth_scale` units per metre), `rgb.txt`,
//!   `depth.txt`: every camera frame, as sensed (with the sensor's noise);
//! - `estimate.txt`: the autopilot's `world_from_camera` estimate of every frame (TUM format,
//!   ENU metres), after the rangefinder's height correction;
//! - `camera.toml`: the camera model;
//! - `origin.toml`: the geodetic position of the ENU frame's origin (WGS84);
//! - `flight.txt`: per frame, the camera mount's pitch below the horizon (degrees), the flight
//!   mode and its target.
//!
//! The simulated detector's input, which a real flight replaces by its network:
//! - `mask/` (instance ids) and `boxes.txt` (each rock's box and role, target or distractor).
//!
//! Kept apart, in `groundtruth/`, because no real flight has it: `groundtruth/groundtruth.txt`,
//! the true `world_from_camera` of every frame. Readers of the folder never see it unless it is
//! moved up.
//!
//! Images are written by a background thread, so the mission keeps flying while PNGs encode;
//! the lists are written last, so an interrupted recording never looks complete.

use std::path::{Path, PathBuf};
use std::sync::mpsc::{Receiver, SyncSender, sync_channel};
use std::thread::JoinHandle;

use super::error::{Context, MissionError, MissionResult};
use nalgebra::Isometry3;
use scarp_datasets::sequence::{
    BoxRecord, CameraFile, boxes_from_mask, format_boxes, frame_name, write_depth_png,
    write_image_lists, write_mask_png, write_rgb_png,
};
use scarp_datasets::world::World;
use scarp_export::atomic::write_bytes_atomically;
use scarp_export::tum::{StampedPose, format_timestamp, write_tum_trajectory};
use scarp_slam::{PinholeCamera, RgbdFrame};
use serde::{Deserialize, Serialize};

use super::mode::Mode;

/// The geodetic position (WGS84) of a flight's ENU origin: `origin.toml`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FlightOrigin {
    /// Latitude, degrees north.
    pub lat_deg: f64,
    /// Longitude, degrees east.
    pub lon_deg: f64,
    /// Height above the WGS84 ellipsoid, metres.
    pub alt_m: f64,
}

impl FlightOrigin {
    /// The origin of `world`'s ENU frame.
    pub fn of_world(world: &World) -> Self {
        let o = world.config.origin;
        Self {
            lat_deg: o.lat_deg,
            lon_deg: o.lon_deg,
            alt_m: o.alt_m,
        }
    }

    /// As the GeoJSON writer takes it.
    pub fn geodetic(&self) -> scarp_export::geojson::Geodetic {
        scarp_export::geojson::Geodetic {
            lat_deg: self.lat_deg,
            lon_deg: self.lon_deg,
            alt_m: self.alt_m,
        }
    }

    /// Reads `origin.toml`.
    ///
    /// # Errors
    /// A missing or malformed file, named.
    pub fn read(path: &Path) -> MissionResult<Self> {
        let text =
            std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
        toml::from_str(&text).with_context(|| format!("parsing {}", path.display()))
    }
}

/// Depth PNG units per metre: 1000 reaches 65 m, beyond the sensor's 30 m.
pub const RECORD_DEPTH_SCALE: f64 = 1000.0;

/// Frames waiting for the writer thread; the mission waits when it is this far ahead.
const QUEUE_FRAMES: usize = 8;

/// Writes a flight folder frame by frame (see the [module docs](self)).
pub struct FlightRecorder {
    dir: PathBuf,
    queue: Option<SyncSender<RgbdFrame>>,
    writer: Option<JoinHandle<MissionResult<()>>>,
    estimate: Vec<StampedPose>,
    truth: Vec<StampedPose>,
    flight_log: String,
    boxes: Vec<BoxRecord>,
}

impl FlightRecorder {
    /// Starts a recording in `dir` (created) for `camera`, in the ENU frame at `origin`.
    ///
    /// # Errors
    /// When `dir` or its subfolders cannot be created, or `camera.toml` or `origin.toml`
    /// cannot be written.
    pub fn new(dir: &Path, camera: &PinholeCamera, origin: FlightOrigin) -> MissionResult<Self> {
        for sub in ["rgb", "depth", "mask", "groundtruth"] {
            let path = dir.join(sub);
            std::fs::create_dir_all(&path)
                .with_context(|| format!("creating {}", path.display()))?;
        }
        CameraFile::new(camera, RECORD_DEPTH_SCALE).write(&dir.join("camera.toml"))?;
        write_bytes_atomically(
            dir.join("origin.toml"),
            toml::to_string(&origin)?.as_bytes(),
        )?;
        let (queue, frames) = sync_channel(QUEUE_FRAMES);
        let images_dir = dir.to_path_buf();
        let writer = std::thread::Builder::new()
            .name("flight-recorder".into())
            .spawn(move || write_frames(&images_dir, &frames))
            .context("starting the flight recorder's writer thread")?;
        Ok(Self {
            dir: dir.to_path_buf(),
            queue: Some(queue),
            writer: Some(writer),
            estimate: Vec::new(),
            truth: Vec::new(),
            flight_log: String::from(
                "# per frame: timestamp_s mount_pitch_down_deg mode target (- for none)\n",
            ),
            boxes: Vec::new(),
        })
    }

    /// Records one frame: its images (queued for the writer), the estimate and true
    /// `world_from_camera` (ENU metres), the mount's pitch below the horizon (degrees) and the
    /// flight mode. `world` gives the rocks' roles for `boxes.txt`.
    ///
    /// # Errors
    /// When the writer thread has stopped (its error is reported by [`Self::finish`]).
    pub fn record(
        &mut self,
        frame: &RgbdFrame,
        world_from_camera_estimate: &Isometry3<f64>,
        world_from_camera_truth: &Isometry3<f64>,
        mount_pitch_down_deg: f64,
        mode: Mode,
        world: &World,
    ) -> MissionResult<()> {
        let t = frame.timestamp_s;
        if let Some(mask) = &frame.instance_mask {
            self.boxes.extend(boxes_from_mask(mask, t, |id| {
                world.rock(id).map(|r| r.role)
            }));
        }
        self.estimate.push(StampedPose {
            timestamp_s: t,
            world_from_camera: *world_from_camera_estimate,
        });
        self.truth.push(StampedPose {
            timestamp_s: t,
            world_from_camera: *world_from_camera_truth,
        });
        let target = mode
            .target()
            .map_or_else(|| "-".to_string(), |id| id.to_string());
        self.flight_log.push_str(&format!(
            "{} {mount_pitch_down_deg:.4} {} {target}\n",
            format_timestamp(t),
            mode.as_str()
        ));
        let queue = self
            .queue
            .as_ref()
            .context("the flight recording is already finished")?;
        if queue.send(frame.clone()).is_err() {
            return Err(MissionError::invalid(
                "the flight recorder's writer stopped; see the error at the end of the run",
            ));
        }
        Ok(())
    }

    /// Waits for the images, then writes the lists, the trajectories, `flight.txt` and
    /// `boxes.txt`. Returns the number of frames recorded.
    ///
    /// # Errors
    /// The writer thread's first error (naming the file), or a list that cannot be written.
    pub fn finish(mut self) -> MissionResult<usize> {
        drop(self.queue.take());
        if let Some(writer) = self.writer.take() {
            writer.join().map_err(|_| {
                MissionError::invalid("the flight recorder's writer thread panicked")
            })??;
        }
        let dir = &self.dir;
        write_tum_trajectory(
            &dir.join("estimate.txt"),
            &self.estimate,
            "state-estimator world_from_camera (ENU metres), as flown",
        )?;
        write_tum_trajectory(
            &dir.join("groundtruth").join("groundtruth.txt"),
            &self.truth,
            "GROUND TRUTH (simulation only): true world_from_camera (ENU metres)",
        )?;
        write_bytes_atomically(dir.join("flight.txt"), self.flight_log.as_bytes())?;
        write_bytes_atomically(dir.join("boxes.txt"), format_boxes(&self.boxes).as_bytes())?;
        let timestamps: Vec<f64> = self.estimate.iter().map(|p| p.timestamp_s).collect();
        write_image_lists(dir, &timestamps)?;
        Ok(timestamps.len())
    }
}

/// The writer thread: every frame's colour, depth and mask PNGs, until the queue closes.
fn write_frames(dir: &Path, frames: &Receiver<RgbdFrame>) -> MissionResult<()> {
    for frame in frames {
        let name = frame_name(frame.timestamp_s);
        write_rgb_png(&dir.join("rgb").join(&name), &frame.rgb)?;
        write_depth_png(
            &dir.join("depth").join(&name),
            &frame.depth_m,
            RECORD_DEPTH_SCALE,
        )?;
        if let Some(mask) = &frame.instance_mask {
            write_mask_png(&dir.join("mask").join(&name), mask)?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use scarp_datasets::sequence::Sequence;
    use scarp_slam::image::{DepthImage, MaskImage, RgbImage};

    #[test]
    fn a_recording_reads_back_as_a_sequence_without_ground_truth() {
        let dir = tempfile::tempdir().unwrap();
        let camera = PinholeCamera::from_hfov(32, 24, 80.0).unwrap();
        let world = World::from_name_or_path("default").unwrap();
        let origin = FlightOrigin::of_world(&world);
        let mut recorder = FlightRecorder::new(dir.path(), &camera, origin).unwrap();
        let mut mask = MaskImage::filled(32, 24, 0);
        *mask.get_mut(3, 4).unwrap() = 1;
        for k in 0..3 {
            let t = 0.25 * f64::from(k + 1);
            let frame = RgbdFrame::new(
                t,
                RgbImage::filled(32, 24, [10, 20, 30]),
                DepthImage::filled(32, 24, 2.5 + f32::from(k as u8)),
                Some(mask.clone()),
            )
            .unwrap();
            let estimate = Isometry3::translation(f64::from(k), 0.0, 10.0);
            let truth = Isometry3::translation(f64::from(k) + 0.5, 0.0, 10.0);
            recorder
                .record(&frame, &estimate, &truth, 55.0, Mode::Search, &world)
                .unwrap();
        }
        assert_eq!(recorder.finish().unwrap(), 3);

        let seq = Sequence::open(dir.path()).unwrap();
        assert_eq!(seq.len(), 3);
        let frame = seq.load_frame(2).unwrap();
        assert!((frame.timestamp_s - 0.75).abs() < 1e-9);
        assert_eq!(frame.depth_m.get(5, 5), Some(&4.5));
        assert_eq!(frame.rgb.get(0, 0), Some(&[10, 20, 30]));
        let entry = &seq.entries[1];
        // The estimate is there; the truth is kept apart.
        assert!(entry.world_from_camera_truth.is_none());
        let estimate = entry.world_from_camera_estimate.unwrap();
        assert!((estimate.translation.vector.x - 1.0).abs() < 1e-9);
        assert!(dir.path().join("groundtruth/groundtruth.txt").exists());
        let flight = std::fs::read_to_string(dir.path().join("flight.txt")).unwrap();
        assert!(flight.contains("0.500000 55.0000 search -"), "{flight}");
        assert_eq!(
            FlightOrigin::read(&dir.path().join("origin.toml")).unwrap(),
            origin
        );
        let boxes = std::fs::read_to_string(dir.path().join("boxes.txt")).unwrap();
        assert_eq!(boxes.lines().filter(|l| !l.starts_with('#')).count(), 3);
    }
}
