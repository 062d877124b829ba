//! The sensor seam: where the mission's camera frames come from.
//!
//! Every consumer of frames (the live mission's state machine, `scarp process`) reads them
//! through [`Sensors`]: each frame is a [`SensedPose`] (its time, the autopilot's
//! `world_from_camera` estimate, the camera mount's pitch) and, on demand, its images. Asking
//! for the images separately lets a consumer skip a frame without rendering or decoding it
//! (the offline mapping pass reads only the frames that see a target).
//!
//! - [`Simulated`]: the renderer, the state estimator, the camera mount and the vehicle's
//!   dynamics. The mission flies the vehicle; each call to [`Sensors::next_pose`] senses at
//!   the vehicle's current time.
//! - [`Recorded`]: a flight folder in the TUM RGB-D layout with `estimate.txt` (what
//!   `scarp simulate --record` writes and a real drone brings home), frame after frame.

pub mod recorded;
pub mod simulated;

pub use recorded::Recorded;
pub use simulated::Simulated;

use nalgebra::Isometry3;
use scarp_slam::{PinholeCamera, RgbdFrame};

use super::error::MissionResult;

/// One camera frame's time and pose, as the vehicle sensed them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SensedPose {
    /// Mission time of the exposure, seconds.
    pub timestamp_s: f64,
    /// The autopilot's estimate of the camera pose (camera in OpenCV convention to the ENU
    /// world, metres), before the mission's own rangefinder height correction.
    pub world_from_camera_estimate: Isometry3<f64>,
    /// The camera mount's pitch below the horizon, degrees (`None` when the recording does not
    /// say).
    pub mount_pitch_down_deg: Option<f64>,
    /// The true camera pose: only a simulation knows it (ground-truth bookkeeping, never used
    /// to decide anything).
    pub world_from_camera_truth: Option<Isometry3<f64>>,
}

/// A source of camera frames with their pose estimates and times.
///
/// Frames come in time order. [`Self::next_pose`] moves to the next frame;
/// [`Self::images`] returns that frame's images, rendering or decoding them only when asked.
pub trait Sensors {
    /// The camera model of every frame.
    fn camera(&self) -> &PinholeCamera;

    /// Moves to the next frame and returns its time and pose; `None` when the flight has no
    /// more frames.
    ///
    /// # Errors
    /// A frame whose pose cannot be sensed or read (a recording without an estimate for it).
    fn next_pose(&mut self) -> MissionResult<Option<SensedPose>>;

    /// The images of the frame [`Self::next_pose`] last returned.
    ///
    /// # Errors
    /// No current frame, or images that cannot be rendered or read (the file is named).
    fn images(&mut self) -> MissionResult<RgbdFrame>;

    /// The next frame with its images: [`Self::next_pose`] then [`Self::images`].
    ///
    /// # Errors
    /// As theirs.
    fn next_frame(&mut self) -> MissionResult<Option<(SensedPose, RgbdFrame)>> {
        match self.next_pose()? {
            Some(pose) => Ok(Some((pose, self.images()?))),
            None => Ok(None),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Point3;
    use scarp_datasets::world::World;

    use crate::mission::config::MissionConfig;
    use crate::mission::mode::Mode;
    use crate::mission::motion::MotionSystem;
    use crate::mission::mount::CameraMount;
    use crate::mission::record::{FlightOrigin, FlightRecorder};

    /// A hovering simulated drone over the default world's terrain, with a small camera.
    fn hovering<'w>(world: &'w World, config: &MissionConfig) -> Simulated<'w> {
        let camera = PinholeCamera::from_hfov(64, 48, 80.0).unwrap();
        let ground_m = world.terrain_height_m(0.0, 0.0);
        let vehicle = MotionSystem::new(
            &config.planning.flight,
            Point3::new(0.0, 0.0, ground_m + 6.0),
            0.3,
        )
        .unwrap();
        Simulated::new(
            world,
            camera,
            vehicle,
            CameraMount::new(&config.planning.camera),
            config.sensor.clone(),
            &config.estimator,
            7,
        )
    }

