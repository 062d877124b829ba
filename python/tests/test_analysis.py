"""Fragility, bundle adjustment, odometry, sequences and evaluation through Python."""

from __future__ import annotations

import math
import subprocess
from pathlib import Path

import numpy as np
import pytest

import scarp
from conftest import REPO, SHARED_REAL, box_mesh, scarp_binary

BAL = REPO / "slam" / "tests" / "data" / "bal-ladybug-problem-49-7776-pre-shrink-1800.txt"


def test_box_alpha_min_is_atan_of_half_width_over_com_height():
    v, t = box_mesh(0.4, 0.4, 1.0)
    report = scarp.fragility(v, t)
    expected = math.degrees(math.atan(0.4))  # atan(0.2 m / 0.5 m)
    print(f"box: alpha_min {report['alpha_min_deg']:.6f}° (expected {expected:.6f}°), "
          f"interval [{report['alpha_min_low_deg']:.4f}, {report['alpha_min_high_deg']:.4f}]°")
    assert abs(report["alpha_min_deg"] - expected) <= 0.05
    assert report["alpha_min_low_deg"] <= report["alpha_min_deg"] <= report["alpha_min_high_deg"]
    # The keys of fragility.json.
    for key in ("alpha_deg", "center_of_mass", "contact_polygon", "toppling_pga_g", "mass_kg", "alpha_interval"):
        assert key in report
    assert len(report["alpha_deg"]) == 360
    np.testing.assert_allclose(report["center_of_mass"], [0.0, 0.0, 0.5], atol=1e-9)
    assert report["mass_kg"] == pytest.approx(0.16 * 2650.0, rel=1e-6)
    assert report["toppling_pga_g"] == pytest.approx(0.4, abs=1e-3)
    # Configuration keys pass through to the Rust FragilityConfig.
    light = scarp.fragility(v.astype(np.float32), t.astype(np.uint32), density_kg_m3=1000.0, azimuth_count=36)
    assert light["mass_kg"] == pytest.approx(160.0, rel=1e-6)
    assert len(light["alpha_deg"]) == 36


def test_box_with_given_contact_height():
    v, t = box_mesh(0.4, 0.4, 1.0)
    # The part above z = 0.5 is a 0.4 × 0.4 × 0.5 box: α_min = atan(0.2 / 0.25).
    report = scarp.fragility(v, t, contact_height_m=0.5)
    assert report["alpha_min_deg"] == pytest.approx(math.degrees(math.atan(0.8)), abs=0.05)


def test_bundle_adjust_bal_matches_its_own_costs():
    result = scarp.bundle_adjust_bal(BAL, max_iterations=10, threads=1)
    assert result["iterations"] <= 10
    assert len(result["costs"]) == result["iterations"] + 1
    assert result["costs"][0] == pytest.approx(result["initial_cost"])
    assert result["final_cost"] < 0.1 * result["initial_cost"]
    assert result["cameras"] > 0 and result["points"] > 0


def test_bundle_adjust_bal_is_the_cli_figure(tmp_path):
    binary = scarp_binary()
    if binary is None:
        pytest.skip("no scarp binary (set SCARP_BIN or build target/*/scarp)")
    import json

    out = subprocess.run([str(binary), "ba", str(BAL), "--max-iterations", "10", "--threads", "1", "--json"],
                         check=True, capture_output=True, text=True).stdout
    cli = json.loads(out)
    py = scarp.bundle_adjust_bal(BAL, max_iterations=10, threads=1)
    assert py["costs"] == cli["costs"]
    assert py["iterations"] == cli["iterations"]


def test_odometry_recovers_a_small_motion():
    # A textured, slanted scene: a plane z = 2 + 0.3·x with a sinusoidal texture, rendered by
    # ray casting from two cameras 2 cm apart.
    h, w, f = 120, 160, 100.0
    cx, cy = (w - 1) / 2, (h - 1) / 2

    def render(tx: float):
        u, v = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
        dx, dy = (u - cx) / f, (v - cy) / f
        # Camera at (tx, 0, 0) looking along +z: point = (tx + z·dx, z·dy, z) on z = 2 + 0.3·x.
        z = (2.0 + 0.3 * tx) / (1.0 - 0.3 * dx)
        x, y = tx + z * dx, z * dy
        tex = 128 + 60 * np.sin(x * 25) + 50 * np.cos(y * 31)
        color = np.repeat(np.clip(tex, 0, 255).astype(np.uint8)[..., None], 3, axis=-1)
        return z.astype(np.float32), np.ascontiguousarray(color)

    odo = scarp.RgbdOdometry()
    d0, c0 = render(0.0)
    pose0, status0 = odo.track(d0, c0, (f, f, cx, cy))
    assert status0 == "first_frame"
    np.testing.assert_array_equal(pose0, np.eye(4))
    d1, c1 = render(0.02)
    pose1, status1 = odo.track(d1, c1, np.array([[f, 0, cx], [0, f, cy], [0, 0, 1]]))
    assert status1 == "ok", odo.last_details
    assert pose1.shape == (4, 4) and pose1.dtype == np.float64
    assert abs(pose1[0, 3] - 0.02) < 0.004, pose1
    assert abs(pose1[1, 3]) < 0.004 and abs(pose1[2, 3]) < 0.004


