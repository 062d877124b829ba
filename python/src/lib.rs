//! `scarp._scarp`: the native module behind the `scarp` Python package.
//!
//! The Python package (`python/scarp/__init__.py`) is the public API; this module is its engine
//! and is not meant to be called directly. Conventions are those of the Rust crates:
//! - world is local ENU metres, the camera is OpenCV (x right, y down, z forward);
//! - poses are 4×4 float64 arrays named by what they map (`world_from_camera`);
//! - depth is an H×W float32 array of metres along the camera z axis, 0 meaning no data;
//! - colour is an H×W×3 uint8 sRGB array.
//!
//! Configurations cross the boundary as JSON strings of the Rust `serde` config structs (every
//! key checked, unknown keys refused), and reports come back as JSON strings of the same structs
//! the CLI prints, so the Python dictionaries carry the CLI's keys.
//!
//! Errors: bad input (dtype, shape, a non-contiguous array, a non-finite or non-rigid pose, a
//! bad configuration key) raises `ValueError`; a file that cannot be read or written raises
//! `OSError`. Every entry point runs inside [`guard`], so a panic in the library becomes a
//! `RuntimeError` naming it instead of crossing the FFI boundary.

use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::PathBuf;

use nalgebra::{Isometry3, Matrix3, Point3, Rotation3, Translation3, UnitQuaternion};
use numpy::ndarray::Dimension;
use numpy::{
    Element, PyArray, PyArray1, PyArrayDyn, PyArrayMethods, PyReadonlyArray, PyUntypedArray,
    PyUntypedArrayMethods,
};
use pyo3::exceptions::{PyOSError, PyRuntimeError, PyValueError};
use pyo3::prelude::*;

use scarp::evaluation::mesh::{MeshEvalConfig, evaluate_mesh};
use scarp::evaluation::trajectory::{TrajectoryEvalConfig, evaluate_trajectory};
use scarp::fragility::scan::{analyze_closed_scan, close_scan};
use scarp::fragility::{ContactSpec, FragilityConfig, analyze_detailed};
use scarp_datasets::sequence::Sequence;
use scarp_export::glb::{GlbNode, GlbOptions, write_glb};
use scarp_export::ply::{PlyEncoding, read_mesh, write_mesh};
use scarp_export::tum::{StampedPose, read_tum_trajectory};
use scarp_slam::ba::{LmConfig, read_bal, solve_bal};
use scarp_slam::image::{DepthImage, RgbImage};
use scarp_slam::meshing::{MeshingConfig, extract_mesh, remove_small_components};
use scarp_slam::odometry::{OdometryConfig, track_frames};
use scarp_slam::tsdf::{Roi, TsdfConfig, TsdfVolume};
use scarp_slam::{PinholeCamera, RgbdFrame, TriangleMesh};

// ---------------------------------------------------------------------------------------------
// Boundary helpers
// ---------------------------------------------------------------------------------------------

/// Runs `f`, turning a Rust panic into a Python `RuntimeError` (never unwinding into Python).
fn guard<T>(what: &str, f: impl FnOnce() -> PyResult<T>) -> PyResult<T> {
    match catch_unwind(AssertUnwindSafe(f)) {
        Ok(result) => result,
        Err(payload) => {
            let message = payload
                .downcast_ref::<&str>()
                .map(|s| (*s).to_string())
                .or_else(|| payload.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "unknown panic".to_string());
            Err(PyRuntimeError::new_err(format!(
                "scarp: internal error in {what}: {message} (this is a bug in scarp)"
            )))
        }
    }
}

fn value_error(e: impl std::fmt::Display) -> PyErr {
    PyValueError::new_err(e.to_string())
}

fn os_error(e: impl std::fmt::Display) -> PyErr {
    PyOSError::new_err(e.to_string())
}

/// Parses a JSON configuration of a serde struct, naming it in the error.
fn parse_config<T: serde::de::DeserializeOwned>(what: &str, json: &str) -> PyResult<T> {
    serde_json::from_str(json).map_err(|e| PyValueError::new_err(format!("{what}: {e}")))
}

fn to_json(value: &impl serde::Serialize) -> PyResult<String> {
    serde_json::to_string(value).map_err(|e| PyRuntimeError::new_err(e.to_string()))
}

