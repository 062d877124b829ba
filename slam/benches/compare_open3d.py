#!/usr/bin/env python3
"""Open3D VoxelBlockGrid and RGBD odometry on the same frames as `scarp map`, for the speed comparison.

TSDF: same voxel size, truncation (4 voxels, for block allocation as well as integration), block
resolution (8), depth range and region of interest (--roi, as `scarp map --roi`: Open3D's unique
block coordinates are filtered to the blocks intersecting the region inside the timer, as scarp
filters them); ground-truth poses. With --scarp-map (scarp's map.json of the same sequence and
settings) it prints scarp's figures beside Open3D's and the speed-up Open3D time / scarp time of
integration (median, p90) and meshing. With --scarp BIN it runs `BIN map` itself on the same
sequence and settings, just before Open3D, so both sides are timed in one run. Open3D's own
allocation walks one pixel in 16, so it updates fewer blocks per frame than scarp's exact band
walk (1.6x fewer on the noisy orbit's cylinder); --same-blocks also times Open3D on the blocks
of every pixel's band, the same voxel work as scarp's. Odometry (with --odometry-pairs N): Open3D's hybrid RGBD odometry (t.pipelines.odometry,
Method.Hybrid, 3 levels) on the first N consecutive frame pairs, initialised with the state
estimate's relative motion as scarp is; its per-pair time and its ATE over those frames (chained,
SE(3)-aligned like `scarp eval traj`) are printed next to scarp's figures read from a map.json
(--scarp-map DIR/map.json from `scarp map --poses odometry`).

Setup (Debian):  apt-get install libusb-1.0-0 libgomp1
                 pip install open3d-cpu==0.19.0   (0.20's CPU wheel gives empty TSDF meshes)
Usage:           scarp render --path orbit --frames 120 --seed 3 --out /tmp/orbit
                 python3 slam/benches/compare_open3d.py /tmp/orbit --voxel 0.01 --max-depth 8 \
                     [--roi cyl:x,y,z0,z1,r] --scarp target/release/scarp [--repeat 3] \
                     [--gt rock_1.ply]   (from `scarp world --out DIR`: both meshes scored)
                 or, from a map.json made beforehand:
                 scarp map /tmp/orbit --poses groundtruth --voxel 0.01 --out /tmp/map --json
                 python3 slam/benches/compare_open3d.py /tmp/orbit --voxel 0.01 [--frames N] \
                     [--max-depth 8] [--roi cyl:x,y,z0,z1,r] --scarp-map /tmp/map/map.json
                 python3 slam/benches/compare_open3d.py /tmp/orbit --frames 0 --odometry-pairs 30 \
                     --scarp-map /tmp/map_odometry/map.json

Prints the median and p90 integration time per frame (block allocation + integration, as
`integrate_ms_*` in scarp's map.json), the meshing time (marching cubes, as scarp's
`marching_cubes_ms`), the triangle and block counts as JSON.
"""

