#!/usr/bin/env python3
"""The true rock's and the mission's scan's horizontal sections just above the contact.

    python3 docs/campaigns/tools/sections.py RUN_DIR ROCK_ID [--along-x X0 X1 STEP]

RUN_DIR is one run of a campaign (it holds `mission.json`, `world_gt/` and `targets/`). The
scan (`targets/<id>/mesh.ply` of the target mapped at rock ROCK_ID) is moved into the world
frame by the SE(3) alignment of its keyframes (`keyframes_ba.txt`) to their true poses, as
`mission::mapping::map_to_world` does. Both surfaces are sampled densely (400 000 points each).
Heights are above the pedestal's top (the true contact), in bands of ±2.5 mm.

Default: per 30° sector around the true contact's centroid, the largest radius (cm) at 0, 0.5,
1, 2, 3, 4, 6 and 10 cm up. With `--along-x`: per x column (±1 cm) from X0 to X1 (world
metres), the section's least and greatest y (m, relative to the run's rounded y), for a rock
long along x (session 30: stone A0 on edge). Needs numpy.
"""
import json
import struct
import sys

import numpy as np

HEIGHTS_M = (0.0, 0.005, 0.01, 0.02, 0.03, 0.04, 0.06, 0.1)
TYPES = {"float": "f", "double": "d", "uchar": "B", "int": "i", "uint": "I"}


def read_ply(path):
    """Vertices (n×3) and triangles (m×3) of a binary little-endian PLY."""
    with open(path, "rb") as f:
        props, counts, element = [], {}, None
        while (line := f.readline().decode().strip()) != "end_header":
            t = line.split()
            if t[0] == "element":
                element = t[1]
                counts[element] = int(t[2])
            elif t[0] == "property" and element == "vertex":
                props.append(TYPES[t[1]])
        fmt = "<" + "".join(props)
        size = struct.calcsize(fmt)
        data = f.read(counts["vertex"] * size)
        vertices = np.array([struct.unpack_from(fmt, data, i * size)[:3] for i in range(counts["vertex"])])
        faces = []
        for _ in range(counts.get("face", 0)):
            n = f.read(1)[0]
            faces.append(struct.unpack(f"<{n}i", f.read(4 * n))[:3])
    return vertices, np.array(faces, dtype=int)


def sample(vertices, faces, n=400_000, seed=0):
    rng = np.random.default_rng(seed)
    a, b, c = vertices[faces[:, 0]], vertices[faces[:, 1]], vertices[faces[:, 2]]
    area = np.linalg.norm(np.cross(b - a, c - a), axis=1)
    pick = rng.choice(len(faces), n, p=area / area.sum())
    u, v = rng.random(n), rng.random(n)
    flip = u + v > 1
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    return a[pick] + u[:, None] * (b[pick] - a[pick]) + v[:, None] * (c[pick] - a[pick])


def positions(path):
    return np.loadtxt(path)[:, 1:4]


def scan_in_world(target):
    """The scan's vertices moved by the rotation and translation that best map its keyframes'
    positions onto the true ones (Umeyama without scale)."""
    src, dst = positions(f"{target}/keyframes_ba.txt"), positions(f"{target}/keyframes_groundtruth.txt")
    ms, md = src.mean(0), dst.mean(0)
    u, _, vt = np.linalg.svd((src - ms).T @ (dst - md))
    d = np.diag([1.0, 1.0, np.sign(np.linalg.det(vt.T @ u.T))])
    rotation = vt.T @ d @ u.T
    vertices, faces = read_ply(f"{target}/mesh.ply")
    return vertices @ rotation.T + (md - rotation @ ms), faces


def main():
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    run, rock = sys.argv[1], int(sys.argv[2])
    target = next(t["id"] for t in json.load(open(f"{run}/mission.json"))["targets"] if t.get("gt_rock_id") == rock)
    pedestal, _ = read_ply(f"{run}/world_gt/pedestal_{rock}.ply")
    top = pedestal[:, 2].max()
    truth = sample(*read_ply(f"{run}/world_gt/rock_{rock}.ply"))
    scan = sample(*scan_in_world(f"{run}/targets/{target}"))
    axis = truth[np.abs(truth[:, 2] - top) < 0.002][:, :2].mean(0)
    print(f"pedestal top {top:.3f} m, true contact centroid ({axis[0]:.3f}, {axis[1]:.3f})")
    for name, points in (("truth", truth), ("scan", scan)):
        bands = [points[np.abs(points[:, 2] - top - h) < 0.0025] for h in HEIGHTS_M]
        if "--along-x" in sys.argv:
            x0, x1, step = map(float, sys.argv[sys.argv.index("--along-x") + 1:][:3])
            y0 = round(axis[1])
            print(f"{name}: y − ({y0}) per x column, rows at heights (cm) {[h * 100 for h in HEIGHTS_M]}")
            for h, band in zip(HEIGHTS_M, bands):
                cells = []
                for x in np.arange(x0, x1 + 1e-9, step):
                    col = band[np.abs(band[:, 0] - x) < 0.01]
                    cells.append("    --     " if len(col) == 0 else f"{col[:, 1].min() - y0:+.3f}{col[:, 1].max() - y0:+.3f}")
                print(f"  {h * 100:4.1f} cm  " + " ".join(cells))
        else:
            print(f"{name}: largest radius (cm) per 30° sector at heights (cm) {[h * 100 for h in HEIGHTS_M]}")
            for sector in range(12):
                row = []
                for band in bands:
                    d = band[:, :2] - axis
                    s = (np.arctan2(d[:, 1], d[:, 0]) % (2 * np.pi) / (2 * np.pi) * 12).astype(int) % 12
                    r = np.linalg.norm(d[s == sector], axis=1)
                    row.append(f"{r.max() * 100:5.1f}" if len(r) else "   --")
                print(f"  sector {sector:2d} " + " ".join(row))


if __name__ == "__main__":
    main()
