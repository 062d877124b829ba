//! Errors of the geometry core.

use thiserror::Error;

/// An error from a geometry-core constructor or operation. Each variant names the field or
/// element at fault.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum SlamError {
    /// A camera intrinsic is not usable (zero, negative where it must be positive, or not finite).
    #[error("invalid camera intrinsic `{field}` = {value}: {reason}")]
    InvalidCamera {
        /// The intrinsic's name (`fx`, `fy`, `cx`, `cy`, `width`, `height`, `hfov_deg`).
        field: &'static str,
        /// The offending value.
        value: f64,
        /// Why it was rejected.
        reason: &'static str,
    },
    /// Two images that must share a size do not.
    #[error(
        "image size mismatch: {what} is {actual_width}×{actual_height}, expected {expected_width}×{expected_height}"
    )]
    ImageSizeMismatch {
        /// Which image has the wrong size.
        what: &'static str,
        /// Expected width in pixels.
        expected_width: u32,
        /// Expected height in pixels.
        expected_height: u32,
        /// Actual width in pixels.
        actual_width: u32,
        /// Actual height in pixels.
        actual_height: u32,
    },
    /// An image buffer whose length does not match width × height.
    #[error("image buffer holds {len} pixels, but {width}×{height} needs {expected}")]
    ImageBufferLength {
        /// Width in pixels.
        width: u32,
        /// Height in pixels.
        height: u32,
        /// Required pixel count.
        expected: usize,
        /// Actual pixel count.
        len: usize,
    },
    /// A mesh face refers to a vertex that does not exist.
    #[error("mesh face {face} refers to vertex {index}, but the mesh has {vertex_count} vertices")]
    FaceIndexOutOfRange {
        /// The face's index.
        face: usize,
        /// The offending vertex index.
        index: u32,
        /// The number of vertices.
        vertex_count: usize,
    },
    /// A per-vertex attribute array whose length differs from the vertex count.
    #[error("mesh attribute `{attribute}` has {len} entries for {vertex_count} vertices")]
    AttributeLength {
        /// The attribute (`normals` or `colors`).
        attribute: &'static str,
        /// Its length.
        len: usize,
        /// The number of vertices.
        vertex_count: usize,
    },
    /// A value that must be finite is NaN or infinite.
    #[error("{what} is not finite")]
    NotFinite {
        /// What was not finite (for example `vertex 12` or `world_from_camera`).
        what: String,
    },
    /// A geometric construction that has no unique answer (for example `look_at` with the eye on
    /// the target, or a view direction parallel to `up`).
    #[error("degenerate geometry: {0}")]
    Degenerate(String),
    /// A heightfield whose shape or values are unusable.
    #[error("terrain heightfield: {reason}")]
    InvalidHeightfield {
        /// What is wrong (names the field and value).
        reason: String,
    },
    /// A setting is out of range.
    #[error("invalid setting `{field}`: {reason}")]
    InvalidConfig {
        /// The setting.
        field: &'static str,
        /// Why it was rejected.
        reason: &'static str,
    },
}