import argparse
import atexit
import json
import math
import shutil
import subprocess
import tempfile
import statistics
import time
import tomllib
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
    """camera.toml of a sequence (intrinsics, depth scale, and flags such as depth_registered)."""
    with open(path, "rb") as file:
        return tomllib.load(file)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("sequence", type=Path)
    parser.add_argument("--voxel", type=float, default=0.01)
    parser.add_argument("--max-depth", type=float, default=10.0)
    parser.add_argument("--frames", type=int, default=0, help="0 = all (TSDF); -1 skips it")
    parser.add_argument("--odometry-pairs", type=int, default=0, help="frame pairs for odometry")
    parser.add_argument("--roi", help="cyl:x,y,z_min,z_max,r or box:x0,y0,z0,x1,y1,z1 (metres)")
    parser.add_argument(
        "--weight-threshold", type=float, default=3.0,
        help="Open3D meshing weight threshold (Open3D's default 3: it meshes voxels whose weight, "
             "one per frame, exceeds it, i.e. seen by 4 frames or more); --scarp meshes the same "
             "voxels (scarp map --min-observations threshold + 1)",
    )
    parser.add_argument("--scarp-map", type=Path, help="scarp's map.json to print beside")
    parser.add_argument(
        "--save-mesh", type=Path,
        help="write Open3D's mesh (PLY) here, to score it beside scarp's with `scarp eval mesh`",
    )
    parser.add_argument(
        "--same-blocks", action="store_true",
        help="Open3D integrates, in each frame, the blocks scarp's exact band walk updates "
             "(every pixel's truncation band, sampled every half voxel, outside the timer) "
             "rather than those its own allocation samples (one pixel in 16): the same voxel "
             "work on both sides; its times are printed under same_blocks, its speed-ups as "
             "open3d_over_scarp's *_same_blocks",
    )
    parser.add_argument("--scarp", type=Path, help="scarp binary: run `scarp map` in this run")
    parser.add_argument(
        "--gt", type=Path,
        help="with --scarp: a ground-truth mesh (PLY, e.g. rock_1.ply from `scarp world`) that "
             "both tools' meshes are scored against with `scarp eval mesh --crop-to-gt 0.1` at "
             "1 and 2 cm, so a speed-up is read beside what each tool's work bought",
    )
    parser.add_argument(
        "--depth-sample", choices=["bilinear", "nearest"], default="bilinear",
        help="with --scarp: `scarp map --depth-sample`. Open3D reads each voxel's depth from the "
             "nearest pixel; scarp's default interpolates between agreeing pixels (four loads "
             "and a blend per voxel). `nearest` times both tools on the same sampling rule",
    )
    parser.add_argument(
        "--repeat", type=int, default=1,
        help="with --scarp: rounds of scarp then Open3D, back to back; prints every round's "
             "speed-ups and their median (a shared machine's load moves both tools' times)",
    )
    args = parser.parse_args()
    if args.repeat < 1:
        parser.error("--repeat must be at least 1")
    if args.repeat > 1 and not args.scarp:
        parser.error("--repeat needs --scarp (both tools timed in each round)")
    if args.gt and not args.scarp:
        parser.error("--gt needs --scarp (its `eval mesh` scores both meshes)")
    if args.scarp and args.frames != 0:
        # scarp map fuses the whole sequence: timing Open3D on fewer frames is not the same work.
        parser.error("--scarp runs scarp map on every frame: use it with --frames 0")
    roi_text = args.roi
    args.roi = parse_roi(args.roi) if args.roi else None
    if args.gt and not args.save_mesh:
        # Open3D's mesh must reach a file for `scarp eval mesh`.
        scratch = Path(tempfile.mkdtemp(prefix="open3d_mesh_"))
        atexit.register(shutil.rmtree, scratch, ignore_errors=True)
        args.save_mesh = scratch / "mesh.ply"
    rounds = []
    for _ in range(args.repeat):
        if args.scarp:
            args.scarp_map = run_scarp_map(args, roi_text)
        rounds.append(one_round(args))
        if args.gt:
            rounds[-1]["mesh_scores"] = score_meshes(args)
        if args.scarp:
            # Read: its meshes need not wait for the exit (hundreds of MB on a full frame).
            shutil.rmtree(args.scarp_map.parent, ignore_errors=True)
    result = rounds[-1]
    if args.scarp:
        result["scarp_depth_sample"] = args.depth_sample
    if args.repeat > 1:
        result["rounds"] = [r.get("open3d_over_scarp", {}) for r in rounds]
        result["median_open3d_over_scarp"] = {
            k: statistics.median(r["open3d_over_scarp"][k] for r in rounds)
            for k in rounds[0].get("open3d_over_scarp", {})
        }
    print(json.dumps(result, indent=2))


