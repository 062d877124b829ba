//! How often the mapping rings lose their base ring, and why: plans the rings around every
//! target of the built-in worlds from many vehicle positions (where a mission may be when it
//! plans or re-plans them: on the approach, after the map cylinder is re-centred) and around
//! cylinders moved as a localization error moves them, and counts the plans that fly the base
//! ring, drop it (with the reason's class), or fail.
//!
//! ```text
//! cargo run --release --example ring_plan_survey [-- WORLD...]
//! ```
//!
//! Prints one line per world and target, then the totals. The start positions are 16 azimuths
//! × 3 distances from the cylinder's surface (2, 5 and 10 m) × 3 heights above the terrain
//! under them (2.5, 6 and 12 m); the cylinders are the truth's and the truth's moved 0.5 m
//! north, east, south and west.

use std::collections::BTreeMap;

use anyhow::{Context, Result};
use nalgebra::{Point3, Vector3};
use scarp::mission::config::MissionConfig;
use scarp::mission::environment::planning_environment;
use scarp::mission::mapping::rock_cylinder;
use scarp_datasets::world::{RockRole, World};
use scarp_planning::prelude::{Repair, Waypoint};

/// The class of a plan's outcome: `flown`, `dropped: <what blocked it>` or `error`.
fn outcome(plan: &Result<scarp_planning::prelude::RingPlan, impl std::fmt::Display>) -> String {
    match plan {
        Err(_) => "error".into(),
        Ok(plan) => match plan.repairs.iter().find_map(|r| match r {
            Repair::DroppedRing { reason, .. } => Some(reason.clone()),
            _ => None,
        }) {
            None => {
                let route = plan
                    .repairs
                    .iter()
                    .find_map(|r| match r {
                        Repair::Rerouted {
                            start_turned_deg,
                            vertical_approach,
                            stepped_transitions,
                        } => Some(format!(
                            "flown, rerouted:{}{}{}",
                            if *start_turned_deg != 0.0 {
                                " turned"
                            } else {
                                ""
                            },
                            if *vertical_approach { " vertical" } else { "" },
                            if *stepped_transitions { " stepped" } else { "" },
                        )),
                        _ => None,
                    })
                    .unwrap_or_else(|| "flown".into());
                let trimmed = plan
                    .repairs
                    .iter()
                    .any(|r| matches!(r, Repair::TrimmedRing { .. }));
                if trimmed {
                    route + ", trimmed to an arc"
                } else {
                    route
                }
            }
            Some(reason) if reason.contains("over the slope") => "dropped: terrain lift".into(),
            Some(reason) if reason.contains("transition") => {
                "dropped: approach or transition".into()
            }
            Some(reason) => format!(
                "dropped: the ring itself, near {}",
                reason
                    .split_once('[')
                    .and_then(|(_, r)| r.split_once(']'))
                    .map_or("?", |(what, _)| what)
            ),
        },
    }
}

fn main() -> Result<()> {
    let names: Vec<String> = std::env::args().skip(1).collect();
    let names = if names.is_empty() {
        vec!["default".into(), "library-a".into(), "library-b".into()]
    } else {
        names
    };
    let config = MissionConfig::default();
    let planning = &config.planning;
    let mut totals: BTreeMap<String, usize> = BTreeMap::new();
    for name in &names {
        let world = World::from_name_or_path(name).with_context(|| format!("world {name}"))?;
        let env = planning_environment(&world)?;
        for rock in world.rocks.iter().filter(|r| r.role == RockRole::Target) {
            let mut counts: BTreeMap<String, usize> = BTreeMap::new();
            for (dx, dy) in [(0.0, 0.0), (0.0, 0.5), (0.5, 0.0), (0.0, -0.5), (-0.5, 0.0)] {
                let shift = Vector3::new(dx, dy, 0.0);
                let cylinder = rock_cylinder(&world, rock, &shift, &config.cylinder)?;
                for k in 0..16 {
                    let azimuth = std::f64::consts::TAU * f64::from(k) / 16.0;
                    for distance_m in [2.0, 5.0, 10.0] {
                        for height_m in [2.5, 6.0, 12.0] {
                            let r = cylinder.radius_m + distance_m;
                            let (x, y) = (
                                cylinder.center_x_m + r * azimuth.cos(),
                                cylinder.center_y_m + r * azimuth.sin(),
                            );
                            let z = world.terrain_height_m(x, y) + height_m;
                            let start =
                                Waypoint::new(Point3::new(x, y, z), azimuth + std::f64::consts::PI);
                            if env
                                .clearance_at(&start.position_m)
                                .is_some_and(|c| c.clearance_m < planning.clearance.min_clearance_m)
                            {
                                *counts
                                    .entry("start inside the clearance".into())
                                    .or_default() += 1;
                                continue;
                            }
                            let plan = planning.rings_around(&cylinder, &start, &env);
                            let class = outcome(&plan);
                            if std::env::var_os("SURVEY_CASES").is_some()
                                && class.contains("rerouted")
                            {
                                println!(
                                    "  {class}: offset ({dx}, {dy}) start {:?}",
                                    start.position_m
                                );
                            }
                            *counts.entry(class).or_default() += 1;
                        }
                    }
                }
            }
            println!("{name} rock {}: {counts:?}", rock.id);
            for (k, v) in counts {
                *totals.entry(k).or_default() += v;
            }
        }
    }
    println!("total: {totals:?}");
    Ok(())
}
