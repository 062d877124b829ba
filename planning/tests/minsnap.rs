//! Min-snap: waypoints hit exactly, continuity to snap at the knots, limits respected under
//! dense sampling, lower snap cost than a naive spline, start from the current velocity, and
//! clear errors on bad input.

use nalgebra::{Point3, Vector3};
use proptest::prelude::*;
use scarp_planning::minsnap::{Segment, solve_fixed_times};
use scarp_planning::prelude::*;

fn zigzag() -> Path {
    Path::new(vec![
        Waypoint::new(Point3::new(0.0, 0.0, 5.0), 0.0),
        Waypoint::new(Point3::new(4.0, 1.0, 5.5), 0.3),
        Waypoint::new(Point3::new(6.0, 5.0, 6.0), 1.2),
        Waypoint::new(Point3::new(2.0, 7.0, 5.0), 2.5),
        Waypoint::new(Point3::new(-3.0, 4.0, 4.0), 3.0),
        Waypoint::new(Point3::new(-1.0, 0.5, 5.0), 4.0),
    ])
}

fn assert_hits_waypoints(traj: &Trajectory, path: &Path) {
    let times = traj.waypoint_times_s();
    assert_eq!(times.len(), path.waypoints.len());
    for (t, w) in times.iter().zip(&path.waypoints) {
        let s = traj.sample(*t);
        assert!(
            (s.position_m - w.position_m).norm() < 1e-9,
            "at {t}: {} vs {}",
            s.position_m,
            w.position_m
        );
        assert!((s.yaw_rad - w.yaw_rad).abs() < 1e-9);
    }
}

/// Derivatives 0..=4 from both sides of every interior knot, evaluated on the two polynomials
/// that meet there, and by finite differences across the knot.
fn assert_continuous_to_snap(traj: &Trajectory) {
    let segs = traj.segments();
    for j in 0..segs.len() - 1 {
        for order in 0..=4 {
            let left = segs[j].derivative(1.0, order);
            let right = segs[j + 1].derivative(0.0, order);
            let scale = left.norm().max(right.norm()).max(1.0);
            assert!(
                (left - right).norm() < 1e-7 * scale,
                "knot {j}, derivative {order}: {left} vs {right}"
            );
            // Numeric: the trajectory sampled just either side of the knot.
            let t = traj.knot_times_s()[j + 1];
            let eps = 1e-7;
            let a = traj.derivative(t - eps, order);
            let b = traj.derivative(t + eps, order);
            assert!(
                (a - b).norm() < 1e-4 * scale,
                "knot {j}, derivative {order}: jump {}",
                (a - b).norm()
            );
        }
    }
}

#[test]
fn waypoints_exact_and_continuous_to_snap() {
    let path = zigzag();
    let traj = plan_min_snap(&path, &StartState::default(), &MinSnapConfig::default()).unwrap();
    assert_hits_waypoints(&traj, &path);
    assert_continuous_to_snap(&traj);
    // Ends at rest.
    let end = traj.sample(traj.duration_s());
    assert!(end.velocity_mps.norm() < 1e-9 && end.acceleration_mps2.norm() < 1e-9);
}

#[test]
fn limits_hold_under_dense_sampling() {
    let cfg = MinSnapConfig::default();
    let traj = plan_min_snap(&zigzag(), &StartState::default(), &cfg).unwrap();
    let (mut vmax, mut amax) = (0.0f64, 0.0f64);
    let n = (traj.duration_s() / 0.001) as usize;
    for k in 0..=n {
        let s = traj.sample(k as f64 * 0.001);
        vmax = vmax.max(s.velocity_mps.norm());
        amax = amax.max(s.acceleration_mps2.norm());
    }
    println!(
        "duration {:.2} s, v_max {vmax:.4}, a_max {amax:.4}",
        traj.duration_s()
    );
    assert!(vmax <= cfg.max_speed_mps, "speed {vmax}");
    assert!(amax <= cfg.max_accel_mps2, "accel {amax}");
    // Time scaling makes the tightest limit nearly active rather than leaving the plan slow.
    assert!(vmax >= 0.9 * cfg.max_speed_mps || amax >= 0.9 * cfg.max_accel_mps2);
}