def one_round(args):
    """Open3D's TSDF (and odometry) on the sequence, beside scarp's map.json when given."""
    result = {"open3d": o3d.__version__}
    if args.frames >= 0:
        result.update(compare_tsdf(args))
        if args.same_blocks:
            result["same_blocks"] = compare_tsdf(args, band_blocks=True)
    if args.odometry_pairs > 0:
        result.update(compare_odometry(args))
    if args.scarp_map:
        ours = json.loads(args.scarp_map.read_text())
        keys = ["integrate_ms_median", "integrate_ms_p90", "mesh_ms", "marching_cubes_ms",
                "triangles", "blocks", "blocks_updated_median",
                "odometry_ms_median", "ate_rmse_m", "estimate_ate_rmse_m"]
        result["scarp"] = {k: ours[k] for k in keys if k in ours}
        # Speed-up of scarp over Open3D (> 1: scarp is faster) for each time both report.
        speedup = {}
        for k in ["integrate_ms_median", "integrate_ms_p90", "mesh_ms", "odometry_ms_median"]:
            # Open3D's meshing is marching cubes alone; scarp's mesh_ms adds its small-component
            # filter, so the ratio uses scarp's marching_cubes_ms when map.json has it.
            ours_key = "marching_cubes_ms" if k == "mesh_ms" and ours.get("marching_cubes_ms") else k
            if ours_key in ours and k in result and ours[ours_key] > 0:
                speedup[k] = result[k] / ours[ours_key]
        same = result.get("same_blocks")
        for k in ["integrate_ms_median", "integrate_ms_p90"]:
            if same and ours.get(k):
                # Open3D on scarp's blocks (its block finding untimed) against scarp's whole
                # integration: the same voxel work, with the block finding given to Open3D.
                speedup[f"{k}_same_blocks"] = same[k] / ours[k]
        result["open3d_over_scarp"] = speedup
        if ours.get("blocks_updated_median") and result.get("blocks_updated_median"):
            # > 1: scarp updates more blocks per frame (its band walk is exact; Open3D's
            # allocation samples one pixel in 16 and four points along each band).
            result["blocks_updated_scarp_over_open3d"] = (
                ours["blocks_updated_median"] / result["blocks_updated_median"]
            )
    return result


def score_meshes(args):
    """F-score, precision and recall at 1 and 2 cm of Open3D's and scarp's meshes of this round
    against --gt (`scarp eval mesh`, reconstruction farther than 0.1 m from the truth's bounding
    box ignored, as `scarp map --world` scores)."""
    meshes = {"open3d": args.save_mesh, "scarp": args.scarp_map.parent / "mesh.ply"}
    if args.same_blocks:
        meshes["open3d_same_blocks"] = same_blocks_mesh(args.save_mesh)
    scores = {}
    for tool, mesh in meshes.items():
        for tau in (0.01, 0.02):
            command = [str(args.scarp.resolve()), "eval", "mesh", "--gt", str(args.gt),
                       "--mesh", str(mesh), "--tau", str(tau), "--crop-to-gt", "0.1",
                       "--json", "--log", "warn"]
            run = subprocess.run(command, check=True, capture_output=True, text=True)
            score = json.loads(run.stdout)
            scores.setdefault(tool, {})[f"tau_{tau:g}"] = {
                k: score[k] for k in ("fscore", "precision", "recall")
            }
    return scores


def same_blocks_mesh(path):
    """Where Open3D's --same-blocks mesh goes, beside --save-mesh's (none without it)."""
    return path.with_name(path.stem + "_same_blocks" + path.suffix) if path else None


def run_scarp_map(args, roi_text):
    """`scarp map` with ground-truth poses and the same voxel, depth range and region; returns
    the path of its map.json (in a temporary directory: the caller removes it once the round is
    read, and it is removed at exit otherwise)."""
    out = Path(tempfile.mkdtemp(prefix="scarp_map_"))
    atexit.register(shutil.rmtree, out, ignore_errors=True)
    # Resolved: `Path("./scarp")` prints as "scarp", which subprocess would look up on PATH.
    command = [str(args.scarp.resolve()), "map", str(args.sequence), "--poses", "groundtruth",
               "--voxel", str(args.voxel), "--max-depth", str(args.max_depth),
               "--out", str(out), "--log", "warn", "--depth-sample", args.depth_sample]
    if roi_text:
        command += ["--roi", roi_text]
    # Open3D meshes weights above the threshold; scarp counts observations, at least N.
    command += ["--min-observations", str(min(255, math.floor(args.weight_threshold) + 1))]
    subprocess.run(command, check=True, stdout=subprocess.DEVNULL)
    return out / "map.json"


def parse_roi(text):
    """`cyl:x,y,z_min,z_max,r` or `box:x0,y0,z0,x1,y1,z1`, as `scarp map --roi`."""
    kind, _, rest = text.partition(":")
    values = [float(v) for v in rest.split(",")]
    if kind == "cyl" and len(values) == 5:
        return ("cyl", values)
    if kind == "box" and len(values) == 6:
        return ("box", values)
    raise SystemExit(f"bad --roi {text!r}")


