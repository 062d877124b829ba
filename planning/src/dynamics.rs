//! Quadrotor rigid-body dynamics: mass, inertia, linear drag, four rotors in X configuration
//! with thrust limits and a first-order motor lag, integrated with RK4. Optional wind gusts
//! (a seeded Ornstein–Uhlenbeck process).
//!
//! Frames: world ENU, body FLU. The attitude is `world_from_body`; body rates are in the body
//! frame.

use nalgebra::{Matrix3, Matrix4, Point3, Quaternion, UnitQuaternion, Vector3, Vector4};
use serde::{Deserialize, Serialize};

use crate::error::{PlanError, check_finite, check_positive, check_range};

/// Physical parameters of the vehicle. Defaults approximate a 3DR Iris (the paper's vehicle).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct QuadrotorParams {
    /// Mass (kg). Default 1.5.
    pub mass_kg: f64,
    /// Principal moments of inertia about body x, y, z (kg·m²). Default (0.0291, 0.0291, 0.0552).
    pub inertia_kgm2: [f64; 3],
    /// Distance from the centre to each rotor (m); rotors sit at ±45° (X frame). Default 0.25.
    pub arm_length_m: f64,
    /// Largest thrust of one rotor (N). Default 8.0 (thrust-to-weight ≈ 2.2).
    pub max_rotor_thrust_n: f64,
    /// Reaction torque per newton of rotor thrust (m). Default 0.016.
    pub yaw_torque_per_thrust_m: f64,
    /// Time constant of the rotor thrust response (s); 0 makes it instantaneous. Default 0.02.
    pub motor_time_constant_s: f64,
    /// Linear drag along body x, y, z (N per m/s of air-relative velocity). Default (0.2, 0.2, 0.3).
    pub drag_n_per_mps: [f64; 3],
    /// Gravitational acceleration (m/s²). Default 9.81.
    pub gravity_mps2: f64,
}

impl Default for QuadrotorParams {
    fn default() -> Self {
        Self {
            mass_kg: 1.5,
            inertia_kgm2: [0.029125, 0.029125, 0.055225],
            arm_length_m: 0.25,
            max_rotor_thrust_n: 8.0,
            yaw_torque_per_thrust_m: 0.016,
            motor_time_constant_s: 0.02,
            drag_n_per_mps: [0.2, 0.2, 0.3],
            gravity_mps2: 9.81,
        }
    }
}

impl QuadrotorParams {
    /// Checks that every parameter is finite and physical, and that the rotors can lift the
    /// vehicle.
    pub fn validate(&self) -> Result<(), PlanError> {
        check_positive("quad.mass_kg", self.mass_kg)?;
        for (i, j) in self.inertia_kgm2.iter().enumerate() {
            check_positive(format!("quad.inertia_kgm2[{i}]"), *j)?;
        }
        check_positive("quad.arm_length_m", self.arm_length_m)?;
        check_positive("quad.max_rotor_thrust_n", self.max_rotor_thrust_n)?;
        check_positive("quad.yaw_torque_per_thrust_m", self.yaw_torque_per_thrust_m)?;
        check_range(
            "quad.motor_time_constant_s",
            self.motor_time_constant_s,
            0.0,
            1.0,
        )?;
        for (i, d) in self.drag_n_per_mps.iter().enumerate() {
            check_range(format!("quad.drag_n_per_mps[{i}]"), *d, 0.0, 1e3)?;
        }
        check_positive("quad.gravity_mps2", self.gravity_mps2)?;
        if 4.0 * self.max_rotor_thrust_n <= self.mass_kg * self.gravity_mps2 {
            return Err(PlanError::InvalidParameter {
                field: "quad.max_rotor_thrust_n".into(),
                value: self.max_rotor_thrust_n,
                reason: "four rotors cannot lift the mass".into(),
            });
        }
        Ok(())
    }

    /// Inertia matrix (kg·m², body frame).
    pub fn inertia(&self) -> Matrix3<f64> {
        Matrix3::from_diagonal(&Vector3::from(self.inertia_kgm2))
    }

