//! The world as the planner sees it: its terrain as a heightfield and every rock and pedestal as
//! a mesh obstacle, for planning, the clearance checks and the collision log.

use super::error::MissionResult;
use scarp_datasets::world::World;
use scarp_planning::prelude::{Environment, Obstacle};

/// The world's terrain and every rock and pedestal, as the planner sees them.
pub fn planning_environment(world: &World) -> MissionResult<Environment> {
    let terrain = world.heightfield.clone();
    let mesh_obstacle = |m: &scarp_slam::TriangleMesh| Obstacle::Mesh {
        positions_m: m
            .positions
            .iter()
            .map(|p| [f64::from(p.x), f64::from(p.y), f64::from(p.z)])
            .collect(),
        faces: m.faces.clone(),
    };
    let obstacles: Vec<Obstacle> = world_obstacles(world)
        .map(|(_, mesh)| mesh_obstacle(mesh))
        .collect();
    Ok(Environment::new(Some(terrain), &obstacles)?)
}

/// The world's obstacles in the planning environment's order (each rock, then its pedestal),
/// each with its name in reports (`rock <id>`, `pedestal <id>`): obstacle index i of
/// [`planning_environment`] is item i here.
pub fn world_obstacles(world: &World) -> impl Iterator<Item = (String, &scarp_slam::TriangleMesh)> {
    world.rocks.iter().flat_map(|r| {
        std::iter::once((format!("rock {}", r.id), &r.mesh)).chain(
            r.pedestal
                .as_ref()
                .map(|p| (format!("pedestal {}", r.id), p)),
        )
    })
}
