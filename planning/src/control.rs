//! Geometric tracking control on SE(3) (Lee, Leok and McClamroch 2010), in the form used by the
//! paper's controller (Lim 2019): position and velocity gains act as accelerations, the
//! desired attitude follows from the commanded force and the reference yaw, and the attitude
//! loop outputs body torques (and, for autopilots that take them, body-rate commands).
//!
//! Frames: world ENU, body FLU; attitudes are `world_from_body`.

use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

use crate::dynamics::{ActuatorCommand, QuadState, QuadrotorParams};
use crate::error::{PlanError, check_positive, check_range};
use crate::minsnap::{FlatState, Trajectory};

/// Controller gains and limits.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ControllerConfig {
    /// Position gain K_p per world axis (1/s²). Default (8, 8, 20) (DESIGN; paper's controller).
    pub position_gain_per_s2: [f64; 3],
    /// Velocity gain K_v per world axis (1/s). Default (1.5, 1.5, 3.3) (DESIGN).
    pub velocity_gain_per_s: [f64; 3],
    /// Attitude gain k_R per body axis, as angular acceleration per unit error (1/s²).
    /// Default (400, 400, 40) (tuned here: ω_n = 20 rad/s on roll and pitch, which the 100 Hz
    /// loop and 20 ms motors still follow; slower attitude loops eat the light damping of the
    /// DESIGN position gains, ζ ≈ 0.27 on x and y).
    pub attitude_gain_per_s2: [f64; 3],
    /// Angular-rate gain k_Ω per body axis (1/s). Default (35, 35, 12) (tuned with k_R:
    /// damping ≈ 0.87 on roll and pitch).
    pub rate_gain_per_s: [f64; 3],
    /// Attitude gain of the body-rate output, for autopilots that take rate commands (1/s).
    /// Default (8, 8, 4) (an attitude time constant of 0.125 s, as in the paper's controller).
    pub body_rate_gain_per_s: [f64; 3],
    /// Largest commanded tilt of the thrust from vertical (degrees). Default 40.
    pub max_tilt_deg: f64,
    /// Control rate (Hz). Default 100 (DESIGN).
    pub rate_hz: f64,
    /// Time step of the finite differences that give the reference body rates and angular
    /// accelerations (s). Default 0.002.
    pub feedforward_step_s: f64,
}

impl Default for ControllerConfig {
    fn default() -> Self {
        Self {
            position_gain_per_s2: [8.0, 8.0, 20.0],
            velocity_gain_per_s: [1.5, 1.5, 3.3],
            attitude_gain_per_s2: [400.0, 400.0, 40.0],
            rate_gain_per_s: [35.0, 35.0, 12.0],
            body_rate_gain_per_s: [8.0, 8.0, 4.0],
            max_tilt_deg: 40.0,
            rate_hz: 100.0,
            feedforward_step_s: 0.002,
        }
    }
}

impl ControllerConfig {
    /// Checks that every gain is finite and non-negative, the rate positive and the tilt limit
    /// in (0°, 89°].
    pub fn validate(&self) -> Result<(), PlanError> {
        let groups = [
            ("controller.position_gain_per_s2", self.position_gain_per_s2),
            ("controller.velocity_gain_per_s", self.velocity_gain_per_s),
            ("controller.attitude_gain_per_s2", self.attitude_gain_per_s2),
            ("controller.rate_gain_per_s", self.rate_gain_per_s),
            ("controller.body_rate_gain_per_s", self.body_rate_gain_per_s),
        ];
        for (name, g) in groups {
            for (i, v) in g.iter().enumerate() {
                check_range(format!("{name}[{i}]"), *v, 0.0, 1e6)?;
            }
        }
        check_range("controller.max_tilt_deg", self.max_tilt_deg, 1.0, 89.0)?;
        check_positive("controller.rate_hz", self.rate_hz)?;
        check_positive("controller.feedforward_step_s", self.feedforward_step_s)?;
        Ok(())
    }
}

/// What the controller tracks at one instant: flat outputs plus the feedforward body rates and
/// angular accelerations of the reference attitude.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Reference {
    /// Position, velocity, acceleration, yaw and their derivatives (world ENU).
    pub flat: FlatState,
    /// Body rates of the reference attitude (reference body frame, rad/s).
    pub body_rate_radps: Vector3<f64>,
    /// Angular acceleration of the reference attitude (reference body frame, rad/s²).
    pub body_accel_radps2: Vector3<f64>,
}