    /// Allocation matrix: rotor thrusts (N) → [collective thrust (N), torque x, y, z (N·m)].
    ///
    /// Rotors: 0 front-left, 1 rear-left, 2 rear-right, 3 front-right; 0 and 2 spin so that
    /// their reaction torque is +z, 1 and 3 −z.
    pub fn allocation(&self) -> Matrix4<f64> {
        let d = self.arm_length_m / std::f64::consts::SQRT_2;
        let pos = [(d, d), (-d, d), (-d, -d), (d, -d)];
        let spin = [1.0, -1.0, 1.0, -1.0];
        let c = self.yaw_torque_per_thrust_m;
        Matrix4::from_fn(|r, i| match r {
            0 => 1.0,
            1 => pos[i].1,
            2 => -pos[i].0,
            _ => c * spin[i],
        })
    }
}

/// The vehicle state.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct QuadState {
    /// Position of the body origin (world ENU, m).
    pub position_m: Point3<f64>,
    /// Velocity (world, m/s).
    pub velocity_mps: Vector3<f64>,
    /// Attitude `world_from_body`.
    pub world_from_body: UnitQuaternion<f64>,
    /// Angular velocity (body frame, rad/s).
    pub body_rate_radps: Vector3<f64>,
    /// Current thrust of each rotor (N).
    pub rotor_thrust_n: [f64; 4],
}

impl QuadState {
    /// Hovering at `position_m` with heading `yaw_rad`, rotors at hover thrust.
    pub fn hover(params: &QuadrotorParams, position_m: Point3<f64>, yaw_rad: f64) -> Self {
        let f = params.mass_kg * params.gravity_mps2 / 4.0;
        Self {
            position_m,
            velocity_mps: Vector3::zeros(),
            world_from_body: UnitQuaternion::from_euler_angles(0.0, 0.0, yaw_rad),
            body_rate_radps: Vector3::zeros(),
            rotor_thrust_n: [f; 4],
        }
    }

    /// Heading: angle of the body x axis projected on the horizontal plane, from east (rad).
    pub fn yaw_rad(&self) -> f64 {
        let x = self.world_from_body * Vector3::x();
        x.y.atan2(x.x)
    }

    /// Angle between the body z axis and world up (rad).
    pub fn tilt_rad(&self) -> f64 {
        let z = self.world_from_body * Vector3::z();
        z.z.clamp(-1.0, 1.0).acos()
    }

    /// Whether every component is finite.
    pub fn is_finite(&self) -> bool {
        self.position_m.iter().all(|v| v.is_finite())
            && self.velocity_mps.iter().all(|v| v.is_finite())
            && self.world_from_body.coords.iter().all(|v| v.is_finite())
            && self.body_rate_radps.iter().all(|v| v.is_finite())
            && self.rotor_thrust_n.iter().all(|v| v.is_finite())
    }
}

/// What the controller asks of the airframe: collective thrust and body torques.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct ActuatorCommand {
    /// Collective thrust along body +z (N).
    pub thrust_n: f64,
    /// Torque about body x, y, z (N·m).
    pub torque_nm: Vector3<f64>,
}

/// Wind model: a constant mean plus an Ornstein–Uhlenbeck gust per axis.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct WindConfig {
    /// Mean wind (world, m/s). Default zero.
    pub mean_mps: [f64; 3],
    /// Stationary standard deviation of the gusts per axis (m/s). Default 0 (no gusts).
    pub gust_std_mps: f64,
    /// Correlation time of the gusts (s). Default 2.0.
    pub gust_time_constant_s: f64,
    /// Seed of the gust generator. Default 0.
    pub seed: u64,
}

impl Default for WindConfig {
    fn default() -> Self {
        Self {
            mean_mps: [0.0; 3],
            gust_std_mps: 0.0,
            gust_time_constant_s: 2.0,
            seed: 0,
        }
    }
}

impl WindConfig {
    /// Checks that the values are finite and non-negative where needed.
    pub fn validate(&self) -> Result<(), PlanError> {
        for (i, m) in self.mean_mps.iter().enumerate() {
            check_finite(format!("wind.mean_mps[{i}]"), *m)?;
        }
        check_range("wind.gust_std_mps", self.gust_std_mps, 0.0, 100.0)?;
        check_positive("wind.gust_time_constant_s", self.gust_time_constant_s)?;
        Ok(())
    }
}

