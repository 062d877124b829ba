//! Loading rock meshes named in a world file.

use std::path::Path;

use scarp_slam::TriangleMesh;

use crate::DatasetError;

/// The scanned double rock shipped with scarp (binary PLY, 0.128 m tall, z up).
pub const DOUBLE_ROCK_PLY: &[u8] = include_bytes!("../../assets/double_rock.ply");

/// Loads the mesh a world file names: `builtin:double_rock`, or a `.ply` / `.obj` path
/// relative to `base_dir` (the world file's folder).
///
/// # Errors
/// [`DatasetError::Mesh`] naming the file for an unknown built-in, an unknown extension, or a
/// file the PLY or OBJ reader rejects.
pub fn load_mesh(source: &str, base_dir: &Path) -> Result<TriangleMesh, DatasetError> {
    let mesh_error = |path: &Path, message: String| DatasetError::Mesh {
        path: path.to_path_buf(),
        message,
    };
    if let Some(name) = source.strip_prefix("builtin:") {
        return match name {
            "double_rock" => scarp_export::ply::read_mesh_from_reader(DOUBLE_ROCK_PLY, source)
                .map_err(|e| mesh_error(Path::new(source), e.to_string())),
            _ => Err(mesh_error(
                Path::new(source),
                "unknown built-in mesh (known: builtin:double_rock)".into(),
            )),
        };
    }
    let path = base_dir.join(source);
    let extension = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    match extension.as_deref() {
        Some("ply") => {
            scarp_export::ply::read_mesh(&path).map_err(|e| mesh_error(&path, e.to_string()))
        }
        Some("obj") => {
            scarp_export::obj::read_obj(&path).map_err(|e| mesh_error(&path, e.to_string()))
        }
        _ => Err(mesh_error(
            &path,
            "unknown mesh format (expected .ply or .obj)".into(),
        )),
    }
}