impl Reference {
    /// A hover reference (no feedforward).
    pub fn hover(flat: FlatState) -> Self {
        Self {
            flat,
            body_rate_radps: Vector3::zeros(),
            body_accel_radps2: Vector3::zeros(),
        }
    }

    /// The reference at `t_s` along `trajectory`, with feedforward body rates and angular
    /// accelerations from central differences (step `step_s`) of the flat attitude.
    pub fn from_trajectory(
        trajectory: &Trajectory,
        t_s: f64,
        gravity_mps2: f64,
        step_s: f64,
    ) -> Self {
        let flat = trajectory.sample(t_s);
        let att = |t: f64| {
            let s = trajectory.sample(t);
            attitude_from_flat(&s.acceleration_mps2, s.yaw_rad, gravity_mps2)
        };
        let h = step_s;
        let rates = |t: f64| {
            let r0 = att(t);
            let rp = att(t + h);
            let rm = att(t - h);
            let rdot = (rp.matrix() - rm.matrix()) / (2.0 * h);
            vee(&(r0.matrix().transpose() * rdot))
        };
        let w = rates(t_s);
        let wdot = (rates(t_s + h) - rates(t_s - h)) / (2.0 * h);
        Self {
            flat,
            body_rate_radps: w,
            body_accel_radps2: wdot,
        }
    }
}

/// The attitude whose body z axis carries the thrust for acceleration `accel_mps2` and whose
/// body y axis is perpendicular to the heading direction (cos ψ, sin ψ, 0), so that body x
/// points along the heading when the vehicle is level.
///
/// Uses the Lee construction: b3 = (a + g e3)/‖·‖, b2 = b3 × b1c/‖·‖ with
/// b1c = (cos ψ, sin ψ, 0), b1 = b2 × b3. Falls back to level when the thrust direction is
/// degenerate.
pub fn attitude_from_flat(
    accel_mps2: &Vector3<f64>,
    yaw_rad: f64,
    gravity_mps2: f64,
) -> Rotation3<f64> {
    let t = accel_mps2 + Vector3::z() * gravity_mps2;
    attitude_from_thrust_direction(&t, yaw_rad)
}

fn attitude_from_thrust_direction(force: &Vector3<f64>, yaw_rad: f64) -> Rotation3<f64> {
    let b1c = Vector3::new(yaw_rad.cos(), yaw_rad.sin(), 0.0);
    let n = force.norm();
    let b3 = if n > 1e-9 { force / n } else { Vector3::z() };
    let b2_raw = b3.cross(&b1c);
    let b2 = if b2_raw.norm() > 1e-9 {
        b2_raw.normalize()
    } else {
        Vector3::y()
    };
    let b1 = b2.cross(&b3);
    Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[b1, b2, b3]))
}

/// The vee map: skew-symmetric matrix → vector.
fn vee(m: &Matrix3<f64>) -> Vector3<f64> {
    Vector3::new(
        0.5 * (m[(2, 1)] - m[(1, 2)]),
        0.5 * (m[(0, 2)] - m[(2, 0)]),
        0.5 * (m[(1, 0)] - m[(0, 1)]),
    )
}

/// The controller's output for one tick.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ControlOutput {
    /// Collective thrust (N) and body torques (N·m), for a torque-controlled airframe.
    pub command: ActuatorCommand,
    /// Body-rate command (body frame, rad/s), for a rate-controlled autopilot.
    pub body_rate_cmd_radps: Vector3<f64>,
    /// Desired attitude `world_from_body`.
    pub desired_world_from_body: UnitQuaternion<f64>,
    /// Commanded acceleration including gravity compensation (world, m/s²).
    pub accel_cmd_mps2: Vector3<f64>,
    /// Attitude error e_R (body frame).
    pub attitude_error: Vector3<f64>,
}

/// Geometric SE(3) controller for a given airframe.
#[derive(Debug, Clone)]
pub struct GeometricController {
    cfg: ControllerConfig,
    mass_kg: f64,
    gravity_mps2: f64,
    inertia: Matrix3<f64>,
}

