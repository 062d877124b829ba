//! PLY (Stanford polygon file format) read and write, through `ply-rs-bw`.
//!
//! # What is read
//! - `element vertex`: `x y z` (any scalar type; `double` is rounded to f32), optional normals
//!   `nx ny nz` (or `normal_x normal_y normal_z`), optional colours `red green blue` (or
//!   `diffuse_red diffuse_green diffuse_blue`) as `uchar`, `ushort` (high byte kept) or
//!   `float`/`double` in [0, 1]. Other vertex properties (alpha, quality, …) are ignored.
//! - `element face`: one integer list property `vertex_indices` (or `vertex_index`), with any
//!   integer count and index types. Polygons with more than three corners are triangulated as
//!   a fan around their first corner. Other face properties are ignored.
//! - Any other element is parsed (so a damaged file is still caught) and ignored.
//! - Encodings: `ascii`, `binary_little_endian` and `binary_big_endian`.
//!
//! Positions are returned as stored: the frame and units are whatever the file's author used
//! (scarp writes world ENU metres unless a function says otherwise).
//!
//! # What is rejected
//! Every problem is an [`PlyError`] naming the file and the element at fault; no input makes the
//! reader panic. Rejected are: a missing or malformed header, a missing `vertex` element or
//! `x y z`, partial normal or colour triples, property types that make no sense (a list for
//! `x`, float face indices), truncated files (fewer elements than the header declares, or a
//! last ASCII line without its line break), extra values on an ASCII line, data after the last
//! element, non-finite positions or normals, faces with fewer than three corners and face
//! indices outside the vertex range. Element indices in messages count from 0.
//!
//! # What is written
//! `vertex` with `float x y z`, then `float nx ny nz` and `uchar red green blue` when the mesh
//! has them, and `face` with `list uchar int vertex_indices` (the layout MeshLab, Blender and
//! CloudCompare all read). ASCII floats are printed with the shortest digits that round-trip,
//! so ASCII and binary round trips are both bit-exact. Files are written atomically (see
//! [`crate::atomic`]).

mod read;
mod write;

use std::fmt;
use std::fs::File;
use std::io::{self, BufReader, Read, Write};
use std::path::{Path, PathBuf};

use scarp_slam::{PointCloud, SlamError, TriangleMesh};
use thiserror::Error;

use crate::atomic::{AtomicWriteError, write_atomically};

/// How a PLY payload is encoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum PlyEncoding {
    /// Human-readable text, one element per line.
    Ascii,
    /// Binary, little-endian: the compact default that every viewer reads.
    BinaryLittleEndian,
    /// Binary, big-endian (legacy; supported for completeness).
    BinaryBigEndian,
}

impl fmt::Display for PlyEncoding {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Ascii => "ascii",
            Self::BinaryLittleEndian => "binary_little_endian",
            Self::BinaryBigEndian => "binary_big_endian",
        })
    }
}

/// The plural noun for `count` elements named `element` in messages ("vertices", "faces").
fn plural(element: &str) -> String {
    match element {
        "vertex" => "vertices".to_owned(),
        "face" => "faces".to_owned(),
        other => format!("'{other}' elements"),
    }
}

