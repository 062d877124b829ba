//! `scarp render`: render a camera path through a world into a TUM RGB-D sequence.

use std::path::PathBuf;

use anyhow::Context;
use clap::{Args, ValueEnum};
use nalgebra::{Isometry3, Point3, Vector3};
use scarp_datasets::paths;
use scarp_datasets::sequence::{RenderSettings, SequenceSummary, write_sequence};
use scarp_datasets::world::World;
use scarp_export::tum::StampedPose;
use scarp_planning::camera::CameraConfig;
use scarp_planning::finelocalize::{FineLocalizeConfig, plan_fine_localization, view_direction};
use scarp_planning::geometry::Waypoint;
use scarp_slam::PinholeCamera;
use scarp_slam::geometry::look_at;

/// Render a sequence (RGB, depth, instance masks, true and estimated poses, boxes).
#[derive(Debug, Args)]
pub struct RenderArgs {
    /// A built-in world (`default`, `library-a`, `library-b`) or a world TOML file.
    #[arg(long, default_value = "default")]
    pub world: String,
    /// `orbit` (4 m around the first target, 2 m above it), `lawnmower` (sweep at `--altitude`
    /// over the whole terrain, or over an `--area-m` square around `--target` when given),
    /// `finecircle` (the paper's fine-localization circle around `--target` at the search
    /// altitude, camera pitched 55° down at the target's centroid, 25 waypoints over 720°), a
    /// `+`-joined list of those (`lawnmower+finecircle`), or a TUM trajectory file of
    /// `world_from_camera` poses.
    #[arg(long, default_value = "orbit")]
    pub path: String,
    /// Number of frames of each path in the list (ignored for a trajectory file, which sets its
    /// own).
    #[arg(long, default_value_t = 120)]
    pub frames: usize,
    /// Target rock id for `finecircle` and for a local `lawnmower` (default: the first target
    /// for `finecircle`; none for `lawnmower`, which then sweeps the whole terrain).
    #[arg(long)]
    pub target: Option<u32>,
    /// Search altitude above the terrain's mean height, m (lawn-mower and fine-localization
    /// circle). Default 10, the mission's search height (`search_height_agl_m`): at 20 m the
    /// fine-localization circle sees its rock from 24 m, beyond the depth filter's 18 m.
    #[arg(long, default_value_t = 10.0)]
    pub altitude: f64,
    /// Side of the square swept by a `lawnmower` around `--target`, m.
    #[arg(long, default_value_t = 30.0)]
    pub area_m: f64,
    /// Output sequence directory.
    #[arg(long)]
    pub out: PathBuf,
    /// Seed of the sensor and estimator noise.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Clean images, and an estimate equal to the ground truth.
    #[arg(long)]
    pub no_noise: bool,
    /// A mission configuration (TOML, as `scarp simulate --config` takes): its `[sensor]` and
    /// `[estimator]` tables set the camera's noise and the pose estimate's error (for example
    /// `[estimator]` with `preset = "rtk"`). Other tables are checked and not used.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Depth PNG units per metre; default 5000 (TUM) for orbits and files, 1000 for lawn-mower
    /// sweeps, whose depths exceed 13 m.
    #[arg(long)]
    pub depth_scale: Option<f64>,
    /// Print a JSON summary on stdout.
    #[arg(long)]
    pub json: bool,
}

/// Which kind of path.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
enum PathKind {
    Orbit,
    Lawnmower,
    FineCircle,
    File,
}

/// The default camera: 640×480, 80° horizontal field of view.
pub fn default_camera() -> PinholeCamera {
    // Constant, valid intrinsics.
    PinholeCamera::from_hfov(640, 480, 80.0).expect("valid default camera")
}

