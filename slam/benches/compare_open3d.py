#!/usr/bin/env python3
"""Open3D VoxelBlockGrid on the same frames as `scarp map`, for the TSDF speed comparison.

Same voxel size, truncation (4 voxels), block resolution (8) and depth range; ground-truth poses.

Setup (Debian):  apt-get install libusb-1.0-0 libgomp1
                 pip install open3d-cpu==0.19.0   (0.20's CPU wheel gives empty TSDF meshes)
Usage:           scarp render --path orbit --frames 120 --no-noise --out /tmp/orbit
                 python3 slam/benches/compare_open3d.py /tmp/orbit --voxel 0.01 [--frames N]
                 scarp map /tmp/orbit --poses groundtruth --voxel 0.01 --out /tmp/map --json

Prints the median and p90 integration time per frame (block allocation + integration, as
`integrate_ms_*` in scarp's map.json), the meshing time and the triangle count as JSON.
"""

import argparse
import json
import statistics
import time
from pathlib import Path

import numpy as np
import open3d as o3d
import open3d.core as o3c


def read_list(path):
    rows = []
    for line in Path(path).read_text().splitlines():
        if line.strip() and not line.startswith("#"):
            rows.append(line.split())
    return rows


def camera_from_world(tx, ty, tz, qx, qy, qz, qw):
    x, y, z, w = qx, qy, qz, qw
    r = np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )
    world_from_camera = np.eye(4)
    world_from_camera[:3, :3] = r
    world_from_camera[:3, 3] = [tx, ty, tz]
    return np.linalg.inv(world_from_camera)


def parse_camera(path):
    values = {}
    for line in Path(path).read_text().splitlines():
        if "=" in line and not line.startswith("#"):
            key, value = line.split("=", 1)
            values[key.strip()] = float(value)
    return values


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("sequence", type=Path)
    parser.add_argument("--voxel", type=float, default=0.01)
    parser.add_argument("--max-depth", type=float, default=10.0)
    parser.add_argument("--frames", type=int, default=0, help="0 = all")
    args = parser.parse_args()

    seq = args.sequence
    cam = parse_camera(seq / "camera.toml")
    intrinsic = o3c.Tensor(
        [[cam["fx"], 0, cam["cx"]], [0, cam["fy"], cam["cy"]], [0, 0, 1]], o3c.float64
    )
    rgb = read_list(seq / "rgb.txt")
    depth = read_list(seq / "depth.txt")
    poses = read_list(seq / "groundtruth.txt")
    n = len(depth) if args.frames <= 0 else min(args.frames, len(depth))
    device = o3c.Device("CPU:0")
    vbg = o3d.t.geometry.VoxelBlockGrid(
        attr_names=("tsdf", "weight", "color"),
        attr_dtypes=(o3c.float32, o3c.float32, o3c.float32),
        attr_channels=((1), (1), (3)),
        voxel_size=args.voxel,
        block_resolution=8,
        block_count=200000,
        device=device,
    )
    times_ms = []
    for i in range(n):
        d = o3d.t.io.read_image(str(seq / depth[i][1])).to(device)
        c = o3d.t.io.read_image(str(seq / rgb[i][1])).to(device)
        extrinsic = o3c.Tensor(camera_from_world(*map(float, poses[i][1:8])), o3c.float64)
        start = time.perf_counter()
        blocks = vbg.compute_unique_block_coordinates(
            d, intrinsic, extrinsic, cam["depth_scale"], args.max_depth
        )
        vbg.integrate(
            blocks, d, c, intrinsic, intrinsic, extrinsic, cam["depth_scale"], args.max_depth,
            trunc_voxel_multiplier=4.0,
        )
        times_ms.append((time.perf_counter() - start) * 1e3)
    start = time.perf_counter()
    mesh = vbg.extract_triangle_mesh()
    mesh_ms = (time.perf_counter() - start) * 1e3
    times_ms.sort()
    print(
        json.dumps(
            {
                "open3d": o3d.__version__,
                "frames": n,
                "integrate_ms_median": statistics.median(times_ms),
                "integrate_ms_p90": times_ms[min(len(times_ms) - 1, int(0.9 * (len(times_ms) - 1) + 0.5))],
                "mesh_ms": mesh_ms,
                "triangles": int(mesh.triangle.indices.shape[0]),
            },
            indent=2,
        )
    )


if __name__ == "__main__":
    main()