def roi_mask(roi, coords, voxel):
    """Which blocks (int array n×3 of block coordinates) intersect the region; the same test as
    scarp's `Roi::intersects_box` on the block's extent [8·b − ½, 8·b + 7½) voxels."""
    block = 8 * voxel
    lo = coords.astype(np.float64) * block - 0.5 * voxel
    hi = lo + block
    kind, v = roi
    if kind == "box":
        return np.all((lo <= np.array(v[3:])) & (hi >= np.array(v[:3])), axis=1)
    x, y, z0, z1, r = v
    dx = np.maximum(lo[:, 0] - x, 0) + np.maximum(x - hi[:, 0], 0)
    dy = np.maximum(lo[:, 1] - y, 0) + np.maximum(y - hi[:, 1], 0)
    return (lo[:, 2] <= z1) & (hi[:, 2] >= z0) & (dx * dx + dy * dy <= r * r)


def read_poses(path):
    return [np.linalg.inv(camera_from_world(*map(float, row[1:8]))) for row in read_list(path)]


def ate_rmse(estimate, truth):
    """ATE RMSE of camera positions after a least-squares SE(3) alignment (Horn/Umeyama)."""
    x = np.array([p[:3, 3] for p in estimate])
    y = np.array([p[:3, 3] for p in truth])
    mx, my = x.mean(0), y.mean(0)
    u, _, vt = np.linalg.svd((y - my).T @ (x - mx))
    d = np.diag([1, 1, np.sign(np.linalg.det(u @ vt))])
    r = u @ d @ vt
    aligned = (r @ (x - mx).T).T + my
    return float(np.sqrt(((aligned - y) ** 2).sum(1).mean()))


def compare_odometry(args):
    seq = args.sequence
    cam = parse_camera(seq / "camera.toml")
    intrinsic = o3c.Tensor(
        [[cam["fx"], 0, cam["cx"]], [0, cam["fy"], cam["cy"]], [0, 0, 1]], o3c.float64
    )
    rgb = read_list(seq / "rgb.txt")
    depth = read_list(seq / "depth.txt")
    truth = read_poses(seq / "groundtruth.txt")
    estimate = read_poses(seq / "estimate.txt")
    n = min(args.odometry_pairs + 1, len(depth))

    def load(i):
        image = o3d.t.geometry.RGBDImage(
            o3d.t.io.read_image(str(seq / rgb[i][1])).to(o3c.float32, scale=1.0 / 255.0),
            o3d.t.io.read_image(str(seq / depth[i][1])),
        )
        return image

    times_ms = []
    chained = [estimate[0]]
    previous = load(0)
    for i in range(1, n):
        current = load(i)
        # source = current, target = previous: the result maps current-camera points into the
        # previous camera (previous_from_current), initialised with the estimator's motion.
        guess = np.linalg.inv(estimate[i - 1]) @ estimate[i]
        start = time.perf_counter()
        result = o3d.t.pipelines.odometry.rgbd_odometry_multi_scale(
            current, previous, intrinsic, o3c.Tensor(guess, o3c.float64),
            cam["depth_scale"], args.max_depth,
            [o3d.t.pipelines.odometry.OdometryConvergenceCriteria(k) for k in (10, 5, 3)],
            o3d.t.pipelines.odometry.Method.Hybrid,
        )
        times_ms.append((time.perf_counter() - start) * 1e3)
        chained.append(chained[-1] @ result.transformation.numpy())
        previous = current
    times_ms.sort()
    return {
        "odometry_pairs": n - 1,
        "odometry_ms_median": statistics.median(times_ms),
        "odometry_ate_rmse_m": ate_rmse(chained, truth[:n]),
        "estimate_ate_rmse_m": ate_rmse(estimate[:n], truth[:n]),
    }