/// SplitMix64: a small, seedable, portable generator, so gusts are bit-for-bit reproducible
/// without tying them to a particular `rand` release.
#[derive(Debug, Clone)]
struct SplitMix64(u64);

impl SplitMix64 {
    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in (0, 1].
    fn next_open01(&mut self) -> f64 {
        ((self.next_u64() >> 11) as f64 + 1.0) / (1u64 << 53) as f64
    }

    /// Standard normal (Box–Muller).
    fn next_normal(&mut self) -> f64 {
        let u1 = self.next_open01();
        let u2 = self.next_open01();
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    }
}

/// A wind field evolving in time.
#[derive(Debug, Clone)]
pub struct Wind {
    cfg: WindConfig,
    gust_mps: Vector3<f64>,
    rng: SplitMix64,
}

impl Wind {
    /// Starts the process from a stationary draw (deterministic for the seed).
    pub fn new(cfg: WindConfig) -> Self {
        let mut rng = SplitMix64(cfg.seed);
        let gust_mps = Vector3::from_fn(|_, _| cfg.gust_std_mps * rng.next_normal());
        Self { cfg, gust_mps, rng }
    }

    /// Current wind velocity (world, m/s).
    pub fn velocity_mps(&self) -> Vector3<f64> {
        Vector3::from(self.cfg.mean_mps) + self.gust_mps
    }

    /// Advances the gusts by `dt_s` (exact OU discretisation).
    pub fn step(&mut self, dt_s: f64) {
        if self.cfg.gust_std_mps <= 0.0 {
            return;
        }
        let a = (-dt_s / self.cfg.gust_time_constant_s).exp();
        let s = self.cfg.gust_std_mps * (1.0 - a * a).sqrt();
        for i in 0..3 {
            self.gust_mps[i] = a * self.gust_mps[i] + s * self.rng.next_normal();
        }
    }
}

/// Time derivative of the state.
#[derive(Debug, Clone, Copy)]
struct Derivative {
    velocity: Vector3<f64>,
    acceleration: Vector3<f64>,
    quat_dot: Quaternion<f64>,
    angular_accel: Vector3<f64>,
    rotor_dot: Vector4<f64>,
}

/// The quadrotor model with its precomputed matrices.
#[derive(Debug, Clone)]
pub struct Quadrotor {
    params: QuadrotorParams,
    inertia: Matrix3<f64>,
    inertia_inv: Matrix3<f64>,
    allocation: Matrix4<f64>,
    allocation_inv: Matrix4<f64>,
}

impl Quadrotor {
    /// Builds the model. Fails if the parameters are invalid.
    pub fn new(params: QuadrotorParams) -> Result<Self, PlanError> {
        params.validate()?;
        let allocation = params.allocation();
        let allocation_inv =
            allocation
                .try_inverse()
                .ok_or_else(|| PlanError::InvalidParameter {
                    field: "quad.arm_length_m".into(),
                    value: params.arm_length_m,
                    reason: "rotor allocation matrix is singular".into(),
                })?;
        let inertia = params.inertia();
        Ok(Self {
            params,
            inertia,
            // Diagonal with positive entries (validated), so invertible.
            inertia_inv: Matrix3::from_diagonal(
                &Vector3::from(params.inertia_kgm2).map(|j| 1.0 / j),
            ),
            allocation,
            allocation_inv,
        })
    }

    /// The parameters.
    pub fn params(&self) -> &QuadrotorParams {
        &self.params
    }

    /// Rotor thrusts (N) that realise `cmd` within the motor limits. When the command cannot be
    /// met, yaw torque is given up first, then the thrusts are clipped.
    pub fn mix(&self, cmd: &ActuatorCommand) -> [f64; 4] {
        let fmax = self.params.max_rotor_thrust_n;
        let full = self.allocation_inv
            * Vector4::new(
                cmd.thrust_n,
                cmd.torque_nm.x,
                cmd.torque_nm.y,
                cmd.torque_nm.z,
            );
        let no_yaw =
            self.allocation_inv * Vector4::new(cmd.thrust_n, cmd.torque_nm.x, cmd.torque_nm.y, 0.0);
        // Largest fraction of the yaw torque that keeps every rotor in [0, fmax].
        let mut lambda: f64 = 1.0;
        for i in 0..4 {
            let base = no_yaw[i];
            let delta = full[i] - no_yaw[i];
            if delta > 0.0 && base + delta > fmax {
                lambda = lambda.min(((fmax - base) / delta).max(0.0));
            } else if delta < 0.0 && base + delta < 0.0 {
                lambda = lambda.min((base / -delta).max(0.0));
            }
        }
        let f = no_yaw + (full - no_yaw) * lambda;
        std::array::from_fn(|i| {
            if f[i].is_finite() {
                f[i].clamp(0.0, fmax)
            } else {
                0.0
            }
        })
    }

