//! The plotting helpers write real PNGs of the rings and a flown trajectory (no fonts needed).
#![cfg(feature = "plot")]

mod common;

use nalgebra::Point3;
use scarp_planning::plot::{PlotConfig, PlotScene, write_side_view_png, write_top_view_png};
use scarp_planning::prelude::*;

#[test]
fn top_and_side_views_are_written() {
    let (env, points) = common::two_metre_rock();
    let cfg = PlanningConfig::default();
    let cylinder = VerticalCylinder::bounding(&points).unwrap();
    let start = Waypoint::new(Point3::new(8.0, 3.0, 5.0), 0.0);
    let rings = common::plan_rings(&cylinder, &start, &env, &cfg).unwrap();
    let traj = plan_min_snap(&rings.path, &StartState::default(), &cfg.min_snap).unwrap();
    let flown = fly_trajectory(&traj, &env, &cfg.flight).unwrap();
    let scene = PlotScene {
        cylinder: Some(cylinder),
        rings: rings.rings.clone(),
        waypoints: rings.path.waypoints.iter().map(|w| w.position_m).collect(),
        trajectory: traj
            .sample_uniform(0.1)
            .iter()
            .map(|s| s.position_m)
            .collect(),
        flown: flown.samples.iter().map(|s| s.position_m).collect(),
    };
    let dir = std::env::temp_dir().join(format!("scarp-planning-plot-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let plot_cfg = PlotConfig::default();
    let top = dir.join("top.png");
    let side = dir.join("side.png");
    write_top_view_png(&top, &scene, Some(&env), &plot_cfg).unwrap();
    write_side_view_png(&side, &scene, Some(&env), &plot_cfg).unwrap();
    for p in [&top, &side] {
        let bytes = std::fs::read(p).unwrap();
        assert_eq!(&bytes[1..4], b"PNG");
        assert!(
            bytes.len() > 2000,
            "{} is only {} bytes",
            p.display(),
            bytes.len()
        );
    }
    if std::env::var_os("SCARP_KEEP_PLOTS").is_none() {
        std::fs::remove_dir_all(&dir).unwrap();
    } else {
        println!("plots in {}", dir.display());
    }
}
