//! glTF 2.0 binary (`.glb`) scenes of rock meshes: a writer for Blender, MeshLab and web
//! viewers, and a validating reader.
//!
//! # Frames
//! scarp's world is ENU (x east, y north, z up, metres); glTF is y-up (x right, y up, z towards
//! the viewer, metres). On export every position and normal goes through the proper rotation
//! `(x, y, z)_ENU → (x, z, −y)_glTF` (x→x, z→y, y→−z, determinant +1, so triangle winding and
//! outward normals are kept), and the reader applies the inverse, so the rock stands upright in
//! Blender and a round trip is exact. See [`enu_to_gltf`] and [`gltf_to_enu`].
//!
//! # What is written
//! One mesh and one named node per [`GlbNode`], all in one scene:
//! - `POSITION` (float VEC3, with the `min`/`max` bounds the specification requires),
//! - `NORMAL` when the mesh has normals (float VEC3, re-normalised; normals that cannot be
//!   normalised are replaced by area-weighted face normals),
//! - `COLOR_0` when the mesh has colours (float VEC3, linear: the sRGB bytes are decoded, as
//!   glTF requires),
//! - `u32` triangle indices,
//! - a PBR metallic-roughness material (roughness 0.9, metallic 0 by default; white base colour
//!   times the vertex colours, or a neutral rock grey for meshes without colours),
//! - the node's `extras` (any JSON: rock id, fragility, …) and the scene's `extras`.
//!
//! Every buffer view starts on a 4-byte boundary and the chunks are padded as the GLB container
//! requires. Files are written atomically (see [`crate::atomic`]).
//!
//! # What is read
//! [`read_glb`] checks the container (magic, version, declared and chunk lengths), parses and
//! validates the JSON with the `gltf` crate, then checks every accessor it reads against its
//! buffer view and buffer (bounds, alignment, stride, component types), the `POSITION` bounds
//! and the index range, before it returns meshes in ENU. Node transforms (the whole scene
//! hierarchy) are applied. Truncated or corrupt files are errors that name the file; no input
//! makes it panic.
//!
//! ```
//! use nalgebra::Point3;
//! use scarp_export::glb::{GlbNode, GlbOptions, glb_to_vec, read_glb_from_slice};
//! use scarp_slam::TriangleMesh;
//!
//! let rock = TriangleMesh::new(
//!     vec![Point3::new(0.0, 0.0, 0.0), Point3::new(1.0, 0.0, 0.0), Point3::new(0.0, 0.0, 2.0)],
//!     vec![[0, 1, 2]],
//! )
//! .unwrap();
//! let node = GlbNode::new("rock-7", &rock).with_extras(serde_json::json!({"rock_id": 7}));
//! let bytes = glb_to_vec(&[node], &GlbOptions::default()).unwrap();
//! let back = read_glb_from_slice(&bytes, "rock.glb").unwrap();
//! assert_eq!(back.nodes[0].mesh.positions, rock.positions); // ENU again, exactly
//! assert_eq!(back.nodes[0].extras.as_ref().unwrap()["rock_id"], 7);
//! ```

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use gltf_json::validation::{Checked, USize64};
use gltf_json::{self as json, Index};
use nalgebra::{Matrix3, Matrix4, Point3, Vector3, Vector4};
use scarp_slam::{SlamError, TriangleMesh};
use serde_json::Value;
use thiserror::Error;

use crate::atomic::{AtomicWriteError, write_bytes_atomically};

/// What went wrong writing or reading a GLB file. Reading errors name the file (the path, or
/// the source name given to [`read_glb_from_slice`]).
#[derive(Debug, Error)]
pub enum GlbError {
    /// The file could not be opened or read.
    #[error("{}: cannot read: {source}", path.display())]
    Open {
        /// The path as given.
        path: PathBuf,
        /// The operating system's reason.
        source: std::io::Error,
    },
    /// The data does not start with the GLB magic `glTF`.
    #[error("{file}: not a GLB file (it starts with {found:?}, not \"glTF\")")]
    NotGlb {
        /// The file or source name.
        file: String,
        /// The first bytes found.
        found: Vec<u8>,
    },
    /// The data ends before the length its header or a chunk header declares.
    #[error("{file}: truncated: {what} needs {expected_bytes} bytes, the file has {actual_bytes}")]
    Truncated {
        /// The file or source name.
        file: String,
        /// What was being read (`the GLB header`, `the JSON chunk`, …).
        what: &'static str,
        /// Bytes needed.
        expected_bytes: usize,
        /// Bytes present.
        actual_bytes: usize,
    },
    /// The container or the data it holds is inconsistent.
    #[error("{file}: corrupt: {message}")]
    Corrupt {
        /// The file or source name.
        file: String,
        /// What is wrong.
        message: String,
    },
    /// A valid glTF feature this reader does not handle (external buffers, sparse accessors,
    /// points or lines, …).
    #[error("{file}: unsupported: {message}")]
    Unsupported {
        /// The file or source name.
        file: String,
        /// Which feature.
        message: String,
    },
    /// The JSON chunk is not valid glTF (as the `gltf` crate parses and validates it).
    #[error("{file}: invalid glTF: {message}")]
    Gltf {
        /// The file or source name.
        file: String,
        /// The `gltf` crate's message.
        message: String,
    },
    /// A mesh to write is inconsistent (bad face index, attribute length, non-finite position).
    #[error("mesh '{name}': {source}")]
    InvalidMesh {
        /// The node's name.
        name: String,
        /// What is wrong.
        source: SlamError,
    },
    /// A mesh to write has no triangles (glTF accessors cannot be empty).
    #[error("mesh '{name}' has no triangles")]
    EmptyMesh {
        /// The node's name.
        name: String,
    },
    /// The scene does not fit the GLB container (4 GiB) or JSON encoding failed.
    #[error("cannot encode the GLB: {message}")]
    Encode {
        /// What failed.
        message: String,
    },
    /// Writing the file failed (the message names the path and the failed step).
    #[error(transparent)]
    Write(#[from] AtomicWriteError),
}

/// Converts an ENU vector (x east, y north, z up) to glTF's y-up axes: `(x, z, −y)`.
pub fn enu_to_gltf(v: &Vector3<f32>) -> [f32; 3] {
    [v.x, v.z, -v.y]
}

/// Converts a glTF y-up vector back to ENU: `(x, −z, y)`. Inverse of [`enu_to_gltf`].
pub fn gltf_to_enu(v: [f32; 3]) -> Vector3<f32> {
    Vector3::new(v[0], -v[2], v[1])
}

/// The sRGB transfer function, inverted: an 8-bit sRGB value to linear [0, 1].
pub fn srgb_to_linear(value: u8) -> f32 {
    let c = f64::from(value) / 255.0;
    let linear = if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    };
    linear as f32
}