/// A short description of a Python object for error messages: dtype and shape of an array.
fn describe(obj: &Bound<'_, PyAny>) -> String {
    match obj.cast::<PyUntypedArray>() {
        Ok(a) => format!("a {} array of shape {:?}", a.dtype(), a.shape()),
        Err(_) => match obj.get_type().name() {
            Ok(name) => format!("an object of type {name}"),
            Err(_) => "an object of unknown type".to_string(),
        },
    }
}

/// Borrows `obj` as a C-contiguous numpy array of element `T` and dimension `D`, without
/// copying. `expected` says what was wanted, for the error message.
///
/// # Errors
/// `ValueError` naming `name` when `obj` is not a numpy array, has another dtype or number of
/// dimensions, is not C-contiguous, or is being written elsewhere.
fn borrow_array<'py, T: Element, D: Dimension>(
    obj: &Bound<'py, PyAny>,
    name: &str,
    expected: &str,
) -> PyResult<PyReadonlyArray<'py, T, D>> {
    let untyped = obj.cast::<PyUntypedArray>().map_err(|_| {
        PyValueError::new_err(format!(
            "{name} must be a numpy array ({expected}), got {}",
            describe(obj)
        ))
    })?;
    let typed = obj.cast::<PyArray<T, D>>().map_err(|_| {
        PyValueError::new_err(format!("{name} must be {expected}, got {}", describe(obj)))
    })?;
    if !untyped.is_c_contiguous() {
        return Err(PyValueError::new_err(format!(
            "{name} must be C-contiguous ({expected}), got a strided view of shape {:?}; \
             pass numpy.ascontiguousarray({name})",
            untyped.shape()
        )));
    }
    typed
        .try_readonly()
        .map_err(|e| PyValueError::new_err(format!("{name} cannot be read: {e}")))
}

/// Checks the trailing dimension of an N×`cols` array.
fn check_cols(name: &str, shape: &[usize], cols: usize, expected: &str) -> PyResult<()> {
    if shape.len() != 2 || shape[1] != cols {
        return Err(PyValueError::new_err(format!(
            "{name} must be {expected}, got shape {shape:?}"
        )));
    }
    Ok(())
}

/// A 4×4 float64 rigid transform → isometry.
///
/// # Errors
/// `ValueError` for a non-finite entry, a last row other than (0, 0, 0, 1), or a rotation block
/// that is not orthonormal with determinant +1 (within 1e-5).
fn pose_from_array(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<Isometry3<f64>> {
    let array = borrow_array::<f64, numpy::Ix2>(obj, name, "a 4×4 float64 array")?;
    let shape = array.shape();
    if shape != [4, 4] {
        return Err(PyValueError::new_err(format!(
            "{name} must be a 4×4 float64 array, got shape {shape:?}"
        )));
    }
    let m = array.as_slice().map_err(value_error)?;
    if let Some(i) = m.iter().position(|v| !v.is_finite()) {
        return Err(PyValueError::new_err(format!(
            "{name} has a non-finite entry at [{}, {}] ({})",
            i / 4,
            i % 4,
            m[i]
        )));
    }
    let last = [m[12], m[13], m[14], m[15]];
    if last != [0.0, 0.0, 0.0, 1.0] {
        return Err(PyValueError::new_err(format!(
            "{name} must be a rigid transform with last row [0, 0, 0, 1], got {last:?}"
        )));
    }
    let r = Matrix3::new(m[0], m[1], m[2], m[4], m[5], m[6], m[8], m[9], m[10]);
    let orthonormality = (r.transpose() * r - Matrix3::identity()).abs().max();
    if orthonormality > 1e-5 || r.determinant() < 0.0 {
        return Err(PyValueError::new_err(format!(
            "{name}: the upper-left 3×3 block is not a rotation (|RᵀR − I| = {orthonormality:.2e}, \
             det = {:.6})",
            r.determinant()
        )));
    }
    let rotation = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(r));
    Ok(Isometry3::from_parts(
        Translation3::new(m[3], m[7], m[11]),
        rotation,
    ))
}

/// An isometry → a new 4×4 float64 array (row-major).
fn pose_to_array<'py>(
    py: Python<'py>,
    pose: &Isometry3<f64>,
) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
    let h = pose.to_homogeneous();
    let rows: Vec<f64> = (0..4)
        .flat_map(|r| (0..4).map(move |c| h[(r, c)]))
        .collect();
    PyArray1::from_vec(py, rows).reshape(vec![4, 4])
}

