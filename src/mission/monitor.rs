//! The safety layer: what the vehicle's own sensors say about its clearance, acted on in the
//! control loop whatever the state estimate says.
//!
//! Two sensors feed it: a downward rangefinder (vertical distance to the surface below, with
//! noise and dropouts), and the depth camera's nearest measured point. The monitor
//! 1. corrects the state estimate's height, as an autopilot fusing a rangefinder with a
//!    terrain model does: the median, over recent readings, of the measured range minus the
//!    range the terrain model predicts below the *estimated* position is the estimate's
//!    vertical error, and is removed from it. Everything downstream (localization, ring plans,
//!    the map's anchor, the controller) then works in a frame whose heights match the ground,
//!    so the rings are flown at their planned clearance, not at whatever the GPS walk leaves.
//!    The correction is rate-limited, so a first reading does not jerk the vehicle, and fades
//!    when the ground is out of range;
//! 2. climbs away when any sensed surface comes nearer than the safety radius (a reflex on the
//!    controller only, not on the estimate), and counts each such intervention; where the
//!    nearest surface is the depth camera's, it also backs away from it horizontally, since a
//!    climb does not take the vehicle off a rock's side (library-b seed 62, session 55: a neck
//!    ring's way out climbed along the block it had circled, from 0.72 m to 0.28 m).
//!
//! The clearance budget, in DESIGN terms: the airframe's radius (the collision radius, 0.3 m)
//! plus a 0.5 m margin gives the safety radius (0.8 m). Heights are sensed near the ground, so
//! the estimator's 3σ vertical error (2.4 m for the GPS preset) drops out of the budget
//! wherever the rangefinder reaches.

use std::collections::VecDeque;

use nalgebra::{Isometry3, Point3, Vector2};
use scarp_slam::PinholeCamera;
use scarp_slam::image::DepthImage;
use scarp_slam::stats::median;
use serde::{Deserialize, Serialize};

/// The safety layer's settings (`[safety]` in a mission file).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SafetyConfig {
    /// Whether the monitor acts. Default true; false flies on the estimate alone.
    pub monitor: bool,
    /// A sensed surface nearer than this triggers a climb, metres. Default 0.8 (airframe radius
    /// 0.3 plus a 0.5 margin).
    pub safety_radius_m: f64,
    /// The rangefinder's range, metres. Default 40 (a lidar altimeter's: the search flies
    /// 10–20 m above the ground).
    pub rangefinder_max_range_m: f64,
    /// The rangefinder's noise σ, metres. Default 0.02.
    pub rangefinder_sigma_m: f64,
    /// Probability that a rangefinder reading is missing. Default 0.05.
    pub rangefinder_dropout_probability: f64,
    /// Readings whose median gives the vertical error. Default 15 (0.75 s at 20 Hz): a surface
    /// edge seen for less than half of it (the estimate and the truth over different sides of
    /// a rock's rim) does not move the median.
    pub median_window: usize,
    /// Fastest change of the vertical correction, m/s. Default 0.5.
    pub max_correction_rate_mps: f64,
    /// Without readings, the correction and any climb fade with this time constant, seconds.
    /// Default 20 (the GPS walk's correlation time is 30 s).
    pub fade_time_s: f64,
    /// While a surface stays inside the safety radius, the reflex grows by this much per
    /// second per metre of intrusion, on top of the intrusion itself, 1/s. Default 2. A reflex
    /// of the intrusion alone lets a steady walk of the estimate towards the surface take half
    /// of every metre it walks (library-b seed 62: the estimate walked 1.0 m in 11 s and the
    /// vehicle came 0.42 m from the block); with this integral part, a steady walk only holds
    /// an intrusion of its speed over this gain (0.05 m at 0.1 m/s), plus what the vehicle's
    /// lag lets in at the onset. 0 keeps the intrusion alone.
    pub reflex_integral_gain_per_s: f64,
    /// A collision ends the flight (`"end_reason": "crashed"`) unless this is true (the CLI's
    /// `--allow-collisions`, for debugging). Default false.
    pub allow_collisions: bool,
}

