"""scarp: TSDF fusion, RGBD odometry, bundle adjustment, fragility analysis and evaluation of
rock maps, with numpy arrays in and out.

Conventions (those of the Rust crates):

- World is local ENU (x east, y north, z up), metres. The camera is OpenCV: x right, y down,
  z forward; pixel (u, v) is (column, row) with pixel centres at integers.
- Poses are 4×4 float64 arrays named by what they map: ``world_from_camera`` takes a point in
  camera coordinates to world coordinates.
- Depth is an H×W float32 array of metres along the camera z axis; 0 means no measurement.
- Colour is an H×W×3 uint8 sRGB array.

Arrays are borrowed without a copy where the layout allows (C-contiguous, the right dtype);
anything else raises ``ValueError`` with a message naming the argument, as do NaN poses and
unknown configuration keys. Files that cannot be read or written raise ``OSError``.

Example::

    import numpy as np, scarp
    vol = scarp.TsdfVolume(voxel_size_m=0.01)
    depth = np.full((120, 160), 2.0, np.float32)          # a wall 2 m ahead
    color = np.zeros((120, 160, 3), np.uint8)
    vol.integrate(depth, color, fx=100, fy=100, cx=79.5, cy=59.5, world_from_camera=np.eye(4))
    mesh = vol.extract_mesh()
    print(mesh.vertices[:, 2].mean())                      # ≈ 2.0
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass
from typing import Any, Dict, Iterator, Optional, Tuple, Union

import numpy as np

from . import _scarp

__all__ = [
    "Mesh",
    "TsdfVolume",
    "RgbdOdometry",
    "Frame",
    "SequenceReader",
    "read_sequence",
    "bundle_adjust_bal",
    "fragility",
    "eval_mesh",
    "eval_traj",
    "read_ply",
    "read_tum",
]

__version__: str = _scarp.__version__

PathLike = Union[str, "os.PathLike[str]"]


def _floats(name: str, values: Dict[str, Any]) -> None:
    for key, v in values.items():
        if isinstance(v, bool) or not isinstance(v, (int, float, np.floating, np.integer)):
            raise ValueError(f"{name}: `{key}` must be a number, got {type(v).__name__}")
        if not math.isfinite(float(v)):
            raise ValueError(f"{name}: `{key}` must be finite, got {v}")


def _pose(value: Any, name: str) -> np.ndarray:
    """A 4×4 pose as float64 (float32 is widened: 16 numbers; other dtypes are refused)."""
    if isinstance(value, np.ndarray) and value.dtype == np.float32:
        value = value.astype(np.float64)
    return value


@dataclass
class Mesh:
    """A triangle mesh in world ENU metres.

    Attributes:
        vertices: N×3 float32 positions, metres (float64 is accepted when writing).
        triangles: M×3 uint32 vertex indices, counter-clockwise seen from outside (any integer
            dtype is accepted when writing).
        colors: N×3 uint8 sRGB vertex colours (zeros when the source had none).
        normals: N×3 float32 unit vertex normals, or None.
    """

    vertices: np.ndarray
    triangles: np.ndarray
    colors: np.ndarray
    normals: Optional[np.ndarray] = None

    @classmethod
    def _from_native(cls, arrays: Tuple[Any, Any, Any, Any]) -> "Mesh":
        vertices, triangles, colors, normals = arrays
        if colors is None:
            colors = np.zeros((vertices.shape[0], 3), np.uint8)
        return cls(vertices=vertices, triangles=triangles, colors=colors, normals=normals)

    def __len__(self) -> int:
        """Number of triangles."""
        return int(self.triangles.shape[0])

    def write_ply(self, path: PathLike, ascii: bool = False) -> None:
        """Writes the mesh (with colours) as PLY, binary little-endian unless ``ascii``.

        The file is written to a temporary name and renamed, so a failure leaves no half file.

        Raises:
            ValueError: the arrays are malformed (dtype, shape, index out of range).
            OSError: the file cannot be written.
        """
        v, t = _mesh_arrays(self.vertices, self.triangles, "write_ply")
        _scarp.write_ply(os.fspath(path), v, t, self.colors, ascii)

    def write_glb(self, path: PathLike, name: str = "mesh") -> None:
        """Writes the mesh as binary glTF 2.0 (GLB). glTF is y-up: ENU (x, y, z) is stored as
        (x, z, −y), as every scarp GLB is.

        Raises:
            ValueError: the arrays are malformed.
            OSError: the file cannot be written.
        """
        v, t = _mesh_arrays(self.vertices, self.triangles, "write_glb")
        _scarp.write_glb_file(os.fspath(path), v, t, self.colors, name)


def read_ply(path: PathLike) -> Mesh:
    """Reads a PLY mesh (ASCII or binary).

    Raises:
        OSError: the file cannot be opened.
        ValueError: the file is not a valid PLY mesh.
    """
    return Mesh._from_native(_scarp.read_ply(os.fspath(path)))


class TsdfVolume:
    """A voxel-hashed truncated signed distance volume (8³-voxel blocks, allocated only where
    depth lands inside the region of interest), with colour.

    Args:
        voxel_size_m: voxel edge, metres (default 0.01).
        truncation_voxels: truncation distance in voxels (default 4).
        roi: region of interest, ``"cyl:x,y,z_min,z_max,r"`` or ``"box:x0,y0,z0,x1,y1,z1"``
            (world metres), or None for everywhere.
        **config: any other field of the Rust ``TsdfConfig`` (``max_weight``, ``min_depth_m``,
            ``max_depth_m``, ``min_block_support``).

    Raises:
        ValueError: a value out of range or an unknown keyword.
    """

    def __init__(
        self,
        voxel_size_m: float = 0.01,
        truncation_voxels: float = 4.0,
        roi: Optional[str] = None,
        **config: Any,
    ) -> None:
        _floats("TsdfVolume", {"voxel_size_m": voxel_size_m, "truncation_voxels": truncation_voxels})
        if roi is not None and not isinstance(roi, str):
            raise ValueError(
                "roi must be None or a string 'cyl:x,y,z_min,z_max,r' / 'box:x0,y0,z0,x1,y1,z1'"
            )
        fields = dict(config, voxel_size_m=float(voxel_size_m), truncation_voxels=float(truncation_voxels))
        self._native = _scarp.TsdfVolume(json.dumps(fields), roi)

    def integrate(
        self,
        depth_m: np.ndarray,
        color: np.ndarray,
        *,
        fx: float,
        fy: float,
        cx: float,
        cy: float,
        world_from_camera: np.ndarray,
    ) -> Dict[str, int]:
        """Fuses one RGBD frame seen at ``world_from_camera``.

        Args:
            depth_m: H×W float32, metres along the camera z axis; 0 = no data.
            color: H×W×3 uint8 sRGB.
            fx, fy, cx, cy: pinhole intrinsics, pixels.
            world_from_camera: 4×4 float64 rigid transform (float32 is accepted and widened).

        Returns:
            ``{"blocks_updated": int, "blocks_allocated": int}``.

        Raises:
            ValueError: wrong dtype or shape, non-contiguous arrays, negative or NaN depth,
                bad intrinsics, or a pose that is not finite and rigid.
        """
        _floats("integrate", {"fx": fx, "fy": fy, "cx": cx, "cy": cy})
        stats = self._native.integrate(
            depth_m, color, float(fx), float(fy), float(cx), float(cy), _pose(world_from_camera, "world_from_camera")
        )
        return json.loads(stats)

    def extract_mesh(
        self, min_weight: float = 0.0, min_component_triangles: int = 0, min_observations: int = 0
    ) -> Mesh:
        """Marching cubes over every allocated block.

        Args:
            min_weight: only voxels whose weight (sum of 1/z^2, z in metres) exceeds this take part.
            min_component_triangles: drop connected components with fewer triangles
                (``scarp map`` uses 200).
            min_observations: only voxels observed by at least this many frames take part
                (0 to 255; Open3D's ``weight_threshold`` t keeps what t + 1 keeps here).
        """
        for name, value, top in (
            ("min_component_triangles", min_component_triangles, None),
            ("min_observations", min_observations, 255),
        ):
            if isinstance(value, bool) or int(value) < 0 or (top is not None and int(value) > top):
                bound = f" at most {top}" if top is not None else ""
                raise ValueError(f"{name} must be a non-negative integer{bound}")
        return Mesh._from_native(
            self._native.extract_mesh(float(min_weight), int(min_component_triangles), int(min_observations))
        )

    def stats(self) -> Dict[str, int]:
        """Blocks and voxels allocated (the Rust ``VolumeStats``)."""
        return json.loads(self._native.stats())

    @property
    def config(self) -> Dict[str, Any]:
        """The full configuration in force (every ``TsdfConfig`` field)."""
        return json.loads(self._native.config_json())

    def clear(self) -> None:
        """Empties the volume."""
        self._native.clear()


def _intrinsics(intrinsics: Any) -> Tuple[float, float, float, float]:
    """(fx, fy, cx, cy) from a 4-sequence, a dict with those keys, or a 3×3 K matrix."""
    if isinstance(intrinsics, dict):
        try:
            values = [intrinsics[k] for k in ("fx", "fy", "cx", "cy")]
        except KeyError as e:
            raise ValueError(f"intrinsics lacks {e}") from None
    else:
        a = np.asarray(intrinsics, dtype=np.float64)
        if a.shape == (3, 3):
            values = [a[0, 0], a[1, 1], a[0, 2], a[1, 2]]
        elif a.shape == (4,):
            values = list(a)
        else:
            raise ValueError(
                f"intrinsics must be (fx, fy, cx, cy), a dict or a 3×3 K matrix, got shape {a.shape}"
            )
    fx, fy, cx, cy = (float(v) for v in values)
    _floats("intrinsics", {"fx": fx, "fy": fy, "cx": cx, "cy": cy})
    return fx, fy, cx, cy


class RgbdOdometry:
    """Frame-to-frame RGBD odometry: coarse-to-fine Gauss–Newton on SE(3) over a photometric and
    a point-to-plane residual with robust weights.

    Each :meth:`track` call tracks the frame against the previous one and returns the frame's
    ``world_from_camera``, chained from ``world_from_first_camera`` (default identity).

    Args:
        world_from_first_camera: 4×4 pose given to the first frame.
        **config: fields of the Rust ``OdometryConfig`` (``levels``, ``max_iterations``, ...).

    Raises:
        ValueError: a value out of range or an unknown keyword.
    """

    def __init__(self, world_from_first_camera: Optional[np.ndarray] = None, **config: Any) -> None:
        first = None if world_from_first_camera is None else _pose(world_from_first_camera, "world_from_first_camera")
        self._native = _scarp.RgbdOdometry(json.dumps(config), first)
        self.last_details: Dict[str, Any] = {}

    def track(
        self,
        depth_m: np.ndarray,
        color: np.ndarray,
        intrinsics: Any,
        prior: Optional[np.ndarray] = None,
    ) -> Tuple[np.ndarray, str]:
        """Tracks one frame.

        Args:
            depth_m: H×W float32 metres (0 = no data).
            color: H×W×3 uint8.
            intrinsics: (fx, fy, cx, cy), a dict with those keys, or a 3×3 K matrix.
            prior: predicted 4×4 ``world_from_camera`` of this frame (e.g. GPS/IMU); the initial
                guess of the solve and the fallback when tracking fails. Default: the previous
                frame's pose.

        Returns:
            ``(world_from_camera, status)``: status is ``"first_frame"``, ``"ok"``, or
            ``"failed: <reason>"`` (the pose is then the prior, or the previous pose). Inlier
            ratio, correspondences and iterations are in :attr:`last_details`.

        Raises:
            ValueError: malformed arrays, bad intrinsics, a non-rigid or NaN prior, or a frame
                whose size differs from the previous one.
        """
        fx, fy, cx, cy = _intrinsics(intrinsics)
        p = None if prior is None else _pose(prior, "prior")
        pose, status, details = self._native.track(depth_m, color, fx, fy, cx, cy, p)
        self.last_details = json.loads(details)
        return pose, status

    def reset(self) -> None:
        """Forgets the previous frame; the next one starts a new trajectory."""
        self._native.reset()


def bundle_adjust_bal(
    path: PathLike, *, max_iterations: int = 50, threads: Optional[int] = None, **config: Any
) -> Dict[str, Any]:
    """Bundle-adjusts a BAL ("Bundle Adjustment in the Large") problem with Levenberg–Marquardt
    and the Schur complement, as ``scarp ba --json`` does.

    Args:
        path: the BAL text file.
        max_iterations: accepted and rejected steps.
        threads: worker threads (default all cores; the result does not depend on it).
        **config: other fields of the Rust ``LmConfig``, e.g. ``loss={"kind": "huber",
            "delta_px": 1.0}``.

    Returns:
        The dictionary of ``scarp ba --json``: ``initial_cost``, ``final_cost``, ``iterations``,
        ``costs`` (``costs[k]`` after iteration k), ``log``, ``termination``, ``cameras``,
        ``points``, ``observations``, ``seconds``, ...

    Raises:
        OSError: the file cannot be opened. ValueError: a malformed file or configuration.
    """
    fields = dict(config, max_iterations=int(max_iterations))
    return json.loads(_scarp.bundle_adjust_bal(os.fspath(path), json.dumps(fields), threads))


def _mesh_arrays(vertices: Any, triangles: Any, what: str) -> Tuple[np.ndarray, np.ndarray]:
    """Vertices as float32 (float64 narrowed) and triangles as uint32 (any integer dtype, range
    checked); other dtypes raise ValueError."""
    v = vertices
    if isinstance(v, np.ndarray) and v.dtype == np.float64:
        v = v.astype(np.float32)
    t = triangles
    if isinstance(t, np.ndarray) and np.issubdtype(t.dtype, np.integer) and t.dtype != np.uint32:
        if t.size and (t.min() < 0 or t.max() > np.iinfo(np.uint32).max):
            raise ValueError(f"{what}: triangle indices must be non-negative")
        t = t.astype(np.uint32)
    return v, t


def fragility(
    vertices: np.ndarray,
    triangles: np.ndarray,
    *,
    contact_height_m: Optional[float] = None,
    scan: bool = False,
    **config: Any,
) -> Dict[str, Any]:
    """The fragility of a rock: its smallest rocking angle α_min and the toppling acceleration
    g·tan(α_min), as ``scarp fragility --json`` (and the mission's ``fragility.json``).

    Args:
        vertices: N×3 (float32, or float64 narrowed) metres, z up unless ``up`` is given.
        triangles: M×3 integer vertex indices; the mesh must be closed and consistently wound
            (or an open scan with ``scan=True``).
        contact_height_m: the contact plane's height; default: found automatically (the neck of
            the area profile, or the rock's lowest points).
        scan: the mesh is an open scan standing on its support: cut, close and extrapolate the
            contact, widening the α_min interval over the contact readings.
        **config: fields of the Rust ``FragilityConfig``: ``up``, ``density_kg_m3``,
            ``azimuth_count``, ``g_m_s2``, ``uncertainty={...}``, ``scan={...}``, ...

    Returns:
        The keys of ``fragility.json``: ``alpha_min_deg``, ``alpha_min_low_deg``,
        ``alpha_min_high_deg``, ``alpha_min_azimuth_deg``, ``alpha_deg`` (α(θ) per azimuth),
        ``center_of_mass``, ``contact_polygon``, ``toppling_pga_g``, ``mass_kg``, ...

    Raises:
        ValueError: malformed arrays, an open or non-manifold mesh, a centre of mass outside
            the contact, or a bad configuration.
    """
    v, t = _mesh_arrays(vertices, triangles, "fragility")
    if contact_height_m is not None:
        _floats("fragility", {"contact_height_m": contact_height_m})
        contact_height_m = float(contact_height_m)
    return json.loads(_scarp.fragility(v, t, json.dumps(config), contact_height_m, bool(scan)))


MeshLike = Union[Mesh, PathLike, Tuple[np.ndarray, np.ndarray]]


def _as_mesh(value: MeshLike, what: str) -> Tuple[np.ndarray, np.ndarray]:
    if isinstance(value, Mesh):
        return _mesh_arrays(value.vertices, value.triangles, what)
    if isinstance(value, (str, os.PathLike)):
        m = read_ply(value)
        return m.vertices, m.triangles
    if isinstance(value, tuple) and len(value) == 2:
        return _mesh_arrays(value[0], value[1], what)
    raise ValueError(f"{what} must be a Mesh, a PLY path or a (vertices, triangles) tuple")


def eval_mesh(
    mesh: MeshLike,
    gt: MeshLike,
    *,
    tau_m: float = 0.01,
    crop_to_gt_m: Optional[float] = None,
    samples_per_m2: float = 40_000.0,
    seed: int = 0,
) -> Dict[str, Any]:
    """Scores a reconstruction against a ground-truth mesh, as ``scarp eval mesh --json``:
    accuracy and completeness (mean, median, p90, metres), precision, recall and F-score at
    ``tau_m``.

    Args:
        mesh, gt: a :class:`Mesh`, a PLY path, or a (vertices, triangles) tuple.
        tau_m: precision/recall threshold, metres.
        crop_to_gt_m: ignore reconstruction farther than this from the ground truth's bounding
            box, metres.
        samples_per_m2: surface samples per square metre on each mesh.
        seed: seed of the surface sampling.
    """
    v, t = _as_mesh(mesh, "mesh")
    gv, gtri = _as_mesh(gt, "gt")
    config = {"tau_m": tau_m, "crop_to_gt_m": crop_to_gt_m, "samples_per_m2": samples_per_m2, "seed": seed}
    return json.loads(_scarp.eval_mesh(v, t, gv, gtri, json.dumps(config)))


def read_tum(path: PathLike) -> np.ndarray:
    """Reads a TUM trajectory file (``t tx ty tz qx qy qz qw``) as an N×8 float64 array."""
    return _scarp.read_tum(os.fspath(path))


def _as_trajectory(value: Union[PathLike, np.ndarray], what: str) -> np.ndarray:
    if isinstance(value, (str, os.PathLike)):
        return read_tum(value)
    return value


def eval_traj(
    gt: Union[PathLike, np.ndarray],
    est: Union[PathLike, np.ndarray],
    *,
    align: str = "se3",
    max_dt_s: float = 0.02,
) -> Dict[str, Any]:
    """Trajectory error as the TUM RGB-D benchmark defines it, as ``scarp eval traj --json``:
    ATE (RMSE, mean, median, max, metres) after alignment and RPE.

    Args:
        gt, est: TUM files or N×8 float64 arrays (t tx ty tz qx qy qz qw).
        align: ``"se3"``, ``"sim3"`` or ``"none"``.
        max_dt_s: largest timestamp difference of an associated pair, seconds.
    """
    config = {"alignment": align, "max_dt_s": max_dt_s}
    return json.loads(_scarp.eval_traj(_as_trajectory(gt, "gt"), _as_trajectory(est, "est"), json.dumps(config)))


@dataclass
class Frame:
    """One frame of a recorded sequence.

    Attributes:
        index: position in the sequence.
        timestamp_s: capture time, seconds (the sequence's clock).
        depth_m: H×W float32 metres (0 = no data).
        color: H×W×3 uint8.
        world_from_camera_estimate: the state estimator's 4×4 pose (``estimate.txt``), or None.
        world_from_camera_truth: the ground-truth 4×4 pose (``groundtruth.txt``), or None.
    """

    index: int
    timestamp_s: float
    depth_m: np.ndarray
    color: np.ndarray
    world_from_camera_estimate: Optional[np.ndarray]
    world_from_camera_truth: Optional[np.ndarray]

    @property
    def pose(self) -> Optional[np.ndarray]:
        """The best pose known: the estimate, else the ground truth."""
        if self.world_from_camera_estimate is not None:
            return self.world_from_camera_estimate
        return self.world_from_camera_truth


class SequenceReader:
    """A TUM-layout RGB-D folder (``rgb/``, ``depth/``, ``rgb.txt``, ``depth.txt``,
    ``camera.toml``, optional ``groundtruth.txt`` and ``estimate.txt``). Iterating loads the
    frames one at a time."""

    def __init__(self, directory: PathLike) -> None:
        self._native = _scarp.Sequence(os.fspath(directory))
        fx, fy, cx, cy, w, h = self._native.camera()
        #: Intrinsics: fx, fy, cx, cy (pixels), width, height.
        self.camera: Dict[str, float] = {"fx": fx, "fy": fy, "cx": cx, "cy": cy, "width": w, "height": h}

    def __len__(self) -> int:
        return len(self._native)

    def __getitem__(self, index: int) -> Frame:
        if index < 0:
            index += len(self)
        t, depth, color, estimate, truth = self._native.frame(index)
        return Frame(index, t, depth, color, estimate, truth)

    def __iter__(self) -> Iterator[Frame]:
        for i in range(len(self)):
            yield self[i]


def read_sequence(directory: PathLike) -> SequenceReader:
    """Opens a TUM-layout RGB-D sequence folder; iterate it for :class:`Frame` objects.

    Raises:
        OSError: the folder or a list file cannot be read.
        ValueError: a malformed list, camera file or pose.
    """
    return SequenceReader(directory)
