//! The camera mount's pitch servo. The search and fine-localization views look down at γ;
//! the base ring asks for a nearly level view. The servo turns at a bounded rate, so the view
//! changes smoothly between frames and the odometry keeps its overlap.

use nalgebra::Isometry3;
use scarp_planning::camera::{CameraConfig, body_from_camera_at_pitch};

/// Pitch state of the camera mount.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraMount {
    pitch_down_rad: f64,
    max_rate_radps: f64,
    time_s: f64,
}

impl CameraMount {
    /// At the camera's default pitch γ at mission time 0.
    pub fn new(camera: &CameraConfig) -> Self {
        Self {
            pitch_down_rad: camera.pitch_down_rad(),
            max_rate_radps: camera.pitch_rate_deg_s.to_radians(),
            time_s: 0.0,
        }
    }

    /// Turns toward `target_pitch_down_rad` for the time since the last call, at most at the
    /// servo's rate, and records `time_s` as now. A non-finite target or a time in the past
    /// leaves the pitch where it is.
    pub fn slew_toward(&mut self, target_pitch_down_rad: f64, time_s: f64) {
        let dt = time_s - self.time_s;
        if !(dt.is_finite() && dt >= 0.0 && target_pitch_down_rad.is_finite()) {
            return;
        }
        self.time_s = time_s;
        let max_step = self.max_rate_radps * dt;
        let step = (target_pitch_down_rad - self.pitch_down_rad).clamp(-max_step, max_step);
        self.pitch_down_rad += step;
    }

    /// The current pitch below the body's x axis (degrees).
    pub fn pitch_down_deg(&self) -> f64 {
        self.pitch_down_rad.to_degrees()
    }

    /// Camera (OpenCV) to body (FLU) at the current pitch.
    pub fn body_from_camera(&self) -> Isometry3<f64> {
        body_from_camera_at_pitch(self.pitch_down_rad)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn turns_at_the_servo_rate_then_holds() {
        let camera = CameraConfig::default();
        let mut mount = CameraMount::new(&camera);
        assert_eq!(mount.pitch_down_deg(), 55.0);
        // 30°/s: half a second turns 15° of the 50° asked for.
        mount.slew_toward(5f64.to_radians(), 0.5);
        assert!((mount.pitch_down_deg() - 40.0).abs() < 1e-9);
        mount.slew_toward(5f64.to_radians(), 10.0);
        assert!((mount.pitch_down_deg() - 5.0).abs() < 1e-9);
        // Bad input changes nothing.
        mount.slew_toward(f64::NAN, 11.0);
        mount.slew_toward(1.0, 9.0);
        assert!((mount.pitch_down_deg() - 5.0).abs() < 1e-9);
    }

    #[test]
    fn default_pitch_matches_the_fixed_mount() {
        let camera = CameraConfig::default();
        let mount = CameraMount::new(&camera);
        let a = mount.body_from_camera();
        let b = camera.body_from_camera();
        assert!((a.to_homogeneous() - b.to_homogeneous()).abs().max() < 1e-15);
    }
}
