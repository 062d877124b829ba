//! The scene the tracker's tests fly: a 1°-a-frame orbit of the default world's first target.

use nalgebra::Isometry3;
use scarp_datasets::paths::default_orbit;
use scarp_datasets::world::World;
use scarp_slam::PinholeCamera;
use scarp_slam::tsdf::Roi;

/// The default world, a 320×240 camera, the orbit's stamped true poses (timestamp seconds,
/// `world_from_camera`), and a region of interest 3 m around the target.
pub struct OrbitScene {
    pub world: World,
    pub camera: PinholeCamera,
    pub poses: Vec<(f64, Isometry3<f64>)>,
    pub roi: Roi,
}

pub fn orbit_scene() -> OrbitScene {
    let world = World::builtin_default().unwrap();
    let camera = PinholeCamera::from_hfov(320, 240, 80.0).unwrap();
    let poses = default_orbit(&world, 360)
        .unwrap()
        .iter()
        .map(|p| (p.timestamp_s, p.world_from_camera))
        .collect();
    let target = world.targets().next().unwrap().centroid;
    let roi = Roi::Cylinder {
        center_xy: [target.x, target.y],
        z_min: target.z - 3.0,
        z_max: target.z + 3.0,
        radius_m: 3.0,
    };
    OrbitScene {
        world,
        camera,
        poses,
        roi,
    }
}
