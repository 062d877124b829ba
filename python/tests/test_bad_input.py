"""Bad input raises ValueError with a message naming the argument; it never panics."""

from __future__ import annotations

import numpy as np
import pytest

import scarp

K = dict(fx=100.0, fy=100.0, cx=79.5, cy=59.5)


def frame():
    return np.full((120, 160), 2.0, np.float32), np.zeros((120, 160, 3), np.uint8), np.eye(4)


def test_wrong_depth_dtype():
    depth, color, pose = frame()
    with pytest.raises(ValueError, match=r"depth_m must be an H×W float32.*float64"):
        scarp.TsdfVolume().integrate(depth.astype(np.float64), color, world_from_camera=pose, **K)


def test_wrong_color_dtype_and_shape():
    depth, color, pose = frame()
    vol = scarp.TsdfVolume()
    with pytest.raises(ValueError, match="color must be an H×W×3 uint8"):
        vol.integrate(depth, color.astype(np.float32), world_from_camera=pose, **K)
    with pytest.raises(ValueError, match=r"matching depth_m \(120×160\)"):
        vol.integrate(depth, color[:60], world_from_camera=pose, **K)
    with pytest.raises(ValueError, match="color must be"):
        vol.integrate(depth, color[..., 0].copy(), world_from_camera=pose, **K)
    with pytest.raises(ValueError, match="must be a numpy array"):
        vol.integrate(depth, color.tolist(), world_from_camera=pose, **K)


def test_non_contiguous_array():
    depth, color, pose = frame()
    wide = np.full((120, 320), 2.0, np.float32)
    with pytest.raises(ValueError, match="C-contiguous"):
        scarp.TsdfVolume().integrate(wide[:, ::2], color, world_from_camera=pose, **K)
    with pytest.raises(ValueError, match="C-contiguous"):
        scarp.TsdfVolume().integrate(depth, color, world_from_camera=np.asfortranarray(np.diag([1.0, -1.0, -1.0, 1.0])), **K)


def test_nan_and_non_rigid_poses():
    depth, color, _ = frame()
    vol = scarp.TsdfVolume()
    pose = np.eye(4)
    pose[1, 3] = np.nan
    with pytest.raises(ValueError, match=r"world_from_camera has a non-finite entry at \[1, 3\]"):
        vol.integrate(depth, color, world_from_camera=pose, **K)
    with pytest.raises(ValueError, match="not a rotation"):
        vol.integrate(depth, color, world_from_camera=np.diag([2.0, 1.0, 1.0, 1.0]), **K)
    with pytest.raises(ValueError, match="4×4"):
        vol.integrate(depth, color, world_from_camera=np.eye(3), **K)
    with pytest.raises(ValueError, match="last row"):
        bad = np.eye(4)
        bad[3, 0] = 1.0
        vol.integrate(depth, color, world_from_camera=bad, **K)


def test_nan_depth_and_bad_intrinsics():
    depth, color, pose = frame()
    depth[3, 7] = np.nan
    with pytest.raises(ValueError, match=r"depth_m\[3, 7\]"):
        scarp.TsdfVolume().integrate(depth, color, world_from_camera=pose, **K)
    depth, color, pose = frame()
    with pytest.raises(ValueError):
        scarp.TsdfVolume().integrate(depth, color, world_from_camera=pose, fx=-1.0, fy=100.0, cx=1.0, cy=1.0)
    with pytest.raises(ValueError, match="finite"):
        scarp.TsdfVolume().integrate(depth, color, world_from_camera=pose, fx=float("nan"), fy=100.0, cx=1.0, cy=1.0)


def test_fragility_bad_meshes():
    with pytest.raises(ValueError, match="vertices must be"):
        scarp.fragility(np.zeros((4, 2), np.float32), np.zeros((1, 3), np.uint32))
    with pytest.raises(ValueError, match="triangles must be"):
        scarp.fragility(np.zeros((4, 3), np.float32), np.zeros((1, 3), np.float32))
    with pytest.raises(ValueError):
        # An index past the last vertex.
        scarp.fragility(np.zeros((3, 3), np.float32), np.array([[0, 1, 7]], np.uint32))
    with pytest.raises(ValueError):
        # An open mesh (one triangle) is not a solid.
        scarp.fragility(np.eye(3, dtype=np.float32), np.array([[0, 1, 2]], np.uint32))
    with pytest.raises(ValueError, match="azimuth_count"):
        from conftest import box_mesh

        v, t = box_mesh(0.4, 0.4, 1.0)
        scarp.fragility(v, t, azimuth_count=7)
    with pytest.raises(ValueError, match="unknown field"):
        scarp.fragility(np.zeros((3, 3), np.float32), np.zeros((0, 3), np.uint32), densty=1.0)


def test_odometry_bad_input():
    depth, color, pose = frame()
    odo = scarp.RgbdOdometry()
    with pytest.raises(ValueError, match="intrinsics"):
        odo.track(depth, color, (100.0, 100.0))
    bad = np.eye(4)
    bad[0, 0] = np.inf
    with pytest.raises(ValueError, match="prior has a non-finite entry"):
        odo.track(depth, color, (100.0, 100.0, 79.5, 59.5), prior=bad)


def test_files_that_do_not_exist():
    with pytest.raises(OSError):
        scarp.read_ply("/nonexistent/mesh.ply")
    with pytest.raises(OSError):
        scarp.bundle_adjust_bal("/nonexistent/problem.txt")
    with pytest.raises(OSError):
        scarp.read_sequence("/nonexistent/sequence")
