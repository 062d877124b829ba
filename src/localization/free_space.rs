//! The depth image's evidence in the point update (ours, not the paper's): a rock's centroid
//! lies inside the rock, so it is never in the free space in front of a measured surface, nor
//! under the ground at the rock's foot, nor on the line of sight to a pixel that shows ground
//! (a surface within [`GROUND_BAND_M`] of the floor): that ray meets no rock before the ground,
//! and behind the ground lies only more ground.
//!
//! Why: the box alone leaves every point of the enlarged cones' intersection equally likely.
//! From the fine-localization circle, which looks 55° down, that intersection reaches about a
//! metre above and below the rock: over 44 targets (session 35) the point set's vertical 1σ was
//! 0.43–0.56 m whatever the rock, and 8 of the 12 centres more than 0.5 m off missed on the
//! vertical alone. The depth camera already measures where the rock's surface is and where the
//! ground is; points in front of the surface or under the ground are carved away, and the set
//! shrinks to the rock and what no view could see into.
//!
//! The evidence only scales weights down (by [`FreeSpace::ruled_out_weight`], never to zero),
//! so a depth hole, a moving estimate frame or a box on the wrong rock cannot leave an update
//! without weight.

use nalgebra::{Isometry3, Point2, Point3};
use scarp_slam::PinholeCamera;
use scarp_slam::image::DepthImage;

use super::LocalizationConfig;
use super::box_depth::pixel_ranges_in_box;
use crate::detection::BoundingBox;

/// The quantile of the heights of a box's depth points taken as the ground at the rock's foot:
/// low enough to be ground, high enough to skip a stray low pixel.
const FLOOR_QUANTILE: f64 = 0.05;

/// Height above the floor within which a measured surface counts as ground, m. The same band
/// tells the object from the ground when the map's centre is taken from a box
/// ([`super::silhouette::center_in_box`]).
pub const GROUND_BAND_M: f64 = 0.25;

/// Pixel step of the grid of depth samples for the floor.
const FLOOR_STEP_PX: usize = 4;

/// Fewest depth samples in a box for a floor.
const FLOOR_MIN_SAMPLES: usize = 20;

/// The free space and the floor that one depth frame shows around one box.
#[derive(Debug, Clone)]
pub struct FreeSpace<'a> {
    camera: &'a PinholeCamera,
    depth_m: &'a DepthImage,
    world_from_camera: Isometry3<f64>,
    camera_from_world: Isometry3<f64>,
    floor_z_m: Option<f64>,
    rock_floor_z_m: Option<f64>,
    margin_m: f64,
    margin_per_m: f64,
    ruled_out_weight: f64,
}

impl<'a> FreeSpace<'a> {
    /// The evidence of `depth_m` (metres along the camera's z axis, 0 where nothing was
    /// measured; the same size as `camera`'s image) taken at `world_from_camera` (world ENU,
    /// metres), for points that project near the tracked box `bbox` (px), with `config`'s
    /// `free_space_*` tolerances and box enlargement.
    ///
    /// The floor is the 5% quantile of the heights of the depth points inside the enlarged box;
    /// the rock's floor, that of the points inside `bbox` itself that are higher than the floor
    /// by more than [`GROUND_BAND_M`] (each needs 20 samples). A point counts as ruled out when
    /// it lies more than `free_space_margin_m + free_space_margin_per_m · d²` in front of the
    /// depth `d` measured where it projects (the depth noise of a stereo camera grows as d²),
    /// when that measured surface is ground (within [`GROUND_BAND_M`] of the floor), or when
    /// it lies more than `free_space_margin_m` below the rock's floor (the floor without one).
    /// Ruled-out points keep `free_space_weight` of their box weight.
    pub fn new(
        camera: &'a PinholeCamera,
        depth_m: &'a DepthImage,
        world_from_camera: &Isometry3<f64>,
        bbox: &BoundingBox,
        config: &LocalizationConfig,
    ) -> Self {
        let (floor_z_m, rock_floor_z_m) = floors_z_m(
            camera,
            depth_m,
            world_from_camera,
            bbox,
            &bbox.enlarged(config.box_enlargement_px),
        );
        Self {
            camera,
            depth_m,
            world_from_camera: *world_from_camera,
            camera_from_world: world_from_camera.inverse(),
            floor_z_m,
            rock_floor_z_m,
            margin_m: config.free_space_margin_m,
            margin_per_m: config.free_space_margin_per_m,
            ruled_out_weight: config.free_space_weight,
        }
    }