impl Default for SafetyConfig {
    fn default() -> Self {
        Self {
            monitor: true,
            safety_radius_m: 0.8,
            rangefinder_max_range_m: 40.0,
            rangefinder_sigma_m: 0.02,
            rangefinder_dropout_probability: 0.05,
            median_window: 15,
            max_correction_rate_mps: 0.5,
            fade_time_s: 20.0,
            reflex_integral_gain_per_s: 2.0,
            allow_collisions: false,
        }
    }
}

impl SafetyConfig {
    /// Checks the values.
    ///
    /// # Errors
    /// A message naming the key at fault.
    pub fn validate(&self) -> Result<(), String> {
        let positive = [
            ("safety.safety_radius_m", self.safety_radius_m),
            (
                "safety.rangefinder_max_range_m",
                self.rangefinder_max_range_m,
            ),
            (
                "safety.max_correction_rate_mps",
                self.max_correction_rate_mps,
            ),
            ("safety.fade_time_s", self.fade_time_s),
        ];
        for (key, value) in positive {
            if !(value.is_finite() && value > 0.0) {
                return Err(format!("`{key}` = {value}: must be a positive number"));
            }
        }
        if !(self.reflex_integral_gain_per_s.is_finite() && self.reflex_integral_gain_per_s >= 0.0)
        {
            return Err("`safety.reflex_integral_gain_per_s` must be ≥ 0".into());
        }
        if !(self.rangefinder_sigma_m.is_finite() && self.rangefinder_sigma_m >= 0.0) {
            return Err("`safety.rangefinder_sigma_m` must be ≥ 0".into());
        }
        if !(0.0..=1.0).contains(&self.rangefinder_dropout_probability) {
            return Err("`safety.rangefinder_dropout_probability` must lie in [0, 1]".into());
        }
        if self.median_window == 0 {
            return Err("`safety.median_window` must be ≥ 1".into());
        }
        Ok(())
    }
}

/// What the sensors report at one camera step.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Senses {
    /// The rangefinder's reading, metres (`None`: dropout or nothing in range).
    pub range_measured_m: Option<f64>,
    /// The range the terrain model predicts below the state estimate's position, metres.
    pub range_expected_m: Option<f64>,
    /// Distance from the camera to the nearest measured depth point, metres.
    pub nearest_depth_m: Option<f64>,
    /// The horizontal direction from the camera towards that point, world ENU (a unit vector;
    /// `None` where it lies nearly straight above or below, or is unknown).
    pub nearest_depth_toward_xy: Option<Vector2<f64>>,
}

/// What the monitor decided at one step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MonitorStep {
    /// Add this to the vertical error of the position the controller flies on, metres: the
    /// sensed vertical error removed, minus any climb.
    pub vertical_correction_m: f64,
    /// Add this to the horizontal error of the position the controller flies on, world ENU
    /// metres: the back-away reflex ([`SafetyMonitor::retreat_xy_m`]).
    pub retreat_xy_m: Vector2<f64>,
    /// The nearest sensed surface, metres.
    pub sensed_clearance_m: Option<f64>,
    /// An intervention began at this step (a surface came inside the safety radius).
    pub intervention_started: bool,
}

/// The monitor's state between camera steps.
#[derive(Debug, Clone)]
pub struct SafetyMonitor {
    config: SafetyConfig,
    innovations_m: VecDeque<f64>,
    /// The smoothed estimate of the vertical error to remove, metres.
    correction_m: f64,
    /// The extra climb commanded by interventions, metres (≥ 0).
    climb_m: f64,
    /// The climb when the intrusion in progress began, metres.
    climb_at_onset_m: f64,
    /// The integral part of the reflex over the intrusion in progress, metres: the gain times
    /// the intrusion, summed over time since its onset.
    reflex_integral_m: f64,
    /// The back-away commanded by interventions of the depth camera, world ENU metres, pointing
    /// towards the surface backed away from.
    retreat_xy_m: Vector2<f64>,
    /// The back-away when the intrusion in progress began.
    retreat_at_onset_xy_m: Vector2<f64>,
    previous_time_s: Option<f64>,
    last_reading_s: Option<f64>,
    intervening: bool,
    /// Interventions so far.
    pub interventions: usize,
}

