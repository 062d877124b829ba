#!/usr/bin/env python3
"""Fragility on rocks no one tuned against: random shapes, scanned with true poses.

usage: fresh_shapes.py --bin SCARP --out DIR [--seeds 1-4] [--count 16] [--no-noise] [--jobs 2]
                       [--rescore SCARP] [--config FRAGILITY.toml] [--exact] [--low-ring]

Draws `--count` rocks from each of `--seeds` (`1-4`, or `1,3`): procedural boulders and blocks (random size, squareness,
roughness, facets) and the built-in scanned stones, each at a random yaw, four in ten tilted
5–15°, 0.8–1.4 m tall. Each stands on a 1.1 m pedestal whose top is the narrowest the world
accepts (0.20 m, then 5 cm steps: as PBRs overhang their pedestals), on a flat 16 m world. Two
rings of views, 36 at 0.2 m above the pedestal's top and 2 m out, 24 above the rock, are rendered
(`scarp render`, with the sensor's noise unless `--no-noise`), fused with the true poses
(`scarp map --poses groundtruth --voxel 0.01`, a 1.2 m cylinder round the rock), and analysed
(`scarp fragility --scan --json`). The truth is the world's rock on its pedestal
(`scarp fragility ROCK --pedestal PEDESTAL`).

It asks whether the scan path's contact holds on shapes outside the three worlds' 11 targets,
whose settings the campaigns chose. The views are not the mission's rings (no odometry, no
coverage-driven end), so a failure here is the scan path's alone.

Prints per rock: truth, scan α_min and interval, the centre of mass's height H over the contact
and δ = H·(tan α_scan − tan α_true), how much farther the scan puts the critical contact edge
from the centre of mass (cm); then the totals. With `--rescore`, only re-analyses DIR's meshes
with another binary (and a `FragilityConfig` TOML), for A/B of analysis changes. With
`--exact`, the scan analysed is the world's own surfaces instead of the map's (the rock's faces
above its contact and the pedestal's below, subdivided twice to about 1 cm edges as a map's
are; needs numpy): what the analysis makes of a perfect scan. It renders and maps nothing, so
new seeds' exact surfaces take seconds a rock.
"""
import argparse
import json
import math
import os
import random
import statistics
import subprocess
from concurrent.futures import ThreadPoolExecutor

WORLD = """name = "fresh-shapes"
[origin]
lat_deg = 33.0
lon_deg = -116.0
alt_m = 1000.0
[sun]
azimuth_deg = 200.0
elevation_deg = 45.0
ambient = 0.35
[texture]
seed = 3
[terrain.procedural]
seed = 1
size_m = 16.0
resolution_m = 0.25
scarp_height_m = 0.0
scarp_strike_deg = 0.0
scarp_width_m = 1.0
scarp_offset_m = 0.0
roughness_m = 0.02
roughness_wavelength_m = 8.0
[[rocks]]
id = 1
role = "target"
position_m = [0.0, 0.0]
height_m = {height}
{pose}
{shape}
pedestal = {{ height_m = {pedestal}, base_radius_m = 1.0, top_radius_m = {top} }}
contact_radius_m = 0.15
"""
PEDESTAL_M = 1.1
STONES = ["stone_e22", "stone_073ac15d", "stone_0", "stone_a0", "double_rock"]


def seeds(text):
    """The seeds of `1-4` or `1,3` (or a mix: `1-2,5`)."""
    out = []
    for part in text.split(","):
        first, _, last = part.partition("-")
        out.extend(range(int(first), int(last or first) + 1))
    return out


