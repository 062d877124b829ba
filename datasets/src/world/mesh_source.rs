//! Loading rock meshes named in a world file.

use std::path::Path;

use scarp_slam::TriangleMesh;

use crate::DatasetError;
use crate::rock::subdivide_flat;

/// The scanned double rock shipped with scarp (binary PLY, 0.128 m tall, z up).
pub const DOUBLE_ROCK_PLY: &[u8] = include_bytes!("../../assets/double_rock.ply");

/// A scanned rock built into scarp, named `builtin:<name>` in world files. Every one is a
/// closed, outward-wound mesh; its units do not matter, since a world scales each rock to its
/// `height_m`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BuiltinMesh {
    /// The name after `builtin:`.
    pub name: &'static str,
    /// The binary PLY file (`datasets/assets/`).
    pub ply: &'static [u8],
    /// Levels of flat midpoint subdivision applied on loading (each multiplies the triangles
    /// by 4 without changing the surface), so a flat contact cut through a coarse
    /// decimation stays close to a plane.
    pub refine_levels: u32,
    /// What it is, its source and licence.
    pub description: &'static str,
}

/// The built-in meshes, in the order the "unknown built-in" error lists them. See
/// `datasets/assets/README.md` for sources and licences.
pub const BUILTIN_MESHES: &[BuiltinMesh] = &[
    BuiltinMesh {
        name: "double_rock",
        ply: DOUBLE_ROCK_PLY,
        refine_levels: 0,
        description: "a scanned precariously balanced rock (DREAMS-lab/pbr_gazebo, Apache-2.0); 40 276 triangles, leaning in its scanned pose",
    },
    BuiltinMesh {
        name: "stone_e22",
        ply: include_bytes!("../../assets/stones_ibois/E22.ply"),
        refine_levels: 0,
        description: "an elongated quarry stone (IBOIS EPFL, MIT); 12 530 triangles",
    },
    BuiltinMesh {
        name: "stone_073ac15d",
        ply: include_bytes!("../../assets/stones_ibois/073ac15d.ply"),
        refine_levels: 0,
        description: "a rounded quarry stone (IBOIS EPFL, MIT); 26 978 triangles",
    },
    BuiltinMesh {
        name: "stone_a0",
        ply: include_bytes!("../../assets/stones_ibois/A0_dec500.ply"),
        refine_levels: 2,
        description: "a flat slab of quarry stone, 444 × 303 × 71 (IBOIS EPFL, MIT); a 500-triangle decimation refined to 8 000",
    },
    BuiltinMesh {
        name: "stone_e34",
        ply: include_bytes!("../../assets/stones_ibois/E34_dec500.ply"),
        refine_levels: 2,
        description: "a blocky quarry stone, 301 × 193 × 155 (IBOIS EPFL, MIT); a 500-triangle decimation refined to 8 000",
    },
    BuiltinMesh {
        name: "stone_0",
        ply: include_bytes!("../../assets/stones_ibois/stone0_162v.ply"),
        refine_levels: 2,
        description: "a remeshed stone with icosphere topology (IBOIS EPFL, MIT); 320 triangles refined to 5 120",
    },
];

/// The built-in mesh called `name` (without the `builtin:` prefix), if there is one.
pub fn builtin_mesh(name: &str) -> Option<&'static BuiltinMesh> {
    BUILTIN_MESHES.iter().find(|m| m.name == name)
}

/// Loads the mesh a world file names: `builtin:<name>` for one of [`BUILTIN_MESHES`], or a
/// `.ply` / `.obj` path relative to `base_dir` (the world file's folder).
///
/// # Errors
/// [`DatasetError::Mesh`] naming the file for an unknown built-in (the message lists the known
/// ones), an unknown extension, or a file the PLY or OBJ reader rejects.
pub fn load_mesh(source: &str, base_dir: &Path) -> Result<TriangleMesh, DatasetError> {
    let mesh_error = |path: &Path, message: String| DatasetError::Mesh {
        path: path.to_path_buf(),
        message,
    };
    if let Some(name) = source.strip_prefix("builtin:") {
        let Some(builtin) = builtin_mesh(name) else {
            let known: Vec<String> = BUILTIN_MESHES
                .iter()
                .map(|m| format!("builtin:{}", m.name))
                .collect();
            return Err(mesh_error(
                Path::new(source),
                format!("unknown built-in mesh (known: {})", known.join(", ")),
            ));
        };
        let mesh = scarp_export::ply::read_mesh_from_reader(builtin.ply, source)
            .map_err(|e| mesh_error(Path::new(source), e.to_string()))?;
        return Ok(if builtin.refine_levels == 0 {
            mesh
        } else {
            subdivide_flat(&mesh, builtin.refine_levels)
        });
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
