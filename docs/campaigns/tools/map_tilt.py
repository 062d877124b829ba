#!/usr/bin/env python3
"""The map frame's tilt from gravity, per mapped target of a campaign, and α_min with it removed.

usage: map_tilt.py CAMPAIGN_DIR [--reanalysed OUT_DIR] [--analyse CONTACT_DIAGNOSIS] [--jobs 2]

Per target with a mesh (world, seed, true rock id):
- `tilt`: the angle between the map's up and the world's: the rotation world_from_map averaged
  over the keyframes (`keyframes_groundtruth.txt` against `keyframes_ba.txt`, the poses the mesh
  was fused at);
- `est`: the angle between the map's up and the state estimate's up averaged over the same
  keyframes (`trajectory.txt` at the keyframes' times): how far BA left the map from the
  estimate's attitude;
- `span_s`: the keyframes' time span;
- `support`: `support_tilt_deg` from its `mission.json`, or from `--reanalysed`'s (the
  `OUT_DIR` of `contact_diagnosis CAMPAIGN_DIR "" OUT_DIR`), where written.

Then the spread of each (min, median, p90, max). With `--analyse`, each mesh is also rotated by its
true tilt about its centroid (its up made the world's) and analysed with
`contact_diagnosis --mesh` (the `cargo run --release --example contact_diagnosis` binary):
that is α_min with the map's gravity error removed, beside the mesh as flown: each target's
error (OUT where the truth is outside its interval) and the totals of both (within 2°, truth
inside, median width, RMS error). Needs numpy.
"""
import argparse
import glob
import json
import math
import os
import subprocess
import sys
import tempfile
from concurrent.futures import ThreadPoolExecutor

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from kf_jumps import read_tum  # noqa: E402


def tum(path):
    """{timestamp: world_from_camera rotation} of a TUM file."""
    return {round(t, 4): np.array(r) for t, _, r in read_tum(path)}


def mean_rotation(pairs):
    """The rotation nearest the sum of `b_from_a` over (b, a) pairs of rotations."""
    u, _, vt = np.linalg.svd(sum(b @ a.T for b, a in pairs))
    return u @ vt


def angle_deg(up):
    return math.degrees(math.acos(min(1.0, up[2] / np.linalg.norm(up))))


def rotate_ply(src, dst, r):
    """Writes scarp's binary PLY `src` rotated by `r` about its vertices' mean."""
    data = open(src, "rb").read()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    header = data[:end].decode()
    count = int(next(l for l in header.splitlines() if l.startswith("element vertex")).split()[-1])
    props = [l.split()[-1] for l in header.splitlines() if l.startswith("property ")]
    layout = [("p", "<f4", 3)]
    if "nx" in props:
        layout.append(("n", "<f4", 3))
    if "red" in props:
        layout.append(("c", "u1", 3))
    dt = np.dtype(layout)
    v = np.frombuffer(data, dtype=dt, count=count, offset=end).copy()
    centre = v["p"].astype(np.float64).mean(0)
    v["p"] = ((v["p"] - centre) @ r.T + centre).astype(np.float32)
    if "n" in v.dtype.names:
        v["n"] = (v["n"] @ r.T).astype(np.float32)
    open(dst, "wb").write(data[:end] + v.tobytes() + data[end + count * dt.itemsize:])


def targets(campaign, reanalysed):
    for mission_path in sorted(glob.glob(campaign + "/runs/*/seed-*/mission.json")):
        run = os.path.dirname(mission_path)
        world, seed = run.split("/")[-2:]
        support = {}
        if reanalysed:
            again = json.load(open(f"{reanalysed}/runs/{world}/{seed}/mission.json"))["targets"]
            support = {t["id"]: t.get("support_tilt_deg") for t in again}
        estimate = tum(run + "/trajectory.txt")
        times = np.array(sorted(estimate))
        for t in json.load(open(mission_path))["targets"]:
            target = f"{run}/targets/{t['id']}"
            if t.get("gt_role") != "target" or not os.path.exists(target + "/mesh.ply"):
                continue
            ba = tum(target + "/keyframes_ba.txt")
            truth = tum(target + "/keyframes_groundtruth.txt")
            keys = sorted(k for k in ba if k in truth)
            if len(keys) < 3:
                continue
            world_from_map = mean_rotation((truth[k], ba[k]) for k in keys)
            estimate_from_map = mean_rotation(
                (estimate[times[np.argmin(abs(times - k))]], ba[k]) for k in keys)
            yield {
                "label": f"{world} {seed} {t['gt_rock_id']}",
                "world": world,
                "rock": t["gt_rock_id"],
                "mesh": target + "/mesh.ply",
                "world_from_map": world_from_map,
                "tilt": angle_deg(world_from_map @ [0, 0, 1.0]),
                "est": angle_deg(estimate_from_map @ [0, 0, 1.0]),
                "span_s": keys[-1] - keys[0],
                "support": support.get(t["id"], t.get("support_tilt_deg")),
            }