def draw(seed, count):
    """(name, height m, shape line, pose lines) of `count` rocks drawn from `seed`."""
    rng = random.Random(seed)
    out = []
    for i in range(count):
        kind = ["boulder", "block", "block", "stone"][i % 4]
        pose = f"yaw_deg = {rng.uniform(0, 360):.0f}"
        if rng.random() >= 0.6:
            pose += f"\ntilt_deg = {rng.uniform(5, 15):.1f}\ntilt_azimuth_deg = {rng.uniform(0, 360):.0f}"
        if kind == "boulder":
            r = [rng.uniform(0.5, 0.9), rng.uniform(0.5, 0.8), rng.uniform(0.45, 0.8)]
            shape = (f"shape = {{ boulder = {{ seed = {rng.randrange(1000)}, radii_m = "
                     f"[{r[0]:.2f}, {r[1]:.2f}, {r[2]:.2f}], roughness = {rng.uniform(0.04, 0.14):.2f} }} }}")
        elif kind == "block":
            s = [rng.uniform(0.5, 1.0), rng.uniform(0.3, 0.8), rng.uniform(0.6, 1.0)]
            shape = (f"shape = {{ block = {{ seed = {rng.randrange(1000)}, size_m = "
                     f"[{s[0]:.2f}, {s[1]:.2f}, {s[2]:.2f}], squareness = {rng.uniform(3, 8):.1f}, "
                     f"roughness = {rng.uniform(0, 0.08):.2f}, facets = {rng.randrange(0, 10)}, "
                     f"facet_depth = 0.15 }} }}")
        else:
            shape = f'shape = {{ mesh = "builtin:{rng.choice(STONES)}" }}'
        out.append((f"{seed}-{i:02d}-{kind}", round(rng.uniform(0.8, 1.4), 2), shape, pose))
    return out


def quaternion(r):
    """(qx, qy, qz, qw) of the rotation matrix `r` (rows)."""
    t = r[0][0] + r[1][1] + r[2][2]
    if t > 0:
        s = math.sqrt(t + 1) * 2
        return ((r[2][1] - r[1][2]) / s, (r[0][2] - r[2][0]) / s, (r[1][0] - r[0][1]) / s, s / 4)
    i = max(range(3), key=lambda k: r[k][k])
    j, k = (i + 1) % 3, (i + 2) % 3
    s = math.sqrt(1 + r[i][i] - r[j][j] - r[k][k]) * 2
    q = [0.0, 0.0, 0.0]
    q[i] = s / 4
    q[j] = (r[j][i] + r[i][j]) / s
    q[k] = (r[k][i] + r[i][k]) / s
    return (*q, (r[k][j] - r[j][k]) / s)


def rings(height_m, path, low_ring=False):
    """Writes the two rings round the rock on the origin as a TUM trajectory (camera in world,
    OpenCV axes: x right, y down, z forward); with `low_ring`, a third of 36 views 3 cm above the
    pedestal's top, 1.5 m out, looking level (under an overhang the other two do not see)."""
    lines, t = [], 0.0
    top = PEDESTAL_M + height_m
    plan = [(PEDESTAL_M + 0.2, 2.0, PEDESTAL_M + 0.05, 36)]
    if low_ring:
        plan.append((PEDESTAL_M + 0.03, 1.5, PEDESTAL_M + 0.03, 36))
    plan.append((top + 0.8, 2.4, PEDESTAL_M + height_m / 2, 24))
    for z, radius, look_z, n in plan:
        for k in range(n):
            a = 2 * math.pi * k / n
            eye = (radius * math.cos(a), radius * math.sin(a), z)
            f = (-eye[0], -eye[1], look_z - z)
            norm = math.sqrt(sum(c * c for c in f))
            f = [c / norm for c in f]
            x = [f[1], -f[0], 0.0]  # f × up, up = +z
            norm = math.hypot(x[0], x[1])
            x = [c / norm for c in x]
            y = [f[1] * x[2] - f[2] * x[1], f[2] * x[0] - f[0] * x[2], f[0] * x[1] - f[1] * x[0]]
            q = quaternion([[x[0], y[0], f[0]], [x[1], y[1], f[1]], [x[2], y[2], f[2]]])
            t += 0.1
            lines.append(f"{t:.3f} {eye[0]:.6f} {eye[1]:.6f} {eye[2]:.6f} "
                         + " ".join(f"{c:.9f}" for c in q))
    with open(path, "w") as out:
        out.write("# fresh_shapes rings\n" + "\n".join(lines) + "\n")


def read_ply(path):
    """Vertices (n×3 float) and triangles (m×3 int) of a binary little-endian PLY."""
    import numpy as np
    data = open(path, "rb").read()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    props, counts, element = [], {}, None
    for line in data[:end].decode().splitlines():
        words = line.split()
        if words[:1] == ["element"]:
            element = words[1]
            counts[element] = int(words[2])
        elif words[:1] == ["property"] and element == "vertex":
            props.append((words[-1], {"float": "<f4", "uchar": "u1", "double": "<f8"}[words[1]]))
    vertex = np.dtype(props)
    raw = np.frombuffer(data, dtype=vertex, count=counts["vertex"], offset=end)
    v = np.stack([raw["x"], raw["y"], raw["z"]], 1).astype(np.float64)
    face = np.dtype([("n", "u1"), ("i", "<i4", 3)])
    f = np.frombuffer(data, dtype=face, count=counts["face"], offset=end + vertex.itemsize * len(v))
    return v, f["i"].astype(np.int64)


