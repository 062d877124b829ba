//! `scarp plan`: plan the mapping rings around a target, turn them into a minimum-snap
//! trajectory, check clearance against the terrain and rocks, and fly it in simulation.

use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use clap::Args;
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use scarp_datasets::world::World;
use scarp_export::atomic::{write_atomically, write_bytes_atomically};
use scarp_export::tum::{StampedPose, write_tum_trajectory};
use scarp_planning::plot::{PlotConfig, PlotScene, write_side_view_png, write_top_view_png};
use scarp_planning::prelude::*;
use serde::Serialize;

use scarp::mission::config::MissionConfig;
use scarp::mission::environment::planning_environment;
use scarp::mission::mapping::rock_cylinder;
use scarp_planning::camera::body_from_camera_at_pitch;

use crate::simulate::load_config;

/// Plan and fly the mapping rings around a target.
#[derive(Debug, Args)]
pub struct PlanArgs {
    /// A built-in world (`default`, `library-a`, `library-b`) or a world TOML file.
    #[arg(long, default_value = "default")]
    pub world: String,
    /// A rock id of the world, or a point `x,y,z` (world metres, z at the target's base).
    #[arg(long)]
    pub target: String,
    /// Radius of the target's bounding cylinder, metres (for a point target; a rock's comes
    /// from its mesh).
    #[arg(long, default_value_t = 1.0)]
    pub radius: f64,
    /// Height of the target's bounding cylinder, metres (for a point target).
    #[arg(long, default_value_t = 2.0)]
    pub height: f64,
    /// Output directory.
    #[arg(long)]
    pub out: PathBuf,
    /// A mission configuration (TOML, as `scarp simulate --config` takes): its `[planning]`
    /// and `[cylinder]` tables and `map_camera_rate_hz` are used; other tables are checked.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Print `flight.json` on stdout.
    #[arg(long)]
    pub json: bool,
}

/// The target cylinder named by `--target`.
fn target_cylinder(
    world: &World,
    args: &PlanArgs,
    config: &MissionConfig,
) -> anyhow::Result<VerticalCylinder> {
    if let Ok(id) = args.target.parse::<u32>() {
        let rock = world
            .rock(id)
            .with_context(|| format!("--target {id}: the world has no rock {id}"))?;
        return Ok(rock_cylinder(
            world,
            rock,
            &Vector3::zeros(),
            &config.cylinder,
        )?);
    }
    let values: Vec<f64> = args
        .target
        .split(',')
        .map(|v| v.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .with_context(|| format!("--target `{}`: expected a rock id or x,y,z", args.target))?;
    let [x, y, z] = values[..] else {
        bail!(
            "--target `{}`: expected a rock id or three numbers x,y,z",
            args.target
        );
    };
    Ok(VerticalCylinder::new(
        x,
        y,
        args.radius,
        z,
        z + args.height,
    )?)
}

/// What `flight.json` holds: the flight metrics plus the plan's size.
#[derive(Debug, Serialize)]
struct FlightReport<'a> {
    #[serde(flatten)]
    metrics: &'a FlightMetrics,
    cylinder: &'a VerticalCylinder,
    rings: usize,
    waypoints: usize,
    trajectory_duration_s: f64,
    repairs: Vec<String>,
}

fn write_csv(path: &Path, header: &str, rows: impl Iterator<Item = String>) -> anyhow::Result<()> {
    write_atomically(path, |w| {
        writeln!(w, "{header}")?;
        for row in rows {
            writeln!(w, "{row}")?;
        }
        Ok(())
    })?;
    Ok(())
}

/// `world_from_body` of a flat state: position and yaw (level body).
fn world_from_body(position: &Point3<f64>, yaw_rad: f64) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::from(position.coords),
        UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw_rad),
    )
}

/// The camera's poses along `trajectory`, one every `1 / rate_hz` seconds: the level body at
/// each sample, and the mount pitched as the mission points it while flying `rings`
/// ([`RingPlan::camera_pitch_down_deg_at`]; the mount's slew rate is not modelled).
fn camera_poses(
    trajectory: &Trajectory,
    rings: &RingPlan,
    camera: &CameraConfig,
    rate_hz: f64,
) -> Vec<StampedPose> {
    trajectory
        .sample_uniform(1.0 / rate_hz)
        .iter()
        .map(|s| {
            let pitch_deg = rings.camera_pitch_down_deg_at(s.position_m.z, camera.pitch_down_deg);
            StampedPose {
                timestamp_s: s.time_s,
                world_from_camera: world_from_body(&s.position_m, s.yaw_rad)
                    * body_from_camera_at_pitch(pitch_deg.to_radians()),
            }
        })
        .collect()
}

