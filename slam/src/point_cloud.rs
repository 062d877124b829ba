//! Point clouds.

use nalgebra::{Isometry3, Point3, Vector3};

use crate::SlamError;

/// A set of 3D points with optional per-point normals and colours. The frame of the positions is
/// the owner's to state (world ENU metres unless a function says otherwise).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PointCloud {
    /// Positions in metres.
    pub positions: Vec<Point3<f32>>,
    /// Unit normals, empty or one per point.
    pub normals: Vec<Vector3<f32>>,
    /// 8-bit sRGB colours, empty or one per point.
    pub colors: Vec<[u8; 3]>,
}

impl PointCloud {
    /// A cloud of bare positions.
    pub fn from_positions(positions: Vec<Point3<f32>>) -> Self {
        Self {
            positions,
            ..Self::default()
        }
    }

    /// Number of points.
    pub fn len(&self) -> usize {
        self.positions.len()
    }

    /// Whether the cloud has no points.
    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }

    /// Checks that attribute arrays are empty or one per point, and that positions are finite.
    ///
    /// # Errors
    /// [`SlamError::AttributeLength`] or [`SlamError::NotFinite`].
    pub fn validate(&self) -> Result<(), SlamError> {
        crate::mesh::check_attributes(&self.positions, &self.normals, &self.colors)
    }

    /// Applies a rigid transform to positions and normals. If the positions are in frame A,
    /// pass `b_from_a` to obtain them in frame B.
    pub fn transform(&mut self, b_from_a: &Isometry3<f64>) {
        crate::mesh::transform_points(&mut self.positions, &mut self.normals, b_from_a);
    }
}