    /// Collective thrust (N) and body torque (N·m) produced by the rotor thrusts.
    pub fn wrench(&self, rotor_thrust_n: &[f64; 4]) -> (f64, Vector3<f64>) {
        let w = self.allocation * Vector4::from(*rotor_thrust_n);
        (w[0], Vector3::new(w[1], w[2], w[3]))
    }

    /// Linear acceleration (world, m/s²) in `state` with air velocity `wind_mps`.
    pub fn acceleration(&self, state: &QuadState, wind_mps: &Vector3<f64>) -> Vector3<f64> {
        let (thrust, _) = self.wrench(&state.rotor_thrust_n);
        let r = state.world_from_body;
        let air_body = r.inverse() * (state.velocity_mps - wind_mps);
        let drag_body = -Vector3::from(self.params.drag_n_per_mps).component_mul(&air_body);
        (r * (Vector3::z() * thrust + drag_body)) / self.params.mass_kg
            - Vector3::z() * self.params.gravity_mps2
    }

    fn derivative(&self, s: &QuadState, rotor_cmd: &[f64; 4], wind: &Vector3<f64>) -> Derivative {
        let (_, torque) = self.wrench(&s.rotor_thrust_n);
        let w = s.body_rate_radps;
        let angular_accel = self.inertia_inv * (torque - w.cross(&(self.inertia * w)));
        let q = s.world_from_body.quaternion();
        let quat_dot = q * Quaternion::from_imag(w) * 0.5;
        let tau = self.params.motor_time_constant_s;
        let rotor_dot = if tau > 0.0 {
            Vector4::from_fn(|i, _| (rotor_cmd[i] - s.rotor_thrust_n[i]) / tau)
        } else {
            Vector4::zeros()
        };
        Derivative {
            velocity: s.velocity_mps,
            acceleration: self.acceleration(s, wind),
            quat_dot,
            angular_accel,
            rotor_dot,
        }
    }

    fn advance(s: &QuadState, d: &Derivative, h: f64) -> QuadState {
        let q = s.world_from_body.quaternion() + d.quat_dot * h;
        QuadState {
            position_m: s.position_m + d.velocity * h,
            velocity_mps: s.velocity_mps + d.acceleration * h,
            // Renormalised; a zero quaternion cannot arise from a unit one in a small step.
            world_from_body: UnitQuaternion::from_quaternion(q),
            body_rate_radps: s.body_rate_radps + d.angular_accel * h,
            rotor_thrust_n: std::array::from_fn(|i| s.rotor_thrust_n[i] + d.rotor_dot[i] * h),
        }
    }

    /// One RK4 step of `dt_s` with the actuator command and wind held constant.
    pub fn step(
        &self,
        state: &QuadState,
        cmd: &ActuatorCommand,
        wind_mps: &Vector3<f64>,
        dt_s: f64,
    ) -> QuadState {
        let rotor_cmd = self.mix(cmd);
        if self.params.motor_time_constant_s <= 0.0 {
            let mut s0 = *state;
            s0.rotor_thrust_n = rotor_cmd;
            return self.step_inner(&s0, &rotor_cmd, wind_mps, dt_s);
        }
        self.step_inner(state, &rotor_cmd, wind_mps, dt_s)
    }