def test_eval_traj_and_mesh(tmp_path):
    rng = np.random.default_rng(0)
    t = np.arange(20) * 0.1
    gt = np.zeros((20, 8))
    gt[:, 0] = t
    gt[:, 1] = t  # moving along x
    gt[:, 7] = 1.0
    est = gt.copy()
    est[:, 1:4] += rng.normal(0, 0.01, (20, 3))
    metrics = scarp.eval_traj(gt, est, align="none")
    assert metrics["pairs"] == 20
    assert 0.005 < metrics["ate_rmse_m"] < 0.03
    path = tmp_path / "gt.txt"
    np.savetxt(path, gt, fmt="%.6f")
    assert scarp.eval_traj(path, path)["ate_rmse_m"] == pytest.approx(0.0, abs=1e-9)
    with pytest.raises(ValueError, match="unknown variant `affine`"):
        scarp.eval_traj(gt, est, align="affine")

    v, tri = box_mesh(0.4, 0.4, 1.0)
    shifted = v.copy()
    shifted[:, 0] += 0.005
    scores = scarp.eval_mesh((shifted, tri), (v, tri), tau_m=0.01)
    assert scores["fscore"] > 0.95
    assert scarp.eval_mesh((v, tri), (v, tri), tau_m=0.01)["accuracy_mean_m"] < 1e-6


REDKITCHEN = SHARED_REAL / "7scenes_redkitchen_50"


@pytest.mark.skipif(not REDKITCHEN.is_dir(), reason="../shared/data/real/7scenes_redkitchen_50 is absent")
def test_redkitchen_through_python_matches_scarp_map(tmp_path):
    seq = scarp.read_sequence(REDKITCHEN)
    assert len(seq) == 50
    cam = seq.camera
    vol = scarp.TsdfVolume(voxel_size_m=0.01)
    times = []
    for frame in seq:
        assert frame.depth_m.dtype == np.float32 and frame.depth_m.shape == (480, 640)
        assert frame.color.shape == (480, 640, 3)
        assert frame.world_from_camera_truth is not None
        times.append(frame.timestamp_s)
        vol.integrate(frame.depth_m, frame.color, fx=cam["fx"], fy=cam["fy"], cx=cam["cx"], cy=cam["cy"],
                      world_from_camera=frame.world_from_camera_truth)
    assert times == sorted(times)
    mesh = vol.extract_mesh(min_component_triangles=200)
    print(f"redkitchen through Python: {len(mesh.vertices)} vertices, {len(mesh)} triangles")
    assert len(mesh) > 50_000

    binary = scarp_binary()
    if binary is None:
        pytest.skip("no scarp binary to compare with (set SCARP_BIN or build target/*/scarp)")
    subprocess.run([str(binary), "map", str(REDKITCHEN), "--poses", "groundtruth", "--voxel", "0.01",
                    "--out", str(tmp_path / "map")], check=True, capture_output=True)
    cli = scarp.read_ply(tmp_path / "map" / "mesh.ply")
    # The same library path: the same mesh, vertex for vertex.
    assert cli.vertices.shape == mesh.vertices.shape and cli.triangles.shape == mesh.triangles.shape
    np.testing.assert_allclose(cli.vertices, mesh.vertices, atol=1e-6)
    np.testing.assert_array_equal(cli.triangles, mesh.triangles)
    scores = scarp.eval_mesh(mesh, cli, tau_m=0.01)
    assert scores["fscore"] > 0.999


def _mission_dir():
    import os

    d = os.environ.get("SCARP_MISSION_DIR")
    return Path(d) if d else None


@pytest.mark.skipif(_mission_dir() is None, reason="SCARP_MISSION_DIR (a finished `scarp simulate` folder) not set")
def test_fragility_of_a_mission_mesh_reproduces_its_fragility_json():
    import json

    targets = sorted((_mission_dir() / "targets").glob("*/fragility.json"))
    if not targets:
        pytest.skip("the mission analysed no target")
    for path in targets:
        mesh = scarp.read_ply(path.parent / "mesh.ply")
        report = scarp.fragility(mesh.vertices, mesh.triangles, scan=True)
        written = json.loads(path.read_text())
        assert set(report) == set(written)
        for key in ("alpha_min_deg", "alpha_min_low_deg", "alpha_min_high_deg", "alpha_min_azimuth_deg"):
            assert report[key] == pytest.approx(written[key], abs=1e-6), key
        print(f"{path.parent.name}: α_min {report['alpha_min_deg']:.3f}° "
              f"[{report['alpha_min_low_deg']:.3f}, {report['alpha_min_high_deg']:.3f}]° as in fragility.json")