/// A degree-9 spline through the same points with the same durations, whose interior
/// derivatives are guessed instead of optimised: Catmull-Rom velocities, zero higher
/// derivatives. Continuous to snap, but not minimum-snap.
fn naive_spline(path: &Path, durations: &[f64]) -> Trajectory {
    let p: Vec<Vector3<f64>> = path.waypoints.iter().map(|w| w.position_m.coords).collect();
    let n = p.len();
    let vel: Vec<Vector3<f64>> = (0..n)
        .map(|i| {
            if i == 0 || i == n - 1 {
                Vector3::zeros()
            } else {
                (p[i + 1] - p[i - 1]) / (durations[i - 1] + durations[i])
            }
        })
        .collect();
    // Coefficients from endpoint values (position, velocity; acc, jerk, snap zero) by solving
    // the 10×10 Hermite system with nalgebra.
    let a = nalgebra::SMatrix::<f64, 10, 10>::from_fn(|r, i| {
        let k = r % 5;
        let tau: f64 = if r < 5 { 0.0 } else { 1.0 };
        if i < k {
            0.0
        } else {
            let f: f64 = (0..k).map(|m| (i - m) as f64).product();
            f * tau.powi((i - k) as i32)
        }
    });
    let a_inv = a.try_inverse().unwrap();
    let segs = (0..n - 1)
        .map(|j| {
            let t = durations[j];
            let mut coeffs = [[0.0; 10]; 4];
            for d in 0..3 {
                let mut b = nalgebra::SVector::<f64, 10>::zeros();
                b[0] = p[j][d];
                b[1] = vel[j][d] * t;
                b[5] = p[j + 1][d];
                b[6] = vel[j + 1][d] * t;
                coeffs[d].copy_from_slice((a_inv * b).as_slice());
            }
            let mut b = nalgebra::SVector::<f64, 10>::zeros();
            b[0] = path.waypoints[j].yaw_rad;
            b[5] = path.waypoints[j + 1].yaw_rad;
            coeffs[3].copy_from_slice((a_inv * b).as_slice());
            Segment {
                duration_s: t,
                coeffs,
            }
        })
        .collect();
    Trajectory::from_segments(segs).unwrap()
}

#[test]
fn snap_cost_beats_a_naive_spline() {
    let path = zigzag();
    let traj = plan_min_snap(&path, &StartState::default(), &MinSnapConfig::default()).unwrap();
    // The same points: every knot of the min-snap trajectory (long legs are subdivided).
    let knots = traj.knot_path();
    let durations: Vec<f64> = traj.segments().iter().map(|s| s.duration_s).collect();
    let naive = naive_spline(&knots, &durations);
    assert_hits_waypoints(&naive, &knots);
    let (j_opt, j_naive) = (traj.snap_cost(), naive.snap_cost());
    println!("snap cost: min-snap {j_opt:.6}, naive {j_naive:.6}");
    assert!(j_opt < j_naive, "{j_opt} vs {j_naive}");
}

#[test]
fn starts_from_the_current_velocity() {
    let path = zigzag();
    let start = StartState {
        velocity_mps: Vector3::new(0.0, -0.6, 0.2),
        acceleration_mps2: Vector3::new(0.1, 0.0, 0.0),
        yaw_rate_radps: 0.2,
    };
    let cfg = MinSnapConfig::default();
    let traj = plan_min_snap(&path, &start, &cfg).unwrap();
    let s0 = traj.sample(0.0);
    assert!((s0.velocity_mps - start.velocity_mps).norm() < 1e-9);
    assert!((s0.acceleration_mps2 - start.acceleration_mps2).norm() < 1e-9);
    assert!((s0.yaw_rate_radps - 0.2).abs() < 1e-9);
    assert_hits_waypoints(&traj, &path);
    let peaks = traj.peaks(0.001);
    assert!(
        peaks.speed_mps <= cfg.max_speed_mps && peaks.accel_mps2 <= cfg.max_accel_mps2,
        "{peaks:?}"
    );
    // Too fast a start is refused.
    let fast = StartState {
        velocity_mps: Vector3::new(2.0, 0.0, 0.0),
        ..Default::default()
    };
    assert!(matches!(
        plan_min_snap(&path, &fast, &cfg),
        Err(PlanError::StartTooFast { .. })
    ));
}