/// Builds an RGBD frame from a depth (H×W float32) and a colour (H×W×3 uint8) array.
fn frame_from_arrays(
    depth_m: &Bound<'_, PyAny>,
    color: &Bound<'_, PyAny>,
    timestamp_s: f64,
) -> PyResult<RgbdFrame> {
    let depth =
        borrow_array::<f32, numpy::Ix2>(depth_m, "depth_m", "an H×W float32 array of metres")?;
    let rgb = borrow_array::<u8, numpy::Ix3>(color, "color", "an H×W×3 uint8 array")?;
    let (h, w) = (depth.shape()[0], depth.shape()[1]);
    let cs = rgb.shape();
    if cs != [h, w, 3] {
        return Err(PyValueError::new_err(format!(
            "color must be an H×W×3 uint8 array matching depth_m ({h}×{w}), got shape {cs:?}"
        )));
    }
    if h == 0 || w == 0 {
        return Err(PyValueError::new_err("depth_m is empty"));
    }
    let depth_values = depth.as_slice().map_err(value_error)?;
    if let Some(i) = depth_values.iter().position(|v| !v.is_finite() || *v < 0.0) {
        return Err(PyValueError::new_err(format!(
            "depth_m[{}, {}] = {} (depth must be finite and ≥ 0; 0 means no data)",
            i / w,
            i % w,
            depth_values[i]
        )));
    }
    let (w32, h32) = (
        u32::try_from(w).map_err(value_error)?,
        u32::try_from(h).map_err(value_error)?,
    );
    let depth_image = DepthImage::from_vec(w32, h32, depth_values.to_vec()).map_err(value_error)?;
    let pixels: Vec<[u8; 3]> = rgb
        .as_slice()
        .map_err(value_error)?
        .chunks_exact(3)
        .map(|c| [c[0], c[1], c[2]])
        .collect();
    let rgb_image = RgbImage::from_vec(w32, h32, pixels).map_err(value_error)?;
    RgbdFrame::new(timestamp_s, rgb_image, depth_image, None).map_err(value_error)
}

fn camera_for(frame: &RgbdFrame, fx: f64, fy: f64, cx: f64, cy: f64) -> PyResult<PinholeCamera> {
    PinholeCamera::new(fx, fy, cx, cy, frame.width(), frame.height()).map_err(value_error)
}

/// A mesh from N×3 float32 vertices, M×3 uint32 triangles and optional N×3 uint8 colours.
fn mesh_from_arrays(
    vertices: &Bound<'_, PyAny>,
    triangles: &Bound<'_, PyAny>,
    colors: Option<&Bound<'_, PyAny>>,
) -> PyResult<TriangleMesh> {
    let v =
        borrow_array::<f32, numpy::Ix2>(vertices, "vertices", "an N×3 float32 array of metres")?;
    check_cols("vertices", v.shape(), 3, "an N×3 float32 array of metres")?;
    let f = borrow_array::<u32, numpy::Ix2>(
        triangles,
        "triangles",
        "an M×3 uint32 array of vertex indices",
    )?;
    check_cols(
        "triangles",
        f.shape(),
        3,
        "an M×3 uint32 array of vertex indices",
    )?;
    let vs = v.as_slice().map_err(value_error)?;
    if let Some(i) = vs.iter().position(|x| !x.is_finite()) {
        return Err(PyValueError::new_err(format!(
            "vertices[{}, {}] is not finite ({})",
            i / 3,
            i % 3,
            vs[i]
        )));
    }
    let positions: Vec<Point3<f32>> = vs
        .chunks_exact(3)
        .map(|p| Point3::new(p[0], p[1], p[2]))
        .collect();
    let faces: Vec<[u32; 3]> = f
        .as_slice()
        .map_err(value_error)?
        .chunks_exact(3)
        .map(|t| [t[0], t[1], t[2]])
        .collect();
    let mut mesh = TriangleMesh::new(positions, faces).map_err(value_error)?;
    if let Some(colors) = colors {
        let c = borrow_array::<u8, numpy::Ix2>(colors, "colors", "an N×3 uint8 array")?;
        check_cols("colors", c.shape(), 3, "an N×3 uint8 array")?;
        if c.shape()[0] != mesh.positions.len() {
            return Err(PyValueError::new_err(format!(
                "colors has {} rows but there are {} vertices",
                c.shape()[0],
                mesh.positions.len()
            )));
        }
        mesh.colors = c
            .as_slice()
            .map_err(value_error)?
            .chunks_exact(3)
            .map(|c| [c[0], c[1], c[2]])
            .collect();
    }
    Ok(mesh)
}

