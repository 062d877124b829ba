//! Shared fixtures for the integration tests.
#![allow(dead_code)]

use nalgebra::Point3;
use scarp_planning::prelude::*;

/// A closed ellipsoid mesh (outward faces) centred at `c` with semi-axes `r`.
pub fn ellipsoid(c: [f64; 3], r: [f64; 3], n_lat: usize, n_lon: usize) -> Obstacle {
    let mut positions_m = vec![[c[0], c[1], c[2] - r[2]]];
    for i in 1..n_lat {
        let th = std::f64::consts::PI * i as f64 / n_lat as f64;
        for j in 0..n_lon {
            let ph = std::f64::consts::TAU * j as f64 / n_lon as f64;
            positions_m.push([
                c[0] + r[0] * th.sin() * ph.cos(),
                c[1] + r[1] * th.sin() * ph.sin(),
                c[2] - r[2] * th.cos(),
            ]);
        }
    }
    positions_m.push([c[0], c[1], c[2] + r[2]]);
    let top = (positions_m.len() - 1) as u32;
    let ring = |i: usize, j: usize| (1 + (i - 1) * n_lon + j % n_lon) as u32;
    let mut faces = Vec::new();
    for j in 0..n_lon {
        faces.push([0, ring(1, j + 1), ring(1, j)]);
        faces.push([top, ring(n_lat - 1, j), ring(n_lat - 1, j + 1)]);
    }
    for i in 1..n_lat - 1 {
        for j in 0..n_lon {
            let (a, b, c2, d) = (
                ring(i, j),
                ring(i, j + 1),
                ring(i + 1, j),
                ring(i + 1, j + 1),
            );
            faces.push([a, b, d]);
            faces.push([a, d, c2]);
        }
    }
    Obstacle::Mesh { positions_m, faces }
}

/// The 2 m rock of the flight tests: an ellipsoid standing on flat ground at z = 0, its mesh
/// as an obstacle, and target points on its surface (what fine localization would return).
pub fn two_metre_rock() -> (Environment, Vec<Point3<f64>>) {
    let rock = ellipsoid([0.0, 0.0, 1.0], [0.9, 0.6, 1.0], 12, 24);
    let points = match &rock {
        Obstacle::Mesh { positions_m, .. } => positions_m
            .iter()
            .map(|p| Point3::new(p[0], p[1], p[2]))
            .collect(),
        Obstacle::Cylinder { .. } => unreachable!(),
    };
    let terrain = Heightfield::flat(-40.0, -40.0, 1.0, 81, 81, 0.0).unwrap();
    (Environment::new(Some(terrain), &[rock]).unwrap(), points)
}

/// The mapping rings of `cylinder` from `start`, planned clear of `env` with `cfg`'s camera,
/// ring and clearance settings.
pub fn plan_rings(
    cylinder: &VerticalCylinder,
    start: &Waypoint,
    env: &Environment,
    cfg: &PlanningConfig,
) -> Result<RingPlan, PlanError> {
    cfg.rings_around(cylinder, start, env)
}

/// The min-snap trajectory along `path` from rest, kept clear of `env` with `cfg`'s settings;
/// panics if it cannot be planned, and asserts it is clear.
pub fn clear_trajectory_from_rest(
    path: &Path,
    env: &Environment,
    cfg: &PlanningConfig,
) -> Trajectory {
    let (traj, report, _) = plan_clear_trajectory(
        path,
        &StartState::default(),
        &cfg.min_snap,
        env,
        &cfg.clearance,
    )
    .unwrap();
    assert!(report.is_clear(), "{report:?}");
    traj
}