impl SafetyMonitor {
    /// A monitor with no readings yet.
    pub fn new(config: &SafetyConfig) -> Self {
        Self {
            config: config.clone(),
            innovations_m: VecDeque::with_capacity(config.median_window),
            correction_m: 0.0,
            climb_m: 0.0,
            climb_at_onset_m: 0.0,
            reflex_integral_m: 0.0,
            retreat_xy_m: Vector2::zeros(),
            retreat_at_onset_xy_m: Vector2::zeros(),
            previous_time_s: None,
            last_reading_s: None,
            intervening: false,
            interventions: 0,
        }
    }

    /// Add this to the state estimate's height, metres: the sensed vertical error removed. 0
    /// when the monitor is off.
    pub fn height_correction_m(&self) -> f64 {
        if self.config.monitor {
            self.correction_m
        } else {
            0.0
        }
    }

    /// The climb the reflex commands, metres (≥ 0): subtract it from the height the controller
    /// flies on. 0 when the monitor is off.
    pub fn climb_m(&self) -> f64 {
        if self.config.monitor {
            self.climb_m
        } else {
            0.0
        }
    }

    /// The back-away the reflex commands, world ENU metres, pointing towards the surface it
    /// backs away from: add it to the horizontal position the controller flies on (the
    /// controller then believes itself that much nearer the surface, and moves off). Zero when
    /// the monitor is off.
    pub fn retreat_xy_m(&self) -> Vector2<f64> {
        if self.config.monitor {
            self.retreat_xy_m
        } else {
            Vector2::zeros()
        }
    }

    /// The correction of the controller's height in force: [`Self::height_correction_m`]
    /// minus [`Self::climb_m`].
    pub fn vertical_correction_m(&self) -> f64 {
        self.height_correction_m() - self.climb_m()
    }

    /// Takes the sensors' report at mission time `time_s` (non-decreasing) and updates the
    /// correction for the next control period.
    pub fn update(&mut self, time_s: f64, senses: &Senses) -> MonitorStep {
        let c = &self.config;
        let dt = self.previous_time_s.map_or(0.0, |t| (time_s - t).max(0.0));
        self.previous_time_s = Some(time_s);
        if let (Some(measured), Some(expected)) = (senses.range_measured_m, senses.range_expected_m)
        {
            if self.innovations_m.len() == c.median_window {
                self.innovations_m.pop_front();
            }
            self.innovations_m.push_back(measured - expected);
            self.last_reading_s = Some(time_s);
        }
        let fresh = self
            .last_reading_s
            .is_some_and(|t| time_s - t <= c.fade_time_s);
        let fade = (-dt / c.fade_time_s).exp();
        let target = if fresh {
            median(self.innovations_m.make_contiguous()).unwrap_or(0.0)
        } else {
            self.innovations_m.clear();
            self.correction_m * fade
        };
        let step = c.max_correction_rate_mps * dt;
        self.correction_m += (target - self.correction_m).clamp(-step, step);
        let sensed = [senses.range_measured_m, senses.nearest_depth_m]
            .into_iter()
            .flatten()
            .min_by(f64::total_cmp);
        let inside = sensed.is_some_and(|s| s < c.safety_radius_m);
        let intervention_started = inside && !self.intervening && c.monitor;
        if intervention_started {
            self.climb_at_onset_m = self.climb_m;
            self.retreat_at_onset_xy_m = self.retreat_xy_m;
            self.reflex_integral_m = 0.0;
        }
        match sensed {
            // Climb by the whole intrusion at once (the reflex, not the smoothing), plus its
            // integral while it lasts, and never less: the vehicle lags the command, so a
            // shrinking intrusion means the climb is working, and an intrusion that holds means
            // something (the estimate's walk) pushes back.
            Some(s) if inside => {
                let intrusion = c.safety_radius_m - s;
                self.reflex_integral_m += c.reflex_integral_gain_per_s * intrusion * dt;
                let reflex = intrusion + self.reflex_integral_m;
                self.climb_m = self.climb_m.max(self.climb_at_onset_m + reflex);
                // The same, away from the camera's nearest surface, where that is the nearest.
                if let (Some(depth), Some(toward)) =
                    (senses.nearest_depth_m, senses.nearest_depth_toward_xy)
                    && depth <= s
                {
                    let retreat = self.retreat_at_onset_xy_m + toward * reflex;
                    if retreat.norm() > self.retreat_xy_m.norm() {
                        self.retreat_xy_m = retreat;
                    }
                }
            }
            _ => {
                self.climb_m *= fade;
                self.retreat_xy_m *= fade;
            }
        }
        self.intervening = inside;
        if intervention_started {
            self.interventions += 1;
        }
        MonitorStep {
            vertical_correction_m: self.vertical_correction_m(),
            retreat_xy_m: self.retreat_xy_m(),
            sensed_clearance_m: sensed,
            intervention_started,
        }
    }
}

