//! Benchmarks: min-snap solving (with time allocation and scaling), simulated flight speed and
//! clearance queries over a 200 m × 200 m, 0.5 m terrain grid.
//!
//! Run with `cargo bench -p scarp-planning --bench planning`. The flight benchmark also prints
//! the real-time factor (simulated seconds per wall-clock second); the mission budget is ≥ 10×.

use std::hint::black_box;
use std::time::Instant;

use criterion::{Criterion, criterion_group, criterion_main};
use nalgebra::Point3;
use scarp_planning::minsnap::{initial_durations, solve_fixed_times};
use scarp_planning::prelude::*;

/// Rings around a 12 m pillar (several rings, 16 waypoints each) and a flat world.
fn pillar_rings() -> (Environment, Path) {
    let cfg = PlanningConfig::default();
    let cyl = VerticalCylinder::new(0.0, 0.0, 1.5, 0.0, 12.0).expect("valid cylinder");
    let start = Waypoint::new(Point3::new(10.0, 0.0, 8.0), 0.0);
    let plan = plan_mapping_rings(&cyl, &start, &cfg.camera, &cfg.mapping).expect("rings");
    let terrain = Heightfield::flat(-50.0, -50.0, 1.0, 101, 101, 0.0).expect("terrain");
    (
        Environment::new(Some(terrain), &[]).expect("env"),
        plan.path,
    )
}

fn bench_min_snap(c: &mut Criterion) {
    let (_, path) = pillar_rings();
    let cfg = MinSnapConfig::default();
    let n = path.waypoints.len();
    c.bench_function(&format!("min_snap/plan_{n}_waypoints"), |b| {
        b.iter(|| plan_min_snap(black_box(&path), &StartState::default(), &cfg).expect("plan"))
    });
    let durations = initial_durations(&path, &cfg);
    c.bench_function(&format!("min_snap/solve_fixed_times_{n}_waypoints"), |b| {
        b.iter(|| {
            solve_fixed_times(black_box(&path), &StartState::default(), &durations).expect("solve")
        })
    });
}

fn bench_flight(c: &mut Criterion) {
    let (env, path) = pillar_rings();
    let cfg = PlanningConfig::default();
    let traj = plan_min_snap(&path, &StartState::default(), &cfg.min_snap).expect("plan");
    let sim = Simulator::new(cfg.flight).expect("sim");
    let t0 = Instant::now();
    let r = sim.fly(&traj, &env).expect("flight");
    let wall = t0.elapsed().as_secs_f64();
    eprintln!(
        "flight: {:.1} s simulated in {:.3} s wall = {:.0}× real time; RMS {:.4} m, max {:.4} m, yaw max {:.3}°",
        r.metrics.duration_s,
        wall,
        r.metrics.duration_s / wall,
        r.metrics.position_rms_m,
        r.metrics.position_max_m,
        r.metrics.yaw_max_deg
    );
    let mut group = c.benchmark_group("flight");
    group.sample_size(10);
    group.bench_function(format!("fly_{:.0}s_of_rings", traj.duration_s()), |b| {
        b.iter(|| sim.fly(black_box(&traj), &env).expect("flight"))
    });
    group.finish();
}

/// One clearance query per point of a 20 × 20 grid at `height_agl_m` over rolling terrain.
fn bench_clearance(c: &mut Criterion) {
    let terrain = Heightfield::from_fn(-100.0, -100.0, 0.5, 401, 401, |x, y| {
        3.0 * (0.05 * x).sin() * (0.04 * y).cos() + 0.02 * x
    })
    .expect("terrain");
    let env = Environment::new(Some(terrain.clone()), &[]).expect("env");
    let mut group = c.benchmark_group("clearance");
    for height_agl_m in [1.0, 10.0, 25.0] {
        let points: Vec<Point3<f64>> = (0..400)
            .map(|k| {
                let (x, y) = (-90.0 + 9.0 * (k % 20) as f64, -90.0 + 9.0 * (k / 20) as f64);
                Point3::new(
                    x,
                    y,
                    terrain.height_at(x, y).expect("on grid") + height_agl_m,
                )
            })
            .collect();
        group.bench_function(format!("400_points_{height_agl_m:.0}m_agl"), |b| {
            b.iter(|| {
                points
                    .iter()
                    .filter_map(|p| env.clearance_at(black_box(p)))
                    .map(|s| s.clearance_m)
                    .sum::<f64>()
            })
        });
    }
    group.finish();
}

criterion_group!(benches, bench_min_snap, bench_flight, bench_clearance);
criterion_main!(benches);
