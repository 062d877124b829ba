#!/usr/bin/env python3
"""Fragility of planned-ring scans fused with true poses: the analysis alone, off the flight.

usage: scan_study.py --bin SCARP [--bin SCARP ...] --out DIR [--worlds default,library-a,library-b]
                     [--seeds 0-3] [--stride 2] [--jobs 2]

For every target rock of each world, `scarp plan` plans the mapping rings around its true
cylinder. Every `--stride`-th pose of the planned camera trajectory is rendered with the sensor's
noise (`scarp render --seed S`), fused with the true poses as a mission fuses its target
(`scarp map --poses groundtruth --voxel 0.01 --max-depth 5`, a cylinder round the rock), and
analysed by each binary (`scarp fragility --scan --json`). The truth is the world's rock on its
pedestal (`scarp fragility ROCK --pedestal PEDESTAL`).

It isolates what the depth noise does to the contact from what the flight (odometry, coverage,
an early end) does. Prints one row per scan and binary, then per binary: analysed, refused,
|error| <= 2 deg, over 3 deg high, truth inside the interval, median width, and the refusals by
reason. Sequences and meshes stay in DIR, so a re-run only analyses.
"""
import argparse
import json
import os
import statistics
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from reanalyse import refusal_kind  # noqa: E402


def run(cmd, **kw):
    return subprocess.run(cmd, capture_output=True, text=True, **kw)


def seeds_of(text):
    a, _, b = text.partition("-")
    return list(range(int(a), int(b or a) + 1))


def prepare(scarp, out, world, rock, seed, stride):
    """Plans, renders and fuses one scan; returns the mesh path or an error string."""
    d = os.path.join(out, world, "rock-%d" % rock["id"])
    mesh = os.path.join(d, "seed-%d" % seed, "map", "mesh.ply")
    if os.path.exists(mesh):
        return mesh
    plan = os.path.join(d, "plan")
    if not os.path.exists(os.path.join(plan, "camera_trajectory.txt")):
        r = run([scarp, "plan", "--world", world, "--target", str(rock["id"]), "--out", plan])
        if r.returncode:
            return "plan failed: " + r.stderr.strip().splitlines()[-1]
    lines = open(os.path.join(plan, "camera_trajectory.txt")).read().splitlines()
    head = [x for x in lines if x.startswith("#")]
    poses = [x for x in lines if not x.startswith("#")][::stride]
    sd = os.path.join(d, "seed-%d" % seed)
    os.makedirs(sd, exist_ok=True)
    traj = os.path.join(sd, "path.txt")
    open(traj, "w").write("\n".join(head + poses) + "\n")
    seq = os.path.join(sd, "seq")
    r = run([scarp, "render", "--world", world, "--path", traj, "--seed", str(seed), "--out", seq])
    if r.returncode:
        return "render failed: " + r.stderr.strip().splitlines()[-1]
    x, y, _ = rock["centroid"]
    z = rock["contact"]["height_m"]
    roi = "cyl:%.3f,%.3f,%.3f,%.3f,1.6" % (x, y, z - 1.8, z + rock["height_m"] + 0.5)
    r = run([scarp, "map", seq, "--poses", "groundtruth", "--voxel", "0.01", "--max-depth", "5",
             "--roi", roi, "--out", os.path.join(sd, "map")])
    if r.returncode:
        return "map failed: " + r.stderr.strip().splitlines()[-1]
    subprocess.run(["rm", "-rf", seq])
    return mesh


def analyse(scarp, mesh):
    r = run([scarp, "fragility", "--scan", "--json", mesh])
    if r.returncode:
        lines = r.stderr.strip().splitlines()
        # The CLI's last line names the mesh, then gives the analysis' reason.
        return {"refused": lines[-1].split(mesh + ": ", 1)[-1] if lines
                else "exit %d" % r.returncode}
    return json.loads(r.stdout)


def truth(scarp, out, world, rock):
    gt = os.path.join(out, world, "world")
    r = run([scarp, "fragility", "--json", os.path.join(gt, "rock_%d.ply" % rock["id"]),
             "--pedestal", os.path.join(gt, rock["pedestal_mesh"])])
    return json.loads(r.stdout)["alpha_min_deg"]


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--bin", action="append", required=True)
    p.add_argument("--out", required=True)
    p.add_argument("--worlds", default="default,library-a,library-b")
    p.add_argument("--seeds", default="0-3")
    p.add_argument("--stride", type=int, default=2)
    p.add_argument("--jobs", type=int, default=2)
    a = p.parse_args()
    scarp = a.bin[0]
    cases = []
    for world in a.worlds.split(","):
        gt = os.path.join(a.out, world, "world")
        if not os.path.exists(os.path.join(gt, "world.json")):
            r = run([scarp, "world", "--world", world, "--out", gt])
            if r.returncode:
                sys.exit("world %s: %s" % (world, r.stderr))
        rocks = json.load(open(os.path.join(gt, "world.json")))["rocks"]
        for rock in rocks:
            if rock["role"] != "target" or not rock.get("pedestal_mesh"):
                continue
            alpha = truth(scarp, a.out, world, rock)
            cases += [(world, rock, alpha, s) for s in seeds_of(a.seeds)]
    with ThreadPoolExecutor(a.jobs) as pool:
        meshes = list(pool.map(lambda c: prepare(scarp, a.out, c[0], c[1], c[3], a.stride), cases))
        results = {b: list(pool.map(lambda m: analyse(b, m) if m.endswith(".ply")
                                    else {"refused": m}, meshes)) for b in a.bin}
    for b in a.bin:
        print("## %s" % b)
        n = ok = within = over = inside = 0
        widths, kinds = [], {}
        for (world, rock, alpha, seed), res in zip(cases, results[b]):
            n += 1
            if "refused" in res:
                k = refusal_kind(res["refused"])[:110]
                kinds[k] = kinds.get(k, 0) + 1
                print("%-10s rock %2d seed %2d  truth %6.2f  refused: %s"
                      % (world, rock["id"], seed, alpha, res["refused"][-120:]))
                continue
            ok += 1
            e = res["alpha_min_deg"] - alpha
            lo, hi = res["alpha_min_low_deg"], res["alpha_min_high_deg"]
            within += abs(e) <= 2
            over += e > 3
            inside += lo <= alpha <= hi
            widths.append(hi - lo)
            print("%-10s rock %2d seed %2d  truth %6.2f  read %6.2f  error %+6.2f  [%6.2f, %6.2f]%s"
                  % (world, rock["id"], seed, alpha, res["alpha_min_deg"], e, lo, hi,
                     "" if lo <= alpha <= hi else "  OUTSIDE"))
        print("scans %d, analysed %d, refused %d; within 2 deg %d (%.1f%% of all); over 3 deg "
              "high %d; truth inside %d of %d; median width %.2f deg"
              % (n, ok, n - ok, within, 100.0 * within / max(n, 1), over, inside, ok,
                 statistics.median(widths) if widths else float("nan")))
        for k, c in sorted(kinds.items(), key=lambda kv: -kv[1]):
            print("  refused %2d: %s" % (c, k))


if __name__ == "__main__":
    main()
