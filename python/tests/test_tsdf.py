"""TSDF fusion and meshing through Python."""

from __future__ import annotations

import numpy as np
import pytest

import scarp

INTRINSICS = dict(fx=100.0, fy=100.0, cx=79.5, cy=59.5)


def test_plane_at_two_metres_is_meshed_at_two_metres(plane_frames):
    vol = scarp.TsdfVolume(voxel_size_m=0.01, truncation_voxels=4.0)
    for depth, color, pose in plane_frames:
        stats = vol.integrate(depth, color, world_from_camera=pose, **INTRINSICS)
        assert stats["blocks_updated"] > 0
    mesh = vol.extract_mesh()
    assert mesh.vertices.dtype == np.float32 and mesh.vertices.shape[1] == 3
    assert mesh.triangles.dtype == np.uint32 and mesh.triangles.shape[1] == 3
    assert mesh.colors.dtype == np.uint8 and mesh.colors.shape == mesh.vertices.shape
    assert len(mesh) > 1000
    z = mesh.vertices[:, 2].astype(np.float64)
    print(f"plane: {len(z)} vertices, z mean {z.mean():.6f} m, min {z.min():.6f}, max {z.max():.6f}")
    assert abs(z.mean() - 2.0) <= 0.01
    assert np.all(np.abs(z - 2.0) <= 0.01)
    # The plane spans the union of the three views: x from about −1.65 to +1.65 m at 2 m.
    assert mesh.vertices[:, 0].min() < -1.5 and mesh.vertices[:, 0].max() > 1.5
    assert mesh.triangles.max() < len(mesh.vertices)


def test_roi_limits_allocation(plane_frames):
    depth, color, pose = plane_frames[1]
    full = scarp.TsdfVolume()
    full.integrate(depth, color, world_from_camera=pose, **INTRINSICS)
    boxed = scarp.TsdfVolume(roi="box:-0.2,-0.2,1.8,0.2,0.2,2.2")
    boxed.integrate(depth, color, world_from_camera=pose, **INTRINSICS)
    assert 0 < boxed.stats()["blocks"] < full.stats()["blocks"]
    verts = boxed.extract_mesh().vertices
    assert np.all(np.abs(verts[:, :2]) < 0.3)
    assert boxed.config["roi"]["kind"] == "box"


def test_mesh_files_round_trip(tmp_path, plane_frames):
    vol = scarp.TsdfVolume(voxel_size_m=0.02)
    for depth, color, pose in plane_frames:
        vol.integrate(depth, color, world_from_camera=pose, **INTRINSICS)
    mesh = vol.extract_mesh()
    mesh.write_ply(tmp_path / "plane.ply")
    mesh.write_glb(tmp_path / "plane.glb")
    back = scarp.read_ply(tmp_path / "plane.ply")
    np.testing.assert_array_equal(back.vertices, mesh.vertices)
    np.testing.assert_array_equal(back.triangles, mesh.triangles)
    np.testing.assert_array_equal(back.colors, mesh.colors)
    glb = (tmp_path / "plane.glb").read_bytes()
    assert glb[:4] == b"glTF" and int.from_bytes(glb[8:12], "little") == len(glb)
    # A mesh built in Python with float64 vertices and int64 indices writes too.
    box = scarp.Mesh(
        vertices=np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], np.float64),
        triangles=np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]], np.int64),
        colors=np.full((4, 3), 200, np.uint8),
    )
    box.write_ply(tmp_path / "tet.ply", ascii=True)
    assert len(scarp.read_ply(tmp_path / "tet.ply")) == 4
    with pytest.raises(ValueError, match="colors has 3 rows but there are 4 vertices"):
        scarp.Mesh(box.vertices, box.triangles, box.colors[:3]).write_glb(tmp_path / "bad.glb")


def test_unknown_config_key_is_a_value_error():
    with pytest.raises(ValueError, match="voxel_sise_m"):
        scarp.TsdfVolume(voxel_sise_m=0.01)
    with pytest.raises(ValueError, match="voxel_size_m"):
        scarp.TsdfVolume(voxel_size_m=-1.0)
    with pytest.raises(ValueError, match="region of interest"):
        scarp.TsdfVolume(roi="sphere:1,2,3")


def test_meshing_can_require_observations(plane_frames):
    vol = scarp.TsdfVolume()
    for depth, color, pose in plane_frames:
        vol.integrate(depth, color, world_from_camera=pose, **INTRINSICS)
    every = vol.extract_mesh()
    # The middle of the plane is seen by all three frames; its sides by fewer.
    seen_by_three = vol.extract_mesh(min_observations=3)
    assert 0 < len(seen_by_three.triangles) < len(every.triangles)
    assert len(vol.extract_mesh(min_observations=4).triangles) == 0
    for bad in (-1, 256, True):
        with pytest.raises(ValueError, match="min_observations"):
            vol.extract_mesh(min_observations=bad)