def band_block_coordinates(depth_m, intrinsic, world_from_camera, truncation_m, voxel_m,
                           max_depth_m):
    """The blocks (n×3 int array) that the truncation bands of every pixel with a depth in
    (0, max_depth_m] cross, as scarp's exact walk finds them: each band sampled every half voxel
    (blocks are 8 voxels) from depth − truncation to depth + truncation. A block is 8 voxels with
    voxel centres at multiples of the voxel size, so block b spans [8b − ½, 8b + 7½) voxels."""
    v, u = np.nonzero((depth_m > 0) & (depth_m <= max_depth_m))
    z = depth_m[v, u]
    rays = np.stack(
        [(u - intrinsic[0, 2]) / intrinsic[0, 0], (v - intrinsic[1, 2]) / intrinsic[1, 1],
         np.ones_like(z)], axis=1,
    )
    rotation, origin = world_from_camera[:3, :3], world_from_camera[:3, 3]
    block_m = 8 * voxel_m
    steps = int(math.ceil(2 * truncation_m / (0.5 * voxel_m))) + 1
    found = []
    for t in np.linspace(-truncation_m, truncation_m, steps):
        points = (rays * (z + t)[:, None]) @ rotation.T + origin
        cells = np.floor((points + 0.5 * voxel_m) / block_m).astype(np.int64)
        # One int64 key per block (21 bits an axis, as scarp packs them): a 1-D unique is
        # many times faster than numpy's unique over rows.
        found.append(np.unique(((cells[:, 0] + (1 << 20)) << 42) | ((cells[:, 1] + (1 << 20)) << 21)
                               | (cells[:, 2] + (1 << 20))))
    keys = np.unique(np.concatenate(found))
    mask = (1 << 21) - 1
    return np.stack([(keys >> 42) & mask, (keys >> 21) & mask, keys & mask], axis=1).astype(
        np.int32) - (1 << 20)


def compare_tsdf(args, band_blocks=False):
    """Open3D's integration and meshing of the sequence; with `band_blocks`, each frame
    integrates the blocks of `band_block_coordinates` (found outside the timer) instead of
    those of its own allocation."""
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
    active_blocks = []
    if band_blocks:
        # Every frame's band blocks are found before any frame is timed: numpy's threaded
        # matrix products leave their threads spinning for a while, which slowed the
        # integration timed right after them by up to 3x.
        exact = [
            band_block_coordinates(
                o3d.t.io.read_image(str(seq / depth[i][1])).as_tensor().numpy()[:, :, 0]
                .astype(np.float64) / cam["depth_scale"],
                intrinsic.numpy(),
                np.linalg.inv(camera_from_world(*map(float, poses[i][1:8]))),
                4.0 * args.voxel, args.voxel, args.max_depth,
            )
            for i in range(n)
        ]
        time.sleep(1.0)
    for i in range(n):
        d = o3d.t.io.read_image(str(seq / depth[i][1])).to(device)
        c = o3d.t.io.read_image(str(seq / rgb[i][1])).to(device)
        extrinsic = o3c.Tensor(camera_from_world(*map(float, poses[i][1:8])), o3c.float64)
        start = time.perf_counter()
        if band_blocks:
            blocks = o3c.Tensor(exact[i])
        else:
            # Truncation 4 voxels for allocation too (Open3D's default allocates an 8-voxel
            # band).
            blocks = vbg.compute_unique_block_coordinates(
                d, intrinsic, extrinsic, cam["depth_scale"], args.max_depth,
                trunc_voxel_multiplier=4.0,
            )
        if args.roi is not None:
            keep = roi_mask(args.roi, blocks.numpy(), args.voxel)
            blocks = o3c.Tensor(blocks.numpy()[keep])
        vbg.integrate(
            blocks, d, c, intrinsic, intrinsic, extrinsic, cam["depth_scale"], args.max_depth,
            trunc_voxel_multiplier=4.0,
        )
        times_ms.append((time.perf_counter() - start) * 1e3)
        active_blocks.append(int(blocks.shape[0]))
    start = time.perf_counter()
    mesh = vbg.extract_triangle_mesh(weight_threshold=args.weight_threshold)
    mesh_ms = (time.perf_counter() - start) * 1e3
    mesh_path = same_blocks_mesh(args.save_mesh) if band_blocks else args.save_mesh
    if mesh_path:
        o3d.io.write_triangle_mesh(str(mesh_path), mesh.to_legacy())
    times_ms.sort()
    return {
        "frames": n,
        "integrate_ms_median": statistics.median(times_ms),
        "integrate_ms_p90": times_ms[min(len(times_ms) - 1, int(0.9 * (len(times_ms) - 1) + 0.5))],
        "mesh_ms": mesh_ms,
        "triangles": int(mesh.triangle.indices.shape[0]),
        "blocks": int(vbg.hashmap().size()),
        "blocks_updated_median": statistics.median(active_blocks),
    }


if __name__ == "__main__":
    main()
