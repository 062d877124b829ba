//! Simulated flight: the geometric controller (at its own rate, zero-order hold) drives the
//! quadrotor model (RK4 at the physics rate) along a reference, and the run is summarised in
//! the metrics that `flight.json` carries.

use nalgebra::{Point3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

use crate::clearance::{ClearanceConfig, Environment};
use crate::control::{ControllerConfig, GeometricController, Reference, attitude_from_flat};
use crate::dynamics::{QuadState, Quadrotor, QuadrotorParams, Wind, WindConfig};
use crate::error::{PlanError, check_positive, check_range};
use crate::geometry::wrap_angle;
use crate::minsnap::Trajectory;

/// Simulation settings.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FlightConfig {
    /// Airframe.
    pub quad: QuadrotorParams,
    /// Controller gains and rate.
    pub controller: ControllerConfig,
    /// Wind (default: calm).
    pub wind: WindConfig,
    /// Physics integration rate (Hz), at least 200 and rounded to a multiple of the controller
    /// rate. Default 500.
    pub physics_rate_hz: f64,
    /// Time flown after the trajectory ends, holding the last point (s). Default 1.0.
    pub settle_time_s: f64,
    /// Period of the clearance samples of the flown track (s). Default 0.05.
    pub clearance_sample_period_s: f64,
    /// The flight is abandoned when the position error exceeds this (m). Default 20.
    pub divergence_limit_m: f64,
}

impl Default for FlightConfig {
    fn default() -> Self {
        Self {
            quad: QuadrotorParams::default(),
            controller: ControllerConfig::default(),
            wind: WindConfig::default(),
            physics_rate_hz: 500.0,
            settle_time_s: 1.0,
            clearance_sample_period_s: 0.05,
            divergence_limit_m: 20.0,
        }
    }
}

impl FlightConfig {
    /// Checks every nested configuration and the rates.
    pub fn validate(&self) -> Result<(), PlanError> {
        self.quad.validate()?;
        self.controller.validate()?;
        self.wind.validate()?;
        check_range("flight.physics_rate_hz", self.physics_rate_hz, 200.0, 1e5)?;
        check_range("flight.settle_time_s", self.settle_time_s, 0.0, 1e4)?;
        check_positive(
            "flight.clearance_sample_period_s",
            self.clearance_sample_period_s,
        )?;
        check_positive("flight.divergence_limit_m", self.divergence_limit_m)?;
        Ok(())
    }
}

/// One logged instant (at the controller rate).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct FlightSample {
    /// Simulation time (s).
    pub time_s: f64,
    /// True position (world ENU, m).
    pub position_m: Point3<f64>,
    /// True velocity (world, m/s).
    pub velocity_mps: Vector3<f64>,
    /// True attitude `world_from_body`.
    pub world_from_body: UnitQuaternion<f64>,
    /// Reference position (m).
    pub reference_position_m: Point3<f64>,
    /// Reference yaw (rad, unwrapped).
    pub reference_yaw_rad: f64,
    /// Commanded collective thrust (N).
    pub thrust_cmd_n: f64,
}

/// The summary written to `flight.json`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct FlightMetrics {
    /// RMS of the position error ‖p − p_ref‖ over the flight (m).
    pub position_rms_m: f64,
    /// Largest position error (m).
    pub position_max_m: f64,
    /// RMS of the heading error (degrees).
    pub yaw_rms_deg: f64,
    /// Largest heading error, wrapped to [0°, 180°] (degrees).
    pub yaw_max_deg: f64,
    /// Largest true speed (m/s).
    pub speed_max_mps: f64,
    /// Largest true acceleration magnitude (m/s², kinematic, gravity excluded).
    pub accel_max_mps2: f64,
    /// Smallest clearance of the flown track to terrain and obstacles (m); `None` when the
    /// environment is empty.
    pub min_clearance_m: Option<f64>,
    /// Simulated time, including the settling time (s).
    pub duration_s: f64,
    /// Largest tilt of the body z axis from vertical (degrees).
    pub tilt_max_deg: f64,
    /// Largest reference speed (m/s).
    pub reference_speed_max_mps: f64,
    /// Largest reference acceleration (m/s²).
    pub reference_accel_max_mps2: f64,
}

