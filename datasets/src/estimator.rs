//! A state-estimator model: what a GPS/IMU filter would report for the camera pose.
//!
//! Position error per axis is a first-order Gauss–Markov process (a random walk pulled back
//! toward zero with correlation time τ, so its spread stays at the configured σ) plus white
//! noise. Attitude error is the same kind of process on roll, pitch and yaw, applied about the
//! world axes: `R_est = Rz(δyaw)·Ry(δpitch)·Rx(δroll)·R_true`.

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use rand::SeedableRng;
use rand::rngs::Xoshiro256PlusPlus;
use rand_distr::{Distribution, StandardNormal};
use scarp_export::tum::StampedPose;
use serde::{Deserialize, Serialize};

/// What the vehicle's position comes from: the defaults of every noise level.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum EstimatorPreset {
    /// A consumer GNSS receiver fused with an IMU: the position walks by σ 0.5 m horizontally
    /// and 0.8 m vertically.
    #[default]
    Gps,
    /// RTK GNSS, as survey drones carry: σ 2 cm horizontally and 3 cm vertically. The attitude
    /// (from the IMU) is as with `gps`.
    Rtk,
}

/// Noise levels of the state estimator. In a config file (`[estimator]`), `preset` sets the
/// defaults and any other key overrides its value.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(from = "EstimatorTable")]
pub struct EstimatorConfig {
    /// The preset the other fields default to. Default `gps`.
    pub preset: EstimatorPreset,
    /// Stationary σ of the horizontal GPS random walk, metres per axis. Default 0.5.
    pub horizontal_sigma_m: f64,
    /// Stationary σ of the vertical GPS random walk, metres. Default 0.8.
    pub vertical_sigma_m: f64,
    /// Correlation time of the position walk, seconds. Default 30.
    pub position_correlation_s: f64,
    /// White position noise per sample, horizontal, metres. Default 0.02.
    pub horizontal_white_m: f64,
    /// White position noise per sample, vertical, metres. Default 0.03.
    pub vertical_white_m: f64,
    /// Stationary σ of roll and pitch errors, degrees. Default 0.5.
    pub roll_pitch_sigma_deg: f64,
    /// Stationary σ of the yaw error, degrees. Default 2.0.
    pub yaw_sigma_deg: f64,
    /// Correlation time of the attitude errors, seconds. Default 10.
    pub attitude_correlation_s: f64,
    /// A constant position error added to the walk (estimate − truth), metres, world ENU:
    /// a scripted bias for testing what flies on the estimate. Default zero.
    pub bias_m: [f64; 3],
}

impl Default for EstimatorConfig {
    fn default() -> Self {
        Self::preset(EstimatorPreset::Gps)
    }
}

/// `[estimator]` as written: a preset and any overrides.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct EstimatorTable {
    #[serde(default)]
    preset: EstimatorPreset,
    horizontal_sigma_m: Option<f64>,
    vertical_sigma_m: Option<f64>,
    position_correlation_s: Option<f64>,
    horizontal_white_m: Option<f64>,
    vertical_white_m: Option<f64>,
    roll_pitch_sigma_deg: Option<f64>,
    yaw_sigma_deg: Option<f64>,
    attitude_correlation_s: Option<f64>,
    bias_m: Option<[f64; 3]>,
}

impl From<EstimatorTable> for EstimatorConfig {
    fn from(t: EstimatorTable) -> Self {
        let base = Self::preset(t.preset);
        Self {
            preset: t.preset,
            horizontal_sigma_m: t.horizontal_sigma_m.unwrap_or(base.horizontal_sigma_m),
            vertical_sigma_m: t.vertical_sigma_m.unwrap_or(base.vertical_sigma_m),
            position_correlation_s: t
                .position_correlation_s
                .unwrap_or(base.position_correlation_s),
            horizontal_white_m: t.horizontal_white_m.unwrap_or(base.horizontal_white_m),
            vertical_white_m: t.vertical_white_m.unwrap_or(base.vertical_white_m),
            roll_pitch_sigma_deg: t.roll_pitch_sigma_deg.unwrap_or(base.roll_pitch_sigma_deg),
            yaw_sigma_deg: t.yaw_sigma_deg.unwrap_or(base.yaw_sigma_deg),
            attitude_correlation_s: t
                .attitude_correlation_s
                .unwrap_or(base.attitude_correlation_s),
            bias_m: t.bias_m.unwrap_or(base.bias_m),
        }
    }
}

