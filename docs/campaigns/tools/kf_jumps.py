#!/usr/bin/env python3
"""Where a target's odometry went wrong, keyframe by keyframe.

usage: kf_jumps.py TARGET_DIR [odometry|ba] [--all]

Reads TARGET_DIR/keyframes_{odometry,ba}.txt and keyframes_groundtruth.txt (as a mission
writes them) and prints, for each keyframe, its pose relative to the first keyframe against the
truth's: the position error (m) and the rotation error (degrees). The map frame is anchored at
the first keyframe, so a drift grows smoothly and a jump is one keyframe where the error steps.
Without --all, only the keyframes where the error changes by more than 1 cm or 0.1° are shown.
"""
import math
import sys


def rotation(qx, qy, qz, qw):
    return [
        [1 - 2 * (qy * qy + qz * qz), 2 * (qx * qy - qz * qw), 2 * (qx * qz + qy * qw)],
        [2 * (qx * qy + qz * qw), 1 - 2 * (qx * qx + qz * qz), 2 * (qy * qz - qx * qw)],
        [2 * (qx * qz - qy * qw), 2 * (qy * qz + qx * qw), 1 - 2 * (qx * qx + qy * qy)],
    ]


def read_tum(path):
    poses = []
    for line in open(path):
        if line.startswith("#") or not line.strip():
            continue
        v = [float(x) for x in line.split()]
        poses.append((v[0], v[1:4], rotation(*v[4:8])))
    return poses


def relative(a, b):
    """a⁻¹·b as (translation, rotation matrix)."""
    ra_t = [[a[2][j][i] for j in range(3)] for i in range(3)]
    d = [b[1][i] - a[1][i] for i in range(3)]
    t = [sum(ra_t[i][k] * d[k] for k in range(3)) for i in range(3)]
    r = [[sum(ra_t[i][k] * b[2][k][j] for k in range(3)) for j in range(3)] for i in range(3)]
    return t, r


def angle_deg(ra, rb):
    trace = sum(ra[i][j] * rb[i][j] for i in range(3) for j in range(3))
    return math.degrees(math.acos(max(-1.0, min(1.0, (trace - 1) / 2))))


def main():
    args = [a for a in sys.argv[1:] if not a.startswith("--")]
    if not args:
        sys.exit(__doc__)
    target = args[0]
    which = args[1] if len(args) > 1 else "odometry"
    show_all = "--all" in sys.argv
    estimated = read_tum(f"{target}/keyframes_{which}.txt")
    truth = read_tum(f"{target}/keyframes_groundtruth.txt")
    if len(estimated) != len(truth):
        sys.exit(f"{target}: {len(estimated)} {which} keyframes against {len(truth)} true ones")
    print("keyframe  t (s)  position error (m)  rotation error (°)  true step (m)")
    previous = (0.0, 0.0)
    for k, (e, g) in enumerate(zip(estimated, truth)):
        te, re = relative(estimated[0], e)
        tg, rg = relative(truth[0], g)
        error_m = math.dist(te, tg)
        error_deg = angle_deg(re, rg)
        step_m = math.dist(truth[k][1], truth[k - 1][1]) if k else 0.0
        jumped = abs(error_m - previous[0]) > 0.01 or abs(error_deg - previous[1]) > 0.1
        if show_all or jumped:
            print(f"{k:8d}  {e[0]:.2f}  {error_m:.4f}  {error_deg:.3f}  {step_m:.3f}")
        previous = (error_m, error_deg)


if __name__ == "__main__":
    main()
