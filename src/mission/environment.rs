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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mission::config::MissionConfig;
    use crate::mission::mapping::rock_cylinder;
    use nalgebra::{Point3, Vector3};
    use scarp_planning::prelude::{Repair, Waypoint};

    /// Starts from which the straight way to the default world's rock 1 (its cylinder 0.5 m
    /// south of the truth, as a localization error puts it) is blocked, found by
    /// `examples/ring_plan_survey.rs`: the base ring used to be dropped from both. One is
    /// cleared by climbing between the rings before moving across, the other by starting the
    /// rings elsewhere round the rock.
    #[test]
    fn a_blocked_way_to_the_rings_is_rerouted_and_the_base_ring_kept() {
        let world = World::builtin_default().unwrap();
        let env = planning_environment(&world).unwrap();
        let config = MissionConfig::default();
        let rock = world.rocks.iter().find(|r| r.id == 1).unwrap();
        let south = Vector3::new(0.0, -0.5, 0.0);
        let cylinder = rock_cylinder(&world, rock, &south, &config.cylinder).unwrap();
        for (start_m, stepped, turned) in [
            ([-12.0234, 13.1438, 4.0359], true, false),
            ([-11.0284, 9.9459, 4.0607], false, true),
        ] {
            let start = Waypoint::new(Point3::from(start_m), 0.0);
            let plan = config
                .planning
                .rings_around(&cylinder, &start, &env)
                .unwrap();
            assert!(plan.flies_base_ring(), "{:?}", plan.repairs);
            assert!(plan.clearance.as_ref().unwrap().is_clear());
            let rerouted = plan.repairs.iter().find_map(|r| match r {
                Repair::Rerouted {
                    start_turned_deg,
                    stepped_transitions,
                    ..
                } => Some((*stepped_transitions, *start_turned_deg != 0.0)),
                _ => None,
            });
            assert_eq!(rerouted, Some((stepped, turned)), "{:?}", plan.repairs);
        }
    }
}