impl EstimatorConfig {
    /// The noise levels of `preset`.
    pub fn preset(preset: EstimatorPreset) -> Self {
        let gps = Self {
            preset,
            horizontal_sigma_m: 0.5,
            vertical_sigma_m: 0.8,
            position_correlation_s: 30.0,
            horizontal_white_m: 0.02,
            vertical_white_m: 0.03,
            roll_pitch_sigma_deg: 0.5,
            yaw_sigma_deg: 2.0,
            attitude_correlation_s: 10.0,
            bias_m: [0.0; 3],
        };
        match preset {
            EstimatorPreset::Gps => gps,
            EstimatorPreset::Rtk => Self {
                horizontal_sigma_m: 0.02,
                vertical_sigma_m: 0.03,
                horizontal_white_m: 0.005,
                vertical_white_m: 0.01,
                ..gps
            },
        }
    }
}

impl EstimatorConfig {
    /// How the error of the estimated rotation between two poses grows with the time Δt
    /// between them, degrees per √second: about this × √Δt (1σ, the three axes together).
    ///
    /// Each axis's error is a Gauss–Markov process, whose change over Δt has the variance
    /// 2σ²(1 − e^(−Δt/τ)) ≤ 2σ²Δt/τ: exact for Δt ≪ `attitude_correlation_s`, an upper bound
    /// beyond it.
    pub fn attitude_walk_deg_per_sqrt_s(&self) -> f64 {
        let sigma_deg =
            (self.yaw_sigma_deg.powi(2) + 2.0 * self.roll_pitch_sigma_deg.powi(2)).sqrt();
        sigma_deg * (2.0 / self.attitude_correlation_s.max(1e-9)).sqrt()
    }
}

/// A first-order Gauss–Markov process with stationary σ and correlation time τ.
#[derive(Debug, Clone, Copy)]
struct GaussMarkov {
    sigma: f64,
    tau_s: f64,
    value: f64,
}

impl GaussMarkov {
    fn new(sigma: f64, tau_s: f64, rng: &mut Xoshiro256PlusPlus) -> Self {
        let draw: f64 = StandardNormal.sample(rng);
        Self {
            sigma,
            tau_s,
            value: sigma * draw,
        }
    }

    fn step(&mut self, dt_s: f64, rng: &mut Xoshiro256PlusPlus) -> f64 {
        let phi = (-dt_s.max(0.0) / self.tau_s.max(1e-9)).exp();
        let draw: f64 = StandardNormal.sample(rng);
        self.value = phi * self.value + (1.0 - phi * phi).sqrt() * self.sigma * draw;
        self.value
    }
}

impl EstimatorConfig {
    /// The estimated poses for a true trajectory (same timestamps), from seed `seed`.
    pub fn estimate(&self, truth: &[StampedPose], seed: u64) -> Vec<StampedPose> {
        let mut estimator = StateEstimator::new(self, seed);
        truth
            .iter()
            .map(|pose| StampedPose {
                timestamp_s: pose.timestamp_s,
                world_from_camera: estimator.observe(pose.timestamp_s, &pose.world_from_camera),
            })
            .collect()
    }
}

/// The estimator as a running process: feed it true poses in time order and it returns what the
/// GPS/IMU filter would report. [`EstimatorConfig::estimate`] is this applied to a whole
/// trajectory, so a closed-loop simulation that calls [`StateEstimator::observe`] at its camera
/// times gets the same errors as a rendered sequence with the same timestamps and seed.
#[derive(Debug, Clone)]
pub struct StateEstimator {
    rng: Xoshiro256PlusPlus,
    /// x, y, z position walks, then roll, pitch, yaw.
    walks: [GaussMarkov; 6],
    white_m: [f64; 3],
    bias_m: Vector3<f64>,
    previous_t: Option<f64>,
}

impl StateEstimator {
    /// A new process with its stationary initial error drawn from `seed`.
    pub fn new(cfg: &EstimatorConfig, seed: u64) -> Self {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
        let mut walk = |sigma: f64, tau_s: f64| GaussMarkov::new(sigma, tau_s, &mut rng);
        let walks = [
            walk(cfg.horizontal_sigma_m, cfg.position_correlation_s),
            walk(cfg.horizontal_sigma_m, cfg.position_correlation_s),
            walk(cfg.vertical_sigma_m, cfg.position_correlation_s),
            walk(
                cfg.roll_pitch_sigma_deg.to_radians(),
                cfg.attitude_correlation_s,
            ),
            walk(
                cfg.roll_pitch_sigma_deg.to_radians(),
                cfg.attitude_correlation_s,
            ),
            walk(cfg.yaw_sigma_deg.to_radians(), cfg.attitude_correlation_s),
        ];
        Self {
            rng,
            walks,
            white_m: [
                cfg.horizontal_white_m,
                cfg.horizontal_white_m,
                cfg.vertical_white_m,
            ],
            bias_m: Vector3::from(cfg.bias_m),
            previous_t: None,
        }
    }

