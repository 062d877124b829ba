#!/usr/bin/env python3
"""Session 49 (#17): replay one target's localization from a recorded flight.

    scarp simulate --seed 60 --out run --record rec      # a default mission is about 12 GB
    python3 localization_window.py --bin target/release/scarp rec run/world_gt/world.json \\
        237 295.7 3 [--poses groundtruth] [-- extra scarp localize arguments]

Cuts the recording to the frames stamped T0..T1 s (the target's registration to the start of
its mapping: `run.log`'s "registered" and "fine_localize → map" lines), runs
`scarp localize --detector simulated` on it, and prints the C_e of the target on true rock
ROCK against the rock's centroid moved by the estimator's mean error over the window (with
`--poses groundtruth`, against the centroid itself), metres.
"""
import argparse
import json
import os
import subprocess
import sys
import tempfile

import numpy as np


def positions(path):
    return np.array([[float(x) for x in l.split()[1:4]] for l in open(path) if not l.startswith("#")])


def cut(recording, window, t0, t1):
    os.makedirs(window, exist_ok=True)
    files = {"rgb.txt": "rgb.txt", "depth.txt": "depth.txt", "estimate.txt": "estimate.txt",
             "boxes.txt": "boxes.txt", "groundtruth/groundtruth.txt": "groundtruth.txt"}
    for source, target in files.items():
        with open(os.path.join(window, target), "w") as out:
            for line in open(os.path.join(recording, source)):
                if line.startswith("#") or t0 <= float(line.split()[0]) <= t1:
                    out.write(line)
    for name in ["rgb", "depth", "mask", "camera.toml"]:
        os.symlink(os.path.abspath(os.path.join(recording, name)), os.path.join(window, name))


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--bin", default="target/release/scarp")
    p.add_argument("--poses", default="estimate", choices=["estimate", "groundtruth"])
    p.add_argument("recording")
    p.add_argument("world_json")
    p.add_argument("t0", type=float)
    p.add_argument("t1", type=float)
    p.add_argument("rock", type=int)
    p.add_argument("extra", nargs="*")
    a = p.parse_args()
    world = json.load(open(a.world_json))
    name = world.get("name", "default")
    with tempfile.TemporaryDirectory() as tmp:
        window = os.path.join(tmp, "window")
        cut(a.recording, window, a.t0, a.t1)
        out = subprocess.run(
            [a.bin, "localize", window, "--world", name, "--detector", "simulated", "--poses", a.poses,
             "--json", "--out", os.path.join(tmp, "out"), *a.extra],
            check=True, capture_output=True, text=True).stdout
        mean_error = np.zeros(3)
        if a.poses == "estimate":
            mean_error = (positions(os.path.join(window, "estimate.txt"))
                          - positions(os.path.join(window, "groundtruth.txt"))).mean(axis=0)
    centroid = np.array([r for r in world["rocks"] if r["id"] == a.rock][0]["centroid"])
    for t in json.loads(out)["targets"]:
        if t.get("gt_rock_id") == a.rock:
            offset = np.array(t["center"]) - centroid - mean_error
            print("rock %d: %s after %d updates; C_e offset (x, y, z) %s m" % (
                a.rock, t["status"], t["updates"], np.round(offset, 2)))
            return
    sys.exit("no target on rock %d" % a.rock)


if __name__ == "__main__":
    main()
