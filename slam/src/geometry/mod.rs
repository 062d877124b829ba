//! Cameras and rigid transforms.

mod camera;
mod floor;
mod heightfield;
mod pca;
mod polygon;
mod transform;
mod triangle;
mod volume;

pub use camera::PinholeCamera;
pub use floor::{floor_i32, floor_i64};
pub use heightfield::Heightfield;
pub use pca::{eigenpairs_ascending, mean_and_scatter};
pub use polygon::{convex_hull_2d, polygon_centroid, polygon_signed_area};
pub use transform::{
    check_finite_isometry, isometry_from_tum, look_at, quaternion_from_xyzw, renormalized,
    rotation_angle_deg, tum_from_isometry, yaw_pitch_roll_from_rotation,
};
pub use triangle::closest_point_on_triangle;
pub use volume::{TetrahedronSums, tetrahedron_sums};