/// Renders a sequence as the arguments say; shared by `render` and `simulate`.
///
/// # Errors
/// World, path and writing errors, naming the file or key.
pub fn render_sequence(args: &RenderArgs) -> anyhow::Result<SequenceSummary> {
    let world = World::from_name_or_path(&args.world)
        .with_context(|| format!("loading world `{}`", args.world))?;
    let camera = default_camera();
    let mut kinds = Vec::new();
    let mut poses: Vec<StampedPose> = Vec::new();
    for name in args.path.split('+') {
        let (kind, mut piece) = match name {
            "orbit" => (PathKind::Orbit, paths::default_orbit(&world, args.frames)?),
            "lawnmower" => (PathKind::Lawnmower, lawnmower_path(&world, &camera, args)?),
            "finecircle" => {
                let current = poses.last().map(|p| p.world_from_camera);
                (
                    PathKind::FineCircle,
                    fine_circle_path(&world, args, current.as_ref())?,
                )
            }
            file => {
                anyhow::ensure!(
                    args.path == name,
                    "a trajectory file cannot be joined with other paths (`{}`)",
                    args.path
                );
                (
                    PathKind::File,
                    paths::from_tum_file(std::path::Path::new(file))?,
                )
            }
        };
        // Joined paths continue the frame clock.
        let offset_s = poses
            .last()
            .map_or(0.0, |p| p.timestamp_s + 1.0 / paths::FRAME_RATE_HZ);
        for p in &mut piece {
            p.timestamp_s += offset_s;
        }
        kinds.push(kind);
        poses.extend(piece);
    }
    let far = kinds
        .iter()
        .any(|k| matches!(k, PathKind::Lawnmower | PathKind::FineCircle));
    let depth_scale = args
        .depth_scale
        .unwrap_or(if far { 1000.0 } else { 5000.0 });
    anyhow::ensure!(
        depth_scale > 0.0 && depth_scale.is_finite(),
        "--depth-scale must be positive"
    );
    let config = super::simulate::load_config(args.config.as_ref())?;
    let settings = RenderSettings {
        camera,
        noise: !args.no_noise,
        sensor: config.sensor,
        estimator: config.estimator,
        seed: args.seed,
        depth_scale,
    };
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    let bar = super::progress_bar(poses.len() as u64, "rendering");
    let summary = write_sequence(&args.out, &world, &poses, &settings, &|| bar.inc(1))?;
    bar.finish_and_clear();
    Ok(summary)
}

/// The lawn-mower sweep: over the whole terrain, or over an `--area-m` square centred on
/// `--target`'s centroid.
fn lawnmower_path(
    world: &World,
    camera: &PinholeCamera,
    args: &RenderArgs,
) -> anyhow::Result<Vec<StampedPose>> {
    let Some(id) = args.target else {
        return Ok(paths::lawnmower(
            world,
            args.altitude,
            camera.hfov_deg(),
            args.frames,
        )?);
    };
    let rock = world
        .rock(id)
        .with_context(|| format!("--target {id}: no rock with that id in the world"))?;
    anyhow::ensure!(
        args.area_m > 0.0 && args.area_m.is_finite(),
        "--area-m must be positive"
    );
    let h = 0.5 * args.area_m;
    let c = rock.centroid;
    let area = (c.x - h, c.y - h, c.x + h, c.y + h);
    Ok(paths::lawnmower_in(
        world,
        area,
        args.altitude,
        camera.hfov_deg(),
        args.frames,
    )?)
}

/// The paper's fine-localization circle (§III, Motion Planning) around `--target` (default the
/// first target), planned by [`scarp_planning::finelocalize::plan_fine_localization`] from the
/// rock's true vertices at the search altitude (terrain mean + `--altitude`), starting from
/// `current` (the end of the previous path) or from the circle's east point. `--frames` poses
/// are spread evenly over the arc (720°); the camera is pitched γ down toward the centre C_e.
fn fine_circle_path(
    world: &World,
    args: &RenderArgs,
    current: Option<&Isometry3<f64>>,
) -> anyhow::Result<Vec<StampedPose>> {
    anyhow::ensure!(args.frames > 0, "--frames must be positive");
    let rock = match args.target {
        Some(id) => world
            .rock(id)
            .with_context(|| format!("--target {id}: no rock with that id in the world"))?,
        None => world
            .targets()
            .next()
            .context("finecircle: the world has no target")?,
    };
    let points: Vec<Point3<f64>> = rock.mesh.positions.iter().map(|p| p.cast()).collect();
    let search_altitude_m = paths::mean_terrain_height_m(world) + args.altitude;
    let cam_cfg = CameraConfig::default();
    let start = match current {
        Some(pose) => {
            // Heading of the camera's optical axis projected on the ground.
            let axis = pose.rotation * Vector3::z();
            Waypoint::new(Point3::from(pose.translation.vector), axis.y.atan2(axis.x))
        }
        None => {
            let radius = (search_altitude_m - rock.centroid.z) / cam_cfg.pitch_down_rad().tan();
            Waypoint::new(
                Point3::new(rock.centroid.x + radius, rock.centroid.y, search_altitude_m),
                std::f64::consts::PI,
            )
        }
    };
    let plan = plan_fine_localization(
        &points,
        &start,
        search_altitude_m,
        &cam_cfg,
        &FineLocalizeConfig::default(),
    )
    .with_context(|| format!("planning the fine-localization circle of rock {}", rock.id))?;
    // The arc: the last `waypoints` of the path (the first may be the current pose).
    let arc = &plan.path.waypoints;
    let arc = &arc[arc
        .len()
        .saturating_sub(FineLocalizeConfig::default().waypoints + 1)..];
    let arc: Vec<&Waypoint> = arc
        .iter()
        .filter(|w| {
            ((w.position_m.xy() - plan.circle_center_m.xy()).norm() - plan.radius_m).abs() < 1e-6
        })
        .collect();
    anyhow::ensure!(arc.len() >= 2, "the fine-localization arc is empty");
    let (yaw0, yaw1) = (arc[0].yaw_rad, arc[arc.len() - 1].yaw_rad);
    let pitch = cam_cfg.pitch_down_rad();
    let centre = plan.circle_center_m;
    let poses = (0..args.frames)
        .map(|k| {
            let s = if args.frames > 1 {
                k as f64 / (args.frames - 1) as f64
            } else {
                0.0
            };
            // Yaw points at the centre: the azimuth of the eye is yaw + π.
            let yaw = yaw0 + (yaw1 - yaw0) * s;
            let azimuth = yaw + std::f64::consts::PI;
            let eye = Point3::new(
                centre.x + plan.radius_m * azimuth.cos(),
                centre.y + plan.radius_m * azimuth.sin(),
                centre.z,
            );
            let forward = view_direction(azimuth, pitch);
            look_at(&eye, &(eye + forward), &Vector3::z()).map(|world_from_camera| StampedPose {
                timestamp_s: k as f64 / paths::FRAME_RATE_HZ,
                world_from_camera,
            })
        })
        .collect::<Result<Vec<_>, _>>()?;
    Ok(poses)
}