    /// What the simulation senses, recorded as `scarp simulate --record` does, reads back
    /// through the same seam: the same times, estimates and mount pitch, the depth to the
    /// recording's 1 mm, no true pose, and then the end of the flight.
    #[test]
    fn a_simulated_flight_recorded_reads_back_through_the_seam() {
        let world = World::builtin_default().unwrap();
        let config = MissionConfig::default();
        let mut live = hovering(&world, &config);
        let dir = tempfile::tempdir().unwrap();
        let mut recorder =
            FlightRecorder::new(dir.path(), live.camera(), FlightOrigin::of_world(&world)).unwrap();
        let mut sensed = Vec::new();
        for k in 1..=3 {
            let t = 0.25 * f64::from(k);
            live.vehicle_mut()
                .advance_to(t, &nalgebra::Vector3::zeros())
                .unwrap();
            live.slew_mount(30.0, t);
            let (pose, frame) = live.next_frame().unwrap().unwrap();
            let truth = pose
                .world_from_camera_truth
                .expect("a simulation knows the truth");
            let pitch = pose.mount_pitch_down_deg.unwrap();
            recorder
                .record(
                    &frame,
                    &pose.world_from_camera_estimate,
                    &truth,
                    pitch,
                    Mode::Search,
                    &world,
                )
                .unwrap();
            sensed.push((pose, frame));
        }
        assert_eq!(live.frames_taken(), 3);
        // The mount slews toward 30° at its rate, so the pitch changes between frames.
        assert_ne!(
            sensed[0].0.mount_pitch_down_deg,
            sensed[2].0.mount_pitch_down_deg
        );
        assert_eq!(recorder.finish().unwrap(), 3);

        let mut recorded = Recorded::open(dir.path()).unwrap();
        assert_eq!(recorded.len(), 3);
        assert!(recorded.images().is_err(), "no frame before the first pose");
        for (k, (pose, frame)) in sensed.iter().enumerate() {
            let (read, images) = recorded.next_frame().unwrap().unwrap();
            assert_eq!(recorded.index(), Some(k));
            assert!((read.timestamp_s - pose.timestamp_s).abs() < 1e-9);
            let moved = (read.world_from_camera_estimate.translation.vector
                - pose.world_from_camera_estimate.translation.vector)
                .norm();
            assert!(moved < 1e-6, "estimate moved by {moved} m");
            let pitch = read.mount_pitch_down_deg.unwrap();
            assert!((pitch - pose.mount_pitch_down_deg.unwrap()).abs() < 1e-4);
            assert!(
                read.world_from_camera_truth.is_none(),
                "truth is kept apart"
            );
            let worst_mm = frame
                .depth_m
                .as_slice()
                .iter()
                .zip(images.depth_m.as_slice())
                .map(|(&live_m, &read_m)| {
                    if live_m > 0.0 && live_m <= 65.0 {
                        (live_m - read_m).abs() * 1000.0
                    } else {
                        // Beyond the 16-bit PNG's 65.535 m a depth is recorded as missing.
                        if read_m == 0.0 { 0.0 } else { f32::INFINITY }
                    }
                })
                .fold(0.0_f32, f32::max);
            assert!(worst_mm <= 0.5 + 1e-3, "depth differs by {worst_mm} mm");
            assert_eq!(frame.rgb.as_slice(), images.rgb.as_slice());
        }
        assert!(recorded.next_pose().unwrap().is_none(), "the flight ends");
        recorded.rewind();
        let first = recorded.next_pose().unwrap().unwrap();
        assert!((first.timestamp_s - sensed[0].0.timestamp_s).abs() < 1e-9);
    }

    /// One sensed pose gives one exposure: the camera refuses to expose twice.
    #[test]
    fn a_simulated_pose_exposes_once() {
        let world = World::builtin_default().unwrap();
        let config = MissionConfig::default();
        let mut live = hovering(&world, &config);
        assert!(live.images().is_err());
        live.next_pose().unwrap().unwrap();
        live.images().unwrap();
        let err = live.images().unwrap_err().to_string();
        assert!(err.contains("no sensed pose"), "{err}");
    }
}