/// The sRGB transfer function: linear [0, 1] (clamped; NaN gives 0) to the nearest 8-bit sRGB
/// value. `linear_to_srgb(srgb_to_linear(v)) == v` for every byte.
pub fn linear_to_srgb(linear: f32) -> u8 {
    let l = f64::from(linear);
    let l = if l.is_nan() { 0.0 } else { l.clamp(0.0, 1.0) };
    let s = if l <= 0.003_130_8 {
        12.92 * l
    } else {
        1.055 * l.powf(1.0 / 2.4) - 0.055
    };
    // In [0, 255] after the clamp; `as` saturates anyway.
    (s * 255.0).round() as u8
}

/// One named mesh instance to export.
#[derive(Debug, Clone)]
pub struct GlbNode<'a> {
    /// Node and mesh name shown in Blender's outliner (for example the rock id).
    pub name: String,
    /// The mesh, in world ENU metres.
    pub mesh: &'a TriangleMesh,
    /// Metadata stored as the node's `extras` (Blender shows it as custom properties);
    /// `Value::Null` writes none.
    pub extras: Value,
}

impl<'a> GlbNode<'a> {
    /// A node without extras.
    pub fn new(name: impl Into<String>, mesh: &'a TriangleMesh) -> Self {
        Self {
            name: name.into(),
            mesh,
            extras: Value::Null,
        }
    }

    /// The same node with `extras` as metadata.
    pub fn with_extras(mut self, extras: Value) -> Self {
        self.extras = extras;
        self
    }
}

/// Scene-wide export settings.
#[derive(Debug, Clone, PartialEq)]
pub struct GlbOptions {
    /// PBR roughness of the rock material, [0, 1]. Default 0.9 (matte stone).
    pub roughness: f32,
    /// PBR metalness, [0, 1]. Default 0.
    pub metallic: f32,
    /// Render both faces of each triangle. Default true: a mapped rock is often open where it
    /// sits on its pedestal.
    pub double_sided: bool,
    /// The scene's name. Default `"scarp"`.
    pub scene_name: String,
    /// Metadata stored as the scene's `extras`; `Value::Null` writes none.
    pub scene_extras: Value,
}

impl Default for GlbOptions {
    fn default() -> Self {
        Self {
            roughness: 0.9,
            metallic: 0.0,
            double_sided: true,
            scene_name: "scarp".to_owned(),
            scene_extras: Value::Null,
        }
    }
}

/// Base colour of meshes without vertex colours: a neutral sandstone grey (linear RGBA).
const UNCOLOURED_BASE: [f32; 4] = [0.45, 0.42, 0.38, 1.0];

fn to_extras(value: &Value) -> Result<json::Extras, GlbError> {
    if value.is_null() {
        return Ok(None);
    }
    serde_json::value::to_raw_value(value)
        .map(Some)
        .map_err(|e| GlbError::Encode {
            message: format!("extras: {e}"),
        })
}

/// Accumulates the binary chunk and the JSON objects that describe it.
struct Builder {
    root: json::Root,
    bin: Vec<u8>,
}

impl Builder {
    /// Appends `bytes` as a new buffer view starting on a 4-byte boundary.
    fn view(&mut self, bytes: &[u8], target: json::buffer::Target) -> Index<json::buffer::View> {
        while !self.bin.len().is_multiple_of(4) {
            self.bin.push(0);
        }
        let offset = self.bin.len();
        self.bin.extend_from_slice(bytes);
        self.root.push(json::buffer::View {
            buffer: Index::new(0),
            byte_length: USize64::from(bytes.len()),
            byte_offset: Some(USize64::from(offset)),
            byte_stride: None,
            name: None,
            target: Some(Checked::Valid(target)),
            extensions: None,
            extras: None,
        })
    }