/// The arrays of a mesh, moved into numpy without copying the flat buffers:
/// (vertices N×3 float32, triangles M×3 uint32, colors N×3 uint8 or None, normals N×3 float32 or
/// None).
type MeshArrays<'py> = (
    Bound<'py, PyArrayDyn<f32>>,
    Bound<'py, PyArrayDyn<u32>>,
    Option<Bound<'py, PyArrayDyn<u8>>>,
    Option<Bound<'py, PyArrayDyn<f32>>>,
);

fn mesh_to_arrays(py: Python<'_>, mesh: TriangleMesh) -> PyResult<MeshArrays<'_>> {
    let n = mesh.positions.len();
    let m = mesh.faces.len();
    let vertices: Vec<f32> = mesh
        .positions
        .iter()
        .flat_map(|p| [p.x, p.y, p.z])
        .collect();
    let vertices = PyArray1::from_vec(py, vertices).reshape(vec![n, 3])?;
    let triangles = PyArray1::from_vec(py, mesh.faces.into_flattened()).reshape(vec![m, 3])?;
    let colors = if mesh.colors.len() == n && n > 0 {
        Some(PyArray1::from_vec(py, mesh.colors.into_flattened()).reshape(vec![n, 3])?)
    } else {
        None
    };
    let normals = if mesh.normals.len() == n && n > 0 {
        let flat: Vec<f32> = mesh.normals.iter().flat_map(|v| [v.x, v.y, v.z]).collect();
        Some(PyArray1::from_vec(py, flat).reshape(vec![n, 3])?)
    } else {
        None
    };
    Ok((vertices, triangles, colors, normals))
}

// ---------------------------------------------------------------------------------------------
// TSDF
// ---------------------------------------------------------------------------------------------

/// A voxel-hashed TSDF volume (scarp_slam::tsdf::TsdfVolume).
#[pyclass(module = "scarp._scarp", name = "TsdfVolume")]
struct PyTsdfVolume {
    volume: TsdfVolume,
}

#[pymethods]
impl PyTsdfVolume {
    /// `config_json`: a JSON object of `TsdfConfig` fields; `roi`: `cyl:x,y,z_min,z_max,r` or
    /// `box:x0,y0,z0,x1,y1,z1` (metres), overriding the config's.
    #[new]
    #[pyo3(signature = (config_json, roi=None))]
    fn new(config_json: &str, roi: Option<&str>) -> PyResult<Self> {
        guard("TsdfVolume()", || {
            let mut config: TsdfConfig = parse_config("TSDF configuration", config_json)?;
            if let Some(text) = roi {
                config.roi = Some(text.parse::<Roi>().map_err(value_error)?);
            }
            let volume = TsdfVolume::new(config).map_err(value_error)?;
            Ok(Self { volume })
        })
    }

    /// Fuses one frame; returns the JSON of `IntegrationStats`.
    #[allow(clippy::too_many_arguments)]
    fn integrate(
        &mut self,
        py: Python<'_>,
        depth_m: &Bound<'_, PyAny>,
        color: &Bound<'_, PyAny>,
        fx: f64,
        fy: f64,
        cx: f64,
        cy: f64,
        world_from_camera: &Bound<'_, PyAny>,
    ) -> PyResult<String> {
        guard("TsdfVolume.integrate", || {
            let frame = frame_from_arrays(depth_m, color, 0.0)?;
            let camera = camera_for(&frame, fx, fy, cx, cy)?;
            let pose = pose_from_array(world_from_camera, "world_from_camera")?;
            let volume = &mut self.volume;
            let stats = py
                .detach(|| volume.integrate(&frame, &camera, &pose))
                .map_err(value_error)?;
            to_json(&stats)
        })
    }

    /// Marching cubes over the volume: (vertices, triangles, colors, normals).
    #[pyo3(signature = (min_weight=0.0, min_component_triangles=0, min_observations=0))]
    fn extract_mesh<'py>(
        &self,
        py: Python<'py>,
        min_weight: f32,
        min_component_triangles: usize,
        min_observations: u8,
    ) -> PyResult<MeshArrays<'py>> {
        guard("TsdfVolume.extract_mesh", || {
            if !(min_weight.is_finite() && min_weight >= 0.0) {
                return Err(PyValueError::new_err(format!(
                    "min_weight must be finite and ≥ 0, got {min_weight}"
                )));
            }
            let config = MeshingConfig {
                min_weight,
                min_observations,
                min_component_triangles,
            };
            let volume = &self.volume;
            let mesh = py.detach(|| {
                let mesh = extract_mesh(volume, &config);
                if min_component_triangles > 0 {
                    remove_small_components(&mesh, min_component_triangles)
                } else {
                    mesh
                }
            });
            mesh_to_arrays(py, mesh)
        })
    }

    /// The JSON of `VolumeStats` (blocks, voxels, memory).
    fn stats(&self) -> PyResult<String> {
        guard("TsdfVolume.stats", || to_json(&self.volume.stats()))
    }

    /// The volume's configuration as JSON.
    fn config_json(&self) -> PyResult<String> {
        guard("TsdfVolume.config_json", || to_json(self.volume.config()))
    }

    /// Empties the volume.
    fn clear(&mut self) {
        self.volume.clear();
    }
}

