//! Target localization with the bounding-box depth filter (paper §III, Algorithms 2–3, with the
//! fixes of DESIGN.md).
//!
//! Each target is a set of points in world coordinates (ENU, metres). A tracked box whose
//! back-projected cone holds no point of any target registers a new target: points are drawn in
//! the cone of the enlarged box between the near and far depth ([`points`]). A box whose cone
//! holds points of a target ([`cone`], the four inward half-spaces N·L > 0) updates that target
//! on keyframes: every point is noised, weighted by where its projection falls with respect to
//! the box and, when the frame has depth, by whether the depth leaves them possible (not in
//! the free space in front of a measured surface, not under the ground: [`free_space`]), and
//! the noised points are resampled ([`update`]). A Gaussian fit of the set gives
//! the centre, the PCA ellipsoid, λ_max, the KL divergence between successive fits and the
//! differential entropy ([`gaussian`]), which drive each target's status ([`target`]); the
//! centre reported, C_e, is the point nearest the keyframe boxes' central rays once they spread
//! enough ([`triangulation`]). The
//! [`catalog`] keeps the targets, removes false ones with hit and miss counters and merges
//! duplicates.
//!
//! ```
//! use nalgebra::Isometry3;
//! use rand::SeedableRng;
//! use scarp::detection::BoundingBox;
//! use scarp::localization::{LocalizationConfig, TargetCatalog};
//! use scarp_slam::PinholeCamera;
//!
//! let camera = PinholeCamera::from_hfov(640, 480, 80.0).unwrap();
//! let mut catalog = TargetCatalog::new(LocalizationConfig::default()).unwrap();
//! let mut rng = rand::rngs::Xoshiro256PlusPlus::seed_from_u64(7);
//! let world_from_camera = Isometry3::identity();
//! let bbox = BoundingBox::new(300.0, 220.0, 340.0, 260.0).unwrap();
//! let report = catalog
//!     .observe(&camera, &world_from_camera, &[(1, bbox)], &mut rng)
//!     .unwrap();
//! assert_eq!(report.registered.len(), 1);
//! let target = &catalog.targets()[0];
//! assert_eq!(target.points().len(), 2000);
//! // The fresh cone stretches 3–18 m ahead.
//! assert!((target.center().z - 10.5).abs() < 0.5);
//! ```

pub mod box_depth;
pub mod catalog;
pub mod cone;
pub mod config;
pub mod free_space;
pub mod gaussian;
pub mod keyframe;
pub mod points;
pub mod silhouette;
pub mod target;
#[cfg(test)]
pub(crate) mod test_scenes;
pub mod triangulation;
pub mod update;

pub use catalog::{ObserveReport, TargetCatalog};
pub use cone::BoxCone;
pub use config::LocalizationConfig;
pub use gaussian::{Ellipsoid, Gaussian3};
pub use target::{Target, TargetStatus};

use crate::detection::BoundingBox;

/// What went wrong in localization. Messages name the field, box or pose at fault.
#[derive(Debug, thiserror::Error)]
pub enum LocalizationError {
    /// A configuration field is out of range.
    #[error("localization config: `{field}` = {value}: {reason}")]
    InvalidConfig {
        /// The field name.
        field: &'static str,
        /// Its value.
        value: f64,
        /// What is wrong.
        reason: &'static str,
    },
    /// A box has a non-finite edge or no area.
    #[error("box {index} ({bbox:?}): {reason}")]
    InvalidBox {
        /// Position of the box in the input slice.
        index: usize,
        /// The box.
        bbox: BoundingBox,
        /// What is wrong.
        reason: &'static str,
    },
    /// A box does not overlap the image at all.
    #[error("box {index} ({bbox:?}) lies outside the {width}×{height} image")]
    BoxOutsideImage {
        /// Position of the box in the input slice.
        index: usize,
        /// The box.
        bbox: BoundingBox,
        /// Image width, px.
        width: u32,
        /// Image height, px.
        height: u32,
    },
    /// A pose has a NaN or infinite component.
    #[error("`{what}` is not a finite transform")]
    NonFinitePose {
        /// Which pose.
        what: &'static str,
    },
    /// The camera intrinsics are unusable.
    #[error("camera: {0}")]
    Camera(#[from] scarp_slam::SlamError),
    /// The depth image given with a frame is not the camera's size.
    #[error("the depth image is {}×{} px but the camera's image is {}×{} px", depth.0, depth.1, camera.0, camera.1)]
    DepthSize {
        /// Depth image width and height, px.
        depth: (u32, u32),
        /// Camera image width and height, px.
        camera: (u32, u32),
    },
    /// Too few or non-finite points for a Gaussian fit.
    #[error("a Gaussian fit needs at least 2 finite points, got {count}")]
    TooFewPoints {
        /// Number of points given.
        count: usize,
    },
}

/// Checks a `world_from_camera` transform for NaN or infinite components.
///
/// # Errors
/// [`LocalizationError::NonFinitePose`].
pub fn check_pose(
    world_from_camera: &nalgebra::Isometry3<f64>,
    what: &'static str,
) -> Result<(), LocalizationError> {
    scarp_slam::geometry::check_finite_isometry(world_from_camera, what)
        .map_err(|_| LocalizationError::NonFinitePose { what })
}

/// Checks that a box is usable in a `width × height` image: finite edges, positive area, and
/// some overlap with the image.
///
/// # Errors
/// [`LocalizationError::InvalidBox`] or [`LocalizationError::BoxOutsideImage`], naming `index`.
pub fn check_box(
    bbox: &BoundingBox,
    index: usize,
    width: u32,
    height: u32,
) -> Result<(), LocalizationError> {
    let finite = [bbox.x_min, bbox.y_min, bbox.x_max, bbox.y_max]
        .iter()
        .all(|v| v.is_finite());
    if !finite {
        return Err(LocalizationError::InvalidBox {
            index,
            bbox: *bbox,
            reason: "an edge is not finite",
        });
    }
    if bbox.x_min >= bbox.x_max || bbox.y_min >= bbox.y_max {
        return Err(LocalizationError::InvalidBox {
            index,
            bbox: *bbox,
            reason: "zero or negative area",
        });
    }
    let image = BoundingBox {
        x_min: -0.5,
        y_min: -0.5,
        x_max: f64::from(width) - 0.5,
        y_max: f64::from(height) - 0.5,
    };
    if bbox.intersection(&image).is_none() {
        return Err(LocalizationError::BoxOutsideImage {
            index,
            bbox: *bbox,
            width,
            height,
        });
    }
    Ok(())
}