/// What went wrong reading or writing a PLY file. Every variant names the file (`file` is the
/// path as given, or the source name passed to a `*_from_reader` function) and, where it
/// applies, the element (0-based) at fault.
#[derive(Debug, Error)]
pub enum PlyError {
    /// The file could not be opened.
    #[error("{}: cannot open: {source}", path.display())]
    Open {
        /// The path as given.
        path: PathBuf,
        /// The operating system's reason.
        source: io::Error,
    },
    /// Reading failed for a reason other than the end of the data.
    #[error("{file}: read error: {source}")]
    Io {
        /// The file or source name.
        file: String,
        /// The underlying error.
        source: io::Error,
    },
    /// The header is missing, malformed or incomplete.
    #[error("{file}: bad header: {message}")]
    Header {
        /// The file or source name.
        file: String,
        /// What is wrong, with the header line when known.
        message: String,
    },
    /// The header is well formed but does not describe something we can read (no vertex
    /// element, no `x`, a list where a scalar belongs, …).
    #[error("{file}: {message}")]
    Layout {
        /// The file or source name.
        file: String,
        /// What is missing or of the wrong type.
        message: String,
    },
    /// The data ends before all elements the header declares.
    #[error(
        "{file}: truncated: expected {expected} {}, read {read}{note}",
        plural(element)
    )]
    Truncated {
        /// The file or source name.
        file: String,
        /// The element being read (`vertex`, `face`, …).
        element: String,
        /// How many the header declares.
        expected: usize,
        /// How many complete ones were read.
        read: usize,
        /// Extra detail (empty, or starting with a separator).
        note: &'static str,
    },
    /// An element's data cannot be parsed.
    #[error("{file}: {element} {index}{}: {message}", line.map(|l| format!(" (line {l})")).unwrap_or_default())]
    Malformed {
        /// The file or source name.
        file: String,
        /// The element name.
        element: String,
        /// The element's index.
        index: usize,
        /// The 1-based line for ASCII files.
        line: Option<usize>,
        /// What is wrong.
        message: String,
    },
    /// A face refers to a vertex that does not exist (or to a negative index).
    #[error(
        "{file}: face {face} refers to vertex {index} but the file has {vertex_count} vertices"
    )]
    FaceIndexOutOfRange {
        /// The file or source name.
        file: String,
        /// The face's index in the file (before triangulation).
        face: usize,
        /// The offending index as stored.
        index: i64,
        /// The number of vertices the header declares.
        vertex_count: usize,
    },
    /// A face has fewer than three corners.
    #[error("{file}: face {face} has {corners} corners; a face needs at least 3")]
    DegenerateFace {
        /// The file or source name.
        file: String,
        /// The face's index in the file.
        face: usize,
        /// How many corners it lists.
        corners: usize,
    },
    /// A position or normal is NaN or infinite.
    #[error("{file}: vertex {vertex} has a non-finite {attribute} ({value:e})")]
    NotFinite {
        /// The file or source name.
        file: String,
        /// The vertex index.
        vertex: usize,
        /// `position` or `normal`.
        attribute: &'static str,
        /// The offending component.
        value: f64,
    },
    /// Non-whitespace data follows the last declared element (a sign of a wrong element count).
    #[error("{file}: {bytes} bytes of unexpected data after the last element")]
    TrailingData {
        /// The file or source name.
        file: String,
        /// How many bytes follow (whitespace included).
        bytes: usize,
    },
    /// The mesh or cloud to write is inconsistent (bad face index, attribute length, non-finite
    /// value) or too large for the PLY layout we write.
    #[error("{file}: cannot write an invalid mesh: {source}")]
    InvalidMesh {
        /// The destination.
        file: String,
        /// What is wrong with the mesh.
        source: SlamError,
    },
    /// Writing the file failed (the message names the path and the failed step).
    #[error(transparent)]
    Write(#[from] AtomicWriteError),
}

/// Reads a triangle mesh from a PLY file. A file without a `face` element gives a mesh without
/// faces.
///
/// # Errors
/// [`PlyError::Open`] if the file cannot be opened; otherwise any of the rejections listed in
/// the [module documentation](self), naming `path`.
pub fn read_mesh(path: impl AsRef<Path>) -> Result<TriangleMesh, PlyError> {
    let path = path.as_ref();
    let file = open(path)?;
    read_mesh_from_reader(file, &path.display().to_string())
}

/// Reads a triangle mesh from any byte source; `source_name` names it in error messages.
///
/// # Errors
/// As [`read_mesh`], except [`PlyError::Open`].
pub fn read_mesh_from_reader<R: Read>(
    reader: R,
    source_name: &str,
) -> Result<TriangleMesh, PlyError> {
    let data = read::read_ply(BufReader::new(reader), source_name, true)?;
    Ok(TriangleMesh {
        positions: data.positions,
        normals: data.normals,
        colors: data.colors,
        faces: data.faces,
    })
}