// ---------------------------------------------------------------------------------------------
// Odometry
// ---------------------------------------------------------------------------------------------

/// Frame-to-frame RGBD odometry (scarp_slam::odometry::track_frames).
#[pyclass(module = "scarp._scarp", name = "RgbdOdometry")]
struct PyRgbdOdometry {
    config: OdometryConfig,
    previous: Option<(RgbdFrame, PinholeCamera, Isometry3<f64>)>,
    initial_world_from_camera: Isometry3<f64>,
}

#[pymethods]
impl PyRgbdOdometry {
    /// `config_json`: a JSON object of `OdometryConfig` fields; `world_from_first_camera`: the
    /// pose given to the first frame (default identity).
    #[new]
    #[pyo3(signature = (config_json, world_from_first_camera=None))]
    fn new(
        config_json: &str,
        world_from_first_camera: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Self> {
        guard("RgbdOdometry()", || {
            let config: OdometryConfig = parse_config("odometry configuration", config_json)?;
            config.validate().map_err(value_error)?;
            let initial = match world_from_first_camera {
                Some(p) => pose_from_array(p, "world_from_first_camera")?,
                None => Isometry3::identity(),
            };
            Ok(Self {
                config,
                previous: None,
                initial_world_from_camera: initial,
            })
        })
    }

    /// Tracks a frame against the previous one. Returns (world_from_camera 4×4, status, JSON of
    /// details).
    #[allow(clippy::too_many_arguments)]
    #[pyo3(signature = (depth_m, color, fx, fy, cx, cy, prior=None))]
    fn track<'py>(
        &mut self,
        py: Python<'py>,
        depth_m: &Bound<'py, PyAny>,
        color: &Bound<'py, PyAny>,
        fx: f64,
        fy: f64,
        cx: f64,
        cy: f64,
        prior: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<(Bound<'py, PyArrayDyn<f64>>, String, String)> {
        guard("RgbdOdometry.track", || {
            let frame = frame_from_arrays(depth_m, color, 0.0)?;
            let camera = camera_for(&frame, fx, fy, cx, cy)?;
            let prior = prior.map(|p| pose_from_array(p, "prior")).transpose()?;
            let Some((reference, reference_camera, world_from_reference)) = self.previous.take()
            else {
                let pose = prior.unwrap_or(self.initial_world_from_camera);
                self.previous = Some((frame, camera, pose));
                let details = serde_json::json!({ "first_frame": true });
                return Ok((
                    pose_to_array(py, &pose)?,
                    "first_frame".to_string(),
                    details.to_string(),
                ));
            };
            if reference_camera != camera {
                // Keep the reference: this frame is refused, not tracked.
                self.previous = Some((reference, reference_camera, world_from_reference));
                return Err(PyValueError::new_err(
                    "the frame's size or intrinsics differ from the previous frame's; \
                     call reset() to start a new sequence",
                ));
            }
            let guess = match &prior {
                Some(p) => world_from_reference.inverse() * p,
                None => Isometry3::identity(),
            };
            let config = &self.config;
            let result = py.detach(|| track_frames(&camera, &reference, &frame, &guess, config));
            let result = match result {
                Ok(r) => r,
                Err(e) => {
                    self.previous = Some((reference, reference_camera, world_from_reference));
                    return Err(value_error(e));
                }
            };
            let (pose, status) = match &result.failure {
                None => (
                    world_from_reference * result.reference_from_current,
                    "ok".to_string(),
                ),
                Some(failure) => (
                    prior.unwrap_or(world_from_reference),
                    format!("failed: {failure}"),
                ),
            };
            let details = serde_json::json!({
                "inlier_ratio": result.inlier_ratio,
                "correspondences": result.correspondences,
                "iterations": result.iterations,
                "failure": result.failure.as_ref().map(|f| f.to_string()),
            });
            self.previous = Some((frame, camera, pose));
            Ok((pose_to_array(py, &pose)?, status, details.to_string()))
        })
    }

    /// Forgets the previous frame: the next frame starts a new trajectory.
    fn reset(&mut self) {
        self.previous = None;
    }
}

// ---------------------------------------------------------------------------------------------
// Functions
// ---------------------------------------------------------------------------------------------

/// Bundle-adjusts a BAL problem file; returns the JSON of `scarp ba --json`.
#[pyfunction]
#[pyo3(signature = (path, config_json, threads=None))]
fn bundle_adjust_bal(
    py: Python<'_>,
    path: PathBuf,
    config_json: &str,
    threads: Option<usize>,
) -> PyResult<String> {
    guard("bundle_adjust_bal", || {
        let config: LmConfig = parse_config("bundle adjustment configuration", config_json)?;
        config.validate().map_err(value_error)?;
        if threads == Some(0) {
            return Err(PyValueError::new_err("threads must be at least 1"));
        }
        let mut builder = rayon_pool_builder();
        if let Some(t) = threads {
            builder = builder.num_threads(t);
        }
        let pool = builder
            .build()
            .map_err(|e| PyRuntimeError::new_err(e.to_string()))?;
        let mut problem = read_bal(&path).map_err(os_or_value)?;
        let start = std::time::Instant::now();
        let summary = py
            .detach(|| pool.install(|| solve_bal(&mut problem, &config)))
            .map_err(value_error)?;
        let json = serde_json::json!({
            "file": path.display().to_string(),
            "cameras": problem.cameras.len(),
            "points": problem.points.len(),
            "observations": problem.observations.len(),
            "initial_cost": summary.initial_cost,
            "final_cost": summary.final_cost,
            "iterations": summary.iterations,
            "seconds": start.elapsed().as_secs_f64(),
            "threads": pool.current_num_threads(),
            "termination": summary.termination,
            "linear_solver": summary.linear_solver,
            "costs": summary.costs,
            "log": summary.log,
        });
        Ok(json.to_string())
    })
}

fn rayon_pool_builder() -> rayon::ThreadPoolBuilder {
    rayon::ThreadPoolBuilder::new()
}

/// A reading error: `OSError` when the file could not be opened, `ValueError` for bad content.
fn os_or_value(e: impl std::error::Error + 'static) -> PyErr {
    let mut source: Option<&(dyn std::error::Error + 'static)> = Some(&e);
    while let Some(s) = source {
        if s.is::<std::io::Error>() {
            return os_error(&e);
        }
        source = s.source();
    }
    value_error(&e)
}

/// The fragility analysis of a closed rock mesh (or an open scan with `scan=True`); returns the
/// JSON of `fragility.json` / `scarp fragility --json`.
#[pyfunction]
#[pyo3(signature = (vertices, triangles, config_json, contact_height_m=None, scan=false))]
fn fragility(
    py: Python<'_>,
    vertices: &Bound<'_, PyAny>,
    triangles: &Bound<'_, PyAny>,
    config_json: &str,
    contact_height_m: Option<f64>,
    scan: bool,
) -> PyResult<String> {
    guard("fragility", || {
        let config: FragilityConfig = parse_config("fragility configuration", config_json)?;
        config.validate().map_err(value_error)?;
        let mesh = mesh_from_arrays(vertices, triangles, None)?;
        if let Some(h) = contact_height_m
            && !h.is_finite()
        {
            return Err(PyValueError::new_err(format!(
                "contact_height_m must be finite, got {h}"
            )));
        }
        let analysis = py
            .detach(|| match (contact_height_m, scan) {
                (Some(h), _) => analyze_detailed(&mesh, ContactSpec::Height(h), &config),
                (None, true) => {
                    close_scan(&mesh, &config.scan).and_then(|c| analyze_closed_scan(&c, &config))
                }
                (None, false) => analyze_detailed(&mesh, ContactSpec::Auto, &config),
            })
            .map_err(value_error)?;
        to_json(&analysis.report)
    })
}

/// Scores a reconstruction against a ground-truth mesh; returns the JSON of
/// `scarp eval mesh --json`.
#[pyfunction]
fn eval_mesh(
    py: Python<'_>,
    vertices: &Bound<'_, PyAny>,
    triangles: &Bound<'_, PyAny>,
    gt_vertices: &Bound<'_, PyAny>,
    gt_triangles: &Bound<'_, PyAny>,
    config_json: &str,
) -> PyResult<String> {
    guard("eval_mesh", || {
        let config: MeshEvalConfig = parse_config("mesh evaluation configuration", config_json)?;
        let mesh = mesh_from_arrays(vertices, triangles, None)?;
        let gt = mesh_from_arrays(gt_vertices, gt_triangles, None)?;
        let scores = py
            .detach(|| evaluate_mesh(&mesh, &gt, &config, None))
            .map_err(value_error)?;
        to_json(&scores)
    })
}

/// N×8 float64 TUM rows (t tx ty tz qx qy qz qw) → stamped poses.
fn stamped_from_array(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<Vec<StampedPose>> {
    let expected = "an N×8 float64 array of TUM rows (t tx ty tz qx qy qz qw)";
    let a = borrow_array::<f64, numpy::Ix2>(obj, name, expected)?;
    check_cols(name, a.shape(), 8, expected)?;
    a.as_slice()
        .map_err(value_error)?
        .chunks_exact(8)
        .enumerate()
        .map(|(i, r)| {
            if r.iter().any(|v| !v.is_finite()) {
                return Err(PyValueError::new_err(format!(
                    "{name} row {i} is not finite"
                )));
            }
            let q = nalgebra::Quaternion::new(r[7], r[4], r[5], r[6]);
            if (q.norm() - 1.0).abs() > 1e-3 {
                return Err(PyValueError::new_err(format!(
                    "{name} row {i}: the quaternion has norm {:.6}, not 1",
                    q.norm()
                )));
            }
            Ok(StampedPose {
                timestamp_s: r[0],
                world_from_camera: Isometry3::from_parts(
                    Translation3::new(r[1], r[2], r[3]),
                    UnitQuaternion::new_normalize(q),
                ),
            })
        })
        .collect()
}

/// Trajectory error (ATE, RPE) of `est` against `gt`; returns the JSON of
/// `scarp eval traj --json`.
#[pyfunction]
fn eval_traj(gt: &Bound<'_, PyAny>, est: &Bound<'_, PyAny>, config_json: &str) -> PyResult<String> {
    guard("eval_traj", || {
        let config: TrajectoryEvalConfig =
            parse_config("trajectory evaluation configuration", config_json)?;
        let gt = stamped_from_array(gt, "gt")?;
        let est = stamped_from_array(est, "est")?;
        let metrics = evaluate_trajectory(&gt, &est, &config).map_err(value_error)?;
        to_json(&metrics)
    })
}

/// Reads a TUM trajectory file as an N×8 float64 array (t tx ty tz qx qy qz qw).
#[pyfunction]
fn read_tum<'py>(py: Python<'py>, path: PathBuf) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
    guard("read_tum", || {
        let poses = read_tum_trajectory(&path).map_err(os_or_value)?;
        let n = poses.len();
        let flat: Vec<f64> = poses
            .iter()
            .flat_map(|p| {
                let t = p.world_from_camera.translation.vector;
                let q = p.world_from_camera.rotation.coords; // (i, j, k, w)
                [p.timestamp_s, t.x, t.y, t.z, q.x, q.y, q.z, q.w]
            })
            .collect();
        PyArray1::from_vec(py, flat).reshape(vec![n, 8])
    })
}

/// Reads a PLY mesh: (vertices, triangles, colors, normals).
#[pyfunction]
fn read_ply(py: Python<'_>, path: PathBuf) -> PyResult<MeshArrays<'_>> {
    guard("read_ply", || {
        let mesh = read_mesh(&path).map_err(os_or_value)?;
        mesh_to_arrays(py, mesh)
    })
}

/// Writes a mesh as binary little-endian (or ASCII) PLY.
#[pyfunction]
#[pyo3(signature = (path, vertices, triangles, colors=None, ascii=false))]
fn write_ply(
    path: PathBuf,
    vertices: &Bound<'_, PyAny>,
    triangles: &Bound<'_, PyAny>,
    colors: Option<&Bound<'_, PyAny>>,
    ascii: bool,
) -> PyResult<()> {
    guard("write_ply", || {
        let mesh = mesh_from_arrays(vertices, triangles, colors)?;
        let encoding = if ascii {
            PlyEncoding::Ascii
        } else {
            PlyEncoding::BinaryLittleEndian
        };
        write_mesh(&path, &mesh, encoding).map_err(os_or_value)
    })
}

/// Writes a mesh as binary glTF (GLB, y up: ENU is turned into glTF's frame).
#[pyfunction]
#[pyo3(signature = (path, vertices, triangles, colors=None, name="mesh"))]
fn write_glb_file(
    path: PathBuf,
    vertices: &Bound<'_, PyAny>,
    triangles: &Bound<'_, PyAny>,
    colors: Option<&Bound<'_, PyAny>>,
    name: &str,
) -> PyResult<()> {
    guard("write_glb", || {
        let mut mesh = mesh_from_arrays(vertices, triangles, colors)?;
        if mesh.normals.is_empty() {
            mesh.compute_vertex_normals();
        }
        write_glb(&path, &[GlbNode::new(name, &mesh)], &GlbOptions::default()).map_err(os_or_value)
    })
}

/// A TUM-layout RGB-D sequence folder (scarp_datasets::sequence::Sequence).
#[pyclass(module = "scarp._scarp", name = "Sequence")]
struct PySequence {
    sequence: Sequence,
}

#[pymethods]
impl PySequence {
    #[new]
    fn new(dir: PathBuf) -> PyResult<Self> {
        guard("read_sequence", || {
            let sequence = Sequence::open(&dir).map_err(os_or_value)?;
            Ok(Self { sequence })
        })
    }

    fn __len__(&self) -> usize {
        self.sequence.len()
    }

    /// (fx, fy, cx, cy, width, height).
    fn camera(&self) -> (f64, f64, f64, f64, u32, u32) {
        let c = &self.sequence.camera;
        (c.fx, c.fy, c.cx, c.cy, c.width, c.height)
    }

    /// Frame `index`: (timestamp_s, depth_m H×W float32, color H×W×3 uint8,
    /// world_from_camera estimate or None, ground truth or None).
    #[allow(clippy::type_complexity)]
    fn frame<'py>(
        &self,
        py: Python<'py>,
        index: usize,
    ) -> PyResult<(
        f64,
        Bound<'py, PyArrayDyn<f32>>,
        Bound<'py, PyArrayDyn<u8>>,
        Option<Bound<'py, PyArrayDyn<f64>>>,
        Option<Bound<'py, PyArrayDyn<f64>>>,
    )> {
        guard("Sequence.frame", || {
            let Some(entry) = self.sequence.entries.get(index) else {
                return Err(pyo3::exceptions::PyIndexError::new_err(format!(
                    "frame {index} out of range (the sequence has {})",
                    self.sequence.len()
                )));
            };
            let frame = py
                .detach(|| self.sequence.load_frame(index))
                .map_err(os_or_value)?;
            let (w, h) = (frame.width() as usize, frame.height() as usize);
            let depth = PyArray1::from_vec(py, frame.depth_m.into_vec()).reshape(vec![h, w])?;
            let color = PyArray1::from_vec(py, frame.rgb.into_vec().into_flattened())
                .reshape(vec![h, w, 3])?;
            let estimate = entry
                .world_from_camera_estimate
                .map(|p| pose_to_array(py, &p))
                .transpose()?;
            let truth = entry
                .world_from_camera_truth
                .map(|p| pose_to_array(py, &p))
                .transpose()?;
            Ok((frame.timestamp_s, depth, color, estimate, truth))
        })
    }
}

/// The native module.
#[pymodule]
fn _scarp(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyTsdfVolume>()?;
    m.add_class::<PyRgbdOdometry>()?;
    m.add_class::<PySequence>()?;
    m.add_function(wrap_pyfunction!(bundle_adjust_bal, m)?)?;
    m.add_function(wrap_pyfunction!(fragility, m)?)?;
    m.add_function(wrap_pyfunction!(eval_mesh, m)?)?;
    m.add_function(wrap_pyfunction!(eval_traj, m)?)?;
    m.add_function(wrap_pyfunction!(read_tum, m)?)?;
    m.add_function(wrap_pyfunction!(read_ply, m)?)?;
    m.add_function(wrap_pyfunction!(write_ply, m)?)?;
    m.add_function(wrap_pyfunction!(write_glb_file, m)?)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