/// Distance from the camera centre to the nearest measured point of a depth image, metres
/// (every second pixel of every second row: a 2-pixel gap cannot hide an obstacle that could
/// touch the airframe). `None` for an image with no measurement.
pub fn nearest_depth_m(depth_m: &DepthImage, camera: &PinholeCamera) -> Option<f64> {
    nearest_depth_point(depth_m, camera).map(|p| p.coords.norm())
}

/// The nearest measured point of a depth image (as [`nearest_depth_m`]), in the camera frame
/// (x right, y down, z forward, metres). Of points at the same distance, the first in
/// row-major order.
pub fn nearest_depth_point(depth_m: &DepthImage, camera: &PinholeCamera) -> Option<Point3<f64>> {
    let (w, h) = (depth_m.width() as usize, depth_m.height() as usize);
    let values = depth_m.as_slice();
    let mut nearest: Option<(f64, Point3<f64>)> = None;
    for v in (0..h).step_by(2) {
        let y = (v as f64 - camera.cy) / camera.fy;
        for u in (0..w).step_by(2) {
            let z = f64::from(values[v * w + u]);
            // A ray is at least as long as its depth: farther depths cannot win.
            if z > 0.0 && z.is_finite() && nearest.is_none_or(|(n, _)| z < n) {
                let x = (u as f64 - camera.cx) / camera.fx;
                let distance = z * (1.0 + x * x + y * y).sqrt();
                if nearest.is_none_or(|(n, _)| distance < n) {
                    nearest = Some((distance, Point3::new(x * z, y * z, z)));
                }
            }
        }
    }
    nearest.map(|(_, p)| p)
}

