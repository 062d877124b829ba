//! Flight: the controller and dynamics fly the mapping rings of a 2 m rock within the issue's
//! tracking bounds, and the hover recovers from a 30° tilt.

mod common;

use nalgebra::{Point3, UnitQuaternion, Vector3};
use scarp_planning::control::Reference;
use scarp_planning::prelude::*;

fn rings_trajectory() -> (Environment, RingPlan, Trajectory) {
    let (env, points) = common::two_metre_rock();
    let cfg = PlanningConfig::default();
    let cylinder = VerticalCylinder::bounding(&points).unwrap();
    let start = Waypoint::new(Point3::new(8.0, 3.0, 5.0), 0.0);
    let rings = common::plan_rings(&cylinder, &start, &env, &cfg).unwrap();
    let traj = common::clear_trajectory_from_rest(&rings.path, &env, &cfg);
    (env, rings, traj)
}

#[test]
fn mapping_rings_of_a_two_metre_rock_are_tracked() {
    let (env, rings, traj) = rings_trajectory();
    let cfg = FlightConfig::default();
    let result = fly_trajectory(&traj, &env, &cfg).unwrap();
    let m = result.metrics;
    println!(
        "rings: {}, trajectory {:.1} s, metrics {m:?}",
        rings.rings.len(),
        traj.duration_s()
    );
    assert!(
        m.position_rms_m <= 0.10,
        "position RMS {} m",
        m.position_rms_m
    );
    assert!(
        m.position_max_m <= 0.30,
        "position max {} m",
        m.position_max_m
    );
    assert!(m.yaw_max_deg <= 5.0, "yaw max {}°", m.yaw_max_deg);
    assert!(m.speed_max_mps <= 1.1, "speed {}", m.speed_max_mps);
    let clearance = m.min_clearance_m.unwrap();
    assert!(clearance >= 1.2, "flown clearance {clearance}");
    // flight.json fields.
    let json = serde_json::to_value(m).unwrap();
    for key in [
        "position_rms_m",
        "position_max_m",
        "yaw_max_deg",
        "speed_max_mps",
        "accel_max_mps2",
        "min_clearance_m",
        "duration_s",
    ] {
        assert!(
            json.get(key).is_some_and(|v| v.is_number()),
            "{key} missing in {json}"
        );
    }
}

#[test]
fn mapping_rings_in_gusts_stay_bounded_and_are_deterministic() {
    let (env, _, traj) = rings_trajectory();
    let cfg = FlightConfig {
        wind: WindConfig {
            mean_mps: [1.0, 0.0, 0.0],
            gust_std_mps: 0.5,
            gust_time_constant_s: 2.0,
            seed: 42,
        },
        ..Default::default()
    };
    let a = fly_trajectory(&traj, &env, &cfg).unwrap();
    let b = fly_trajectory(&traj, &env, &cfg).unwrap();
    assert_eq!(a.metrics, b.metrics);
    println!("gusts: {:?}", a.metrics);
    assert!(a.metrics.position_max_m < 0.5, "{:?}", a.metrics);
}

#[test]
fn hover_recovers_from_thirty_degree_tilt() {
    let cfg = FlightConfig::default();
    let sim = Simulator::new(cfg).unwrap();
    let target = Point3::new(0.0, 0.0, 10.0);
    for axis in [
        Vector3::x_axis(),
        Vector3::y_axis(),
        nalgebra::Unit::new_normalize(Vector3::new(1.0, 1.0, 0.0)),
    ] {
        let mut s = QuadState::hover(&cfg.quad, target, 0.5);
        s.world_from_body =
            UnitQuaternion::from_axis_angle(&axis, 30f64.to_radians()) * s.world_from_body;
        let reference = Reference::hover(FlatState::hover(target, 0.5));
        let r = sim
            .run(s, 8.0, |_| reference, &Environment::empty())
            .unwrap();
        let f = r.final_state;
        let lost_m = r
            .samples
            .iter()
            .map(|x| target.z - x.position_m.z)
            .fold(0.0, f64::max);
        println!(
            "axis {axis:?}: final error {:.4} m, tilt {:.3}°, max error {:.3} m, lost {lost_m:.3} m",
            (f.position_m - target).norm(),
            f.tilt_rad().to_degrees(),
            r.metrics.position_max_m
        );
        assert!(
            (f.position_m - target).norm() < 0.05,
            "final error {}",
            (f.position_m - target).norm()
        );
        assert!(f.tilt_rad().to_degrees() < 1.0);
        assert!(f.velocity_mps.norm() < 0.05);
        assert!(r.metrics.position_max_m < 1.0);
        // Attitude is back within 2° after one second.
        let one_s = r.samples.iter().find(|x| x.time_s >= 1.0).unwrap();
        let tilt = (one_s.world_from_body * Vector3::z()).z.acos().to_degrees();
        assert!(tilt < 2.0, "tilt after 1 s: {tilt}°");
    }
}