    fn step_inner(
        &self,
        s: &QuadState,
        rotor_cmd: &[f64; 4],
        wind: &Vector3<f64>,
        h: f64,
    ) -> QuadState {
        let k1 = self.derivative(s, rotor_cmd, wind);
        let s2 = Self::advance(s, &k1, 0.5 * h);
        let k2 = self.derivative(&s2, rotor_cmd, wind);
        let s3 = Self::advance(s, &k2, 0.5 * h);
        let k3 = self.derivative(&s3, rotor_cmd, wind);
        let s4 = Self::advance(s, &k3, h);
        let k4 = self.derivative(&s4, rotor_cmd, wind);
        let combo = Derivative {
            velocity: (k1.velocity + 2.0 * k2.velocity + 2.0 * k3.velocity + k4.velocity) / 6.0,
            acceleration: (k1.acceleration
                + 2.0 * k2.acceleration
                + 2.0 * k3.acceleration
                + k4.acceleration)
                / 6.0,
            quat_dot: (k1.quat_dot + k2.quat_dot * 2.0 + k3.quat_dot * 2.0 + k4.quat_dot) / 6.0,
            angular_accel: (k1.angular_accel
                + 2.0 * k2.angular_accel
                + 2.0 * k3.angular_accel
                + k4.angular_accel)
                / 6.0,
            rotor_dot: (k1.rotor_dot + 2.0 * k2.rotor_dot + 2.0 * k3.rotor_dot + k4.rotor_dot)
                / 6.0,
        };
        let mut out = Self::advance(s, &combo, h);
        if self.params.motor_time_constant_s <= 0.0 {
            out.rotor_thrust_n = *rotor_cmd;
        } else {
            let fmax = self.params.max_rotor_thrust_n;
            for f in &mut out.rotor_thrust_n {
                *f = f.clamp(0.0, fmax);
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hover_is_an_equilibrium() {
        let quad = Quadrotor::new(QuadrotorParams::default()).unwrap();
        let p = quad.params;
        let mut s = QuadState::hover(&p, Point3::new(1.0, 2.0, 3.0), 0.7);
        let cmd = ActuatorCommand {
            thrust_n: p.mass_kg * p.gravity_mps2,
            torque_nm: Vector3::zeros(),
        };
        for _ in 0..1000 {
            s = quad.step(&s, &cmd, &Vector3::zeros(), 0.002);
        }
        assert!((s.position_m - Point3::new(1.0, 2.0, 3.0)).norm() < 1e-9);
        assert!((s.yaw_rad() - 0.7).abs() < 1e-9);
    }

    #[test]
    fn free_fall_and_mixer_roundtrip() {
        let quad = Quadrotor::new(QuadrotorParams {
            motor_time_constant_s: 0.0,
            ..Default::default()
        })
        .unwrap();
        let mut s = QuadState::hover(quad.params(), Point3::origin(), 0.0);
        for _ in 0..500 {
            s = quad.step(&s, &ActuatorCommand::default(), &Vector3::zeros(), 0.002);
        }
        // 1 s of free fall with linear drag k = c_z/m: z(t) = −(g/k)(t − (1 − e^{−kt})/k).
        let k: f64 = 0.3 / 1.5;
        let z = -(9.81 / k) * (1.0 - (1.0 - (-k).exp()) / k);
        assert!(
            (s.position_m.z - z).abs() < 1e-8,
            "{} vs {z}",
            s.position_m.z
        );
        let cmd = ActuatorCommand {
            thrust_n: 15.0,
            torque_nm: Vector3::new(0.1, -0.05, 0.01),
        };
        let (t, m) = quad.wrench(&quad.mix(&cmd));
        assert!((t - 15.0).abs() < 1e-9 && (m - cmd.torque_nm).norm() < 1e-9);
    }

    #[test]
    fn wind_is_deterministic_and_stationary() {
        let cfg = WindConfig {
            gust_std_mps: 1.0,
            seed: 7,
            ..Default::default()
        };
        let (mut a, mut b) = (Wind::new(cfg), Wind::new(cfg));
        let mut sum2 = 0.0;
        let n = 20000;
        for _ in 0..n {
            a.step(0.05);
            b.step(0.05);
            sum2 += a.velocity_mps().x.powi(2);
        }
        assert_eq!(a.velocity_mps(), b.velocity_mps());
        let std = (sum2 / n as f64).sqrt();
        assert!((std - 1.0).abs() < 0.25, "{std}");
    }
}