/// Metrics and the full log of a simulated flight.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FlightResult {
    /// Summary.
    pub metrics: FlightMetrics,
    /// Log at the controller rate.
    pub samples: Vec<FlightSample>,
    /// Final state.
    pub final_state: QuadState,
}

/// Controller plus airframe, ready to fly references.
#[derive(Debug, Clone)]
pub struct Simulator {
    cfg: FlightConfig,
    quad: Quadrotor,
    controller: GeometricController,
}

impl Simulator {
    /// Builds the simulator. Fails on an invalid configuration.
    pub fn new(cfg: FlightConfig) -> Result<Self, PlanError> {
        cfg.validate()?;
        Ok(Self {
            quad: Quadrotor::new(cfg.quad)?,
            controller: GeometricController::new(cfg.controller, &cfg.quad)?,
            cfg,
        })
    }

    /// The configuration.
    pub fn config(&self) -> &FlightConfig {
        &self.cfg
    }

    /// The airframe model.
    pub fn quadrotor(&self) -> &Quadrotor {
        &self.quad
    }

    /// Flies `reference(t)` for `duration_s` from `initial`, with clearance measured against
    /// `env`. Fails if the state becomes non-finite or the error exceeds the divergence limit.
    pub fn run(
        &self,
        initial: QuadState,
        duration_s: f64,
        mut reference: impl FnMut(f64) -> Reference,
        env: &Environment,
    ) -> Result<FlightResult, PlanError> {
        check_range("duration_s", duration_s, 0.0, 1e6)?;
        let ctrl_dt = 1.0 / self.cfg.controller.rate_hz;
        let substeps = (self.cfg.physics_rate_hz / self.cfg.controller.rate_hz)
            .round()
            .max(1.0) as usize;
        let dt = ctrl_dt / substeps as f64;
        let ticks = (duration_s / ctrl_dt).ceil() as usize;
        let clearance_every =
            ((self.cfg.clearance_sample_period_s / ctrl_dt).round() as usize).max(1);

        let mut wind = Wind::new(self.cfg.wind);
        let mut state = initial;
        let mut samples = Vec::with_capacity(ticks + 1);
        let (mut sum_e2, mut max_e, mut sum_y2, mut max_y) = (0.0, 0.0f64, 0.0, 0.0f64);
        let (mut max_v, mut max_a, mut max_tilt, mut ref_v, mut ref_a) =
            (0.0f64, 0.0f64, 0.0f64, 0.0f64, 0.0f64);
        let mut min_clear: Option<f64> = None;
        for k in 0..=ticks {
            let t = k as f64 * ctrl_dt;
            let r = reference(t);
            if !state.is_finite() {
                return Err(PlanError::FlightDiverged {
                    time_s: t,
                    position_error_m: f64::NAN,
                });
            }
            let e = (state.position_m - r.flat.position_m).norm();
            if e > self.cfg.divergence_limit_m {
                return Err(PlanError::FlightDiverged {
                    time_s: t,
                    position_error_m: e,
                });
            }
            let ye = wrap_angle(state.yaw_rad() - r.flat.yaw_rad)
                .abs()
                .to_degrees();
            sum_e2 += e * e;
            max_e = max_e.max(e);
            sum_y2 += ye * ye;
            max_y = max_y.max(ye);
            max_v = max_v.max(state.velocity_mps.norm());
            max_a = max_a.max(self.quad.acceleration(&state, &wind.velocity_mps()).norm());
            max_tilt = max_tilt.max(state.tilt_rad().to_degrees());
            ref_v = ref_v.max(r.flat.velocity_mps.norm());
            ref_a = ref_a.max(r.flat.acceleration_mps2.norm());
            if (k % clearance_every == 0 || k == ticks)
                && let Some(c) = env.clearance_at(&state.position_m)
            {
                min_clear = Some(min_clear.map_or(c.clearance_m, |m: f64| m.min(c.clearance_m)));
            }
            let out = self.controller.update(&state, &r);
            samples.push(FlightSample {
                time_s: t,
                position_m: state.position_m,
                velocity_mps: state.velocity_mps,
                world_from_body: state.world_from_body,
                reference_position_m: r.flat.position_m,
                reference_yaw_rad: r.flat.yaw_rad,
                thrust_cmd_n: out.command.thrust_n,
            });
            if k == ticks {
                break;
            }
            for _ in 0..substeps {
                let w = wind.velocity_mps();
                state = self.quad.step(&state, &out.command, &w, dt);
                wind.step(dt);
            }
        }
        let n = samples.len() as f64;
        Ok(FlightResult {
            metrics: FlightMetrics {
                position_rms_m: (sum_e2 / n).sqrt(),
                position_max_m: max_e,
                yaw_rms_deg: (sum_y2 / n).sqrt(),
                yaw_max_deg: max_y,
                speed_max_mps: max_v,
                accel_max_mps2: max_a,
                min_clearance_m: min_clear,
                duration_s: ticks as f64 * ctrl_dt,
                tilt_max_deg: max_tilt,
                reference_speed_max_mps: ref_v,
                reference_accel_max_mps2: ref_a,
            },
            samples,
            final_state: state,
        })
    }