    /// The height of the ground at the rock's foot, world z in metres, if the box held enough
    /// depth.
    pub fn floor_z_m(&self) -> Option<f64> {
        self.floor_z_m
    }

    /// The height of the lowest part of the rock the box shows, world z in metres, if the box
    /// held enough depth above the ground.
    pub fn rock_floor_z_m(&self) -> Option<f64> {
        self.rock_floor_z_m
    }

    /// The weight factor a point ruled out keeps.
    pub fn ruled_out_weight(&self) -> f64 {
        self.ruled_out_weight
    }

    /// The factor for a point at `world` (world ENU, metres) that projects to `pixel`: 1, or
    /// [`Self::ruled_out_weight`] when the depth puts it under the floor, in free space, or on
    /// the line of sight to ground. Points that project where nothing was measured are ruled
    /// out by the floor alone.
    pub fn factor(&self, world: &Point3<f64>, pixel: &Point2<f64>) -> f64 {
        if self
            .rock_floor_z_m
            .or(self.floor_z_m)
            .is_some_and(|floor| world.z < floor - self.margin_m)
        {
            return self.ruled_out_weight;
        }
        if pixel.x < -0.5 || pixel.y < -0.5 {
            return 1.0;
        }
        let (u, v) = (pixel.x.round(), pixel.y.round());
        let Some(measured_m) = self
            .depth_m
            .get(u as u32, v as u32)
            .map(|&d| f64::from(d))
            .filter(|d| *d > 0.0 && d.is_finite())
        else {
            return 1.0;
        };
        let in_front_m = measured_m - (self.camera_from_world * world).z;
        let free = in_front_m > self.margin_m + self.margin_per_m * measured_m * measured_m;
        let surface =
            self.world_from_camera * self.camera.unproject(&Point2::new(u, v), measured_m);
        let ground = self
            .floor_z_m
            .is_some_and(|floor| surface.z < floor + GROUND_BAND_M);
        if free || ground {
            self.ruled_out_weight
        } else {
            1.0
        }
    }
}

/// The floor and the rock's floor (see [`FreeSpace::new`]), world z in metres, from the depth
/// points inside `enlarged` and `bbox`, sampled every 4 px.
pub fn floors_z_m(
    camera: &PinholeCamera,
    depth_m: &DepthImage,
    world_from_camera: &Isometry3<f64>,
    bbox: &BoundingBox,
    enlarged: &BoundingBox,
) -> (Option<f64>, Option<f64>) {
    let (columns, rows) = pixel_ranges_in_box(depth_m, enlarged);
    // (height, whether the sample lies inside the tracked box)
    let mut samples = Vec::new();
    for v in rows.step_by(FLOOR_STEP_PX) {
        for u in columns.clone().step_by(FLOOR_STEP_PX) {
            if let Some(&d) = depth_m.get(u, v)
                && d > 0.0
                && d.is_finite()
            {
                let pixel = Point2::new(f64::from(u), f64::from(v));
                let p = camera.unproject(&pixel, f64::from(d));
                let inside = pixel.x >= bbox.x_min
                    && pixel.x <= bbox.x_max
                    && pixel.y >= bbox.y_min
                    && pixel.y <= bbox.y_max;
                samples.push(((world_from_camera * p).z, inside));
            }
        }
    }
    let quantile = |mut heights: Vec<f64>| {
        (heights.len() >= FLOOR_MIN_SAMPLES)
            .then(|| scarp_slam::stats::quantile_in_place(&mut heights, FLOOR_QUANTILE))
            .flatten()
    };
    let floor = quantile(samples.iter().map(|s| s.0).collect());
    let rock_floor = floor.and_then(|floor| {
        quantile(
            samples
                .iter()
                .filter(|(z, inside)| *inside && *z >= floor + GROUND_BAND_M)
                .map(|s| s.0)
                .collect(),
        )
    });
    (floor, rock_floor)
}

#[cfg(test)]
mod tests {
    use super::*;
    use scarp_slam::geometry::look_at;