    /// The slowly varying part of the position error now (metres, world ENU): the GPS walk
    /// and the scripted bias, without the white noise. A controller flying on the estimate sits
    /// off the truth by this.
    pub fn position_drift_m(&self) -> Vector3<f64> {
        Vector3::new(
            self.walks[0].value,
            self.walks[1].value,
            self.walks[2].value,
        ) + self.bias_m
    }

    /// Advances the error processes to `timestamp_s` and returns the estimate of the true
    /// `world_from_camera`. Times must not decrease; a repeated or earlier time advances by 0 s.
    pub fn observe(
        &mut self,
        timestamp_s: f64,
        world_from_camera: &Isometry3<f64>,
    ) -> Isometry3<f64> {
        let dt = self.previous_t.map_or(0.0, |t| timestamp_s - t);
        self.previous_t = Some(timestamp_s);
        let rng = &mut self.rng;
        let e: [f64; 6] = std::array::from_fn(|k| self.walks[k].step(dt, rng));
        let noise: [f64; 3] = std::array::from_fn(|k| {
            let draw: f64 = StandardNormal.sample(rng);
            self.white_m[k] * draw
        });
        let position_error =
            Vector3::new(e[0] + noise[0], e[1] + noise[1], e[2] + noise[2]) + self.bias_m;
        let attitude_error = UnitQuaternion::from_euler_angles(e[3], e[4], e[5]);
        Isometry3::from_parts(
            Translation3::from(world_from_camera.translation.vector + position_error),
            attitude_error * world_from_camera.rotation,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_preset_sets_the_defaults_and_keys_override_it() {
        let rtk: EstimatorConfig = toml::from_str("preset = \"rtk\"").unwrap();
        assert_eq!(rtk, EstimatorConfig::preset(EstimatorPreset::Rtk));
        assert_eq!((rtk.horizontal_sigma_m, rtk.vertical_sigma_m), (0.02, 0.03));
        let tuned: EstimatorConfig =
            toml::from_str("preset = \"rtk\"\nyaw_sigma_deg = 0.5").unwrap();
        assert_eq!(tuned.yaw_sigma_deg, 0.5);
        assert_eq!(tuned.horizontal_sigma_m, 0.02);
        let gps: EstimatorConfig = toml::from_str("").unwrap();
        assert_eq!(gps, EstimatorConfig::default());
        assert_eq!(gps.horizontal_sigma_m, 0.5);
        // What `scarp config` prints reads back as itself.
        let printed = toml::to_string(&tuned).unwrap();
        assert_eq!(toml::from_str::<EstimatorConfig>(&printed).unwrap(), tuned);
        let error = toml::from_str::<EstimatorConfig>("preset = \"galileo\"").unwrap_err();
        assert!(error.to_string().contains("galileo"), "{error}");
        assert!(toml::from_str::<EstimatorConfig>("horizontal_sigma = 1.0").is_err());
    }

    #[test]
    fn error_spread_matches_configuration() {
        let config = EstimatorConfig {
            position_correlation_s: 0.5,
            attitude_correlation_s: 0.5,
            ..Default::default()
        };
        let truth: Vec<StampedPose> = (0..20_000)
            .map(|k| StampedPose {
                timestamp_s: k as f64 * 0.05,
                world_from_camera: Isometry3::identity(),
            })
            .collect();
        let est = config.estimate(&truth, 3);
        let n = est.len() as f64;
        let rms = |f: &dyn Fn(&StampedPose) -> f64| {
            (est.iter().map(|p| f(p).powi(2)).sum::<f64>() / n).sqrt()
        };
        let x = rms(&|p| p.world_from_camera.translation.x);
        let z = rms(&|p| p.world_from_camera.translation.z);
        let expected_x = (0.5f64.powi(2) + 0.02f64.powi(2)).sqrt();
        assert!((x / expected_x - 1.0).abs() < 0.1, "x rms {x}");
        assert!((z / 0.8 - 1.0).abs() < 0.1, "z rms {z}");
        let yaw = rms(&|p| p.world_from_camera.rotation.euler_angles().2.to_degrees());
        assert!((yaw / 2.0 - 1.0).abs() < 0.1, "yaw rms {yaw}");
        assert_eq!(est, config.estimate(&truth, 3));
    }
}
