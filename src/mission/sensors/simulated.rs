//! The simulated vehicle and its sensors: the dynamics the mission flies, the camera mount,
//! the GPS/IMU state estimator and the RGB-D camera (the renderer at the true pose, then the
//! sensor's noise, seeded per frame).

use nalgebra::{Isometry3, Vector3};
use scarp_datasets::estimator::StateEstimator;
use scarp_datasets::noise::derive_seed;
use scarp_datasets::render::Renderer;
use scarp_datasets::sensor::SensorConfig;
use scarp_datasets::world::World;
use scarp_slam::{PinholeCamera, RgbdFrame};

use super::super::error::{MissionError, MissionResult};
use super::super::motion::MotionSystem;
use super::super::mount::CameraMount;
use super::{SensedPose, Sensors};

/// The sensed pose whose images are still to be taken.
#[derive(Debug, Clone, Copy)]
struct Exposure {
    timestamp_s: f64,
    world_from_camera_truth: Isometry3<f64>,
}

/// A simulated drone: the mission flies [`Self::vehicle_mut`] and points the mount; each
/// [`Sensors::next_pose`] senses at the vehicle's current time and pose.
pub struct Simulated<'w> {
    camera: PinholeCamera,
    renderer: Renderer<'w>,
    vehicle: MotionSystem,
    mount: CameraMount,
    estimator: StateEstimator,
    sensor: SensorConfig,
    seed: u64,
    frames_taken: u64,
    exposure: Option<Exposure>,
}

impl<'w> Simulated<'w> {
    /// Sensors on `vehicle` in `world`. `seed` seeds the camera's noise (per frame) and the
    /// state estimator's drift, so the same seed senses the same flight.
    pub fn new(
        world: &'w World,
        camera: PinholeCamera,
        vehicle: MotionSystem,
        mount: CameraMount,
        sensor: SensorConfig,
        estimator: &scarp_datasets::estimator::EstimatorConfig,
        seed: u64,
    ) -> Self {
        Self {
            camera,
            renderer: Renderer::new(world),
            vehicle,
            mount,
            estimator: StateEstimator::new(estimator, derive_seed(seed, 0x5e57)),
            sensor,
            seed,
            frames_taken: 0,
            exposure: None,
        }
    }

    /// The vehicle's dynamics (true state, trajectory, mission time).
    pub fn vehicle(&self) -> &MotionSystem {
        &self.vehicle
    }

    /// The vehicle's dynamics, to command a trajectory or advance time.
    pub fn vehicle_mut(&mut self) -> &mut MotionSystem {
        &mut self.vehicle
    }

    /// Turns the camera mount toward `target_pitch_down_deg` below the horizon until mission
    /// time `time_s`, at the servo's rate.
    pub fn slew_mount(&mut self, target_pitch_down_deg: f64, time_s: f64) {
        self.mount
            .slew_toward(target_pitch_down_deg.to_radians(), time_s);
    }

    /// The camera mount's pitch below the horizon, degrees.
    pub fn mount_pitch_down_deg(&self) -> f64 {
        self.mount.pitch_down_deg()
    }

    /// The state estimator's current position error (estimate − truth, ENU metres): what the
    /// controller flies off by and where the rangefinder's map prediction is made. Only a
    /// simulation knows it.
    pub fn position_drift_m(&self) -> Vector3<f64> {
        self.estimator.position_drift_m()
    }

    /// Frames whose images were taken so far.
    pub fn frames_taken(&self) -> u64 {
        self.frames_taken
    }
}

impl Sensors for Simulated<'_> {
    fn camera(&self) -> &PinholeCamera {
        &self.camera
    }

    /// Senses at the vehicle's current time: the true camera pose (body pose and mount) and
    /// the estimator's reading of it. A simulated flight never ends by itself.
    fn next_pose(&mut self) -> MissionResult<Option<SensedPose>> {
        let timestamp_s = self.vehicle.time_s();
        let truth = self.vehicle.world_from_body() * self.mount.body_from_camera();
        let estimate = self.estimator.observe(timestamp_s, &truth);
        self.exposure = Some(Exposure {
            timestamp_s,
            world_from_camera_truth: truth,
        });
        Ok(Some(SensedPose {
            timestamp_s,
            world_from_camera_estimate: estimate,
            mount_pitch_down_deg: Some(self.mount.pitch_down_deg()),
            world_from_camera_truth: Some(truth),
        }))
    }

    /// Renders the true view and applies the sensor's noise, seeded by the frame's index.
    /// Each sensed pose gives one exposure: a second call errs.
    fn images(&mut self) -> MissionResult<RgbdFrame> {
        let exposure = self.exposure.take().ok_or_else(|| {
            MissionError::invalid("simulated camera: no sensed pose to take the images at")
        })?;
        let index = self.frames_taken;
        self.frames_taken += 1;
        let rendered = self
            .renderer
            .render(&self.camera, &exposure.world_from_camera_truth)?;
        let seed = derive_seed(self.seed, index);
        let depth = self
            .sensor
            .corrupt_depth(&rendered.depth_m, self.camera.fx, seed);
        let rgb = self.sensor.corrupt_rgb(&rendered.rgb, derive_seed(seed, 1));
        Ok(RgbdFrame::new(
            exposure.timestamp_s,
            rgb,
            depth,
            Some(rendered.instance),
        )?)
    }
}