impl GeometricController {
    /// Builds the controller for the airframe `params`. Fails on invalid gains or parameters.
    pub fn new(cfg: ControllerConfig, params: &QuadrotorParams) -> Result<Self, PlanError> {
        cfg.validate()?;
        params.validate()?;
        Ok(Self {
            cfg,
            mass_kg: params.mass_kg,
            gravity_mps2: params.gravity_mps2,
            inertia: params.inertia(),
        })
    }

    /// The gains.
    pub fn config(&self) -> &ControllerConfig {
        &self.cfg
    }

    /// Computes thrust, torques and body-rate command to track `reference` from `state`.
    pub fn update(&self, state: &QuadState, reference: &Reference) -> ControlOutput {
        let c = &self.cfg;
        let r = &reference.flat;
        let e_p = state.position_m - r.position_m;
        let e_v = state.velocity_mps - r.velocity_mps;
        let kp = Vector3::from(c.position_gain_per_s2);
        let kv = Vector3::from(c.velocity_gain_per_s);
        let g = self.gravity_mps2;
        let mut acc = r.acceleration_mps2 - kp.component_mul(&e_p) - kv.component_mul(&e_v)
            + Vector3::z() * g;
        // Tilt and minimum-thrust limits on the commanded force direction.
        acc.z = acc.z.max(0.2 * g);
        let horiz = (acc.x * acc.x + acc.y * acc.y).sqrt();
        let max_h = acc.z * c.max_tilt_deg.to_radians().tan();
        if horiz > max_h {
            let s = max_h / horiz;
            acc.x *= s;
            acc.y *= s;
        }
        let force = acc * self.mass_kg;
        let rot = state.world_from_body.to_rotation_matrix();
        let rm = rot.matrix();
        let rd = attitude_from_thrust_direction(&force, r.yaw_rad);
        let rdm = rd.matrix();
        let thrust = force.dot(&(rm * Vector3::z())).max(0.0);

        let e_r = 0.5 * vee(&(rdm.transpose() * rm - rm.transpose() * rdm));
        let rt_rd = rm.transpose() * rdm;
        let w_d = rt_rd * reference.body_rate_radps;
        let wdot_d = rt_rd * reference.body_accel_radps2;
        let w = state.body_rate_radps;
        let e_w = w - w_d;
        let kr = Vector3::from(c.attitude_gain_per_s2);
        let kw = Vector3::from(c.rate_gain_per_s);
        let j = &self.inertia;
        let torque = j * (-kr.component_mul(&e_r) - kw.component_mul(&e_w)) + w.cross(&(j * w))
            - j * (w.cross(&w_d) - wdot_d);
        let body_rate_cmd = w_d - Vector3::from(c.body_rate_gain_per_s).component_mul(&e_r);
        ControlOutput {
            command: ActuatorCommand {
                thrust_n: thrust,
                torque_nm: torque,
            },
            body_rate_cmd_radps: body_rate_cmd,
            desired_world_from_body: UnitQuaternion::from_rotation_matrix(&rd),
            accel_cmd_mps2: acc,
            attitude_error: e_r,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Point3;

    #[test]
    fn hover_command_balances_gravity() {
        let p = QuadrotorParams::default();
        let ctl = GeometricController::new(ControllerConfig::default(), &p).unwrap();
        let s = QuadState::hover(&p, Point3::new(0.0, 0.0, 5.0), 0.3);
        let out = ctl.update(
            &s,
            &Reference::hover(FlatState::hover(Point3::new(0.0, 0.0, 5.0), 0.3)),
        );
        assert!((out.command.thrust_n - p.mass_kg * p.gravity_mps2).abs() < 1e-9);
        assert!(out.command.torque_nm.norm() < 1e-9);
    }

    #[test]
    fn attitude_error_sign_drives_back() {
        // Rolled right (about +x): the torque about x must be negative.
        let p = QuadrotorParams::default();
        let ctl = GeometricController::new(ControllerConfig::default(), &p).unwrap();
        let mut s = QuadState::hover(&p, Point3::origin(), 0.0);
        s.world_from_body = UnitQuaternion::from_euler_angles(0.2, 0.0, 0.0);
        let out = ctl.update(
            &s,
            &Reference::hover(FlatState::hover(Point3::origin(), 0.0)),
        );
        assert!(out.command.torque_nm.x < 0.0);
        assert!(out.body_rate_cmd_radps.x < 0.0);
    }
}