    fn accessor(
        &mut self,
        view: Index<json::buffer::View>,
        count: usize,
        component: json::accessor::ComponentType,
        type_: json::accessor::Type,
        bounds: Option<(Value, Value)>,
    ) -> Index<json::Accessor> {
        let (min, max) = bounds.map_or((None, None), |(a, b)| (Some(a), Some(b)));
        self.root.push(json::Accessor {
            buffer_view: Some(view),
            byte_offset: None,
            count: USize64::from(count),
            component_type: Checked::Valid(json::accessor::GenericComponentType(component)),
            extensions: None,
            extras: None,
            type_: Checked::Valid(type_),
            min,
            max,
            name: None,
            normalized: false,
            sparse: None,
        })
    }

    fn vec3_f32(&mut self, values: &[[f32; 3]], with_bounds: bool) -> Index<json::Accessor> {
        let mut bytes = Vec::with_capacity(values.len() * 12);
        let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
        for v in values {
            for k in 0..3 {
                bytes.extend_from_slice(&v[k].to_le_bytes());
                lo[k] = lo[k].min(v[k]);
                hi[k] = hi[k].max(v[k]);
            }
        }
        let view = self.view(&bytes, json::buffer::Target::ArrayBuffer);
        let bounds = with_bounds.then(|| {
            let to_json =
                |a: [f32; 3]| Value::from(a.iter().map(|&c| f64::from(c)).collect::<Vec<_>>());
            (to_json(lo), to_json(hi))
        });
        self.accessor(
            view,
            values.len(),
            json::accessor::ComponentType::F32,
            json::accessor::Type::Vec3,
            bounds,
        )
    }
}

/// Unit normals in ENU for export: re-normalised, with face normals where a stored normal is
/// zero or not finite.
fn export_normals(mesh: &TriangleMesh) -> Vec<Vector3<f32>> {
    let mut fallback: Option<Vec<Vector3<f32>>> = None;
    let mut normals = Vec::with_capacity(mesh.normals.len());
    for (i, n) in mesh.normals.iter().enumerate() {
        let unit = n
            .cast::<f64>()
            .try_normalize(1e-12)
            .filter(|u| u.iter().all(|c| c.is_finite()));
        normals.push(match unit {
            Some(u) => u.cast(),
            None => {
                let computed = fallback.get_or_insert_with(|| {
                    let mut m = TriangleMesh {
                        positions: mesh.positions.clone(),
                        faces: mesh.faces.clone(),
                        ..TriangleMesh::default()
                    };
                    m.compute_vertex_normals();
                    m.normals
                });
                computed[i]
            }
        });
    }
    normals
}