    /// The state of a vehicle exactly on `trajectory` at its start: position, velocity,
    /// attitude and rotor thrusts for the start acceleration and yaw, body rates from the
    /// feedforward.
    pub fn initial_state_on(&self, trajectory: &Trajectory) -> QuadState {
        let p = &self.cfg.quad;
        let r = Reference::from_trajectory(
            trajectory,
            0.0,
            p.gravity_mps2,
            self.cfg.controller.feedforward_step_s,
        );
        let att = attitude_from_flat(&r.flat.acceleration_mps2, r.flat.yaw_rad, p.gravity_mps2);
        let thrust = p.mass_kg * (r.flat.acceleration_mps2 + Vector3::z() * p.gravity_mps2).norm();
        QuadState {
            position_m: r.flat.position_m,
            velocity_mps: r.flat.velocity_mps,
            world_from_body: UnitQuaternion::from_rotation_matrix(&att),
            body_rate_radps: r.body_rate_radps,
            rotor_thrust_n: [thrust / 4.0; 4],
        }
    }

    /// Flies `trajectory` from a state on its start, then holds its end for
    /// `settle_time_s`.
    pub fn fly(
        &self,
        trajectory: &Trajectory,
        env: &Environment,
    ) -> Result<FlightResult, PlanError> {
        let g = self.cfg.quad.gravity_mps2;
        let h = self.cfg.controller.feedforward_step_s;
        let initial = self.initial_state_on(trajectory);
        let duration = trajectory.duration_s() + self.cfg.settle_time_s;
        self.run(
            initial,
            duration,
            |t| Reference::from_trajectory(trajectory, t, g, h),
            env,
        )
    }
}

/// Flies `trajectory` with the configuration `cfg` in `env` (see [`Simulator::fly`]).
pub fn fly_trajectory(
    trajectory: &Trajectory,
    env: &Environment,
    cfg: &FlightConfig,
) -> Result<FlightResult, PlanError> {
    Simulator::new(*cfg)?.fly(trajectory, env)
}

/// Clearance of the flown track, sampled as the metrics do, for callers that want the report.
pub fn flown_clearance(
    result: &FlightResult,
    env: &Environment,
    cfg: &ClearanceConfig,
) -> crate::clearance::ClearanceReport {
    env.check_points(result.samples.iter().map(|s| &s.position_m), cfg)
}
