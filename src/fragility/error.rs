//! Errors of the fragility analysis.

use scarp_slam::SlamError;
use thiserror::Error;

/// An error from [`analyze`](super::analyze) or one of its steps. Each variant names the mesh,
/// field, edge or height at fault; none of them is raised by a panic.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum FragilityError {
    /// The mesh failed the geometry core's checks (a face index out of range, a per-vertex
    /// attribute of the wrong length, or a NaN/infinite vertex).
    #[error("{mesh} mesh is invalid: {source}")]
    InvalidMesh {
        /// Which mesh (`rock` or `pedestal`).
        mesh: &'static str,
        /// What the geometry core reported.
        source: SlamError,
    },
    /// The mesh has no faces (or none left after dropping faces that repeat a vertex).
    #[error("{mesh} mesh is empty: it has no usable faces")]
    EmptyMesh {
        /// Which mesh (`rock` or `pedestal`).
        mesh: &'static str,
    },
    /// An edge belongs to only one face: the surface has a hole and encloses no volume.
    #[error(
        "{mesh} mesh is open: {count} boundary edge(s), for example vertices {a}–{b} at {position:?} m; \
         the analysis needs a closed (watertight) surface"
    )]
    OpenMesh {
        /// Which mesh (`rock` or `pedestal`).
        mesh: &'static str,
        /// Number of boundary edges.
        count: usize,
        /// First vertex of an example boundary edge (input index).
        a: u32,
        /// Second vertex of that edge (input index).
        b: u32,
        /// Position of vertex `a`, metres, input frame.
        position: [f32; 3],
    },
    /// An edge is shared by more than two faces.
    #[error(
        "{mesh} mesh is non-manifold: {count} edge(s) shared by more than two faces, for example \
         vertices {a}–{b} at {position:?} m"
    )]
    NonManifold {
        /// Which mesh (`rock` or `pedestal`).
        mesh: &'static str,
        /// Number of such edges.
        count: usize,
        /// First vertex of an example edge (input index).
        a: u32,
        /// Second vertex of that edge (input index).
        b: u32,
        /// Position of vertex `a`, metres, input frame.
        position: [f32; 3],
    },
    /// Two faces that share an edge traverse it in the same direction, so their normals
    /// disagree.
    #[error(
        "{mesh} mesh has inconsistent winding: {count} edge(s) traversed twice in the same \
         direction, for example vertices {a}–{b} at {position:?} m"
    )]
    InconsistentWinding {
        /// Which mesh (`rock` or `pedestal`).
        mesh: &'static str,
        /// Number of such edges.
        count: usize,
        /// First vertex of an example edge (input index).
        a: u32,
        /// Second vertex of that edge (input index).
        b: u32,
        /// Position of vertex `a`, metres, input frame.
        position: [f32; 3],
    },
    /// The geometry has no usable extent: it encloses (numerically) no volume, the contact
    /// section is empty, or similar. The message says which.
    #[error("degenerate geometry: {0}")]
    Degenerate(String),
    /// A configuration value or argument is out of range.
    #[error("invalid fragility setting `{field}` = {value}: {reason}")]
    InvalidConfig {
        /// The field or argument name (for example `density_kg_m3` or `up`).
        field: &'static str,
        /// The offending value, formatted.
        value: String,
        /// Why it was rejected.
        reason: &'static str,
    },
    /// The requested contact height does not cut the rock.
    #[error(
        "contact height {contact_height_m} m is outside the rock, which spans {z_min_m}..{z_max_m} m along up"
    )]
    ContactOutsideRock {
        /// The requested contact height, metres along up.
        contact_height_m: f64,
        /// Lowest point of the mesh, metres along up.
        z_min_m: f64,
        /// Highest point of the mesh, metres along up.
        z_max_m: f64,
    },
    /// The pedestal does not support the rock.
    #[error("pedestal does not support the rock: {0}")]
    NoPedestalContact(String),
    /// The centre of mass lies outside the contact polygon, so the rock as given would not
    /// stand (often a wrong `up` direction or contact).
    #[error(
        "centre of mass lies {distance_m:.4} m outside the contact polygon (towards azimuth \
         {azimuth_deg:.1}°): the rock would not stand; check the up direction and the contact"
    )]
    ComOutsideContact {
        /// Horizontal distance from the centre of mass to the contact polygon, metres.
        distance_m: f64,
        /// Azimuth in which the rock would fall, degrees counter-clockwise from levelled +x.
        azimuth_deg: f64,
    },
    /// A section of the mesh did not form closed loops (the mesh is not a closed 2-manifold
    /// near that height).
    #[error("section at height {height_m} m does not close: {reason}")]
    OpenSection {
        /// Height of the section plane, metres along up.
        height_m: f64,
        /// What went wrong.
        reason: &'static str,
    },
    /// Writing the figure failed.
    #[error("figure {path}: {reason}")]
    Figure {
        /// The output path.
        path: String,
        /// What went wrong.
        reason: String,
    },
}