/// Encodes nodes as a GLB file in memory.
///
/// # Errors
/// [`GlbError::InvalidMesh`] if a mesh fails [`TriangleMesh::validate`];
/// [`GlbError::EmptyMesh`] for a mesh without triangles; [`GlbError::Encode`] if the scene
/// exceeds the 4 GiB GLB limit.
pub fn glb_to_vec(nodes: &[GlbNode<'_>], options: &GlbOptions) -> Result<Vec<u8>, GlbError> {
    let mut b = Builder {
        root: json::Root::default(),
        bin: Vec::new(),
    };
    b.root.asset = json::Asset {
        generator: Some(concat!("scarp-export ", env!("CARGO_PKG_VERSION")).to_owned()),
        extras: to_extras(&serde_json::json!({
            "scarp_frame": "world ENU metres exported y-up: glTF (x, y, z) = (east, up, -north)"
        }))?,
        ..json::Asset::default()
    };
    let mut material_for = BTreeMap::<bool, Index<json::Material>>::new();
    let mut node_indices = Vec::with_capacity(nodes.len());

    for node in nodes {
        let mesh = node.mesh;
        mesh.validate().map_err(|source| GlbError::InvalidMesh {
            name: node.name.clone(),
            source,
        })?;
        if mesh.faces.is_empty() {
            return Err(GlbError::EmptyMesh {
                name: node.name.clone(),
            });
        }
        let positions: Vec<[f32; 3]> = mesh
            .positions
            .iter()
            .map(|p| enu_to_gltf(&p.coords))
            .collect();
        let mut attributes = BTreeMap::new();
        let position = b.vec3_f32(&positions, true);
        attributes.insert(Checked::Valid(json::mesh::Semantic::Positions), position);
        if !mesh.normals.is_empty() {
            let normals: Vec<[f32; 3]> = export_normals(mesh).iter().map(enu_to_gltf).collect();
            let normal = b.vec3_f32(&normals, false);
            attributes.insert(Checked::Valid(json::mesh::Semantic::Normals), normal);
        }
        let coloured = !mesh.colors.is_empty();
        if coloured {
            let colors: Vec<[f32; 3]> = mesh.colors.iter().map(|c| c.map(srgb_to_linear)).collect();
            let color = b.vec3_f32(&colors, false);
            attributes.insert(Checked::Valid(json::mesh::Semantic::Colors(0)), color);
        }
        let index_bytes: Vec<u8> = mesh
            .faces
            .iter()
            .flatten()
            .flat_map(|i| i.to_le_bytes())
            .collect();
        let view = b.view(&index_bytes, json::buffer::Target::ElementArrayBuffer);
        let indices = b.accessor(
            view,
            mesh.faces.len() * 3,
            json::accessor::ComponentType::U32,
            json::accessor::Type::Scalar,
            None,
        );

        let material = match material_for.get(&coloured) {
            Some(&m) => m,
            None => {
                let m = b.root.push(json::Material {
                    name: Some(
                        if coloured {
                            "rock (vertex colours)"
                        } else {
                            "rock"
                        }
                        .to_owned(),
                    ),
                    double_sided: options.double_sided,
                    pbr_metallic_roughness: json::material::PbrMetallicRoughness {
                        base_color_factor: json::material::PbrBaseColorFactor(if coloured {
                            [1.0; 4]
                        } else {
                            UNCOLOURED_BASE
                        }),
                        metallic_factor: json::material::StrengthFactor(
                            options.metallic.clamp(0.0, 1.0),
                        ),
                        roughness_factor: json::material::StrengthFactor(
                            options.roughness.clamp(0.0, 1.0),
                        ),
                        ..Default::default()
                    },
                    ..Default::default()
                });
                material_for.insert(coloured, m);
                m
            }
        };
        let mesh_index = b.root.push(json::Mesh {
            extensions: None,
            extras: None,
            name: Some(node.name.clone()),
            primitives: vec![json::mesh::Primitive {
                attributes,
                extensions: None,
                extras: None,
                indices: Some(indices),
                material: Some(material),
                mode: Checked::Valid(json::mesh::Mode::Triangles),
                targets: None,
            }],
            weights: None,
        });
        node_indices.push(b.root.push(json::Node {
            mesh: Some(mesh_index),
            name: Some(node.name.clone()),
            extras: to_extras(&node.extras)?,
            ..Default::default()
        }));
    }

    let scene = b.root.push(json::Scene {
        extensions: None,
        extras: to_extras(&options.scene_extras)?,
        name: Some(options.scene_name.clone()),
        nodes: node_indices,
    });
    b.root.scene = Some(scene);
    if !b.bin.is_empty() {
        b.root.push(json::Buffer {
            byte_length: USize64::from(b.bin.len()),
            name: None,
            uri: None,
            extensions: None,
            extras: None,
        });
    }
    let json_bytes = b.root.to_vec().map_err(|e| GlbError::Encode {
        message: format!("JSON: {e}"),
    })?;
    // 12-byte header, two 8-byte chunk headers, each chunk padded to 4 bytes.
    let total = 12 + 8 + json_bytes.len().next_multiple_of(4) + 8 + b.bin.len().next_multiple_of(4);
    let length = u32::try_from(total).map_err(|_| GlbError::Encode {
        message: format!("{total} bytes exceed the 4 GiB GLB limit"),
    })?;
    let glb = gltf::binary::Glb {
        header: gltf::binary::Header {
            magic: *b"glTF",
            version: 2,
            length,
        },
        json: json_bytes.into(),
        bin: (!b.bin.is_empty()).then_some(b.bin.into()),
    };
    glb.to_vec().map_err(|e| GlbError::Encode {
        message: e.to_string(),
    })
}

/// Writes nodes as a GLB file at `path`, atomically.
///
/// # Errors
/// As [`glb_to_vec`], plus [`GlbError::Write`] if the file cannot be written (nothing is
/// written when encoding fails).
pub fn write_glb(
    path: impl AsRef<Path>,
    nodes: &[GlbNode<'_>],
    options: &GlbOptions,
) -> Result<(), GlbError> {
    let bytes = glb_to_vec(nodes, options)?;
    write_bytes_atomically(path, &bytes)?;
    Ok(())
}

/// A mesh node read back from a GLB file.
#[derive(Debug, Clone, PartialEq)]
pub struct GlbMesh {
    /// The node's name (or its mesh's name when the node has none).
    pub name: Option<String>,
    /// All triangle primitives of the node's mesh, merged, with the node's scene transform
    /// applied, in world ENU metres. Normals and colours are kept when every primitive has
    /// them; colours are converted back to 8-bit sRGB.
    pub mesh: TriangleMesh,
    /// The node's `extras`.
    pub extras: Option<Value>,
}

/// The content of a GLB file.
#[derive(Debug, Clone, PartialEq)]
pub struct GlbContents {
    /// The mesh nodes of the default scene (or of all scenes' roots when there is no default),
    /// in depth-first order.
    pub nodes: Vec<GlbMesh>,
    /// The scene's `extras`.
    pub scene_extras: Option<Value>,
}

/// Reads and validates a GLB file.
///
/// # Errors
/// [`GlbError::Open`] if the file cannot be read; otherwise as [`read_glb_from_slice`].
pub fn read_glb(path: impl AsRef<Path>) -> Result<GlbContents, GlbError> {
    let path = path.as_ref();
    let bytes = std::fs::read(path).map_err(|source| GlbError::Open {
        path: path.to_path_buf(),
        source,
    })?;
    read_glb_from_slice(&bytes, &path.display().to_string())
}

fn u32_at(bytes: &[u8], at: usize) -> u32 {
    let mut word = [0u8; 4];
    if let Some(src) = bytes.get(at..at + 4) {
        word.copy_from_slice(src);
    }
    u32::from_le_bytes(word)
}

/// Checks the GLB container: header, chunk layout and lengths. Returns the JSON and BIN chunks.
fn check_container<'b>(
    bytes: &'b [u8],
    file: &str,
) -> Result<(&'b [u8], Option<&'b [u8]>), GlbError> {
    let corrupt = |message: String| GlbError::Corrupt {
        file: file.to_owned(),
        message,
    };
    let truncated = |what, expected_bytes| GlbError::Truncated {
        file: file.to_owned(),
        what,
        expected_bytes,
        actual_bytes: bytes.len(),
    };
    let prefix = &bytes[..bytes.len().min(4)];
    if !b"glTF".starts_with(prefix) {
        return Err(GlbError::NotGlb {
            file: file.to_owned(),
            found: bytes.iter().take(4).copied().collect(),
        });
    }
    if bytes.len() < 12 {
        return Err(truncated("the GLB header", 12));
    }
    let version = u32_at(bytes, 4);
    if version != 2 {
        return Err(GlbError::Unsupported {
            file: file.to_owned(),
            message: format!("GLB version {version} (only 2 is supported)"),
        });
    }
    let declared = u32_at(bytes, 8) as usize;
    if declared > bytes.len() {
        return Err(truncated("the length in the GLB header", declared));
    }
    if declared < bytes.len() {
        return Err(corrupt(format!(
            "the header declares {declared} bytes but the file has {}",
            bytes.len()
        )));
    }
    let mut at = 12;
    let mut json_chunk: &[u8] = &[];
    let mut bin = None;
    let mut chunk = 0;
    while at < bytes.len() {
        if bytes.len() - at < 8 {
            return Err(truncated("a chunk header", at + 8));
        }
        let length = u32_at(bytes, at) as usize;
        let kind = &bytes[at + 4..at + 8];
        let start = at + 8;
        let end = start
            .checked_add(length)
            .filter(|&e| e <= bytes.len())
            .ok_or_else(|| truncated("a chunk", start.saturating_add(length)))?;
        if !length.is_multiple_of(4) {
            return Err(corrupt(format!(
                "chunk {chunk} is {length} bytes long, not a multiple of 4"
            )));
        }
        match (chunk, kind) {
            (0, b"JSON") => json_chunk = &bytes[start..end],
            (0, _) => return Err(corrupt(format!("the first chunk is {kind:?}, not JSON"))),
            (1, b"BIN\0") => bin = Some(&bytes[start..end]),
            // Later chunks of unknown type must be ignored (glTF 2.0, 4.4.3.1).
            _ => {}
        }
        at = end;
        chunk += 1;
    }
    if chunk == 0 {
        return Err(truncated("the JSON chunk", 20));
    }
    Ok((json_chunk, bin))
}

/// Checks what `gltf-json` 1.4's validation indexes without a bounds check (a primitive's
/// `POSITION` accessor), so that validating a corrupt file cannot panic.
fn precheck_json(json_chunk: &[u8], file: &str) -> Result<(), GlbError> {
    let root = json::Root::from_slice(json_chunk).map_err(|e| GlbError::Gltf {
        file: file.to_owned(),
        message: e.to_string(),
    })?;
    for (m, mesh) in root.meshes.iter().enumerate() {
        for (p, primitive) in mesh.primitives.iter().enumerate() {
            for (semantic, index) in &primitive.attributes {
                if index.value() >= root.accessors.len() {
                    return Err(GlbError::Gltf {
                        file: file.to_owned(),
                        message: format!(
                            "meshes[{m}].primitives[{p}].attributes[{semantic:?}] refers to accessor {} but there are {}",
                            index.value(),
                            root.accessors.len()
                        ),
                    });
                }
            }
        }
    }
    Ok(())
}

/// Reads and validates a GLB file held in memory; `source_name` names it in errors.
///
/// # Errors
/// [`GlbError::NotGlb`], [`GlbError::Truncated`] or [`GlbError::Corrupt`] for a damaged
/// container, out-of-bounds or misaligned accessors, bad bounds or indices, or non-finite
/// data; [`GlbError::Gltf`] for invalid JSON; [`GlbError::Unsupported`] for external buffers,
/// sparse accessors, non-triangle primitives or attribute types other than those listed in the
/// [module documentation](self).
pub fn read_glb_from_slice(bytes: &[u8], source_name: &str) -> Result<GlbContents, GlbError> {
    let file = source_name;
    let (json_chunk, bin) = check_container(bytes, file)?;
    precheck_json(json_chunk, file)?;
    let gltf = gltf::Gltf::from_slice(bytes).map_err(|e| {
        let message = e.to_string();
        GlbError::Gltf {
            file: file.to_owned(),
            message: message
                .strip_prefix("invalid glTF: ")
                .unwrap_or(&message)
                .to_owned(),
        }
    })?;
    let reader = Reader {
        file,
        bin: bin.unwrap_or(&[]),
    };
    for buffer in gltf.buffers() {
        match buffer.source() {
            gltf::buffer::Source::Bin => {
                if bin.is_none() {
                    return Err(reader.corrupt(format!(
                        "buffer {} refers to the BIN chunk, which is missing",
                        buffer.index()
                    )));
                }
                if buffer.length() > reader.bin.len() {
                    return Err(reader.corrupt(format!(
                        "buffer {} declares {} bytes but the BIN chunk holds {}",
                        buffer.index(),
                        buffer.length(),
                        reader.bin.len()
                    )));
                }
            }
            gltf::buffer::Source::Uri(_) => {
                return Err(reader.unsupported(format!(
                    "buffer {} is external (a URI), not in the BIN chunk",
                    buffer.index()
                )));
            }
        }
    }

    let roots: Vec<gltf::Node<'_>> = match gltf.default_scene() {
        Some(scene) => scene.nodes().collect(),
        None => gltf.scenes().flat_map(|s| s.nodes()).collect(),
    };
    let scene_extras = match gltf.default_scene().or_else(|| gltf.scenes().next()) {
        Some(scene) => reader.extras(scene.extras())?,
        None => None,
    };
    let mut nodes = Vec::new();
    let mut on_path = vec![false; gltf.nodes().len()];
    for root in roots {
        reader.visit(&root, &Matrix4::identity(), &mut on_path, &mut nodes)?;
    }
    Ok(GlbContents {
        nodes,
        scene_extras,
    })
}