/// Reads the vertices of a PLY file as a point cloud (positions, and normals and colours when
/// present). Faces and other elements are parsed, so a damaged file is still an error, but
/// their content is ignored.
///
/// # Errors
/// As [`read_mesh`], except that face problems other than parse errors are not checked.
pub fn read_point_cloud(path: impl AsRef<Path>) -> Result<PointCloud, PlyError> {
    let path = path.as_ref();
    let file = open(path)?;
    read_point_cloud_from_reader(file, &path.display().to_string())
}

/// Reads a point cloud from any byte source; `source_name` names it in error messages.
///
/// # Errors
/// As [`read_point_cloud`], except [`PlyError::Open`].
pub fn read_point_cloud_from_reader<R: Read>(
    reader: R,
    source_name: &str,
) -> Result<PointCloud, PlyError> {
    let data = read::read_ply(BufReader::new(reader), source_name, false)?;
    Ok(PointCloud {
        positions: data.positions,
        normals: data.normals,
        colors: data.colors,
    })
}

/// Writes a triangle mesh to `path` atomically. Normals and colours are written when the mesh
/// has them.
///
/// # Errors
/// [`PlyError::InvalidMesh`] if [`TriangleMesh::validate`] fails, a normal is not finite or the
/// mesh has more than `i32::MAX` vertices (nothing is written then); [`PlyError::Write`] if the
/// file cannot be written.
pub fn write_mesh(
    path: impl AsRef<Path>,
    mesh: &TriangleMesh,
    encoding: PlyEncoding,
) -> Result<(), PlyError> {
    let path = path.as_ref();
    let name = path.display().to_string();
    write::check_mesh(mesh, &name)?;
    write_atomically(path, |w| {
        write::write_ply(
            w,
            &mesh.positions,
            &mesh.normals,
            &mesh.colors,
            Some(&mesh.faces),
            encoding,
        )
    })?;
    Ok(())
}

/// Writes a triangle mesh as PLY to any byte sink (for example a `Vec<u8>`).
///
/// # Errors
/// [`PlyError::InvalidMesh`] as in [`write_mesh`]; [`PlyError::Io`] (named `<writer>`) if the
/// sink fails.
pub fn write_mesh_to_writer<W: Write>(
    writer: &mut W,
    mesh: &TriangleMesh,
    encoding: PlyEncoding,
) -> Result<(), PlyError> {
    let name = "<writer>";
    write::check_mesh(mesh, name)?;
    write::write_ply(
        writer,
        &mesh.positions,
        &mesh.normals,
        &mesh.colors,
        Some(&mesh.faces),
        encoding,
    )
    .map_err(|source| PlyError::Io {
        file: name.to_owned(),
        source,
    })
}

/// Writes a point cloud (a PLY file with only a `vertex` element) to `path` atomically.
///
/// # Errors
/// [`PlyError::InvalidMesh`] if [`PointCloud::validate`] fails or a normal is not finite;
/// [`PlyError::Write`] if the file cannot be written.
pub fn write_point_cloud(
    path: impl AsRef<Path>,
    cloud: &PointCloud,
    encoding: PlyEncoding,
) -> Result<(), PlyError> {
    let path = path.as_ref();
    let name = path.display().to_string();
    write::check_cloud(cloud, &name)?;
    write_atomically(path, |w| {
        write::write_ply(
            w,
            &cloud.positions,
            &cloud.normals,
            &cloud.colors,
            None,
            encoding,
        )
    })?;
    Ok(())
}

/// Writes a point cloud as PLY to any byte sink.
///
/// # Errors
/// As [`write_point_cloud`], with [`PlyError::Io`] (named `<writer>`) if the sink fails.
pub fn write_point_cloud_to_writer<W: Write>(
    writer: &mut W,
    cloud: &PointCloud,
    encoding: PlyEncoding,
) -> Result<(), PlyError> {
    let name = "<writer>";
    write::check_cloud(cloud, name)?;
    write::write_ply(
        writer,
        &cloud.positions,
        &cloud.normals,
        &cloud.colors,
        None,
        encoding,
    )
    .map_err(|source| PlyError::Io {
        file: name.to_owned(),
        source,
    })
}

fn open(path: &Path) -> Result<File, PlyError> {
    File::open(path).map_err(|source| PlyError::Open {
        path: path.to_path_buf(),
        source,
    })
}