/// Runs `scarp plan`.
///
/// # Errors
/// World, planning (with the reason a plan was rejected) and writing errors.
pub fn run(args: PlanArgs) -> anyhow::Result<()> {
    let world = World::from_name_or_path(&args.world)
        .with_context(|| format!("loading world `{}`", args.world))?;
    let mission_config = load_config(args.config.as_ref())?;
    let cylinder = target_cylinder(&world, &args, &mission_config)?;
    let env = planning_environment(&world)?;
    let config = &mission_config.planning;
    // Start at search altitude, east of the target, facing it.
    let start_xy = (
        cylinder.center_x_m + cylinder.radius_m + 10.0,
        cylinder.center_y_m,
    );
    let start_z = world.terrain_height_m(start_xy.0, start_xy.1) + 20.0;
    let start = Waypoint::new(
        Point3::new(start_xy.0, start_xy.1, start_z),
        std::f64::consts::PI,
    );
    let rings = config
        .rings_around(&cylinder, &start, &env)
        .context("planning the mapping rings")?;
    let (trajectory, _clearance, repairs) = plan_clear_trajectory(
        &rings.path,
        &StartState::default(),
        &config.min_snap,
        &env,
        &config.clearance,
    )
    .context("planning the trajectory")?;
    let flight =
        fly_trajectory(&trajectory, &env, &config.flight).context("flying the trajectory")?;

    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    write_csv(
        &args.out.join("rings.csv"),
        "ring,center_x_m,center_y_m,z_m,radius_m,counter_clockwise,band_bottom_m,band_top_m,span_deg",
        rings.rings.iter().enumerate().map(|(i, r)| {
            format!(
                "{i},{},{},{},{},{},{},{},{}",
                r.center_x_m,
                r.center_y_m,
                r.z_m,
                r.radius_m,
                r.counter_clockwise,
                r.band_bottom_m,
                r.band_top_m,
                r.span_rad.to_degrees()
            )
        }),
    )?;
    write_csv(
        &args.out.join("waypoints.csv"),
        "x_m,y_m,z_m,yaw_rad",
        rings.path.waypoints.iter().map(|w| {
            format!(
                "{},{},{},{}",
                w.position_m.x, w.position_m.y, w.position_m.z, w.yaw_rad
            )
        }),
    )?;
    let samples = trajectory.sample_uniform(0.05);
    write_csv(
        &args.out.join("trajectory.csv"),
        "t_s,x_m,y_m,z_m,vx_mps,vy_mps,vz_mps,ax_mps2,ay_mps2,az_mps2,yaw_rad",
        samples.iter().map(|s| {
            let (p, v, a) = (s.position_m, s.velocity_mps, s.acceleration_mps2);
            format!(
                "{},{},{},{},{},{},{},{},{},{},{}",
                s.time_s, p.x, p.y, p.z, v.x, v.y, v.z, a.x, a.y, a.z, s.yaw_rad
            )
        }),
    )?;
    let poses: Vec<StampedPose> = samples
        .iter()
        .map(|s| StampedPose {
            timestamp_s: s.time_s,
            world_from_camera: world_from_body(&s.position_m, s.yaw_rad),
        })
        .collect();
    write_tum_trajectory(
        &args.out.join("trajectory.txt"),
        &poses,
        "planned world_from_body (level, yaw only), ENU metres",
    )?;
    write_tum_trajectory(
        &args.out.join("camera_trajectory.txt"),
        &camera_poses(
            &trajectory,
            &rings,
            &config.camera,
            mission_config.map_camera_rate_hz,
        ),
        "planned world_from_camera (OpenCV axes; the mount pitched as on the rings), ENU metres",
    )?;
    let scene = PlotScene {
        cylinder: Some(cylinder),
        rings: rings.rings.clone(),
        waypoints: rings.path.waypoints.iter().map(|w| w.position_m).collect(),
        trajectory: samples.iter().map(|s| s.position_m).collect(),
        flown: flight.samples.iter().map(|s| s.position_m).collect(),
    };
    let plot = PlotConfig::default();
    write_top_view_png(&args.out.join("top.png"), &scene, Some(&env), &plot)?;
    write_side_view_png(&args.out.join("side.png"), &scene, Some(&env), &plot)?;
    let report = FlightReport {
        metrics: &flight.metrics,
        cylinder: &cylinder,
        rings: rings.rings.len(),
        waypoints: rings.path.waypoints.len(),
        trajectory_duration_s: trajectory.duration_s(),
        repairs: rings
            .repairs
            .iter()
            .chain(&repairs)
            .map(|r| format!("{r:?}"))
            .collect(),
    };
    let json = serde_json::to_string_pretty(&report)?;
    write_bytes_atomically(args.out.join("flight.json"), json.as_bytes())?;
    if args.json {
        println!("{json}");
    } else {
        let m = &flight.metrics;
        eprintln!(
            "{} rings, {:.0} s flight: position error RMS {:.3} m (max {:.3} m), yaw max {:.2}°, min clearance {:?} m → {}",
            rings.rings.len(),
            m.duration_s,
            m.position_rms_m,
            m.position_max_m,
            m.yaw_max_deg,
            m.min_clearance_m,
            args.out.display()
        );
    }
    Ok(())
}