/// Runs `scarp render`.
///
/// # Errors
/// As [`render_sequence`].
pub fn run(args: RenderArgs) -> anyhow::Result<()> {
    let summary = render_sequence(&args)?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&summary)?);
    } else {
        eprintln!(
            "wrote {} frames ({} boxes) to {} in {:.1} s ({:.0} frames/s)",
            summary.frames,
            summary.boxes,
            args.out.display(),
            summary.seconds,
            summary.frames as f64 / summary.seconds.max(1e-9)
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn args(path: &str) -> RenderArgs {
        RenderArgs {
            world: "default".into(),
            path: path.into(),
            frames: 30,
            target: Some(1),
            altitude: 10.0,
            area_m: 30.0,
            out: PathBuf::from("unused"),
            seed: 0,
            no_noise: true,
            config: None,
            depth_scale: None,
            json: false,
        }
    }

    #[test]
    fn fine_circle_looks_at_the_target_from_the_search_altitude() {
        let world = World::builtin_default().unwrap();
        let rock = world.rock(1).unwrap();
        let poses = fine_circle_path(&world, &args("finecircle"), None).unwrap();
        assert_eq!(poses.len(), 30);
        // C_e: the mean of the points given to the planner (the rock's vertices).
        let ce = rock
            .mesh
            .positions
            .iter()
            .fold(Vector3::zeros(), |acc, p| acc + p.coords.cast::<f64>())
            / rock.mesh.positions.len() as f64;
        let h_s = paths::mean_terrain_height_m(&world) + 10.0;
        let radius = (h_s - ce.z) / 55f64.to_radians().tan();
        let mut turned = 0.0;
        for w in poses.windows(2) {
            let (a, b) = (&w[0].world_from_camera, &w[1].world_from_camera);
            let (pa, pb) = (a.translation.vector, b.translation.vector);
            turned += (pa.xy() - ce.xy()).angle(&(pb.xy() - ce.xy()));
        }
        for p in &poses {
            let eye = p.world_from_camera.translation.vector;
            assert!((eye.z - h_s).abs() < 1e-9);
            assert!(((eye.xy() - ce.xy()).norm() - radius).abs() < 1e-6);
            // The optical axis passes through C_e, pitched 55° down.
            let axis = p.world_from_camera.rotation * Vector3::z();
            assert!((axis.z + 55f64.to_radians().sin()).abs() < 1e-9);
            let to_rock = (ce - eye).normalize();
            assert!(axis.dot(&to_rock) > 1.0 - 1e-9);
        }
        // Two full turns.
        assert!(
            (turned.to_degrees() - 720.0).abs() < 1.0,
            "{}",
            turned.to_degrees()
        );
    }

    #[test]
    fn unknown_target_is_an_error() {
        let world = World::builtin_default().unwrap();
        let mut a = args("finecircle");
        a.target = Some(999);
        let err = fine_circle_path(&world, &a, None).unwrap_err();
        assert!(err.to_string().contains("999"), "{err}");
    }
}