/// Decoding context: the file name for errors and the BIN chunk.
struct Reader<'b> {
    file: &'b str,
    bin: &'b [u8],
}

/// Vertex attributes of one primitive, in glTF axes.
struct Primitive {
    positions: Vec<[f32; 3]>,
    normals: Option<Vec<[f32; 3]>>,
    colors: Option<Vec<[u8; 3]>>,
    faces: Vec<[u32; 3]>,
}

impl Reader<'_> {
    fn corrupt(&self, message: String) -> GlbError {
        GlbError::Corrupt {
            file: self.file.to_owned(),
            message,
        }
    }

    fn unsupported(&self, message: String) -> GlbError {
        GlbError::Unsupported {
            file: self.file.to_owned(),
            message,
        }
    }

    fn extras(&self, extras: &json::Extras) -> Result<Option<Value>, GlbError> {
        extras
            .as_ref()
            .map(|raw| serde_json::from_str(raw.get()))
            .transpose()
            .map_err(|e| self.corrupt(format!("extras: {e}")))
    }

    /// Depth-first over the node tree; `on_path` catches cycles, which validation allows.
    fn visit(
        &self,
        node: &gltf::Node<'_>,
        parent: &Matrix4<f64>,
        on_path: &mut [bool],
        out: &mut Vec<GlbMesh>,
    ) -> Result<(), GlbError> {
        let index = node.index();
        match on_path.get(index) {
            Some(false) => {}
            _ => {
                return Err(self.corrupt(format!("node {index} is its own ancestor")));
            }
        }
        on_path[index] = true;
        let local = node.transform().matrix();
        let local = Matrix4::from_fn(|r, c| f64::from(local[c][r]));
        let world = parent * local;
        if let Some(mesh) = node.mesh() {
            let name = node.name().or(mesh.name()).map(str::to_owned);
            let merged = self.mesh(&mesh, &world)?;
            out.push(GlbMesh {
                name,
                mesh: merged,
                extras: self.extras(node.extras())?,
            });
        }
        for child in node.children() {
            self.visit(&child, &world, on_path, out)?;
        }
        on_path[index] = false;
        Ok(())
    }

    fn mesh(&self, mesh: &gltf::Mesh<'_>, world: &Matrix4<f64>) -> Result<TriangleMesh, GlbError> {
        let mut merged = TriangleMesh::default();
        let identity = *world == Matrix4::identity();
        let linear: Matrix3<f64> = world.fixed_view::<3, 3>(0, 0).into_owned();
        let normal_matrix = linear
            .try_inverse()
            .ok_or_else(|| self.corrupt(format!("mesh {} has a singular transform", mesh.index())))?
            .transpose();
        for primitive in mesh.primitives() {
            let p = self.primitive(&primitive, mesh.index())?;
            let positions = p.positions.iter().map(|&v| {
                let v = if identity {
                    v
                } else {
                    let h = world
                        * Vector4::new(f64::from(v[0]), f64::from(v[1]), f64::from(v[2]), 1.0);
                    [h.x as f32, h.y as f32, h.z as f32]
                };
                Point3::from(gltf_to_enu(v))
            });
            let part = TriangleMesh {
                positions: positions.collect(),
                normals: p
                    .normals
                    .map(|ns| {
                        ns.iter()
                            .map(|&n| {
                                let n = if identity {
                                    n
                                } else {
                                    let m = normal_matrix
                                        * Vector3::new(
                                            f64::from(n[0]),
                                            f64::from(n[1]),
                                            f64::from(n[2]),
                                        );
                                    let m = m.try_normalize(1e-12).unwrap_or(m);
                                    [m.x as f32, m.y as f32, m.z as f32]
                                };
                                gltf_to_enu(n)
                            })
                            .collect()
                    })
                    .unwrap_or_default(),
                colors: p.colors.unwrap_or_default(),
                faces: p.faces,
            };
            merged.append(&part);
        }
        merged
            .validate()
            .map_err(|e| self.corrupt(format!("mesh {}: {e}", mesh.index())))?;
        Ok(merged)
    }

    fn primitive(
        &self,
        primitive: &gltf::Primitive<'_>,
        mesh: usize,
    ) -> Result<Primitive, GlbError> {
        let what =
            |attribute: &str| format!("mesh {mesh} primitive {} {attribute}", primitive.index());
        if primitive.mode() != gltf::mesh::Mode::Triangles {
            return Err(self.unsupported(format!(
                "{} is {:?}; only triangles are read",
                what("mode"),
                primitive.mode()
            )));
        }
        let position = primitive
            .get(&gltf::Semantic::Positions)
            .ok_or_else(|| self.corrupt(format!("{} is missing", what("POSITION"))))?;
        let positions = self.read_f32x3(&position, &what("POSITION"), true)?;
        self.check_bounds(&position, &positions, &what("POSITION"))?;
        let n = positions.len();
        let same_count = |acc: &gltf::Accessor<'_>, name: &str| {
            if acc.count() == n {
                Ok(())
            } else {
                Err(self.corrupt(format!(
                    "{} has {} items for {n} vertices",
                    what(name),
                    acc.count()
                )))
            }
        };
        let normals = match primitive.get(&gltf::Semantic::Normals) {
            Some(acc) => {
                same_count(&acc, "NORMAL")?;
                Some(self.read_f32x3(&acc, &what("NORMAL"), true)?)
            }
            None => None,
        };
        let colors = match primitive.get(&gltf::Semantic::Colors(0)) {
            Some(acc) => {
                same_count(&acc, "COLOR_0")?;
                Some(self.read_colors(&acc, &what("COLOR_0"))?)
            }
            None => None,
        };
        let indices: Vec<u32> = match primitive.indices() {
            Some(acc) => self.read_indices(&acc, &what("indices"))?,
            None => {
                let n = u32::try_from(n)
                    .map_err(|_| self.unsupported(format!("{} vertices without indices", n)))?;
                (0..n).collect()
            }
        };
        if !indices.len().is_multiple_of(3) {
            return Err(self.corrupt(format!(
                "{} has {} entries, not a multiple of 3",
                what("indices"),
                indices.len()
            )));
        }
        if let Some(&bad) = indices.iter().find(|&&i| i as usize >= n) {
            return Err(self.corrupt(format!(
                "{} refers to vertex {bad} but the primitive has {n} vertices",
                what("indices")
            )));
        }
        Ok(Primitive {
            positions,
            normals,
            colors,
            faces: indices
                .chunks_exact(3)
                .map(|c| [c[0], c[1], c[2]])
                .collect(),
        })
    }

    /// The accessor's elements as byte slices, after checking it against its view and buffer.
    fn elements<'a>(
        &'a self,
        acc: &gltf::Accessor<'_>,
        what: &str,
        vertex_attribute: bool,
    ) -> Result<impl Iterator<Item = &'a [u8]> + 'a, GlbError> {
        if acc.sparse().is_some() {
            return Err(self.unsupported(format!("{what} is a sparse accessor")));
        }
        let view = acc
            .view()
            .ok_or_else(|| self.unsupported(format!("{what} has no buffer view")))?;
        let buffer_length = view.buffer().length();
        let view_end = view
            .offset()
            .checked_add(view.length())
            .filter(|&e| e <= buffer_length && e <= self.bin.len())
            .ok_or_else(|| {
                self.corrupt(format!(
                    "{what}: buffer view {} ({} bytes at {}) runs past its buffer ({buffer_length} bytes)",
                    view.index(),
                    view.length(),
                    view.offset()
                ))
            })?;
        let data = &self.bin[view.offset()..view_end];
        let component = acc.data_type().size();
        let size = acc.size();
        let stride = view.stride().unwrap_or(size);
        if stride < size {
            return Err(self.corrupt(format!(
                "{what}: stride {stride} is smaller than its {size}-byte elements"
            )));
        }
        let alignment = if vertex_attribute {
            4.max(component)
        } else {
            component
        };
        if !acc.offset().is_multiple_of(component)
            || !(view.offset() + acc.offset()).is_multiple_of(component)
            || (vertex_attribute
                && (!(view.offset() + acc.offset()).is_multiple_of(alignment)
                    || !stride.is_multiple_of(alignment)))
        {
            return Err(self.corrupt(format!(
                "{what} is misaligned (view offset {}, accessor offset {}, stride {stride})",
                view.offset(),
                acc.offset()
            )));
        }
        let count = acc.count();
        let needed = match count {
            0 => Some(0),
            _ => (count - 1)
                .checked_mul(stride)
                .and_then(|b| b.checked_add(acc.offset()))
                .and_then(|b| b.checked_add(size)),
        };
        if needed.is_none_or(|needed| needed > data.len()) {
            return Err(self.corrupt(format!(
                "{what}: {count} elements of {size} bytes (stride {stride}) at offset {} do not fit buffer view {} ({} bytes)",
                acc.offset(),
                view.index(),
                data.len()
            )));
        }
        let offset = acc.offset();
        Ok((0..count).map(move |i| &data[offset + i * stride..offset + i * stride + size]))
    }

    fn read_f32x3(
        &self,
        acc: &gltf::Accessor<'_>,
        what: &str,
        require_finite: bool,
    ) -> Result<Vec<[f32; 3]>, GlbError> {
        use gltf::accessor::{DataType, Dimensions};
        if acc.data_type() != DataType::F32 || acc.dimensions() != Dimensions::Vec3 {
            return Err(self.unsupported(format!(
                "{what} is {:?} {:?}; expected float VEC3",
                acc.data_type(),
                acc.dimensions()
            )));
        }
        // `elements` checks the count against the data first, so the capacity is bounded by
        // the file size; every element slice is exactly 12 bytes (float VEC3).
        let elements = self.elements(acc, what, true)?;
        let mut out = Vec::with_capacity(acc.count());
        for (i, e) in elements.enumerate() {
            let v = [0, 4, 8].map(|k| f32::from_le_bytes([e[k], e[k + 1], e[k + 2], e[k + 3]]));
            if require_finite && !v.iter().all(|c| c.is_finite()) {
                return Err(self.corrupt(format!("{what} element {i} is not finite: {v:?}")));
            }
            out.push(v);
        }
        Ok(out)
    }

    fn read_colors(&self, acc: &gltf::Accessor<'_>, what: &str) -> Result<Vec<[u8; 3]>, GlbError> {
        use gltf::accessor::{DataType, Dimensions};
        match acc.dimensions() {
            Dimensions::Vec3 | Dimensions::Vec4 => {}
            other => {
                return Err(self.unsupported(format!("{what} is {other:?}; expected VEC3 or VEC4")));
            }
        }
        // Element slices hold 3 or 4 components of the matched type, and k < 3.
        let decode: fn(&[u8], usize) -> f32 = match (acc.data_type(), acc.normalized()) {
            (DataType::F32, _) => {
                |e, k| f32::from_le_bytes([e[4 * k], e[4 * k + 1], e[4 * k + 2], e[4 * k + 3]])
            }
            (DataType::U8, true) => |e, k| f32::from(e[k]) / 255.0,
            (DataType::U16, true) => {
                |e, k| f32::from(u16::from_le_bytes([e[2 * k], e[2 * k + 1]])) / 65535.0
            }
            (t, normalized) => {
                return Err(self.unsupported(format!(
                    "{what} is {t:?} (normalized: {normalized}); expected float or normalized u8/u16"
                )));
            }
        };
        Ok(self
            .elements(acc, what, true)?
            .map(|e| [0, 1, 2].map(|k| linear_to_srgb(decode(e, k))))
            .collect())
    }

    fn read_indices(&self, acc: &gltf::Accessor<'_>, what: &str) -> Result<Vec<u32>, GlbError> {
        use gltf::accessor::{DataType, Dimensions};
        if acc.dimensions() != Dimensions::Scalar {
            return Err(self.corrupt(format!("{what} is {:?}, not SCALAR", acc.dimensions())));
        }
        // Element slices are exactly one component of the matched type.
        let decode: fn(&[u8]) -> u32 = match acc.data_type() {
            DataType::U8 => |e| u32::from(e[0]),
            DataType::U16 => |e| u32::from(u16::from_le_bytes([e[0], e[1]])),
            DataType::U32 => |e| u32::from_le_bytes([e[0], e[1], e[2], e[3]]),
            other => {
                return Err(self.corrupt(format!("{what} are {other:?}; expected u8, u16 or u32")));
            }
        };
        Ok(self.elements(acc, what, false)?.map(decode).collect())
    }

    /// POSITION must carry min and max (glTF 2.0, 3.6.2.4), and they must hold the data.
    fn check_bounds(
        &self,
        acc: &gltf::Accessor<'_>,
        positions: &[[f32; 3]],
        what: &str,
    ) -> Result<(), GlbError> {
        let parse = |v: Option<Value>, which: &str| -> Result<[f64; 3], GlbError> {
            let v = v.ok_or_else(|| {
                self.corrupt(format!(
                    "{what} has no {which} (the specification requires it)"
                ))
            })?;
            let a = v.as_array().filter(|a| a.len() == 3);
            let nums: Option<Vec<f64>> = a.map(|a| a.iter().filter_map(Value::as_f64).collect());
            match nums {
                Some(n) if n.len() == 3 => Ok([n[0], n[1], n[2]]),
                _ => Err(self.corrupt(format!("{what} {which} is not three numbers: {v}"))),
            }
        };
        let min = parse(acc.min(), "min")?;
        let max = parse(acc.max(), "max")?;
        for (i, p) in positions.iter().enumerate() {
            for k in 0..3 {
                let c = f64::from(p[k]);
                // Writers round bounds differently; allow a relative 1e-5.
                let tol = |b: f64| 1e-5 * b.abs().max(1e-3);
                if c < min[k] - tol(min[k]) || c > max[k] + tol(max[k]) {
                    return Err(self.corrupt(format!(
                        "{what} element {i} ({p:?}) lies outside the declared bounds {min:?}..{max:?}"
                    )));
                }
            }
        }
        Ok(())
    }
}