    /// A camera 10 m above flat ground at z = 0, looking straight down, whose depth image sees a
    /// 2 m box-shaped rock top (z = 2) in the middle third of the image and ground elsewhere.
    fn scene() -> (PinholeCamera, Isometry3<f64>, DepthImage) {
        let camera = PinholeCamera::from_hfov(120, 90, 80.0).unwrap();
        let world_from_camera = look_at(
            &Point3::new(0.0, 0.0, 10.0),
            &Point3::origin(),
            &nalgebra::Vector3::y(),
        )
        .unwrap();
        let mut depth = DepthImage::filled(120, 90, 0.0);
        for v in 0..90 {
            for u in 0..120 {
                let rock = (40..80).contains(&u) && (30..60).contains(&v);
                *depth.get_mut(u, v).unwrap() = if rock { 8.0 } else { 10.0 };
            }
        }
        (camera, world_from_camera, depth)
    }

    /// The whole image, as the tracked box with no enlargement.
    fn whole() -> BoundingBox {
        BoundingBox::new(0.0, 0.0, 119.0, 89.0).unwrap()
    }

    fn config(free_space_margin_per_m: f64) -> LocalizationConfig {
        LocalizationConfig {
            box_enlargement_px: 0.0,
            free_space_weight: 0.05,
            free_space_margin_m: 0.2,
            free_space_margin_per_m,
            ..Default::default()
        }
    }

    #[test]
    fn free_space_and_underground_points_are_ruled_out_and_the_rest_kept() {
        let (camera, pose, depth) = scene();
        let evidence = FreeSpace::new(&camera, &depth, &pose, &whole(), &config(0.0));
        let floor = evidence.floor_z_m().unwrap();
        assert!(floor.abs() < 1e-6, "floor {floor}");
        // The box holds the rock's top alone: no part of it is lower.
        let rock_floor = evidence.rock_floor_z_m().unwrap();
        assert!((rock_floor - 2.0).abs() < 1e-6, "rock floor {rock_floor}");
        let project = |p: Point3<f64>| camera.project(&(pose.inverse() * p)).unwrap();
        let at = |p: Point3<f64>| evidence.factor(&p, &project(p));
        // Inside the rock, within the margin below the lowest part the box shows: kept.
        assert_eq!(at(Point3::new(0.0, 0.0, 1.9)), 1.0);
        // Lower, where a pedestal would stand: ruled out.
        assert_eq!(at(Point3::new(0.0, 0.0, 1.0)), 0.05);
        // Just above the rock's top, within the margin: kept.
        assert_eq!(at(Point3::new(0.0, 0.0, 2.1)), 1.0);
        // A metre above the rock: free space.
        assert_eq!(at(Point3::new(0.0, 0.0, 3.0)), 0.05);
        // Beside the rock, a metre above the ground: free space too.
        assert_eq!(at(Point3::new(5.0, 0.0, 1.0)), 0.05);
        // Beside the rock, on the ground: its pixel shows ground, so no rock lies on its ray.
        assert_eq!(at(Point3::new(5.0, 0.0, 0.05)), 0.05);
        // Under the ground, wherever it projects.
        assert_eq!(at(Point3::new(0.0, 0.0, -0.5)), 0.05);
    }

    #[test]
    fn holes_and_the_noise_margin_keep_points() {
        let (camera, pose, mut depth) = scene();
        let above_rock = Point3::new(0.0, 0.0, 3.0);
        let pixel = camera.project(&(pose.inverse() * above_rock)).unwrap();
        // A margin growing as d² (0.02 · 8² = 1.28 m) covers the metre above the rock.
        let noisy = FreeSpace::new(&camera, &depth, &pose, &whole(), &config(0.02));
        assert_eq!(noisy.factor(&above_rock, &pixel), 1.0);
        // No measurement where it projects: nothing says it is free.
        *depth
            .get_mut(pixel.x.round() as u32, pixel.y.round() as u32)
            .unwrap() = 0.0;
        let holed = FreeSpace::new(&camera, &depth, &pose, &whole(), &config(0.0));
        assert_eq!(holed.factor(&above_rock, &pixel), 1.0);
        // An empty depth frame: no floor and no free space.
        let empty = DepthImage::filled(120, 90, 0.0);
        let blind = FreeSpace::new(&camera, &empty, &pose, &whole(), &config(0.0));
        assert!(blind.floor_z_m().is_none() && blind.rock_floor_z_m().is_none());
        assert_eq!(blind.factor(&Point3::new(0.0, 0.0, -3.0), &pixel), 1.0);
    }
}