#[test]
fn fine_localization_arc_is_flown_with_yaw_toward_the_target() {
    let (env, points) = common::two_metre_rock();
    let cfg = PlanningConfig::default();
    let current = Waypoint::new(Point3::new(-25.0, 5.0, 15.0), 0.0);
    let plan = plan_fine_localization_clear(
        &points,
        &current,
        15.0,
        &cfg.camera,
        &cfg.fine_localize,
        &env,
        &cfg.clearance,
    )
    .unwrap();
    let (traj, _, _) = plan_clear_trajectory(
        &plan.path,
        &StartState::default(),
        &cfg.min_snap,
        &env,
        &cfg.clearance,
    )
    .unwrap();
    let r = fly_trajectory(&traj, &env, &cfg.flight).unwrap();
    println!(
        "fine localization: {:.1} s, {:?}",
        traj.duration_s(),
        r.metrics
    );
    assert!(r.metrics.position_rms_m <= 0.10 && r.metrics.position_max_m <= 0.3);
    assert!(r.metrics.yaw_max_deg <= 5.0);
    // On the circle the heading points at C_e within the tracking error.
    let ce = plan.pca.centroid_m;
    let on_circle = r.samples.iter().filter(|s| {
        ((s.position_m.xy() - plan.circle_center_m.xy()).norm() - plan.radius_m).abs() < 0.05
            && s.time_s > traj.knot_times_s()[2]
    });
    for s in on_circle {
        let d = ce - s.position_m;
        let yaw = s.world_from_body * Vector3::x();
        let err = scarp_planning::geometry::wrap_angle(d.y.atan2(d.x) - yaw.y.atan2(yaw.x))
            .abs()
            .to_degrees();
        assert!(err < 5.0, "heading off C_e by {err}° at t = {}", s.time_s);
    }
}

#[test]
fn long_lawn_mower_plans_fast_and_flies() {
    let cfg = PlanningConfig::default();
    let area = SearchArea::Rectangle {
        min_x_m: 0.0,
        min_y_m: 0.0,
        max_x_m: 60.0,
        max_y_m: 600.0,
    };
    // Lanes across the long side: many short lanes, many waypoints (the sparse solver's case).
    let coverage = CoverageConfig {
        lane_heading_deg: Some(0.0),
        ..cfg.coverage
    };
    let plan = plan_lawn_mower(&area, 12.0, 0.0, &cfg.camera, &coverage).unwrap();
    assert!(plan.lanes > 30, "{} lanes", plan.lanes);
    let t0 = std::time::Instant::now();
    let traj = plan_min_snap(&plan.path, &StartState::default(), &cfg.min_snap).unwrap();
    println!(
        "lawn-mower: {} waypoints planned in {:.2} s, {:.0} s long",
        plan.path.waypoints.len(),
        t0.elapsed().as_secs_f64(),
        traj.duration_s()
    );
    let r = fly_trajectory(&traj, &Environment::empty(), &cfg.flight).unwrap();
    println!("lawn-mower flight: {:?}", r.metrics);
    assert!(r.metrics.position_max_m <= 0.3 && r.metrics.yaw_max_deg <= 5.0);
    assert!(r.metrics.min_clearance_m.is_none());
}