TUM_PAIR = SHARED_REAL / "tum_fr1_xyz_pair"


@pytest.mark.skipif(not TUM_PAIR.is_dir(), reason="../shared/data/real/tum_fr1_xyz_pair is absent")
def test_odometry_on_a_real_tum_pair_matches_truth_and_the_cli(tmp_path):
    seq = scarp.read_sequence(TUM_PAIR)
    f0, f1 = seq[0], seq[1]
    cam = seq.camera
    intrinsics = (cam["fx"], cam["fy"], cam["cx"], cam["cy"])
    odo = scarp.RgbdOdometry(world_from_first_camera=f0.world_from_camera_truth)
    assert odo.track(f0.depth_m, f0.color, intrinsics)[1] == "first_frame"
    pose, status = odo.track(f1.depth_m, f1.color, intrinsics)
    assert status == "ok", odo.last_details
    truth_rel = np.linalg.inv(f0.world_from_camera_truth) @ f1.world_from_camera_truth
    est_rel = np.linalg.inv(f0.world_from_camera_truth) @ pose
    t_err = np.linalg.norm(truth_rel[:3, 3] - est_rel[:3, 3])
    r = truth_rel[:3, :3].T @ est_rel[:3, :3]
    r_err = math.degrees(math.acos(min(1.0, max(-1.0, (np.trace(r) - 1) / 2))))
    print(f"TUM pair: motion {np.linalg.norm(truth_rel[:3, 3]) * 1e3:.1f} mm, "
          f"error {t_err * 1e3:.1f} mm, {r_err:.3f}°")
    assert t_err < 0.01 and r_err < 0.5

    binary = scarp_binary()
    if binary is None:
        pytest.skip("no scarp binary to compare with")
    subprocess.run([str(binary), "odometry", str(TUM_PAIR), "--out", str(tmp_path / "odo")],
                   check=True, capture_output=True)
    cli = scarp.read_tum(tmp_path / "odo" / "trajectory.txt")
    np.testing.assert_allclose(pose[:3, 3], cli[1, 1:4], atol=1e-6)


def test_eval_mesh_and_traj_are_the_cli_figures(tmp_path):
    import json

    binary = scarp_binary()
    if binary is None:
        pytest.skip("no scarp binary (set SCARP_BIN or build target/*/scarp)")
    v, t = box_mesh(0.4, 0.4, 1.0)
    gt = scarp.Mesh(v.astype(np.float32), t.astype(np.uint32), np.zeros((8, 3), np.uint8))
    moved = scarp.Mesh((v + [0.004, -0.003, 0.002]).astype(np.float32), t.astype(np.uint32), gt.colors)
    gt.write_ply(tmp_path / "gt.ply")
    moved.write_ply(tmp_path / "mesh.ply")
    cli = json.loads(subprocess.run(
        [str(binary), "eval", "mesh", "--gt", str(tmp_path / "gt.ply"), "--mesh", str(tmp_path / "mesh.ply"),
         "--tau", "0.005", "--json"], check=True, capture_output=True, text=True).stdout)
    py = scarp.eval_mesh(tmp_path / "mesh.ply", tmp_path / "gt.ply", tau_m=0.005)
    _assert_same_figures(py, cli)

    rng = np.random.default_rng(1)
    n = 30
    gt_rows = np.zeros((n, 8))
    gt_rows[:, 0] = np.arange(n) * 0.05
    gt_rows[:, 1] = np.linspace(0, 2, n)
    gt_rows[:, 7] = 1.0
    est_rows = gt_rows.copy()
    est_rows[:, 1:4] += rng.normal(0, 0.02, (n, 3))
    np.savetxt(tmp_path / "gt.txt", gt_rows, fmt="%.9f")
    np.savetxt(tmp_path / "est.txt", est_rows, fmt="%.9f")
    cli = json.loads(subprocess.run(
        [str(binary), "eval", "traj", "--gt", str(tmp_path / "gt.txt"), "--est", str(tmp_path / "est.txt"),
         "--align", "sim3", "--json"], check=True, capture_output=True, text=True).stdout)
    py = scarp.eval_traj(tmp_path / "gt.txt", tmp_path / "est.txt", align="sim3")
    _assert_same_figures(py, cli)


def _assert_same_figures(py, cli):
    """The same keys and values (numbers to 1e-12 relative: the CLI may be a debug build)."""
    assert set(py) == set(cli)
    for key, value in cli.items():
        if isinstance(value, float):
            assert py[key] == pytest.approx(value, rel=1e-12, abs=1e-15), key
        else:
            assert py[key] == value, key
