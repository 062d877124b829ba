#!/usr/bin/env python3
"""Where a mapped rock was missed, and whether the mapping flight ever looked there.

    python3 docs/campaigns/tools/missed_surface.py RUN_DIR TARGET_ID ROCK_ID T_START_S T_END_S

RUN_DIR is one mission's output (`mission.json`, `groundtruth.txt`, `world_gt/`, `targets/`).
TARGET_ID is the catalogue id (the folder under `targets/`), ROCK_ID the true rock's id
(`gt_rock_id` in `mission.json`), and T_START_S–T_END_S the mapping interval of the run log
(`fine_localize → map` to `mapped`).

The scan (`targets/ID/mesh.ply`, map frame) is moved into the world by the rigid fit of its BA
keyframe positions to their true positions. A true rock vertex more than 3 cm from every scan
vertex is *missed*. Prints:
- the missed area per 10 cm height band above the rock's lowest point and per 45° azimuth
  (counter-clockwise from east, about the rock's mean vertex);
- for the missed and the seen vertices (above the lowest 20 cm, which is the contact), in how
  many of the interval's true camera poses (every other frame) each lay in the 640×480 image
  of the mission's 80° camera, within 5 m, facing the camera (cosine above 0.2). Occlusion is
  not modelled, so "in view" is an upper bound.

Needs numpy and scipy.
"""
import sys

import numpy as np
from scipy.spatial import cKDTree

TYPES = {"float": "<f4", "double": "<f8", "uchar": "u1", "int": "<i4"}


def read_ply(path):
    """(vertices n×3, faces m×3) of a binary little-endian PLY with triangle faces."""
    data = open(path, "rb").read()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    vertices, faces, props, element = 0, 0, [], None
    for line in data[:end].decode().splitlines():
        t = line.split()
        if t[:2] == ["element", "vertex"]:
            vertices, element = int(t[2]), "vertex"
        elif t[:2] == ["element", "face"]:
            faces, element = int(t[2]), "face"
        elif t and t[0] == "property" and element == "vertex":
            props.append(TYPES[t[1]])
    vertex_type = np.dtype([(f"p{i}", p) for i, p in enumerate(props)])
    v = np.frombuffer(data, vertex_type, vertices, end)
    xyz = np.stack([v["p0"], v["p1"], v["p2"]], 1).astype(float)
    face_type = np.dtype([("n", "u1"), ("i", "<i4", 3)])
    f = np.frombuffer(data, face_type, faces, end + vertices * vertex_type.itemsize)["i"]
    return xyz, f


def rigid_fit(source, target):
    """(R, t) with target ≈ R source + t, least squares (Kabsch)."""
    ms, mt = source.mean(0), target.mean(0)
    u, _, vt = np.linalg.svd((source - ms).T @ (target - mt))
    d = np.diag([1, 1, np.sign(np.linalg.det(vt.T @ u.T))])
    r = vt.T @ d @ u.T
    return r, mt - r @ ms


def rotation(q):
    x, y, z, w = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def main():
    run, target, rock = sys.argv[1], sys.argv[2], sys.argv[3]
    t_start, t_end = float(sys.argv[4]), float(sys.argv[5])
    truth, faces = read_ply(f"{run}/world_gt/rock_{rock}.ply")
    scan, _ = read_ply(f"{run}/targets/{target}/mesh.ply")
    ba = np.loadtxt(f"{run}/targets/{target}/keyframes_ba.txt")[:, 1:4]
    gt = np.loadtxt(f"{run}/targets/{target}/keyframes_groundtruth.txt")[:, 1:4]
    r, t = rigid_fit(ba, gt)
    missed = cKDTree(scan @ r.T + t).query(truth)[0] > 0.03

    tri = truth[faces]
    face_normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    area = np.zeros(len(truth))
    normals = np.zeros_like(truth)
    for k in range(3):
        np.add.at(area, faces[:, k], np.linalg.norm(face_normals, axis=1) / 6)
        np.add.at(normals, faces[:, k], face_normals)
    normals /= np.linalg.norm(normals, axis=1, keepdims=True) + 1e-12
    height = truth[:, 2] - truth[:, 2].min()
    centre = truth.mean(0)
    azimuth = np.degrees(np.arctan2(truth[:, 1] - centre[1], truth[:, 0] - centre[0])) % 360
    print(f"rock {height.max():.2f} m tall, {area.sum():.2f} m², missed {area[missed].sum():.2f} m²")
    for low in np.arange(0, height.max(), 0.1):
        band = (height >= low) & (height < low + 0.1)
        if area[band].sum() > 0:
            print(f"  height {low:.1f}–{low + 0.1:.1f} m: missed {area[band & missed].sum() / area[band].sum():.2f}")
    for low in range(0, 360, 45):
        sector = (azimuth >= low) & (azimuth < low + 45)
        print(f"  azimuth {low}–{low + 45}°: missed {area[sector & missed].sum() / area[sector].sum():.2f}")

    poses = np.loadtxt(f"{run}/groundtruth.txt")
    poses = poses[(poses[:, 0] >= t_start) & (poses[:, 0] <= t_end)][::2]
    focal_px = 320 / np.tan(np.radians(40))
    in_view = np.zeros(len(truth))
    for pose in poses:
        eye = pose[1:4]
        p = (truth - eye) @ rotation(pose[4:8])
        z = np.maximum(p[:, 2], 1e-6)
        u, v = focal_px * p[:, 0] / z + 319.5, focal_px * p[:, 1] / z + 239.5
        to_eye = eye - truth
        facing = (normals * to_eye).sum(1) / np.linalg.norm(to_eye, axis=1) > 0.2
        in_view += (p[:, 2] > 0.1) & (p[:, 2] < 5) & (u >= 0) & (u < 640) & (v >= 0) & (v < 480) & facing
    print(f"{len(poses)} frames between {t_start} and {t_end} s")
    for name, mask in (("missed", missed & (height > 0.2)), ("seen", ~missed & (height > 0.2))):
        print(f"  {name}: {mask.sum()} vertices, in view in a median of {np.median(in_view[mask]):.0f} "
              f"frames, in none: {(in_view[mask] == 0).mean():.0%}")


if __name__ == "__main__":
    main()