#[test]
fn bad_input_gives_clear_errors() {
    let cfg = MinSnapConfig::default();
    let mut path = zigzag();
    path.waypoints[2].position_m.y = f64::NAN;
    let err = plan_min_snap(&path, &StartState::default(), &cfg).unwrap_err();
    assert!(
        err.to_string().contains("waypoints[2].position_m.y"),
        "{err}"
    );
    let mut path = zigzag();
    path.waypoints[3].yaw_rad = f64::INFINITY;
    let err = plan_min_snap(&path, &StartState::default(), &cfg).unwrap_err();
    assert!(err.to_string().contains("waypoints[3].yaw_rad"), "{err}");
    let mut path = zigzag();
    path.waypoints[2] = path.waypoints[1];
    assert_eq!(
        plan_min_snap(&path, &StartState::default(), &cfg).unwrap_err(),
        PlanError::DuplicateWaypoint { index: 1 }
    );
    let one = Path::new(vec![zigzag().waypoints[0]]);
    assert!(matches!(
        plan_min_snap(&one, &StartState::default(), &cfg),
        Err(PlanError::TooFew { .. })
    ));
    let nan_start = StartState {
        velocity_mps: Vector3::new(f64::NAN, 0.0, 0.0),
        ..Default::default()
    };
    assert!(matches!(
        plan_min_snap(&zigzag(), &nan_start, &cfg),
        Err(PlanError::NonFinite { .. })
    ));
    let zero_limit = MinSnapConfig {
        max_speed_mps: 0.0,
        ..cfg
    };
    let err = plan_min_snap(&zigzag(), &StartState::default(), &zero_limit).unwrap_err();
    assert!(err.to_string().contains("max_speed_mps"), "{err}");
    assert!(solve_fixed_times(&zigzag(), &StartState::default(), &[1.0, 1.0]).is_err());
    assert!(
        solve_fixed_times(
            &zigzag(),
            &StartState::default(),
            &[1.0, 1.0, -1.0, 1.0, 1.0]
        )
        .is_err()
    );
}

#[test]
fn yaw_only_segment_turns_in_place() {
    let path = Path::new(vec![
        Waypoint::new(Point3::new(0.0, 0.0, 5.0), 0.0),
        Waypoint::new(Point3::new(0.0, 0.0, 5.0), 1.5),
        Waypoint::new(Point3::new(3.0, 0.0, 5.0), 1.5),
    ]);
    let cfg = MinSnapConfig::default();
    let traj = plan_min_snap(&path, &StartState::default(), &cfg).unwrap();
    assert_hits_waypoints(&traj, &path);
    assert!(traj.peaks(0.001).yaw_rate_radps <= cfg.max_yaw_rate_radps);
}

fn waypoint_strategy() -> impl Strategy<Value = Vec<(f64, f64, f64, f64)>> {
    prop::collection::vec(
        (-20.0..20.0f64, -20.0..20.0f64, 1.0..15.0f64, -3.0..3.0f64),
        2..9,
    )
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 32, ..ProptestConfig::default() })]

    #[test]
    fn random_paths_hit_waypoints_and_respect_limits(raw in waypoint_strategy()) {
        let mut wps: Vec<Waypoint> = Vec::new();
        for (x, y, z, yaw) in raw {
            let w = Waypoint::new(Point3::new(x, y, z), yaw);
            if wps.last().is_none_or(|l| (l.position_m - w.position_m).norm() > 0.5) {
                wps.push(w);
            }
        }
        prop_assume!(wps.len() >= 2);
        let path = Path::new(wps);
        let cfg = MinSnapConfig::default();
        let traj = plan_min_snap(&path, &StartState::default(), &cfg).unwrap();
        assert_hits_waypoints(&traj, &path);
        assert_continuous_to_snap(&traj);
        let p = traj.peaks(0.002);
        prop_assert!(p.speed_mps <= cfg.max_speed_mps, "speed {}", p.speed_mps);
        prop_assert!(p.accel_mps2 <= cfg.max_accel_mps2, "accel {}", p.accel_mps2);
        prop_assert!(p.yaw_rate_radps <= cfg.max_yaw_rate_radps, "yaw rate {}", p.yaw_rate_radps);
    }
}