/// The horizontal direction towards `world_from_camera · point_camera` from the camera, world
/// ENU (unit); `None` where the point lies within about 6° of straight above or below the
/// camera (a climb, not a back-away, is the answer there).
pub fn horizontal_direction_towards(
    world_from_camera: &Isometry3<f64>,
    point_camera: &Point3<f64>,
) -> Option<Vector2<f64>> {
    let ray = world_from_camera.rotation * point_camera.coords;
    let horizontal = ray.xy();
    (horizontal.norm() > 0.1 * ray.norm()).then(|| horizontal.normalize())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn senses(measured: f64, expected: f64) -> Senses {
        Senses {
            range_measured_m: Some(measured),
            range_expected_m: Some(expected),
            ..Senses::default()
        }
    }

    /// The estimate says 1.5 m higher than the truth: the ground reads 1.5 m nearer than the
    /// map predicts, and the correction converges to −1.5 m at its rate limit.
    #[test]
    fn a_vertical_bias_is_measured_and_removed_at_the_rate_limit() {
        let mut monitor = SafetyMonitor::new(&SafetyConfig::default());
        let mut t = 0.0;
        let first = monitor.update(t, &senses(3.0, 4.5));
        assert_eq!(first.vertical_correction_m, 0.0, "no time has passed");
        t += 1.0;
        let second = monitor.update(t, &senses(3.0, 4.5));
        assert!(
            (second.vertical_correction_m + 0.5).abs() < 1e-12,
            "{second:?}"
        );
        for _ in 0..100 {
            t += 0.05;
            monitor.update(t, &senses(3.0, 4.5));
        }
        assert!((monitor.vertical_correction_m() + 1.5).abs() < 1e-12);
        assert_eq!(monitor.interventions, 0);
    }

    /// A rock's rim under the vehicle for a few readings does not move the correction.
    #[test]
    fn a_short_surface_mismatch_does_not_move_the_median() {
        let mut monitor = SafetyMonitor::new(&SafetyConfig::default());
        let mut t = 0.0;
        for _ in 0..200 {
            t += 0.05;
            monitor.update(t, &senses(5.0, 5.2));
        }
        let settled = monitor.vertical_correction_m();
        assert!((settled + 0.2).abs() < 1e-9);
        for _ in 0..6 {
            t += 0.05;
            monitor.update(t, &senses(3.8, 5.2));
        }
        assert!((monitor.vertical_correction_m() - settled).abs() < 1e-9);
    }

    #[test]
    fn a_surface_inside_the_safety_radius_commands_a_climb_once_per_intrusion() {
        let mut monitor = SafetyMonitor::new(&SafetyConfig::default());
        let near = Senses {
            nearest_depth_m: Some(0.5),
            ..Senses::default()
        };
        let step = monitor.update(0.0, &near);
        assert!(step.intervention_started);
        assert!((step.vertical_correction_m + 0.3).abs() < 1e-12, "{step:?}");
        // Held: not re-added, only grown by the integral part (2/s × 0.3 m × 0.05 s).
        let held = monitor.update(0.05, &near);
        assert!(!held.intervention_started);
        assert!(
            (held.vertical_correction_m + 0.33).abs() < 1e-12,
            "{held:?}"
        );
        let deeper = Senses {
            nearest_depth_m: Some(0.4),
            ..Senses::default()
        };
        let integral = 0.03 + 2.0 * 0.4 * 0.01;
        assert!(
            (monitor.update(0.06, &deeper).vertical_correction_m + 0.4 + integral).abs() < 1e-12
        );
        let clear = Senses {
            nearest_depth_m: Some(3.0),
            ..Senses::default()
        };
        monitor.update(0.1, &clear);
        assert!(monitor.update(0.15, &near).intervention_started);
        assert_eq!(monitor.interventions, 2);
        // Once clear for long, the climb fades away.
        for k in 0..4000 {
            monitor.update(0.2 + 0.05 * f64::from(k), &clear);
        }
        assert!(monitor.vertical_correction_m().abs() < 1e-3);
    }

    /// A rock's side 0.5 m off in the camera's view, to the east: the reflex climbs and backs
    /// away west by the intrusion; the rangefinder's surface below only climbs.
    #[test]
    fn a_surface_seen_beside_the_vehicle_is_backed_away_from() {
        let mut monitor = SafetyMonitor::new(&SafetyConfig::default());
        let east = Vector2::new(1.0, 0.0);
        let beside = Senses {
            nearest_depth_m: Some(0.5),
            nearest_depth_toward_xy: Some(east),
            ..Senses::default()
        };
        let step = monitor.update(0.0, &beside);
        assert!(step.intervention_started);
        assert!((step.retreat_xy_m - east * 0.3).norm() < 1e-12, "{step:?}");
        assert!((step.vertical_correction_m + 0.3).abs() < 1e-12);
        // Deeper: more (and its integral, 2/s × 0.4 m × 0.05 s); shallower while it lasts:
        // kept.
        let deeper = Senses {
            nearest_depth_m: Some(0.4),
            ..beside
        };
        let deepest = east * 0.44;
        assert!((monitor.update(0.05, &deeper).retreat_xy_m - deepest).norm() < 1e-12);
        assert!((monitor.update(0.1, &beside).retreat_xy_m - deepest).norm() < 1e-12);
        // Clear for long: it fades.
        for k in 0..4000 {
            monitor.update(0.2 + 0.05 * f64::from(k), &Senses::default());
        }
        assert!(monitor.retreat_xy_m().norm() < 1e-3);

        let mut monitor = SafetyMonitor::new(&SafetyConfig::default());
        let below = Senses {
            range_measured_m: Some(0.5),
            nearest_depth_m: Some(2.0),
            nearest_depth_toward_xy: Some(east),
            ..Senses::default()
        };
        let step = monitor.update(0.0, &below);
        assert!(step.intervention_started);
        assert_eq!(step.retreat_xy_m, Vector2::zeros(), "the nearest is below");
    }

    /// Closest true approach to a wall 1.5 m east of a hovering vehicle while the estimate
    /// walks west at `walk_mps` for 20 s (the controller, holding its place in the estimate's
    /// frame, carries the truth east by as much), the depth camera reporting the wall: the
    /// real controller and airframe of the mission, the monitor in the loop as the mission
    /// runs it (the back-away added to the position the controller flies on, every 0.05 s).
    fn closest_approach_to_a_wall_m(walk_mps: f64, config: &SafetyConfig) -> f64 {
        let planning = scarp_planning::prelude::PlanningConfig::default();
        let mut motion = crate::mission::motion::MotionSystem::new(
            &planning.flight,
            Point3::new(0.0, 0.0, 10.0),
            0.0,
        )
        .unwrap();
        let wall_x_m = 1.5;
        let mut monitor = SafetyMonitor::new(config);
        let mut closest_m = f64::INFINITY;
        for k in 1..=1200 {
            let t = 0.05 * f64::from(k);
            let walk_m = walk_mps * t.min(20.0);
            let retreat = monitor.retreat_xy_m();
            let flown = nalgebra::Vector3::new(retreat.x - walk_m, retreat.y, -monitor.climb_m());
            motion.advance_to(t, &flown).unwrap();
            let distance_m = wall_x_m - motion.state().position_m.x;
            closest_m = closest_m.min(distance_m);
            monitor.update(
                t,
                &Senses {
                    nearest_depth_m: Some(distance_m),
                    nearest_depth_toward_xy: Some(Vector2::new(1.0, 0.0)),
                    ..Senses::default()
                },
            );
        }
        closest_m
    }

    /// The walk of session 55's library-b seed 62 (1 m in 11 s) and the GPS preset's 1σ walk
    /// over a second (σ 0.5 m, correlation 30 s: 0.5·√(2/30) = 0.13 m/s) keep the vehicle
    /// 0.5 m or more from the wall (the collision radius is 0.3 m, the safety radius 0.8 m);
    /// with the intrusion alone as the reflex, both come nearer (0.24 m and through the wall).
    #[test]
    fn a_walk_towards_a_wall_cannot_push_the_vehicle_through_the_reflex() {
        for walk_mps in [0.09, 0.13] {
            let closest_m = closest_approach_to_a_wall_m(walk_mps, &SafetyConfig::default());
            assert!(closest_m >= 0.5, "walk {walk_mps} m/s: {closest_m:.3} m");
            let proportional_only = SafetyConfig {
                reflex_integral_gain_per_s: 0.0,
                ..SafetyConfig::default()
            };
            let without = closest_approach_to_a_wall_m(walk_mps, &proportional_only);
            assert!(without < 0.5, "walk {walk_mps} m/s: {without:.3} m");
        }
    }

    #[test]
    fn the_direction_towards_a_point_is_horizontal_and_none_straight_down() {
        // A camera looking north, level: x right (east), y down, z forward (north).
        let rotation = nalgebra::Rotation3::from_matrix_unchecked(nalgebra::Matrix3::new(
            1.0, 0.0, 0.0, //
            0.0, 0.0, 1.0, //
            0.0, -1.0, 0.0,
        ));
        let world_from_camera = Isometry3::from_parts(
            nalgebra::Translation3::new(5.0, 5.0, 2.0),
            nalgebra::UnitQuaternion::from_rotation_matrix(&rotation),
        );
        let ahead =
            horizontal_direction_towards(&world_from_camera, &Point3::new(0.0, 0.5, 1.0)).unwrap();
        assert!((ahead - Vector2::new(0.0, 1.0)).norm() < 1e-12, "{ahead}");
        let right =
            horizontal_direction_towards(&world_from_camera, &Point3::new(2.0, 0.0, 0.0)).unwrap();
        assert!((right - Vector2::new(1.0, 0.0)).norm() < 1e-12, "{right}");
        assert_eq!(
            horizontal_direction_towards(&world_from_camera, &Point3::new(0.0, 1.0, 0.05)),
            None
        );
    }

    #[test]
    fn without_readings_the_correction_fades() {
        let mut monitor = SafetyMonitor::new(&SafetyConfig::default());
        for k in 0..200 {
            monitor.update(0.05 * f64::from(k), &senses(2.0, 3.0));
        }
        assert!((monitor.vertical_correction_m() + 1.0).abs() < 1e-9);
        for k in 0..4000 {
            monitor.update(10.0 + 0.05 * f64::from(k), &Senses::default());
        }
        assert!(monitor.vertical_correction_m().abs() < 0.05);
    }

    #[test]
    fn a_monitor_turned_off_corrects_nothing() {
        let config = SafetyConfig {
            monitor: false,
            ..SafetyConfig::default()
        };
        let mut monitor = SafetyMonitor::new(&config);
        for k in 0..100 {
            let step = monitor.update(
                0.05 * f64::from(k),
                &Senses {
                    nearest_depth_m: Some(0.1),
                    ..senses(2.0, 3.0)
                },
            );
            assert_eq!(step.vertical_correction_m, 0.0);
            assert!(!step.intervention_started);
        }
    }

    #[test]
    fn the_nearest_depth_is_the_distance_along_the_ray() {
        let camera = PinholeCamera::new(100.0, 100.0, 50.0, 40.0, 101, 81).unwrap();
        let mut depth = DepthImage::filled(101, 81, 0.0);
        assert_eq!(nearest_depth_m(&depth, &camera), None);
        *depth.get_mut(50, 40).unwrap() = 3.0;
        // 50 px off-axis at f = 100 px: the ray is √1.25 times the depth.
        *depth.get_mut(100, 40).unwrap() = 2.9;
        let nearest = nearest_depth_m(&depth, &camera).unwrap();
        assert!((nearest - 3.0).abs() < 1e-9, "{nearest}");
        *depth.get_mut(100, 40).unwrap() = 2.0;
        let nearest = nearest_depth_m(&depth, &camera).unwrap();
        assert!((nearest - 2.0 * 1.25f64.sqrt()).abs() < 1e-9, "{nearest}");
        // The point itself: half a depth to the right, level with the axis.
        let point = nearest_depth_point(&depth, &camera).unwrap();
        assert!(
            (point - Point3::new(1.0, 0.0, 2.0)).norm() < 1e-6,
            "{point}"
        );
    }

    #[test]
    fn bad_values_are_named() {
        let config = SafetyConfig {
            safety_radius_m: -1.0,
            ..SafetyConfig::default()
        };
        assert!(config.validate().unwrap_err().contains("safety_radius_m"));
    }
}