def exact_scan(rock, pedestal, contact_z, out):
    """Writes the world's rock faces above `contact_z` and pedestal faces below it as one mesh,
    every triangle split in four twice (the support's top is found from its faces too)."""
    import numpy as np
    rv, rf = read_ply(rock)
    pv, pf = read_ply(pedestal)
    rf = rf[(rv[rf][:, :, 2] >= contact_z - 0.002).all(1)]
    pf = pf[(pv[pf][:, :, 2] <= contact_z + 0.002).all(1)]
    v = np.concatenate([rv, pv])
    f = np.concatenate([rf, pf + len(rv)])
    for _ in range(2):
        edges = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), 1)
        unique, inverse = np.unique(edges, axis=0, return_inverse=True)
        mid = inverse.reshape(3, -1).T + len(v)
        v = np.concatenate([v, (v[unique[:, 0]] + v[unique[:, 1]]) / 2])
        a, b, c = f.T
        ab, bc, ca = mid.T
        f = np.concatenate([np.stack(t, 1) for t in [(a, ab, ca), (ab, b, bc), (ca, bc, c), (ab, bc, ca)]])
    v = v.astype("<f4")
    faces = np.zeros(len(f), dtype=np.dtype([("n", "u1"), ("i", "<i4", 3)]))
    faces["n"], faces["i"] = 3, f
    with open(out, "wb") as o:
        o.write((f"ply\nformat binary_little_endian 1.0\nelement vertex {len(v)}\nproperty float x\n"
                 f"property float y\nproperty float z\nelement face {len(f)}\n"
                 "property list uchar int vertex_indices\nend_header\n").encode())
        o.write(v.tobytes() + faces.tobytes())


def run(binary, *args):
    done = subprocess.run([binary, *args], capture_output=True, text=True)
    if done.returncode:
        raise RuntimeError(done.stderr.strip().splitlines()[-1])
    return done.stdout


def scan(binary, mesh, config):
    return json.loads(run(binary, "fragility", mesh, "--scan", "--json",
                          *(["--config", config] if config else [])))