def levelling(world_from_map):
    """The smallest rotation (map frame) taking the world's up, as the map holds it, to +z."""
    up = world_from_map.T @ [0, 0, 1.0]
    axis = np.cross(up, [0, 0, 1.0])
    s, c = np.linalg.norm(axis), up[2]
    if s < 1e-12:
        return np.eye(3)
    k = axis / s
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + s * kx + (1 - c) * kx @ kx


def analyse(binary, row, scratch):
    """(truth, α_min, low, high) of the mesh as flown and levelled, `None` where refused."""
    levelled = os.path.join(scratch, row["label"].replace(" ", "_") + ".ply")
    rotate_ply(row["mesh"], levelled, levelling(row["world_from_map"]))
    out = []
    for mesh in (row["mesh"], levelled):
        done = subprocess.run([binary, "--mesh", mesh, row["world"], str(row["rock"]), "x"],
                              capture_output=True, text=True)
        line = next((l for l in done.stdout.splitlines() if l.startswith("INTERVAL")), None)
        out.append(tuple(map(float, line.split()[2:6])) if line else None)
    os.remove(levelled)
    return out


def spread(name, values):
    v = np.array([x for x in values if x is not None])
    if len(v):
        print(f"{name}: n {len(v)}, min {v.min():.2f}, median {np.median(v):.2f}, "
              f"p90 {np.percentile(v, 90):.2f}, max {v.max():.2f}")


def totals(name, readings):
    ok = [r for r in readings if r]
    if not ok:
        print(f"{name}: {len(readings)} meshes, all refused")
        return
    errors = np.array([a - t for t, a, _, _ in ok])
    widths = sorted(hi - lo for _, _, lo, hi in ok)
    print(f"{name}: {len(readings)} meshes, refused {len(readings) - len(ok)}, "
          f"within 2° {int((abs(errors) <= 2).sum())}, "
          f"inside {sum(lo <= t <= hi for t, _, lo, hi in ok)}, "
          f"median width {widths[len(widths) // 2]:.2f}°, RMS {math.sqrt((errors ** 2).mean()):.2f}°")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("campaign")
    ap.add_argument("--reanalysed", metavar="OUT_DIR")
    ap.add_argument("--analyse", metavar="CONTACT_DIAGNOSIS")
    ap.add_argument("--jobs", type=int, default=2)
    args = ap.parse_args()
    rows = list(targets(args.campaign, args.reanalysed))
    for r in rows:
        support = "-" if r["support"] is None else f"{r['support']:.3f}"
        print(f"{r['label']}: tilt {r['tilt']:.3f} est {r['est']:.3f} span {r['span_s']:.0f} s "
              f"support {support}")
    spread("map tilt from gravity (°)", [r["tilt"] for r in rows])
    spread("map up from the estimate's mean (°)", [r["est"] for r in rows])
    spread("keyframes' span (s)", [r["span_s"] for r in rows])
    spread("|support tilt − map tilt| where levelled (°)",
           [abs(r["support"] - r["tilt"]) for r in rows if r["support"]])
    if args.analyse:
        with tempfile.TemporaryDirectory() as scratch, ThreadPoolExecutor(args.jobs) as ex:
            pairs = list(ex.map(lambda r: analyse(args.analyse, r, scratch), rows))
        def error(reading):
            return "refused" if reading is None else "%+.2f%s" % (
                reading[1] - reading[0], "" if reading[2] <= reading[0] <= reading[3] else " OUT")
        for r, (flown, levelled) in zip(rows, pairs):
            print(f"{r['label']}: α error as flown {error(flown)}, levelled {error(levelled)}")
        totals("as flown", [p[0] for p in pairs])
        totals("levelled by the true tilt", [p[1] for p in pairs])


if __name__ == "__main__":
    main()