def make(args, rock):
    """Builds, scans and analyses one rock; the row of its figures."""
    name, height, shape, pose = rock
    d = os.path.join(args.out, name)
    os.makedirs(d, exist_ok=True)
    p = lambda n: os.path.join(d, n)  # noqa: E731
    row = dict(name=name)
    try:
        for step in range(16):
            top = round(0.2 + 0.05 * step, 2)
            with open(p("world.toml"), "w") as out:
                out.write(WORLD.format(height=height, pose=pose, shape=shape, pedestal=PEDESTAL_M, top=top))
            try:
                run(args.bin, "world", "--world", p("world.toml"), "--out", p("gt"))
                break
            except RuntimeError as e:
                if "top_radius" not in str(e):
                    raise
                too_wide = str(e)
        else:
            # No pedestal the generator accepts holds this rock (a flat stone scaled to the drawn
            # height has a contact metres across): not a scan to analyse, so it is counted apart.
            row["no_world"] = too_wide[-160:]
            return row
        truth = json.loads(run(args.bin, "fragility", p("gt/rock_1.ply"), "--pedestal",
                               p("gt/pedestal_1.ply"), "--json"))
        row["truth"] = truth["alpha_min_deg"]
        # The exact surfaces need no views: a world and its truth are enough.
        if not args.exact and not os.path.exists(p("map/mesh.ply")):
            rings(height, p("rings.txt"), args.low_ring)
            run(args.bin, "render", "--world", p("world.toml"), "--path", p("rings.txt"),
                *(["--no-noise"] if args.no_noise else []), "--out", p("seq"))
            contact = json.load(open(p("gt/world.json")))["rocks"][0]["contact"]["height_m"]
            run(args.bin, "map", p("seq"), "--poses", "groundtruth", "--voxel", "0.01", "--roi",
                f"cyl:0,0,{contact - 0.6:.2f},{contact + height + 0.4:.2f},1.2", "--out", p("map"))
        mesh = p("map/mesh.ply")
        if args.exact:
            mesh = p("exact.ply")
            contact = json.load(open(p("gt/world.json")))["rocks"][0]["contact"]["height_m"]
            exact_scan(p("gt/rock_1.ply"), p("gt/pedestal_1.ply"), contact, mesh)
        f = scan(args.rescore or args.bin, mesh, args.config)
        h = f["com_height_above_contact_m"]
        row.update(alpha=f["alpha_min_deg"], low=f["alpha_min_low_deg"], high=f["alpha_min_high_deg"],
                   H=h, delta_cm=100 * h * (math.tan(math.radians(f["alpha_min_deg"]))
                                            - math.tan(math.radians(row["truth"]))))
    except (RuntimeError, KeyError, ValueError) as e:
        row["error"] = str(e)[-160:]
    return row


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--bin", required=True)
    ap.add_argument("--out", required=True)
    ap.add_argument("--seeds", default="1", help="seeds, `1-4` or `1,3`; their rocks are pooled")
    ap.add_argument("--count", type=int, default=16)
    ap.add_argument("--no-noise", action="store_true")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--rescore", help="re-analyse the meshes in --out with this binary")
    ap.add_argument("--config", help="FragilityConfig TOML for the analysis")
    ap.add_argument("--exact", action="store_true", help="analyse the world's exact surfaces")
    ap.add_argument("--low-ring", action="store_true",
                    help="a third ring 3 cm above the pedestal's top, 1.5 m out (new maps only)")
    args = ap.parse_args()
    args.bin = os.path.abspath(args.bin)
    with ThreadPoolExecutor(args.jobs) as pool:
        rocks = [rock for seed in seeds(args.seeds) for rock in draw(seed, args.count)]
        rows = list(pool.map(lambda r: make(args, r), rocks))
    name = "fresh_shapes_exact.json" if args.exact else "fresh_shapes.json"
    with open(os.path.join(args.out, name), "w") as out:
        json.dump(rows, out, indent=1)
    done = [r for r in rows if "alpha" in r]
    built = [r for r in rows if "no_world" not in r]
    for r in rows:
        if "no_world" in r:
            print(f"{r['name']:18s} no world: {r['no_world'][-110:]}")
        elif "alpha" in r:
            inside = r["low"] <= r["truth"] <= r["high"]
            print(f"{r['name']:18s} truth {r['truth']:6.2f} scan {r['alpha']:6.2f} "
                  f"[{r['low']:6.2f}, {r['high']:6.2f}]{'' if inside else ' OUT'} "
                  f"H {r['H']:.2f} δ {r['delta_cm']:+.2f} cm")
        else:
            print(f"{r['name']:18s} refused: {r['error'][-110:]}")
    if done:
        errors = [r["alpha"] - r["truth"] for r in done]
        print(f"{len(done)} of {len(built)} analysed ({len(rows) - len(built)} of {len(rows)} drawn "
              f"left out: no pedestal holds them): |error| <= 2° {sum(abs(e) <= 2 for e in errors)}, "
              f"over +3° {sum(e > 3 for e in errors)}, under -3° {sum(e < -3 for e in errors)}, "
              f"truth inside {sum(r['low'] <= r['truth'] <= r['high'] for r in done)}, median width "
              f"{statistics.median(r['high'] - r['low'] for r in done):.2f}°, mean |error| "
              f"{statistics.mean(abs(e) for e in errors):.2f}°, median error "
              f"{statistics.median(errors):+.2f}°, median δ "
              f"{statistics.median(r['delta_cm'] for r in done):+.2f} cm")
        for kind in ("boulder", "block", "stone"):
            of_kind = [r for r in done if r["name"].endswith(kind)]
            print(f"  {kind}s: {len(of_kind)} analysed, |error| <= 2° "
                  f"{sum(abs(r['alpha'] - r['truth']) <= 2 for r in of_kind)}, over +3° "
                  f"{sum(r['alpha'] - r['truth'] > 3 for r in of_kind)}, truth inside "
                  f"{sum(r['low'] <= r['truth'] <= r['high'] for r in of_kind)}")


if __name__ == "__main__":
    main()
